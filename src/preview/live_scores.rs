//! Live erasure scores in the preview, when the simulated room gives ground truth.
//!
//! Every `every`-th camera frame, the room's ground truth at its capture (the robot's
//! silhouette and the room without the robot) is read back, and so are the GPU's mask and
//! composite of that frame at the end of the update that erases it; the frame is then scored
//! as a replay scores every frame ([`crate::replay`]): IoU and leak of the erased region
//! against the silhouette, PSNR of Ĩ(t) inside it. The preview shows the
//! mean of the last [`WINDOW`] scored frames. Sampling keeps the read-backs (four images per
//! scored frame) off most frames.

use std::collections::{BTreeMap, VecDeque};

use avatarm_core::dr::MaskScores;
use avatarm_erase::{EraseConfig, EraseState, EraseTargets};
use avatarm_sim::{SimCameras, VideoCounter};
use bevy::prelude::*;

use crate::score::{
    FrameImages, FramePart, FrameStore, frame_key, request_part, request_truth, score_against_truth,
};
use crate::{AvatarmSystems, SceneResource};

/// Scored frames averaged for the display.
pub const WINDOW: usize = 10;

/// Frames waiting for their pipeline images before they are dropped.
const MAX_PENDING: usize = 16;

/// Scores the sampled frames (needs the simulated room with ground truth).
pub struct LiveDrPlugin {
    /// Score every N-th camera frame.
    pub every: u64,
}

/// The live scores.
#[derive(Resource, Debug, Default)]
pub struct LiveDr {
    /// Newest last: each scored frame's mask scores and PSNR (dB).
    pub recent: VecDeque<(MaskScores, Option<f64>)>,
    /// Frames scored so far.
    pub scored: u64,
    every: u64,
    stopped: bool,
    last_index: Option<u64>,
    pending: BTreeMap<i64, Parts>,
}

/// One sampled frame's images as they come back.
#[derive(Default, Debug)]
struct Parts {
    t_s: f64,
    images: FrameImages,
    /// The composite's α_H (0 without H or with erasure off), known when it is requested.
    alpha_h: Option<f32>,
    /// The mask and composite have been requested.
    requested: bool,
}

/// The images a live score needs.
const PARTS: [FramePart; 4] = [
    FramePart::NoRobot,
    FramePart::Silhouette,
    FramePart::Mask,
    FramePart::Composite,
];

impl FrameStore for LiveDr {
    fn arrived(&mut self, key: i64) -> Option<&mut FrameImages> {
        self.pending.get_mut(&key).map(|p| &mut p.images)
    }
}

impl LiveDr {
    /// Asks for no more read-backs (the app is about to quit).
    pub fn stop(&mut self) {
        self.stopped = true;
    }

    /// Starts again for another camera (a switch): the recent scores and the frames waiting
    /// for their images are dropped (a read-back still in flight finds no frame to fill);
    /// `scored` keeps counting.
    pub fn restart(&mut self) {
        self.recent.clear();
        self.pending.clear();
        self.last_index = None;
    }

    /// Mean IoU, leak % and PSNR (dB) over the recent scored frames.
    pub fn means(&self) -> Option<(f64, f64, Option<f64>)> {
        let n = self.recent.len();
        if n == 0 {
            return None;
        }
        let iou = self.recent.iter().map(|(m, _)| m.iou).sum::<f64>() / n as f64;
        let leak = self.recent.iter().map(|(m, _)| m.leak_pct).sum::<f64>() / n as f64;
        let psnrs: Vec<f64> = self.recent.iter().filter_map(|(_, p)| *p).collect();
        let psnr = (!psnrs.is_empty()).then(|| psnrs.iter().sum::<f64>() / psnrs.len() as f64);
        Some((iou, leak, psnr))
    }
}

impl Plugin for LiveDrPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(LiveDr {
            every: self.every.max(1),
            ..default()
        })
        .add_systems(
            Last,
            (request_parts, score_parts)
                .chain()
                .in_set(AvatarmSystems::Score),
        );
    }
}

