//! A background H built from the footage itself, for recordings with no empty-room photograph.
//!
//! Each frame adds its pixels that the (dilated) robot mask does not cover; the estimate of a
//! pixel is the per-channel median of the last `keep` samples it got (robust to a passer-by or
//! a missed sliver of the robot in a few frames), with the number of samples it got in all.
//! Pixels no frame ever uncovered (where the robot stood the whole time) are inpainted
//! ([`HoleFill`]): by default with Telea's method ([`super::inpaint`]), which carries the
//! colours and the isophotes arriving at the hole's rim inwards; or, for comparison, ring by
//! ring (each pixel the mean of its 8-neighbours already known: a flat smear). Filled pixels
//! are marked: they are a guess, and the replay reports how much of the robot's region had to
//! be guessed.

use crate::dr::RgbaView;
use crate::error::{Error, Result};

/// How the pixels no frame showed are filled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HoleFill {
    /// Telea's fast-marching inpainting with neighbourhoods of this radius (px).
    Telea {
        /// Neighbourhood radius (px).
        radius: f32,
    },
    /// Ring by ring inwards, each pixel the rounded mean of its 8-neighbours already known.
    Rings,
}

impl Default for HoleFill {
    /// Telea's method with a 5 px radius.
    fn default() -> Self {
        Self::Telea { radius: 5.0 }
    }
}

/// Accumulates uncovered pixels of frames of one size.
#[derive(Debug, Clone)]
pub struct FootageBackground {
    width: u32,
    height: u32,
    keep: usize,
    /// `keep` RGB samples per pixel, a ring per pixel.
    samples: Vec<[u8; 3]>,
    /// Samples each pixel got in all.
    counts: Vec<u32>,
    frames: u64,
}

/// The background H out of [`FootageBackground`].
#[derive(Debug, Clone, PartialEq)]
pub struct BackgroundEstimate {
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// H, RGBA8 (opaque).
    pub rgba: Vec<u8>,
    /// 1 where some frame showed the pixel, 0 where it was filled from its surroundings.
    pub seen: Vec<u8>,
    /// Samples per pixel.
    pub counts: Vec<u32>,
}

impl BackgroundEstimate {
    /// Of the pixels of `region` (0/1 per pixel, e.g. the robot's), the fraction whose
    /// background was seen (not filled); `None` for an empty region or a size mismatch.
    pub fn seen_fraction(&self, region: &[u8]) -> Option<f64> {
        if region.len() != self.seen.len() {
            return None;
        }
        let (mut inside, mut seen) = (0u64, 0u64);
        for (&r, &s) in region.iter().zip(&self.seen) {
            if r > 0 {
                inside += 1;
                seen += u64::from(s > 0);
            }
        }
        (inside > 0).then(|| seen as f64 / inside as f64)
    }

    /// The share of all pixels that had to be filled.
    pub fn filled_fraction(&self) -> f64 {
        let filled = self.seen.iter().filter(|&&s| s == 0).count();
        filled as f64 / self.seen.len().max(1) as f64
    }
}

impl FootageBackground {
    /// An empty accumulator for `width × height` frames keeping the last `keep` samples (1 to
    /// 64) of each pixel.
    pub fn new(width: u32, height: u32, keep: usize) -> Result<Self> {
        if width == 0 || height == 0 || !(1..=64).contains(&keep) {
            return Err(Error::BadSetting {
                what: "background from footage".into(),
                message: format!(
                    "{width}x{height} frames keeping {keep} samples a pixel (1 to 64)"
                ),
            });
        }
        let n = width as usize * height as usize;
        Ok(Self {
            width,
            height,
            keep,
            samples: vec![[0; 3]; n * keep],
            counts: vec![0; n],
            frames: 0,
        })
    }

