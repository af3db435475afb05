//! Glass to glass in the preview, live: each camera frame the erase takes is stamped again when
//! the window's frame that first shows it is presented (the render world, after the present),
//! and the status line shows capture → presented.
//!
//! The capture stamp is on the app's fixed clock (`Time<Fixed>`, the video sources'
//! convention), so a frame's age when the erase takes it can read up to one fixed step short;
//! taken → presented is the wall clock's. Only where the app runs on the wall clock (not with
//! `--step-ms` or `--frames`, whose simulated time is not the wall's). On a window, the display's
//! own scan-out and response come after the present and are not measured. In XR the frame is
//! stamped at the runtime's predicted display time for it (OpenXR 1.0,
//! `XrFrameState::predictedDisplayTime`, the time the frame is submitted for in `xrEndFrame`;
//! a frame late for it is stamped at the present), read against the runtime's clock at the
//! present through `XR_KHR_convert_timespec_time` (Windows:
//! `XR_KHR_win32_convert_performance_counter_time`) where the runtime grants it.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use avatarm_core::stats::Spread;
use avatarm_erase::{EraseState, EraseSystems};
use bevy::prelude::*;
use bevy::render::extract_resource::{ExtractResource, ExtractResourcePlugin};
use bevy::render::{Render, RenderApp, RenderSystems};

/// How many recent frames the live median is over.
const RECENT: usize = 30;

/// The frames presented so far, shared with the render world: capture → presented (ms) and
/// taken → presented (ms; taken: put before the view by the update that shows it).
#[derive(Resource, Clone, Default)]
pub struct GlassToGlass(Arc<Mutex<Series>>);

#[derive(Default)]
struct Series {
    glass_ms: Vec<f64>,
    display_ms: Vec<f64>,
    /// Capture → on the headset's display (ms) of those stamped there (XR).
    headset_glass_ms: Vec<f64>,
    /// Whether the newest was stamped at the headset's display.
    newest_on_headset: bool,
}

impl GlassToGlass {
    fn series(&self) -> std::sync::MutexGuard<'_, Series> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The newest frame's capture → presented and the median of the last [`RECENT`] (ms), once
    /// one was presented.
    pub fn recent(&self) -> Option<(f64, f64)> {
        let s = self.series();
        let recent = &s.glass_ms[s.glass_ms.len().saturating_sub(RECENT)..];
        Some((*recent.last()?, Spread::of(recent).median))
    }

    /// Capture → presented of all of them (ms).
    pub fn spread(&self) -> Spread {
        Spread::of(&self.series().glass_ms)
    }

    /// Taken → presented of all of them (ms).
    pub fn display_spread(&self) -> Spread {
        Spread::of(&self.series().display_ms)
    }

    /// Capture → on the headset's display (ms) of the frames stamped there (XR), not those
    /// the window alone showed (before a session, after it, or while it showed nothing).
    pub fn headset_spread(&self) -> Spread {
        Spread::of(&self.series().headset_glass_ms)
    }

    /// What the newest stamp ends at: `on the headset's display` (XR) or `presented`.
    fn end(&self) -> &'static str {
        if self.series().newest_on_headset {
            "on the headset's display"
        } else {
            "presented"
        }
    }

    /// What all stamps so far end at: `presented`, `on the headset's display`, or both where
    /// some were stamped at the window's present (before a session, after it) and some at the
    /// headset's display.
    fn end_of_all(&self) -> &'static str {
        let s = self.series();
        match (s.headset_glass_ms.len(), s.glass_ms.len()) {
            (0, _) => "presented",
            (on_headset, all) if on_headset == all => "on the headset's display",
            _ => "presented or on the headset's display",
        }
    }

    /// The status line's words, empty before the first presented frame.
    pub fn line(&self) -> String {
        self.recent().map_or_else(String::new, |(last, median)| {
            format!(
                "\nglass to glass (capture -> {}) {last:5.1} ms, median {median:5.1} ms",
                self.end()
            )
        })
    }
}

/// In XR, in the render world: when the headset shows the frame this render submitted, for
/// the video frame [`TakenFrame`] numbers `frame`. `None` where this render has no new video
/// frame to stamp, submitted nothing to the headset (no session, one stopping, or the runtime
/// said not to render), or the runtime did not grant the time conversion extension. Set
/// before [`stamp_presented`] each render, which uses it only for the same frame.
#[derive(Resource, Clone, Copy, Default, Debug, PartialEq)]
pub struct XrDisplayAhead(pub Option<HeadsetDisplay>);

