//! The robot site's trial measure, kept as it goes: each tick's sample is folded into running
//! sums ([`PoseErrors`], counts, the highest lift) and forgotten, so a robot site that serves
//! for days holds a few seconds of samples and targets, never the session.

use std::collections::VecDeque;

use avatarm_core::teleop::mapping::PoseErrors;
use avatarm_mapping::TeleopSample;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// The paper's measure at the robot site: the real object against the twin's target of the
/// same moment (the target stamped then, interpolated), from the grasp on.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct TrialMeasure {
    /// When the gripper first closed (s, site clock).
    pub grasp_at_s: Option<f64>,
    /// Position RMSE (m).
    pub pos_rmse_m: Option<f64>,
    /// Roll, pitch, yaw RMSE (degrees).
    pub rpy_rmse_deg: Option<[f64; 3]>,
    /// Position RMSE against the target as it arrived (m): without the network's delay.
    pub pos_rmse_as_received_m: Option<f64>,
    /// Samples compared.
    pub samples: usize,
    /// Highest lift of the real object from its start (m).
    pub real_lift_m: f64,
    /// Highest commanded tool-point speed (m/s).
    pub max_tcp_speed: f64,
    /// Ticks the limiter was stopping the arm.
    pub stop_ticks: u64,
}

/// Targets more than this far apart (s) are a gap: no target is interpolated across it.
const MAX_GAP_S: f64 = 0.2;

/// How far before the newest target's stamp targets are kept for the samples to come (s).
const KEEP_S: f64 = 1.0;

/// How long a sample waits for the target stamped after it (s, site clock) before it is left
/// out of the comparison: far beyond any delay the link is used with.
const WAIT_S: f64 = 5.0;

/// The measure as it goes ([`TrialTrack::sample`] each tick, [`TrialTrack::target`] for each
/// target used), read at the end by [`TrialTrack::finish`].
#[derive(Debug, Default)]
pub struct TrialTrack {
    start_z: f64,
    grasp_at_s: Option<f64>,
    stop_ticks: u64,
    real_lift_m: f64,
    nan_commands: u64,
    /// Against the target stamped at the sample's moment.
    then: PoseErrors,
    /// Against the target the tick had received.
    received: PoseErrors,
    /// Samples since the grasp (stamp, real object) waiting for a target stamped after them.
    waiting: VecDeque<(f64, Isometry3<f64>)>,
    /// Targets used (stamp, pose), in the order of their stamps: from the one before the
    /// oldest waiting sample, or the last [`KEEP_S`].
    targets: Vec<(f64, Isometry3<f64>)>,
}

impl TrialTrack {
    /// A track for a real object that starts at height `start_z` (m).
    pub fn new(start_z: f64) -> Self {
        Self {
            start_z,
            ..Self::default()
        }
    }

    /// A target used, stamped `stamp_s` (s, site clock).
    pub fn target(&mut self, stamp_s: f64, pose: Isometry3<f64>) {
        let at = self.targets.partition_point(|(t, _)| *t <= stamp_s);
        self.targets.insert(at, (stamp_s, pose));
        self.settle(f64::NEG_INFINITY);
    }

    /// One control tick's sample.
    pub fn sample(&mut self, s: &TeleopSample) {
        if s.qdot.iter().any(|v| !v.is_finite()) {
            self.nan_commands += 1;
        }
        if s.stopping {
            self.stop_ticks += 1;
        }
        let real = s.real_object();
        if let Some(r) = real {
            self.real_lift_m = self.real_lift_m.max(r.translation.z - self.start_z);
        }
        if self.grasp_at_s.is_none() && s.gripper_closed {
            self.grasp_at_s = Some(s.t_s);
        }
        if self.grasp_at_s.is_some()
            && let Some(r) = real
        {
            self.received.push(&s.target, &r);
            self.waiting.push_back((s.t_s, r));
        }
        self.settle(s.t_s - WAIT_S);
    }

    /// Compares each waiting sample that a target stamped after it has arrived for; leaves
    /// out those stamped before `give_up_before_s`; forgets the targets no sample needs.
    fn settle(&mut self, give_up_before_s: f64) {
        let newest = self.targets.last().map_or(f64::NEG_INFINITY, |t| t.0);
        while let Some(&(t_s, real)) = self.waiting.front() {
            if t_s < newest {
                if let Some(target) = target_at(&self.targets, t_s) {
                    self.then.push(&target, &real);
                }
            } else if t_s >= give_up_before_s {
                break;
            }
            self.waiting.pop_front();
        }
        // Targets the coming samples may still fall between: those of the last second (a
        // sample's tick may trail the newest target's stamp), and the one before.
        let keep_from = self
            .waiting
            .front()
            .map_or(newest, |w| w.0)
            .min(newest - KEEP_S);
        let first = self.targets.partition_point(|(t, _)| *t <= keep_from);
        self.targets.drain(..first.saturating_sub(1));
    }

    /// Non-finite joint velocities among the samples (must be 0).
    pub fn nan_commands(&self) -> u64 {
        self.nan_commands
    }

