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

use nalgebra::{Isometry3, Point3};
use serde::{Deserialize, Serialize};

use crate::camera::PinholeCamera;
use crate::error::{Error, Result};
use crate::robot::{RobotModel, Shape};

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

/// Whether an RGBA pixel lies inside every channel's range.
pub fn in_ranges(px: &[u8], ranges: &[[u8; 2]; 4]) -> bool {
    px.iter()
        .zip(ranges)
        .all(|(&v, r)| (r[0]..=r[1]).contains(&v))
}

/// The raw texel a full-resolution pixel reads: nearest, by integer arithmetic (the GPU pass
/// computes the same).
pub fn raw_index(x: u32, full: u32, raw: u32) -> u32 {
    (((2 * u64::from(x) + 1) * u64::from(raw)) / (2 * u64::from(full))) as u32
}

/// Thresholds the twin's render `raw` into a `width × height` mask (0/1), dilated by a square
/// window of radius `radius` (pixels outside the image repeat the edge).
pub fn threshold_mask(
    raw: &RgbaView,
    width: u32,
    height: u32,
    ranges: &[[u8; 2]; 4],
    radius: u32,
) -> Vec<u8> {
    let (w, h) = (width as usize, height as usize);
    let xs: Vec<usize> = (0..width)
        .map(|x| raw_index(x, width, raw.width) as usize)
        .collect();
    let mut mask = vec![0u8; w * h];
    for y in 0..height {
        let ry = raw_index(y, height, raw.height) as usize;
        let row = &raw.data[ry * raw.width as usize * 4..][..raw.width as usize * 4];
        let out = &mut mask[y as usize * w..][..w];
        for (o, &rx) in out.iter_mut().zip(&xs) {
            *o = u8::from(in_ranges(&row[rx * 4..rx * 4 + 4], ranges));
        }
    }
    dilate(&mask, width, height, radius)
}

/// Square (Chebyshev) dilation of a 0/1 mask, separable; the edge repeats.
pub fn dilate(mask: &[u8], width: u32, height: u32, radius: u32) -> Vec<u8> {
    if radius == 0 {
        return mask.to_vec();
    }
    let (w, h, r) = (width as usize, height as usize, radius as usize);
    let mut rows = vec![0u8; w * h];
    for y in 0..h {
        let src = &mask[y * w..][..w];
        let dst = &mut rows[y * w..][..w];
        window_max(src, dst, r);
    }
    let mut out = vec![0u8; w * h];
    let mut col = vec![0u8; h];
    let mut col_out = vec![0u8; h];
    for x in 0..w {
        for y in 0..h {
            col[y] = rows[y * w + x];
        }
        window_max(&col, &mut col_out, r);
        for y in 0..h {
            out[y * w + x] = col_out[y];
        }
    }
    out
}

/// `dst[i] = max(src[i - r ..= i + r])` (clamped), by a running count of ones.
fn window_max(src: &[u8], dst: &mut [u8], r: usize) {
    let n = src.len();
    let mut count = 0usize;
    for &v in &src[..r.min(n - 1) + 1] {
        count += usize::from(v);
    }
    for i in 0..n {
        dst[i] = u8::from(count > 0);
        let add = i + r + 1;
        if add < n {
            count += usize::from(src[add]);
        }
        if i >= r {
            count -= usize::from(src[i - r]);
        }
    }
}

/// Feathered alpha in `[0, 1]`: the mean of `mask` over a square window of radius `feather`
/// (edge repeats). With `feather = 0` it is the mask itself.
pub fn feather_alpha(mask: &[u8], width: u32, height: u32, feather: u32) -> Vec<f32> {
    if feather == 0 {
        return mask.iter().map(|&m| f32::from(m)).collect();
    }
    let (w, h, f) = (width as usize, height as usize, feather as i64);
    let clamp = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
    // Horizontal window sums, then vertical: integer counts, exact.
    let mut rows = vec![0u32; w * h];
    for y in 0..h {
        for x in 0..w {
            rows[y * w + x] = (-f..=f)
                .map(|d| u32::from(mask[y * w + clamp(x as i64 + d, w)]))
                .sum();
        }
    }
    let area = ((2 * f + 1) * (2 * f + 1)) as f32;
    let mut out = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let sum: u32 = (-f..=f).map(|d| rows[clamp(y as i64 + d, h) * w + x]).sum();
            out[y * w + x] = sum as f32 / area;
        }
    }
    out
}

/// Per-channel affine model of the background's brightness, in units of full scale:
/// `H' = gain · H + offset`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Photometric {
    /// Gain per channel (R, G, B).
    pub gain: [f32; 3],
    /// Offset per channel, in `[−1, 1]` (full scale).
    pub offset: [f32; 3],
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

fn same_size(a: &RgbaView, b: &RgbaView, what: &str) -> Result<()> {
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
    let mut h_lut = [[0f32; 256]; 3];
    for (c, lut) in h_lut.iter_mut().enumerate() {
        for (v, hv) in lut.iter_mut().enumerate() {
            *hv =
                (photometric.gain[c] * (v as f32 / 255.0) + photometric.offset[c]).clamp(0.0, 1.0);
        }
    }
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
    );
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

