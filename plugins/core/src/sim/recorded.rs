//! A recording played as the live hardware: its timeline released in real time from a start
//! instant, lap after lap ([`Playback`]), and its robot as the robot behind the mapping
//! ([`RecordedArm`]).
//!
//! What lets a machine without a camera or an arm run the real path end to end: a recorded
//! camera's frames are released at their capture times (the video side's player), its joint
//! states at their sample times (here), both from one [`Playback`], so that each frame meets the
//! joints it was recorded with. A recording cannot move: the arm counts the commands it is sent
//! and reports the recorded joints whatever they say.

use std::sync::Arc;
use std::time::{Duration, Instant};

use nalgebra::DVector;

use crate::error::Error;
use crate::sim::JointState;
use crate::sim::arm::{RobotError, RobotInterface};
use crate::teleop::mapping::GripperCommand;

/// A recorded timeline (stamps in seconds, any origin) played from `start`: the sample stamped
/// `t` in lap `k` (from 0) is released at `start + (t - first) + k * lap`. A lap is the
/// timeline's span plus one `gap_s` (its mean sample period, so that the last sample and the
/// next lap's first are as far apart as two neighbours).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Playback {
    start: Instant,
    first_s: f64,
    lap_s: f64,
}

/// Where a player stands in its timeline: the next sample and its lap.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PlaybackCursor {
    /// Index of the next sample to release.
    pub next: usize,
    /// Its lap (from 0).
    pub lap: u64,
}

/// A sample [`Playback::due`] releases.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Due {
    /// Its index in the timeline.
    pub index: usize,
    /// Its lap (from 0).
    pub lap: u64,
    /// When it is released (its capture or sample instant, played).
    pub at: Instant,
    /// Samples before it that were due but skipped (a player that fell behind releases only
    /// the newest).
    pub skipped: u64,
}

/// The first and last of `stamps_s` (s), checked: not empty, finite and increasing. Errors
/// ([`Error::BadTimeline`]) name `what` and the stamp.
fn check_stamps(what: &str, stamps_s: &[f64]) -> Result<(f64, f64), Error> {
    let bad = |message: String| Error::BadTimeline {
        what: what.to_owned(),
        message,
    };
    let (Some(&first_s), Some(&last_s)) = (stamps_s.first(), stamps_s.last()) else {
        return Err(bad("the timeline is empty".into()));
    };
    if !first_s.is_finite() {
        return Err(bad(format!("stamp 0 ({first_s} s) is not finite")));
    }
    for (i, pair) in stamps_s.windows(2).enumerate() {
        if !(pair[1].is_finite() && pair[1] > pair[0]) {
            return Err(bad(format!(
                "stamp {} ({} s) does not follow stamp {i} ({} s)",
                i + 1,
                pair[1],
                pair[0]
            )));
        }
    }
    Ok((first_s, last_s))
}

impl PlaybackCursor {
    /// Moves past the current sample of a timeline of `len` samples; `true` when that starts a
    /// new lap.
    fn step(&mut self, len: usize) -> bool {
        self.next += 1;
        let wrapped = self.next >= len;
        if wrapped {
            self.next = 0;
            self.lap += 1;
        }
        wrapped
    }
}

impl Playback {
    /// Plays the timeline `what` (named in errors) whose stamps are `stamps_s` (s,
    /// increasing) from `start`. Errors ([`Error::BadTimeline`]): an empty timeline, a stamp
    /// that is not finite or does not increase (naming its index).
    pub fn new(what: &str, start: Instant, stamps_s: &[f64]) -> Result<Self, Error> {
        let (first_s, last_s) = check_stamps(what, stamps_s)?;
        let span = last_s - first_s;
        let gap_s = if stamps_s.len() > 1 {
            span / (stamps_s.len() - 1) as f64
        } else {
            1.0 / 30.0
        };
        Self::with_lap(what, start, first_s, span + gap_s)
    }