/// The headset's display of one video frame, read against the wall clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadsetDisplay {
    /// The video frame's number ([`Taken::number`]).
    pub frame: u64,
    /// Seconds after `at` that the headset shows it: the XR frame's predicted display time
    /// less the runtime's clock read at `at` (both OpenXR `XrTime`, ns; [`display_ahead_s`]).
    pub ahead_s: f64,
    /// When the runtime's clock was read (wall clock).
    pub at: Instant,
}

/// Whether the OpenXR extension that reads the runtime's clock (`XrTime`) against the
/// system's is in an extension set: `XR_KHR_convert_timespec_time` (`CLOCK_MONOTONIC`), on
/// Windows `XR_KHR_win32_convert_performance_counter_time` (OpenXR 1.0 extensions). The
/// headset's display stamps (this module's) need it; a runtime without it is used without.
#[cfg(feature = "xr")]
pub trait ClockConversion {
    /// Whether the set holds it (asked for, or granted: the enabled set, the instance).
    fn has_clock_conversion(&self) -> bool;
}

#[cfg(feature = "xr")]
impl ClockConversion for bevy_mod_openxr::exts::OxrExtensions {
    fn has_clock_conversion(&self) -> bool {
        #[cfg(not(windows))]
        let has = self.khr_convert_timespec_time;
        #[cfg(windows)]
        let has = self.khr_win32_convert_performance_counter_time;
        has
    }
}

/// The instance's: what the runtime granted.
#[cfg(feature = "xr")]
impl ClockConversion for bevy_mod_openxr::resources::OxrInstance {
    fn has_clock_conversion(&self) -> bool {
        #[cfg(not(windows))]
        let has = self.exts().khr_convert_timespec_time.is_some();
        #[cfg(windows)]
        let has = self
            .exts()
            .khr_win32_convert_performance_counter_time
            .is_some();
        has
    }
}

/// Asks for the clock conversion extension ([`ClockConversion`]) in `exts`, an instance's
/// requested set.
#[cfg(feature = "xr")]
pub fn request_clock_conversion(exts: &mut bevy_mod_openxr::exts::OxrExtensions) {
    #[cfg(not(windows))]
    {
        exts.khr_convert_timespec_time = true;
    }
    #[cfg(windows)]
    {
        exts.khr_win32_convert_performance_counter_time = true;
    }
}

/// Seconds from `now_ns` to `display_ns` (the same clock, ns), 0 where the display time has
/// passed: a frame late for its predicted display is shown at the earliest now.
pub fn display_ahead_s(display_ns: i64, now_ns: i64) -> f64 {
    display_ns.saturating_sub(now_ns).max(0) as f64 / 1e9
}

/// [`XrDisplayAhead`] from the extracted XR frame state (`OxrFrameState`, the one `xrEndFrame`
/// was given when the frame loop ran and the runtime asked for a render: bevy_mod_openxr's own
/// conditions) and the runtime's clock (`Instance::now`, which needs the conversion extension:
/// checked first, as it would panic without it). The frame state stays after a session ends,
/// so the conditions are read each render. Only in a render with a frame to stamp (a
/// [`TakenFrame`] not seen before; [`stamp_presented`] stamps each once too): the clock is not
/// read for renders that show no new frame.
#[cfg(feature = "xr")]
fn xr_display_ahead(
    frame: Option<Res<bevy_mod_openxr::resources::OxrFrameState>>,
    instance: Option<Res<bevy_mod_openxr::resources::OxrInstance>>,
    started: Option<Res<bevy_mod_openxr::resources::OxrSessionStarted>>,
    state: Option<Res<bevy_mod_xr::session::XrState>>,
    taken: Option<Res<TakenFrame>>,
    mut ahead: ResMut<XrDisplayAhead>,
    mut last: Local<u64>,
) {
    ahead.0 = None;
    let video = match taken.and_then(|t| t.0) {
        Some(t) if t.number > *last => t.number,
        _ => return,
    };
    *last = video;
    let submitted = bevy_mod_openxr::init::should_run_frame_loop(started, state);
    let frame = frame.filter(|f| submitted && f.should_render);
    ahead.0 = frame.zip(instance).and_then(|(frame, instance)| {
        if !instance.has_clock_conversion() {
            return None;
        }
        let now = instance.now().ok()?;
        Some(HeadsetDisplay {
            frame: video,
            ahead_s: display_ahead_s(frame.predicted_display_time.as_nanos(), now.as_nanos()),
            at: Instant::now(),
        })
    });
}

