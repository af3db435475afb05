//! A camera bumped mid-recording, where the truth is known: a recording's frames (and reference
//! masks) from a moment on, as the camera turned by a known rotation would have taken them.

use std::path::Path;

use avatarm_record::camera::CameraCalibration;
use avatarm_record::{CompressedFrame, ImageFormat, Recording, RecordingWriter};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// `image` as a camera turned by `turn` (a rotation of the optical frame: new points are
/// `turn * old`) would have taken it: a pure rotation moves every pixel by the homography
/// `K R K⁻¹`, whatever its depth. Sampled bilinearly (nearest for a mask), the border
/// clamped (a real bumped camera sees more of the room there, not black).
pub fn turned_image(
    image: &image::RgbaImage,
    k: &Matrix3<f64>,
    turn: &UnitQuaternion<f64>,
    nearest: bool,
) -> image::RgbaImage {
    let k_inv = k.try_inverse().expect("K inverts");
    // Each new pixel's ray, turned back into the old camera.
    let back = k * turn.inverse().to_rotation_matrix().matrix() * k_inv;
    let (w, h) = image.dimensions();
    let pixel = |x: i64, y: i64| {
        *image.get_pixel(
            x.clamp(0, i64::from(w) - 1) as u32,
            y.clamp(0, i64::from(h) - 1) as u32,
        )
    };
    image::RgbaImage::from_fn(w, h, |x, y| {
        let p = back * Vector3::new(f64::from(x), f64::from(y), 1.0);
        let (u, v) = (p.x / p.z, p.y / p.z);
        if nearest {
            return pixel(u.round() as i64, v.round() as i64);
        }
        let (x0, y0) = (u.floor(), v.floor());
        let (fx, fy) = (u - x0, v - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let corners = [
            (pixel(x0, y0), (1.0 - fx) * (1.0 - fy)),
            (pixel(x0 + 1, y0), fx * (1.0 - fy)),
            (pixel(x0, y0 + 1), (1.0 - fx) * fy),
            (pixel(x0 + 1, y0 + 1), fx * fy),
        ];
        image::Rgba(std::array::from_fn(|c| {
            corners
                .iter()
                .map(|(p, wgt)| f64::from(p.0[c]) * wgt)
                .sum::<f64>()
                .round() as u8
        }))
    })
}

/// The recording `r` again at `path`, its frames (and reference masks) from `from_ns` on as
/// the camera turned by `turn` took them; the camera's pose recorded stays the one before.
pub fn write_bumped(
    r: &Recording,
    path: &Path,
    from_ns: u64,
    turn: &UnitQuaternion<f64>,
) -> CameraCalibration {
    let c = r.calibration.clone().expect("calibration");
    let k = Matrix3::from_row_slice(&c.k);
    let mut out = RecordingWriter::create(path).expect("create");
    out.calibration(0, &c).expect("calibration");
    out.camera_pose(0, &r.base_from_camera.expect("pose"))
        .expect("pose");
    for s in &r.joint_states {
        out.joint_states(s).expect("joints");
    }
    let bump = |f: &CompressedFrame, nearest: bool| -> CompressedFrame {
        if f.stamp_ns < from_ns {
            return f.clone();
        }
        let img = image::load_from_memory(&f.data)
            .expect("decodes")
            .to_rgba8();
        let mut data = Vec::new();
        turned_image(&img, &k, turn, nearest)
            .write_to(
                &mut std::io::Cursor::new(&mut data),
                image::ImageFormat::Png,
            )
            .expect("png");
        CompressedFrame {
            stamp_ns: f.stamp_ns,
            format: ImageFormat::Png,
            data,
        }
    };
    for f in &r.frames {
        out.frame(&bump(f, false)).expect("frame");
    }
    for m in &r.reference_masks {
        out.reference_mask(&bump(m, true)).expect("mask");
    }
    out.finish().expect("finish");
    c
}
