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

/// Capture → presented of the frames shown so far (ms), shared with the render world.
#[derive(Resource, Clone, Default)]
pub struct GlassToGlass(Arc<Mutex<Vec<f64>>>);

impl GlassToGlass {
    /// The newest frame's and the median of the last [`RECENT`] (ms), once one was presented.
    pub fn recent(&self) -> Option<(f64, f64)> {
        let all = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        let recent = &all[all.len().saturating_sub(RECENT)..];
        Some((*recent.last()?, Spread::of(recent).median))
    }

    /// Adds a frame's capture → presented (ms).
    pub fn push(&self, ms: f64) {
        Spread::push(
            &mut self.0.lock().unwrap_or_else(PoisonError::into_inner),
            ms,
        );
    }

    /// All of them (ms).
    pub fn spread(&self) -> Spread {
        Spread::of(&self.0.lock().unwrap_or_else(PoisonError::into_inner))
    }

    /// The status line's words, empty before the first presented frame.
    pub fn line(&self) -> String {
        self.recent().map_or_else(String::new, |(last, median)| {
            format!("\nglass to glass (capture -> presented) {last:5.1} ms, median {median:5.1} ms")
        })
    }
}

/// The camera frame the erase took in this update, extracted to the render world.
#[derive(Resource, Clone, Copy, Default, ExtractResource)]
struct TakenFrame(Option<Taken>);

#[derive(Clone, Copy)]
struct Taken {
    /// The erase's frame count when it took it.
    number: u64,
    /// When (wall clock).
    at: Instant,
    /// Its age then (ms): the fixed clock now less its capture stamp.
    age_ms: f64,
}

/// Stamps the frames the erase takes and their present; [`GlassToGlass`] holds the result.
pub struct GlassToGlassPlugin;

impl Plugin for GlassToGlassPlugin {
    fn build(&self, app: &mut App) {
        let record = GlassToGlass::default();
        app.insert_resource(record.clone())
            .init_resource::<TakenFrame>()
            .add_plugins(ExtractResourcePlugin::<TakenFrame>::default())
            .add_systems(Update, note_taken.after(EraseSystems::Prepare))
            .add_systems(Last, say_at_exit);
        if let Some(render) = app.get_sub_app_mut(RenderApp) {
            render
                .insert_resource(record)
                .add_systems(Render, stamp_presented.in_set(RenderSystems::Cleanup));
        }
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
    record.push(t.age_ms + t.at.elapsed().as_secs_f64() * 1e3);
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
