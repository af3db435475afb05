//! Rasterising the model's triangles into coverage, outlines and distance transforms: the images
//! the fit's costs compare (scan-line fill, Felzenszwalb and Huttenlocher's exact Euclidean
//! distance transform, a box blur).

use super::*;

/// Rasterises the triangles seen through `camera_from_base` with `k` and the lens `d` into a
/// `k.width × k.height` 0/1 mask (pixel centres sampled; triangles with a vertex within 1 cm of
/// the camera plane or behind it are left out).
pub fn rasterize(
    triangles: &[[Point3<f64>; 3]],
    camera_from_base: &Isometry3<f64>,
    k: &Intrinsics,
    d: &Distortion,
) -> Vec<u8> {
    let (w, h) = (k.width as usize, k.height as usize);
    let mut mask = vec![0u8; w * h];
    for t in triangles {
        if let Some(p) = project(t, camera_from_base, k, d) {
            fill_triangle(&mut mask, w, h, &p);
        }
    }
    mask
}

/// The share of each pixel the triangles cover, sampled on a 4x4 grid inside the pixel (as a
/// 16-bit set of the samples covered, so overlapping triangles count once).
pub fn coverage(
    triangles: &[[Point3<f64>; 3]],
    camera_from_base: &Isometry3<f64>,
    k: &Intrinsics,
    d: &Distortion,
) -> Vec<u16> {
    let (w, h) = (k.width as usize, k.height as usize);
    let mut bits = vec![0u16; w * h];
    for t in triangles {
        let Some(p) = project(t, camera_from_base, k, d) else {
            continue;
        };
        // In sample units: 4 per pixel, sample (4x + i) at x - 3/8 + i/4.
        let p = p.map(|v| [4.0 * v[0] + 1.5, 4.0 * v[1] + 1.5]);
        for_each_span(&p, 4 * w, 4 * h, |y, xa, xb| {
            let shift = (y % 4) * 4;
            let row = (y / 4) * w;
            let (pa, pb) = (xa / 4, xb / 4);
            let nibble = |a: usize, b: usize| ((0xFu16 << a) & (0xFu16 >> (3 - b))) << shift;
            if pa == pb {
                bits[row + pa] |= nibble(xa % 4, xb % 4);
            } else {
                bits[row + pa] |= nibble(xa % 4, 3);
                for v in &mut bits[row + pa + 1..row + pb] {
                    *v |= 0xF << shift;
                }
                bits[row + pb] |= nibble(0, xb % 4);
            }
        });
    }
    bits
}

/// A triangle's vertices in pixels through the lens (`None` when one is within 1 cm of the
/// camera plane or behind it).
pub(super) fn project(
    t: &[Point3<f64>; 3],
    camera_from_base: &Isometry3<f64>,
    k: &Intrinsics,
    d: &Distortion,
) -> Option<[[f64; 2]; 3]> {
    let mut p = [[0.0f64; 2]; 3];
    for (i, v) in t.iter().enumerate() {
        let c = camera_from_base * v;
        if c.z.is_nan() || c.z < 0.01 {
            return None;
        }
        let (x, y) = d.distort(c.x / c.z, c.y / c.z);
        p[i] = [k.fx * x + k.cx, k.fy * y + k.cy];
    }
    Some(p)
}

/// Calls `f(y, first, last)` for each row `y` of a `w × h` grid whose integer points `first..=
/// last` lie inside the triangle `p` (grid units; boundaries included).
pub(super) fn for_each_span(
    p: &[[f64; 2]; 3],
    w: usize,
    h: usize,
    mut f: impl FnMut(usize, usize, usize),
) {
    let area =
        (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
    if area.abs() < 1e-12 || !area.is_finite() {
        return;
    }
    let lo = p.iter().map(|v| v[1]).fold(f64::INFINITY, f64::min);
    let hi = p.iter().map(|v| v[1]).fold(f64::NEG_INFINITY, f64::max);
    let (y0, y1) = (lo.ceil().max(0.0), hi.floor().min(h as f64 - 1.0));
    if y0 > y1 {
        return;
    }
    for y in y0 as usize..=y1 as usize {
        let yf = y as f64;
        let (mut left, mut right) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..3 {
            let (a, b) = (p[i], p[(i + 1) % 3]);
            let (a, b) = if a[1] <= b[1] { (a, b) } else { (b, a) };
            if yf < a[1] || yf > b[1] || a[1] == b[1] {
                continue;
            }
            let x = a[0] + (yf - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            left = left.min(x);
            right = right.max(x);
        }
        let (xa, xb) = (left.ceil().max(0.0), right.floor().min(w as f64 - 1.0));
        if xa <= xb {
            f(y, xa as usize, xb as usize);
        }
    }
}

pub(super) fn fill_triangle(mask: &mut [u8], w: usize, h: usize, p: &[[f64; 2]; 3]) {
    // Pixel centres at integers (the camera model's convention).
    for_each_span(p, w, h, |y, xa, xb| mask[y * w + xa..=y * w + xb].fill(1));
}

/// The outline of a 0/1 mask: its pixels with a 4-neighbour outside it (or on the image's
/// border).
pub fn outline(mask: &[u8], w: usize, h: usize) -> Vec<u8> {
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if mask[i] == 0 {
                continue;
            }
            let inside = |dx: i64, dy: i64| {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                nx >= 0
                    && ny >= 0
                    && nx < w as i64
                    && ny < h as i64
                    && mask[ny as usize * w + nx as usize] != 0
            };
            if !(inside(1, 0) && inside(-1, 0) && inside(0, 1) && inside(0, -1)) {
                out[i] = 1;
            }
        }
    }
    out
}

