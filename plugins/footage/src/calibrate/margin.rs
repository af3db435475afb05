//! The erase margin a fit calls for: how far the fitted model's outline stays from what the
//! frames show of the robot's outline, as a mask dilation in pixels, written beside the pose
//! (`erase_margin_px`) for `replay --recording` to take by default.
//!
//! Per used frame (those the pairing check found recorded with another frame's joints left
//! out: no pose fits them): the model's outline at the fitted pose (its silhouette's border pixels,
//! those on the image's border left out), and for each of its pixels the Euclidean distance to
//! the nearest observed outline pixel (the image's edges with `--edges`, else the observed
//! silhouette's border; exact distance transform, Felzenszwalb and Huttenlocher 2012). Pixels
//! farther than [`MATCH_PX`] have no counterpart (an occluded part, an edge too faint) and are
//! counted apart. The margin is `ceil(p95 + spread + 1)`: the 95th percentile of the matched
//! distances over all frames, the fit's spread over its starts projected to pixels at the
//! robot's distance, and one pixel for the edge's own width (a pixel the outline crosses
//! mixes the robot's colour with the background's).

use avatarm_core::stats::quantile;
use avatarm_core::vision::calibrate::{CalibrationResult, distance_transform, outline};
use serde::{Deserialize, Serialize};

use super::frames::UsedFrame;

/// Outline pixels farther than this from any observed outline pixel have no counterpart (px).
pub const MATCH_PX: f32 = 8.0;

/// The largest margin (px): a fit that calls for more is too uncertain to erase with; its
/// margin is reported (capped) but not written beside the pose, and a note says to fit again.
pub const MAX_MARGIN_PX: u32 = avatarm_record::camera::MAX_ERASE_MARGIN_PX as u32;

/// The largest spread over starts (px, [`EraseMargin::spread_px`]) of a fit that found the
/// pose: beyond it, answers as good as the fit's put the robot that far apart in the image, so
/// the fit has not told them apart (a wrong basin: the real Panda fitted on frames three of
/// which carry another frame's joints, 24 px) and no margin is written, as past
/// [`MAX_MARGIN_PX`]. A flat valley along the view is well within it (the simulated room
/// 0.5 deg off, fitted from edges: 2.6 px).
pub const MAX_SPREAD_PX: f64 = 16.0;

/// The margin the fit calls for, and what it is made of.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EraseMargin {
    /// The mask's dilation to erase with (px): `ceil(outline_p95_px + spread_px + 1)`, at
    /// most [`MAX_MARGIN_PX`].
    pub dilate_px: u32,
    /// The fit called for more than [`MAX_MARGIN_PX`], or its spread is past
    /// [`MAX_SPREAD_PX`]: too uncertain to erase with (not written beside the pose).
    pub capped: bool,
    /// Frames measured (the used frames not mispaired, with an observed outline).
    pub frames_measured: usize,
    /// Median distance from the model's outline to the observed one (px).
    pub outline_median_px: f64,
    /// 95th percentile of the same (px).
    pub outline_p95_px: f64,
    /// The fit's spread over its starts (rotation and translation), projected to pixels at
    /// the robot's distance from the camera.
    pub spread_px: f64,
    /// Outline pixels measured (over all used frames).
    pub outline_pixels: usize,
    /// Of the model's outline pixels, the share with no observed outline within
    /// [`MATCH_PX`] (%): occluded or too faint to see.
    pub unmatched_pct: f64,
    /// How it was found.
    pub note: String,
}