    /// Frames added so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Adds `frame`'s pixels where `covered` (0/1 per pixel: where the robot may be) is 0.
    /// Errors: a frame or mask of another size.
    pub fn add(&mut self, frame: &RgbaView, covered: &[u8]) -> Result<()> {
        let n = self.counts.len();
        if (frame.width, frame.height) != (self.width, self.height) || covered.len() != n {
            return Err(Error::BadImage {
                what: "background from footage".into(),
                message: format!(
                    "a {}x{} frame with a mask of {} pixels for {}x{} frames",
                    frame.width,
                    frame.height,
                    covered.len(),
                    self.width,
                    self.height
                ),
            });
        }
        for (i, (px, &c)) in frame.data.chunks_exact(4).zip(covered).enumerate() {
            if c != 0 {
                continue;
            }
            let slot = self.counts[i] as usize % self.keep;
            self.samples[i * self.keep + slot] = [px[0], px[1], px[2]];
            self.counts[i] = self.counts[i].saturating_add(1);
        }
        self.frames += 1;
        Ok(())
    }

    /// The background so far: medians where seen, the rest inpainted by Telea's method (all
    /// black when nothing was seen).
    pub fn estimate(&self) -> BackgroundEstimate {
        self.estimate_with(HoleFill::default())
    }

    /// [`FootageBackground::estimate`] with the pixels no frame showed filled by `fill`.
    pub fn estimate_with(&self, fill: HoleFill) -> BackgroundEstimate {
        let (w, h) = (self.width as usize, self.height as usize);
        let n = w * h;
        let mut rgb = vec![[0u8; 3]; n];
        let mut known = vec![false; n];
        let mut scratch = Vec::with_capacity(self.keep);
        for i in 0..n {
            let k = (self.counts[i] as usize).min(self.keep);
            if k == 0 {
                continue;
            }
            let kept = &self.samples[i * self.keep..i * self.keep + k];
            for c in 0..3 {
                scratch.clear();
                scratch.extend(kept.iter().map(|s| s[c]));
                scratch.sort_unstable();
                // The lower median: a value some frame showed.
                rgb[i][c] = scratch[(k - 1) / 2];
            }
            known[i] = true;
        }
        let seen: Vec<u8> = known.iter().map(|&k| u8::from(k)).collect();
        if known.iter().any(|&k| k) {
            fill_hole(&mut rgb, &mut known, w, h, fill);
        }
        BackgroundEstimate {
            width: self.width,
            height: self.height,
            rgba: rgb.iter().flat_map(|p| [p[0], p[1], p[2], 255]).collect(),
            seen,
            counts: self.counts.clone(),
        }
    }
}

/// Fills the pixels of `rgb` where `known` is `false` by `fill` (`known` all `true` after).
pub fn fill_hole(rgb: &mut [[u8; 3]], known: &mut [bool], w: usize, h: usize, fill: HoleFill) {
    match fill {
        HoleFill::Rings => fill_rings(rgb, known, w, h),
        HoleFill::Telea { radius } => super::inpaint::inpaint_telea(rgb, known, w, h, radius),
    }
    known.fill(true);
}

