//! What the erase leaves of the robot along its outline, measured without a reference mask
//! (the rim), and the margin's band refined to the frame.
//!
//! Both read the frame against the background H (after photometric compensation, H'):
//! - a pixel **differs** from H' where some channel differs by more than
//!   [`RimSettings::difference`] levels (background subtraction, as
//!   [`super::background_difference`]);
//! - the robot's colours are learnt from the frame itself: the pixels inside the mask that
//!   differ from H' (the robot, as the frame shows it), as a colour histogram; the
//!   background's from H' in the ring around the mask. A pixel is **robot-coloured** where its
//!   colour is likelier under the robot's histogram than under the background's (histogram
//!   back-projection, Swain & Ballard, "Color indexing", IJCV 7(1), 1991).
//!
//! Masks hold 0 or 1 per pixel, images RGBA8, all `width × height`, row-major.

use serde::Serialize;

use super::{Photometric, RgbaView, chebyshev_distance, differs, erode};
use crate::error::{Error, Result};

/// How the rim is measured and the band refined.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RimSettings {
    /// The ring outside the erased region the rim is looked for in (px, Chebyshev).
    pub ring_px: u32,
    /// Levels (8-bit, any channel) by which a pixel differs from H' to count as not the
    /// background.
    pub difference: u8,
    /// Fewer robot pixels (inside the mask, differing from H') than this: no colour model,
    /// no score.
    pub min_robot_px: usize,
}

impl Default for RimSettings {
    fn default() -> Self {
        Self {
            ring_px: 6,
            difference: 30,
            min_robot_px: 100,
        }
    }
}

/// The rim of one erased frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RimScore {
    /// Pixels of the ring (within `ring_px` outside the erased region) whose H is known.
    pub ring_px: u64,
    /// Of those, the ones the erased frame still shows robot-coloured.
    pub rim_px: u64,
    /// `rim_px` as a share of `ring_px` (%).
    pub rim_pct: f64,
    /// The pixels the robot's colour model was learnt from.
    pub robot_px: u64,
    /// With a reference silhouette: the share of the same ring it calls the robot (%), the
    /// truth `rim_pct` estimates.
    pub truth_pct: Option<f64>,
}

/// H' = `clamp(gain · H + offset)` per channel, rounded to 8 bits, RGBA8 with α = 255 (the
/// composite's background, [`super::composite`], [`Photometric::lut`]).
pub fn compensated(background: &RgbaView, photometric: &Photometric) -> Vec<u8> {
    let lut = photometric.lut();
    let level = |c: usize, v: u8| (lut[c][usize::from(v)] * 255.0).round() as u8;
    background
        .data
        .chunks_exact(4)
        .flat_map(|p| [level(0, p[0]), level(1, p[1]), level(2, p[2]), 255])
        .collect()
}

/// A colour histogram of 16 levels per channel (4,096 bins), normalised.
struct ColourModel {
    p: Vec<f32>,
}

impl ColourModel {
    fn bin(px: &[u8]) -> usize {
        (usize::from(px[0] >> 4) << 8) | (usize::from(px[1] >> 4) << 4) | usize::from(px[2] >> 4)
    }

    /// The histogram of `rgba`'s pixels where `take` is non-zero; `None` with none taken.
    fn learn(rgba: &[u8], take: impl Iterator<Item = bool>) -> Option<(Self, u64)> {
        let mut counts = vec![0u32; 4096];
        let mut n = 0u64;
        for (px, t) in rgba.chunks_exact(4).zip(take) {
            if t {
                counts[Self::bin(px)] += 1;
                n += 1;
            }
        }
        (n > 0).then(|| {
            (
                Self {
                    p: counts.iter().map(|&c| c as f32 / n as f32).collect(),
                },
                n,
            )
        })
    }

    fn p(&self, px: &[u8]) -> f32 {
        self.p[Self::bin(px)]
    }
}

/// Checks that every map (name, values, values per pixel) has `width × height` pixels.
fn check_sizes(live: &RgbaView, maps: &[(&str, &[u8], usize)]) -> Result<()> {
    for &(what, m, per) in maps {
        if m.len() != live.pixels() * per {
            return Err(Error::BadImage {
                what: what.into(),
                message: format!(
                    "{} values for a {}x{} frame ({per} per pixel)",
                    m.len(),
                    live.width,
                    live.height
                ),
            });
        }
    }
    Ok(())
}

/// The ring of `ring_px` px (Chebyshev) outside `erased` (0/1), where `known` is non-zero
/// (everywhere when `None`).
pub fn ring(
    erased: &[u8],
    width: u32,
    height: u32,
    ring_px: u32,
    known: Option<&[u8]>,
) -> Vec<bool> {
    chebyshev_distance(erased, width, height)
        .iter()
        .enumerate()
        .map(|(i, &d)| d >= 1 && d <= ring_px && known.is_none_or(|k| k.get(i) != Some(&0)))
        .collect()
}