    /// Plays from `start` a timeline that begins at `first_s` and repeats every `lap_s` (s):
    /// for several timelines of one recording played together (its frames and its joints), the
    /// frames' playback is the one both take. Errors ([`Error::BadTimeline`], naming `what`):
    /// a first stamp that is not finite, a lap that is not finite or not above 1 ms.
    pub fn with_lap(what: &str, start: Instant, first_s: f64, lap_s: f64) -> Result<Self, Error> {
        if !(first_s.is_finite() && lap_s.is_finite() && lap_s > 1e-3) {
            return Err(Error::BadTimeline {
                what: what.to_owned(),
                message: format!("a timeline from {first_s} s in laps of {lap_s} s"),
            });
        }
        Ok(Self {
            start,
            first_s,
            lap_s,
        })
    }

    /// The instant the sample stamped `stamp_s` is released in lap `lap` (a stamp before the
    /// first: at the start; one too far ahead for the clock: as far as it goes).
    pub fn release(&self, stamp_s: f64, lap: u64) -> Instant {
        let offset = (stamp_s - self.first_s) + lap as f64 * self.lap_s;
        Duration::try_from_secs_f64(offset.max(0.0))
            .ok()
            .and_then(|d| self.start.checked_add(d))
            .unwrap_or_else(|| self.start + Duration::from_secs(u64::from(u32::MAX)))
    }

    /// A lap's length (s).
    pub fn lap_s(&self) -> f64 {
        self.lap_s
    }

    /// The first stamp of the timeline (s).
    pub fn first_s(&self) -> f64 {
        self.first_s
    }

    /// The newest sample of `stamps_s` due at `now` from `cursor` (moved past it), `None` when
    /// the next is not due yet. Samples due before the newest are skipped and counted.
    pub fn due(&self, stamps_s: &[f64], cursor: &mut PlaybackCursor, now: Instant) -> Option<Due> {
        let mut found: Option<Due> = None;
        let mut skipped = 0;
        while let Some(&t) = stamps_s.get(cursor.next) {
            let at = self.release(t, cursor.lap);
            if at > now {
                break;
            }
            if found.is_some() {
                skipped += 1;
            }
            found = Some(Due {
                index: cursor.next,
                lap: cursor.lap,
                at,
                skipped: 0,
            });
            cursor.step(stamps_s.len());
        }
        found.map(|d| Due { skipped, ..d })
    }

    /// The instant the next sample of `stamps_s` from `cursor` is released.
    pub fn next_release(&self, stamps_s: &[f64], cursor: PlaybackCursor) -> Option<Instant> {
        stamps_s
            .get(cursor.next)
            .map(|&t| self.release(t, cursor.lap))
    }
}

/// A recording's robot as the robot behind the mapping: its joint states are released at their
/// sample times ([`Playback`]) and stamped on the caller's clock (the one
/// [`RobotInterface::advance`] is given); commands are checked (a NaN is refused, naming the
/// joint) and counted, never obeyed.
#[derive(Debug, Clone)]
pub struct RecordedArm {
    name: String,
    states: Arc<[JointState]>,
    stamps_s: Vec<f64>,
    playback: Playback,
    cursor: PlaybackCursor,
    /// The caller's clock at an instant (the last `advance`).
    clock: Option<(f64, Instant)>,
    commands: u64,
    laps: u64,
}

