//! The app's real-time integration tests, in a binary of their own: two sites as processes
//! through the impairment relay ([`network`]), over a secure link with access control
//! ([`secure`]), the real frame path from a recorded camera and
//! its stage stamps ([`latency`]), the live drift watch of a bumped camera ([`drift`]), and XR
//! against a real OpenXR runtime ([`xr`]).
//! Their processes run on the wall clock, so they run one at a time and apart from the
//! replays (cargo runs test binaries one after another).

#[path = "../support/mod.rs"]
#[expect(
    dead_code,
    reason = "PyPI's MCAP reader is the app binary's; this one prints only"
)]
mod support;

mod drift;
mod latency;
mod network;
mod secure;
mod xr;

/// One test at a time: each runs real-time processes (the robot site's control loop, its
/// renderer, an OpenXR runtime) whose timing the others' load would disturb on a small
/// machine.
fn serial() -> std::sync::MutexGuard<'static, ()> {
    static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}