    /// The measure; samples still waiting for a later target are left out.
    pub fn finish(&self, max_tcp_speed: f64) -> TrialMeasure {
        let then = self.then.rmse();
        TrialMeasure {
            grasp_at_s: self.grasp_at_s,
            pos_rmse_m: then.map(|e| e[0]),
            rpy_rmse_deg: then.map(|e| [e[1], e[2], e[3]]),
            pos_rmse_as_received_m: self.received.rmse().map(|e| e[0]),
            samples: self.then.len(),
            real_lift_m: self.real_lift_m,
            max_tcp_speed,
            stop_ticks: self.stop_ticks,
        }
    }

    /// Samples and targets held now (bounded by [`WAIT_S`] and [`KEEP_S`]).
    #[cfg(test)]
    fn held(&self) -> (usize, usize) {
        (self.waiting.len(), self.targets.len())
    }
}

/// The target stamped at `t_s`, interpolated between the two around it (`targets` in the
/// order of their stamps); `None` outside them or across a gap of more than [`MAX_GAP_S`].
fn target_at(targets: &[(f64, Isometry3<f64>)], t_s: f64) -> Option<Isometry3<f64>> {
    let after = targets.partition_point(|(t, _)| *t <= t_s);
    if after == 0 || after >= targets.len() {
        return None;
    }
    let (t0, a) = &targets[after - 1];
    let (t1, b) = &targets[after];
    if t1 - t0 > MAX_GAP_S {
        return None;
    }
    let f = if t1 > t0 { (t_s - t0) / (t1 - t0) } else { 1.0 };
    Some(Isometry3::from_parts(
        Translation3::from(a.translation.vector.lerp(&b.translation.vector, f)),
        a.rotation
            * UnitQuaternion::from_scaled_axis(
                (a.rotation.inverse() * b.rotation).scaled_axis() * f,
            ),
    ))
}

#[cfg(test)]
mod tests {
    use nalgebra::{DVector, Vector6};

    use super::*;

    fn p(x: f64) -> Isometry3<f64> {
        Isometry3::translation(x, 0.0, 0.0)
    }

    #[test]
    fn the_target_of_a_moment_is_interpolated_and_gaps_are_left_out() {
        let targets = vec![(0.0, p(0.0)), (0.01, p(1.0)), (0.5, p(2.0))];
        let t = target_at(&targets, 0.005).expect("between two");
        assert!((t.translation.x - 0.5).abs() < 1e-12);
        assert!(target_at(&targets, 0.2).is_none(), "across a gap");
        assert!(target_at(&targets, -1.0).is_none());
        assert!(target_at(&targets, 1.0).is_none());
    }

    fn sample(t_s: f64, real_x: f64, closed: bool) -> TeleopSample {
        TeleopSample {
            t_s,
            target: p(t_s),
            measured: p(real_x),
            truth: None,
            gripper_closed: closed,
            tcp_speed: 0.0,
            max_joint_speed: 0.0,
            stopping: false,
            contacts: 0,
            squeeze_n: 0.0,
            twin_twist: Vector6::zeros(),
            q: DVector::zeros(7),
            qdot: DVector::zeros(7),
            operator: None,
        }
    }

    /// An hour at 100 Hz: the real object 1 cm off the target stamped 0.1 s before each tick
    /// (the network's delay), the target arriving as it goes. The measure holds a bounded
    /// window and gives the offset.
    #[test]
    fn an_hour_is_measured_in_a_bounded_window() {
        let mut track = TrialTrack::new(0.0);
        let mut most = (0, 0);
        for i in 0..360_000 {
            let t = f64::from(i) * 0.01;
            // The target stamped `t - 0.1` arrives now; the object is where the target
            // stamped `t` is, plus 1 cm.
            track.target(t - 0.1, p(t - 0.1));
            track.sample(&sample(t, t + 0.01, i >= 100));
            let held = track.held();
            most = (most.0.max(held.0), most.1.max(held.1));
        }
        let m = track.finish(0.2);
        assert_eq!(m.grasp_at_s, Some(1.0));
        assert!(
            (m.pos_rmse_m.expect("measured") - 0.01).abs() < 1e-9,
            "{m:?}"
        );
        // The tick's own target (as received) is the one stamped at its moment here.
        assert!((m.pos_rmse_as_received_m.expect("measured") - 0.01).abs() < 1e-9);
        assert!(m.samples > 359_000, "{m:?}");
        assert!(most.0 <= 12 && most.1 <= 112, "held at most {most:?}");
    }

    /// A target that never comes: the samples waiting for it are left out after a while, a
    /// gap is not interpolated across, and a NaN command is counted.
    #[test]
    fn samples_without_a_target_are_left_out_and_nan_counted() {
        let mut track = TrialTrack::new(0.0);
        track.target(0.0, p(0.0));
        track.target(0.01, p(0.01));
        for i in 0..1000 {
            track.sample(&sample(f64::from(i) * 0.01, 0.0, true));
        }
        let mut bad = sample(10.0, 0.0, true);
        bad.qdot[3] = f64::NAN;
        track.sample(&bad);
        assert!(track.held().0 <= 501, "{:?}", track.held());
        // A target 9 s later: the samples before it fall in a gap.
        track.target(9.0, p(9.0));
        let m = track.finish(0.0);
        assert_eq!((m.samples, track.nan_commands()), (1, 1), "{m:?}");
    }
}
