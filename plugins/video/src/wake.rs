//! An app woken by its camera: the sources read on threads of their own ([`crate::threaded`])
//! ring a [`FrameWake`] with each frame they send, and [`FrameDrivenRunnerPlugin`]'s runner
//! starts the next update as soon as one arrives (or after a longest wait without frames), so
//! a frame waits for no fixed schedule before it is taken, erased and handed on (the robot
//! site's real-time path, docs/latency.md).

use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant};

use bevy::app::PluginsState;
use bevy::prelude::*;

/// Counts the frames sent to the app and wakes whoever waits for the next.
#[derive(Resource, Clone, Debug, Default)]
pub struct FrameWake(Arc<(Mutex<u64>, Condvar)>);

impl FrameWake {
    /// The app's (inserted if there is none yet): the one its sources ring and its runner
    /// waits on.
    pub fn of(app: &mut App) -> Self {
        app.world_mut()
            .get_resource_or_insert_with(FrameWake::default)
            .clone()
    }

    /// A frame was sent.
    pub fn notify(&self) {
        let (count, ready) = &*self.0;
        *count.lock().unwrap_or_else(PoisonError::into_inner) += 1;
        ready.notify_all();
    }

    /// Frames sent so far.
    pub fn count(&self) -> u64 {
        *self.0.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Waits until more than `seen` frames were sent, or `timeout` passes; the count then.
    pub fn wait_after(&self, seen: u64, timeout: Duration) -> u64 {
        let (count, ready) = &*self.0;
        let guard = count.lock().unwrap_or_else(PoisonError::into_inner);
        let (guard, _) = ready
            .wait_timeout_while(guard, timeout, |c| *c <= seen)
            .unwrap_or_else(PoisonError::into_inner);
        *guard
    }
}

/// The app's runner: an update when a frame arrives (at once if one arrived during the last
/// update), else after `max_wait`; never two updates closer than `min_period` (a source that
/// floods does not spin the app). Inserts a [`FrameWake`] for the sources to ring.
#[derive(Debug, Clone, Copy)]
pub struct FrameDrivenRunnerPlugin {
    /// The longest time between two updates: the camera's frame period keeps the app running
    /// at its rate when frames stop.
    pub max_wait: Duration,
    /// The shortest time from one update's start to the next's.
    pub min_period: Duration,
}

impl Plugin for FrameDrivenRunnerPlugin {
    fn build(&self, app: &mut App) {
        let wake = FrameWake::of(app);
        let Self {
            max_wait,
            min_period,
        } = *self;
        app.set_runner(move |mut app: App| {
            if app.plugins_state() != PluginsState::Cleaned {
                while app.plugins_state() == PluginsState::Adding {
                    bevy::tasks::tick_global_task_pools_on_main_thread();
                }
                app.finish();
                app.cleanup();
            }
            let mut seen = wake.count();
            loop {
                let started = Instant::now();
                app.update();
                if let Some(exit) = app.should_exit() {
                    return exit;
                }
                if let Some(rest) = (started + min_period).checked_duration_since(Instant::now()) {
                    std::thread::sleep(rest);
                }
                seen = wake.wait_after(seen, max_wait);
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_waiter_wakes_at_a_frame_or_at_its_timeout() {
        let wake = FrameWake::default();
        let started = Instant::now();
        assert_eq!(wake.wait_after(0, Duration::from_millis(30)), 0);
        assert!(started.elapsed() >= Duration::from_millis(30));
        // A frame sent before the wait: no wait at all.
        wake.notify();
        let started = Instant::now();
        assert_eq!(wake.wait_after(0, Duration::from_secs(30)), 1);
        assert!(started.elapsed() < Duration::from_secs(10));
        // A frame sent while waiting wakes the waiter.
        let ringer = wake.clone();
        let thread = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            ringer.notify();
        });
        let started = Instant::now();
        assert_eq!(wake.wait_after(1, Duration::from_secs(30)), 2);
        assert!(started.elapsed() < Duration::from_secs(10));
        thread.join().expect("the ringer");
    }
}
