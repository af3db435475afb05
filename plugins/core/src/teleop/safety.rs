//! The safety limiter that every joint-velocity command passes through, last, whatever
//! controller produced it. Always on:
//!
//! - NaN or infinite numbers anywhere in the command, the joint state or the Jacobian: the
//!   command is replaced by a stop.
//! - Watchdog: hand data or joint states older than `timeout_s`, or the hand not tracked: stop.
//! - Joint position limits: a joint that would cross its limit within one period is slowed to
//!   reach it; joint velocity limits: the whole vector is scaled (direction kept).
//! - TCP speed (ISO 10218's 0.25 m/s for collaborative operation, configurable): the linear
//!   speed of the tool point, `‖J_v q̇‖`, is capped by scaling the whole vector.
//! - Acceleration: each joint's change per period is bounded, so a stop is a ramp to zero, not
//!   a jump. After a stop has reached zero and held for `stop_hold_s`, the limiter says to stop
//!   sending ([`Limited::command`] is `None`): a real robot then reverts to position mode and
//!   holds still.

use nalgebra::{DVector, Matrix6xX};

use crate::robot::JointLimits;

/// Settings of the limiter.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SafetySettings {
    /// Largest linear speed of the tool point (m/s).
    pub max_tcp_speed: f64,
    /// Hand data or joint states older than this stop the robot (s).
    pub timeout_s: f64,
    /// Largest change of a joint velocity per second (rad/s² or m/s²).
    pub max_joint_accel: f64,
    /// Zero velocity is sent this long after a stop before the stream ends (s).
    pub stop_hold_s: f64,
}

impl Default for SafetySettings {
    fn default() -> Self {
        Self {
            max_tcp_speed: 0.25,
            timeout_s: 0.1,
            max_joint_accel: 4.0,
            stop_hold_s: 0.2,
        }
    }
}

impl SafetySettings {
    /// Checks the numbers; errors name the field.
    pub fn validate(&self) -> crate::Result<()> {
        for (name, v) in [
            ("max_tcp_speed", self.max_tcp_speed),
            ("timeout_s", self.timeout_s),
            ("max_joint_accel", self.max_joint_accel),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(crate::Error::BadSetting {
                    what: format!("safety.{name}"),
                    message: format!("{v} must be > 0"),
                });
            }
        }
        if !(self.stop_hold_s.is_finite() && self.stop_hold_s >= 0.0) {
            return Err(crate::Error::BadSetting {
                what: "safety.stop_hold_s".into(),
                message: format!("{} must be >= 0", self.stop_hold_s),
            });
        }
        Ok(())
    }
}

/// Why the limiter changed a command (several may hold).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Intervention {
    /// A NaN or infinite input.
    NotFinite,
    /// Hand data too old.
    HandStale,
    /// The hand is not tracked.
    HandLost,
    /// Joint states too old.
    JointsStale,
    /// A joint slowed at its position limit.
    PositionLimit,
    /// Scaled for a joint velocity limit.
    VelocityLimit,
    /// Scaled for the TCP speed cap.
    TcpSpeed,
    /// Slewed by the acceleration limit.
    Acceleration,
}

/// What one tick's inputs are.
#[derive(Debug, Clone, Copy)]
pub struct TickInputs<'a> {
    /// Now (s, app clock).
    pub now_s: f64,
    /// The controller's joint velocities.
    pub qdot: &'a DVector<f64>,
    /// Measured joint positions.
    pub q: &'a [f64],
    /// When those joint states were sampled (s).
    pub joints_stamp_s: Option<f64>,
    /// When the hand data was captured (s); `None` when there is no hand.
    pub hand_stamp_s: Option<f64>,
    /// The hand is tracked.
    pub hand_tracked: bool,
    /// Jacobian of the tool point at `q` (6 × dof, world frame, linear part first).
    pub jacobian: &'a Matrix6xX<f64>,
}

