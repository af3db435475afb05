//! Where the preview's frame time goes: the main world's systems (CPU, `First` to `Last`), the
//! render world's (CPU, extraction's commands to clean-up), each timed view and erase pass on
//! the GPU ([`avatarm_erase::GpuTimes`]), the live frame's upload (CPU and GPU) and the images
//! read back to the CPU per update (the live scores, screenshots, the simulated camera's
//! capture). For `avatarm run --frames N`'s summary and the status line.

use std::collections::VecDeque;
use std::time::Instant;

use avatarm_erase::{GpuTimes, PASS_NAMES, UPLOAD_CPU_SPAN, UPLOAD_SPAN};
use avatarm_twin::readback::ReadbackStats;
use bevy::prelude::*;
use bevy::render::{Render, RenderApp, RenderSystems};

/// The render world's CPU time per frame, as a span of [`GpuTimes`] (measured on the CPU).
pub const RENDER_WORLD_SPAN: &str = "render world (CPU)";

/// Samples kept (the newest).
const KEPT: usize = 240;

/// The main world's CPU time per update and the wall time between updates (ms), newest last.
#[derive(Resource, Debug, Default)]
pub struct FrameBudget {
    main_ms: VecDeque<f64>,
    frame_ms: VecDeque<f64>,
    started: Option<Instant>,
    last_end: Option<Instant>,
    updates: u64,
}

/// Measures [`FrameBudget`] and the render world's CPU time.
pub struct FrameBudgetPlugin;

impl Plugin for FrameBudgetPlugin {
    fn build(&self, app: &mut App) {
        let times = app.world().get_resource::<GpuTimes>().cloned();
        app.init_resource::<FrameBudget>()
            .add_systems(First, start_update)
            .add_systems(Last, end_update);
        if let (Some(times), Some(render_app)) = (times, app.get_sub_app_mut(RenderApp)) {
            render_app
                .insert_resource(RenderClock {
                    times,
                    started: None,
                })
                .add_systems(
                    Render,
                    (
                        start_render.in_set(RenderSystems::ExtractCommands),
                        end_render.in_set(RenderSystems::PostCleanup),
                    ),
                );
        }
    }
}

fn push(q: &mut VecDeque<f64>, v: f64) {
    q.push_back(v);
    while q.len() > KEPT {
        q.pop_front();
    }
}

fn start_update(mut budget: ResMut<FrameBudget>) {
    let now = Instant::now();
    if let Some(last) = budget.started {
        push(&mut budget.frame_ms, (now - last).as_secs_f64() * 1e3);
    }
    budget.started = Some(now);
}

fn end_update(mut budget: ResMut<FrameBudget>) {
    let now = Instant::now();
    if let Some(start) = budget.started {
        push(&mut budget.main_ms, (now - start).as_secs_f64() * 1e3);
    }
    budget.last_end = Some(now);
    budget.updates += 1;
}

#[derive(Resource)]
struct RenderClock {
    times: GpuTimes,
    started: Option<Instant>,
}

fn start_render(mut clock: ResMut<RenderClock>) {
    clock.started = Some(Instant::now());
}

fn end_render(mut clock: ResMut<RenderClock>) {
    if let Some(start) = clock.started.take() {
        clock
            .times
            .record(RENDER_WORLD_SPAN, start.elapsed().as_secs_f64() * 1e3);
    }
}

fn median(values: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = values.collect();
    avatarm_core::stats::Spread::some_of(&v).map(|s| s.median)
}

impl FrameBudget {
    /// The frame budget over the kept updates: medians (ms) of the wall time per update, the
    /// main and render worlds' CPU times, the erase on the GPU, every other timed view on the
    /// GPU, the upload, and the read-backs per update.
    pub fn summary(&self, gpu: &GpuTimes, readbacks: Option<&ReadbackStats>) -> String {
        let ms = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.1}"));
        let frame = median(self.frame_ms.iter().copied());
        let main = median(self.main_ms.iter().copied());
        let n = KEPT;
        let render = gpu.recent_median(RENDER_WORLD_SPAN, n);
        let erase: Option<f64> = {
            let parts: Vec<f64> = PASS_NAMES
                .iter()
                .filter_map(|p| gpu.recent_median(p, n))
                .collect();
            (!parts.is_empty()).then(|| parts.iter().sum())
        };
        let snapshot = gpu.snapshot();
        let views: Vec<String> = snapshot
            .spans
            .keys()
            .filter(|k| {
                !PASS_NAMES.contains(&k.as_str())
                    && ![UPLOAD_SPAN, UPLOAD_CPU_SPAN, RENDER_WORLD_SPAN].contains(&k.as_str())
            })
            .filter_map(|k| gpu.recent_median(k, n).map(|v| format!("{k} {v:.1}")))
            .collect();
        let upload = format!(
            "{} GPU + {} CPU",
            gpu.recent_median(UPLOAD_SPAN, n)
                .map_or("-".to_owned(), |v| format!("{v:.2}")),
            gpu.recent_median(UPLOAD_CPU_SPAN, n)
                .map_or("-".to_owned(), |v| format!("{v:.2}"))
        );
        let readbacks = readbacks.map_or(String::new(), |r| {
            format!(
                "; read-backs {:.2} per update ({:.0} kB)",
                r.images as f64 / self.updates.max(1) as f64,
                r.bytes as f64 / 1e3 / self.updates.max(1) as f64
            )
        });
        format!(
            "frame budget (median ms): update {} = main world {} + render world {} (CPU, in parallel); GPU: erase {}, {}; upload {upload}{readbacks}",
            ms(frame),
            ms(main),
            ms(render),
            erase.map_or("-".to_owned(), |v| format!("{v:.2}")),
            if views.is_empty() {
                "no views timed".to_owned()
            } else {
                views.join(", ")
            },
        )
    }
}
