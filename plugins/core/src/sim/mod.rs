//! The simulated robot: what the real arm would do with our commands, and what it would report.
//!
//! - Commands (joint velocities or joint positions) take effect after `command_latency_s`.
//! - Joints follow with a first-order response of time constant `time_constant_s`: in velocity
//!   mode the joint velocity approaches the command; in position mode the joint position does.
//! - Joint velocity and position limits always hold; a joint that reaches a limit stops there.
//! - Without a fresh velocity command for `command_timeout_s` the robot stops (as Intera does).
//! - Joint states are sampled at `state_rate_hz` and delivered `state_latency_s` later, each
//!   with the time it was sampled.
//!
//! A command with NaN/inf values or the wrong length is refused and the robot keeps its last
//! good command.
//!
//! [`recorded`] plays a recording's robot (and the timeline its camera shares) as the live
//! hardware.
//!
//! [`arm`] puts the simulated robot behind [`arm::RobotInterface`], the trait every robot
//! backend implements (ROS links included), with a gripper that carries the real object.

pub mod arm;
pub mod recorded;

use std::collections::VecDeque;

use nalgebra::DVector;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::robot::JointLimits;

/// Timing and response of the simulated robot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimRobotParams {
    /// Delay between sending a command and the robot acting on it (s).
    pub command_latency_s: f64,
    /// First-order response time constant (s).
    pub time_constant_s: f64,
    /// Joint-state publishing rate (Hz); the real Sawyer publishes at 100 Hz.
    pub state_rate_hz: f64,
    /// Delay between sampling a joint state and receiving it (s).
    pub state_latency_s: f64,
    /// A velocity command older than this is dropped and the robot stops (s).
    pub command_timeout_s: f64,
}

impl Default for SimRobotParams {
    fn default() -> Self {
        Self {
            command_latency_s: 0.02,
            time_constant_s: 0.05,
            state_rate_hz: 100.0,
            state_latency_s: 0.01,
            command_timeout_s: 0.2,
        }
    }
}

/// A command to the robot.
#[derive(Debug, Clone, PartialEq)]
pub enum JointCommand {
    /// Joint velocities (rad/s or m/s).
    Velocity(DVector<f64>),
    /// Joint positions (rad or m).
    Position(DVector<f64>),
}

/// A sampled joint state, as the robot reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct JointState {
    /// When it was sampled (s, simulation clock).
    pub stamp_s: f64,
    /// Joint positions.
    pub positions: DVector<f64>,
    /// Joint velocities.
    pub velocities: DVector<f64>,
}

/// The simulated robot.
#[derive(Debug, Clone)]
pub struct SimRobot {
    params: SimRobotParams,
    limits: Vec<JointLimits>,
    time_s: f64,
    q: DVector<f64>,
    qdot: DVector<f64>,
    pending: VecDeque<(f64, JointCommand)>,
    active: Option<(f64, JointCommand)>,
    outbox: VecDeque<(f64, JointState)>,
    next_sample_s: f64,
}

impl SimRobot {
    /// A robot at rest at `q0` (clamped into its limits), at time 0.
    pub fn new(params: SimRobotParams, limits: Vec<JointLimits>, q0: DVector<f64>) -> Self {
        let n = limits.len();
        let q = DVector::from_fn(n, |i, _| {
            limits[i].clamp_position(q0.get(i).copied().filter(|v| v.is_finite()).unwrap_or(0.0))
        });
        Self {
            params,
            limits,
            time_s: 0.0,
            q,
            qdot: DVector::zeros(n),
            pending: VecDeque::new(),
            active: None,
            outbox: VecDeque::new(),
            next_sample_s: 0.0,
        }
    }

    /// Current simulation time (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The true joint positions now (ground truth; a real robot only gives delayed states).
    pub fn true_positions(&self) -> &DVector<f64> {
        &self.q
    }

    /// The true joint velocities now.
    pub fn true_velocities(&self) -> &DVector<f64> {
        &self.qdot
    }

    /// The parameters.
    pub fn params(&self) -> &SimRobotParams {
        &self.params
    }

