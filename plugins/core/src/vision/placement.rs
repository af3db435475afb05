//! Where the object's digital twin goes in the interaction layer, so that it covers the real
//! object's pixels on the video panel while staying in front of the panel.
//!
//! **The paper's equations.** The twin's centre `o_v = [x_v, y_v, z_v]` and scale `s_v` satisfy
//! `[x', y', z', s']ᵀ = P [x_v, y_v, z_v, s_v]ᵀ` with
//! `P = [[Y/X·φ, 0, 0, 0], [0, φ, 0, 0], [0, 0, (far+near)/(near−far), 2·far·near/(near−far)],
//! [0, 0, −1, 0]]`: the OpenGL perspective matrix of the interaction camera, `φ = φ_v,i` being
//! `cot(fov_y / 2)`, `X × Y` the panel's pixel size. [`PaperProjection`] is that matrix.
//! The paper's table swaps the two plane labels: it calls `far` = 95 cm the "camera-nearest
//! visible plane" and `near` = 75 cm the "farthest"; the matrix needs `near < far`, so near is
//! 75 cm and far 95 cm, which is what [`PaperProjection::paper_table`] uses.
//!
//! **Generalised to any pinhole camera.** The video panel spans the real camera's frustum at
//! its distance ([`panel_corners`]), so from the interaction camera's centre a point seen by the
//! real camera at normalised coordinates `(x/z, y/z)` appears at the same normalised coordinates
//! (whatever the interaction camera's own focal length). The scaling of the whole object about
//! the centre of projection by `s = z_v / z_r` therefore projects onto exactly the same pixels:
//! every point `p` of the real object (real camera frame) goes to `s · p` (interaction camera
//! frame), orientation unchanged ([`place_twin`]). The paper's `s_v` is this `s`; its scaling
//! factor `k = φ_r / φ_v,i` on the motion is needed when the panel is not drawn that way.

use nalgebra::{Isometry3, Matrix4, Point3, Translation3, Vector4};

use crate::error::{Error, Result};
use crate::vision::camera::{Intrinsics, PinholeCamera};

/// The paper's perspective matrix of the interaction camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperProjection {
    /// `φ_v,i = cot(fov_y / 2)`.
    pub phi: f64,
    /// Panel width over height, `X / Y`.
    pub aspect: f64,
    /// Distance to the nearest visible plane (m).
    pub near: f64,
    /// Distance to the farthest visible plane (m).
    pub far: f64,
}

impl PaperProjection {
    /// The values of the paper's Table I, with near and far in the order the matrix needs
    /// (near = 0.75 m, far = 0.95 m), for an `X × Y` panel of `aspect` and a 55° field of view.
    pub fn paper_table(aspect: f64) -> Self {
        Self {
            phi: 1.0 / (55f64.to_radians() / 2.0).tan(),
            aspect,
            near: 0.75,
            far: 0.95,
        }
    }

    /// The interaction camera matching pinhole intrinsics (square pixels, centred principal
    /// point assumed, as the paper does).
    pub fn for_intrinsics(k: &Intrinsics, near: f64, far: f64) -> Self {
        Self {
            phi: 2.0 * k.fy / f64::from(k.height),
            aspect: f64::from(k.width) / f64::from(k.height),
            near,
            far,
        }
    }

    /// The 4×4 matrix of the paper's equation.
    pub fn matrix(&self) -> Matrix4<f64> {
        let (n, f) = (self.near, self.far);
        Matrix4::new(
            self.phi / self.aspect,
            0.0,
            0.0,
            0.0,
            0.0,
            self.phi,
            0.0,
            0.0,
            0.0,
            0.0,
            (f + n) / (n - f),
            2.0 * f * n / (n - f),
            0.0,
            0.0,
            -1.0,
            0.0,
        )
    }

