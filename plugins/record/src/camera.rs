//! The camera files labs have: intrinsics and lens distortion from a ROS `camera_info` YAML
//! (what `camera_calibration` writes), an OpenCV YAML (`cv::FileStorage`, what OpenCV's
//! calibration samples write) or a plain 3x3 matrix; and the camera's pose in the robot's base
//! frame with its direction stated, never guessed.
//!
//! Frames: the camera frame is OpenCV's optical frame (x right, y down, z forward, as ROS's
//! `*_optical_frame` and Foxglove's `CompressedImage.frame_id`); K is row-major in pixels with
//! the centre of the top-left pixel at (0, 0).

use std::path::{Path, PathBuf};

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3,
};
use yaml_rust2::{Yaml, YamlLoader};

/// A camera file that cannot be used: the file and what is wrong, naming the field.
#[derive(Debug, thiserror::Error)]
pub enum CameraFileError {
    /// The file cannot be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file's content.
    #[error("{path}: {message}")]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the field.
        message: String,
    },
}

/// A camera calibration whose numbers cannot be used ([`CameraCalibration::validate`]): what
/// is wrong, naming the field (`K`, `D`, the image size).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct InvalidCalibration(pub String);

/// Lens distortion models, by ROS's `camera_info` names (the coefficients in OpenCV's order).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DistortionModel {
    /// `plumb_bob`: k1, k2, p1, p2, k3 (OpenCV's five-coefficient model).
    PlumbBob,
    /// `rational_polynomial`: k1, k2, p1, p2, k3, k4, k5, k6 (OpenCV's eight).
    RationalPolynomial,
    /// `equidistant`: k1, k2, k3, k4 (OpenCV's fisheye model).
    Equidistant,
}

impl DistortionModel {
    /// ROS's name (`sensor_msgs/CameraInfo.distortion_model`, Foxglove's too).
    pub fn ros_name(self) -> &'static str {
        match self {
            Self::PlumbBob => "plumb_bob",
            Self::RationalPolynomial => "rational_polynomial",
            Self::Equidistant => "equidistant",
        }
    }

    /// The model ROS names `name` (`fisheye` is taken for `equidistant`, as OpenCV calls it).
    pub fn from_ros_name(name: &str) -> Option<Self> {
        match name {
            "plumb_bob" => Some(Self::PlumbBob),
            "rational_polynomial" => Some(Self::RationalPolynomial),
            "equidistant" | "fisheye" => Some(Self::Equidistant),
            _ => None,
        }
    }

    /// How many coefficients the model takes.
    pub fn coefficients(self) -> usize {
        match self {
            Self::PlumbBob => 5,
            Self::RationalPolynomial => 8,
            Self::Equidistant => 4,
        }
    }
}

/// A camera's intrinsics and lens distortion.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraCalibration {
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// K, row-major: `[fx, 0, cx, 0, fy, cy, 0, 0, 1]` (px).
    pub k: [f64; 9],
    /// The distortion model.
    pub distortion_model: DistortionModel,
    /// Its coefficients (zeros: a pinhole), [`DistortionModel::coefficients`] of them.
    pub d: Vec<f64>,
}

impl CameraCalibration {
    /// A pinhole (no distortion) with `k`.
    pub fn pinhole(width: u32, height: u32, k: [f64; 9]) -> Self {
        Self {
            width,
            height,
            k,
            distortion_model: DistortionModel::PlumbBob,
            d: vec![0.0; 5],
        }
    }

