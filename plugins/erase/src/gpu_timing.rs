//! GPU time of each erase pass, measured with timestamp queries around its camera's render.
//!
//! Each pass is a camera ([`ErasePass`]); Bevy renders a camera by running its `Core3d`
//! schedule. A system before that schedule's first set writes a timestamp into the command
//! stream and one after its last set writes another, for the pass cameras only; the pair's
//! difference is the GPU time of that camera's render (clear, draws, and whatever else Bevy
//! records for it). Bevy's own render diagnostics name their spans by pass type
//! (`main_opaque_pass_3d`), the same for every camera, so they cannot tell the three passes
//! apart.
//!
//! The timestamps are resolved after the cameras have rendered and read back without waiting:
//! a frame's times arrive a few frames later, in [`GpuPassTimes`]. Needs the device features
//! `TIMESTAMP_QUERY` and `TIMESTAMP_QUERY_INSIDE_ENCODERS` (Vulkan and DX12 drivers that
//! report timestamps, llvmpipe included); without them [`GpuPassTimes::unavailable`] says
//! why, and nothing is timed.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use bevy::core_pipeline::{Core3d, Core3dSystems};
use bevy::prelude::*;
use bevy::render::extract_component::ExtractComponentPlugin;
use bevy::render::render_resource::{
    BufferDescriptor, BufferUsages, CommandEncoderDescriptor, MapMode, WgpuFeatures,
};
use bevy::render::renderer::{
    CurrentView, PendingCommandBuffers, RenderContext, RenderDevice, RenderGraph,
    RenderGraphSystems, RenderQueue,
};
use bevy::render::{RenderApp, RenderStartup};

use crate::ErasePass;

/// The timed passes, in [`ErasePass::stage`] order.
pub const PASS_NAMES: [&str; PASSES] = ["mask camera", "threshold pass", "composite pass"];

const PASSES: usize = 3;

/// Samples kept per pass (the oldest are dropped): about five minutes of a 30 fps camera.
pub const KEPT: usize = 10_000;

/// Read-back buffers in flight at most; a frame whose buffer is not free is not timed.
const READBACKS: usize = 8;

/// Bytes per resolved query pair, at the alignment `resolve_query_set` needs.
const SLOT: u64 = wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT;

/// GPU times of the erase passes (ms), shared between the render world, which measures them,
/// and the app, which reports them.
#[derive(Resource, Debug, Clone, Default)]
pub struct GpuPassTimes(Arc<Mutex<PassTimes>>);

/// What [`GpuPassTimes`] holds.
#[derive(Debug, Clone, Default)]
pub struct PassTimes {
    /// Per pass ([`PASS_NAMES`]), one sample per render, oldest first (the newest
    /// [`KEPT`]).
    pub ms: [VecDeque<f64>; PASSES],
    /// Samples measured per pass since the start, kept or not.
    pub measured: [u64; PASSES],
    /// Why the passes are not timed (no timestamp queries on this device); `None` while they
    /// are, or before the render device is known.
    pub unavailable: Option<String>,
}

impl PassTimes {
    /// Samples of pass `i` measured after `measured[i]` was `since` (those still kept).
    pub fn since(&self, i: usize, since: u64) -> Vec<f64> {
        let new = self.measured[i].saturating_sub(since) as usize;
        let kept = &self.ms[i];
        kept.iter()
            .skip(kept.len().saturating_sub(new))
            .copied()
            .collect()
    }
}

