//! The camera's turn fitted to frames' edges: the rotation of the optical frame that lays the
//! model's outline (drawn through a start pose) on each frame's edges.
//!
//! A turn of the camera moves each pixel by the homography `K R K⁻¹` whatever the depth seen
//! there (Hartley and Zisserman, *Multiple View Geometry*, 2nd ed., §8.4.2), so the outline is
//! drawn once, at the start pose: each of its pixels becomes a ray (through the lens's
//! inverse), and a candidate rotation R moves the rays and projects them again. The cost is
//! the chamfer distance of [`super::shift::chamfer`] on the field smoothed, read between pixels
//! (bilinear) so that the fit is sub-pixel; Nelder-Mead (`argmin`) minimises it over the rotation vector.

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use avatarm_core::vision::camera::Intrinsics;
use avatarm_core::vision::distortion::Distortion;
use nalgebra::{UnitQuaternion, Vector3};

use crate::FootageError;

/// One frame to fit: the rays of the model's outline pixels at the start pose (optical frame,
/// z = 1) and the frame's distance field to its edges (px, `width × height`), smoothed.
pub struct TurnFrame {
    /// The rays.
    pub rays: Vec<Vector3<f64>>,
    /// The field, smoothed ([`smoothed`]).
    pub field: Vec<f32>,
}

/// A distance field (`w × h`) blurred by a Gaussian of σ 1 px: the outline's pixels sit on
/// pixel centres, where a raw field's bilinear reading has a kink in every pixel, which holds
/// the search at its start; blurred, the cost is smooth (and an edge's distance still has its
/// minimum on the edge).
pub fn smoothed(field: &[f32], (w, h): (usize, usize)) -> Vec<f32> {
    let Some(image) = image::ImageBuffer::<image::Luma<f32>, Vec<f32>>::from_raw(
        w as u32,
        h as u32,
        field.to_vec(),
    ) else {
        return field.to_vec();
    };
    imageproc::filter::gaussian_blur_f32(&image, 1.0).into_raw()
}

/// The rays (optical frame, z = 1) of pixels `(x, y)` seen through `k` and `lens`; pixels
/// where the lens does not invert are left out.
pub fn rays(pixels: &[(i32, i32)], k: &Intrinsics, lens: &Distortion) -> Vec<Vector3<f64>> {
    pixels
        .iter()
        .filter_map(|&(x, y)| {
            let (xd, yd) = ((f64::from(x) - k.cx) / k.fx, (f64::from(y) - k.cy) / k.fy);
            let (xu, yu) = lens.undistort(xd, yd)?;
            Some(Vector3::new(xu, yu, 1.0))
        })
        .collect()
}

/// The mean truncated distance of the rays turned by `turn`, projected through `k` and `lens`,
/// over all frames (px); a ray turned behind the camera or off the image counts the cap.
pub fn turn_cost(
    frames: &[TurnFrame],
    turn: &UnitQuaternion<f64>,
    k: &Intrinsics,
    lens: &Distortion,
    truncate_px: f32,
) -> f64 {
    let (w, h) = (k.width as usize, k.height as usize);
    let cap = f64::from(truncate_px);
    let (mut sum, mut n) = (0.0, 0usize);
    for f in frames {
        for r in &f.rays {
            n += 1;
            let p = turn * r;
            if p.z <= 1e-6 {
                sum += cap;
                continue;
            }
            let (xd, yd) = lens.distort(p.x / p.z, p.y / p.z);
            let (u, v) = (k.fx * xd + k.cx, k.fy * yd + k.cy);
            sum += bilinear(&f.field, (w, h), u, v).map_or(cap, |d| d.min(cap));
        }
    }
    if n == 0 { cap } else { sum / n as f64 }
}

/// The field at `(u, v)` between pixel centres; `None` off the image.
fn bilinear(field: &[f32], (w, h): (usize, usize), u: f64, v: f64) -> Option<f64> {
    if !(u >= 0.0 && v >= 0.0 && u <= (w - 1) as f64 && v <= (h - 1) as f64) {
        return None;
    }
    let (x0, y0) = (u.floor() as usize, v.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (u - x0 as f64, v - y0 as f64);
    let at = |x: usize, y: usize| f64::from(field[y * w + x]);
    Some(
        at(x0, y0) * (1.0 - fx) * (1.0 - fy)
            + at(x1, y0) * fx * (1.0 - fy)
            + at(x0, y1) * (1.0 - fx) * fy
            + at(x1, y1) * fx * fy,
    )
}

/// Nelder-Mead's cost: the rotation vector (rad) to [`turn_cost`].
struct Cost<'a> {
    cost: &'a dyn Fn(&UnitQuaternion<f64>) -> f64,
}

impl CostFunction for Cost<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, p: &Self::Param) -> Result<f64, argmin::core::Error> {
        let omega = Vector3::new(p[0], p[1], p[2]);
        Ok((self.cost)(&UnitQuaternion::from_scaled_axis(omega)))
    }
}

/// The turn (a rotation of the optical frame: new points are `turn * old`) that best lays the
/// frames' rays on their edges, from no turn, within about `search_rad` of it; and its cost (px).
/// Errors: the search itself failed (named).
pub fn fit_turn(
    frames: &[TurnFrame],
    k: &Intrinsics,
    lens: &Distortion,
    truncate_px: f32,
    search_rad: f64,
) -> Result<(UnitQuaternion<f64>, f64), FootageError> {
    let cost = |turn: &UnitQuaternion<f64>| turn_cost(frames, turn, k, lens, truncate_px);
    let step = search_rad.max(1e-4);
    let mut simplex = vec![vec![0.0; 3]];
    for axis in 0..3 {
        let mut v = vec![0.0; 3];
        v[axis] = step;
        simplex.push(v);
    }
    let failed = |e: argmin::core::Error| {
        FootageError::input("drift watch", format!("the turn's fit failed: {e}"))
    };
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-7)
        .map_err(failed)?;
    let result = Executor::new(Cost { cost: &cost }, solver)
        .configure(|s| s.max_iters(300))
        .run()
        .map_err(failed)?;
    let best = result
        .state()
        .get_best_param()
        .cloned()
        .unwrap_or(vec![0.0; 3]);
    let turn = UnitQuaternion::from_scaled_axis(Vector3::new(best[0], best[1], best[2]));
    Ok((turn, cost(&turn)))
}
