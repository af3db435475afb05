//! Diminished reality on the CPU: the robot's mask, the composite that erases it, photometric
//! compensation of the background, and the scores that say how well it worked.
//!
//! This is the reference for the GPU passes of `avatarm_erase`, which do the same arithmetic in
//! the same order (so both agree within one 8-bit level), and the code the replay scores with.
//!
//! The pipeline, per camera frame:
//! 1. the twin rendered white on black (`raw`, possibly at a lower resolution) is thresholded
//!    per channel with inclusive RGBα ranges ([`threshold_mask`]), upsampled to the frame's size
//!    by nearest texel and dilated by a square window (`dilate_px + feather_px`);
//! 2. the feathered alpha is the mean of that mask over a `(2 feather_px + 1)²` window
//!    ([`feather_alpha`]); without feathering it is the mask itself;
//! 3. the composite ([`composite`]) blends, per channel and in the camera's 8-bit encoding,
//!    `Ĩ = I + (H' − I) · α_H · a` where `H' = clamp(gain · H + offset)` is the background after
//!    photometric compensation ([`fit_photometric`]).
//!
//! Pixel maps are row-major, top row first; masks hold 0 or 1 per pixel, images RGBA8.
//!
//! Modules (their items are re-exported here): [`mask`] (threshold, dilation, feathering, the
//! links' bounding spheres), [`background`] (a background H built from the footage itself),
//! [`composite`] (the composite and the background refresh),
//! [`photometric`] (the background's gain and offset), [`scores`] (IoU, leak, overmask, PSNR),
//! [`rim`] (what the erase leaves along the outline, and the margin's band refined to the frame);
//! and, not re-exported, [`view_background`] (a background that follows a moving camera,
//! re-projected from captured views through a geometric proxy of the room).

pub mod background;
pub mod composite;
pub mod inpaint;
pub mod mask;
pub mod photometric;
pub mod rim;
pub mod scores;
pub mod view_background;

pub use background::*;
pub use composite::*;
pub use mask::*;
pub use photometric::*;
pub use rim::*;
pub use scores::*;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// An RGBA8 image borrowed from somewhere else, with its size checked.
#[derive(Debug, Clone, Copy)]
pub struct RgbaView<'a> {
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// `width * height * 4` bytes.
    pub data: &'a [u8],
}