/// The margin over `frames` (each with `drawn`, its model silhouette at the fitted pose,
/// `w × h`, 0/1; those whose index is in `mispaired` left out), fitted to edges (`edges`) or
/// silhouettes. `None` when no outline pixel was matched (nothing to measure).
pub(super) fn erase_margin(
    frames: &[UsedFrame],
    drawn: &[Vec<u8>],
    mispaired: &[usize],
    (w, h): (usize, usize),
    edges: bool,
    result: &CalibrationResult,
) -> Option<EraseMargin> {
    let mut distances: Vec<f64> = Vec::new();
    let mut unmatched = 0usize;
    let mut measured = 0usize;
    for (f, model) in frames.iter().zip(drawn) {
        if mispaired.contains(&f.index) {
            continue;
        }
        let observed = if edges {
            f.silhouette.observed.clone()
        } else {
            outline(&f.silhouette.observed, w, h)
        };
        if !observed.iter().any(|&v| v != 0) {
            continue;
        }
        measured += 1;
        let field = distance_transform(&observed, w, h);
        for (i, &o) in outline(model, w, h).iter().enumerate() {
            let (x, y) = (i % w, i / w);
            if o == 0 || x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                continue;
            }
            if field[i] <= MATCH_PX {
                distances.push(f64::from(field[i]));
            } else {
                unmatched += 1;
            }
        }
    }
    distances.sort_by(f64::total_cmp);
    let p95 = quantile(&distances, 0.95)?;
    let median = quantile(&distances, 0.5)?;
    let spread_px = spread_px(result, frames, mispaired);
    let total = distances.len() + unmatched;
    let wanted = (p95 + spread_px + 1.0).ceil();
    Some(EraseMargin {
        dilate_px: wanted.min(f64::from(MAX_MARGIN_PX)) as u32,
        capped: wanted > f64::from(MAX_MARGIN_PX) || spread_px > MAX_SPREAD_PX,
        frames_measured: measured,
        outline_median_px: median,
        outline_p95_px: p95,
        spread_px,
        outline_pixels: distances.len(),
        unmatched_pct: 100.0 * unmatched as f64 / total.max(1) as f64,
        note: format!(
            "dilate_px = ceil(outline_p95_px + spread_px + 1): the 95th percentile of the distance from the fitted model's outline to the nearest observed {} pixel (those within {MATCH_PX} px), the fit's spread over its starts in the image (the 95th percentile of how far the robot's vertices move between the answer and another start that ended within 10 % of its cost), and 1 px for the edge's own width",
            if edges {
                "image edge"
            } else {
                "silhouette border"
            }
        ),
    })
}

