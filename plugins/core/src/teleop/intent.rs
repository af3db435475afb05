//! Which object the operator's hand is reaching for: goal inference over candidates.
//!
//! The method is Dragan and Srinivasa's goal prediction for shared control ("A policy-blending
//! formalism for shared control", IJRR 32(7), 2013, section 4 and eq. 4): a person moving
//! toward goal `G` is modelled as noisily optimising a cost `C` (here path length, m), so that
//!
//! ```text
//! P(G | ξ_{S→U}) ∝ exp(−β C(ξ_{S→U}) − β V_G(U)) / exp(−β V_G(S)) · P(G),   V_G(X) = |X − G|
//! ```
//!
//! where `ξ_{S→U}` is the hand's path so far, from `S` to its position now `U`. Each step of
//! the path `a → b` contributes `β (|a − G| − |a − b| − |b − G|)` to the log-posterior of `G`:
//! zero for a step straight at `G`, negative for a step that detours from it (by the triangle
//! inequality). The issue asks for the last few hundred milliseconds rather than the whole path
//! since the last grasp: the sum is taken with exponential forgetting of time constant
//! [`IntentSettings::window_s`] (the path older than a window weighs `1/e`), so that the
//! estimate follows a hand that changes its mind.
//!
//! Two gates come from how people reach (Jeannerod, "The timing of natural prehension
//! movements", J. Motor Behavior 16(3), 1984: the hand opens during the transport phase and
//! closes on the object): a closed hand (carrying, or at rest with a fist) is not reaching and
//! the estimate is held; a hand slower than [`IntentSettings::min_speed_m_s`] adds no evidence
//! (at rest the formula sees no motion and would decay toward the prior).
//!
//! The estimate commits to a goal when its probability reaches
//! [`IntentSettings::commit_probability`], and changes course only when another goal is at
//! least [`IntentSettings::switch_margin`] more probable (hysteresis: a robot that turns back
//! and forth between two pieces is slower than one that waits).

use nalgebra::Vector3;

/// Settings of [`IntentEstimator`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IntentSettings {
    /// Rationality β (1/m): how sharply a detour of one metre lowers a goal's likelihood.
    pub beta_per_m: f64,
    /// The forgetting time constant (s): the evidence of a step `window_s` old weighs `1/e`.
    pub window_s: f64,
    /// Below this hand speed (m/s) a step adds no evidence.
    pub min_speed_m_s: f64,
    /// A hand whose aperture is below this (m, mean fingertip distance to the palm) is closed:
    /// not reaching.
    pub closed_aperture_m: f64,
    /// The estimate commits to a goal at this probability.
    pub commit_probability: f64,
    /// A committed estimate moves to another goal only when that goal is this much more
    /// probable.
    pub switch_margin: f64,
    /// The robot may go around the estimated object (its grasp pose, gripper open) when the
    /// probability is at least this and the hand is within [`IntentSettings::near_m`].
    pub descend_probability: f64,
    /// See `descend_probability` (m, between the hand and the goal, in the hand's scene).
    pub near_m: f64,
    /// Measure the path in the horizontal plane only (z left out): for objects on a table,
    /// which the hand reaches across above and drops onto at the end, where the height of the
    /// path says little about which object.
    pub planar: bool,
}

impl Default for IntentSettings {
    fn default() -> Self {
        Self {
            beta_per_m: 500.0,
            window_s: 0.6,
            min_speed_m_s: 0.03,
            closed_aperture_m: 0.0,
            commit_probability: 0.6,
            switch_margin: 0.2,
            descend_probability: 0.85,
            near_m: 0.15,
            planar: false,
        }
    }
}

impl IntentSettings {
    /// Checks the numbers; errors name the field.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |what: &str, message: String| {
            Err(crate::Error::BadSetting {
                what: format!("intent.{what}"),
                message,
            })
        };
        for (name, v) in [
            ("beta_per_m", self.beta_per_m),
            ("window_s", self.window_s),
            ("near_m", self.near_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(name, format!("{v} must be > 0"));
            }
        }
        for (name, v) in [
            ("min_speed_m_s", self.min_speed_m_s),
            ("closed_aperture_m", self.closed_aperture_m),
            ("switch_margin", self.switch_margin),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, format!("{v} must be >= 0"));
            }
        }
        for (name, v) in [
            ("commit_probability", self.commit_probability),
            ("descend_probability", self.descend_probability),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 1.0) {
                return bad(name, format!("{v} must be in (0, 1]"));
            }
        }
        Ok(())
    }
}

/// The estimate after a hand sample.
#[derive(Debug, Clone, PartialEq)]
pub struct IntentEstimate {
    /// The committed goal (an index into the candidates), if any.
    pub goal: Option<usize>,
    /// Its probability (0 without a goal).
    pub probability: f64,
    /// The hand is within [`IntentSettings::near_m`] of the goal and the goal's probability
    /// is at least [`IntentSettings::descend_probability`].
    pub near: bool,
    /// The goal changed with this sample (from none, or from another goal).
    pub changed: bool,
}

