//! `avatarm calibrate --recording FILE.mcap --urdf DESCRIPTION`: the camera's pose fitted to the
//! robot itself, so that the mask lands on the robot without a calibration board.
//!
//! The recording gives the frames' robot silhouettes (its reference masks, or with
//! `--background FILE` each frame's difference from an empty-room photograph,
//! [`dr::background_difference`]), the joints at each frame (interpolated to the capture
//! time) and K; the rough pose comes from `--pose FILE`,
//! `--look-at EYE,TARGET` or the recording. [`avatarm_core::vision::calibrate`] fits the pose
//! (and with `--intrinsics` fx, fy) on the `--fit` frames; the IoU of the model silhouette
//! against the reference is measured on every frame before and after, so that `--eval` frames
//! left out of the fit say how well the pose generalises. With `--edges` no silhouette is
//! needed: the fit draws the robot's outline to each frame's own image edges (Canny's), among
//! the room's ([`Observed::Edges`]); reference masks, where the recording has them, only score
//! it. Written to `--out`:
//! `camera_pose.yaml` (`base_from_camera`, a 4x4 matrix: what `--pose` and `avatarm import
//! --pose` read), `camera_info.yaml` with `--intrinsics`, `overlay_before_NNNNN.png` and
//! `overlay_after_NNNNN.png` (the model's silhouette tinted red, the reference's outline in
//! green; with `--edges` the frame's Canny edges in yellow, and each frame's edge map, white on
//! black, in `edges_NNNNN.png`), and `report.json`.
//!
//! A recording of a camera on a head (Alice's headset camera: the head's tracked poses and the
//! mount, `avatarm_record::HEAD_FRAME`) gets its *mount* fitted instead: each frame's robot is
//! put in the head's frame at the frame's capture (the tracked poses interpolated to it), where
//! one `camera_from_head` must explain every frame, and the same fit runs on it from the rough
//! mount (`--mount FILE`, or the recording's). The views from several head poses constrain it
//! better than one fixed view does. Written: `camera_mount.yaml` (`head_from_camera`: what
//! `--mount` and `avatarm replay --believed-mount` read) instead of `camera_pose.yaml`.

use std::path::PathBuf;
use std::time::Instant;

use avatarm_core::dr;
use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::vision::calibrate::{
    CalibrationOptions, Observed, RobotSilhouette, SilhouetteFrame, calibrate, clip_below,
    rasterize,
};
use avatarm_core::vision::camera::CameraPose;
use avatarm_core::vision::distortion::Distortion;
use avatarm_record::camera::read_pose;
use avatarm_record::{HEAD_POSE_SLACK_NS, Recording};
use nalgebra::{Isometry3, UnitQuaternion};
use serde_json::json;

use crate::AppError;
use crate::replay::recording::{
    decode, interpolate, joint_vectors, overlay, recording_camera, recording_mount,
};

/// The pairing check draws every frame's joints against every frame's mask: up to this many.
const MAX_PAIRING_FRAMES: usize = 60;

/// Frames one fit takes at most (10 take 50 s on two cores).
const MAX_FIT_FRAMES: usize = 100;

/// The largest Sobel gradient's magnitude of 8-bit luma, in imageproc's scale (its `canny`
/// doc): a higher threshold finds no edge.
const MAX_SOBEL: f32 = 1141.0;

/// Frames one run decodes, draws and scores at most (fit and held out).
const MAX_USED_FRAMES: usize = 300;