impl GpuPassTimes {
    /// A copy of the samples so far.
    pub fn snapshot(&self) -> PassTimes {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Per pass, the median of its last `n` samples (ms), for a live display.
    pub fn recent_medians(&self, n: usize) -> [Option<f64>; PASSES] {
        let times = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        std::array::from_fn(|i| {
            let kept = &times.ms[i];
            let mut recent: Vec<f64> = kept
                .iter()
                .skip(kept.len().saturating_sub(n))
                .copied()
                .collect();
            recent.sort_by(f64::total_cmp);
            recent.get(recent.len() / 2).copied()
        })
    }

    /// Why the passes are not timed, if they are not.
    pub fn unavailable(&self) -> Option<String> {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .unavailable
            .clone()
    }

    /// Samples measured per pass so far (a mark for [`PassTimes::since`]).
    pub fn measured(&self) -> [u64; PASSES] {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .measured
    }

    fn update(&self, f: impl FnOnce(&mut PassTimes)) {
        f(&mut self.0.lock().unwrap_or_else(PoisonError::into_inner));
    }
}

/// Times the erase passes on the GPU. Added by [`crate::ErasePlugin`].
pub(crate) struct PassTimingPlugin;

impl Plugin for PassTimingPlugin {
    fn build(&self, app: &mut App) {
        let times = GpuPassTimes::default();
        app.insert_resource(times.clone())
            .add_plugins(ExtractComponentPlugin::<ErasePass>::default());
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        render_app
            .insert_resource(times)
            .add_systems(RenderStartup, create_clock)
            .add_systems(Core3d, stamp::<false>.before(Core3dSystems::Prepass))
            .add_systems(Core3d, stamp::<true>.after(Core3dSystems::PostProcess))
            .add_systems(
                RenderGraph,
                collect
                    .after(RenderGraphSystems::Render)
                    .before(RenderGraphSystems::Submit),
            );
    }
}

/// A read-back buffer and the passes its copy holds.
struct Readback {
    buffer: wgpu::Buffer,
    passes: [bool; PASSES],
    /// [`WAITING`], [`MAPPED`] or [`FAILED`], set by the map callback.
    state: Arc<AtomicU8>,
}

const WAITING: u8 = 0;
const MAPPED: u8 = 1;
const FAILED: u8 = 2;

/// The render world's query set and read-back buffers.
#[derive(Resource)]
struct PassClock {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    period_ns: f64,
    /// Timestamps written per pass this frame: 1 begun, 2 begun and ended.
    stamps: [u8; PASSES],
    free: Vec<wgpu::Buffer>,
    in_flight: Vec<Readback>,
}

fn create_clock(
    mut commands: Commands,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    times: Res<GpuPassTimes>,
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
        label: Some("erase pass timestamps"),
        ty: wgpu::QueryType::Timestamp,
        count: 2 * PASSES as u32,
    });
    let size = SLOT * PASSES as u64;
    let resolved = device.create_buffer(&BufferDescriptor {
        label: Some("erase pass timestamps resolved"),
        size,
        usage: BufferUsages::QUERY_RESOLVE | BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let free = (0..READBACKS)
        .map(|_| {
            device.create_buffer(&BufferDescriptor {
                label: Some("erase pass timestamps read-back"),
                size,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
        .collect();
    times.update(|t| t.unavailable = None);
    commands.insert_resource(PassClock {
        queries,
        resolved,
        period_ns: f64::from(queue.get_timestamp_period()),
        stamps: [0; PASSES],
        free,
        in_flight: Vec::new(),
    });
}

/// The pass the camera being rendered is, if it is one.
fn current_pass(view: Option<Res<CurrentView>>, passes: &Query<&ErasePass>) -> Option<usize> {
    passes.get(view?.0).ok().map(|p| p.stage.min(PASSES - 1))
}

/// Writes the begin (`END = false`) or end timestamp of the pass camera being rendered.
fn stamp<const END: bool>(
    view: Option<Res<CurrentView>>,
    passes: Query<&ErasePass>,
    clock: Option<ResMut<PassClock>>,
    mut ctx: RenderContext,
) {
    let (Some(i), Some(mut clock)) = (current_pass(view, &passes), clock) else {
        return;
    };
    // An end needs this frame's begin; stamps counts the ones written (2: both).
    if clock.stamps[i] != u8::from(END) {
        return;
    }
    ctx.command_encoder()
        .write_timestamp(&clock.queries, 2 * i as u32 + u32::from(END));
    clock.stamps[i] += 1;
}

/// Reads the buffers whose copies have arrived, then resolves this frame's timestamps into a
/// free buffer that maps once the frame's commands are done.
fn collect(
    clock: Option<ResMut<PassClock>>,
    device: Res<RenderDevice>,
    times: Res<GpuPassTimes>,
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
        let samples: Vec<(usize, f64)> = {
            let bytes = r.buffer.slice(..).get_mapped_range();
            (0..PASSES)
                .filter(|&i| r.passes[i])
                .filter_map(|i| {
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
                    Some((i, ms))
                })
                .collect()
        };
        r.buffer.unmap();
        clock.free.push(r.buffer);
        times.update(|t| {
            for (i, ms) in samples {
                t.ms[i].push_back(ms);
                t.measured[i] += 1;
                if t.ms[i].len() > KEPT {
                    t.ms[i].pop_front();
                }
            }
        });
    }

    let written = std::mem::take(&mut clock.stamps).map(|n| n == 2);
    if !written.contains(&true) {
        return;
    }
    let Some(buffer) = clock.free.pop() else {
        return;
    };
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor {
        label: Some("erase pass timestamps"),
    });
    for i in (0..PASSES).filter(|&i| written[i]) {
        let queries = 2 * i as u32..2 * i as u32 + 2;
        encoder.resolve_query_set(&clock.queries, queries, &clock.resolved, SLOT * i as u64);
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
        passes: written,
        state,
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn since_gives_the_samples_after_a_mark_still_kept() {
        let mut t = PassTimes::default();
        t.ms[1] = (0..5).map(f64::from).collect();
        t.measured[1] = 5;
        assert_eq!(t.since(1, 2), [2.0, 3.0, 4.0]);
        assert_eq!(t.since(1, 5), Vec::<f64>::new());
        assert!(t.since(0, 0).is_empty());
        // The oldest were dropped: 12 measured, the last 5 kept; after mark 4, 8 are newer
        // but only the 5 kept come back.
        t.measured[1] = 12;
        assert_eq!(t.since(1, 4), [0.0, 1.0, 2.0, 3.0, 4.0]);
        assert_eq!(t.since(1, 10), [3.0, 4.0]);
    }
}
