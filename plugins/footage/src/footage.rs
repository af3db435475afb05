//! `avatarm import FOLDER --out FILE.mcap`: the camera frames a lab has, with the robot's
//! joints at each, into a recording ([`avatarm_record`]) that Foxglove opens and Avatarm
//! replays.
//!
//! What a folder may hold:
//! - a listing, `frames.csv` or `frames.json` (or `--listing FILE`):
//!   - CSV with a header: `file` (the frame, relative to the listing), `stamp_s` (capture
//!     time, s), optionally `mask` (a reference silhouette, 255 = robot), and one column per
//!     joint, named by the joint's name (rad or m);
//!   - JSON: `{"joint_names": [..], "frames": [{"file", "stamp_s", "mask", "joints": {name:
//!     value}} or {.., "q": [..]}]}`, `q` in `joint_names`' order (or `--joint-names`, or the
//!     description's movable joints in q order with `--urdf`);
//! - or EasyHeC's layout (a public hand–eye calibration dataset): `color/NNNNNN.png`,
//!   `mask/NNNNNN.png`, `qpos/NNNNNN.txt` (the joints in q order), `K.txt`; frames `--fps`
//!   apart;
//! - the camera file: `--camera` or `camera_info.yaml`, `camera.yaml`, `K.txt` in the folder
//!   ([`avatarm_record::camera::read_calibration`]);
//! - the camera's pose with its direction stated: `--pose` or `pose.yaml`, `pose.json`
//!   ([`avatarm_record::camera::read_pose`]); optional.

use std::path::{Path, PathBuf};

use avatarm_record::camera::{read_calibration, read_pose};
use avatarm_record::{CompressedFrame, ImageFormat, JointStates, RecordingWriter};

use crate::FootageError;

