//! What a real camera does to a clean rendering: exposure changes over time and sensor noise.

use serde::{Deserialize, Serialize};

use crate::rng::Rng;

/// Sensor effects of the simulated camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct SensorModel {
    /// Gaussian noise, standard deviation in 8-bit levels (0 = none).
    pub noise_sigma: f64,
    /// Exposure gain over time as `[t_s, gain]` keyframes, linear in between (empty = 1).
    pub exposure: Vec<[f64; 2]>,
}

impl SensorModel {
    /// The exposure gain at `t_s`.
    pub fn gain_at(&self, t_s: f64) -> f64 {
        let e = &self.exposure;
        match e.len() {
            0 => 1.0,
            _ if t_s <= e[0][0] => e[0][1],
            _ => e
                .windows(2)
                .find(|w| t_s <= w[1][0])
                .map(|w| {
                    let s = (t_s - w[0][0]) / (w[1][0] - w[0][0]).max(1e-9);
                    w[0][1] + (w[1][1] - w[0][1]) * s
                })
                .unwrap_or(e[e.len() - 1][1]),
        }
    }

    /// Whether this model changes frames at all.
    pub fn is_identity(&self) -> bool {
        self.noise_sigma <= 0.0 && self.exposure.iter().all(|k| k[1] == 1.0)
    }

    /// Applies only the exposure gain at `t_s` (no noise): the view a noiseless camera would
    /// give, used for ground truth under changing exposure.
    pub fn apply_gain(&self, rgba: &mut [u8], t_s: f64) {
        let gain = self.gain_at(t_s);
        if gain == 1.0 {
            return;
        }
        for px in rgba.chunks_exact_mut(4) {
            for c in &mut px[..3] {
                *c = (f64::from(*c) * gain).round().clamp(0.0, 255.0) as u8;
            }
        }
    }

    /// Applies gain and noise in place to RGBA8 pixels (alpha untouched); `rng` should be seeded
    /// per frame so that frames are reproducible independently.
    pub fn apply(&self, rgba: &mut [u8], t_s: f64, rng: &mut Rng) {
        if self.is_identity() {
            return;
        }
        let gain = self.gain_at(t_s);
        for px in rgba.chunks_exact_mut(4) {
            for c in &mut px[..3] {
                let noise = if self.noise_sigma > 0.0 {
                    rng.gaussian() * self.noise_sigma
                } else {
                    0.0
                };
                *c = (f64::from(*c) * gain + noise).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gain_interpolates_and_noise_is_seeded() {
        let s = SensorModel {
            noise_sigma: 2.0,
            exposure: vec![[0.0, 1.0], [1.0, 1.3]],
        };
        assert!((s.gain_at(0.5) - 1.15).abs() < 1e-12);
        assert_eq!(s.gain_at(9.0), 1.3);
        let mut a = vec![100u8; 64];
        let mut b = a.clone();
        s.apply(&mut a, 1.0, &mut Rng::new(3));
        s.apply(&mut b, 1.0, &mut Rng::new(3));
        assert_eq!(a, b);
        assert!(a.chunks(4).all(|p| p[3] == 100), "alpha untouched");
        let mean = a.chunks(4).map(|p| f64::from(p[0])).sum::<f64>() / 16.0;
        assert!((mean - 130.0).abs() < 3.0);
    }
}
