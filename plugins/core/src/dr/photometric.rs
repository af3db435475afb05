//! Photometric compensation: the background's gain and offset fitted to each live frame.

use serde::{Deserialize, Serialize};

use super::{RgbaView, same_size};
use crate::error::{Error, Result};

/// Per-channel affine model of the background's brightness, in units of full scale:
/// `H' = gain · H + offset`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Photometric {
    /// Gain per channel (R, G, B).
    pub gain: [f32; 3],
    /// Offset per channel, in `[−1, 1]` (full scale).
    pub offset: [f32; 3],
}

impl Photometric {
    /// H' per channel (R, G, B) for each 8-bit value of H, in full scale:
    /// `clamp(gain · v / 255 + offset, 0, 1)`, the composite's arithmetic.
    pub fn lut(&self) -> [[f32; 256]; 3] {
        let mut lut = [[0f32; 256]; 3];
        for (c, l) in lut.iter_mut().enumerate() {
            for (v, hv) in l.iter_mut().enumerate() {
                *hv = (self.gain[c] * (v as f32 / 255.0) + self.offset[c]).clamp(0.0, 1.0);
            }
        }
        lut
    }
}

impl Default for Photometric {
    fn default() -> Self {
        Self {
            gain: [1.0; 3],
            offset: [0.0; 3],
        }
    }
}

/// Fits `H' = gain · H + offset` to the live frame per channel on pixels that are not excluded
/// (`exclude[i] != 0` skips pixel `i`), every `step`-th pixel in x and y. Robust: clipped pixels
/// are left out and three rounds of trimming drop residuals beyond 3 robust sigmas (from the
/// median absolute deviation), so objects that moved or a mask that missed do not pull the fit.
/// Falls back to the identity when fewer than 64 usable samples remain.
pub fn fit_photometric(
    live: &RgbaView,
    background: &RgbaView,
    exclude: Option<&[u8]>,
    step: u32,
) -> Result<Photometric> {
    same_size(live, background, "background")?;
    if let Some(e) = exclude
        && e.len() != live.pixels()
    {
        return Err(Error::BadImage {
            what: "photometric exclusion mask".into(),
            message: format!("{} pixels for a {} pixel frame", e.len(), live.pixels()),
        });
    }
    let step = step.max(1) as usize;
    let (w, h) = (live.width as usize, live.height as usize);
    let mut fit = Photometric::default();
    for c in 0..3 {
        let mut samples: Vec<(f32, f32)> = Vec::with_capacity(w * h / (step * step) + 1);
        for y in (0..h).step_by(step) {
            for x in (0..w).step_by(step) {
                let i = y * w + x;
                if exclude.is_some_and(|e| e[i] != 0) {
                    continue;
                }
                let (hv, iv) = (background.data[i * 4 + c], live.data[i * 4 + c]);
                if hv <= 2 || hv >= 253 || iv <= 2 || iv >= 253 {
                    continue;
                }
                samples.push((f32::from(hv) / 255.0, f32::from(iv) / 255.0));
            }
        }
        let Some((g, o)) = robust_line(&mut samples) else {
            continue;
        };
        fit.gain[c] = g;
        fit.offset[c] = o;
    }
    Ok(fit)
}

/// Least-squares line `y = g x + o` with three trimming rounds; `None` when degenerate.
fn robust_line(samples: &mut Vec<(f32, f32)>) -> Option<(f32, f32)> {
    let mut line = None;
    for _ in 0..4 {
        if samples.len() < 64 {
            return line;
        }
        let n = samples.len() as f64;
        let (mut sx, mut sy, mut sxx, mut sxy) = (0f64, 0f64, 0f64, 0f64);
        for &(x, y) in samples.iter() {
            let (x, y) = (f64::from(x), f64::from(y));
            sx += x;
            sy += y;
            sxx += x * x;
            sxy += x * y;
        }
        let var = sxx - sx * sx / n;
        let (g, o) = if var > 1e-6 * n {
            let g = ((sxy - sx * sy / n) / var).clamp(0.2, 5.0);
            (g, (sy - g * sx) / n)
        } else {
            // One brightness only: an offset explains it as well as a gain; keep the gain.
            (1.0, (sy - sx) / n)
        };
        line = Some((g as f32, o as f32));
        let mut residuals: Vec<f32> = samples
            .iter()
            .map(|&(x, y)| (y - (g as f32 * x + o as f32)).abs())
            .collect();
        let mid = residuals.len() / 2;
        let mad = *residuals.select_nth_unstable_by(mid, f32::total_cmp).1;
        let cut = (3.0 * 1.4826 * mad).max(2.0 / 255.0);
        let before = samples.len();
        samples.retain(|&(x, y)| (y - (g as f32 * x + o as f32)).abs() <= cut);
        if samples.len() == before {
            break;
        }
    }
    line
}