/// What `avatarm import FOLDER` does.
#[derive(Debug, Clone)]
pub struct FootageOptions {
    /// The folder.
    pub folder: PathBuf,
    /// The recording to write (`.mcap`).
    pub out: PathBuf,
    /// The listing, when not `frames.csv`/`frames.json` in the folder.
    pub listing: Option<PathBuf>,
    /// The camera file, when not in the folder.
    pub camera: Option<PathBuf>,
    /// The pose file, when not in the folder.
    pub pose: Option<PathBuf>,
    /// Names for joints given in q order.
    pub joint_names: Vec<String>,
    /// A description whose movable joints name joints given in q order.
    pub urdf: Option<PathBuf>,
    /// Where the description's `package://` URIs are looked for.
    pub packages: avatarm_core::robot::PackagePath,
    /// Frames per second where the source has no stamps (EasyHeC).
    pub fps: f64,
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct FootageSummary {
    /// Which layout the folder had (`listing CSV`, `listing JSON`, `EasyHeC`).
    pub layout: &'static str,
    /// Frames written.
    pub frames: usize,
    /// Reference masks written.
    pub masks: usize,
    /// Image size (px).
    pub size: (u32, u32),
    /// From the first frame to the last (s).
    pub duration_s: f64,
    /// The joints' names.
    pub joints: Vec<String>,
    /// Whether a camera pose was written.
    pub pose: bool,
}

/// One frame as the source lists it.
#[derive(Debug, Clone)]
struct Entry {
    /// Where it was listed (`frames.csv, line 3`), for errors.
    at: String,
    file: PathBuf,
    stamp_s: f64,
    mask: Option<PathBuf>,
    /// Values by name, or in q order (names resolved later).
    joints: Joints,
}

#[derive(Debug, Clone)]
enum Joints {
    Named(Vec<(String, f64)>),
    Ordered(Vec<f64>),
}

fn listing_error(at: &str, message: impl Into<String>) -> FootageError {
    FootageError::input(at, message)
}

fn read(path: &Path) -> Result<Vec<u8>, FootageError> {
    std::fs::read(path).map_err(|source| FootageError::Io {
        path: path.to_owned(),
        action: "read",
        source,
    })
}

fn finite(at: &str, what: &str, text: &str) -> Result<f64, FootageError> {
    let v: f64 = text
        .trim()
        .parse()
        .map_err(|_| listing_error(at, format!("{what}: '{text}' is not a number")))?;
    if !v.is_finite() {
        return Err(listing_error(at, format!("{what}: {v} is not finite")));
    }
    Ok(v)
}

fn csv_entries(path: &Path) -> Result<Vec<Entry>, FootageError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path.display().to_string();
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| listing_error(&name, e.to_string()))?;
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| listing_error(&name, e.to_string()))?
        .iter()
        .map(str::to_owned)
        .collect();
    let column = |c: &str| header.iter().position(|h| h == c);
    let (Some(file), Some(stamp)) = (column("file"), column("stamp_s")) else {
        return Err(listing_error(
            &name,
            format!("the header {header:?} needs `file` and `stamp_s` columns"),
        ));
    };
    let mask = column("mask");
    let joints: Vec<(usize, &String)> = header
        .iter()
        .enumerate()
        .filter(|(i, _)| ![Some(file), Some(stamp), mask].contains(&Some(*i)))
        .collect();
    let mut out = Vec::new();
    for (row, record) in reader.records().enumerate() {
        let at = format!("{name}, line {}", row + 2);
        let record = record.map_err(|e| listing_error(&at, e.to_string()))?;
        let cell = |i: usize| record.get(i).unwrap_or("");
        let named = joints
            .iter()
            .map(|(i, n)| {
                Ok((
                    (*n).clone(),
                    finite(&at, &format!("joint '{n}'"), cell(*i))?,
                ))
            })
            .collect::<Result<Vec<_>, FootageError>>()?;
        out.push(Entry {
            file: dir.join(cell(file)),
            stamp_s: finite(&at, "stamp_s", cell(stamp))?,
            mask: mask
                .map(cell)
                .filter(|m| !m.is_empty())
                .map(|m| dir.join(m)),
            joints: Joints::Named(named),
            at,
        });
    }
    Ok(out)
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JsonListing {
    #[serde(default)]
    joint_names: Vec<String>,
    frames: Vec<JsonFrame>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JsonFrame {
    file: PathBuf,
    stamp_s: f64,
    #[serde(default)]
    mask: Option<PathBuf>,
    #[serde(default)]
    joints: Option<std::collections::BTreeMap<String, f64>>,
    #[serde(default)]
    q: Option<Vec<f64>>,
}

fn json_entries(path: &Path) -> Result<(Vec<Entry>, Vec<String>), FootageError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path.display().to_string();
    let text = read(path)?;
    let listing: JsonListing =
        serde_json::from_slice(&text).map_err(|e| listing_error(&name, e.to_string()))?;
    let mut out = Vec::new();
    for (i, f) in listing.frames.into_iter().enumerate() {
        let at = format!("{name}, frames[{i}]");
        let joints = match (f.joints, f.q) {
            (Some(j), None) => Joints::Named(j.into_iter().collect()),
            (None, Some(q)) => Joints::Ordered(q),
            _ => {
                return Err(listing_error(
                    &at,
                    "give either `joints` (by name) or `q` (in order)",
                ));
            }
        };
        if !f.stamp_s.is_finite() {
            return Err(listing_error(
                &at,
                format!("stamp_s {} is not finite", f.stamp_s),
            ));
        }
        out.push(Entry {
            file: dir.join(f.file),
            stamp_s: f.stamp_s,
            mask: f.mask.map(|m| dir.join(m)),
            joints,
            at,
        });
    }
    Ok((out, listing.joint_names))
}