    /// The calibration a `sensor_msgs/CameraInfo` carries: its size, K (row-major, px), its
    /// `distortion_model` by ROS's name and D (none: a pinhole's zeros), checked
    /// ([`Self::validate`]). Errors: a model not read (`plumb_bob`, `rational_polynomial`,
    /// `equidistant`), or numbers [`Self::validate`] refuses; the message names the field.
    pub fn from_camera_info(
        width: u32,
        height: u32,
        k: [f64; 9],
        distortion_model: &str,
        d: Vec<f64>,
    ) -> Result<Self, InvalidCalibration> {
        let model = DistortionModel::from_ros_name(distortion_model).ok_or_else(|| {
            InvalidCalibration(format!(
                "distortion model '{distortion_model}' is not read (plumb_bob, rational_polynomial, equidistant)"
            ))
        })?;
        let c = Self {
            width,
            height,
            k,
            distortion_model: model,
            d: if d.is_empty() {
                vec![0.0; model.coefficients()]
            } else {
                d
            },
        };
        c.validate()?;
        Ok(c)
    }

    /// Checks the numbers: a size, finite values, fx and fy > 0, the last row of K `0 0 1`,
    /// as many coefficients as the model takes. The message names the field.
    pub fn validate(&self) -> Result<(), InvalidCalibration> {
        if self.width == 0 || self.height == 0 {
            return Err(InvalidCalibration(format!(
                "image size {}x{}: must not be 0",
                self.width, self.height
            )));
        }
        if let Some(v) = self.k.iter().chain(&self.d).find(|v| !v.is_finite()) {
            return Err(InvalidCalibration(format!(
                "K or D holds {v}: every value must be finite"
            )));
        }
        if !(self.k[0] > 0.0 && self.k[4] > 0.0) {
            return Err(InvalidCalibration(format!(
                "K: fx {} and fy {} must be > 0",
                self.k[0], self.k[4]
            )));
        }
        if self.k[6..] != [0.0, 0.0, 1.0] {
            return Err(InvalidCalibration(format!(
                "K: the last row is {:?}, not [0, 0, 1]",
                &self.k[6..]
            )));
        }
        let n = self.distortion_model.coefficients();
        if self.d.len() != n {
            return Err(InvalidCalibration(format!(
                "D: {} coefficients for {} (which takes {n})",
                self.d.len(),
                self.distortion_model.ros_name()
            )));
        }
        Ok(())
    }

    /// Whether every distortion coefficient is zero.
    pub fn is_pinhole(&self) -> bool {
        self.d.iter().all(|v| *v == 0.0)
    }
}

fn content(path: &Path, message: impl Into<String>) -> CameraFileError {
    CameraFileError::Content {
        path: path.to_owned(),
        message: message.into(),
    }
}

