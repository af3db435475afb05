//! GPU time of named spans of a frame's work, measured with timestamp queries: every camera
//! that carries [`GpuTimed`] (its whole render) and any span a render-world system opens with
//! [`GpuClock::begin`] and closes with [`GpuClock::end`] (the flat silhouettes of
//! [`crate::flat`], the erase passes).
//!
//! A camera is rendered by running its `Core3d` schedule: a system before its first system (the
//! GPU preprocessing's, then the prepass) writes a timestamp into the command stream and one
//! after its last (post-processing, then the upscaling copy into the target) writes another;
//! the pair's difference is the GPU time of that camera's render (culling, clear, draws,
//! post-processing and the copy into its target). Bevy's own render diagnostics name their spans by pass type
//! (`main_opaque_pass_3d`), the same for every camera, so they cannot tell cameras apart.
//!
//! The timestamps are resolved after the frame's rendering and read back without waiting: a
//! frame's times arrive a few frames later, in [`GpuTimes`]. Needs the device features
//! `TIMESTAMP_QUERY` and `TIMESTAMP_QUERY_INSIDE_ENCODERS` (Vulkan and DX12 drivers that
//! report timestamps, llvmpipe included); without them [`GpuTimes::unavailable`] says why, and
//! nothing is timed.

use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use bevy::core_pipeline::{Core3d, Core3dSystems};
use bevy::prelude::*;
use bevy::render::extract_component::{ExtractComponent, ExtractComponentPlugin};
use bevy::render::render_resource::{
    BufferDescriptor, BufferUsages, CommandEncoder, CommandEncoderDescriptor, MapMode, WgpuFeatures,
};
use bevy::render::renderer::{
    CurrentView, PendingCommandBuffers, RenderContext, RenderDevice, RenderGraph,
    RenderGraphSystems, RenderQueue,
};
use bevy::render::{RenderApp, RenderStartup};

/// Samples kept per span (the oldest are dropped): about five minutes of a 30 fps camera.
pub const KEPT: usize = 10_000;

/// Spans a frame can time at most; more are not timed that frame.
pub const MAX_SPANS: usize = 256;

/// Read-back buffers in flight at most; a frame whose buffer is not free is not timed. A
/// frame's times arrive at most this many frames after it.
pub const READBACKS: usize = 8;

/// Bytes per resolved timestamp pair, at the alignment `resolve_query_set` needs.
const SLOT: u64 = wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT;

/// Times this camera's whole render on the GPU under `name` (added by
/// [`crate::camera::spawn_pinhole_camera`]).
#[derive(Component, ExtractComponent, Debug, Clone, PartialEq, Eq)]
pub struct GpuTimed(pub String);

/// The samples of one span.
#[derive(Debug, Clone, Default)]
pub struct SpanSamples {
    /// GPU time of each measurement (ms), oldest first (the newest [`KEPT`]).
    pub ms: VecDeque<f64>,
    /// Measurements since the start, kept or not.
    pub measured: u64,
}

/// What [`GpuTimes`] holds.
#[derive(Debug, Clone, Default)]
pub struct SpanTimes {
    /// Per span name.
    pub spans: BTreeMap<String, SpanSamples>,
    /// Why nothing is timed (no timestamp queries on this device); `None` while spans are, or
    /// before the render device is known.
    pub unavailable: Option<String>,
}

impl SpanTimes {
    /// Samples of `name` measured after its count was `since` (those still kept).
    pub fn since(&self, name: &str, since: u64) -> Vec<f64> {
        let Some(s) = self.spans.get(name) else {
            return Vec::new();
        };
        let new = s.measured.saturating_sub(since) as usize;
        s.ms.iter()
            .skip(s.ms.len().saturating_sub(new))
            .copied()
            .collect()
    }

    /// Measurements per span so far (a mark for [`SpanTimes::since`]).
    pub fn marks(&self) -> BTreeMap<String, u64> {
        self.spans
            .iter()
            .map(|(k, v)| (k.clone(), v.measured))
            .collect()
    }
}

/// GPU times of named spans (ms), shared between the render world, which measures them, and
/// the app, which reports them.
#[derive(Resource, Debug, Clone, Default)]
pub struct GpuTimes(Arc<Mutex<SpanTimes>>);

