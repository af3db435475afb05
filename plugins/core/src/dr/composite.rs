//! The composite that erases the robot (the paper's interaction layer, on the CPU) and the
//! background refresh from pixels the robot cannot cover.

use super::{EraseSettings, Photometric, RgbaView, feather_alpha, same_size, threshold_mask};
use crate::error::{Error, Result};

/// The composite `Ĩ = I + (H' − I) · α_H · a` per channel, RGBA8 out with α = 255.
pub fn composite(
    live: &RgbaView,
    background: &RgbaView,
    alpha: &[f32],
    alpha_h: f32,
    photometric: &Photometric,
) -> Result<Vec<u8>> {
    same_size(live, background, "background")?;
    if alpha.len() != live.pixels() {
        return Err(Error::BadImage {
            what: "mask alpha".into(),
            message: format!("{} pixels for a {} pixel frame", alpha.len(), live.pixels()),
        });
    }
    // H' per channel and 8-bit value, computed once. Pixels outside the mask (t = 0) take the
    // formula's exact value (the live pixel) without it; the others follow the formula in the
    // order the GPU pass evaluates it, so both round alike.
    let h_lut = photometric.lut();
    let mut out = vec![0u8; live.data.len()];
    for (((o, i), hpx), &a) in out
        .chunks_exact_mut(4)
        .zip(live.data.chunks_exact(4))
        .zip(background.data.chunks_exact(4))
        .zip(alpha)
    {
        let t = a * alpha_h;
        if t == 0.0 {
            o.copy_from_slice(&[i[0], i[1], i[2], 255]);
            continue;
        }
        for c in 0..3 {
            let iv = f32::from(i[c]) / 255.0;
            let hv = h_lut[c][usize::from(hpx[c])];
            let v = (iv + (hv - iv) * t).clamp(0.0, 1.0);
            o[c] = (v * 255.0).round() as u8;
        }
        o[3] = 255;
    }
    Ok(out)
}

/// Threshold, feather and composite in one call, as the GPU passes do.
pub fn erase_frame(
    live: &RgbaView,
    background: &RgbaView,
    raw_twin: &RgbaView,
    settings: &EraseSettings,
    photometric: &Photometric,
) -> Result<Vec<u8>> {
    let mask = threshold_mask(
        raw_twin,
        live.width,
        live.height,
        &settings.ranges,
        settings.mask_radius(),
        None,
    )?;
    let alpha = feather_alpha(&mask, live.width, live.height, settings.feather_px);
    let alpha_h = if settings.enabled {
        settings.alpha_h
    } else {
        0.0
    };
    composite(live, background, &alpha, alpha_h, photometric)
}

/// Blends the live frame into the background where `robot_free[i] != 0`, with weight `rate`,
/// after undoing the photometric model (so the background keeps its own exposure).
pub fn refresh_background(
    background: &mut [u8],
    live: &RgbaView,
    robot_free: &[u8],
    rate: f32,
    photometric: &Photometric,
) {
    for ((b, i), &free) in background
        .chunks_exact_mut(4)
        .zip(live.data.chunks_exact(4))
        .zip(robot_free)
    {
        if free == 0 {
            continue;
        }
        for c in 0..3 {
            let g = photometric.gain[c].max(1e-3);
            let seen = ((f32::from(i[c]) / 255.0 - photometric.offset[c]) / g).clamp(0.0, 1.0);
            let old = f32::from(b[c]) / 255.0;
            b[c] = ((old + (seen - old) * rate) * 255.0).round() as u8;
        }
    }
}
