//! Pinhole cameras: intrinsics, pose, projection of world points to pixels.
//!
//! Conventions, the same as OpenCV and ROS's `camera_info`:
//! - the camera's *optical frame* has x right, y down, z forward (into the scene);
//! - pixel coordinates `(u, v)` have the centre of the top-left pixel at `(0, 0)`, so a
//!   centred principal point of a 640×480 camera is `(319.5, 239.5)`.
//!
//! Renderers (Bevy) use a view frame with x right, y up, z backward and pixel centres at
//! half-integers; [`PinholeCamera::clip_from_view`] builds the matching projection.

use nalgebra::{Isometry3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Pinhole intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    /// Focal length along u (px).
    pub fx: f64,
    /// Focal length along v (px).
    pub fy: f64,
    /// Principal point u (px).
    pub cx: f64,
    /// Principal point v (px).
    pub cy: f64,
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
}

impl Default for Intrinsics {
    /// 640×480 with a 60° vertical field of view, as a typical USB webcam (the paper's size).
    fn default() -> Self {
        Self::from_fov_y(60f64.to_radians(), 640, 480)
    }
}

impl Intrinsics {
    /// Square pixels, centred principal point, given vertical field of view.
    pub fn from_fov_y(fov_y_rad: f64, width: u32, height: u32) -> Self {
        let f = 0.5 * f64::from(height) / (0.5 * fov_y_rad).tan();
        Self {
            fx: f,
            fy: f,
            cx: 0.5 * f64::from(width) - 0.5,
            cy: 0.5 * f64::from(height) - 0.5,
            width,
            height,
        }
    }

    /// Vertical field of view (rad).
    pub fn fov_y_rad(&self) -> f64 {
        2.0 * (0.5 * f64::from(self.height) / self.fy).atan()
    }

    /// The same camera at another resolution (`s` = 0.5 halves width and height).
    pub fn scaled(&self, s: f64) -> Self {
        let w = ((f64::from(self.width) * s).round() as u32).max(1);
        let h = ((f64::from(self.height) * s).round() as u32).max(1);
        let sx = f64::from(w) / f64::from(self.width);
        let sy = f64::from(h) / f64::from(self.height);
        Self {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
            width: w,
            height: h,
        }
    }

    /// Checks that the numbers describe a real camera.
    pub fn validate(&self) -> Result<()> {
        let bad = |message: String| Err(Error::BadIntrinsics { message });
        for (name, v) in [
            ("fx", self.fx),
            ("fy", self.fy),
            ("cx", self.cx),
            ("cy", self.cy),
        ] {
            if !v.is_finite() {
                return bad(format!("{name} = {v} is not finite"));
            }
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return bad(format!(
                "fx = {} and fy = {} must be positive",
                self.fx, self.fy
            ));
        }
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return bad(format!(
                "{}x{} is not a usable image size (1..=16384 per side)",
                self.width, self.height
            ));
        }
        Ok(())
    }
}

/// A camera: intrinsics and the pose of its optical frame in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeCamera {
    /// Intrinsics.
    pub intrinsics: Intrinsics,
    /// Pose of the optical frame (x right, y down, z forward) in the world.
    pub world_from_camera: Isometry3<f64>,
}

/// A camera pose given by where it is and what it looks at.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraPose {
    /// Camera centre in the world (m).
    pub eye: [f64; 3],
    /// A point the optical axis passes through (m).
    pub target: [f64; 3],
    /// The world direction that appears up in the image.
    #[serde(default = "default_up")]
    pub up: [f64; 3],
}

fn default_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

impl CameraPose {
    /// The optical frame's pose, or an error when eye = target or up is parallel to the view.
    pub fn to_isometry(&self) -> Result<Isometry3<f64>> {
        let eye = Point3::from(self.eye);
        let forward = (Point3::from(self.target) - eye)
            .try_normalize(1e-9)
            .ok_or_else(|| Error::BadIntrinsics {
                message: "camera pose: eye and target are the same point".into(),
            })?;
        let up = Vector3::from(self.up);
        let right = forward
            .cross(&up)
            .try_normalize(1e-9)
            .ok_or_else(|| Error::BadIntrinsics {
                message: "camera pose: up is parallel to the viewing direction".into(),
            })?;
        let down = forward.cross(&right);
        let rot = Rotation3::from_basis_unchecked(&[right, down, forward]);
        Ok(Isometry3::from_parts(
            Translation3::from(eye.coords),
            UnitQuaternion::from_rotation_matrix(&rot),
        ))
    }
}

impl PinholeCamera {
    /// A camera of `intrinsics` at `eye` looking at `target` (world, m), the world's z up in
    /// its image (the scenes' convention; [`CameraPose`] for another up). Errors as
    /// [`CameraPose::to_isometry`]: eye = target, or a view straight up or down.
    pub fn looking_at(intrinsics: Intrinsics, eye: [f64; 3], target: [f64; 3]) -> Result<Self> {
        Ok(Self {
            intrinsics,
            world_from_camera: CameraPose {
                eye,
                target,
                up: default_up(),
            }
            .to_isometry()?,
        })
    }

    /// Projects a world point to `(u, v, depth)`; `None` when it is behind the camera.
    pub fn project(&self, p_world: &Point3<f64>) -> Option<(f64, f64, f64)> {
        let p = self.world_from_camera.inverse_transform_point(p_world);
        if p.z <= 1e-9 {
            return None;
        }
        let k = &self.intrinsics;
        Some((k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy, p.z))
    }

    /// Whether a projected point lies inside the image.
    pub fn in_image(&self, u: f64, v: f64) -> bool {
        let k = &self.intrinsics;
        u >= -0.5 && v >= -0.5 && u < f64::from(k.width) - 0.5 && v < f64::from(k.height) - 0.5
    }

