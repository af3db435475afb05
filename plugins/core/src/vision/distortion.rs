//! Lens distortion: OpenCV's models, as ROS's `camera_info` names them, on normalised image
//! coordinates `(x, y) = (X/Z, Y/Z)` in the optical frame (x right, y down, z forward); pixels
//! follow as `u = fx·x_d + cx`, `v = fy·y_d + cy`.
//!
//! Formulas: OpenCV, *Camera Calibration and 3D Reconstruction* (the pinhole model with
//! distortion, `calib3d`) and *Fisheye camera model* (`cv::fisheye`):
//! - `plumb_bob` (k1, k2, p1, p2, k3) and `rational_polynomial` (k1, k2, p1, p2, k3, k4, k5,
//!   k6): with `r² = x² + y²`, the radial factor `(1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² +
//!   k5 r⁴ + k6 r⁶)` (the denominator 1 for plumb_bob) and the tangential terms
//!   `x_d = x·radial + 2 p1 x y + p2 (r² + 2x²)`, `y_d = y·radial + p1 (r² + 2y²) + 2 p2 x y`;
//! - `equidistant` (k1, k2, k3, k4): with `θ = atan(r)`, `θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ +
//!   k4 θ⁸)` and `(x_d, y_d) = (θ_d / r)·(x, y)`.
//!
//! [`Distortion::undistort`] inverts them by Newton's method on the 2x2 Jacobian, as far as a
//! model is invertible (a point past a strong barrel's fold is refused, never guessed).
//!
//! [`DistortionMap`] is what a renderer needs to draw a distorted camera's image: a pinhole
//! render wide enough for every ray the lens sees, and for each pixel of the distorted image
//! where its ray lands in that render (the `map` of OpenCV's `remap`, `dst(u, v) =
//! src(map(u, v))`).

use crate::error::{Error, Result};
use crate::vision::camera::Intrinsics;

/// A lens's distortion (the coefficients in OpenCV's order).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Distortion {
    /// A pinhole: no distortion.
    #[default]
    None,
    /// `plumb_bob`: k1, k2, p1, p2, k3.
    PlumbBob([f64; 5]),
    /// `rational_polynomial`: k1, k2, p1, p2, k3, k4, k5, k6.
    RationalPolynomial([f64; 8]),
    /// `equidistant` (OpenCV's fisheye): k1, k2, k3, k4.
    Equidistant([f64; 4]),
}