/// The fit's spread over its starts in pixels, where the mask is drawn: for each other start
/// that ended within 10 % of the answer's cost ([`CalibrationResult::spread_deg_mm`]'s), the
/// 95th percentile over the robot's vertices in the measured frames of how far each moves in
/// the image between that start's pose and the answer's (pinhole, the fitted K); the largest
/// over those starts, 0 with none. Equally good answers apart along the view's depth, or by a
/// turn a shift undoes, move the outline little, and so add little: summing the angle's and
/// the distance's pixels (as before) counted such a pair at 20 px where its outlines were
/// within about 2, and a 1e-16 change of the fit's path moved the margin from 8 to 23 px.
fn spread_px(result: &CalibrationResult, frames: &[UsedFrame], mispaired: &[usize]) -> f64 {
    let Some(best) = result.starts.first() else {
        return 0.0;
    };
    let k = &result.intrinsics;
    let pixel = |camera_from_base: &nalgebra::Isometry3<f64>, p: &nalgebra::Point3<f64>| {
        let c = camera_from_base * p;
        (c.z > 1e-3).then(|| (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy))
    };
    let vertices: Vec<&nalgebra::Point3<f64>> = frames
        .iter()
        .filter(|f| !mispaired.contains(&f.index))
        .flat_map(|f| f.silhouette.triangles.iter().flatten())
        .collect();
    result
        .starts
        .iter()
        .skip(1)
        .filter(|s| s.cost_px <= best.cost_px * 1.1 + 1e-9)
        .filter_map(|s| {
            let mut moved: Vec<f64> = vertices
                .iter()
                .filter_map(|p| {
                    let (a, b) = (
                        pixel(&best.camera_from_base, p)?,
                        pixel(&s.camera_from_base, p)?,
                    );
                    Some((a.0 - b.0).hypot(a.1 - b.1))
                })
                .collect();
            moved.sort_by(f64::total_cmp);
            quantile(&moved, 0.95)
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use avatarm_core::vision::calibrate::{SilhouetteFrame, StartResult};
    use avatarm_core::vision::camera::Intrinsics;
    use nalgebra::Isometry3;

    use super::*;

    fn square(w: usize, h: usize, from: usize, to: usize) -> Vec<u8> {
        (0..w * h)
            .map(|i| u8::from((from..to).contains(&(i % w)) && (from..to).contains(&(i / w))))
            .collect()
    }

    /// The answer 1 m in front of the base, and another start turned `turn_deg` about the
    /// camera's y axis that ended at the same cost.
    fn result(turn_deg: f64) -> CalibrationResult {
        let best = Isometry3::translation(0.0, 0.0, 1.0);
        let other = Isometry3::rotation(nalgebra::Vector3::y() * turn_deg.to_radians()) * best;
        let start = |camera_from_base| StartResult {
            start: ([0.0; 3], [0.0; 3]),
            camera_from_base,
            cost_px: 1.0,
        };
        CalibrationResult {
            camera_from_base: best,
            intrinsics: Intrinsics {
                width: 40,
                height: 40,
                fx: 100.0,
                fy: 100.0,
                cx: 20.0,
                cy: 20.0,
            },
            cost_px: 0.0,
            rough_cost_px: 0.0,
            starts: vec![start(best), start(other)],
            spread_deg_mm: (turn_deg, 0.0),
            evaluations: 0,
            stage_seconds: [0.0; 3],
            stage_evaluations: [0; 3],
        }
    }

    /// Frame `index` seeing the robot as `observed` (0/1, 40x40); the robot a triangle at the
    /// base's origin.
    fn frame(index: usize, observed: Vec<u8>) -> UsedFrame {
        UsedFrame {
            index,
            silhouette: SilhouetteFrame {
                triangles: vec![[nalgebra::Point3::origin(); 3]],
                observed,
            },
            scored: None,
        }
    }

    #[test]
    fn a_model_two_pixels_inside_the_robot_calls_for_three() {
        let (w, h) = (40, 40);
        // The robot is the square 10..30; the model drawn 2 px smaller on every side.
        let robot = || frame(0, square(w, h, 10, 30));
        let drawn = [square(w, h, 12, 28), square(w, h, 16, 24)];
        let margin = |frames: &[UsedFrame], mispaired: &[usize], spread_deg: f64| {
            erase_margin(
                frames,
                &drawn[..frames.len()],
                mispaired,
                (w, h),
                false,
                &result(spread_deg),
            )
            .expect("measured")
        };
        let m = margin(&[robot()], &[], 0.0);
        assert!((m.outline_p95_px - 2.0).abs() < 1e-6, "{m:?}");
        assert_eq!((m.dilate_px, m.unmatched_pct), (3, 0.0));
        // Another answer as good, turned 0.5 deg: the robot 0.87 px away in the image (f =
        // 100 px, 1 m away), so 0.87 px more.
        let m = margin(&[robot()], &[], 0.5);
        assert!(
            (m.spread_px - 100.0 * 0.5f64.to_radians().tan()).abs() < 1e-9,
            "{m:?}"
        );
        assert_eq!(m.dilate_px, 4);
        // The same turn about the robot itself (a turn and the shift that undoes it, as
        // equally good answers along a flat valley are): the robot stays where it is in the
        // image, so nothing more (summing the angle's and the shift's pixels gave 2 px more).
        let mut pivoted = result(0.5);
        let pivot = nalgebra::Translation3::new(0.0, 0.0, 1.0);
        pivoted.starts[1].camera_from_base = pivot
            * Isometry3::rotation(nalgebra::Vector3::y() * 0.5f64.to_radians())
            * pivot.inverse()
            * pivoted.camera_from_base;
        let m =
            erase_margin(&[robot()], &drawn[..1], &[], (w, h), false, &pivoted).expect("measured");
        assert!(m.spread_px < 1e-9 && m.dilate_px == 3, "{m:?}");
        // Equally good answers 20 px apart (a wrong basin): not written, whatever the sum.
        let m = margin(&[robot()], &[], 11.3);
        assert!(
            m.spread_px > MAX_SPREAD_PX && m.dilate_px < MAX_MARGIN_PX,
            "{m:?}"
        );
        assert!(m.capped, "{m:?}");
        // A frame recorded with another frame's joints (drawn 6 px inside) is left out.
        let m = margin(&[robot(), frame(1, square(w, h, 10, 30))], &[1], 0.0);
        assert_eq!((m.dilate_px, m.frames_measured), (3, 1));
        // A spread beyond reason is capped and said.
        let m = margin(&[robot()], &[], 45.0);
        assert_eq!((m.dilate_px, m.capped), (MAX_MARGIN_PX, true));
        // Nothing observed: nothing to measure.
        let empty = [frame(0, vec![0; w * h])];
        assert!(erase_margin(&empty, &drawn[..1], &[], (w, h), true, &result(0.0)).is_none());
    }
}