impl RecordedArm {
    /// The arm of a recording named `name` (for messages) whose joint states are `states`
    /// (stamps in the recording's seconds, increasing; every vector of one length), played by
    /// `playback`. States without velocities get them by finite differences (the erase's
    /// latency compensation extrapolates with them). Errors ([`Error::BadTimeline`]): no state,
    /// stamps that do not increase, vectors of other lengths or values not finite.
    pub fn new(
        name: impl Into<String>,
        states: Vec<JointState>,
        playback: Playback,
    ) -> Result<Self, Error> {
        let name = name.into();
        let what = format!("{name}: joint states");
        let stamps_s: Vec<f64> = states.iter().map(|s| s.stamp_s).collect();
        check_stamps(&what, &stamps_s)?;
        let dof = states[0].positions.len();
        if let Some((i, s)) = states.iter().enumerate().find(|(_, s)| {
            s.positions.len() != dof
                || (!s.velocities.is_empty() && s.velocities.len() != dof)
                || s.positions
                    .iter()
                    .chain(&s.velocities)
                    .any(|v| !v.is_finite())
        }) {
            return Err(Error::BadTimeline {
                what,
                message: format!(
                    "state {i} at {} s: {} positions and {} velocities, or a value not finite; the first has {dof} positions",
                    s.stamp_s,
                    s.positions.len(),
                    s.velocities.len()
                ),
            });
        }
        // Central differences inside, one-sided at the ends (stamps increase: no division by 0).
        let velocity = |i: usize| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(states.len() - 1));
            if a == b {
                DVector::zeros(dof)
            } else {
                (&states[b].positions - &states[a].positions)
                    / (states[b].stamp_s - states[a].stamp_s)
            }
        };
        let filled: Vec<DVector<f64>> = (0..states.len())
            .map(|i| {
                if states[i].velocities.is_empty() {
                    velocity(i)
                } else {
                    states[i].velocities.clone()
                }
            })
            .collect();
        let states: Arc<[JointState]> = states
            .into_iter()
            .zip(filled)
            .map(|(s, velocities)| JointState { velocities, ..s })
            .collect();
        Ok(Self {
            name,
            states,
            stamps_s,
            playback,
            cursor: PlaybackCursor::default(),
            clock: None,
            commands: 0,
            laps: 0,
        })
    }

    /// Commands sent (and not obeyed).
    pub fn commands(&self) -> u64 {
        self.commands
    }

    fn refuse(&self, message: String) -> RobotError {
        RobotError {
            robot: self.name.clone(),
            message,
        }
    }

    fn on_clock(&self, at: Instant) -> Option<f64> {
        let (now_s, now) = self.clock?;
        Some(if at <= now {
            now_s - (now - at).as_secs_f64()
        } else {
            now_s + (at - now).as_secs_f64()
        })
    }
}

impl RobotInterface for RecordedArm {
    fn name(&self) -> &str {
        &self.name
    }

    /// Every state due since the last call (oldest first), stamped on the caller's clock.
    /// Nothing before the first [`RobotInterface::advance`].
    fn receive(&mut self) -> Vec<JointState> {
        let now = Instant::now();
        let mut out = Vec::new();
        if self.clock.is_none() {
            return out;
        }
        // A caller that fell behind by more than a lap (a slow start) skips the whole laps it
        // missed: it gets the last lap's states, not a lap per call until it catches up.
        if let Some(next) = self.playback.next_release(&self.stamps_s, self.cursor) {
            let behind = now.saturating_duration_since(next).as_secs_f64();
            let laps = (behind / self.playback.lap_s()).floor();
            if laps >= 1.0 {
                let skipped = laps as u64;
                self.cursor.lap += skipped;
                self.laps += skipped;
            }
        }
        while let Some(at) = self.playback.next_release(&self.stamps_s, self.cursor) {
            if at > now || out.len() >= self.states.len() {
                break;
            }
            let i = self.cursor.next;
            let stamp_s = self.on_clock(at).unwrap_or(0.0);
            out.push(JointState {
                stamp_s,
                ..self.states[i].clone()
            });
            if self.cursor.step(self.states.len()) {
                self.laps += 1;
            }
        }
        out
    }

    fn send(&mut self, qdot: &DVector<f64>) -> Result<(), RobotError> {
        if let Some(i) = qdot.iter().position(|v| !v.is_finite()) {
            return Err(self.refuse(format!("joint {i}'s velocity {} is not finite", qdot[i])));
        }
        self.commands += 1;
        Ok(())
    }

    fn gripper(&mut self, command: &GripperCommand) -> Result<(), RobotError> {
        if !command.force_n.is_finite() {
            return Err(self.refuse(format!("gripper force {} is not finite", command.force_n)));
        }
        Ok(())
    }

    fn advance(&mut self, now_s: f64) {
        self.clock = Some((now_s, Instant::now()));
    }