/// The rim: of the pixels within `settings.ring_px` outside `erased` (where `known` is
/// non-zero, all when `None`), the share the erased frame `shown` still shows robot-coloured
/// (differing from H' and likelier under the robot's colours, learnt from `live` inside
/// `erased`, than under H''s in the ring). `background` is H' (RGBA8; [`compensated`]);
/// `truth`, a reference silhouette (0/1) where there is one, scores the same ring.
/// `Ok(None)`: too few robot pixels to learn its colours from, or no ring. Errors: sizes
/// that differ.
pub fn rim_score(
    live: &RgbaView,
    shown: &[u8],
    background: &[u8],
    erased: &[u8],
    known: Option<&[u8]>,
    truth: Option<&[u8]>,
    settings: &RimSettings,
) -> Result<Option<RimScore>> {
    check_sizes(
        live,
        &[
            ("erased frame", shown, 4),
            ("background H'", background, 4),
            ("erased region", erased, 1),
            ("known background", known.unwrap_or(erased), 1),
            ("reference silhouette", truth.unwrap_or(erased), 1),
        ],
    )?;
    let live_differs = differs(live.data, background, settings.difference);
    let Some((robot, robot_px)) = ColourModel::learn(
        live.data,
        erased
            .iter()
            .zip(&live_differs)
            .map(|(&e, &d)| e != 0 && d != 0),
    ) else {
        return Ok(None);
    };
    if (robot_px as usize) < settings.min_robot_px {
        return Ok(None);
    }
    let in_ring = ring(erased, live.width, live.height, settings.ring_px, known);
    let Some((room, ring_px)) = ColourModel::learn(background, in_ring.iter().copied()) else {
        return Ok(None);
    };
    let shown_differs = differs(shown, background, settings.difference);
    let rim_px = shown
        .chunks_exact(4)
        .zip(&in_ring)
        .zip(&shown_differs)
        .filter(|((px, r), d)| **r && **d != 0 && robot.p(px) > room.p(px))
        .count() as u64;
    let truth_pct = truth.map(|t| {
        let robot = in_ring
            .iter()
            .zip(t)
            .filter(|(r, t)| **r && **t != 0)
            .count();
        100.0 * robot as f64 / ring_px as f64
    });
    Ok(Some(RimScore {
        ring_px,
        rim_px,
        rim_pct: 100.0 * rim_px as f64 / ring_px as f64,
        robot_px,
        truth_pct,
    }))
}