/// The limited command.
#[derive(Debug, Clone, PartialEq)]
pub struct Limited {
    /// Joint velocities to send; `None`: send nothing (stopped and held long enough).
    pub command: Option<DVector<f64>>,
    /// What was changed.
    pub interventions: Vec<Intervention>,
    /// The tool point's linear speed of the command (m/s).
    pub tcp_speed: f64,
    /// The robot is being stopped (watchdog or bad input).
    pub stopping: bool,
}

/// The limiter's state between ticks.
#[derive(Debug, Clone)]
pub struct SafetyLimiter {
    settings: SafetySettings,
    limits: Vec<JointLimits>,
    last: DVector<f64>,
    last_s: Option<f64>,
    stopped_since: Option<f64>,
}

impl SafetyLimiter {
    /// A limiter for a robot with these joint limits.
    pub fn new(settings: SafetySettings, limits: Vec<JointLimits>) -> Self {
        let n = limits.len();
        Self {
            settings,
            limits,
            last: DVector::zeros(n),
            last_s: None,
            stopped_since: None,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &SafetySettings {
        &self.settings
    }

    /// Limits one command. `dt` is the control period (s) used for the position look-ahead.
    pub fn tick(&mut self, input: &TickInputs, dt: f64) -> Limited {
        let n = self.limits.len();
        let mut why: Vec<Intervention> = Vec::new();
        let note = |why: &mut Vec<Intervention>, i: Intervention| {
            if !why.contains(&i) {
                why.push(i);
            }
        };
        let finite = input.now_s.is_finite()
            && dt.is_finite()
            && dt > 0.0
            && input.qdot.len() == n
            && input.q.len() == n
            && input.jacobian.ncols() == n
            && input
                .qdot
                .iter()
                .chain(input.q)
                .chain(input.jacobian.iter())
                .all(|v| v.is_finite());
        if !finite {
            note(&mut why, Intervention::NotFinite);
        }
        let age_ok = |stamp: Option<f64>| {
            stamp.is_some_and(|s| s.is_finite() && input.now_s - s <= self.settings.timeout_s)
        };
        if !age_ok(input.joints_stamp_s) {
            note(&mut why, Intervention::JointsStale);
        }
        if !input.hand_tracked {
            note(&mut why, Intervention::HandLost);
        } else if !age_ok(input.hand_stamp_s) {
            note(&mut why, Intervention::HandStale);
        }
        let stopping = !why.is_empty();
        let mut qdot = if stopping {
            DVector::zeros(n)
        } else {
            input.qdot.clone()
        };
        if !stopping {
            // Position limits: do not cross within one period.
            for (i, l) in self.limits.iter().enumerate() {
                if l.lower > l.upper {
                    continue;
                }
                let next = input.q[i] + qdot[i] * dt;
                if next > l.upper && qdot[i] > 0.0 {
                    qdot[i] = ((l.upper - input.q[i]) / dt).max(0.0);
                    note(&mut why, Intervention::PositionLimit);
                } else if next < l.lower && qdot[i] < 0.0 {
                    qdot[i] = ((l.lower - input.q[i]) / dt).min(0.0);
                    note(&mut why, Intervention::PositionLimit);
                }
            }
            // Joint velocity limits, direction kept.
            let scale = self
                .limits
                .iter()
                .zip(qdot.iter())
                .filter(|(l, _)| l.velocity > 0.0)
                .map(|(l, v)| {
                    if v.abs() > l.velocity {
                        l.velocity / v.abs()
                    } else {
                        1.0
                    }
                })
                .fold(1.0, f64::min);
            if scale < 1.0 {
                qdot *= scale;
                note(&mut why, Intervention::VelocityLimit);
            }
            // TCP speed.
            let speed = tcp_speed(input.jacobian, &qdot);
            if speed > self.settings.max_tcp_speed {
                qdot *= self.settings.max_tcp_speed / speed;
                note(&mut why, Intervention::TcpSpeed);
            }
        }
        // Acceleration: slew from the last command (also when stopping: a ramp, not a jump).
        let period = match self.last_s {
            Some(t) if input.now_s.is_finite() && input.now_s > t => {
                (input.now_s - t).min(dt.max(1e-6) * 4.0)
            }
            _ => dt.max(1e-6),
        };
        let max_step = self.settings.max_joint_accel * period;
        let mut slewed = false;
        for i in 0..n {
            let last = if self.last[i].is_finite() {
                self.last[i]
            } else {
                0.0
            };
            let delta = (qdot[i] - last).clamp(-max_step, max_step);
            if (last + delta - qdot[i]).abs() > 1e-12 {
                slewed = true;
            }
            qdot[i] = last + delta;
        }
        if slewed {
            note(&mut why, Intervention::Acceleration);
            // Slewing toward a new command can only raise the TCP speed if the old one was
            // faster; keep the cap as the last word (when the inputs can be trusted).
            if finite {
                let speed = tcp_speed(input.jacobian, &qdot);
                if speed > self.settings.max_tcp_speed {
                    qdot *= self.settings.max_tcp_speed / speed;
                    note(&mut why, Intervention::TcpSpeed);
                }
            }
        }
        if input.now_s.is_finite() {
            self.last_s = Some(input.now_s);
        }
        self.last = qdot.clone();
        let at_rest = qdot.iter().all(|v| v.abs() < 1e-9);
        let command = if stopping && at_rest {
            let since = *self.stopped_since.get_or_insert(input.now_s);
            if input.now_s - since >= self.settings.stop_hold_s {
                None
            } else {
                Some(qdot.clone())
            }
        } else {
            self.stopped_since = None;
            Some(qdot.clone())
        };
        let tcp = if finite {
            tcp_speed(input.jacobian, &qdot)
        } else {
            0.0
        };
        Limited {
            command,
            interventions: why,
            tcp_speed: tcp,
            stopping,
        }
    }
}

/// Linear speed of the tool point for joint velocities `qdot`.
pub fn tcp_speed(jacobian: &Matrix6xX<f64>, qdot: &DVector<f64>) -> f64 {
    if jacobian.ncols() != qdot.len() {
        return f64::INFINITY;
    }
    (jacobian.fixed_rows::<3>(0) * qdot).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(n: usize) -> Vec<JointLimits> {
        vec![
            JointLimits {
                lower: -1.0,
                upper: 1.0,
                velocity: 2.0,
                effort: 10.0,
            };
            n
        ]
    }

    /// Two joints moving the tool along x and y at 1 m per rad/s.
    fn jac() -> Matrix6xX<f64> {
        let mut j = Matrix6xX::zeros(2);
        j[(0, 0)] = 1.0;
        j[(1, 1)] = 1.0;
        j
    }

    fn tick(
        l: &mut SafetyLimiter,
        now: f64,
        qdot: [f64; 2],
        q: [f64; 2],
        hand: Option<f64>,
    ) -> Limited {
        let qdot = DVector::from_row_slice(&qdot);
        let j = jac();
        l.tick(
            &TickInputs {
                now_s: now,
                qdot: &qdot,
                q: &q,
                joints_stamp_s: Some(now - 0.01),
                hand_stamp_s: hand,
                hand_tracked: hand.is_some(),
                jacobian: &j,
            },
            0.01,
        )
    }

    fn limiter() -> SafetyLimiter {
        SafetyLimiter::new(SafetySettings::default(), limits(2))
    }

    #[test]
    fn tcp_speed_is_capped_after_the_ramp() {
        let mut l = limiter();
        let mut out = None;
        for k in 0..100 {
            let t = f64::from(k) * 0.01;
            out = Some(tick(&mut l, t, [1.0, 1.0], [0.0, 0.0], Some(t)));
            let o = out.as_ref().expect("set");
            assert!(o.tcp_speed <= 0.25 + 1e-9, "tick {k}: {}", o.tcp_speed);
        }
        let o = out.expect("ran");
        assert!((o.tcp_speed - 0.25).abs() < 1e-9, "{}", o.tcp_speed);
        assert!(o.interventions.contains(&Intervention::TcpSpeed));
        // Each reason once, even when the cap is applied before and after the ramp.
        let mut seen = o.interventions.clone();
        seen.sort_by_key(|i| format!("{i:?}"));
        seen.dedup();
        assert_eq!(seen.len(), o.interventions.len(), "{:?}", o.interventions);
        // Direction kept.
        let c = o.command.expect("sending");
        assert!((c[0] - c[1]).abs() < 1e-12);
    }

    #[test]
    fn nan_and_stale_data_ramp_to_a_stop_then_the_stream_ends() {
        let mut l = limiter();
        let mut t = 0.0;
        for _ in 0..50 {
            tick(&mut l, t, [0.2, 0.0], [0.0, 0.0], Some(t));
            t += 0.01;
        }
        // A NaN command: never sent, the robot ramps down.
        let o = tick(&mut l, t, [f64::NAN, 0.0], [0.0, 0.0], Some(t));
        assert!(o.stopping && o.interventions.contains(&Intervention::NotFinite));
        let c = o.command.expect("still ramping");
        assert!(c.iter().all(|v| v.is_finite()));
        assert!(c[0] < 0.2 && c[0] >= 0.2 - 4.0 * 0.01 - 1e-12, "{c}");
        // Hand data frozen at t: after the timeout the watchdog stops the robot.
        let frozen = t;
        let mut ended = None;
        let mut last = c[0];
        for k in 1..200 {
            let now = t + f64::from(k) * 0.01;
            let o = tick(&mut l, now, [0.2, 0.0], [0.0, 0.0], Some(frozen));
            match o.command {
                Some(c) => {
                    // Monotone ramp down, no jumps larger than the acceleration bound.
                    assert!((c[0] - last).abs() <= 4.0 * 0.01 + 1e-12);
                    last = c[0];
                }
                None => {
                    ended = Some(now);
                    break;
                }
            }
        }
        let ended = ended.expect("the stream ends");
        assert!(last.abs() < 1e-9, "last sent {last}");
        assert!(ended - frozen < 0.1 + 0.05 + 0.2 + 0.05, "ended at {ended}");
        // Tracking back: commands resume from zero.
        let o = tick(
            &mut l,
            ended + 0.01,
            [0.2, 0.0],
            [0.0, 0.0],
            Some(ended + 0.01),
        );
        assert!(!o.stopping);
        assert!(o.command.expect("sending")[0] <= 0.04 + 1e-12);
    }

    #[test]
    fn lost_hand_and_position_and_velocity_limits() {
        let mut l = limiter();
        let o = tick(&mut l, 0.0, [0.5, 0.0], [0.0, 0.0], None);
        assert!(o.stopping && o.interventions.contains(&Intervention::HandLost));
        // At the upper limit, a joint is not pushed further.
        let mut l = SafetyLimiter::new(
            SafetySettings {
                max_joint_accel: 1e6,
                max_tcp_speed: 100.0,
                ..SafetySettings::default()
            },
            limits(2),
        );
        let o = tick(&mut l, 0.0, [1.0, -5.0], [0.999, 0.0], Some(0.0));
        let c = o.command.expect("sending");
        assert!(c[0] <= 0.1 + 1e-9, "{c}");
        assert!(o.interventions.contains(&Intervention::PositionLimit));
        assert!(o.interventions.contains(&Intervention::VelocityLimit));
        assert!(c[1].abs() <= 2.0 + 1e-9);
    }

    #[test]
    fn settings_are_checked() {
        assert!(SafetySettings::default().validate().is_ok());
        let bad = SafetySettings {
            max_tcp_speed: f64::NAN,
            ..SafetySettings::default()
        };
        assert!(
            bad.validate()
                .expect_err("nan")
                .to_string()
                .contains("max_tcp_speed")
        );
    }
}