    fn status_line(&self) -> Option<String> {
        Some(format!(
            "{}: a recording played ({} laps of {:.1} s); {} commands not obeyed",
            self.name,
            self.laps,
            self.playback.lap_s(),
            self.commands
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(t: f64, q: f64) -> JointState {
        JointState {
            stamp_s: t,
            positions: DVector::from_element(2, q),
            velocities: DVector::zeros(0),
        }
    }

    #[test]
    fn a_timeline_is_released_at_its_stamps_lap_after_lap() {
        let start = Instant::now();
        let stamps = [10.0, 10.1, 10.2];
        let p = Playback::new("test", start, &stamps).expect("valid");
        assert!((p.lap_s() - 0.3).abs() < 1e-12);
        let mut c = PlaybackCursor::default();
        // At 0.15 s: samples 0 and 1 are due, 0 skipped.
        let d = p
            .due(&stamps, &mut c, start + Duration::from_millis(150))
            .expect("due");
        assert_eq!((d.index, d.lap, d.skipped), (1, 0, 1));
        assert_eq!(d.at, start + Duration::from_millis(100));
        assert!(
            p.due(&stamps, &mut c, start + Duration::from_millis(150))
                .is_none()
        );
        // The second lap's first sample at 0.3 s.
        let d = p
            .due(&stamps, &mut c, start + Duration::from_millis(301))
            .expect("due");
        assert_eq!((d.index, d.lap, d.skipped), (0, 1, 1));
        assert!(Playback::new("test", start, &[]).is_err());
        let e = Playback::new("test", start, &[0.0, 0.2, 0.1]).expect_err("order");
        assert!(e.to_string().contains("test: stamp 2"), "{e}");
        assert!(Playback::new("test", start, &[0.0, f64::NAN]).is_err());
    }

    #[test]
    fn the_recorded_arm_reports_its_joints_on_the_caller_s_clock_and_obeys_nothing() {
        let start = Instant::now();
        let states = vec![state(5.0, 0.1), state(5.01, 0.2), state(5.02, 0.3)];
        let p = Playback::new("test", start, &[5.0, 5.01, 5.02]).expect("valid");
        let mut arm = RecordedArm::new("rec", states, p).expect("valid");
        // Nothing before the clock is known.
        assert!(arm.receive().is_empty());
        std::thread::sleep(Duration::from_millis(25));
        arm.advance(100.0);
        let got = arm.receive();
        assert_eq!(got.len(), 3, "{got:?}");
        assert!((got[1].positions[0] - 0.2).abs() < 1e-12);
        // Velocities by central differences: 0.1 rad in 10 ms.
        assert!((got[1].velocities[0] - 10.0).abs() < 1e-9, "{got:?}");
        // Sample 1 was released 10 ms after the start; the clock read 100 s about 25 ms after.
        let d = got[1].stamp_s - got[0].stamp_s;
        assert!((d - 0.01).abs() < 1e-6, "{d}");
        assert!(got[2].stamp_s <= 100.0 && got[0].stamp_s > 99.9, "{got:?}");
        // A caller late by more than a lap (30 ms) gets only what was released in the last
        // lap, stamped as released: at most a lap old.
        std::thread::sleep(Duration::from_millis(75));
        arm.advance(200.0);
        let late = arm.receive();
        assert!((1..=3).contains(&late.len()), "{late:?}");
        assert!(
            late.iter()
                .all(|s| s.stamp_s > 200.0 - 0.031 && s.stamp_s <= 200.0),
            "{late:?}"
        );
        let ok = DVector::from_element(2, 0.1);
        arm.send(&ok).expect("a command is taken");
        let bad = DVector::from_vec(vec![0.0, f64::NAN]);
        let e = arm.send(&bad).expect_err("NaN");
        assert!(e.to_string().contains("joint 1"), "{e}");
        assert_eq!(arm.commands(), 1);
        assert!(arm.status_line().is_some_and(|s| s.contains("1 commands")));
        let uneven = vec![
            state(0.0, 0.0),
            JointState {
                positions: DVector::zeros(3),
                ..state(0.1, 0.0)
            },
        ];
        assert!(RecordedArm::new("rec", uneven, p).is_err());
    }
}