impl GpuTimes {
    /// A copy of the samples so far.
    pub fn snapshot(&self) -> SpanTimes {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// The median of the last `n` samples of `name` (ms), for a live display.
    pub fn recent_median(&self, name: &str, n: usize) -> Option<f64> {
        let times = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        let kept = &times.spans.get(name)?.ms;
        let mut recent: Vec<f64> = kept
            .iter()
            .skip(kept.len().saturating_sub(n))
            .copied()
            .collect();
        recent.sort_by(f64::total_cmp);
        recent.get(recent.len() / 2).copied()
    }

    /// Why nothing is timed, if nothing is.
    pub fn unavailable(&self) -> Option<String> {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .unavailable
            .clone()
    }

    /// Measurements per span so far (a mark for [`SpanTimes::since`]).
    pub fn marks(&self) -> BTreeMap<String, u64> {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .marks()
    }

    /// Records a sample measured elsewhere (a CPU time, by a name that says so).
    pub fn record(&self, name: &str, ms: f64) {
        self.update(|t| push_sample(t, name.to_owned(), ms));
    }

    fn update(&self, f: impl FnOnce(&mut SpanTimes)) {
        f(&mut self.0.lock().unwrap_or_else(PoisonError::into_inner));
    }
}

fn push_sample(t: &mut SpanTimes, name: String, ms: f64) {
    let s = t.spans.entry(name).or_default();
    s.ms.push_back(ms);
    s.measured += 1;
    if s.ms.len() > KEPT {
        s.ms.pop_front();
    }
}

/// Times [`GpuTimed`] cameras and the spans render systems open on [`GpuClock`]. Added once by
/// whichever plugin needs it first ([`crate::flat::FlatRenderPlugin`] adds it).
pub struct GpuTimingPlugin;

impl Plugin for GpuTimingPlugin {
    fn build(&self, app: &mut App) {
        let times = GpuTimes::default();
        app.insert_resource(times.clone())
            .add_plugins(ExtractComponentPlugin::<GpuTimed>::default());
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        render_app
            .insert_resource(times)
            .init_resource::<OpenCamera>()
            .add_systems(RenderStartup, create_clock)
            .add_systems(
                Core3d,
                stamp_camera::<false>
                    .before(bevy::pbr::clear_indirect_parameters_metadata)
                    .before(Core3dSystems::Prepass),
            )
            .add_systems(
                Core3d,
                stamp_camera::<true>
                    .after(Core3dSystems::PostProcess)
                    .after(bevy::core_pipeline::upscaling::upscaling),
            )
            .add_systems(
                RenderGraph,
                collect
                    .after(RenderGraphSystems::Render)
                    .before(RenderGraphSystems::Submit),
            );
    }
}

/// A span opened this frame by [`GpuClock::begin`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SpanId(usize);

/// A read-back buffer and the span names its copy holds.
struct Readback {
    buffer: wgpu::Buffer,
    names: Vec<Option<String>>,
    /// [`WAITING`], [`MAPPED`] or [`FAILED`], set by the map callback.
    state: Arc<AtomicU8>,
}

const WAITING: u8 = 0;
const MAPPED: u8 = 1;
const FAILED: u8 = 2;

/// The render world's query set and read-back buffers. Render systems time their work with
/// [`GpuClock::begin`] / [`GpuClock::end`]; absent when the device has no timestamp queries.
#[derive(Resource)]
pub struct GpuClock {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    period_ns: f64,
    /// This frame's spans: the name and the timestamps written (1 begun, 2 begun and ended).
    spans: Vec<(String, u8)>,
    free: Vec<wgpu::Buffer>,
    in_flight: Vec<Readback>,
}

impl GpuClock {
    /// Opens the span `name` with a timestamp written into `encoder`; `None` when this frame
    /// already holds [`MAX_SPANS`] spans.
    pub fn begin(&mut self, encoder: &mut CommandEncoder, name: &str) -> Option<SpanId> {
        let i = self.spans.len();
        if i >= MAX_SPANS {
            return None;
        }
        encoder.write_timestamp(&self.queries, 2 * i as u32);
        self.spans.push((name.to_owned(), 1));
        Some(SpanId(i))
    }