/// A bounding sphere of a link's visual geometry, in the link frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkSphere {
    /// Index of the link in the model.
    pub link: usize,
    /// Centre in the link frame.
    pub centre: Point3<f64>,
    /// Radius (m).
    pub radius: f64,
}

/// Bounding spheres of every visual of the robot. Meshes use the bounds of the loaded file;
/// a mesh that cannot be loaded gets a 0.2 m sphere at its origin (with a note in the result).
pub fn link_spheres(model: &RobotModel) -> (Vec<LinkSphere>, Vec<String>) {
    let mut out = Vec::new();
    let mut notes = Vec::new();
    for (li, link) in model.links.iter().enumerate() {
        for g in &link.visuals {
            let o = g.origin.translation.vector;
            let (centre, radius) = match &g.shape {
                Shape::Box { size } => (o, 0.5 * size.norm()),
                Shape::Cylinder { radius, length } => (o, radius.hypot(0.5 * length)),
                Shape::Capsule { radius, length } => (o, radius + 0.5 * length),
                Shape::Sphere { radius } => (o, *radius),
                Shape::Mesh { path, scale, .. } => {
                    match crate::mesh::load_mesh(path, scale)
                        .ok()
                        .and_then(|m| m.bounds())
                    {
                        Some((lo, hi)) => {
                            let lo = nalgebra::Vector3::new(lo[0], lo[1], lo[2]).cast::<f64>();
                            let hi = nalgebra::Vector3::new(hi[0], hi[1], hi[2]).cast::<f64>();
                            let centre = g.origin * Point3::from(0.5 * (lo + hi));
                            (centre.coords, 0.5 * (hi - lo).norm())
                        }
                        None => {
                            notes.push(format!(
                                "link '{}': mesh {} has no bounds; using a 0.2 m sphere",
                                link.name,
                                path.display()
                            ));
                            (o, 0.2)
                        }
                    }
                }
            };
            out.push(LinkSphere {
                link: li,
                centre: Point3::from(centre),
                radius,
            });
        }
    }
    (out, notes)
}

/// A conservative robot region for photometric fitting and background refresh: every link's
/// bounding sphere projected into the camera, grown by `margin_px`. Spheres behind the camera
/// are skipped. Returns a 0/1 map of `width × height` of the camera.
pub fn sphere_mask(
    camera: &PinholeCamera,
    link_poses: &[Isometry3<f64>],
    spheres: &[LinkSphere],
    margin_px: f64,
) -> Vec<u8> {
    let k = &camera.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let mut mask = vec![0u8; w * h];
    for s in spheres {
        let Some(pose) = link_poses.get(s.link) else {
            continue;
        };
        let Some((u, v, z)) = camera.project(&(pose * s.centre)) else {
            continue;
        };
        if z <= s.radius {
            // The camera is inside the sphere: everything may be robot.
            mask.fill(1);
            return mask;
        }
        // The silhouette of a sphere is within the circle of its tangent cone's radius.
        let r = k.fx.max(k.fy) * s.radius / (z * z - s.radius * s.radius).sqrt() + margin_px;
        let (y0, y1) = ((v - r).floor().max(0.0), (v + r).ceil().min(h as f64 - 1.0));
        let mut y = y0;
        while y <= y1 {
            let dy = y - v;
            let half = (r * r - dy * dy).max(0.0).sqrt();
            let (x0, x1) = (
                (u - half).floor().max(0.0),
                (u + half).ceil().min(w as f64 - 1.0),
            );
            if x0 <= x1 {
                let row = y as usize * w;
                mask[row + x0 as usize..=row + x1 as usize].fill(1);
            }
            y += 1.0;
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let m = threshold_mask(&view(4, 2, &raw), 4, 2, &[[240, 255]; 4], 0);
        assert_eq!(m, vec![1, 0, 0, 1, 0, 1, 0, 0]);
        let mut ranges = [[240, 255]; 4];
        ranges[3] = [0, 255];
        let m = threshold_mask(&view(4, 2, &raw), 4, 2, &ranges, 0);
        assert_eq!(m[2], 1, "alpha range opened");
        // Half-resolution raw upsampled by nearest texel.
        let raw2 = [255u8, 255, 255, 255, 0, 0, 0, 255];
        let m = threshold_mask(&view(2, 1, &raw2), 4, 2, &[[240, 255]; 4], 0);
        assert_eq!(m, vec![1, 1, 0, 0, 1, 1, 0, 0]);
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
        let robot = crate::kinematics::tests::sawyer();
        let (spheres, notes) = link_spheres(&robot);
        assert!(notes.is_empty());
        assert!(spheres.len() >= 7);
        let camera = PinholeCamera {
            intrinsics: crate::camera::Intrinsics::default(),
            world_from_camera: crate::camera::CameraPose {
                eye: [2.0, 0.0, 0.6],
                target: [0.3, 0.0, 0.3],
                up: [0.0, 0.0, 1.0],
            }
            .to_isometry()
            .expect("camera"),
        };
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
