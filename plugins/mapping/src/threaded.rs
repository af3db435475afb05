//! The robot side of the control loop on a thread of its own, at the control rate, whatever the
//! app's updates cost ([`Teleop::on_control_thread`]).
//!
//! `avatarm run` steps the hand, the physics and the operator's side of the mapping in the app's
//! `FixedUpdate`. When an update takes longer than a control period (a software renderer, a
//! 1080p window), Bevy runs the missed fixed steps back to back: a robot ticked there gets its
//! commands in bursts and its link is judged by the app's clock (a joint state that arrived
//! during a slow update is read only after it, so the link looks down). On this thread the
//! robot, the mapping's robot side ([`avatarm_core::teleop::mapping::Mapper::robot_side`]), the
//! limiter and the watchdog run every period on the wall clock, as the robot site's control loop
//! of `avatarm serve` does: the app hands over the newest operator target
//! ([`crate::TickSource::Remote`]) and takes back the joint states, the ticks' log and the
//! counters.
//!
//! Clocks: the thread ticks on seconds since its start (its epoch). A target's stamps (the
//! app's clock, `Time<Fixed>`) are moved onto the thread's clock by the offset between the two
//! at hand-over; joint states and log samples come back moved by the offset at take-back (the
//! joint states kept in order where the app's clock lost time against the wall's). A
//! target that was not renewed within three periods keeps its pose but loses its twist (the
//! arm is not driven on at the last velocity while the app is slow); the hand's watchdog
//! ([`avatarm_core::teleop::safety::SafetySettings::timeout_s`]) stops the arm when the
//! operator's hand data grow older than its timeout on the wall clock.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use avatarm_core::sim::JointState;
use avatarm_core::sim::arm::{RobotError, RobotInterface};
use avatarm_core::stats::Spread;
use avatarm_core::teleop::mapping::GripperCommand;
use nalgebra::{DVector, Isometry3};

use crate::{MappingError, RemoteTarget, Teleop, TeleopSample, TeleopStatus, TickSource};

/// Most joint states and log samples kept for an app that does not take them (about a minute
/// at 100 Hz); the oldest beyond are dropped and counted ([`ThreadStats::dropped`]).
const MAX_KEPT: usize = 6_000;

/// A target not renewed within this many control periods loses its twist (its pose is kept):
/// a stream that stopped does not drive the arm on at its last velocity until the watchdog.
pub const FRESH_PERIODS: f64 = 3.0;

/// A control loop's schedule: a tick every period on the wall clock; a tick that comes more than
/// a period late (the machine stalled) restarts the schedule from then rather than running the
/// missed ticks back to back. Shared by `avatarm serve`'s loop and [`Teleop::on_control_thread`].
#[derive(Debug, Clone, Copy)]
pub struct Ticker {
    period: Duration,
    next_due: Instant,
}

impl Ticker {
    /// Ticks every `period` from now.
    pub fn new(period: Duration) -> Self {
        Self {
            period,
            next_due: Instant::now(),
        }
    }

    /// Sleeps until the next tick is due; `true` when it came late (the schedule restarted).
    pub fn wait(&mut self) -> bool {
        std::thread::sleep(self.next_due.saturating_duration_since(Instant::now()));
        self.next_due += self.period;
        let late = self.next_due < Instant::now();
        if late {
            self.next_due = Instant::now() + self.period;
        }
        late
    }
}

/// The control thread's timing, for the status line and the run's summary.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ThreadStats {
    /// The period asked for (ms).
    pub period_ms: f64,
    /// Tick-to-tick intervals as run (ms).
    pub intervals_ms: Spread,
    /// Ticks that started more than a period late (the machine stalled the thread).
    pub late_ticks: u64,
    /// Targets the app handed over (ticks whose operator side gave one).
    pub targets: u64,
    /// Joint states and log samples dropped because the app did not take them in time.
    pub dropped: u64,
}

impl ThreadStats {
    /// One line: the rate as run.
    pub fn line(&self) -> String {
        format!(
            "control thread: a tick every {:.1} ms median (asked {:.1} ms; p95 {:.1}, max {:.1}), {} late",
            self.intervals_ms.median,
            self.period_ms,
            self.intervals_ms.p95,
            self.intervals_ms.max,
            self.late_ticks
        )
    }
}