impl Distortion {
    /// The model ROS names `model` (`plumb_bob`, `rational_polynomial`, `equidistant` or
    /// `fisheye`) with coefficients `d`: as many as it takes, or none (a pinhole). Errors: an
    /// unknown model, a wrong count, a coefficient that is not finite.
    pub fn from_ros(model: &str, d: &[f64]) -> Result<Self> {
        let bad = |message: String| Error::BadSetting {
            what: "lens distortion".into(),
            message,
        };
        if let Some(v) = d.iter().find(|v| !v.is_finite()) {
            return Err(bad(format!("coefficient {v} is not finite")));
        }
        if d.iter().all(|&v| v == 0.0) {
            return Ok(Self::None);
        }
        let take = |n: usize| -> Result<Vec<f64>> {
            if d.len() == n {
                Ok(d.to_vec())
            } else {
                Err(bad(format!(
                    "{model} takes {n} coefficients, not {}",
                    d.len()
                )))
            }
        };
        match model {
            "plumb_bob" => {
                let v = take(5)?;
                Ok(Self::PlumbBob([v[0], v[1], v[2], v[3], v[4]]))
            }
            "rational_polynomial" => {
                let v = take(8)?;
                Ok(Self::RationalPolynomial([
                    v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7],
                ]))
            }
            "equidistant" | "fisheye" => {
                let v = take(4)?;
                Ok(Self::Equidistant([v[0], v[1], v[2], v[3]]))
            }
            other => Err(bad(format!(
                "model '{other}' is not known (plumb_bob, rational_polynomial, equidistant)"
            ))),
        }
    }

    /// ROS's name of the model (`none` for a pinhole).
    pub fn ros_name(&self) -> &'static str {
        match self {
            Self::None => "none",
            Self::PlumbBob(_) => "plumb_bob",
            Self::RationalPolynomial(_) => "rational_polynomial",
            Self::Equidistant(_) => "equidistant",
        }
    }

    /// The coefficients, in OpenCV's order (none for a pinhole).
    pub fn coefficients(&self) -> &[f64] {
        match self {
            Self::None => &[],
            Self::PlumbBob(d) => d,
            Self::RationalPolynomial(d) => d,
            Self::Equidistant(d) => d,
        }
    }

    /// Whether it is a pinhole.
    pub fn is_none(&self) -> bool {
        matches!(self, Self::None)
    }

    /// Checks that the lens inverts over the whole image of `image` (each pixel has an
    /// undistorted ray, so a render can be drawn through it; [`DistortionMap`]). Errors: a
    /// lens past a barrel's fold within the image (naming how many pixels), or one
    /// [`DistortionMap::new`] refuses.
    pub fn check_over(&self, image: &Intrinsics) -> Result<()> {
        if self.is_none() {
            return Ok(());
        }
        let map = DistortionMap::new(image, self, 1.0)?;
        if map.unmapped > 0 {
            return Err(Error::BadSetting {
                what: "lens distortion".into(),
                message: format!(
                    "does not invert at {} of the image's pixels (past a barrel's fold): not a lens over this image",
                    map.unmapped
                ),
            });
        }
        Ok(())
    }

    /// The distorted normalised coordinates of the undistorted `(x, y)`.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let polynomial = |k: [f64; 6], p1: f64, p2: f64| {
            let num = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[2]));
            let den = 1.0 + r2 * (k[3] + r2 * (k[4] + r2 * k[5]));
            let radial = num / den;
            (
                x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
            )
        };
        match *self {
            Self::None => (x, y),
            Self::PlumbBob([k1, k2, p1, p2, k3]) => polynomial([k1, k2, k3, 0.0, 0.0, 0.0], p1, p2),
            Self::RationalPolynomial([k1, k2, p1, p2, k3, k4, k5, k6]) => {
                polynomial([k1, k2, k3, k4, k5, k6], p1, p2)
            }
            Self::Equidistant([k1, k2, k3, k4]) => {
                let r = r2.sqrt();
                if r < 1e-12 {
                    return (x, y);
                }
                let t = r.atan();
                let t2 = t * t;
                let td = t * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
                (x * td / r, y * td / r)
            }
        }
    }

    /// The undistorted `(x, y)` whose distortion is `(xd, yd)`, within 1e-12; `None` where
    /// Newton's method does not converge (outside the region the model maps one to one).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        if self.is_none() {
            return Some((xd, yd));
        }
        if !(xd.is_finite() && yd.is_finite()) {
            return None;
        }
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let (fx, fy) = self.distort(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            if ex.abs() < 1e-12 && ey.abs() < 1e-12 {
                return Some((x, y));
            }
            // The Jacobian by central differences (the models are smooth where invertible).
            let h = 1e-7;
            let (ax, ay) = self.distort(x + h, y);
            let (bx, by) = self.distort(x - h, y);
            let (cx, cy) = self.distort(x, y + h);
            let (dx, dy) = self.distort(x, y - h);
            let (j11, j21) = ((ax - bx) / (2.0 * h), (ay - by) / (2.0 * h));
            let (j12, j22) = ((cx - dx) / (2.0 * h), (cy - dy) / (2.0 * h));
            let det = j11 * j22 - j12 * j21;
            if !det.is_finite() || det <= 1e-9 {
                return None;
            }
            x -= (j22 * ex - j12 * ey) / det;
            y -= (j11 * ey - j21 * ex) / det;
            if !(x.is_finite() && y.is_finite()) {
                return None;
            }
        }
        None
    }
}

/// [`DistortionMap::texels`]' value for a pixel whose ray the pinhole render does not hold.
pub const NO_TEXEL: u16 = u16::MAX;

