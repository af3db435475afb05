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

/// Chebyshev (8-neighbour) distance, in pixels, from every pixel to the nearest non-zero pixel
/// of `mask` (`width` × `height`, row-major): 0 on the mask, `u32::MAX` everywhere when the
/// mask is empty. A pixel at distance `d` is covered by [`crate::dr::dilate`] with radius
/// `d`. Two-pass chamfer transform with unit weights, which is exact for this metric
/// (Rosenfeld & Pfaltz, "Distance functions on digital pictures", 1968).
pub fn chebyshev_distance(mask: &[u8], width: u32, height: u32) -> Vec<u32> {
    let (w, h) = (width as usize, height as usize);
    let far = u32::MAX;
    let mut d: Vec<u32> = mask.iter().map(|&m| if m != 0 { 0 } else { far }).collect();
    if d.len() != w * h || !d.contains(&0) {
        return vec![far; mask.len()];
    }
    let step = |v: u32| v.saturating_add(1);
    for y in 0..h {
        for x in 0..w {
            let mut best = d[y * w + x];
            if x > 0 {
                best = best.min(step(d[y * w + x - 1]));
            }
            if y > 0 {
                let up = (y - 1) * w;
                best = best.min(step(d[up + x]));
                if x > 0 {
                    best = best.min(step(d[up + x - 1]));
                }
                if x + 1 < w {
                    best = best.min(step(d[up + x + 1]));
                }
            }
            d[y * w + x] = best;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let mut best = d[y * w + x];
            if x + 1 < w {
                best = best.min(step(d[y * w + x + 1]));
            }
            if y + 1 < h {
                let down = (y + 1) * w;
                best = best.min(step(d[down + x]));
                if x + 1 < w {
                    best = best.min(step(d[down + x + 1]));
                }
                if x > 0 {
                    best = best.min(step(d[down + x - 1]));
                }
            }
            d[y * w + x] = best;
        }
    }
    d
}

/// Leak (% of `truth`'s robot pixels not covered) of `mask` dilated by each radius
/// `0..=max_radius` (square dilation, as [`crate::dr::dilate`]); `None` when the sizes differ
/// or `truth` has no robot pixel.
pub fn leak_by_dilation(
    mask: &[u8],
    truth: &[u8],
    width: u32,
    height: u32,
    max_radius: u32,
) -> Option<Vec<f64>> {
    if mask.len() != truth.len() || mask.len() != (width as usize) * (height as usize) {
        return None;
    }
    let robot = truth.iter().filter(|&&t| t != 0).count();
    if robot == 0 {
        return None;
    }
    let distance = chebyshev_distance(mask, width, height);
    // uncovered[r] = robot pixels at distance > r.
    let mut at = vec![0usize; max_radius as usize + 2];
    for (&t, &d) in truth.iter().zip(&distance) {
        if t != 0 {
            at[(d.min(max_radius + 1)) as usize] += 1;
        }
    }
    let mut left = robot;
    Some(
        (0..=max_radius as usize)
            .map(|r| {
                left -= at[r];
                100.0 * left as f64 / robot as f64
            })
            .collect(),
    )
}

/// PSNR (dB) of the RGB channels of two RGBA8 images over the pixels where `region[i] != 0`,
/// capped at 100 dB; `None` when the region is empty or the sizes differ.
pub fn psnr_in(a: &[u8], b: &[u8], region: &[u8]) -> Option<f64> {
    if a.len() != b.len() || a.len() != region.len() * 4 {
        return None;
    }
    psnr_where(a, b, region.iter().map(|&r| r != 0))
}

/// PSNR (dB) of the RGB channels of two RGBA8 images over all their pixels, capped at 100 dB
/// (identical images); `None` when the sizes differ or the images are empty. The same
/// definition as [`psnr_in`], with no region.
pub fn psnr(a: &[u8], b: &[u8]) -> Option<f64> {
    if a.len() != b.len() || !a.len().is_multiple_of(4) {
        return None;
    }
    psnr_where(a, b, std::iter::repeat(true))
}

/// PSNR over the pixels `inside` says (one flag per RGBA8 pixel).
fn psnr_where(a: &[u8], b: &[u8], inside: impl Iterator<Item = bool>) -> Option<f64> {
    let (mut sum, mut n) = (0f64, 0u64);
    for ((pa, pb), inside) in a.chunks_exact(4).zip(b.chunks_exact(4)).zip(inside) {
        if !inside {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leak_by_dilation_matches_dilating() {
        let (w, h) = (40u32, 30u32);
        let mut rng = crate::rng::Rng::new(3);
        let mask: Vec<u8> = (0..w * h).map(|_| u8::from(rng.uniform() < 0.02)).collect();
        let truth: Vec<u8> = (0..w * h).map(|_| u8::from(rng.uniform() < 0.5)).collect();
        let leaks = leak_by_dilation(&mask, &truth, w, h, 12).unwrap();
        for (r, leak) in leaks.iter().enumerate() {
            let dilated = crate::dr::dilate(&mask, w, h, r as u32);
            let expected = mask_scores(&dilated, &truth).unwrap().leak_pct;
            assert!(
                (leak - expected).abs() < 1e-9,
                "radius {r}: {leak} vs {expected}"
            );
        }
        assert!(leak_by_dilation(&mask, &vec![0; mask.len()], w, h, 3).is_none());
        assert_eq!(chebyshev_distance(&[0; 4], 2, 2), vec![u32::MAX; 4]);
    }

    /// The whole-image PSNR is the region PSNR over every pixel: 20 log10(255 / 2) dB for a
    /// difference of 2 in every channel, 100 dB for identical images, none for sizes that do
    /// not match.
    #[test]
    fn psnr_is_psnr_in_over_every_pixel() {
        let mut rng = crate::rng::Rng::new(7);
        let a: Vec<u8> = (0..4 * 50).map(|_| (rng.uniform() * 255.0) as u8).collect();
        let b: Vec<u8> = a.iter().map(|&v| v.saturating_add(9)).collect();
        assert_eq!(psnr(&a, &b), psnr_in(&a, &b, &[1; 50]));
        let flat = vec![100u8; 4 * 50];
        let off: Vec<u8> = flat.iter().map(|v| v + 2).collect();
        let expected = 20.0 * (255.0f64 / 2.0).log10();
        assert!((psnr(&flat, &off).unwrap() - expected).abs() < 1e-9);
        assert_eq!(psnr(&flat, &flat), Some(100.0));
        assert_eq!(psnr(&flat, &flat[..196]), None);
        assert_eq!(psnr(&[], &[]), None);
    }
}