/// What the app and the thread exchange, under one lock taken briefly once a tick by each.
#[derive(Default)]
struct Exchange {
    /// The newest target and when it was handed over (s, thread clock); `None`: no valid
    /// target (the operator's side failed or nothing was handed over yet).
    target: Option<(RemoteTarget, f64)>,
    received: Vec<JointState>,
    log: Vec<TeleopSample>,
    status: TeleopStatus,
    status_line: Option<String>,
    true_object: Option<Isometry3<f64>>,
    intervals_ms: Vec<f64>,
    stats: ThreadStats,
    /// Why the thread ended early, if it did.
    ended: Option<String>,
    /// The newest joint state's stamp handed to the app (s, the app's clock).
    taken_stamp_s: f64,
}

fn lock(x: &Mutex<Exchange>) -> MutexGuard<'_, Exchange> {
    x.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The app's handle on the control thread: owned by the app's [`Teleop`], which hands targets
/// over and takes the results back in [`Teleop::tick`]. Dropping it stops the thread and waits
/// for it, so that the robot's own stop (its interface's `Drop`) goes out before the app exits.
pub(crate) struct ControlThread {
    exchange: Arc<Mutex<Exchange>>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    /// The robot's side and the period, until the app's first tick starts the thread: a real arm
    /// does not move (its approach to the start) before the app runs.
    pending: Option<(Box<Teleop>, Duration)>,
    epoch: Instant,
}

impl ControlThread {
    /// Seconds on the thread's clock now.
    fn now_s(&self) -> f64 {
        self.epoch.elapsed().as_secs_f64()
    }

    /// Starts the thread if it has not started (the app's first tick). Errors when the system
    /// cannot start a thread.
    fn start(&mut self) -> Result<(), String> {
        let Some((back, period)) = self.pending.take() else {
            return Ok(());
        };
        self.epoch = Instant::now();
        let (exchange, stop, epoch) = (self.exchange.clone(), self.stop.clone(), self.epoch);
        let handle = std::thread::Builder::new()
            .name("avatarm-control".into())
            .spawn(move || {
                let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    run(*back, period, epoch, &exchange, &stop);
                }));
                if let Err(panic) = ran {
                    // The robot was dropped while unwinding: its stop went out.
                    let why = panic
                        .downcast_ref::<&str>()
                        .map(|s| (*s).to_owned())
                        .or_else(|| panic.downcast_ref::<String>().cloned())
                        .unwrap_or_else(|| "a panic".into());
                    lock(&exchange).ended = Some(why);
                }
            })
            .map_err(|e| format!("the control thread did not start: {e}"))?;
        self.handle = Some(handle);
        Ok(())
    }

    /// Hands over the operator's side of a tick computed at `app_now_s` (the app's clock), or
    /// `None` when it failed; returns the offset (thread clock minus the app's, s).
    pub(crate) fn hand_over(&self, app_now_s: f64, target: Option<RemoteTarget>) -> f64 {
        let now = self.now_s();
        let offset = now - app_now_s;
        let mut x = lock(&self.exchange);
        x.stats.targets += u64::from(target.is_some());
        x.target = target.map(|mut t| {
            // Never stamped ahead of the thread's clock (the watchdog's age is never negative).
            t.target.stamp_s = (t.target.stamp_s + offset).min(now);
            t.hand_stamp_s = (t.hand_stamp_s + offset).min(now);
            (t, now)
        });
        offset
    }

    /// Moves what the thread produced since the last call into the app's `teleop` (the
    /// thread's clock moved onto the app's by `offset`): joint states into
    /// [`Teleop::received`], log samples into [`Teleop::log`] (kept only when it records), the
    /// counters into [`Teleop::status`].
    pub(crate) fn take_back(&self, teleop: &mut FrontState<'_>, offset: f64) {
        let mut x = lock(&self.exchange);
        teleop.received.clear();
        let mut newest = x.taken_stamp_s;
        for mut s in x.received.drain(..) {
            // An app whose clock loses time against the wall's (updates longer than Bevy's
            // largest step) would see the stamps step back at each take: kept in order.
            s.stamp_s = (s.stamp_s - offset).max(newest + 1e-6);
            newest = s.stamp_s;
            teleop.received.push(s);
        }
        x.taken_stamp_s = newest;
        if let Some(last) = teleop.received.last() {
            *teleop.joints = Some(last.clone());
        }
        for mut s in x.log.drain(..) {
            if teleop.record {
                s.t_s -= offset;
                if let Some(op) = &mut s.operator {
                    op.stamp_s -= offset;
                }
                teleop.log.push(s);
            }
        }
        let (own, own_last) = teleop.front_errors;
        *teleop.status = TeleopStatus {
            errors: x.status.errors + own,
            last_error: x.status.last_error.clone().or_else(|| own_last.clone()),
            ..x.status.clone()
        };
    }

    /// The thread's timing so far.
    pub(crate) fn stats(&self) -> ThreadStats {
        let x = lock(&self.exchange);
        ThreadStats {
            intervals_ms: Spread::of(&x.intervals_ms),
            ..x.stats.clone()
        }
    }

    /// Why the thread ended before the app, if it did.
    pub(crate) fn ended(&self) -> Option<String> {
        lock(&self.exchange).ended.clone()
    }
}