/// Recursive goal inference over a fixed list of candidates (module docs).
#[derive(Debug, Clone)]
pub struct IntentEstimator {
    settings: IntentSettings,
    /// Log-posterior of each candidate (up to a constant), uniform prior.
    log_p: Vec<f64>,
    last: Option<(f64, Vector3<f64>)>,
    goal: Option<usize>,
}

impl IntentEstimator {
    /// An estimator over `candidates` goals with a uniform prior. Errors for bad settings.
    pub fn new(settings: IntentSettings, candidates: usize) -> crate::Result<Self> {
        settings.validate()?;
        Ok(Self {
            settings,
            log_p: vec![0.0; candidates],
            last: None,
            goal: None,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &IntentSettings {
        &self.settings
    }

    /// Forgets the evidence and the goal (after a grasp: the next reach starts afresh).
    pub fn reset(&mut self) {
        self.log_p.iter_mut().for_each(|v| *v = 0.0);
        self.last = None;
        self.goal = None;
    }

    /// The probability of each candidate (sums to 1; uniform before any evidence).
    pub fn probabilities(&self) -> Vec<f64> {
        let max = self.log_p.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let w: Vec<f64> = self.log_p.iter().map(|l| (l - max).exp()).collect();
        let sum: f64 = w.iter().sum();
        if sum > 0.0 && sum.is_finite() {
            w.iter().map(|v| v / sum).collect()
        } else {
            vec![1.0 / self.log_p.len().max(1) as f64; self.log_p.len()]
        }
    }

    /// Takes a hand sample at `t_s` (s): `hand` the palm's position, `aperture_m` the hand's
    /// opening (m, mean fingertip distance to the palm), `goals[i]` where candidate `i` is
    /// (same frame as `hand`), `None` for a candidate that cannot be the goal now (gone from
    /// the board). A sample that is not finite, older than the last, or with another number of
    /// goals is ignored (the estimate stays as it was).
    pub fn update(
        &mut self,
        t_s: f64,
        hand: &Vector3<f64>,
        aperture_m: f64,
        goals: &[Option<Vector3<f64>>],
    ) -> IntentEstimate {
        let flat = |v: &Vector3<f64>| {
            if self.settings.planar {
                Vector3::new(v.x, v.y, 0.0)
            } else {
                *v
            }
        };
        let hand = &flat(hand);
        let goals: Vec<Option<Vector3<f64>>> = goals.iter().map(|g| g.map(|g| flat(&g))).collect();
        let goals = &goals[..];
        let valid = t_s.is_finite()
            && hand.iter().all(|v| v.is_finite())
            && goals.len() == self.log_p.len()
            && self.last.is_none_or(|(t, _)| t_s > t);
        if valid {
            self.absorb(t_s, hand, aperture_m, goals);
        }
        self.estimate(hand, goals, valid)
    }

    fn absorb(
        &mut self,
        t_s: f64,
        hand: &Vector3<f64>,
        aperture_m: f64,
        goals: &[Option<Vector3<f64>>],
    ) {
        let s = self.settings;
        let Some((t0, a)) = self.last.replace((t_s, *hand)) else {
            return;
        };
        let dt = t_s - t0;
        let reaching = !(aperture_m.is_finite() && aperture_m < s.closed_aperture_m);
        let moving = (hand - a).norm() / dt >= s.min_speed_m_s;
        let forget = (-dt / s.window_s).exp();
        for (l, g) in self.log_p.iter_mut().zip(goals) {
            let Some(g) = g else {
                *l = f64::NEG_INFINITY;
                continue;
            };
            if !l.is_finite() {
                *l = 0.0;
            }
            *l *= forget;
            if reaching && moving {
                let b = hand;
                *l += s.beta_per_m * ((a - g).norm() - (b - a).norm() - (b - g).norm());
            }
        }
    }

    fn estimate(
        &mut self,
        hand: &Vector3<f64>,
        goals: &[Option<Vector3<f64>>],
        valid: bool,
    ) -> IntentEstimate {
        let s = self.settings;
        let p = self.probabilities();
        let best = p
            .iter()
            .enumerate()
            .filter(|(i, _)| goals.get(*i).is_some_and(Option::is_some))
            .max_by(|a, b| a.1.total_cmp(b.1));
        let before = self.goal;
        if valid && let Some((i, &pi)) = best {
            let current = self.goal.and_then(|g| p.get(g).copied()).unwrap_or(0.0);
            let open = self
                .goal
                .is_none_or(|g| goals.get(g).is_none_or(Option::is_none));
            if pi >= s.commit_probability && (open || pi >= current + s.switch_margin) {
                self.goal = Some(i);
            }
        }
        let goal = self.goal;
        let probability = goal.and_then(|g| p.get(g).copied()).unwrap_or(0.0);
        let near = goal
            .and_then(|g| goals.get(g).copied().flatten())
            .is_some_and(|g| probability >= s.descend_probability && (g - hand).norm() <= s.near_m);
        IntentEstimate {
            goal,
            probability,
            near,
            changed: goal != before && goal.is_some(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn goals() -> Vec<Option<Vector3<f64>>> {
        // Three pieces 5 cm apart on a line, 30 cm in front of the hand.
        [-0.05, 0.0, 0.05]
            .iter()
            .map(|&y| Some(Vector3::new(0.3, y, 0.0)))
            .collect()
    }

    /// Moves the hand in a straight line from `from` to `to` over `duration_s` at 90 Hz.
    fn reach(
        e: &mut IntentEstimator,
        t0: f64,
        from: Vector3<f64>,
        to: Vector3<f64>,
        duration_s: f64,
        goals: &[Option<Vector3<f64>>],
    ) -> Vec<IntentEstimate> {
        let n = (duration_s * 90.0) as usize;
        (1..=n)
            .map(|k| {
                let s = k as f64 / n as f64;
                e.update(t0 + s * duration_s, &from.lerp(&to, s), 0.08, goals)
            })
            .collect()
    }

    #[test]
    fn a_straight_reach_commits_to_its_goal_before_arriving() {
        let g = goals();
        for (target, goal) in g.iter().enumerate() {
            let mut e = IntentEstimator::new(IntentSettings::default(), g.len()).unwrap();
            let to = goal.unwrap() - Vector3::new(0.04, 0.0, 0.0);
            let out = reach(&mut e, 0.0, Vector3::zeros(), to, 1.0, &g);
            let first = out.iter().position(|o| o.goal.is_some()).unwrap();
            assert!(
                out[first..].iter().all(|o| o.goal == Some(target)),
                "{target}"
            );
            // Committed within the first 70 % of the reach.
            assert!(
                first < out.len() * 7 / 10,
                "{target}: {first} of {}",
                out.len()
            );
            assert!(out.last().unwrap().near);
        }
    }

    #[test]
    fn the_estimate_follows_a_hand_that_changes_its_mind() {
        let g = goals();
        let mut e = IntentEstimator::new(IntentSettings::default(), g.len()).unwrap();
        let mid = Vector3::new(0.15, -0.06, 0.0);
        let a = reach(&mut e, 0.0, Vector3::zeros(), mid, 0.5, &g);
        assert_eq!(a.last().unwrap().goal, Some(0));
        let b = reach(&mut e, 0.5, mid, Vector3::new(0.26, 0.05, 0.0), 0.6, &g);
        assert_eq!(b.last().unwrap().goal, Some(2));
        // Across the middle piece at most on the way; no back and forth.
        let changes: Vec<_> = b.iter().filter(|o| o.changed).map(|o| o.goal).collect();
        assert!(changes.len() <= 2, "{changes:?}");
        assert_eq!(changes.last(), Some(&Some(2)));
    }

    #[test]
    fn a_still_or_closed_hand_adds_no_evidence_and_bad_samples_are_ignored() {
        let g = goals();
        let mut e = IntentEstimator::new(IntentSettings::default(), g.len()).unwrap();
        for k in 0..90 {
            e.update(f64::from(k) / 90.0, &Vector3::zeros(), 0.08, &g);
        }
        assert!(
            e.probabilities()
                .iter()
                .all(|p| (p - 1.0 / 3.0).abs() < 1e-12)
        );
        let closed = IntentSettings {
            closed_aperture_m: 0.05,
            ..IntentSettings::default()
        };
        let mut c = IntentEstimator::new(closed, g.len()).unwrap();
        for k in 0..90 {
            let p = Vector3::new(0.003 * f64::from(k), 0.0, 0.0);
            c.update(f64::from(k) / 90.0, &p, 0.03, &g);
        }
        assert!(
            c.probabilities()
                .iter()
                .all(|p| (p - 1.0 / 3.0).abs() < 1e-12)
        );
        let before = e.probabilities();
        let out = e.update(f64::NAN, &Vector3::zeros(), 0.08, &g);
        assert_eq!(out.goal, None);
        e.update(2.0, &Vector3::new(f64::NAN, 0.0, 0.0), 0.08, &g);
        e.update(3.0, &Vector3::zeros(), 0.08, &g[..2]);
        assert_eq!(e.probabilities(), before);
    }

    #[test]
    fn a_goal_that_leaves_the_board_is_never_the_estimate() {
        let mut g = goals();
        g[1] = None;
        let mut e = IntentEstimator::new(IntentSettings::default(), g.len()).unwrap();
        let out = reach(
            &mut e,
            0.0,
            Vector3::zeros(),
            Vector3::new(0.26, 0.0, 0.0),
            1.0,
            &g,
        );
        assert!(out.iter().all(|o| o.goal != Some(1)));
        assert_eq!(e.probabilities()[1], 0.0);
    }

    #[test]
    fn settings_are_checked_by_name() {
        let bad = IntentSettings {
            commit_probability: 1.5,
            ..IntentSettings::default()
        };
        let e = IntentEstimator::new(bad, 3).unwrap_err().to_string();
        assert!(e.contains("intent.commit_probability"), "{e}");
        let nan = IntentSettings {
            beta_per_m: f64::NAN,
            ..IntentSettings::default()
        };
        assert!(IntentEstimator::new(nan, 3).is_err());
    }
}