/// The pinhole render a distorted image is drawn from, and where each of its pixels looks in it.
#[derive(Debug, Clone, PartialEq)]
pub struct DistortionMap {
    /// The distorted image's intrinsics (`width × height` is the map's size).
    pub image: Intrinsics,
    /// The lens.
    pub lens: Distortion,
    /// The pinhole render's intrinsics: the image's focal lengths times the render's scale,
    /// its size and principal point grown (or shrunk) to hold the undistorted rays of all the
    /// image's pixels, one texel of margin, at most three times the scaled size per side.
    pub pinhole: Intrinsics,
    /// Per pixel of the image (row-major), its ray's position in the pinhole render (px,
    /// pixel centres at integers); NaN where the lens does not invert.
    pub coords: Vec<[f32; 2]>,
    /// Per pixel, the pinhole render's nearest texel `(u, v)`, [`NO_TEXEL`] in both where
    /// the ray is outside the render or the lens does not invert.
    pub texels: Vec<[u16; 2]>,
    /// Pixels whose ray the render does not hold (beyond its 3x cap: a wide fisheye's rim).
    pub outside: usize,
    /// Pixels where the lens does not invert (past a strong barrel's fold).
    pub unmapped: usize,
}

impl DistortionMap {
    /// The map of a camera with intrinsics `image` and lens `lens` onto a pinhole render at
    /// `scale` of its resolution (as [`Intrinsics::scaled`]). Errors: bad intrinsics, a scale
    /// outside (0, 1], a lens that inverts at none of the image's pixels.
    pub fn new(image: &Intrinsics, lens: &Distortion, scale: f64) -> Result<Self> {
        image.validate()?;
        if !(scale > 0.0 && scale <= 1.0) {
            return Err(Error::BadSetting {
                what: "distortion map".into(),
                message: format!("scale {scale} is outside (0, 1]"),
            });
        }
        let scaled = image.scaled(scale);
        let ray =
            |u: f64, v: f64| lens.undistort((u - image.cx) / image.fx, (v - image.cy) / image.fy);
        // Every pixel's ray, once: their extent bounds the render.
        let mut rays = Vec::with_capacity(image.width as usize * image.height as usize);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for j in 0..image.height {
            for i in 0..image.width {
                let r = ray(f64::from(i), f64::from(j));
                if let Some((x, y)) = r {
                    let p = [scaled.fx * x + scaled.cx, scaled.fy * y + scaled.cy];
                    for a in 0..2 {
                        lo[a] = lo[a].min(p[a]);
                        hi[a] = hi[a].max(p[a]);
                    }
                }
                rays.push(r);
            }
        }
        if !(lo[0].is_finite() && lo[1].is_finite()) {
            return Err(Error::BadSetting {
                what: "lens distortion".into(),
                message: format!("{lens:?} inverts at none of the image's pixels"),
            });
        }
        let size = [f64::from(scaled.width), f64::from(scaled.height)];
        // At most one scaled image's width (height) beyond each side: 3x per side.
        let first: [f64; 2] = std::array::from_fn(|a| (lo[a].floor() - 1.0).max(-size[a]));
        let last: [f64; 2] =
            std::array::from_fn(|a| (hi[a].ceil() + 1.0).min(2.0 * size[a] - 1.0).max(first[a]));
        let extent: [u32; 2] = std::array::from_fn(|a| (last[a] - first[a]) as u32 + 1);
        let pinhole = Intrinsics {
            fx: scaled.fx,
            fy: scaled.fy,
            cx: scaled.cx - first[0],
            cy: scaled.cy - first[1],
            width: extent[0],
            height: extent[1],
        };
        pinhole.validate()?;
        let (mut coords, mut texels) = (
            Vec::with_capacity(rays.len()),
            Vec::with_capacity(rays.len()),
        );
        let (mut outside, mut unmapped) = (0, 0);
        for r in rays {
            match r {
                Some((x, y)) => {
                    let (u, v) = (pinhole.fx * x + pinhole.cx, pinhole.fy * y + pinhole.cy);
                    coords.push([u as f32, v as f32]);
                    let (tu, tv) = (u.round(), v.round());
                    let inside = (0.0..f64::from(pinhole.width)).contains(&tu)
                        && (0.0..f64::from(pinhole.height)).contains(&tv);
                    if inside {
                        texels.push([tu as u16, tv as u16]);
                    } else {
                        outside += 1;
                        texels.push([NO_TEXEL; 2]);
                    }
                }
                None => {
                    unmapped += 1;
                    coords.push([f32::NAN; 2]);
                    texels.push([NO_TEXEL; 2]);
                }
            }
        }
        Ok(Self {
            image: *image,
            lens: *lens,
            pinhole,
            coords,
            texels,
            outside,
            unmapped,
        })
    }