fn request_parts(
    mut commands: Commands,
    mut live: ResMut<LiveDr>,
    counter: Option<Res<VideoCounter>>,
    cameras: Option<Res<SimCameras>>,
    targets: Option<Res<EraseTargets>>,
    state: Res<EraseState>,
    config: Res<EraseConfig>,
) {
    let (Some(counter), Some(cameras), Some(targets)) = (counter, cameras, targets) else {
        return;
    };
    if live.stopped {
        return;
    }
    if cameras.no_robot.is_none() || cameras.silhouette.is_none() {
        return;
    }
    // The room's truth at the update the camera captured a sampled frame.
    if let Some((index, t_s)) = counter.last
        && live.last_index != Some(index)
    {
        live.last_index = Some(index);
        if index.is_multiple_of(live.every) && live.pending.len() < MAX_PENDING {
            let k = frame_key(t_s);
            live.pending.insert(k, Parts { t_s, ..default() });
            request_truth::<LiveDr>(&mut commands, &cameras, FramePart::NoRobot, k);
            request_truth::<LiveDr>(&mut commands, &cameras, FramePart::Silhouette, k);
        }
    }
    // The pipeline's images of a sampled frame, at the end of the update that erases it (the
    // frame's first: it is fresh there).
    let Some(current) = state.current.as_ref().filter(|c| c.dirty) else {
        return;
    };
    let Some((t_s, _, _)) = &current.frame else {
        return;
    };
    let k = frame_key(*t_s);
    if current.background.is_none() {
        // Nothing to erase with yet (H not set): no score, not a 100 % leak.
        live.pending.remove(&k);
        return;
    }
    let Some(p) = live.pending.get_mut(&k) else {
        return;
    };
    if p.requested {
        return;
    }
    p.requested = true;
    let s = config.settings;
    p.alpha_h = Some(if s.enabled { s.alpha_h } else { 0.0 });
    request_part::<LiveDr>(&mut commands, targets.mask.clone(), FramePart::Mask, k);
    request_part::<LiveDr>(
        &mut commands,
        targets.composite.clone(),
        FramePart::Composite,
        k,
    );
}

fn score_parts(mut live: ResMut<LiveDr>, scene: Res<SceneResource>, config: Res<EraseConfig>) {
    let done: Vec<i64> = live
        .pending
        .iter()
        .filter(|(_, p)| p.images.has(&PARTS))
        .map(|(k, _)| *k)
        .collect();
    let k = config.camera.intrinsics;
    for key in done {
        let Some(p) = live.pending.remove(&key) else {
            continue;
        };
        let FrameImages {
            norobot: Some(mut norobot),
            silhouette: Some(silhouette),
            mask: Some(mask),
            composite: Some(composite),
            ..
        } = p.images
        else {
            continue;
        };
        scene.0.file.camera.sensor.apply_gain(&mut norobot, p.t_s);
        match score_against_truth(
            &config.settings,
            p.alpha_h.unwrap_or(0.0),
            (k.width, k.height),
            &mask,
            &composite,
            &silhouette,
            &norobot,
        ) {
            Some(s) => {
                // Each frame's scores: RUST_LOG=avatarm::preview::live_scores=debug.
                debug!(
                    "live scores of the frame captured at {:.3} s: IoU {:.4}, leak {:.3} %, PSNR {}",
                    p.t_s,
                    s.mask.iou,
                    s.mask.leak_pct,
                    s.psnr_db.map_or("-".to_owned(), |d| format!("{d:.2} dB"))
                );
                live.recent.push_back((s.mask, s.psnr_db));
                while live.recent.len() > WINDOW {
                    live.recent.pop_front();
                }
                live.scored += 1;
            }
            None => warn!("live erasure scores: the mask and the truth differ in size"),
        }
    }
    // Frames the pipeline never delivered (dropped, refused) are forgotten, oldest first.
    while live.pending.len() > MAX_PENDING / 2 {
        live.pending.pop_first();
    }
}
