//! Joint trajectories from keyframes, with minimum-jerk interpolation between them.

use nalgebra::DVector;

/// A keyframe: joint positions to reach at a time.
#[derive(Debug, Clone, PartialEq)]
pub struct Keyframe {
    /// Time (s).
    pub t_s: f64,
    /// Joint positions (joint-vector order).
    pub q: DVector<f64>,
}

/// Keyframes in time order; between two the motion is minimum-jerk (zero velocity and
/// acceleration at each keyframe), before the first and after the last it holds still.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointTrajectory {
    keyframes: Vec<Keyframe>,
}

impl JointTrajectory {
    /// A trajectory; keyframes are sorted by time.
    pub fn new(mut keyframes: Vec<Keyframe>) -> Self {
        keyframes.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        Self { keyframes }
    }

    /// The keyframes.
    pub fn keyframes(&self) -> &[Keyframe] {
        &self.keyframes
    }

    /// Positions at time `t_s`, or `None` for an empty trajectory.
    pub fn sample(&self, t_s: f64) -> Option<DVector<f64>> {
        let first = self.keyframes.first()?;
        if t_s <= first.t_s {
            return Some(first.q.clone());
        }
        for w in self.keyframes.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            if t_s <= b.t_s {
                let span = (b.t_s - a.t_s).max(1e-9);
                let s = ((t_s - a.t_s) / span).clamp(0.0, 1.0);
                let blend = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
                return Some(&a.q + (&b.q - &a.q) * blend);
            }
        }
        self.keyframes.last().map(|k| k.q.clone())
    }

    /// The largest joint speed (rad/s) any segment reaches: 1.875 × Δq / Δt for minimum jerk.
    pub fn peak_joint_speed(&self) -> Vec<f64> {
        let n = self.keyframes.first().map_or(0, |k| k.q.len());
        let mut peak = vec![0.0; n];
        for w in self.keyframes.windows(2) {
            let dt = (w[1].t_s - w[0].t_s).max(1e-9);
            for (i, p) in peak.iter_mut().enumerate() {
                *p = f64::max(*p, 1.875 * (w[1].q[i] - w[0].q[i]).abs() / dt);
            }
        }
        peak
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimum_jerk_between_keyframes() {
        let k = |t, v: f64| Keyframe {
            t_s: t,
            q: DVector::from_vec(vec![v]),
        };
        let tr = JointTrajectory::new(vec![k(2.0, 1.0), k(0.0, 0.0)]);
        assert_eq!(tr.sample(-1.0).unwrap()[0], 0.0);
        assert!((tr.sample(1.0).unwrap()[0] - 0.5).abs() < 1e-12);
        assert_eq!(tr.sample(5.0).unwrap()[0], 1.0);
        // Peak speed at mid-segment: 1.875 · 1 / 2.
        let h = 1e-5;
        let v = (tr.sample(1.0 + h).unwrap()[0] - tr.sample(1.0 - h).unwrap()[0]) / (2.0 * h);
        assert!((v - tr.peak_joint_speed()[0]).abs() < 1e-6);
    }
}