/// What `avatarm calibrate` is given.
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// The recording (MCAP) with reference masks.
    pub recording: PathBuf,
    /// The robot's description.
    pub urdf: PathBuf,
    /// Folders searched for its `package://` URIs.
    pub packages: PackagePath,
    /// A camera file instead of the recording's calibration.
    pub camera: Option<PathBuf>,
    /// The rough pose from a file.
    pub pose: Option<PathBuf>,
    /// The rough pose as the camera's eye and a point it looks at, in the base frame (m).
    pub look_at: Option<([f64; 3], [f64; 3])>,
    /// A camera on a head: the rough mount from a file (`head_from_camera`), else the
    /// recording's.
    pub mount: Option<PathBuf>,
    /// Frames the fit uses (inclusive ranges of indices); every frame with a silhouette when
    /// empty (a reference mask, or with `background` every frame).
    pub fit: Vec<(usize, usize)>,
    /// Only every N-th frame with a silhouette is used at all (fit and measured).
    pub every: usize,
    /// Also fit fx and fy.
    pub fit_focal: bool,
    /// Triangles the robot's silhouette is drawn with.
    pub budget: usize,
    /// The robot's geometry below this height in the base frame (m) is hidden (the table it
    /// stands on) and cut from the silhouette.
    pub hidden_below: Option<f64>,
    /// An empty-room photograph of the same camera: the silhouettes are each frame's
    /// difference from it instead of the reference masks.
    pub background: Option<PathBuf>,
    /// The difference (8-bit levels, any channel) that counts as the robot.
    pub background_threshold: u8,
    /// Fit to each frame's image edges instead of silhouettes: Canny's low and high
    /// thresholds on the Sobel gradient's magnitude of the blurred luma (imageproc's scale: a
    /// clean step of N 8-bit levels gives about 2N to 4N; at most 1141, `MAX_SOBEL`).
    pub edges: Option<(f32, f32)>,
    /// Output folder.
    pub out: PathBuf,
    /// Show a progress bar.
    pub progress: bool,
}