impl<'a> RgbaView<'a> {
    /// Wraps `data`, checking that it holds `width × height` RGBA8 pixels; `what` names the image
    /// in the error.
    pub fn new(what: &str, width: u32, height: u32, data: &'a [u8]) -> Result<Self> {
        let expected = width as usize * height as usize * 4;
        if width == 0 || height == 0 || data.len() != expected {
            return Err(Error::BadImage {
                what: what.to_owned(),
                message: format!(
                    "{width}x{height} RGBA8 needs {expected} bytes, got {}",
                    data.len()
                ),
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// How the mask is made and applied. Every option can be switched off.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EraseSettings {
    /// Erase at all (off shows the live frame untouched).
    pub enabled: bool,
    /// Inclusive 8-bit ranges of R, G, B and α that count as robot in the twin's render.
    pub ranges: [[u8; 2]; 4],
    /// Grow the mask by this many pixels (square window), to cover calibration error.
    pub dilate_px: u32,
    /// Soften the mask's edge over this many pixels, outside the dilated mask.
    pub feather_px: u32,
    /// Opacity of the background panel, `α_H`.
    pub alpha_h: f32,
    /// Render the twin at this fraction of the camera's resolution (1 = same size).
    pub resolution_scale: f64,
    /// Render the twin at the joint state predicted for each frame's capture time instead of
    /// the last received one.
    pub latency_compensation: bool,
    /// Fit the background's per-channel gain and offset to each frame.
    pub photometric: bool,
    /// Blend the live frame into the background where the robot cannot be (0 = never, 1 = copy).
    pub background_refresh: f32,
    /// Draw the mask through the camera's lens distortion (each pixel reads the pinhole render
    /// where its ray lands, [`crate::vision::distortion::DistortionMap`]); off draws it as a
    /// pinhole's, to measure what ignoring the lens costs. No effect on a pinhole camera.
    pub lens_distortion: bool,
    /// For a camera that moves with a head: draw each frame's mask at the head pose of the
    /// frame's capture time, from the tracked poses' history
    /// ([`crate::vision::head::PoseHistory::at`]); off draws it at the newest tracked pose
    /// received. No effect on a fixed camera.
    pub pose_compensation: bool,
    /// Watch a fixed camera for moving (`avatarm_footage::drift`: a few frames a second, the
    /// robot's outline against the frame's edges; a move beyond the margin is fitted again):
    /// `replay --recording`, and `run`/`serve` with a real camera. No effect on the simulated
    /// room's camera (it never moves) or a camera on a head.
    pub drift_watch: bool,
}

impl Default for EraseSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            ranges: [[240, 255]; 4],
            dilate_px: 0,
            feather_px: 0,
            alpha_h: 1.0,
            resolution_scale: 1.0,
            latency_compensation: false,
            photometric: false,
            background_refresh: 0.0,
            lens_distortion: true,
            pose_compensation: true,
            drift_watch: true,
        }
    }
}

impl EraseSettings {
    /// Checks the numbers; `what` names where they came from.
    pub fn validate(&self, what: &str) -> Result<()> {
        let bad = |message: String| {
            Err(Error::BadSetting {
                what: what.to_owned(),
                message,
            })
        };
        for (c, r) in ["R", "G", "B", "alpha"].iter().zip(&self.ranges) {
            if r[0] > r[1] {
                return bad(format!("{c} range [{}, {}] is empty", r[0], r[1]));
            }
        }
        if !(0.0..=1.0).contains(&self.alpha_h) {
            return bad(format!("alpha_h = {} is outside [0, 1]", self.alpha_h));
        }
        if !(self.resolution_scale > 0.05 && self.resolution_scale <= 1.0) {
            return bad(format!(
                "resolution_scale = {} is outside (0.05, 1]",
                self.resolution_scale
            ));
        }
        if !(0.0..=1.0).contains(&self.background_refresh) {
            return bad(format!(
                "background_refresh = {} is outside [0, 1]",
                self.background_refresh
            ));
        }
        if self.dilate_px > 64 || self.feather_px > 32 {
            return bad(format!(
                "dilate_px = {} / feather_px = {} too large (at most 64 / 32)",
                self.dilate_px, self.feather_px
            ));
        }
        Ok(())
    }

