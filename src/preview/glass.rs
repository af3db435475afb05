//! Glass to glass in the preview, live: each camera frame the erase takes is stamped again when
//! the window's frame that first shows it is presented (the render world, after the present),
//! and the status line shows capture → presented.
//!
//! The capture stamp is on the app's fixed clock (`Time<Fixed>`, the video sources'
//! convention), so a frame's age when the erase takes it can read up to one fixed step short;
//! taken → presented is the wall clock's. Only where the app runs on the wall clock (not with
//! `--step-ms` or `--frames`, whose simulated time is not the wall's). The display's own
//! scan-out and response come after the present and are not measured.

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

    /// The status line's words, empty before the first presented frame.
    pub fn line(&self) -> String {
        self.recent().map_or_else(String::new, |(last, median)| {
            format!("\nglass to glass (capture -> presented) {last:5.1} ms, median {median:5.1} ms")
        })
    }
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
                .add_systems(Render, stamp_presented.in_set(RenderSystems::Cleanup));
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
/// to is on the display's way now (each frame once).
fn stamp_presented(
    taken: Option<Res<TakenFrame>>,
    record: Res<GlassToGlass>,
    mut last: Local<u64>,
) {
    let Some(t) = taken.and_then(|t| t.0) else {
        return;
    };
    if t.number <= *last {
        return;
    }
    *last = t.number;
    let display_ms = t.at.elapsed().as_secs_f64() * 1e3;
    let mut s = record.series();
    Spread::push(&mut s.display_ms, display_ms);
    Spread::push(&mut s.glass_ms, t.age_ms + display_ms);
}

/// One line when the app exits (Escape, the window closed): the frames' glass to glass.
fn say_at_exit(mut exits: MessageReader<AppExit>, record: Res<GlassToGlass>) {
    if exits.read().next().is_none() {
        return;
    }
    let s = record.spread();
    if s.n > 0 {
        info!(
            "preview: glass to glass (capture -> presented) median {:.1} ms, p95 {:.1} ms over {} frames",
            s.median, s.p95, s.n
        );
    }
}