    /// Puts the robot at rest at `q` (clamped into its limits; a value that is missing or not
    /// finite keeps the joint where it is), forgetting commands in flight: a simulated room
    /// that shows where a real robot is, in place of a new robot every tick.
    pub fn place(&mut self, q: &DVector<f64>) {
        for i in 0..self.q.len() {
            if let Some(v) = q.get(i).copied().filter(|v| v.is_finite()) {
                self.q[i] = self.limits[i].clamp_position(v);
            }
        }
        self.qdot.fill(0.0);
        self.pending.clear();
        self.active = None;
    }

    /// [`SimRobot::place`], and its clock set to `t_s` (s): a room that shows where another
    /// robot was at `t_s` (a real robot's joint state, a remote site's) stamps its camera frames
    /// on that robot's clock.
    pub fn place_at(&mut self, q: &DVector<f64>, t_s: f64) {
        self.place(q);
        if t_s.is_finite() {
            self.time_s = t_s;
        }
    }

    /// Sends a command now; it acts after the command latency.
    pub fn send(&mut self, command: JointCommand) -> Result<()> {
        let (what, values) = match &command {
            JointCommand::Velocity(v) => ("velocity command", v),
            JointCommand::Position(p) => ("position command", p),
        };
        if values.len() != self.limits.len() {
            return Err(Error::JointCount {
                expected: self.limits.len(),
                got: values.len(),
            });
        }
        if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: format!("{what}, joint {i}"),
                value: *v,
            });
        }
        self.pending
            .push_back((self.time_s + self.params.command_latency_s, command));
        Ok(())
    }

    /// Advances the simulation by `dt` seconds.
    pub fn step(&mut self, dt: f64) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let end = self.time_s + dt;
        // Sub-steps at most 1 ms, so the response and the sampling do not depend on dt.
        let n = (dt / 1e-3).ceil().max(1.0) as usize;
        let h = dt / n as f64;
        for _ in 0..n {
            self.substep(h);
        }
        self.time_s = end;
    }

    fn substep(&mut self, h: f64) {
        let t = self.time_s + h;
        while self.pending.front().is_some_and(|(at, _)| *at <= t + 1e-12) {
            if let Some((at, cmd)) = self.pending.pop_front() {
                self.active = Some((at, cmd));
            }
        }
        let tau = self.params.time_constant_s.max(1e-6);
        let alpha = 1.0 - (-h / tau).exp();
        let n = self.limits.len();
        let target_velocity = match &self.active {
            Some((at, JointCommand::Velocity(v))) if t - at <= self.params.command_timeout_s => {
                v.clone()
            }
            Some((_, JointCommand::Position(p))) => {
                // First-order approach of the position, i.e. velocity (p − q)/τ.
                (p - &self.q) / tau
            }
            _ => DVector::zeros(n),
        };
        for i in 0..n {
            let l = &self.limits[i];
            let target = target_velocity[i].clamp(-l.velocity, l.velocity);
            let is_position = matches!(self.active, Some((_, JointCommand::Position(_))));
            let v = if is_position {
                target
            } else {
                self.qdot[i] + (target - self.qdot[i]) * alpha
            };
            let v = v.clamp(-l.velocity, l.velocity);
            let q = self.q[i] + v * h;
            if q <= l.lower || q >= l.upper {
                self.q[i] = l.clamp_position(q);
                self.qdot[i] = 0.0;
            } else {
                self.q[i] = q;
                self.qdot[i] = v;
            }
        }
        self.time_s = t;
        let period = 1.0 / self.params.state_rate_hz.max(1e-3);
        while self.next_sample_s <= t + 1e-12 {
            self.outbox.push_back((
                self.next_sample_s + self.params.state_latency_s,
                JointState {
                    stamp_s: self.next_sample_s,
                    positions: self.q.clone(),
                    velocities: self.qdot.clone(),
                },
            ));
            self.next_sample_s += period;
        }
    }

    /// Joint states delivered by now, oldest first.
    pub fn receive(&mut self) -> Vec<JointState> {
        let mut out = Vec::new();
        while self
            .outbox
            .front()
            .is_some_and(|(at, _)| *at <= self.time_s + 1e-12)
        {
            if let Some((_, s)) = self.outbox.pop_front() {
                out.push(s);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot(params: SimRobotParams) -> SimRobot {
        let lim = JointLimits {
            lower: -1.0,
            upper: 1.0,
            velocity: 0.5,
            effort: 1.0,
        };
        SimRobot::new(params, vec![lim; 2], DVector::zeros(2))
    }

    #[test]
    fn latency_first_order_and_limits() {
        let params = SimRobotParams {
            command_latency_s: 0.05,
            time_constant_s: 0.1,
            ..Default::default()
        };
        let mut r = robot(params);
        r.send(JointCommand::Velocity(DVector::from_vec(vec![0.2, 5.0])))
            .unwrap();
        r.step(0.04);
        assert_eq!(r.true_velocities()[0], 0.0, "acts before the latency");
        // Keep sending so the command does not time out.
        for _ in 0..60 {
            r.send(JointCommand::Velocity(DVector::from_vec(vec![0.2, 5.0])))
                .unwrap();
            r.step(0.01);
        }
        // After several time constants the velocity has converged; joint 1 is capped at 0.5.
        assert!((r.true_velocities()[0] - 0.2).abs() < 0.01);
        assert!((r.true_velocities()[1] - 0.5).abs() < 0.01 && r.true_velocities()[1] <= 0.5);
        for _ in 0..400 {
            r.send(JointCommand::Velocity(DVector::from_vec(vec![0.2, 5.0])))
                .unwrap();
            r.step(0.01);
        }
        assert_eq!(r.true_positions()[1], 1.0, "stops at the position limit");
        assert_eq!(r.true_velocities()[1], 0.0);
    }

    #[test]
    fn placing_the_robot_clamps_keeps_what_is_not_finite_and_drops_commands() {
        let mut r = robot(SimRobotParams::default());
        r.send(JointCommand::Velocity(DVector::from_vec(vec![0.4, 0.4])))
            .unwrap();
        r.step(0.5);
        r.place(&DVector::from_vec(vec![2.0, f64::NAN]));
        let kept = r.true_positions()[1];
        assert_eq!(r.true_positions()[0], 1.0, "clamped into the limits");
        assert!(
            kept.is_finite() && kept > 0.0,
            "NaN keeps the joint: {kept}"
        );
        assert_eq!(r.true_velocities().norm(), 0.0);
        r.step(0.5);
        assert_eq!(r.true_positions()[0], 1.0, "no command in flight");
        assert_eq!(r.true_positions()[1], kept);
    }

    #[test]
    fn position_mode_timeout_and_bad_commands() {
        let mut r = robot(SimRobotParams::default());
        r.send(JointCommand::Position(DVector::from_vec(vec![0.3, -0.2])))
            .unwrap();
        r.step(2.0);
        assert!((r.true_positions()[0] - 0.3).abs() < 1e-3);
        assert!((r.true_positions()[1] + 0.2).abs() < 1e-3);
        // NaN and wrong length are refused; the last good command stays.
        assert!(
            r.send(JointCommand::Position(DVector::from_vec(vec![
                f64::NAN,
                0.0
            ])))
            .is_err()
        );
        assert!(r.send(JointCommand::Velocity(DVector::zeros(3))).is_err());
        r.step(1.0);
        assert!((r.true_positions()[0] - 0.3).abs() < 1e-3);
        // A single velocity command stops after the timeout.
        r.send(JointCommand::Velocity(DVector::from_vec(vec![0.1, 0.0])))
            .unwrap();
        r.step(1.0);
        let q = r.true_positions()[0];
        r.step(1.0);
        assert!(
            (r.true_positions()[0] - q).abs() < 1e-6,
            "still moving after the timeout"
        );
        assert!(q < 0.3 + 0.1 * 0.25 + 1e-6);
    }

    #[test]
    fn states_are_sampled_at_the_rate_and_delivered_late() {
        let params = SimRobotParams {
            state_rate_hz: 100.0,
            state_latency_s: 0.03,
            ..Default::default()
        };
        let mut r = robot(params);
        r.step(0.02);
        assert!(r.receive().is_empty(), "nothing before the latency");
        r.step(0.08);
        let states = r.receive();
        // Sampled at 0, 10, ..., 70 ms (delivered by 100 ms).
        assert_eq!(states.len(), 8);
        assert!((states[1].stamp_s - 0.01).abs() < 1e-9);
    }
}
