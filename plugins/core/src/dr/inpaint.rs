//! Inpainting of the pixels no frame showed (where the robot stood the whole time): Telea's
//! method (A. Telea, "An Image Inpainting Technique Based on the Fast Marching Method",
//! *Journal of Graphics Tools* 9(1), 2004).
//!
//! The hole is filled from its rim inwards in the order of the distance `T` to the rim, which
//! the fast marching method computes as it goes (the upwind solution of the eikonal equation
//! `|∇T| = 1`, J. A. Sethian, *Level Set Methods and Fast Marching Methods*, 1999). Each pixel
//! `p` reached is the weighted mean, over the known pixels `q` within `radius`, of the
//! first-order estimate `I(q) + ∇I(q)·(p − q)`, weighted (Telea, eq. 5-6) by
//! - direction: `|N(p)·(p − q)| / |p − q|`, `N = ∇T` (the rim's normal), so that the
//!   isophotes arriving at the rim are carried on;
//! - distance: `1 / |p − q|²`;
//! - level: `1 / (1 + |T(p) − T(q)|)`, preferring pixels on the rim's own level.
//!
//! Telea's eq. 5 adds a first-order term, `∇I(q)·(p − q)`, to each `I(q)`; it is left out
//! here: on real frames (the Panda's, `plugins/footage/tests/hole_fill.rs`) it carried noise
//! and edges outwards until they blew up (13.5 dB in the hole against 31.5 dB for a plain
//! ring-by-ring mean); OpenCV's implementation likewise bounds that term to about one level.
//!
//! Known pixels near the rim get `T` too (negative, marched outwards to `2·radius`), so that
//! the level weight and the normal are defined on both sides. Deterministic: the same image and
//! hole give the same fill, so a still camera's fill does not flicker.
//!
//! Written here rather than taken from a crate: the one Rust crate with Telea's method
//! (`inpaint`, EUPL-1.2) is under a licence the project's MIT/Apache-2.0 cannot carry.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// `T` of pixels not reached yet.
const FAR: f32 = 1.0e6;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flag {
    /// Given, or filled already.
    Known,
    /// Given or filled, on the front of the march: its neighbours are reached from it.
    Band,
    /// Not reached yet.
    Inside,
}

/// The image being filled: RGB as `f32`, its flags and distances.
struct Field<'a> {
    w: usize,
    h: usize,
    rgb: &'a mut [[f32; 3]],
    flags: Vec<Flag>,
    t: Vec<f32>,
}

/// Fills the pixels of `rgb` (`w × h`, row-major) where `known` is `false` by Telea's method
/// with neighbourhoods of `radius` px (about 3 to 10; below 1 is taken as 1). Pixels already
/// known keep their values. Returns without a change when nothing or everything is known, or
/// when the sizes do not match `w × h`.
pub fn inpaint_telea(rgb: &mut [[u8; 3]], known: &[bool], w: usize, h: usize, radius: f32) {
    let n = w * h;
    if rgb.len() != n || known.len() != n || known.iter().all(|&k| k) || !known.contains(&true) {
        return;
    }
    let radius = radius.max(1.0);
    let mut values: Vec<[f32; 3]> = rgb.iter().map(|p| p.map(f32::from)).collect();
    let mut field = Field {
        w,
        h,
        rgb: &mut values,
        flags: known
            .iter()
            .map(|&k| if k { Flag::Known } else { Flag::Inside })
            .collect(),
        t: known.iter().map(|&k| if k { 0.0 } else { FAR }).collect(),
    };
    // The rim: known pixels with an unknown 4-neighbour.
    let rim: Vec<usize> = (0..n)
        .filter(|&i| known[i] && field.neighbours4(i).any(|j| !known[j]))
        .collect();
    for &i in &rim {
        field.flags[i] = Flag::Band;
    }
    field.outside_distances(&rim, 2.0 * radius);
    let mut front: BinaryHeap<Reverse<(u32, usize)>> =
        rim.iter().map(|&i| Reverse((0f32.to_bits(), i))).collect();
    while let Some(Reverse((_, i))) = front.pop() {
        if field.flags[i] == Flag::Known {
            continue;
        }
        field.flags[i] = Flag::Known;
        let next: Vec<usize> = field.neighbours4(i).collect();
        for j in next {
            if field.flags[j] != Flag::Inside {
                continue;
            }
            field.t[j] = field.arrival(j);
            let value = field.estimate(j, radius);
            field.rgb[j] = value;
            field.flags[j] = Flag::Band;
            // T ≥ 0 here: its bits order as the values do.
            front.push(Reverse((field.t[j].to_bits(), j)));
        }
    }
    for (out, (v, &k)) in rgb.iter_mut().zip(values.iter().zip(known)) {
        if !k {
            *out = v.map(|c| c.round().clamp(0.0, 255.0) as u8);
        }
    }
}

