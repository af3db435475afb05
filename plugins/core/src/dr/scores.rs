//! Scores: the mask against the true silhouette (IoU, leak, overmask) and PSNR over a region.

use serde::Serialize;

/// How a mask compares with the true robot silhouette.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MaskScores {
    /// Intersection over union.
    pub iou: f64,
    /// True robot pixels not erased, % of robot pixels.
    pub leak_pct: f64,
    /// Erased pixels that are not robot, % of robot pixels.
    pub overmask_pct: f64,
    /// Robot pixels in the truth.
    pub robot_px: u64,
}

/// Scores `erased` (non-zero = erased) against `truth` (non-zero = robot); `None` when the
/// sizes differ. With no robot pixels the IoU is 1 if nothing was erased, else 0, and the
/// percentages are 0 and the number of erased pixels.
pub fn mask_scores(erased: &[u8], truth: &[u8]) -> Option<MaskScores> {
    if erased.len() != truth.len() {
        return None;
    }
    let (mut both, mut only_truth, mut only_erased) = (0u64, 0u64, 0u64);
    for (&e, &t) in erased.iter().zip(truth) {
        match (e != 0, t != 0) {
            (true, true) => both += 1,
            (false, true) => only_truth += 1,
            (true, false) => only_erased += 1,
            (false, false) => {}
        }
    }
    let robot = both + only_truth;
    let union = robot + only_erased;
    let pct = |n: u64| {
        if robot == 0 {
            n as f64
        } else {
            100.0 * n as f64 / robot as f64
        }
    };
    Some(MaskScores {
        iou: if union == 0 {
            1.0
        } else {
            both as f64 / union as f64
        },
        leak_pct: pct(only_truth),
        overmask_pct: pct(only_erased),
        robot_px: robot,
    })
}

/// PSNR (dB) of the RGB channels of two RGBA8 images over the pixels where `region[i] != 0`,
/// capped at 100 dB; `None` when the region is empty or the sizes differ.
pub fn psnr_in(a: &[u8], b: &[u8], region: &[u8]) -> Option<f64> {
    if a.len() != b.len() || a.len() != region.len() * 4 {
        return None;
    }
    let (mut sum, mut n) = (0f64, 0u64);
    for ((pa, pb), &r) in a.chunks_exact(4).zip(b.chunks_exact(4)).zip(region) {
        if r == 0 {
            continue;
        }
        for c in 0..3 {
            let d = f64::from(pa[c]) - f64::from(pb[c]);
            sum += d * d;
        }
        n += 3;
    }
    if n == 0 {
        return None;
    }
    let mse = sum / n as f64;
    Some(if mse <= 0.0 {
        100.0
    } else {
        (10.0 * (255.0f64 * 255.0 / mse).log10()).min(100.0)
    })
}
