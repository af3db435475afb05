//! Where a frame's edges put the robot's outline relative to the model's: the image shift that
//! best lays the model's outline on the frame's edges, by exhaustive chamfer matching.

use serde::{Deserialize, Serialize};

/// The best shift of a model outline over a frame's edges.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OutlineShift {
    /// The shift (px; x right, y down): the frame shows the robot's outline here relative to
    /// where the pose draws it.
    pub shift_px: [f64; 2],
    /// The mean truncated distance from the shifted outline to the nearest edge (px).
    pub cost_px: f64,
    /// The same at no shift: how well the pose itself fits this frame (px).
    pub cost_at_pose_px: f64,
    /// Outline pixels matched (after thinning to the sample budget).
    pub outline_px: usize,
}

/// The model's outline pixels (`outline`: 0/1, `w × h`) off the image's border, thinned
/// evenly to at most `max_samples`.
pub fn outline_samples(outline: &[u8], w: usize, h: usize, max_samples: usize) -> Vec<(i32, i32)> {
    let all: Vec<(i32, i32)> = outline
        .iter()
        .enumerate()
        .filter(|&(i, &o)| {
            let (x, y) = (i % w, i / w);
            o != 0 && x > 0 && y > 0 && x + 1 < w && y + 1 < h
        })
        .map(|(i, _)| ((i % w) as i32, (i / w) as i32))
        .collect();
    let step = all.len().div_ceil(max_samples.max(1)).max(1);
    all.into_iter().step_by(step).collect()
}

/// The mean over `samples` of the distance (`field`: to the nearest edge, px, `w × h`) at each
/// sample moved by `(dx, dy)`, each capped at `truncate_px` (a sample moved off the image
/// counts the cap). The chamfer distance of edge-based model matching (Barrow et al.,
/// *Parametric correspondence and chamfer matching*, 1977; Borgefors, 1988), truncated so
/// that outline the frame does not show (an occluded part, a faint edge) pulls no shift.
pub fn chamfer(
    samples: &[(i32, i32)],
    field: &[f32],
    (w, h): (usize, usize),
    (dx, dy): (i32, i32),
    truncate_px: f32,
) -> f64 {
    if samples.is_empty() {
        return f64::from(truncate_px);
    }
    let (wi, hi) = (w as i32, h as i32);
    let sum: f64 = samples
        .iter()
        .map(|&(x, y)| {
            let (sx, sy) = (x + dx, y + dy);
            let d = if sx < 0 || sy < 0 || sx >= wi || sy >= hi {
                truncate_px
            } else {
                field[sy as usize * w + sx as usize].min(truncate_px)
            };
            f64::from(d)
        })
        .sum();
    sum / samples.len() as f64
}

/// The shift within `±search_px` with the least [`chamfer`] cost: every 2 px over the whole
/// square, then every pixel within 2 px of the best (ties to the smaller shift). `None` when
/// there are no samples.
pub fn best_shift(
    samples: &[(i32, i32)],
    field: &[f32],
    size: (usize, usize),
    search_px: u32,
    truncate_px: f32,
) -> Option<OutlineShift> {
    if samples.is_empty() {
        return None;
    }
    let r = search_px as i32;
    let at = |d: (i32, i32)| chamfer(samples, field, size, d, truncate_px);
    let at_pose = at((0, 0));
    let mut best = ((0, 0), at_pose);
    let consider = |d: (i32, i32), c: f64, best: &mut ((i32, i32), f64)| {
        let norm = |d: (i32, i32)| d.0 * d.0 + d.1 * d.1;
        if c < best.1 - 1e-12 || ((c - best.1).abs() <= 1e-12 && norm(d) < norm(best.0)) {
            *best = (d, c);
        }
    };
    for dy in (-r..=r).step_by(2) {
        for dx in (-r..=r).step_by(2) {
            let c = at((dx, dy));
            consider((dx, dy), c, &mut best);
        }
    }
    let coarse = best.0;
    for dy in coarse.1 - 2..=coarse.1 + 2 {
        for dx in coarse.0 - 2..=coarse.0 + 2 {
            if dx.abs() <= r && dy.abs() <= r {
                let c = at((dx, dy));
                consider((dx, dy), c, &mut best);
            }
        }
    }
    Some(OutlineShift {
        shift_px: [f64::from(best.0.0), f64::from(best.0.1)],
        cost_px: best.1,
        cost_at_pose_px: at_pose,
        outline_px: samples.len(),
    })
}