/// Fits the pose; returns the report (also `out/report.json`).
#[expect(
    clippy::too_many_lines,
    reason = "the command's stages in their order (inputs, rough pose, the fit's stages, outputs, report); splitting it into those stages is left for the next pass (issue 43)"
)]
pub fn run_calibrate(o: &CalibrateOptions) -> Result<serde_json::Value, AppError> {
    let started = Instant::now();
    let name = o.recording.display().to_string();
    let bad = |message: String| AppError::recording(name.to_owned(), message);
    let recording = Recording::open(&o.recording)?;
    let (calibration, k) = recording_camera(&recording, o.camera.as_deref(), &name)?;
    let size = (k.width, k.height);
    // A camera on a head: the fit is of the mount. Each frame's robot is put in the head's
    // frame at the frame's capture, so that one camera_from_head explains every frame.
    let pose_flag = match (&o.pose, &o.look_at) {
        (Some(_), _) => Some("--pose"),
        (None, Some(_)) => Some("--look-at"),
        (None, None) => None,
    };
    let head_from_camera =
        recording_mount(&recording, o.mount.as_deref(), pose_flag, "--mount", &name)?;
    let on_head = head_from_camera.is_some();
    if o.edges.is_some() && o.background.is_some() {
        return Err(AppError::flag(
            "--edges",
            "fits to the frames' own edges: give it or --background, not both",
        ));
    }
    if let Some((low, high)) = o.edges
        && !(low.is_finite() && high.is_finite() && low > 0.0 && low <= high && high <= MAX_SOBEL)
    {
        return Err(AppError::flag(
            "--edge-thresholds",
            format!(
                "{low},{high}: give LOW,HIGH with 0 < LOW <= HIGH <= {MAX_SOBEL} (the Sobel gradient's magnitude)"
            ),
        ));
    }
    if on_head && o.background.is_some() {
        return Err(AppError::flag(
            "--background",
            format!(
                "{name}: the camera rides on a head, so one photograph is not its empty room: fit to the recording's reference masks"
            ),
        ));
    }
    let base_from_camera = match (&o.pose, &o.look_at) {
        _ if head_from_camera.is_some() => head_from_camera.unwrap_or_default(),
        (Some(path), _) => read_pose(path)?,
        (None, Some((eye, target))) => CameraPose {
            eye: *eye,
            target: *target,
            up: [0.0, 0.0, 1.0],
        }
        .to_isometry()?,
        (None, None) => recording.base_from_camera.ok_or_else(|| {
            bad(
                "no rough pose: give --pose FILE or --look-at EYE,TARGET (the recording has none)"
                    .into(),
            )
        })?,
    };
    let rough = base_from_camera.inverse();
    let model = RobotModel::from_urdf_file(&o.urdf, &o.packages)?;
    let mut notes = Vec::new();
    // The lens: every projected vertex goes through it, in the fit and in the IoUs.
    let lens = Distortion::from_ros(calibration.distortion_model.ros_name(), &calibration.d)?;
    let states = joint_vectors(&recording, &model, &name, &mut notes)?;
    let silhouette = RobotSilhouette::new(&model, o.budget)?;
    let background = match &o.background {
        Some(path) => {
            let image = image::open(path).map_err(|source| AppError::Image {
                path: path.clone(),
                action: "read",
                source,
            })?;
            if (image.width(), image.height()) != size {
                return Err(AppError::flag(
                    "--background",
                    format!(
                        "{} is {}x{}, the frames {}x{}",
                        path.display(),
                        image.width(),
                        image.height(),
                        size.0,
                        size.1
                    ),
                ));
            }
            Some(image.to_rgba8().into_raw())
        }
        None => None,
    };
    // How many frames there are to decode and draw, before any is.
    let candidates = if background.is_some() || o.edges.is_some() {
        recording.frames.len()
    } else {
        recording.reference_masks.len()
    };
    let used = candidates.div_ceil(o.every.max(1));
    if used > MAX_USED_FRAMES {
        return Err(AppError::flag(
            "--every",
            format!(
                "{used} frames to use (of {candidates} with a silhouette or edges): at most {MAX_USED_FRAMES}; thin them with --every {}",
                candidates.div_ceil(MAX_USED_FRAMES)
            ),
        ));
    }
    if o.edges.is_some() {
        // For the edge maps, written as they are found.
        std::fs::create_dir_all(&o.out).map_err(|source| AppError::Io {
            path: o.out.clone(),
            action: "create",
            source,
        })?;
    }
    // Where both exist, how well the background's silhouettes match the reference masks.
    let mut difference_vs_reference = Vec::new();
    // The frames with a silhouette: the robot's at its joints, and the observed one.
    let mut frames = Vec::new();
    let mut with_silhouette = 0usize;
    // A camera on a head: frames left out for want of a head pose.
    let mut outside_head = 0usize;
    for (i, f) in recording.frames.iter().enumerate() {
        let reference = recording
            .reference_masks
            .iter()
            .find(|m| m.stamp_ns.abs_diff(f.stamp_ns) <= 1_000_000);
        if reference.is_none() && background.is_none() && o.edges.is_none() {
            continue;
        }
        with_silhouette += 1;
        if !(with_silhouette - 1).is_multiple_of(o.every.max(1)) {
            continue;
        }
        let reference = match reference {
            Some(m) => {
                let mask = decode(m, &name)?;
                if mask.dimensions() != size {
                    return Err(bad(format!(
                        "the reference mask at {} ns is not {}x{}",
                        m.stamp_ns, size.0, size.1
                    )));
                }
                Some(dr::binarise(&mask.into_raw(), 4))
            }
            None => None,
        };
        let observed = match (&background, o.edges) {
            (_, Some((low, high))) => {
                let frame = decode(f, &name)?;
                if frame.dimensions() != size {
                    return Err(bad(format!(
                        "the frame at {} ns is {}x{}, the camera {}x{}",
                        f.stamp_ns,
                        frame.width(),
                        frame.height(),
                        size.0,
                        size.1
                    )));
                }
                let edges = image_edges(&frame, (low, high));
                // Written before the fit, for tuning the thresholds by eye even when the fit
                // is refused or stopped.
                let map = edges.iter().map(|&v| 255 * v).collect();
                if let Some(map) = image::GrayImage::from_raw(size.0, size.1, map) {
                    let path = o.out.join(format!("edges_{i:05}.png"));
                    map.save(&path)
                        .map_err(|source| AppError::write_image(path, source))?;
                }
                if !edges.contains(&1) {
                    notes.push(format!(
                        "frame {i}: no edge above --edge-thresholds {low},{high}: left out"
                    ));
                    continue;
                }
                edges
            }
            (Some(bg), None) => {
                let frame = decode(f, &name)?;
                let frame = dr::RgbaView::new("frame", size.0, size.1, frame.as_raw())?;
                let bg = dr::RgbaView::new("--background", size.0, size.1, bg)?;
                let m = dr::background_difference(&frame, &bg, o.background_threshold, 2)?;
                // An exposure change or someone in view makes the whole frame differ; a robot
                // out of view leaves nothing: neither is a silhouette to fit.
                let coverage = m.iter().filter(|&&v| v > 0).count() as f64 / m.len() as f64;
                if !(0.001..=0.5).contains(&coverage) {
                    notes.push(format!(
                        "frame {i}: {:.1} % of it differs from the background: left out (an exposure change, something else in view, or no robot)",
                        100.0 * coverage
                    ));
                    continue;
                }
                if let Some(s) = reference.as_ref().and_then(|r| dr::mask_scores(&m, r)) {
                    difference_vs_reference.push(s.iou);
                }
                m
            }
            (None, None) => match &reference {
                Some(r) => r.clone(),
                None => continue,
            },
        };
        // Scored (IoUs, pairing) against the reference where there is one, fitted to `observed`
        // (a silhouette; edges score nothing).
        let scored = match reference {
            Some(r) => Some(r),
            None => o.edges.is_none().then(|| observed.clone()),
        };
        let q = interpolate(&states, f.stamp_ns);
        let mut triangles = silhouette.at(&model, &Isometry3::identity(), q.as_slice());
        if let Some(z) = o.hidden_below {
            triangles = clip_below(&triangles, z);
        }
        if on_head {
            // The robot as the head saw it at the frame's capture.
            if !recording.head_covers(f.stamp_ns, HEAD_POSE_SLACK_NS) {
                outside_head += 1;
                notes.push(format!(
                    "frame {i}: captured more than {} ms outside the tracked head poses: left out",
                    HEAD_POSE_SLACK_NS / 1_000_000
                ));
                continue;
            }
            let head_from_base = recording.head_at(f.stamp_ns).unwrap_or_default().inverse();
            for t in &mut triangles {
                for v in t.iter_mut() {
                    *v = head_from_base * *v;
                }
            }
        }
        frames.push((
            i,
            SilhouetteFrame {
                triangles,
                observed,
            },
            scored,
        ));
    }
    if frames.is_empty() && outside_head > 0 {
        return Err(bad(format!(
            "every frame with a silhouette ({outside_head}) was captured more than {} ms outside the tracked head poses",
            HEAD_POSE_SLACK_NS / 1_000_000
        )));
    }
    if frames.is_empty() && o.edges.is_some() {
        return Err(bad(
            "no frame has an edge above the thresholds: lower --edge-thresholds".into(),
        ));
    }
    if frames.is_empty() {
        return Err(bad(
            "no frame has a reference mask (the robot's silhouette to fit): import the frames with their masks, give an empty-room photograph with --background (a fixed camera), or fit to the frames' own edges with --edges".into(),
        ));
    }
    let in_fit = |i: usize| o.fit.is_empty() || o.fit.iter().any(|&(a, b)| (a..=b).contains(&i));
    let fit: Vec<SilhouetteFrame> = frames
        .iter()
        .filter(|(i, _, _)| in_fit(*i))
        .map(|(_, f, _)| f.clone())
        .collect();
    if fit.is_empty() {
        return Err(AppError::flag(
            "--fit",
            format!(
                "no frame with a silhouette (or edges) in that range (frames {} to {})",
                frames[0].0,
                frames[frames.len() - 1].0
            ),
        ));
    }
    if fit.len() > MAX_FIT_FRAMES {
        return Err(AppError::flag(
            "--every",
            format!(
                "{} frames to fit: at most {MAX_FIT_FRAMES} (each costs every evaluation); thin them with --every N or pick them with --fit",
                fit.len()
            ),
        ));
    }
    std::fs::create_dir_all(&o.out).map_err(|source| AppError::Io {
        path: o.out.clone(),
        action: "create",
        source,
    })?;
    let options = CalibrationOptions {
        observed: if o.edges.is_some() {
            Observed::Edges
        } else {
            Observed::Silhouette
        },
        fit_focal: o.fit_focal,
        distortion: lens,
        ..CalibrationOptions::default()
    };
    let bar = crate::progress::bar(1, format!("calibrate on {} frames", fit.len()), o.progress);
    let result = calibrate(&fit, &k, &rough, &options, |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    // Every frame, before and after, at full resolution.
    let mut per_frame = Vec::new();
    // The silhouettes at the fitted pose, kept for the pairing check.
    let mut drawn: Vec<Vec<u8>> = Vec::with_capacity(frames.len());
    let (w, h) = size;
    for (i, f, scored) in &frames {
        let before = rasterize(&f.triangles, &rough, &k, &lens);
        let after = rasterize(
            &f.triangles,
            &result.camera_from_base,
            &result.intrinsics,
            &lens,
        );
        let iou = |m: &[u8]| {
            scored
                .as_deref()
                .and_then(|r| dr::mask_scores(m, r))
                .map_or(f64::NAN, |s| s.iou)
        };
        let image = decode(&recording.frames[*i], &name)?.into_raw();
        // With --edges: what the fit drew the outline to, for tuning --edge-thresholds.
        let edges = o.edges.is_some().then_some(f.observed.as_slice());
        for (tag, m) in [("before", &before), ("after", &after)] {
            let picture = overlay(&image, m, edges, scored.as_deref(), w);
            let picture = image::RgbaImage::from_raw(w, h, picture).ok_or(AppError::ImageSize {
                what: "overlay".into(),
                width: w,
                height: h,
            })?;
            let path = o.out.join(format!("overlay_{tag}_{i:05}.png"));
            picture
                .save(&path)
                .map_err(|source| AppError::write_image(path, source))?;
        }
        per_frame.push(json!({
            "frame": i,
            "fit": in_fit(*i),
            "iou_before": iou(&before),
            "iou_after": iou(&after),
        }));
        drawn.push(after);
    }
    // Pairing: each frame's reference against the silhouette at every frame's joints, at the
    // fitted pose. A frame whose mask another frame's joints explain clearly better than its
    // own was recorded with the wrong joints (or a wrong stamp): no pose can fit it.
    let mut pairing = Vec::new();
    let mut mispaired = Vec::new();
    if frames.iter().any(|(_, _, scored)| scored.is_none()) {
        notes.push(
            "the pairing check was skipped: it needs every frame's reference mask (fitted to edges)"
                .into(),
        );
    } else if frames.len() > MAX_PAIRING_FRAMES {
        notes.push(format!(
            "the pairing check was skipped: {} frames (at most {MAX_PAIRING_FRAMES}; thin them with --every)",
            frames.len()
        ));
    } else {
        for (a, (i, _, scored)) in frames.iter().enumerate() {
            let scores: Vec<f64> = drawn
                .iter()
                .map(|m| {
                    scored
                        .as_deref()
                        .and_then(|r| dr::mask_scores(m, r))
                        .map_or(0.0, |s| s.iou)
                })
                .collect();
            let (best, best_iou) =
                scores.iter().enumerate().fold(
                    (a, scores[a]),
                    |b, (j, &v)| if v > b.1 { (j, v) } else { b },
                );
            let own = scores[a];
            if best != a && best_iou > own + 0.1 {
                mispaired.push(*i);
            }
            pairing.push(json!({
                "frame": i,
                "own_joints_iou": own,
                "best_joints_frame": frames[best].0,
                "best_joints_iou": best_iou,
            }));
        }
        if !mispaired.is_empty() {
            notes.push(format!(
                "frames {mispaired:?}: another frame's joints fit the reference mask better than their own by more than 0.1 IoU (see pairing): the frames and joint states look mispaired, which bounds the IoU any pose reaches"
            ));
        }
    }
    let mean = |fit: bool, key: &str| -> Option<f64> {
        let v: Vec<f64> = per_frame
            .iter()
            .filter(|f| f["fit"].as_bool() == Some(fit))
            .filter_map(|f| f[key].as_f64())
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    // For a camera on a head, "base" below is the head: the pose is the mount.
    let base_from_camera = result.camera_from_base.inverse();
    let change = result.camera_from_base * rough.inverse();
    // The starts reach 8 deg and 0.1 m from the rough pose: an answer far beyond them is more
    // likely a wrong basin (with --edges, the outline laid on other edges) than the camera.
    let (moved_deg, moved_m) = (
        change.rotation.angle().to_degrees(),
        change.translation.vector.norm(),
    );
    if moved_deg > 2.0 * options.start_deg || moved_m > 3.0 * options.start_m {
        notes.push(format!(
            "the fit moved {moved_deg:.1} deg and {:.0} mm from the rough {}, far beyond its starts ({} deg, {} mm): check the overlays; a closer rough {}{} may be needed",
            1e3 * moved_m,
            if on_head { "mount" } else { "pose" },
            options.start_deg,
            1e3 * options.start_m,
            if on_head { "mount" } else { "pose" },
            if o.edges.is_some() {
                ", or silhouettes instead of --edges,"
            } else {
                ""
            }
        ));
    }
    let (pose_file, key, frame_name) = if on_head {
        (
            "camera_mount.yaml",
            "head_from_camera",
            "the head's optical frame (x right, y down, z forward)",
        )
    } else {
        (
            "camera_pose.yaml",
            "base_from_camera",
            "the robot's base frame",
        )
    };
    let pose_path = o.out.join(pose_file);
    let m = base_from_camera.to_homogeneous();
    let rows: String = (0..4)
        .map(|r| {
            format!(
                "  - [{:.9}, {:.9}, {:.9}, {:.9}]\n",
                m[(r, 0)],
                m[(r, 1)],
                m[(r, 2)],
                m[(r, 3)]
            )
        })
        .collect();
    let text = format!(
        "# The camera's pose in {frame_name} (OpenCV optical axes: x right, y down,\n# z forward), fitted by `avatarm calibrate` to {} frames of {}.\n{key}:\n{rows}",
        fit.len(),
        name
    );
    std::fs::write(&pose_path, text).map_err(|e| AppError::write(&pose_path, e))?;
    let mut camera_path = None;
    if o.fit_focal {
        let path = o.out.join("camera_info.yaml");
        let ki = &result.intrinsics;
        let text = format!(
            "# K fitted by `avatarm calibrate` (fx, fy; the principal point and distortion as recorded).\nimage_width: {}\nimage_height: {}\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [{}, 0, {}, 0, {}, {}, 0, 0, 1]\ndistortion_model: {}\ndistortion_coefficients:\n  rows: 1\n  cols: {}\n  data: [{}]\n",
            ki.width,
            ki.height,
            ki.fx,
            ki.cx,
            ki.fy,
            ki.cy,
            calibration.distortion_model.ros_name(),
            calibration.d.len(),
            calibration
                .d
                .iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
        std::fs::write(&path, text).map_err(|e| AppError::write(&path, e))?;
        camera_path = Some(path.display().to_string());
    }
    let stages: Vec<serde_json::Value> = ["coarse", "fine", "full"]
        .iter()
        .enumerate()
        .map(|(i, stage)| {
            json!({"stage": stage, "seconds": result.stage_seconds[i],
                   "evaluations": result.stage_evaluations[i]})
        })
        .collect();
    let q: UnitQuaternion<f64> = base_from_camera.rotation;
    let t = base_from_camera.translation.vector;
    let rpy = q.euler_angles();
    let report = json!({
        "recording": name,
        "robot": model.name,
        "triangles": silhouette.triangle_count(),
        "hidden_below_m": o.hidden_below,
        "distortion": {"model": calibration.distortion_model.ros_name(), "coefficients": calibration.d, "applied": !lens.is_none()},
        "frames_used": frames.len(),
        "silhouettes": match (&o.background, o.edges) {
            (_, Some((low, high))) => json!({
                "source": "image edges (Canny): no silhouette; IoUs against reference masks where the recording has them",
                "canny_thresholds": [low, high],
            }),
            (Some(path), None) => json!({
                "source": "background difference",
                "background": path.display().to_string(),
                "threshold": o.background_threshold,
                "iou_vs_reference_mean": (!difference_vs_reference.is_empty()).then(|| {
                    difference_vs_reference.iter().sum::<f64>() / difference_vs_reference.len() as f64
                }),
            }),
            (None, None) => json!({"source": "reference masks"}),
        },
        "frames_fit": fit.len(),
        "iou": {
            "fit_before": mean(true, "iou_before"),
            "fit_after": mean(true, "iou_after"),
            "held_out_before": mean(false, "iou_before"),
            "held_out_after": mean(false, "iou_after"),
            "per_frame": per_frame,
        },
        "camera": if on_head { "on a head: the fit is the mount (head_from_camera)" } else { "fixed" },
        "head_poses": recording.head_poses.len(),
        key: {
            "translation": [t.x, t.y, t.z],
            "quaternion_xyzw": [q.i, q.j, q.k, q.w],
            "rpy": [rpy.0, rpy.1, rpy.2],
        },
        "change_from_rough": {
            "rotation_deg": change.rotation.angle().to_degrees(),
            "translation_mm": 1e3 * change.translation.vector.norm(),
        },
        "intrinsics": {"fx": result.intrinsics.fx, "fy": result.intrinsics.fy,
                       "cx": result.intrinsics.cx, "cy": result.intrinsics.cy, "fitted": o.fit_focal},
        "cost_px": {"rough": result.rough_cost_px, "fitted": result.cost_px},
        "uncertainty": {
            "spread_deg": result.spread_deg_mm.0,
            "spread_mm": result.spread_deg_mm.1,
            "starts": result.starts.iter().map(|s| json!({
                "start_deg": s.start.0, "start_m": s.start.1, "cost_px": s.cost_px,
            })).collect::<Vec<_>>(),
            "note": "cost_px: the mean truncated chamfer distance between the outlines at half resolution (with --edges, from the model's outline to the nearest image edge); spread: the largest difference between the answer and another start that ended within 10 % of its cost",
        },
        "pairing": pairing,
        "mispaired_frames": mispaired,
        "evaluations": result.evaluations,
        "stages": stages,
        "wall_time_s": started.elapsed().as_secs_f64(),
        "notes": notes,
        "outputs": {"pose": pose_path.display().to_string(), "camera": camera_path},
    });
    let path = o.out.join("report.json");
    let text = serde_json::to_string_pretty(&report)?;
    std::fs::write(&path, text + "\n").map_err(|e| AppError::write(path, e))?;
    Ok(report)
}

/// The frame's image edges, 0/1 per pixel (top row first): Canny's detector on its luma
/// (`imageproc::edges::canny`: a Gaussian of σ 1.4, Sobel gradients, non-maximum suppression,
/// then hysteresis between `low` and `high` on the gradient's magnitude, in imageproc's scale,
/// [`MAX_SOBEL`] at most).
fn image_edges(frame: &image::RgbaImage, (low, high): (f32, f32)) -> Vec<u8> {
    let grey = image::imageops::grayscale(frame);
    imageproc::edges::canny(&grey, low, high)
        .into_raw()
        .into_iter()
        .map(|v| u8::from(v != 0))
        .collect()
}