/// The frame put before the view in this update, extracted to the render world, which stamps
/// it when the window's frame that shows it is presented (each frame once).
#[derive(Resource, Clone, Copy, Default, ExtractResource)]
pub struct TakenFrame(pub Option<Taken>);

/// A frame put before the view.
#[derive(Debug, Clone, Copy)]
pub struct Taken {
    /// Counts the frames taken (a frame is stamped once, by its number).
    pub number: u64,
    /// When it was taken (wall clock).
    pub at: Instant,
    /// Its age then (ms): capture → taken.
    pub age_ms: f64,
}

/// The present stamp: [`TakenFrame`] extracted to the render world, and [`GlassToGlass`] filled
/// after each present. Whoever shows the frames sets [`TakenFrame`] (the preview's erase,
/// [`PreviewGlassPlugin`]; the operator's window).
pub struct GlassToGlassPlugin;

impl Plugin for GlassToGlassPlugin {
    fn build(&self, app: &mut App) {
        let record = GlassToGlass::default();
        app.insert_resource(record.clone())
            .init_resource::<TakenFrame>()
            .add_plugins(ExtractResourcePlugin::<TakenFrame>::default());
        if let Some(render) = app.get_sub_app_mut(RenderApp) {
            render
                .insert_resource(record)
                .init_resource::<XrDisplayAhead>()
                .add_systems(Render, stamp_presented.in_set(RenderSystems::Cleanup));
            #[cfg(feature = "xr")]
            render.add_systems(
                Render,
                xr_display_ahead
                    .in_set(RenderSystems::Cleanup)
                    .before(stamp_presented),
            );
        }
    }
}

/// The preview's glass to glass: the frames its erase takes, and a line at exit.
pub struct PreviewGlassPlugin;

impl Plugin for PreviewGlassPlugin {
    fn build(&self, app: &mut App) {
        app.add_plugins(GlassToGlassPlugin)
            .add_systems(Update, note_taken.after(EraseSystems::Prepare))
            .add_systems(Last, say_at_exit);
    }
}

fn note_taken(
    erase: Res<EraseState>,
    time: Res<Time<Fixed>>,
    mut taken: ResMut<TakenFrame>,
    mut last: Local<u64>,
) {
    let (Some(capture_s), true) = (erase.frame_capture_s, erase.frames_in > *last) else {
        return;
    };
    *last = erase.frames_in;
    taken.0 = Some(Taken {
        number: erase.frames_in,
        at: Instant::now(),
        age_ms: ((time.elapsed_secs_f64() - capture_s) * 1e3).max(0.0),
    });
}

/// In the render world, after the present: the frame taken in the update this render belongs
/// to is on the display's way now, or in XR shown by the headset [`XrDisplayAhead`] later
/// (each frame once).
fn stamp_presented(
    taken: Option<Res<TakenFrame>>,
    record: Res<GlassToGlass>,
    ahead: Res<XrDisplayAhead>,
    mut last: Local<u64>,
) {
    let Some(t) = taken.and_then(|t| t.0) else {
        return;
    };
    if t.number <= *last {
        return;
    }
    *last = t.number;
    // The headset's display of this frame (its clock read at `at`), or the window's now.
    let headset = ahead.0.filter(|d| d.frame == t.number);
    let (after_s, at) = headset.map_or_else(|| (0.0, Instant::now()), |d| (d.ahead_s, d.at));
    let display_ms = (at.saturating_duration_since(t.at).as_secs_f64() + after_s) * 1e3;
    let mut s = record.series();
    s.newest_on_headset = headset.is_some();
    if headset.is_some() {
        Spread::push(&mut s.headset_glass_ms, t.age_ms + display_ms);
    }
    Spread::push(&mut s.display_ms, display_ms);
    Spread::push(&mut s.glass_ms, t.age_ms + display_ms);
}