impl Field<'_> {
    fn xy(&self, i: usize) -> (isize, isize) {
        ((i % self.w) as isize, (i / self.w) as isize)
    }

    fn at(&self, x: isize, y: isize) -> Option<usize> {
        (x >= 0 && y >= 0 && (x as usize) < self.w && (y as usize) < self.h)
            .then(|| y as usize * self.w + x as usize)
    }

    fn neighbours4(&self, i: usize) -> impl Iterator<Item = usize> + use<> {
        let (x, y) = self.xy(i);
        let (w, h) = (self.w as isize, self.h as isize);
        [(x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)]
            .into_iter()
            .filter(move |&(x, y)| x >= 0 && y >= 0 && x < w && y < h)
            .map(move |(x, y)| (y * w + x) as usize)
    }

    /// `T` at pixel `i` from its reached 4-neighbours (those with a distance): the smallest of
    /// the upwind solutions of `|∇T| = 1` over the four quadrants.
    fn arrival(&self, i: usize) -> f32 {
        let (x, y) = self.xy(i);
        let reached =
            |p: Option<usize>| p.filter(|&p| self.flags[p] != Flag::Inside && self.t[p] < FAR);
        let horizontal = [reached(self.at(x - 1, y)), reached(self.at(x + 1, y))];
        let vertical = [reached(self.at(x, y - 1)), reached(self.at(x, y + 1))];
        let mut best = FAR;
        for a in horizontal {
            for b in vertical {
                let t = match (a.map(|a| self.t[a]), b.map(|b| self.t[b])) {
                    (Some(a), Some(b)) if (a - b).abs() < 1.0 => {
                        (a + b + (2.0 - (a - b) * (a - b)).sqrt()) / 2.0
                    }
                    (Some(a), Some(b)) => 1.0 + a.min(b),
                    (Some(a), None) | (None, Some(a)) => 1.0 + a,
                    (None, None) => FAR,
                };
                best = best.min(t);
            }
        }
        best
    }

    /// `∇T` at `i`: central differences, one-sided at the front, over reached pixels.
    fn normal(&self, i: usize) -> (f32, f32) {
        let (x, y) = self.xy(i);
        let t = |p: Option<usize>| {
            p.filter(|&p| self.flags[p] != Flag::Inside)
                .map(|p| self.t[p])
        };
        let along = |before: Option<usize>, after: Option<usize>| match (t(before), t(after)) {
            (Some(b), Some(a)) => (a - b) / 2.0,
            (Some(b), None) => self.t[i] - b,
            (None, Some(a)) => a - self.t[i],
            (None, None) => 0.0,
        };
        (
            along(self.at(x - 1, y), self.at(x + 1, y)),
            along(self.at(x, y - 1), self.at(x, y + 1)),
        )
    }

    /// Telea's estimate of pixel `p` from the reached pixels within `radius`.
    fn estimate(&self, p: usize, radius: f32) -> [f32; 3] {
        let (px, py) = self.xy(p);
        let (nx, ny) = self.normal(p);
        let norm = (nx * nx + ny * ny).sqrt();
        let r = radius.ceil() as isize;
        let (mut sum, mut weights) = ([0f32; 3], 0f32);
        for qy in py - r..=py + r {
            for qx in px - r..=px + r {
                let Some(q) = self.at(qx, qy) else { continue };
                if q == p || self.flags[q] == Flag::Inside {
                    continue;
                }
                let (dx, dy) = ((px - qx) as f32, (py - qy) as f32);
                let d2 = dx * dx + dy * dy;
                if d2 > radius * radius {
                    continue;
                }
                let d = d2.sqrt();
                let direction = if norm > 0.0 {
                    ((dx * nx + dy * ny) / (d * norm)).abs().max(1e-6)
                } else {
                    1.0
                };
                let level = 1.0 / (1.0 + (self.t[p] - self.t[q]).abs());
                let weight = direction * level / d2;
                for (s, v) in sum.iter_mut().zip(self.rgb[q]) {
                    *s += weight * v;
                }
                weights += weight;
            }
        }
        if weights > 0.0 {
            sum.map(|s| (s / weights).clamp(0.0, 255.0))
        } else {
            [0.0; 3]
        }
    }

    /// Marches from the rim outwards over the known pixels up to `limit`, giving them
    /// `T = −distance`, so that `T` and its gradient are defined across the rim.
    fn outside_distances(&mut self, rim: &[usize], limit: f32) {
        // A march of its own: the known pixels are its unknown, the hole stays out of reach.
        let mut flags: Vec<Flag> = self
            .flags
            .iter()
            .map(|f| match f {
                Flag::Known => Flag::Inside,
                Flag::Band => Flag::Band,
                Flag::Inside => Flag::Known,
            })
            .collect();
        let mut t = vec![FAR; self.t.len()];
        for &i in rim {
            t[i] = 0.0;
        }
        std::mem::swap(&mut self.flags, &mut flags);
        std::mem::swap(&mut self.t, &mut t);
        // The hole's own pixels must not seed the march: they are beyond reach here.
        for (ti, f) in self.t.iter_mut().zip(&self.flags) {
            if *f == Flag::Known {
                *ti = FAR;
            }
        }
        let mut front: BinaryHeap<Reverse<(u32, usize)>> =
            rim.iter().map(|&i| Reverse((0f32.to_bits(), i))).collect();
        let mut reached = Vec::new();
        while let Some(Reverse((_, i))) = front.pop() {
            if self.flags[i] == Flag::Known {
                continue;
            }
            self.flags[i] = Flag::Known;
            if self.t[i] > limit {
                continue;
            }
            let next: Vec<usize> = self.neighbours4(i).collect();
            for j in next {
                if self.flags[j] != Flag::Inside {
                    continue;
                }
                self.t[j] = self.arrival(j);
                self.flags[j] = Flag::Band;
                reached.push(j);
                front.push(Reverse((self.t[j].to_bits(), j)));
            }
        }
        let outside = std::mem::replace(&mut self.t, t);
        self.flags = flags;
        for j in reached {
            self.t[j] = -outside[j];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w × h` ramp: (2x + y, x + 3y, 100) per pixel.
    fn ramp(w: usize, h: usize) -> Vec<[u8; 3]> {
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                [(2 * x + y) as u8, (x + 3 * y) as u8, 100]
            })
            .collect()
    }

    fn hole(w: usize, h: usize, inside: impl Fn(usize, usize) -> bool) -> Vec<bool> {
        (0..w * h).map(|i| !inside(i % w, i / w)).collect()
    }

    #[test]
    fn a_ramp_is_carried_across_a_hole_and_the_known_pixels_are_kept() {
        let (w, h) = (40, 30);
        let truth = ramp(w, h);
        let known = hole(w, h, |x, y| (12..28).contains(&x) && (8..22).contains(&y));
        let mut image = truth.clone();
        for (p, &k) in image.iter_mut().zip(&known) {
            if !k {
                *p = [255, 0, 255];
            }
        }
        inpaint_telea(&mut image, &known, w, h, 5.0);
        let mut worst = 0i32;
        for ((a, b), &k) in image.iter().zip(&truth).zip(&known) {
            if k {
                assert_eq!(a, b, "a known pixel changed");
            } else {
                for c in 0..3 {
                    worst = worst.max((i32::from(a[c]) - i32::from(b[c])).abs());
                }
            }
        }
        // A ramp of 3 levels a pixel across a 16x14 hole: the weighted mean leans towards
        // the rim's values, at most 15 levels off at the hole's middle (measured 15).
        assert!(worst <= 16, "worst error {worst}");
        // The same input, the same fill.
        let mut again = truth.clone();
        inpaint_telea(&mut again, &known, w, h, 5.0);
        assert_eq!(again, image);
    }

    #[test]
    fn an_edge_into_the_hole_is_carried_on() {
        // Left half dark, right half bright; a hole across the edge: the fill keeps the edge
        // (each side from its own side) rather than a grey smear.
        let (w, h) = (40, 40);
        let truth: Vec<[u8; 3]> = (0..w * h)
            .map(|i| if i % w < 20 { [30; 3] } else { [220; 3] })
            .collect();
        let known = hole(w, h, |x, y| (10..30).contains(&x) && (15..25).contains(&y));
        let mut image = truth.clone();
        inpaint_telea(&mut image, &known, w, h, 5.0);
        let at = |x: usize, y: usize| i32::from(image[y * w + x][0]);
        assert!(
            at(14, 20) < 60 && at(25, 20) > 190,
            "{} {}",
            at(14, 20),
            at(25, 20)
        );
    }

    #[test]
    fn nothing_to_fill_or_nothing_to_fill_from_changes_nothing() {
        let (w, h) = (4, 3);
        let image = ramp(w, h);
        for known in [vec![true; w * h], vec![false; w * h], vec![true; 5]] {
            let mut out = image.clone();
            inpaint_telea(&mut out, &known, w, h, 3.0);
            assert_eq!(out, image);
        }
    }
}