    fn check(&self, what: &str, src: &[u8], bytes_per_pixel: usize) -> Result<()> {
        let expected = self.pinhole.width as usize * self.pinhole.height as usize * bytes_per_pixel;
        if bytes_per_pixel == 0 || src.len() != expected {
            return Err(Error::BadImage {
                what: what.to_owned(),
                message: format!(
                    "{} bytes, but the pinhole render is {}x{} at {bytes_per_pixel} bytes per pixel",
                    src.len(),
                    self.pinhole.width,
                    self.pinhole.height
                ),
            });
        }
        Ok(())
    }

    /// The distorted image of the pinhole render `src` (`pinhole` size, `bytes_per_pixel`
    /// per pixel), each pixel its nearest texel's (a mask's lookup); zeros where
    /// [`NO_TEXEL`]. `what` names `src` in the error.
    pub fn remap_nearest(&self, what: &str, src: &[u8], bytes_per_pixel: usize) -> Result<Vec<u8>> {
        self.check(what, src, bytes_per_pixel)?;
        let row = self.pinhole.width as usize;
        let mut out = vec![0u8; self.texels.len() * bytes_per_pixel];
        for (o, t) in out.chunks_exact_mut(bytes_per_pixel).zip(&self.texels) {
            if t[0] != NO_TEXEL {
                let at = (t[1] as usize * row + t[0] as usize) * bytes_per_pixel;
                o.copy_from_slice(&src[at..at + bytes_per_pixel]);
            }
        }
        Ok(out)
    }