impl Drop for ControlThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            // The thread catches its own panics (said in `ended`): joining cannot fail.
            let _ = h.join();
        }
    }
}

/// The parts of the app's [`Teleop`] that [`ControlThread::take_back`] fills.
pub(crate) struct FrontState<'a> {
    pub(crate) received: &'a mut Vec<JointState>,
    pub(crate) joints: &'a mut Option<JointState>,
    pub(crate) log: &'a mut Vec<TeleopSample>,
    pub(crate) status: &'a mut TeleopStatus,
    pub(crate) record: bool,
    /// The app's own refused ticks (its operator side failed) and the last reason.
    pub(crate) front_errors: &'a (u64, Option<String>),
}

/// The robot as the app's side sees it while the thread owns the real one: its name, its
/// status line and the object's true pose as the thread last saw them; it takes no command
/// (the thread sends them).
struct RobotOnThread {
    name: String,
    exchange: Arc<Mutex<Exchange>>,
}

impl RobotInterface for RobotOnThread {
    fn name(&self) -> &str {
        &self.name
    }

    fn receive(&mut self) -> Vec<JointState> {
        Vec::new()
    }

    fn send(&mut self, _: &DVector<f64>) -> Result<(), RobotError> {
        Err(RobotError {
            robot: self.name.clone(),
            message: "the robot is commanded by its control thread".into(),
        })
    }

    fn gripper(&mut self, _: &GripperCommand) -> Result<(), RobotError> {
        self.send(&DVector::zeros(0))
    }

    fn status_line(&self) -> Option<String> {
        let x = lock(&self.exchange);
        match &x.ended {
            Some(why) => Some(format!("CONTROL THREAD ENDED: {why}")),
            None => x.status_line.clone(),
        }
    }

    fn true_object_pose(&self) -> Option<Isometry3<f64>> {
        lock(&self.exchange).true_object
    }
}

impl Teleop {
    /// Moves this loop's robot, robot side of the mapping, limiter and watchdog onto a thread of
    /// their own that ticks every `period` on the wall clock (see the [module](self)); returns
    /// the app's side, whose [`Teleop::tick`] hands the operator's target over and takes the
    /// joint states, log and counters back. Errors when the period is not positive or the
    /// thread cannot start.
    pub fn on_control_thread(mut self, period: Duration) -> Result<Self, MappingError> {
        if period.is_zero() {
            return Err(MappingError::Setup {
                message: "control thread: the period must be > 0".into(),
            });
        }
        if self.thread.is_some() {
            return Err(MappingError::Setup {
                message: "control thread: this loop's robot side already runs on one".into(),
            });
        }
        let exchange = Arc::new(Mutex::new(Exchange {
            status: self.status.clone(),
            status_line: self.robot.status_line(),
            stats: ThreadStats {
                period_ms: period.as_secs_f64() * 1e3,
                ..ThreadStats::default()
            },
            taken_stamp_s: f64::NEG_INFINITY,
            ..Exchange::default()
        }));
        let front_robot = Box::new(RobotOnThread {
            name: self.robot.name().to_owned(),
            exchange: exchange.clone(),
        });
        let mut front = Self::with_robot_parts(&self, front_robot);
        self.record = true;
        front.thread = Some(ControlThread {
            exchange,
            stop: Arc::new(AtomicBool::new(false)),
            handle: None,
            pending: Some((Box::new(self), period)),
            epoch: Instant::now(),
        });
        Ok(front)
    }