    /// Normalised device coordinates of a point in the OpenGL view frame (x right, y up,
    /// looking along −z); `None` behind the camera.
    pub fn ndc(&self, p_view: &Point3<f64>) -> Option<[f64; 3]> {
        let c = self.matrix() * Vector4::new(p_view.x, p_view.y, p_view.z, 1.0);
        (c.w > 1e-12).then(|| [c.x / c.w, c.y / c.w, c.z / c.w])
    }
}

/// Where the twin goes: its pose in the interaction camera's optical frame (x right, y down,
/// z forward) and its uniform scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwinPlacement {
    /// Pose of the twin in the interaction camera's optical frame.
    pub camera_from_twin: Isometry3<f64>,
    /// Uniform scale of the twin relative to the real object.
    pub scale: f64,
}

/// Places the twin of an object whose pose the real camera sees at `world_from_object` so that
/// its origin is at depth `depth_v` in front of the interaction camera. Errors when the object is
/// behind the real camera or `depth_v` is not positive.
pub fn place_twin(
    real: &PinholeCamera,
    world_from_object: &Isometry3<f64>,
    depth_v: f64,
) -> Result<TwinPlacement> {
    if depth_v.is_nan() || depth_v <= 0.0 {
        return Err(Error::BadSetting {
            what: "object twin placement".into(),
            message: format!("twin depth {depth_v} m must be positive"),
        });
    }
    let camera_from_object = real.world_from_camera.inverse() * world_from_object;
    let z = camera_from_object.translation.z;
    if z.is_nan() || z <= 1e-6 {
        return Err(Error::BadSetting {
            what: "object twin placement".into(),
            message: format!("the object is behind the real camera (depth {z:.3} m)"),
        });
    }
    let scale = depth_v / z;
    Ok(TwinPlacement {
        camera_from_twin: Isometry3::from_parts(
            Translation3::from(camera_from_object.translation.vector * scale),
            camera_from_object.rotation,
        ),
        scale,
    })
}