fn easyhec_entries(folder: &Path, fps: f64) -> Result<Vec<Entry>, FootageError> {
    let color = folder.join("color");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&color)
        .map_err(|source| FootageError::Io {
            path: color.clone(),
            action: "read",
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
        })
        .collect();
    files.sort();
    let mut out = Vec::new();
    for (i, file) in files.into_iter().enumerate() {
        let stem = file
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default()
            .to_owned();
        let qpos = folder.join("qpos").join(format!("{stem}.txt"));
        let at = qpos.display().to_string();
        let text = String::from_utf8_lossy(&read(&qpos)?).into_owned();
        let q = text
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
            .enumerate()
            .map(|(k, t)| finite(&at, &format!("value {k}"), t))
            .collect::<Result<Vec<_>, _>>()?;
        let mask = folder.join("mask").join(format!("{stem}.png"));
        out.push(Entry {
            at,
            stamp_s: i as f64 / fps,
            mask: mask.is_file().then_some(mask),
            file,
            joints: Joints::Ordered(q),
        });
    }
    if out.is_empty() {
        return Err(listing_error(
            &color.display().to_string(),
            "no PNG or JPEG frames",
        ));
    }
    Ok(out)
}

fn first_file(folder: &Path, names: &[&str]) -> Option<PathBuf> {
    names.iter().map(|n| folder.join(n)).find(|p| p.is_file())
}

/// An image file as it is: its bytes, their format and the image's size (px).
type Encoded = (Vec<u8>, ImageFormat, (u32, u32));

fn encoded(path: &Path, at: &str) -> Result<Encoded, FootageError> {
    let data = read(path)?;
    let format = ImageFormat::of_bytes(&data)
        .ok_or_else(|| listing_error(at, format!("{}: not a PNG or JPEG image", path.display())))?;
    let size = image::ImageReader::new(std::io::Cursor::new(&data))
        .with_guessed_format()
        .map_err(|source| FootageError::Io {
            path: path.to_owned(),
            action: "read",
            source,
        })?
        .into_dimensions()
        .map_err(|source| FootageError::Image {
            path: path.to_owned(),
            action: "read",
            source,
        })?;
    Ok((data, format, size))
}