fn read_text(path: &Path) -> Result<String, CameraFileError> {
    std::fs::read_to_string(path).map_err(|source| CameraFileError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Parses YAML (JSON is YAML too). OpenCV's `%YAML:1.0` directive and `!!opencv-matrix` tags
/// are not YAML 1.2: they are taken out first (the tagged mapping stays a mapping).
fn parse_yaml(path: &Path, text: &str) -> Result<Yaml, CameraFileError> {
    let cleaned: String = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("%YAML"))
        .map(|l| l.replace("!!opencv-matrix", ""))
        .collect::<Vec<_>>()
        .join("\n");
    let docs =
        YamlLoader::load_from_str(&cleaned).map_err(|e| content(path, format!("not YAML: {e}")))?;
    docs.into_iter()
        .next()
        .ok_or_else(|| content(path, "empty file"))
}

fn number(y: &Yaml) -> Option<f64> {
    match y {
        // YAML's own spellings of the non-finite values (refused later, by name).
        Yaml::Real(s) => match s
            .trim_start_matches(['+', '-'])
            .to_ascii_lowercase()
            .as_str()
        {
            ".nan" => Some(f64::NAN),
            ".inf" => Some(if s.starts_with('-') {
                f64::NEG_INFINITY
            } else {
                f64::INFINITY
            }),
            _ => s.parse().ok(),
        },
        Yaml::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// A list of numbers, or a `{rows, cols, data}` matrix (ROS and OpenCV), flattened row-major.
fn numbers(path: &Path, field: &str, y: &Yaml) -> Result<Vec<f64>, CameraFileError> {
    let list = |items: &Vec<Yaml>| -> Result<Vec<f64>, CameraFileError> {
        items
            .iter()
            .enumerate()
            .map(|(i, v)| match v {
                Yaml::Array(row) => Err(content(
                    path,
                    format!(
                        "{field}[{i}]: a row of {} where a number was expected",
                        row.len()
                    ),
                )),
                v => number(v)
                    .ok_or_else(|| content(path, format!("{field}[{i}]: {v:?} is not a number"))),
            })
            .collect()
    };
    match y {
        Yaml::Array(items) if items.iter().all(|v| matches!(v, Yaml::Array(_))) => {
            let mut out = Vec::new();
            for (r, row) in items.iter().enumerate() {
                if let Yaml::Array(row) = row {
                    out.extend(list(row).map_err(|_| {
                        content(
                            path,
                            format!("{field}, row {r}: every value must be a number"),
                        )
                    })?);
                }
            }
            Ok(out)
        }
        Yaml::Array(items) => list(items),
        Yaml::Hash(_) => {
            let data = &y["data"];
            let Yaml::Array(items) = data else {
                return Err(content(path, format!("{field}: no `data` list")));
            };
            let values = list(items)?;
            if let (Some(rows), Some(cols)) = (y["rows"].as_i64(), y["cols"].as_i64())
                && (rows * cols) as usize != values.len()
            {
                return Err(content(
                    path,
                    format!("{field}: {rows}x{cols} but {} values", values.len()),
                ));
            }
            Ok(values)
        }
        _ => Err(content(path, format!("{field}: not a list or a matrix"))),
    }
}

fn first<'a>(y: &'a Yaml, keys: &[&'static str]) -> Option<(&'static str, &'a Yaml)> {
    keys.iter()
        .map(|k| (*k, &y[*k]))
        .find(|(_, v)| !v.is_badvalue())
}

/// Reads a camera's intrinsics and distortion: a ROS `camera_info` YAML (`image_width`,
/// `image_height`, `camera_matrix`, `distortion_model`, `distortion_coefficients`), an OpenCV
/// YAML (`camera_matrix`/`cameraMatrix`/`K` and `distortion_coefficients`/`distCoeffs`/`D` as
/// `!!opencv-matrix`; the model from the number of coefficients: 5 plumb_bob, 8
/// rational_polynomial, 4 only with `distortion_model` saying which, since OpenCV's fisheye
/// and a plumb_bob without k3 both have 4), or a text file of a 3x3 matrix (no distortion).
/// `size` gives the image size where the file has none (a plain matrix, an OpenCV file
/// without `image_width`). Errors name the file and the field.
pub fn read_calibration(
    path: &Path,
    size: Option<(u32, u32)>,
) -> Result<CameraCalibration, CameraFileError> {
    let text = read_text(path)?;
    // A plain matrix: nine numbers, whitespace or commas between them.
    let plain: Option<Vec<f64>> = text
        .split(|c: char| c.is_whitespace() || c == ',' || c == '[' || c == ']')
        .filter(|t| !t.is_empty())
        .map(|t| t.parse().ok())
        .collect();
    let calibration = if let Some(values) = plain {
        let k: [f64; 9] = values.try_into().map_err(|v: Vec<f64>| {
            content(path, format!("{} numbers: a 3x3 matrix K has 9", v.len()))
        })?;
        let (width, height) = size.ok_or_else(|| {
            content(
                path,
                "a plain matrix has no image size, and none was given (the images give it on import)",
            )
        })?;
        CameraCalibration::pinhole(width, height, k)
    } else {
        let y = parse_yaml(path, &text)?;
        let (field, k) = first(&y, &["camera_matrix", "cameraMatrix", "K", "k"])
            .ok_or_else(|| content(path, "no camera_matrix (nor cameraMatrix, K)"))?;
        let k: [f64; 9] = numbers(path, field, k)?.try_into().map_err(|v: Vec<f64>| {
            content(
                path,
                format!("{field}: {} values, a 3x3 matrix has 9", v.len()),
            )
        })?;
        let d = match first(
            &y,
            &[
                "distortion_coefficients",
                "distCoeffs",
                "dist_coeffs",
                "D",
                "d",
            ],
        ) {
            Some((field, d)) => numbers(path, field, d)?,
            None => Vec::new(),
        };
        let named = match &y["distortion_model"] {
            Yaml::String(s) => Some(DistortionModel::from_ros_name(s).ok_or_else(|| {
                content(
                    path,
                    format!(
                        "distortion_model '{s}': Avatarm knows plumb_bob, rational_polynomial and equidistant"
                    ),
                )
            })?),
            Yaml::BadValue => None,
            other => return Err(content(path, format!("distortion_model: {other:?} is not a name"))),
        };
        let model = match (named, d.len()) {
            (Some(m), _) => m,
            (None, 0 | 5) => DistortionModel::PlumbBob,
            (None, 8) => DistortionModel::RationalPolynomial,
            (None, 4) => {
                return Err(content(
                    path,
                    "4 distortion coefficients: OpenCV's fisheye (equidistant) or a plumb_bob without k3? Say which with distortion_model: equidistant or plumb_bob",
                ));
            }
            (None, n) => {
                return Err(content(
                    path,
                    format!(
                        "{n} distortion coefficients: Avatarm takes 5 (plumb_bob), 8 (rational_polynomial) or 4 (equidistant)"
                    ),
                ));
            }
        };
        // None given: zeros; a plumb_bob with 4 (no k3): k3 is zero.
        let mut d = d;
        if d.is_empty() || (model == DistortionModel::PlumbBob && d.len() == 4) {
            d.resize(model.coefficients(), 0.0);
        }
        let dimension = |keys: &[&'static str]| {
            first(&y, keys)
                .and_then(|(_, v)| v.as_i64())
                .and_then(|v| u32::try_from(v).ok())
        };
        let (width, height) = match (
            dimension(&["image_width", "width"]),
            dimension(&["image_height", "height"]),
            size,
        ) {
            (Some(w), Some(h), _) => (w, h),
            (_, _, Some(s)) => s,
            _ => {
                return Err(content(
                    path,
                    "no image_width and image_height, and no image size was given (the images give it on import)",
                ));
            }
        };
        CameraCalibration {
            width,
            height,
            k,
            distortion_model: model,
            d,
        }
    };
    if let Some((w, h)) = size
        && (w, h) != (calibration.width, calibration.height)
    {
        return Err(content(
            path,
            format!(
                "the file says {}x{}, the images are {w}x{h}",
                calibration.width, calibration.height
            ),
        ));
    }
    calibration.validate().map_err(|m| content(path, m.0))?;
    Ok(calibration)
}

/// Reads the camera's pose in the robot's base frame: a YAML or JSON file whose one top-level
/// key states the direction, `camera_from_base` (maps base-frame points into the camera
/// frame, OpenCV's extrinsics `[R|t]`) or `base_from_camera` (the camera's pose in the base
/// frame), holding either a 4x4 matrix (a list of 4 rows, or 16 numbers row-major, or
/// `matrix:`), or `translation: [x, y, z]` (m) with `quaternion_xyzw` or `quaternion_wxyz` or
/// `rotation_vector: [rx, ry, rz]` (axis × angle, rad, OpenCV's `rvec`). Returns
/// base_from_camera. A file that does not say the direction, or the quaternion's order, is an
/// error, never a guess; so is a matrix whose rotation is not one (orthonormality within
/// 1e-4, determinant +1) or a quaternion whose norm is off 1 by more than 1e-3.
pub fn read_pose(path: &Path) -> Result<Isometry3<f64>, CameraFileError> {
    read_transform(
        path,
        ("base_from_camera", "the camera's pose in the base frame"),
        (
            "camera_from_base",
            "base points into the camera frame, OpenCV's [R|t]",
        ),
    )
}

/// The largest erase margin a pose file may ask for (px).
pub const MAX_ERASE_MARGIN_PX: i64 = 64;

/// The erase margin a pose or mount file carries (`erase_margin_px: N`, which `avatarm
/// calibrate` writes beside the pose it fits: the mask dilation, in pixels, that covers how
/// far the fitted outline stays from the frames'); `None` when the file has none. Errors: the
/// file cannot be read or parsed, or the value is not a whole number from 0 to
/// [`MAX_ERASE_MARGIN_PX`] (naming the file).
pub fn read_erase_margin(path: &Path) -> Result<Option<u32>, CameraFileError> {
    let text = read_text(path)?;
    let y = parse_yaml(path, &text)?;
    match &y["erase_margin_px"] {
        Yaml::BadValue => Ok(None),
        Yaml::Integer(v) if (0..=MAX_ERASE_MARGIN_PX).contains(v) => Ok(Some(*v as u32)),
        other => Err(content(
            path,
            format!(
                "erase_margin_px: {other:?} is not a whole number of pixels from 0 to {MAX_ERASE_MARGIN_PX}"
            ),
        )),
    }
}

/// Reads the mount of a camera on a head: a YAML or JSON file whose one top-level key is
/// `head_from_camera` (the camera's pose in the head's optical frame: x right, y down,
/// z forward) or `camera_from_head`, holding a pose as [`read_pose`] reads it. Returns
/// head_from_camera. Errors as [`read_pose`]'s.
pub fn read_mount(path: &Path) -> Result<Isometry3<f64>, CameraFileError> {
    read_transform(
        path,
        ("head_from_camera", "the camera's pose in the head's frame"),
        ("camera_from_head", "head points into the camera frame"),
    )
}

/// A pose file under one of two keys: `direct` (`a_from_b`, returned as it is) or `inverse`
/// (`b_from_a`, inverted), each with what it means for the error naming neither.
fn read_transform(
    path: &Path,
    direct: (&str, &str),
    inverse: (&str, &str),
) -> Result<Isometry3<f64>, CameraFileError> {
    let text = read_text(path)?;
    let y = parse_yaml(path, &text)?;
    let (direction, pose) = match (&y[inverse.0], &y[direct.0]) {
        (Yaml::BadValue, Yaml::BadValue) => {
            return Err(content(
                path,
                format!(
                    "the pose's direction is not stated: put it under {} ({}) or {} ({})",
                    inverse.0, inverse.1, direct.0, direct.1
                ),
            ));
        }
        (p, Yaml::BadValue) => (inverse.0, p),
        (Yaml::BadValue, p) => (direct.0, p),
        _ => {
            return Err(content(
                path,
                format!("both {} and {}: give one", inverse.0, direct.0),
            ));
        }
    };
    let iso = pose_of(path, direction, pose)?;
    Ok(if direction == inverse.0 {
        iso.inverse()
    } else {
        iso
    })
}

fn vector3(path: &Path, field: &str, y: &Yaml) -> Result<Vector3<f64>, CameraFileError> {
    let v = numbers(path, field, y)?;
    let v: [f64; 3] = v
        .try_into()
        .map_err(|v: Vec<f64>| content(path, format!("{field}: {} values, not 3", v.len())))?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(content(path, format!("{field}: {v:?} is not finite")));
    }
    Ok(Vector3::from(v))
}

fn pose_of(path: &Path, direction: &str, y: &Yaml) -> Result<Isometry3<f64>, CameraFileError> {
    let matrix = match y {
        Yaml::Array(_) => Some((direction.to_owned(), y)),
        Yaml::Hash(_) if !y["matrix"].is_badvalue() => {
            Some((format!("{direction}.matrix"), &y["matrix"]))
        }
        _ => None,
    };
    if let Some((field, m)) = matrix {
        let v = numbers(path, &field, m)?;
        let v: [f64; 16] = v.try_into().map_err(|v: Vec<f64>| {
            content(
                path,
                format!("{field}: {} values, a 4x4 matrix has 16", v.len()),
            )
        })?;
        if v.iter().any(|x| !x.is_finite()) {
            return Err(content(path, format!("{field}: not every value is finite")));
        }
        let m = Matrix4::from_row_slice(&v);
        if (m.fixed_view::<1, 4>(3, 0) - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0)).amax()
            > 1e-9
        {
            return Err(content(
                path,
                format!("{field}: the last row is not [0, 0, 0, 1]"),
            ));
        }
        let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into();
        let off = (r.transpose() * r - Matrix3::identity()).amax();
        if off > 1e-4 || r.determinant() < 0.0 {
            return Err(content(
                path,
                format!(
                    "{field}: the 3x3 block is not a rotation (RᵀR off identity by {off:.2e}, det {:.4})",
                    r.determinant()
                ),
            ));
        }
        let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
        let t = Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
        return Ok(Isometry3::from_parts(t, rotation));
    }
    if !matches!(y, Yaml::Hash(_)) {
        return Err(content(path, format!("{direction}: a matrix or a mapping")));
    }
    let t = vector3(path, &format!("{direction}.translation"), &y["translation"])?;
    let field = |k: &str| format!("{direction}.{k}");
    let rotation = if !y["quaternion_xyzw"].is_badvalue() || !y["quaternion_wxyz"].is_badvalue() {
        let (key, xyzw) = if y["quaternion_xyzw"].is_badvalue() {
            ("quaternion_wxyz", false)
        } else {
            ("quaternion_xyzw", true)
        };
        let q = numbers(path, &field(key), &y[key])?;
        let q: [f64; 4] = q.try_into().map_err(|v: Vec<f64>| {
            content(path, format!("{}: {} values, not 4", field(key), v.len()))
        })?;
        let q = if xyzw {
            Quaternion::new(q[3], q[0], q[1], q[2])
        } else {
            Quaternion::new(q[0], q[1], q[2], q[3])
        };
        let norm = q.norm();
        if !norm.is_finite() || (norm - 1.0).abs() > 1e-3 {
            return Err(content(path, format!("{}: norm {norm}, not 1", field(key))));
        }
        UnitQuaternion::from_quaternion(q)
    } else if !y["rotation_vector"].is_badvalue() {
        UnitQuaternion::from_scaled_axis(vector3(
            path,
            &field("rotation_vector"),
            &y["rotation_vector"],
        )?)
    } else if !y["quaternion"].is_badvalue() {
        return Err(content(
            path,
            format!(
                "{}: say the order: quaternion_xyzw (ROS, Eigen's coeffs) or quaternion_wxyz",
                field("quaternion")
            ),
        ));
    } else {
        return Err(content(
            path,
            format!(
                "{direction}: no rotation (quaternion_xyzw, quaternion_wxyz, rotation_vector or matrix)"
            ),
        ));
    };
    Ok(Isometry3::from_parts(Translation3::from(t), rotation))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("avatarm_camera_{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write");
        p
    }

    #[test]
    fn ros_and_opencv_files_give_the_same_calibration() {
        let ros = file(
            "ros.yaml",
            "image_width: 640\nimage_height: 480\ncamera_name: desk\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [600.5, 0, 320.25, 0, 601, 240.5, 0, 0, 1]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.1, -0.2, 0.001, 0.002, 0.05]\n",
        );
        let cv = file(
            "cv.yaml",
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 600.5, 0., 320.25, 0., 601., 240.5, 0., 0., 1. ]\ndistortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ 0.1, -0.2, 0.001, 0.002, 0.05 ]\n",
        );
        let a = read_calibration(&ros, None).expect("ros");
        let b = read_calibration(&cv, Some((640, 480))).expect("opencv");
        assert_eq!(a, b);
        assert_eq!(a.k[2], 320.25);
        assert_eq!(a.distortion_model, DistortionModel::PlumbBob);
        // Eight: rational; four: must say which.
        let eight = file(
            "eight.yaml",
            "K: [500, 0, 320, 0, 500, 240, 0, 0, 1]\nD: [0, 0, 0, 0, 0, 0, 0, 0]\n",
        );
        let c = read_calibration(&eight, Some((640, 480))).expect("eight");
        assert_eq!(c.distortion_model, DistortionModel::RationalPolynomial);
        let four = file(
            "four.yaml",
            "K: [500, 0, 320, 0, 500, 240, 0, 0, 1]\nD: [0.1, 0, 0, 0]\n",
        );
        let e = read_calibration(&four, Some((640, 480))).expect_err("ambiguous");
        assert!(e.to_string().contains("Say which"), "{e}");
        let fisheye = file(
            "fisheye.yaml",
            "K: [500, 0, 320, 0, 500, 240, 0, 0, 1]\nD: [0.1, 0, 0, 0]\ndistortion_model: equidistant\n",
        );
        let c = read_calibration(&fisheye, Some((640, 480))).expect("fisheye");
        assert_eq!(c.distortion_model, DistortionModel::Equidistant);
    }

    #[test]
    fn a_pose_file_s_erase_margin_is_read_and_a_bad_one_named() {
        let pose = "base_from_camera:\n  - [1, 0, 0, 0]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 1]\n  - [0, 0, 0, 1]\n";
        let plain = file("pose_plain.yaml", pose);
        assert_eq!(read_erase_margin(&plain).expect("read"), None);
        let with = file("pose_margin.yaml", &format!("{pose}erase_margin_px: 3\n"));
        assert_eq!(read_erase_margin(&with).expect("read"), Some(3));
        read_pose(&with).expect("the pose still reads");
        for bad in ["-1", "2.5", "1000", "wide"] {
            let f = file("pose_bad.yaml", &format!("{pose}erase_margin_px: {bad}\n"));
            let e = read_erase_margin(&f).expect_err(bad);
            assert!(e.to_string().contains("pose_bad.yaml"), "{e}");
            assert!(e.to_string().contains("erase_margin_px"), "{e}");
        }
    }

    #[test]
    fn a_plain_matrix_needs_the_size_and_bad_files_name_the_field() {
        let k = file("K.txt", "615.0 0.0 320.0\n0.0 615.0 240.0\n0.0 0.0 1.0\n");
        let e = read_calibration(&k, None).expect_err("no size");
        assert!(e.to_string().contains("no image size"), "{e}");
        let c = read_calibration(&k, Some((640, 480))).expect("K");
        assert!(c.is_pinhole() && c.k[0] == 615.0);
        for (text, want) in [
            (
                "camera_matrix: [1, 0, 0, 0, 1, 0, 0, 0]\nimage_width: 1\nimage_height: 1\n",
                "8 values",
            ),
            (
                "camera_matrix: [0, 0, 0, 0, 1, 0, 0, 0, 1]\nimage_width: 1\nimage_height: 1\n",
                "fx 0",
            ),
            (
                "camera_matrix: [1, 0, 0, 0, .nan, 0, 0, 0, 1]\nimage_width: 1\nimage_height: 1\n",
                "finite",
            ),
            (
                "camera_matrix: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nimage_width: 1\nimage_height: 1\ndistortion_model: kannala\n",
                "kannala",
            ),
            ("image_width: 1\n", "no camera_matrix"),
        ] {
            let e = read_calibration(&file("bad.yaml", text), None).expect_err(text);
            assert!(e.to_string().contains(want), "{text}: {e}");
        }
        let mismatch = file(
            "ros2.yaml",
            "image_width: 640\nimage_height: 480\ncamera_matrix: [500, 0, 320, 0, 500, 240, 0, 0, 1]\n",
        );
        let e = read_calibration(&mismatch, Some((1280, 720))).expect_err("size");
        assert!(e.to_string().contains("1280x720"), "{e}");
    }

    #[test]
    fn every_pose_convention_gives_the_same_pose_and_a_missing_direction_is_an_error() {
        // The camera 1.2 m in front of the base looking back at it (OpenCV axes).
        let base_from_camera = Isometry3::from_parts(
            Translation3::new(1.2, 0.1, 0.5),
            UnitQuaternion::from_euler_angles(-1.9, 0.05, 1.6),
        );
        let camera_from_base = base_from_camera.inverse();
        let m = camera_from_base.to_homogeneous();
        let rows: Vec<String> = (0..4)
            .map(|r| {
                format!(
                    "[{}]",
                    (0..4)
                        .map(|c| format!("{:.17}", m[(r, c)]))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })
            .collect();
        let q = base_from_camera.rotation;
        let t = base_from_camera.translation.vector;
        let rv = camera_from_base.rotation.scaled_axis();
        let tc = camera_from_base.translation.vector;
        let files = [
            format!("camera_from_base: [{}]\n", rows.join(", ")),
            format!(
                "{{\"camera_from_base\": {{\"matrix\": [{}]}}}}\n",
                rows.join(", ")
            ),
            format!(
                "base_from_camera:\n  translation: [{:.17}, {:.17}, {:.17}]\n  quaternion_xyzw: [{:.17}, {:.17}, {:.17}, {:.17}]\n",
                t.x, t.y, t.z, q.i, q.j, q.k, q.w
            ),
            format!(
                "base_from_camera:\n  translation: [{:.17}, {:.17}, {:.17}]\n  quaternion_wxyz: [{:.17}, {:.17}, {:.17}, {:.17}]\n",
                t.x, t.y, t.z, q.w, q.i, q.j, q.k
            ),
            format!(
                "camera_from_base:\n  rotation_vector: [{:.17}, {:.17}, {:.17}]\n  translation: [{:.17}, {:.17}, {:.17}]\n",
                rv.x, rv.y, rv.z, tc.x, tc.y, tc.z
            ),
        ];
        for text in &files {
            let pose = read_pose(&file("pose.yaml", text)).expect(text);
            let d = pose.inverse() * base_from_camera;
            assert!(
                d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-9,
                "{text}: {pose:?}"
            );
        }
        for (text, want) in [
            (format!("pose: [{}]\n", rows.join(", ")), "direction is not stated"),
            ("base_from_camera:\n  translation: [0, 0, 1]\n  quaternion: [0, 0, 0, 1]\n".to_owned(), "say the order"),
            ("base_from_camera:\n  translation: [0, 0, 1]\n  quaternion_xyzw: [0, 0, 0, 2]\n".to_owned(), "norm 2"),
            ("base_from_camera: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]\n".to_owned(), "not a rotation"),
            ("camera_from_base: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\nbase_from_camera: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\n".to_owned(), "give one"),
        ] {
            let e = read_pose(&file("bad_pose.yaml", &text)).expect_err(&text);
            assert!(e.to_string().contains(want), "{text}: {e}");
        }
        // A head camera's mount, under its own keys, either way round.
        let mount = read_mount(&file(
            "mount.yaml",
            &format!("camera_from_head: [{}]\n", rows.join(", ")),
        ))
        .expect("mount");
        let d = mount.inverse() * base_from_camera;
        assert!(d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-9);
        let e = read_mount(&file("pose_as_mount.yaml", &files[0])).expect_err("a camera pose");
        assert!(
            e.to_string().contains("camera_from_head")
                && e.to_string().contains("head_from_camera"),
            "{e}"
        );
    }
}