    /// Closes a span opened by [`GpuClock::begin`] this frame.
    pub fn end(&mut self, encoder: &mut CommandEncoder, span: SpanId) {
        if let Some(s) = self.spans.get_mut(span.0)
            && s.1 == 1
        {
            encoder.write_timestamp(&self.queries, 2 * span.0 as u32 + 1);
            s.1 = 2;
        }
    }
}

fn create_clock(
    mut commands: Commands,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    times: Res<GpuTimes>,
) {
    let needed = WgpuFeatures::TIMESTAMP_QUERY | WgpuFeatures::TIMESTAMP_QUERY_INSIDE_ENCODERS;
    if !device.features().contains(needed) {
        let missing = needed - device.features();
        times.update(|t| {
            t.unavailable = Some(format!(
                "the render device has no timestamp queries ({missing:?} missing)"
            ));
        });
        return;
    }
    let device = device.wgpu_device();
    let queries = device.create_query_set(&wgpu::QuerySetDescriptor {
        label: Some("avatarm gpu timestamps"),
        ty: wgpu::QueryType::Timestamp,
        count: 2 * MAX_SPANS as u32,
    });
    let size = SLOT * MAX_SPANS as u64;
    let resolved = device.create_buffer(&BufferDescriptor {
        label: Some("avatarm gpu timestamps resolved"),
        size,
        usage: BufferUsages::QUERY_RESOLVE | BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let free = (0..READBACKS)
        .map(|_| {
            device.create_buffer(&BufferDescriptor {
                label: Some("avatarm gpu timestamps read-back"),
                size,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
        .collect();
    times.update(|t| t.unavailable = None);
    commands.insert_resource(GpuClock {
        queries,
        resolved,
        period_ns: f64::from(queue.get_timestamp_period()),
        spans: Vec::new(),
        free,
        in_flight: Vec::new(),
    });
}

/// The camera being rendered's own span this frame, if it is timed and opened.
#[derive(Resource, Default)]
struct OpenCamera(Option<SpanId>);

/// Writes the begin (`END = false`) or end timestamp of the timed camera being rendered.
fn stamp_camera<const END: bool>(
    view: Option<Res<CurrentView>>,
    cameras: Query<&GpuTimed>,
    clock: Option<ResMut<GpuClock>>,
    mut open: ResMut<OpenCamera>,
    mut ctx: RenderContext,
) {
    let (Some(view), Some(mut clock)) = (view, clock) else {
        return;
    };
    let Ok(GpuTimed(name)) = cameras.get(view.0) else {
        return;
    };
    if END {
        if let Some(span) = open.0.take() {
            clock.end(ctx.command_encoder(), span);
        }
    } else {
        open.0 = clock.begin(ctx.command_encoder(), name);
    }
}

/// Reads the buffers whose copies have arrived, then resolves this frame's timestamps into a
/// free buffer that maps once the frame's commands are done.
fn collect(
    clock: Option<ResMut<GpuClock>>,
    device: Res<RenderDevice>,
    times: Res<GpuTimes>,
    mut pending: ResMut<PendingCommandBuffers>,
) {
    let Some(mut clock) = clock else {
        return;
    };
    let clock = &mut *clock;
    let (done, waiting): (Vec<Readback>, Vec<Readback>) = std::mem::take(&mut clock.in_flight)
        .into_iter()
        .partition(|r| r.state.load(Ordering::Acquire) != WAITING);
    clock.in_flight = waiting;
    for r in done {
        if r.state.load(Ordering::Acquire) == FAILED {
            clock.free.push(r.buffer);
            continue;
        }
        let samples: Vec<(String, f64)> = {
            let bytes = r.buffer.slice(..).get_mapped_range();
            r.names
                .iter()
                .enumerate()
                .filter_map(|(i, name)| {
                    let at = i * SLOT as usize;
                    let stamp = |k: usize| {
                        bytes
                            .get(at + 8 * k..at + 8 * k + 8)
                            .and_then(|b| <[u8; 8]>::try_from(b).ok())
                            .map(u64::from_le_bytes)
                    };
                    let (begin, end) = (stamp(0)?, stamp(1)?);
                    // A driver that reorders or wraps gives end < begin: no sample.
                    let ms = end.checked_sub(begin)? as f64 * clock.period_ns / 1e6;
                    Some((name.clone()?, ms))
                })
                .collect()
        };
        r.buffer.unmap();
        clock.free.push(r.buffer);
        times.update(|t| {
            for (name, ms) in samples {
                push_sample(t, name, ms);
            }
        });
    }

    let spans = std::mem::take(&mut clock.spans);
    if !spans.iter().any(|s| s.1 == 2) {
        return;
    }
    let Some(buffer) = clock.free.pop() else {
        return;
    };
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor {
        label: Some("avatarm gpu timestamps"),
    });
    let mut names = Vec::with_capacity(spans.len());
    for (i, (name, written)) in spans.into_iter().enumerate() {
        if written == 2 {
            let queries = 2 * i as u32..2 * i as u32 + 2;
            encoder.resolve_query_set(&clock.queries, queries, &clock.resolved, SLOT * i as u64);
            names.push(Some(name));
        } else {
            names.push(None);
        }
    }
    encoder.copy_buffer_to_buffer(&clock.resolved, 0, &buffer, 0, None);
    let state = Arc::new(AtomicU8::new(WAITING));
    let flag = state.clone();
    encoder.map_buffer_on_submit(&buffer, MapMode::Read, .., move |result| {
        flag.store(
            if result.is_ok() { MAPPED } else { FAILED },
            Ordering::Release,
        );
    });
    pending.push_encoder(encoder);
    clock.in_flight.push(Readback {
        buffer,
        names,
        state,
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn since_gives_the_samples_after_a_mark_still_kept() {
        let mut t = SpanTimes::default();
        let s = t.spans.entry("pass".into()).or_default();
        s.ms = (0..5).map(f64::from).collect();
        s.measured = 5;
        assert_eq!(t.since("pass", 2), [2.0, 3.0, 4.0]);
        assert_eq!(t.since("pass", 5), Vec::<f64>::new());
        assert!(t.since("other", 0).is_empty());
        // The oldest were dropped: 12 measured, the last 5 kept; after mark 4, 8 are newer
        // but only the 5 kept come back.
        t.spans.get_mut("pass").expect("span").measured = 12;
        assert_eq!(t.since("pass", 4), [0.0, 1.0, 2.0, 3.0, 4.0]);
        assert_eq!(t.since("pass", 10), [3.0, 4.0]);
        assert_eq!(t.marks()["pass"], 12);
    }
}