    /// The control thread's timing, when the robot side runs on one
    /// ([`Teleop::on_control_thread`]).
    pub fn thread_stats(&self) -> Option<ThreadStats> {
        self.thread.as_ref().map(ControlThread::stats)
    }

    /// The app's side of a tick while a control thread drives the robot: the operator's side
    /// here (its failure counted), handed over; what the thread did since, taken back when
    /// `take_back` (the update's last fixed step: the app's clock then is the one the update's
    /// other inputs are stamped with). The first call starts the thread.
    pub(crate) fn front_tick(
        &mut self,
        now_s: f64,
        operator: Result<RemoteTarget, String>,
        take_back: bool,
    ) {
        let Some(thread) = &mut self.thread else {
            return;
        };
        if let Err(e) = thread.start() {
            lock(&thread.exchange).ended = Some(e);
        }
        let thread = &*thread;
        let target = match operator {
            Ok(t) => Some(t),
            Err(e) => {
                // Moving to the start the hand does not drive the arm yet; an empty reason is
                // no target received (nothing to refuse).
                if !(self.status.approaching || e.is_empty()) {
                    self.front_errors.0 += 1;
                    if self.front_errors.0 % 100 == 1 {
                        bevy::log::warn!(
                            "mapping: {e} ({} refused ticks so far); stopping the robot",
                            self.front_errors.0
                        );
                    }
                    self.front_errors.1 = Some(e);
                }
                None
            }
        };
        let offset = thread.hand_over(now_s, target);
        if !take_back {
            // Earlier fixed steps of an update: the states wait for its last one.
            self.received.clear();
            return;
        }
        thread.take_back(
            &mut FrontState {
                received: &mut self.received,
                joints: &mut self.joints,
                log: &mut self.log,
                status: &mut self.status,
                record: self.record,
                front_errors: &self.front_errors,
            },
            offset,
        );
        if let Some(why) = thread.ended() {
            self.status.last_error = Some(format!("the control thread ended: {why}"));
        }
    }
}

/// The thread: a tick every `period` until `stop` (a late tick restarts the schedule rather
/// than running the missed ones back to back), then the robot dropped (its own stop goes out).
fn run(
    mut teleop: Teleop,
    period: Duration,
    epoch: Instant,
    exchange: &Mutex<Exchange>,
    stop: &AtomicBool,
) {
    let dt = period.as_secs_f64();
    let mut ticker = Ticker::new(period);
    let mut last_tick: Option<Instant> = None;
    while !stop.load(Ordering::Relaxed) {
        let late = ticker.wait();
        let at = Instant::now();
        let now = at.saturating_duration_since(epoch).as_secs_f64();
        let target = lock(exchange)
            .target
            .map(|(t, handed_s)| t.freshened(now - handed_s, FRESH_PERIODS * dt));
        teleop.tick(now, dt, TickSource::Remote(target));
        // Asked of the robot before the lock: a link's status takes its own lock.
        let (status_line, true_object) = (
            teleop.robot().status_line(),
            teleop.robot().true_object_pose(),
        );
        let mut x = lock(exchange);
        if let Some(prev) = last_tick {
            Spread::push(&mut x.intervals_ms, (at - prev).as_secs_f64() * 1e3);
        }
        last_tick = Some(at);
        x.stats.late_ticks += u64::from(late);
        x.received.extend_from_slice(teleop.received());
        x.log.append(&mut teleop.log);
        // An app that stopped taking (paused, closing): the oldest go, counted.
        let (r, l) = (
            x.received.len().saturating_sub(MAX_KEPT),
            x.log.len().saturating_sub(MAX_KEPT),
        );
        if r + l > 0 {
            x.received.drain(..r);
            x.log.drain(..l);
            x.stats.dropped += (r + l) as u64;
        }
        x.status = teleop.status.clone();
        x.status_line = status_line;
        x.true_object = true_object;
    }
    drop(teleop);
}