    /// The square dilation radius the mask pass applies.
    pub fn mask_radius(&self) -> u32 {
        self.dilate_px + self.feather_px
    }
}

pub(crate) fn same_size(a: &RgbaView, b: &RgbaView, what: &str) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        return Err(Error::BadImage {
            what: what.to_owned(),
            message: format!(
                "is {}x{} but the live frame is {}x{}",
                b.width, b.height, a.width, a.height
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::camera::PinholeCamera;
    use nalgebra::{Isometry3, Point3};

    fn view<'a>(w: u32, h: u32, data: &'a [u8]) -> RgbaView<'a> {
        RgbaView::new("test", w, h, data).expect("size")
    }

    #[test]
    fn threshold_respects_every_range_and_scale() {
        // 4x2 raw: white, grey 239, white with alpha 100, white.
        let raw = [
            255, 255, 255, 255, 239, 239, 239, 255, 255, 255, 255, 100, 250, 245, 240, 255, //
            0, 0, 0, 255, 255, 255, 255, 255, 0, 0, 0, 255, 0, 0, 0, 255,
        ];
        let m = threshold_mask(&view(4, 2, &raw), 4, 2, &[[240, 255]; 4], 0, None).expect("sizes");
        assert_eq!(m, vec![1, 0, 0, 1, 0, 1, 0, 0]);
        let mut ranges = [[240, 255]; 4];
        ranges[3] = [0, 255];
        let m = threshold_mask(&view(4, 2, &raw), 4, 2, &ranges, 0, None).expect("sizes");
        assert_eq!(m[2], 1, "alpha range opened");
        // Half-resolution raw upsampled by nearest texel.
        let raw2 = [255u8, 255, 255, 255, 0, 0, 0, 255];
        let m = threshold_mask(&view(2, 1, &raw2), 4, 2, &[[240, 255]; 4], 0, None).expect("sizes");
        assert_eq!(m, vec![1, 1, 0, 0, 1, 1, 0, 0]);
    }

    #[test]
    fn background_difference_finds_the_robot_without_specks_or_holes() {
        let (w, h) = (20u32, 20u32);
        let background: Vec<u8> = (0..w * h).flat_map(|_| [120, 130, 140, 255]).collect();
        let mut frame = background.clone();
        let mut set = |x: u32, y: u32, px: [u8; 4]| {
            let i = ((y * w + x) * 4) as usize;
            frame[i..i + 4].copy_from_slice(&px);
        };
        // The robot: a 6x6 block, one of its pixels the room's colour.
        for y in 5..11 {
            for x in 5..11 {
                set(x, y, [200, 40, 40, 255]);
            }
        }
        set(7, 7, [120, 130, 140, 255]);
        // A speck of noise, and noise below the threshold everywhere else.
        set(15, 15, [255, 255, 255, 255]);
        set(2, 2, [140, 110, 160, 255]);
        let f = view(w, h, &frame);
        let b = view(w, h, &background);
        let m = background_difference(&f, &b, 30, 2).expect("sizes");
        let at = |x: u32, y: u32| m[(y * w + x) as usize];
        assert_eq!(at(7, 7), 1, "the hole is closed");
        assert_eq!((at(15, 15), at(2, 2)), (0, 0), "the speck is opened away");
        assert_eq!(
            m.iter().map(|&v| u32::from(v)).sum::<u32>(),
            36,
            "the block, exactly"
        );
        assert!(background_difference(&f, &view(2, 2, &background[..16]), 30, 2).is_err());
    }

    #[test]
    fn dilation_is_a_square_window() {
        let (w, h) = (7u32, 7u32);
        let mut m = vec![0u8; 49];
        m[3 * 7 + 3] = 1;
        let d = dilate(&m, w, h, 2);
        for y in 0..7i32 {
            for x in 0..7i32 {
                let inside = (x - 3).abs() <= 2 && (y - 3).abs() <= 2;
                assert_eq!(d[(y * 7 + x) as usize], u8::from(inside), "({x},{y})");
            }
        }
        // Edge pixel: the window is clipped, nothing wraps.
        let mut m = vec![0u8; 49];
        m[0] = 1;
        let d = dilate(&m, w, h, 1);
        assert_eq!(d.iter().map(|&v| u32::from(v)).sum::<u32>(), 4);
    }

    #[test]
    fn feathering_keeps_the_dilated_core_opaque() {
        let (w, h) = (21u32, 21u32);
        let mut m = vec![0u8; 441];
        m[10 * 21 + 10] = 1;
        let settings = EraseSettings {
            dilate_px: 2,
            feather_px: 3,
            ..Default::default()
        };
        let d = dilate(&m, w, h, settings.mask_radius());
        let a = feather_alpha(&d, w, h, settings.feather_px);
        for y in 8..=12 {
            for x in 8..=12 {
                assert_eq!(a[y * 21 + x], 1.0, "core pixel ({x},{y})");
            }
        }
        assert!(a[10 * 21 + 16] > 0.0 && a[10 * 21 + 16] < 1.0);
        assert_eq!(a[10 * 21 + 19], 0.0);
    }

    /// The composite's table and fast paths give exactly what the per-pixel formula gives,
    /// for every pair of 8-bit values, every kind of weight and several photometric models.
    #[test]
    fn composite_fast_paths_equal_the_formula() {
        let n = 256 * 256;
        let mut live = vec![0u8; n * 4];
        let mut bg = vec![0u8; n * 4];
        for (k, (l, b)) in live
            .chunks_exact_mut(4)
            .zip(bg.chunks_exact_mut(4))
            .enumerate()
        {
            let (i, h) = ((k / 256) as u8, (k % 256) as u8);
            l.copy_from_slice(&[i, 255 - i, i / 2, 255]);
            b.copy_from_slice(&[h, h / 3, 255 - h, 255]);
        }
        let models = [
            Photometric::default(),
            Photometric {
                gain: [1.3, 0.7, 1.05],
                offset: [-0.02, 0.05, 0.0],
            },
        ];
        for p in &models {
            for (a, alpha_h) in [
                (1.0f32, 1.0f32),
                (0.0, 1.0),
                (1.0, 0.0),
                (0.37, 1.0),
                (1.0, 0.6),
            ] {
                let alpha = vec![a; n];
                let out = composite(
                    &view(65536, 1, &live),
                    &view(65536, 1, &bg),
                    &alpha,
                    alpha_h,
                    p,
                )
                .expect("sizes");
                for (k, ((o, i), hpx)) in out
                    .chunks_exact(4)
                    .zip(live.chunks_exact(4))
                    .zip(bg.chunks_exact(4))
                    .enumerate()
                {
                    for c in 0..3 {
                        let iv = f32::from(i[c]) / 255.0;
                        let hv =
                            (p.gain[c] * (f32::from(hpx[c]) / 255.0) + p.offset[c]).clamp(0.0, 1.0);
                        let v = (iv + (hv - iv) * (a * alpha_h)).clamp(0.0, 1.0);
                        let want = (v * 255.0).round() as u8;
                        assert_eq!(
                            o[c], want,
                            "pixel {k} channel {c}, a {a}, alpha_h {alpha_h}"
                        );
                    }
                    assert_eq!(o[3], 255);
                }
            }
        }
    }

    #[test]
    fn composite_blends_in_the_camera_encoding() {
        let live = [100u8, 150, 200, 255, 10, 20, 30, 255];
        let bg = [200u8, 50, 0, 255, 0, 0, 0, 255];
        let alpha = [1.0f32, 0.0];
        let out = composite(
            &view(2, 1, &live),
            &view(2, 1, &bg),
            &alpha,
            1.0,
            &Photometric::default(),
        )
        .expect("sizes");
        assert_eq!(out, vec![200, 50, 0, 255, 10, 20, 30, 255]);
        let half = composite(
            &view(2, 1, &live),
            &view(2, 1, &bg),
            &alpha,
            0.5,
            &Photometric::default(),
        )
        .expect("sizes");
        assert_eq!(&half[..3], &[150, 100, 100]);
        let wrong = composite(
            &view(2, 1, &live),
            &view(1, 2, &bg),
            &alpha,
            1.0,
            &Photometric::default(),
        );
        assert!(wrong.expect_err("size").to_string().contains("background"));
    }

    #[test]
    fn photometric_fit_recovers_gain_and_ignores_outliers() {
        let (w, h) = (64u32, 64u32);
        let mut bg = vec![0u8; (w * h * 4) as usize];
        let mut live = bg.clone();
        let mut exclude = vec![0u8; (w * h) as usize];
        for i in 0..(w * h) as usize {
            let v = 20 + (i * 7 % 180) as u32;
            for c in 0..3 {
                bg[i * 4 + c] = v as u8;
                live[i * 4 + c] = (f64::from(v) * 1.2 + 5.0).round().min(255.0) as u8;
            }
            // A quarter of the frame is something else entirely (the robot, a hand).
            if (i % 64) < 16 {
                live[i * 4] = 250;
                live[i * 4 + 1] = 3;
                exclude[i] = u8::from(i % 2 == 0);
            }
        }
        let fit =
            fit_photometric(&view(w, h, &live), &view(w, h, &bg), Some(&exclude), 1).expect("fit");
        for c in 0..3 {
            assert!((fit.gain[c] - 1.2).abs() < 0.02, "gain {c}: {fit:?}");
            assert!(
                (fit.offset[c] - 5.0 / 255.0).abs() < 0.01,
                "offset {c}: {fit:?}"
            );
        }
        // Too few usable samples: identity, not garbage.
        let flat = vec![255u8; (w * h * 4) as usize];
        let id = fit_photometric(&view(w, h, &flat), &view(w, h, &flat), None, 1).expect("fit");
        assert_eq!(id, Photometric::default());
    }

    #[test]
    fn scores_and_psnr() {
        let truth = [1u8, 1, 1, 1, 0, 0, 0, 0];
        let erased = [1u8, 1, 1, 0, 1, 0, 0, 0];
        let s = mask_scores(&erased, &truth).expect("sizes");
        assert!((s.iou - 3.0 / 5.0).abs() < 1e-12);
        assert!((s.leak_pct - 25.0).abs() < 1e-12);
        assert!((s.overmask_pct - 25.0).abs() < 1e-12);
        let a = [10u8, 10, 10, 255, 0, 0, 0, 255];
        let b = [11u8, 9, 10, 255, 50, 50, 50, 255];
        let p = psnr_in(&a, &b, &[1, 0]).expect("region");
        let expected = 10.0 * (255.0f64 * 255.0 / (2.0 / 3.0)).log10();
        assert!((p - expected).abs() < 1e-9);
        assert_eq!(psnr_in(&a, &a, &[1, 1]), Some(100.0));
        assert_eq!(psnr_in(&a, &b, &[0, 0]), None);
    }

    #[test]
    fn refresh_moves_background_only_where_free() {
        let mut bg = vec![100u8, 100, 100, 255, 100, 100, 100, 255];
        let live = [200u8, 200, 200, 255, 200, 200, 200, 255];
        refresh_background(
            &mut bg,
            &view(2, 1, &live),
            &[1, 0],
            0.5,
            &Photometric::default(),
        );
        assert_eq!(&bg[..3], &[150, 150, 150]);
        assert_eq!(&bg[4..7], &[100, 100, 100]);
    }

    #[test]
    fn sphere_mask_covers_the_projected_robot() {
        let robot = crate::robot::kinematics::tests::sawyer();
        let (spheres, notes) = link_spheres(&robot);
        assert!(notes.is_empty());
        assert!(spheres.len() >= 7);
        let camera = PinholeCamera::looking_at(
            crate::vision::camera::Intrinsics::default(),
            [2.0, 0.0, 0.6],
            [0.3, 0.0, 0.3],
        )
        .expect("camera");
        let q = vec![0.0; robot.dof()];
        let poses = robot.forward_kinematics(&Isometry3::identity(), &q);
        let mask = sphere_mask(&camera, &poses, &spheres, 2.0);
        // Every link origin projects inside the mask.
        for pose in &poses {
            if let Some((u, v, _)) = camera.project(&Point3::from(pose.translation.vector))
                && camera.in_image(u, v)
            {
                let i = v.round() as usize * 640 + u.round() as usize;
                assert_eq!(mask[i], 1);
            }
        }
        let covered = mask.iter().filter(|&&m| m != 0).count();
        assert!(covered > 1000 && covered < 640 * 480 / 2, "{covered}");
    }

    #[test]
    fn settings_are_checked() {
        let mut s = EraseSettings::default();
        assert!(s.validate("scene").is_ok());
        s.ranges[1] = [250, 240];
        let e = s.validate("scene [erase]").expect_err("empty range");
        assert!(e.to_string().contains("G range"));
        let s = EraseSettings {
            resolution_scale: 0.0,
            ..Default::default()
        };
        assert!(s.validate("x").is_err());
    }
}
