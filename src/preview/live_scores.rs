//! Live erasure scores in the preview, when the simulated room gives ground truth.
//!
//! Every `every`-th camera frame, the room's ground truth at its capture (the robot's
//! silhouette and the room without the robot) is read back, and so are the GPU's mask and
//! composite of that frame at the end of the update that erases it; the frame is then scored
//! as a replay scores every frame ([`crate::replay`]): IoU and leak of the erased region
//! against the silhouette, PSNR of Ĩ(t) inside it. The preview shows the
//! mean of the last [`WINDOW`] scored frames. Sampling keeps the read-backs (four images per
//! scored frame) off most frames. A frame whose truth was read from a render that did not
//! complete (a pipeline still compiling: the first updates, the views a camera switch spawns,
//! [`RenderSettled`]) is not scored: its truth would miss what was not drawn yet.

use std::collections::{BTreeMap, VecDeque};

use avatarm_core::dr::MaskScores;
use avatarm_erase::{EraseConfig, EraseState, EraseTargets};
use avatarm_sim::{SimCameras, VideoCounter};
use avatarm_twin::camera::RenderSettled;
use bevy::diagnostic::FrameCount;
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
    /// Sampled frames not scored because the render their truth was read from had not
    /// completed.
    pub incomplete: u64,
    every: u64,
    stopped: bool,
    last_index: Option<u64>,
    pending: BTreeMap<i64, Parts>,
}

/// One sampled frame's images as they come back.
#[derive(Default, Debug)]
struct Parts {
    t_s: f64,
    /// The frame number of the render the truth was read from.
    truth_frame: u32,
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
                .in_set(AvatarmSystems::Score)
                // The frame count goes up in `Last` too: read before it does.
                .before(bevy::diagnostic::update_frame_count),
        );
    }
}

fn request_parts(
    mut commands: Commands,
    mut live: ResMut<LiveDr>,
    (counter, frame): (Option<Res<VideoCounter>>, Res<FrameCount>),
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
            let truth_frame = RenderSettled::this_update_frame(&frame);
            live.pending.insert(
                k,
                Parts {
                    t_s,
                    truth_frame,
                    ..default()
                },
            );
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

fn score_parts(
    mut live: ResMut<LiveDr>,
    scene: Res<SceneResource>,
    config: Res<EraseConfig>,
    settled: Option<Res<RenderSettled>>,
) {
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
        // The truth arrived, so its render has ended; it completed only if the renderer
        // said so (without the room's settle record, every render counts as complete).
        if settled
            .as_ref()
            .is_some_and(|s| !s.completed(p.truth_frame))
        {
            debug!(
                "live scores: the frame captured at {:.3} s is not scored: its truth's render (frame {}) did not complete",
                p.t_s, p.truth_frame
            );
            live.incomplete += 1;
            continue;
        }
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

#[cfg(test)]
mod tests {
    use std::path::Path;

    use bevy::ecs::system::RunSystemOnce;

    use super::*;

    /// A sampled frame whose truth was read from a render that had not completed is counted
    /// and not scored; the same frame read from a complete render is scored.
    #[test]
    fn a_frame_whose_truth_render_did_not_complete_is_not_scored() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/pouring.toml");
        let scene = avatarm_scene::Scene::load(&path, &Default::default()).expect("scene");
        let config = crate::app::erase_config(&scene);
        let k = config.camera.intrinsics;
        let n = (k.width * k.height) as usize;
        // A robot in the top rows, erased exactly, the room grey where it stood.
        let robot: Vec<u8> = (0..n).map(|i| if i < n / 4 { 255 } else { 0 }).collect();
        let parts = |truth_frame| {
            let mut images = FrameImages::default();
            let size = (k.width, k.height);
            images.put(FramePart::NoRobot, size, 4, vec![120; n * 4]);
            images.put(FramePart::Silhouette, size, 1, robot.clone());
            images.put(FramePart::Mask, size, 1, robot.clone());
            images.put(FramePart::Composite, size, 4, vec![120; n * 4]);
            Parts {
                t_s: 0.5,
                truth_frame,
                images,
                alpha_h: Some(1.0),
                requested: true,
            }
        };
        let mut app = App::new();
        let settled = RenderSettled::default();
        app.insert_resource(settled.clone())
            .insert_resource(SceneResource(scene))
            .insert_resource(config)
            .insert_resource(LiveDr::default());
        // The frame's truth read at `truth_frame`: (scored, not scored as incomplete).
        let mut score = |truth_frame| {
            app.world_mut()
                .resource_mut::<LiveDr>()
                .pending
                .insert(frame_key(0.5), parts(truth_frame));
            app.world_mut().run_system_once(score_parts).unwrap();
            let l = app.world().resource::<LiveDr>();
            (l.scored, l.incomplete)
        };
        // Frame 5 rendered with a pipeline compiling, frame 6 complete (a view spawned at 5).
        settled.note_complete(4);
        settled.note_incomplete(5);
        settled.note_complete(6);
        assert_eq!(score(5), (0, 1), "read at an incomplete frame");
        assert_eq!(score(7), (0, 2), "read at a frame not known complete");
        assert_eq!(score(6), (1, 2));
        assert_eq!(score(4), (2, 2));
        let (iou, leak, psnr) = app.world().resource::<LiveDr>().means().unwrap();
        assert_eq!((iou, leak), (1.0, 0.0));
        assert!(psnr.is_some_and(|p| p > 60.0), "{psnr:?}");
    }
}