/// Fills the unknown pixels in order of their 8-connected distance from the known ones, each
/// with the rounded mean of its known neighbours.
fn fill_rings(rgb: &mut [[u8; 3]], known: &mut [bool], w: usize, h: usize) {
    let neighbours = |i: usize| {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        (-1i64..=1)
            .flat_map(move |dy| (-1i64..=1).map(move |dx| (dx, dy)))
            .filter(|&(dx, dy)| dx != 0 || dy != 0)
            .map(move |(dx, dy)| (x + dx, y + dy))
            .filter(move |&(nx, ny)| nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64)
            .map(move |(nx, ny)| ny as usize * w + nx as usize)
    };
    // The ring next to the known pixels, then the next ring, and so on.
    let mut ring: Vec<usize> = (0..known.len())
        .filter(|&i| !known[i] && neighbours(i).any(|j| known[j]))
        .collect();
    let mut queued = vec![false; known.len()];
    for &i in &ring {
        queued[i] = true;
    }
    while !ring.is_empty() {
        // Each pixel of a ring averages the pixels known before the ring (order-free).
        let values: Vec<[u8; 3]> = ring
            .iter()
            .map(|&i| {
                let (mut sum, mut k) = ([0u32; 3], 0u32);
                for j in neighbours(i).filter(|&j| known[j]) {
                    for c in 0..3 {
                        sum[c] += u32::from(rgb[j][c]);
                    }
                    k += 1;
                }
                let k = k.max(1);
                sum.map(|s| ((s + k / 2) / k) as u8)
            })
            .collect();
        for (&i, v) in ring.iter().zip(values) {
            rgb[i] = v;
            known[i] = true;
        }
        let mut next = Vec::new();
        for &i in &ring {
            for j in neighbours(i) {
                if !known[j] && !queued[j] {
                    queued[j] = true;
                    next.push(j);
                }
            }
        }
        ring = next;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6x4 room whose pixel (x, y) is (10x, 10y, 7); `covered` marks where the robot is.
    fn room(covered: impl Fn(usize, usize) -> bool, noise: u8) -> (Vec<u8>, Vec<u8>) {
        let (mut rgba, mut mask) = (Vec::new(), Vec::new());
        for y in 0..4 {
            for x in 0..6 {
                if covered(x, y) {
                    rgba.extend([255, 255, 255, 255]);
                    mask.push(1);
                } else {
                    rgba.extend([10 * x as u8 + noise, 10 * y as u8, 7, 255]);
                    mask.push(0);
                }
            }
        }
        (rgba, mask)
    }

    #[test]
    fn uncovered_pixels_take_their_median_and_the_never_seen_are_filled_and_marked() {
        let mut b = FootageBackground::new(6, 4, 8).expect("new");
        // The robot moves across columns 1-3; column 2 at rows 1-2 is never uncovered.
        let frames = [
            room(|x, _| x == 1 || x == 2, 0),
            room(|x, y| x == 2 && (1..=2).contains(&y) || x == 3, 0),
            // A passer-by brightens every uncovered pixel once: the median ignores it.
            room(|x, y| x == 2 && (1..=2).contains(&y), 40),
            room(|x, y| x == 2 && (1..=2).contains(&y), 0),
        ];
        for (rgba, mask) in &frames {
            let view = RgbaView::new("frame", 6, 4, rgba).expect("view");
            b.add(&view, mask).expect("add");
        }
        assert_eq!(b.frames(), 4);
        let e = b.estimate();
        let px = |x: usize, y: usize| &e.rgba[(y * 6 + x) * 4..(y * 6 + x) * 4 + 4];
        // Seen pixels are the room, exactly (the outlier frame is outvoted).
        assert_eq!(px(0, 0), [0, 0, 7, 255]);
        assert_eq!(px(3, 2), [30, 20, 7, 255]);
        assert_eq!(px(1, 3), [10, 30, 7, 255]);
        // Column 2 rows 0 and 3 were uncovered once or more; rows 1-2 never.
        assert_eq!(e.seen[6 + 2], 0);
        assert_eq!(e.seen[2 * 6 + 2], 0);
        assert_eq!(e.seen[2], 1);
        assert_eq!(e.counts[0], 4);
        // Filled from the neighbours: between columns 1 and 3, so about column 2's value.
        let filled = px(2, 1);
        assert!((18..=22).contains(&filled[0]), "{filled:?}");
        assert_eq!(filled[2], 7);
        assert!((e.filled_fraction() - 2.0 / 24.0).abs() < 1e-12);
        // Of the robot's region in the last frame (the two never-seen pixels), none was seen.
        assert_eq!(e.seen_fraction(&frames[3].1), Some(0.0));
        assert_eq!(e.seen_fraction(&[0; 24]), None);
    }

    #[test]
    fn only_the_last_samples_count_and_bad_sizes_are_refused() {
        let mut b = FootageBackground::new(6, 4, 2).expect("new");
        for noise in [90, 0, 0] {
            let (rgba, mask) = room(|_, _| false, noise);
            let view = RgbaView::new("frame", 6, 4, &rgba).expect("view");
            b.add(&view, &mask).expect("add");
        }
        // The oldest sample (noise 90) has left the ring of two.
        assert_eq!(&b.estimate().rgba[4..8], [10, 0, 7, 255]);
        let (rgba, _) = room(|_, _| false, 0);
        let view = RgbaView::new("frame", 6, 4, &rgba).expect("view");
        assert!(b.add(&view, &[0; 3]).is_err());
        assert!(FootageBackground::new(0, 4, 2).is_err());
        assert!(FootageBackground::new(6, 4, 0).is_err());
        // Nothing seen: black, all filled.
        let e = FootageBackground::new(2, 2, 1).expect("new").estimate();
        assert_eq!(e.rgba, [0, 0, 0, 255].repeat(4));
        assert_eq!(e.filled_fraction(), 1.0);
    }
}
