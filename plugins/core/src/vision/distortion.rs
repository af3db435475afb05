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

use crate::error::{Error, Result};

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

    /// Whether it is a pinhole.
    pub fn is_none(&self) -> bool {
        matches!(self, Self::None)
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
}