    /// The distorted image of the pinhole render `src`, bilinearly interpolated (a camera's
    /// image: what the lens shows); the edge repeats, zeros where the lens does not invert.
    pub fn remap_bilinear(
        &self,
        what: &str,
        src: &[u8],
        bytes_per_pixel: usize,
    ) -> Result<Vec<u8>> {
        self.check(what, src, bytes_per_pixel)?;
        let (w, h) = (self.pinhole.width as usize, self.pinhole.height as usize);
        let mut out = vec![0u8; self.coords.len() * bytes_per_pixel];
        for (o, c) in out.chunks_exact_mut(bytes_per_pixel).zip(&self.coords) {
            if !(c[0].is_finite() && c[1].is_finite()) {
                continue;
            }
            let (u, v) = (
                f64::from(c[0]).clamp(0.0, (w - 1) as f64),
                f64::from(c[1]).clamp(0.0, (h - 1) as f64),
            );
            let (u0, v0) = (u.floor() as usize, v.floor() as usize);
            let (u1, v1) = ((u0 + 1).min(w - 1), (v0 + 1).min(h - 1));
            let (a, b) = (u - u0 as f64, v - v0 as f64);
            let at =
                |x: usize, y: usize, k: usize| f64::from(src[(y * w + x) * bytes_per_pixel + k]);
            for (k, o) in o.iter_mut().enumerate() {
                let top = at(u0, v0, k) * (1.0 - a) + at(u1, v0, k) * a;
                let bottom = at(u0, v1, k) * (1.0 - a) + at(u1, v1, k) * a;
                *o = (top * (1.0 - b) + bottom * b).round().clamp(0.0, 255.0) as u8;
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_models_match_opencv_s_formulas_and_invert() {
        // Hand-evaluated OpenCV formulas at (x, y) = (0.3, -0.2): r² = 0.13.
        let d = Distortion::PlumbBob([-0.2, 0.05, 0.001, -0.002, 0.01]);
        let (x, y) = (0.3, -0.2);
        let r2: f64 = 0.13;
        let radial = 1.0 - 0.2 * r2 + 0.05 * r2 * r2 + 0.01 * r2.powi(3);
        let expected = (
            x * radial + 2.0 * 0.001 * x * y - 0.002 * (r2 + 2.0 * x * x),
            y * radial + 0.001 * (r2 + 2.0 * y * y) + 2.0 * -0.002 * x * y,
        );
        let got = d.distort(x, y);
        assert!((got.0 - expected.0).abs() < 1e-15 && (got.1 - expected.1).abs() < 1e-15);
        let fisheye = Distortion::Equidistant([0.1, -0.02, 0.003, 0.0]);
        let r = r2.sqrt();
        let t = r.atan();
        let td = t * (1.0 + 0.1 * t * t - 0.02 * t.powi(4) + 0.003 * t.powi(6));
        let got = fisheye.distort(x, y);
        assert!((got.0 - x * td / r).abs() < 1e-15 && (got.1 - y * td / r).abs() < 1e-15);
        let rational = Distortion::RationalPolynomial([0.1, 0.01, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0]);
        let got = rational.distort(x, y);
        let radial = (1.0 + 0.1 * r2 + 0.01 * r2 * r2) / (1.0 + 0.2 * r2);
        assert!((got.0 - x * radial).abs() < 1e-15);
        // Each undoes itself over a webcam's field of view (x, y within ±0.6).
        for model in [d, fisheye, rational] {
            for i in -6..=6 {
                for j in -4..=4 {
                    let (x, y) = (0.1 * f64::from(i), 0.1 * f64::from(j));
                    let (xd, yd) = model.distort(x, y);
                    let (ux, uy) = model.undistort(xd, yd).expect("invertible here");
                    assert!(
                        (ux - x).abs() < 1e-9 && (uy - y).abs() < 1e-9,
                        "{model:?} at {x}, {y}"
                    );
                }
            }
        }
    }

    #[test]
    fn files_name_what_is_wrong_and_zeros_are_a_pinhole() {
        assert_eq!(
            Distortion::from_ros("plumb_bob", &[0.0; 5]).ok(),
            Some(Distortion::None)
        );
        assert_eq!(
            Distortion::from_ros("plumb_bob", &[]).ok(),
            Some(Distortion::None)
        );
        assert_eq!(
            Distortion::from_ros("fisheye", &[0.1, 0.0, 0.0, 0.0]).ok(),
            Some(Distortion::Equidistant([0.1, 0.0, 0.0, 0.0]))
        );
        let e = Distortion::from_ros("plumb_bob", &[0.1, 0.2]).expect_err("count");
        assert!(e.to_string().contains("takes 5"), "{e}");
        let e =
            Distortion::from_ros("plumb_bob", &[f64::NAN, 0.0, 0.0, 0.0, 0.0]).expect_err("nan");
        assert!(e.to_string().contains("not finite"), "{e}");
        let e = Distortion::from_ros("kannala", &[0.1]).expect_err("model");
        assert!(e.to_string().contains("kannala"), "{e}");
        // Past a strong barrel's fold there is no inverse: refused, not guessed.
        let strong = Distortion::PlumbBob([-0.9, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(strong.undistort(2.0, 0.0), None);
        assert_eq!(strong.undistort(f64::NAN, 0.0), None);
    }

    #[test]
    fn a_map_finds_each_pixel_s_ray_in_the_pinhole_render() {
        let k = Intrinsics::from_fov_y(55f64.to_radians(), 160, 120);
        // A pinhole: the render is the image with a pixel of margin.
        let map = DistortionMap::new(&k, &Distortion::None, 1.0).expect("pinhole");
        assert_eq!((map.pinhole.width, map.pinhole.height), (162, 122));
        assert_eq!(map.texels[0], [1, 1]);
        // A webcam's barrel: the render grows to hold the corners' rays.
        let lens = Distortion::PlumbBob([-0.3, 0.1, 0.001, -0.001, 0.0]);
        let map = DistortionMap::new(&k, &lens, 1.0).expect("barrel");
        assert!(
            map.pinhole.width > 170 && map.pinhole.height > 125,
            "{:?}",
            map.pinhole
        );
        // A world ray: its pinhole pixel and its distorted pixel agree through the map.
        for (x, y) in [(0.0, 0.0), (0.35, -0.2), (-0.4, 0.3), (0.1, 0.25)] {
            let (xd, yd) = lens.distort(x, y);
            let (u, v) = (k.fx * xd + k.cx, k.fy * yd + k.cy);
            let (i, j) = (u.round() as usize, v.round() as usize);
            let c = map.coords[j * 160 + i];
            // Rounding the distorted pixel moves the ray by at most half a pixel (times the
            // lens's local magnification, below 1.5 here).
            let (pu, pv) = (
                map.pinhole.fx * x + map.pinhole.cx,
                map.pinhole.fy * y + map.pinhole.cy,
            );
            assert!(
                (f64::from(c[0]) - pu).abs() < 0.75 && (f64::from(c[1]) - pv).abs() < 0.75,
                "ray ({x}, {y}): map {c:?}, pinhole ({pu}, {pv})"
            );
            let t = map.texels[j * 160 + i];
            assert_eq!(
                [f64::from(t[0]), f64::from(t[1])],
                [f64::from(c[0]).round(), f64::from(c[1]).round()]
            );
        }
        // Remapping: a render whose texels hold their own coordinates reads back the texels.
        let (pw, ph) = (map.pinhole.width as usize, map.pinhole.height as usize);
        let src: Vec<u8> = (0..pw * ph)
            .flat_map(|n| [(n % pw) as u8, (n / pw) as u8])
            .collect();
        let out = map.remap_nearest("coordinates", &src, 2).expect("size");
        assert_eq!(out[..2], [map.texels[0][0] as u8, map.texels[0][1] as u8]);
        let smooth = map.remap_bilinear("coordinates", &src, 2).expect("size");
        let centre = 60 * 160 + 80;
        assert!((f64::from(smooth[centre * 2]) - f64::from(map.coords[centre][0])).abs() <= 0.5);
        // Sizes and scales are checked.
        assert!(map.remap_nearest("short", &src[1..], 2).is_err());
        assert!(DistortionMap::new(&k, &lens, 0.0).is_err());
        // A fisheye and a rational lens map every pixel, their rays where the model puts them.
        for lens in [
            Distortion::Equidistant([0.05, -0.01, 0.002, 0.0]),
            Distortion::RationalPolynomial([0.2, 0.01, 0.0, 0.0, 0.0, 0.5, 0.02, 0.0]),
        ] {
            let m = DistortionMap::new(&k, &lens, 1.0).expect("invertible");
            assert_eq!((m.unmapped, m.outside), (0, 0), "{lens:?}");
            let (x, y) = (0.3, -0.2);
            let (xd, yd) = lens.distort(x, y);
            let (i, j) = (
                (k.fx * xd + k.cx).round() as usize,
                (k.fy * yd + k.cy).round() as usize,
            );
            let c = m.coords[j * 160 + i];
            let (pu, pv) = (
                m.pinhole.fx * x + m.pinhole.cx,
                m.pinhole.fy * y + m.pinhole.cy,
            );
            assert!((f64::from(c[0]) - pu).abs() < 0.75 && (f64::from(c[1]) - pv).abs() < 0.75);
        }
        let half = DistortionMap::new(&k, &lens, 0.5).expect("half");
        assert!(
            half.pinhole.width <= map.pinhole.width / 2 + 3,
            "{:?} {:?}",
            half.pinhole,
            map.pinhole
        );
    }
}