/// The pixels on both sides of a 0/1 mask's transitions: those with a 4-neighbour in the image
/// whose value differs (the image's border is no transition). Two pixels wide, so that an edge
/// between them is matched from either side alike: an image edge found at any resolution lies
/// on one of them, and a one-sided cost has no reason to grow or shrink the mask.
pub(super) fn transitions(mask: &[u8], w: usize, h: usize) -> Vec<u8> {
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let here = mask[i] != 0;
            let differs = (x > 0 && (mask[i - 1] != 0) != here)
                || (x + 1 < w && (mask[i + 1] != 0) != here)
                || (y > 0 && (mask[i - w] != 0) != here)
                || (y + 1 < h && (mask[i + w] != 0) != here);
            out[i] = u8::from(differs);
        }
    }
    out
}

/// Exact Euclidean distance (px) from every pixel to the nearest non-zero pixel of `seeds`
/// (Felzenszwalb and Huttenlocher's separable lower envelope of parabolas); `f32::INFINITY`
/// everywhere when there is no seed.
pub fn distance_transform(seeds: &[u8], w: usize, h: usize) -> Vec<f32> {
    const FAR: f64 = 1e20;
    let mut d: Vec<f64> = seeds
        .iter()
        .map(|&s| if s != 0 { 0.0 } else { FAR })
        .collect();
    let mut f = vec![0.0; w.max(h)];
    let mut out = vec![0.0; w.max(h)];
    let mut v = vec![0usize; w.max(h)];
    let mut z = vec![0.0; w.max(h) + 1];
    for x in 0..w {
        for y in 0..h {
            f[y] = d[y * w + x];
        }
        edt_1d(&f[..h], &mut out[..h], &mut v, &mut z);
        for y in 0..h {
            d[y * w + x] = out[y];
        }
    }
    for y in 0..h {
        f[..w].copy_from_slice(&d[y * w..y * w + w]);
        edt_1d(&f[..w], &mut out[..w], &mut v, &mut z);
        d[y * w..y * w + w].copy_from_slice(&out[..w]);
    }
    d.iter()
        .map(|&v| {
            if v >= FAR / 2.0 {
                f32::INFINITY
            } else {
                v.sqrt() as f32
            }
        })
        .collect()
}

/// Squared distances along one line: `out[q] = min_p (q - p)² + f[p]` (the lower envelope of
/// the parabolas rooted at each `p`).
pub(super) fn edt_1d(f: &[f64], out: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let meet = |q: usize, p: usize| {
        ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64))
    };
    let mut k = 0usize;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        let mut s = meet(q, v[k]);
        while s <= z[k] {
            // z[0] is -inf, so this stops at k = 0 at the latest.
            k -= 1;
            s = meet(q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    let mut k = 0usize;
    for (q, o) in out.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let d = q as f64 - v[k] as f64;
        *o = d * d + f[v[k]];
    }
}

/// Pixels beyond a silhouette's box that its blur can reach, with the margin that keeps the
/// box's edge clamping from changing the result (two passes of radius 2, and 2 more).
pub(super) const BLUR_MARGIN: usize = 6;

/// The box `[x0, y0, x1, y1)` of the points, grown by `margin` and clipped to `w × h`
/// (empty when there is no point).
pub(super) fn grown_box(
    points: impl Iterator<Item = [f64; 2]>,
    margin: usize,
    w: usize,
    h: usize,
) -> [usize; 4] {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in points {
        b = [
            b[0].min(p[0]),
            b[1].min(p[1]),
            b[2].max(p[0]),
            b[3].max(p[1]),
        ];
    }
    if !(b[0] <= b[2] && b[1] <= b[3]) {
        return [0; 4];
    }
    let m = margin as f64;
    let clip = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
    [
        clip((b[0] - m).floor(), w),
        clip((b[1] - m).floor(), h),
        clip((b[2] + m).ceil() + 1.0, w),
        clip((b[3] + m).ceil() + 1.0, h),
    ]
}

/// The share of each pixel of the box `u` (`[x0, y0, x1, y1)`) that [`coverage`]'s `bits`
/// (rows `w` wide) cover, blurred by [`blur`]: `(x1 - x0) × (y1 - y0)` values, top row first.
pub(super) fn blurred_coverage(bits: &[u16], u: [usize; 4], w: usize) -> Vec<f32> {
    let (bw, bh) = (u[2] - u[0], u[3] - u[1]);
    let mut m = vec![0.0f32; bw * bh];
    for y in 0..bh {
        let row = &bits[(u[1] + y) * w + u[0]..(u[1] + y) * w + u[2]];
        for (v, c) in m[y * bw..(y + 1) * bw].iter_mut().zip(row) {
            *v = c.count_ones() as f32 / 16.0;
        }
    }
    blur(&mut m, bw, bh);
    m
}

/// Two passes of a box filter of radius 2 along rows and columns (edges repeat).
pub(super) fn blur(v: &mut [f32], w: usize, h: usize) {
    let mut tmp = vec![0.0f32; v.len()];
    for _ in 0..2 {
        for y in 0..h {
            let row = &v[y * w..y * w + w];
            for x in 0..w {
                let mut s = 0.0;
                for d in -2i64..=2 {
                    s += row[(x as i64 + d).clamp(0, w as i64 - 1) as usize];
                }
                tmp[y * w + x] = s / 5.0;
            }
        }
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                for d in -2i64..=2 {
                    s += tmp[(y as i64 + d).clamp(0, h as i64 - 1) as usize * w + x];
                }
                v[y * w + x] = s / 5.0;
            }
        }
    }
}