    /// The unit ray through pixel `(u, v)`, in the world.
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        let k = &self.intrinsics;
        let d = Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0).normalize();
        self.world_from_camera.rotation * d
    }

    /// Pose of the renderer's view frame (x right, y up, z backward) in the world.
    pub fn world_from_view(&self) -> Isometry3<f64> {
        let flip = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        self.world_from_camera * flip
    }

    /// Reverse-Z, infinite-far projection from the renderer's view frame to clip space that puts
    /// every point on the same pixel as [`PinholeCamera::project`] (Bevy's depth convention:
    /// depth 1 at `near`, 0 at infinity).
    pub fn clip_from_view(&self, near: f64) -> Matrix4<f64> {
        let k = &self.intrinsics;
        let (w, h) = (f64::from(k.width), f64::from(k.height));
        // Raster coordinates have pixel centres at +0.5.
        let (cx, cy) = (k.cx + 0.5, k.cy + 0.5);
        Matrix4::new(
            2.0 * k.fx / w,
            0.0,
            1.0 - 2.0 * cx / w,
            0.0,
            0.0,
            2.0 * k.fy / h,
            2.0 * cy / h - 1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            near,
            0.0,
            0.0,
            -1.0,
            0.0,
        )
    }

    /// This camera with its pose perturbed by a rotation of `angle_rad` about `axis` (through the
    /// camera centre) and a translation `offset_m`: a calibration error.
    pub fn perturbed(&self, axis: &Vector3<f64>, angle_rad: f64, offset_m: &Vector3<f64>) -> Self {
        let axis = nalgebra::Unit::try_new(*axis, 1e-12).unwrap_or(Vector3::y_axis());
        let rot = UnitQuaternion::from_axis_angle(&axis, angle_rad);
        let mut out = *self;
        out.world_from_camera = Isometry3::from_parts(
            Translation3::from(self.world_from_camera.translation.vector + offset_m),
            rot * self.world_from_camera.rotation,
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector4;

    fn camera() -> PinholeCamera {
        let pose = CameraPose {
            eye: [1.5, 0.2, 0.8],
            target: [0.0, 0.0, 0.3],
            up: [0.0, 0.0, 1.0],
        };
        PinholeCamera {
            intrinsics: Intrinsics {
                fx: 610.0,
                fy: 605.0,
                cx: 330.2,
                cy: 236.8,
                width: 640,
                height: 480,
            },
            world_from_camera: pose.to_isometry().unwrap(),
        }
    }

    #[test]
    fn target_projects_to_principal_point_and_up_is_up() {
        let c = camera();
        let (u, v, _) = c.project(&Point3::new(0.0, 0.0, 0.3)).unwrap();
        assert!((u - 330.2).abs() < 1e-9 && (v - 236.8).abs() < 1e-9);
        let (_, v_above, _) = c.project(&Point3::new(0.0, 0.0, 0.5)).unwrap();
        assert!(v_above < v, "a higher point must be higher in the image");
        assert!(c.project(&Point3::new(3.0, 0.4, 1.3)).is_none());
    }

    #[test]
    fn clip_matrix_agrees_with_projection() {
        let c = camera();
        let view_from_world = c.world_from_view().inverse().to_homogeneous();
        let clip = c.clip_from_view(0.05) * view_from_world;
        for p in [Point3::new(0.1, -0.2, 0.4), Point3::new(-0.3, 0.25, 0.0)] {
            let (u, v, _) = c.project(&p).unwrap();
            let h = clip * Vector4::new(p.x, p.y, p.z, 1.0);
            let (nx, ny, nz) = (h.x / h.w, h.y / h.w, h.z / h.w);
            // NDC -> raster (centres at +0.5) -> pixel (centres at 0).
            let ur = (nx + 1.0) * 0.5 * 640.0 - 0.5;
            let vr = (1.0 - ny) * 0.5 * 480.0 - 0.5;
            assert!((ur - u).abs() < 1e-9 && (vr - v).abs() < 1e-9);
            assert!(nz > 0.0 && nz < 1.0);
        }
    }

    #[test]
    fn looking_at_puts_the_target_at_the_principal_point_with_z_up() {
        let k = Intrinsics::from_fov_y(1.0, 640, 480);
        let c = PinholeCamera::looking_at(k, [2.0, 1.0, 1.5], [0.0, 0.0, 0.5]).expect("pose");
        let (u, v, _) = c.project(&Point3::new(0.0, 0.0, 0.5)).expect("in front");
        assert!((u - k.cx).abs() < 1e-9 && (v - k.cy).abs() < 1e-9);
        // A point above the target is above it in the image.
        let (_, above, _) = c.project(&Point3::new(0.0, 0.0, 0.6)).expect("in front");
        assert!(above < v);
        // Straight down, z cannot be up: refused.
        assert!(PinholeCamera::looking_at(k, [0.0, 0.0, 2.0], [0.0, 0.0, 0.0]).is_err());
    }

    #[test]
    fn fov_scale_and_validation() {
        let k = Intrinsics::from_fov_y(1.0, 640, 480);
        assert!((k.fov_y_rad() - 1.0).abs() < 1e-12);
        let half = k.scaled(0.5);
        assert_eq!((half.width, half.height), (320, 240));
        assert!((half.cx - 159.5).abs() < 1e-12);
        assert!(Intrinsics { fx: f64::NAN, ..k }.validate().is_err());
        assert!(Intrinsics { width: 0, ..k }.validate().is_err());
        assert!(k.validate().is_ok());
        let bad = CameraPose {
            eye: [0.0; 3],
            target: [0.0, 0.0, 1.0],
            up: [0.0, 0.0, 1.0],
        };
        assert!(bad.to_isometry().is_err());
    }
}