/// Corners of a video panel that spans the camera's frustum at `distance` (m), in the
/// camera's optical frame: top-left, top-right, bottom-right, bottom-left (of the image).
pub fn panel_corners(k: &Intrinsics, distance: f64) -> [Point3<f64>; 4] {
    let (w, h) = (f64::from(k.width), f64::from(k.height));
    let at = |u: f64, v: f64| {
        Point3::new(
            (u - k.cx) / k.fx * distance,
            (v - k.cy) / k.fy * distance,
            distance,
        )
    };
    [
        at(-0.5, -0.5),
        at(w - 0.5, -0.5),
        at(w - 0.5, h - 0.5),
        at(-0.5, h - 0.5),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    fn camera(eye: [f64; 3], target: [f64; 3], k: Intrinsics) -> PinholeCamera {
        PinholeCamera::looking_at(k, eye, target).expect("pose")
    }

    fn bbox(points: impl Iterator<Item = (f64, f64)>) -> [f64; 4] {
        points.fold(
            [f64::MAX, f64::MAX, f64::MIN, f64::MIN],
            |[a, b, c, d], (u, v)| [a.min(u), b.min(v), c.max(u), d.max(v)],
        )
    }

    #[test]
    fn twin_covers_the_real_objects_pixels() {
        let k = Intrinsics {
            fx: 461.0,
            fy: 455.0,
            cx: 322.0,
            cy: 236.5,
            width: 640,
            height: 480,
        };
        let real = camera([1.85, 0.0, 1.3], [0.4, 0.0, 0.95], k);
        // The interaction camera is elsewhere in its own world (in front of the user).
        let interaction = camera([0.0, -3.0, 1.6], [0.2, 0.0, 1.5], k);
        let object = Isometry3::from_parts(
            Translation3::new(0.62, -0.16, 0.8),
            UnitQuaternion::from_euler_angles(0.2, -0.1, 0.7),
        );
        // Corners of a 7 x 7 x 25 cm box (a bottle's bounds).
        let corners: Vec<Point3<f64>> = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 == 0 { -0.035 } else { 0.035 },
                    if i & 2 == 0 { -0.035 } else { 0.035 },
                    if i & 4 == 0 { 0.0 } else { 0.25 },
                )
            })
            .collect();
        let real_px = bbox(corners.iter().map(|c| {
            let (u, v, _) = real.project(&(object * c)).expect("in front");
            (u, v)
        }));
        for depth in [0.3, 0.6, 0.9] {
            let place = place_twin(&real, &object, depth).expect("placement");
            let world_from_twin = interaction.world_from_camera * place.camera_from_twin;
            let twin_px = bbox(corners.iter().map(|c| {
                let p = world_from_twin * Point3::from(c.coords * place.scale);
                let (u, v, _) = interaction.project(&p).expect("in front");
                (u, v)
            }));
            let centre = |b: &[f64; 4]| ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
            let (a, b) = (centre(&real_px), centre(&twin_px));
            assert!((a.0 - b.0).hypot(a.1 - b.1) < 2.0, "centre {a:?} vs {b:?}");
            for (lo, hi) in [(0, 2), (1, 3)] {
                let (sr, st) = (real_px[hi] - real_px[lo], twin_px[hi] - twin_px[lo]);
                assert!((st / sr - 1.0).abs() < 0.02, "size {sr} vs {st}");
            }
        }
    }

    #[test]
    fn the_papers_matrix_agrees_with_the_pinhole_model() {
        let k = Intrinsics::from_fov_y(55f64.to_radians(), 640, 480);
        let p = PaperProjection::for_intrinsics(&k, 0.75, 0.95);
        let table = PaperProjection::paper_table(640.0 / 480.0);
        assert!((p.phi - table.phi).abs() < 1e-9);
        assert!(p.near < p.far, "near and far in the matrix's order");
        // A point in the optical frame (y down, z forward) and in OpenGL's (y up, z back).
        for optical in [
            Point3::new(0.1, -0.05, 0.8),
            Point3::new(-0.2, 0.15, 0.9),
            Point3::new(0.0, 0.0, 0.75),
        ] {
            let view = Point3::new(optical.x, -optical.y, -optical.z);
            let ndc = p.ndc(&view).expect("in front");
            let u = (ndc[0] + 1.0) / 2.0 * 640.0 - 0.5;
            let v = (1.0 - ndc[1]) / 2.0 * 480.0 - 0.5;
            let (pu, pv) = (
                k.fx * optical.x / optical.z + k.cx,
                k.fy * optical.y / optical.z + k.cy,
            );
            assert!((u - pu).abs() < 1e-9 && (v - pv).abs() < 1e-9);
            // The depth range maps near -> -1 and far -> +1.
            assert!((-1.0..=1.0).contains(&ndc[2]) || optical.z < 0.75);
        }
        let near = p.ndc(&Point3::new(0.0, 0.0, -0.75)).expect("near");
        let far = p.ndc(&Point3::new(0.0, 0.0, -0.95)).expect("far");
        assert!((near[2] + 1.0).abs() < 1e-9 && (far[2] - 1.0).abs() < 1e-9);
    }

    #[test]
    fn panel_spans_the_frustum_and_bad_input_is_refused() {
        let k = Intrinsics::default();
        let cam = PinholeCamera {
            intrinsics: k,
            world_from_camera: Isometry3::identity(),
        };
        let corners = panel_corners(&k, 2.0);
        let (u, v, z) = cam.project(&corners[2]).expect("in front");
        assert!((u - 639.5).abs() < 1e-9 && (v - 479.5).abs() < 1e-9 && (z - 2.0).abs() < 1e-12);
        let behind = Isometry3::translation(0.0, 0.0, -1.0);
        let e = place_twin(&cam, &behind, 0.5).expect_err("behind");
        assert!(e.to_string().contains("behind the real camera"));
        let ahead =
            Isometry3::from_parts(Translation3::from(Vector3::z()), UnitQuaternion::identity());
        assert!(place_twin(&cam, &ahead, f64::NAN).is_err());
    }
}