/// One line when the app exits (Escape, the window closed): the frames' glass to glass.
fn say_at_exit(mut exits: MessageReader<AppExit>, record: Res<GlassToGlass>) {
    if exits.read().next().is_none() {
        return;
    }
    let s = record.spread();
    if s.n == 0 {
        return;
    }
    let headset = record.headset_spread();
    // Where the frames end at both, the headset's own figure beside all of them.
    let on_headset = if headset.n > 0 && headset.n < s.n {
        format!(
            "; the {} on the headset's display median {:.1} ms, p95 {:.1} ms",
            headset.n, headset.median, headset.p95
        )
    } else {
        String::new()
    };
    info!(
        "preview: glass to glass (capture -> {}) median {:.1} ms, p95 {:.1} ms over {} frames{on_headset}",
        record.end_of_all(),
        s.median,
        s.p95,
        s.n
    );
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn the_display_ahead_is_the_predicted_time_less_now_and_never_negative() {
        assert_eq!(display_ahead_s(1_011_000_000, 1_000_000_000), 0.011);
        assert_eq!(display_ahead_s(1_000_000_000, 1_011_000_000), 0.0);
        assert_eq!(display_ahead_s(i64::MIN, i64::MAX), 0.0);
    }

    /// A frame taken 10 ms before the headset's clock was read, in XR shown 11 ms after that
    /// reading: taken → shown is 21 ms (from the two instants, not timed), capture → shown 26
    /// ms, the frame is counted at the headset, and the line says so; without XR the same frame
    /// ends at the present, at least 10 ms after it was taken.
    #[test]
    fn in_xr_a_frame_is_stamped_when_the_headset_shows_it() {
        let stamp = |ahead: Option<f64>| {
            let mut world = World::new();
            let record = GlassToGlass::default();
            let read_at = Instant::now();
            world.insert_resource(record.clone());
            world.insert_resource(XrDisplayAhead(ahead.map(|ahead_s| HeadsetDisplay {
                frame: 1,
                ahead_s,
                at: read_at,
            })));
            world.insert_resource(TakenFrame(Some(Taken {
                number: 1,
                at: read_at
                    .checked_sub(Duration::from_millis(10))
                    .expect("a clock 10 ms old"),
                age_ms: 5.0,
            })));
            // One system, run for two renders of the same update: each frame once.
            let system = world.register_system(stamp_presented);
            for _ in 0..2 {
                world.run_system(system).expect("the system runs");
            }
            record
        };
        let xr = stamp(Some(0.011));
        assert_eq!(xr.display_spread().n, 1);
        assert!(
            (xr.display_spread().median - 21.0).abs() < 1e-6,
            "{:?}",
            xr.display_spread()
        );
        assert!(
            (xr.spread().median - 26.0).abs() < 1e-6,
            "{:?}",
            xr.spread()
        );
        assert_eq!(xr.headset_spread().n, 1);
        assert!(
            xr.line().contains("capture -> on the headset's display"),
            "{}",
            xr.line()
        );
        assert_eq!(xr.end_of_all(), "on the headset's display");
        let window = stamp(None);
        assert_eq!(window.end_of_all(), "presented");
        assert_eq!(window.headset_spread().n, 0);
        assert!(window.display_spread().median >= 10.0);
        assert!(
            window.line().contains("capture -> presented)"),
            "{}",
            window.line()
        );
    }

    /// Frames at the headset's display, then ones the window alone showed (the session ended,
    /// or a headset time read for another frame): the newest ends at the present, all of them
    /// at both, the headset's own spread has its 2.
    #[test]
    fn a_run_that_left_xr_says_both_ends() {
        let mut world = World::new();
        let record = GlassToGlass::default();
        world.insert_resource(record.clone());
        let system = world.register_system(stamp_presented);
        for (number, ahead) in [(1, Some(0.011)), (2, Some(0.011)), (3, None)] {
            world.insert_resource(XrDisplayAhead(ahead.map(|ahead_s| HeadsetDisplay {
                frame: number,
                ahead_s,
                at: Instant::now(),
            })));
            world.insert_resource(TakenFrame(Some(Taken {
                number,
                at: Instant::now(),
                age_ms: 5.0,
            })));
            world.run_system(system).expect("the system runs");
        }
        // The headset's time for another frame is not this one's: frame 4 ends at the present.
        world.insert_resource(XrDisplayAhead(Some(HeadsetDisplay {
            frame: 3,
            ahead_s: 0.011,
            at: Instant::now(),
        })));
        world.insert_resource(TakenFrame(Some(Taken {
            number: 4,
            at: Instant::now(),
            age_ms: 5.0,
        })));
        world.run_system(system).expect("the system runs");
        assert_eq!(record.spread().n, 4);
        assert_eq!(record.headset_spread().n, 2);
        assert!(record.headset_spread().median >= 16.0);
        assert_eq!(record.end_of_all(), "presented or on the headset's display");
        assert!(
            record.line().contains("capture -> presented)"),
            "{}",
            record.line()
        );
    }
}