/// Imports the folder into a recording. Errors name the file and the entry (`frames.csv, line
/// 3`, `qpos/000004.txt`) and what is wrong: a missing or unreadable image, frames of
/// different sizes, a joint value or stamp that is not a finite number, stamps that repeat,
/// joints in q order with no names or a different count, a camera file that does not fit
/// the images, a pose whose direction is not stated.
#[expect(
    clippy::too_many_lines,
    reason = "the listing read, every entry checked and the recording written, in that order"
)]
pub fn import_footage(o: &FootageOptions) -> Result<FootageSummary, FootageError> {
    if !(o.fps.is_finite() && o.fps > 0.0) {
        return Err(FootageError::input(
            "--fps",
            format!("{}: must be > 0", o.fps),
        ));
    }
    let folder = &o.folder;
    let listing = o
        .listing
        .clone()
        .or_else(|| first_file(folder, &["frames.csv", "frames.json"]));
    let (layout, mut entries, listed_names) = match &listing {
        Some(p)
            if p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("json")) =>
        {
            let (e, names) = json_entries(p)?;
            ("listing JSON", e, names)
        }
        Some(p) => ("listing CSV", csv_entries(p)?, Vec::new()),
        None if folder.join("color").is_dir() => {
            ("EasyHeC", easyhec_entries(folder, o.fps)?, Vec::new())
        }
        None => {
            return Err(FootageError::input(
                "FOLDER",
                format!(
                    "{}: no frames.csv or frames.json (nor --listing), and no color/ folder (EasyHeC's layout)",
                    folder.display()
                ),
            ));
        }
    };
    if entries.is_empty() {
        return Err(FootageError::input("FOLDER", "the listing has no frames"));
    }
    // Names for joints given in q order.
    let ordered_names: Vec<String> = if !listed_names.is_empty() {
        listed_names
    } else if !o.joint_names.is_empty() {
        o.joint_names.clone()
    } else if let Some(urdf) = &o.urdf {
        let model = avatarm_core::robot::RobotModel::from_urdf_file(urdf, &o.packages)?;
        model.dof_names().iter().map(|s| (*s).to_owned()).collect()
    } else {
        Vec::new()
    };
    entries.sort_by(|a, b| a.stamp_s.total_cmp(&b.stamp_s));
    if let Some(w) = entries.windows(2).find(|w| w[0].stamp_s == w[1].stamp_s) {
        return Err(listing_error(
            &w[1].at,
            format!("stamp_s {} repeats {}'s", w[1].stamp_s, w[0].at),
        ));
    }
    if let Some(e) = entries.iter().find(|e| e.stamp_s < 0.0) {
        return Err(listing_error(
            &e.at,
            format!("stamp_s {} is negative", e.stamp_s),
        ));
    }
    // The images' size, from the first frame (read once: it is written first below).
    let mut first = Some(encoded(&entries[0].file, &entries[0].at)?);
    let size = first.as_ref().map_or((0, 0), |f| f.2);
    let camera = o
        .camera
        .clone()
        .or_else(|| first_file(folder, &["camera_info.yaml", "camera.yaml", "K.txt"]))
        .ok_or_else(|| {
            FootageError::input(
                "--camera",
                "no camera file in the folder (camera_info.yaml, camera.yaml, K.txt): give one (a ROS camera_info or OpenCV YAML, or a 3x3 K)",
            )
        })?;
    let calibration = read_calibration(&camera, Some(size))?;
    let pose = o
        .pose
        .clone()
        .or_else(|| first_file(folder, &["pose.yaml", "pose.json"]))
        .map(|p| read_pose(&p))
        .transpose()?;
    let ns = |s: f64| (s * 1e9).round() as u64;
    let t0 = ns(entries[0].stamp_s);
    let mut out = RecordingWriter::create(&o.out)?;
    out.calibration(t0, &calibration)?;
    if let Some(pose) = &pose {
        out.camera_pose(t0, pose)?;
    }
    let mut names_used: Vec<String> = Vec::new();
    let mut masks = 0;
    for e in &entries {
        let stamp_ns = ns(e.stamp_s);
        let (data, format, s) = match first.take() {
            Some(f) => f,
            None => encoded(&e.file, &e.at)?,
        };
        if s != size {
            return Err(listing_error(
                &e.at,
                format!(
                    "{} is {}x{}, the first frame {}x{}",
                    e.file.display(),
                    s.0,
                    s.1,
                    size.0,
                    size.1
                ),
            ));
        }
        out.frame(&CompressedFrame {
            stamp_ns,
            format,
            data,
        })?;
        if let Some(m) = &e.mask {
            let (data, format, s) = encoded(m, &e.at)?;
            if s != size {
                return Err(listing_error(
                    &e.at,
                    format!(
                        "the mask {} is {}x{}, the frame {}x{}",
                        m.display(),
                        s.0,
                        s.1,
                        size.0,
                        size.1
                    ),
                ));
            }
            out.reference_mask(&CompressedFrame {
                stamp_ns,
                format,
                data,
            })?;
            masks += 1;
        }
        let (names, positions): (Vec<String>, Vec<f64>) = match &e.joints {
            Joints::Named(v) => v.iter().cloned().unzip(),
            Joints::Ordered(q) => {
                if ordered_names.is_empty() {
                    return Err(listing_error(
                        &e.at,
                        "joints in q order and no names for them: give --joint-names, --urdf or the listing's joint_names",
                    ));
                }
                if q.len() != ordered_names.len() {
                    return Err(listing_error(
                        &e.at,
                        format!(
                            "{} joint values for {} names ({})",
                            q.len(),
                            ordered_names.len(),
                            ordered_names.join(", ")
                        ),
                    ));
                }
                (ordered_names.clone(), q.clone())
            }
        };
        if let Some((n, v)) = names.iter().zip(&positions).find(|(_, v)| !v.is_finite()) {
            return Err(listing_error(
                &e.at,
                format!("joint '{n}': {v} is not finite"),
            ));
        }
        names_used.clone_from(&names);
        out.joint_states(&JointStates {
            stamp_ns,
            names,
            positions,
            velocities: Vec::new(),
        })?;
    }
    out.finish()?;
    Ok(FootageSummary {
        layout,
        frames: entries.len(),
        masks,
        size,
        duration_s: entries.last().map_or(0.0, |l| l.stamp_s) - entries[0].stamp_s,
        joints: names_used,
        pose: pose.is_some(),
    })
}