/// The mask's margin band refined to the frame: `mask` (0/1, dilated by `core_px` beyond the
/// robot's drawn silhouette) keeps its core (`mask` eroded by `core_px`) and, of the band
/// between, the pixels that differ from H' (`background`, RGBA8) or whose H is not known
/// (`known` zero), connected (8-neighbour) to the core through such pixels, grown by
/// `grow_px` within the mask (a pixel the robot's edge crosses mixes both colours and may
/// differ by less than the threshold). The band's pixels that look like the background are
/// given back to the frame; a detached blob that differs (a hand near the robot) is too.
/// Errors: sizes that differ.
pub fn refine_band(
    live: &RgbaView,
    background: &[u8],
    mask: &[u8],
    known: Option<&[u8]>,
    core_px: u32,
    grow_px: u32,
    settings: &RimSettings,
) -> Result<Vec<u8>> {
    check_sizes(
        live,
        &[
            ("background H'", background, 4),
            ("mask", mask, 1),
            ("known background", known.unwrap_or(mask), 1),
        ],
    )?;
    let (w, h) = (live.width as usize, live.height as usize);
    let core = erode(mask, live.width, live.height, core_px);
    let d = differs(live.data, background, settings.difference);
    let candidate: Vec<bool> = (0..w * h)
        .map(|i| mask[i] != 0 && (d[i] != 0 || known.is_some_and(|k| k[i] == 0)))
        .collect();
    let mut keep: Vec<u8> = core.clone();
    let mut queue: Vec<usize> = (0..w * h).filter(|&i| core[i] != 0).collect();
    while let Some(i) = queue.pop() {
        let (x, y) = (i % w, i / w);
        for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
            for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                let j = ny * w + nx;
                if keep[j] == 0 && candidate[j] {
                    keep[j] = 1;
                    queue.push(j);
                }
            }
        }
    }
    let grown = super::dilate(&keep, live.width, live.height, grow_px);
    Ok(grown.iter().zip(mask).map(|(&g, &m)| g & m).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 64x48 frame: a grey room, a white robot (a box) where `robot` says, its mask
    /// `mask_offset` px to the left of it.
    fn scene(robot: (usize, usize, usize, usize)) -> (Vec<u8>, Vec<u8>, Vec<u8>) {
        let (w, h) = (64, 48);
        let mut live = Vec::with_capacity(w * h * 4);
        let mut truth = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let on = x >= robot.0 && x < robot.1 && y >= robot.2 && y < robot.3;
                truth[y * w + x] = u8::from(on);
                let v = if on {
                    240
                } else {
                    90 + ((x * 7 + y * 3) % 9) as u8
                };
                live.extend_from_slice(&[v, v, v, 255]);
            }
        }
        let room: Vec<u8> = (0..h)
            .flat_map(|y| (0..w).map(move |x| 90 + ((x * 7 + y * 3) % 9) as u8))
            .flat_map(|v| [v, v, v, 255])
            .collect();
        (live, room, truth)
    }

    /// The room where `mask` is 1, the live frame elsewhere.
    fn erased(live: &[u8], room: &[u8], mask: &[u8]) -> Vec<u8> {
        live.chunks_exact(4)
            .zip(room.chunks_exact(4))
            .zip(mask)
            .flat_map(|((l, r), &m)| if m != 0 { r.to_vec() } else { l.to_vec() })
            .collect()
    }

    #[test]
    fn a_mask_short_of_the_robot_leaves_a_rim_and_a_covering_one_none() {
        let (live, room, truth) = scene((20, 40, 10, 40));
        let view = RgbaView::new("live", 64, 48, &live).expect("view");
        let s = RimSettings::default();
        // The mask 3 px short on the right: the robot's last 3 columns stay shown.
        let short: Vec<u8> = (0..64 * 48)
            .map(|i| u8::from(truth[i] != 0 && i % 64 < 37))
            .collect();
        let shown_short = erased(&live, &room, &short);
        let r = rim_score(&view, &shown_short, &room, &short, None, Some(&truth), &s)
            .expect("sizes")
            .expect("a score");
        assert_eq!(r.rim_px, 3 * 30, "{r:?}");
        assert_eq!(r.truth_pct, Some(r.rim_pct), "the rim is the truth's");
        // Covering it by 2 px: no rim.
        let cover = super::super::dilate(&truth, 64, 48, 2);
        let shown = erased(&live, &room, &cover);
        let r = rim_score(&view, &shown, &room, &cover, None, None, &s)
            .expect("sizes")
            .expect("a score");
        assert_eq!(r.rim_px, 0, "{r:?}");
        // Too few robot pixels: no score; sizes that differ: an error naming the map.
        let tiny =
            rim_score(&view, &shown, &room, &vec![0u8; 64 * 48], None, None, &s).expect("sizes");
        assert!(tiny.is_none());
        let err = rim_score(&view, &shown, &room, &cover[1..], None, None, &s).expect_err("size");
        assert!(err.to_string().contains("erased region"), "{err}");
    }

    #[test]
    fn the_band_is_given_back_where_it_shows_the_room_and_kept_where_it_shows_the_robot() {
        let (live, room, truth) = scene((20, 40, 10, 40));
        let view = RgbaView::new("live", 64, 48, &live).expect("view");
        // A mask drawn 2 px left of the robot, dilated by 5 px.
        let drawn: Vec<u8> = (0..64 * 48)
            .map(|i| u8::from(i % 64 >= 18 && i % 64 < 38 && (10..40).contains(&(i / 64))))
            .collect();
        let mask = super::super::dilate(&drawn, 64, 48, 5);
        let refined =
            refine_band(&view, &room, &mask, None, 5, 1, &RimSettings::default()).expect("sizes");
        let covered = |m: &[u8]| (0..m.len()).filter(|&i| m[i] != 0).count();
        let leak = (0..truth.len())
            .filter(|&i| truth[i] != 0 && refined[i] == 0)
            .count();
        assert_eq!(leak, 0, "the robot stays erased");
        let over = |m: &[u8]| (0..m.len()).filter(|&i| m[i] != 0 && truth[i] == 0).count();
        assert!(covered(&refined) < covered(&mask));
        // The band's room pixels given back but for the core and one grown pixel.
        assert!(
            over(&refined) * 3 < over(&mask),
            "{} {}",
            over(&refined),
            over(&mask)
        );
        // Where H is not known, the band stays erased.
        let unknown = vec![0u8; 64 * 48];
        let kept = refine_band(
            &view,
            &room,
            &mask,
            Some(&unknown),
            5,
            1,
            &RimSettings::default(),
        )
        .expect("sizes");
        assert_eq!(kept, mask);
    }
}
