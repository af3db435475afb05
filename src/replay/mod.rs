//! Headless scene replay: fixed timestep, virtual time, frames and `report.json` written to a
//! folder. The same scene and seed give the same frames.
//!
//! Each app update is one camera frame (`1 / camera.fps` of virtual time); the robot steps in
//! `FixedUpdate` at the control rate. The simulated camera's frames reach the app through the
//! video source (sensor model, latency); the erase pipeline runs on each as it arrives.
//!
//! Every frame is scored against the simulated room's ground truth (captured at the frame's
//! capture time): the erased region against the true robot silhouette, Ĩ(t) against the room
//! without the robot inside the true robot region, and the GPU composite against the CPU
//! reference ([`avatarm_core::dr`]) on the same inputs. Every `frames_every`-th frame is saved:
//! `frame_NNNNN.png` (I(t) as the app received it), `erased_NNNNN.png` (Ĩ(t)), `mask_NNNNN.png`
//! (M(t)), `gt_norobot_NNNNN.png` and `gt_silhouette_NNNNN.png`; `frames.json` lists them with
//! times, joint states and scores, `timestamps.csv` makes the folder a recorded video source,
//! `background.png` is H at the end and `report.json` the summary.
//!
//! - [`task`]: the scene's `[task]` trials, run headless after the video, summarised under
//!   `"object"` in the report.
//! - [`recording`]: `avatarm replay --recording`: a recorded session's frames and joint states
//!   through the erase, scored against the recording's reference masks.

pub mod recording;
pub mod task;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use avatarm_core::dr::{self, MaskScores, Photometric, RgbaView};
use avatarm_core::vision::distortion::{Distortion, DistortionMap};
use avatarm_erase::{
    EraseLens, EraseState, EraseTargets, GpuTimes, PASS_NAMES, SpanTimes, UPLOAD_CPU_SPAN,
    UPLOAD_SPAN,
};
use avatarm_sim::{SimCameras, SimRobotState};
use avatarm_twin::RobotTwin;
use avatarm_video::LiveVideo;
use bevy::prelude::*;
use indicatif::ProgressBar;
use serde::Serialize;

use crate::score::{
    FrameImages, FramePart, FrameStore, TruthScores, frame_key, request_part, request_truth,
    score_against_truth,
};
use crate::{AppError, AppTwin, AvatarmSystems, SceneResource};

pub mod report;
pub(crate) use report::lens_report;
pub use report::{
    DrReport, GpuVsCpu, MaskReport, ReplayCamera, ReplayOutputs, ReplayReport, ReplayRobot,
    ViewsReport,
};
use report::{head_report, mean, stage_timings};
pub use task::ObjectReport;

mod record;
use record::{RecordedFrame, png_bytes, write_recording};
pub(crate) use record::{scene_calibration, write_scene_camera};

/// Options of a replay.
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// Output folder.
    pub out: PathBuf,
    /// Save every N-th camera frame (1 = all).
    pub frames_every: u32,
    /// Show a progress bar on stderr.
    pub progress: bool,
    /// Where the finished report (or the error) is left for the caller.
    pub result: Arc<Mutex<Option<Result<ReplayReport, AppError>>>>,
    /// Also write the replay as a recording (MCAP): every scored frame as the camera gave it,
    /// the simulated robot's joints at its capture, the camera as the app believes it, the true
    /// silhouette as its reference mask, and Avatarm's erased frame and mask.
    pub record: Option<PathBuf>,
}

impl ReplayOptions {
    /// Options writing to `out`, every frame saved, no progress bar.
    pub fn new(out: PathBuf) -> Self {
        Self {
            out,
            frames_every: 1,
            progress: false,
            result: Arc::default(),
            record: None,
        }
    }
}

/// Drives a replay: capture, ground truth, report, exit.
pub struct ReplayPlugin(pub ReplayOptions);

/// One saved frame.
#[derive(Debug, Clone, Serialize)]
pub struct FrameRecord {
    /// Camera frame number.
    pub index: u64,
    /// File of the camera image.
    pub file: String,
    /// Capture time (s, simulation clock).
    pub t_s: f64,
    /// When the frame would arrive at the app (capture + frame latency).
    pub arrival_s: f64,
    /// The robot's true joint positions at capture (empty when not recorded).
    pub q_true: Vec<f64>,
    /// The app twin's joint positions when the frame was shown (last received joint state).
    pub q_twin: Vec<f64>,
    /// Timestamp of that joint state.
    pub twin_stamp_s: Option<f64>,
    /// Joint time the mask twin was drawn at.
    pub mask_stamp_s: Option<f64>,
    /// Scores of the frame.
    pub score: Option<FrameScore>,
}

/// Scores of one frame.
#[derive(Debug, Clone, Serialize)]
pub struct FrameScore {
    /// Capture time (s).
    pub t_s: f64,
    /// Erased region vs true silhouette.
    pub mask: MaskScores,
    /// PSNR of Ĩ(t) against the room without the robot, inside the true robot region (dB).
    pub psnr_robot_db: Option<f64>,
    /// Largest difference between the GPU composite and the CPU reference (8-bit levels).
    pub gpu_cpu_max_diff: u8,
    /// Pixels where the GPU mask and the CPU reference mask differ.
    pub gpu_cpu_mask_mismatch_px: u64,
    /// CPU reference threshold + dilation (ms).
    pub cpu_mask_ms: f64,
    /// CPU reference feathering + composite (ms).
    pub cpu_composite_ms: f64,
    /// Photometric model used.
    pub photometric: Photometric,
}

/// Images and inputs of one frame, gathered from captures that arrive at different times.
#[derive(Default)]
struct Pending {
    images: FrameImages,
    inputs: Option<FrameInputs>,
    q_true: Option<Vec<f64>>,
    /// The pipeline's images have been requested.
    requested: bool,
}

#[derive(Clone)]
struct FrameInputs {
    index: u64,
    t_s: f64,
    live: Arc<Vec<u8>>,
    background: Option<Arc<Vec<u8>>>,
    photometric: Photometric,
    save: bool,
}

#[derive(Resource)]
struct Replay {
    options: ReplayOptions,
    total_frames: u64,
    frame: u64,
    published: u64,
    warmup_left: u32,
    warmup_updates: u32,
    stepping_done: bool,
    pending: usize,
    waited: u32,
    records: Vec<FrameRecord>,
    scores: Vec<FrameScore>,
    frames: BTreeMap<i64, Pending>,
    save_keys: std::collections::HashSet<i64>,
    frame_ms: Vec<f64>,
    last_update: Option<Instant>,
    errors: Vec<String>,
    started: Option<Instant>,
    /// GPU pass samples measured before time started (warm-up renders, not reported).
    gpu_measured_at_start: BTreeMap<String, u64>,
    bar: ProgressBar,
    /// Scored frames for `--record`.
    recorded: Vec<RecordedFrame>,
    /// The mask's lens map ([`EraseLens`], taken when the replay starts).
    lens: Option<Arc<DistortionMap>>,
    /// A camera on a head: per erased frame, the error of the pose its mask was drawn from
    /// against the camera's true pose at capture (degrees, mm), the head's angular speed then
    /// (degrees/s) and how old the newest tracked pose was (ms).
    head_errors: Vec<HeadFrameError>,
    /// A camera on a head, recorded (`--record`): the tracked head poses the app received,
    /// `(stamp_s, world_from_head)`.
    head_poses: Vec<(f64, nalgebra::Isometry3<f64>)>,
    /// A `[chess]` scene: the moves of the game played in the video, at the end.
    chess: Option<Vec<avatarm_mapping::chess::MoveResult>>,
}

/// A camera on a head: how far one frame's mask camera was from the truth.
#[derive(Debug, Clone, Copy)]
struct HeadFrameError {
    t_s: f64,
    angle_deg: f64,
    offset_mm: f64,
    speed_deg_s: f64,
    tracking_age_ms: Option<f64>,
    /// The view-following background: the angle to the nearest view captured before the frame
    /// (degrees), and the share of the robot's region some view saw.
    nearest_view_deg: Option<f64>,
    seen_share: Option<f64>,
    /// Its CPU time for the frame (ms).
    view_background_ms: Option<f64>,
    /// The angle between the frame's camera and the one the background photograph (the
    /// scene's camera at t = 0) was taken from (degrees).
    photo_angle_deg: f64,
}

/// The images a replay scores each frame with.
const PARTS: [FramePart; 5] = [
    FramePart::NoRobot,
    FramePart::Silhouette,
    FramePart::Raw,
    FramePart::Mask,
    FramePart::Composite,
];

impl FrameStore for Replay {
    fn arrived(&mut self, key: i64) -> Option<&mut FrameImages> {
        self.pending = self.pending.saturating_sub(1);
        Some(&mut self.frames.entry(key).or_default().images)
    }
}

impl Plugin for ReplayPlugin {
    fn build(&self, app: &mut App) {
        let scene = &app.world().resource::<SceneResource>().0;
        let head = scene.head.is_some();
        let total_frames = (scene.file.duration_s * scene.file.camera.fps)
            .round()
            .max(1.0) as u64;
        let bar = crate::progress::bar(
            total_frames,
            format!("replay {} (frames)", scene.file.name),
            self.0.progress,
        );
        app.insert_resource(Replay {
            options: self.0.clone(),
            total_frames,
            frame: 0,
            published: 0,
            warmup_left: 3,
            warmup_updates: 0,
            stepping_done: false,
            pending: 0,
            waited: 0,
            records: Vec::new(),
            scores: Vec::new(),
            frames: BTreeMap::new(),
            save_keys: Default::default(),
            frame_ms: Vec::new(),
            last_update: None,
            errors: Vec::new(),
            started: None,
            gpu_measured_at_start: BTreeMap::new(),
            bar,
            recorded: Vec::new(),
            lens: None,
            head_errors: Vec::new(),
            head_poses: Vec::new(),
            chess: None,
        })
        .add_systems(Startup, pause_for_warmup)
        .add_systems(
            Last,
            (drive_replay, score_ready)
                .chain()
                .in_set(AvatarmSystems::Score),
        );
        if self.0.record.is_some() && head {
            app.add_systems(Last, keep_head_poses);
        }
    }
}

/// A camera on a head, recorded: keeps every tracked head pose the app receives.
fn keep_head_poses(
    mut replay: ResMut<Replay>,
    mut poses: MessageReader<avatarm_video::HeadPoseMessage>,
) {
    replay
        .head_poses
        .extend(poses.read().map(|p| (p.stamp_s, p.world_from_head)));
}

/// Updates the replay's warm-up goes on after the empty room is photographed: the GPU times of
/// the warm-up's renders arrive up to this many frames late, and must not count as the
/// replay's.
const WARMUP_AFTER_ROOM: u32 = avatarm_twin::gpu_timing::READBACKS as u32;

/// Updates the replay waits for its background before it gives up.
const MAX_WARMUP_UPDATES: u32 = 300;

fn pause_for_warmup(mut time: ResMut<Time<Virtual>>, replay: Res<Replay>) {
    time.pause();
    if let Err(e) = std::fs::create_dir_all(&replay.options.out) {
        error!(
            "{}: cannot create output folder: {e}",
            replay.options.out.display()
        );
    }
}

fn spawn_capture(
    commands: &mut Commands,
    replay: &mut Replay,
    handle: Handle<Image>,
    part: FramePart,
    k: i64,
) {
    replay.pending += 1;
    request_part::<Replay>(commands, handle, part, k);
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
#[expect(
    clippy::too_many_lines,
    reason = "the replay's Bevy system: one update's steps in their order (warm-up, capture, scoring, the end)"
)]
fn drive_replay(
    mut commands: Commands,
    mut replay: ResMut<Replay>,
    mut time: ResMut<Time<Virtual>>,
    cameras: Option<Res<SimCameras>>,
    robot: Option<Res<SimRobotState>>,
    app_twin: Option<Res<AppTwin>>,
    erase: (
        Option<Res<EraseTargets>>,
        Res<EraseState>,
        Res<LiveVideo>,
        Res<GpuTimes>,
    ),
    twins: Query<&RobotTwin>,
    (scene, lens, chess): (
        Res<SceneResource>,
        Option<Res<EraseLens>>,
        Option<Res<crate::teleop::LiveGame>>,
    ),
    mut exit: MessageWriter<AppExit>,
) {
    if replay.lens.is_none() {
        replay.lens = lens.and_then(|l| l.0.clone());
    }
    let (targets, erase_state, live, gpu_times) = erase;
    let (Some(cameras), Some(robot), Some(app_twin), Some(targets)) =
        (cameras, robot, app_twin, targets)
    else {
        return;
    };
    if replay.warmup_left > 0 {
        // A few frames for render targets and pipelines to exist before time starts, and the
        // empty room's photograph when it is the background (it waits for a settled render).
        let waiting_for_room = scene.0.file.background
            == avatarm_scene::spec::BackgroundSpec::EmptyRoom
            && erase_state.background.is_none();
        replay.warmup_left = replay.warmup_left.saturating_sub(1);
        replay.warmup_updates += 1;
        if waiting_for_room && replay.warmup_updates < MAX_WARMUP_UPDATES {
            // Then a few more updates, so that the GPU times of the warm-up's renders (read
            // back up to READBACKS frames late) belong to the warm-up.
            replay.warmup_left = replay.warmup_left.max(WARMUP_AFTER_ROOM);
            return;
        }
        if waiting_for_room {
            replay.errors.push(format!(
                "background: the empty room was not photographed within {MAX_WARMUP_UPDATES} updates"
            ));
        }
        if replay.warmup_left == 0 {
            time.unpause();
            replay.started = Some(Instant::now());
            replay.gpu_measured_at_start = gpu_times.marks();
        }
        return;
    }
    if !replay.stepping_done {
        let now = Instant::now();
        if let Some(last) = replay.last_update.replace(now) {
            replay.frame_ms.push((now - last).as_secs_f64() * 1e3);
        }
        // Ground truth at this update's capture time.
        let t = robot.0.time_s();
        let k = frame_key(t);
        if cameras.no_robot.is_some() && cameras.silhouette.is_some() {
            for part in [FramePart::NoRobot, FramePart::Silhouette] {
                replay.pending += 1;
                request_truth::<Replay>(&mut commands, &cameras, part, k);
            }
        }
        // The frame the app received now.
        if let Some(f) = live.frame.as_ref().filter(|_| live.fresh) {
            let save = replay
                .published
                .is_multiple_of(u64::from(replay.options.frames_every.max(1)));
            replay.published += 1;
            if save {
                let twin = twins.get(app_twin.0).ok();
                replay.save_keys.insert(frame_key(f.capture_s));
                replay.records.push(FrameRecord {
                    index: f.index,
                    file: format!("frame_{:05}.png", f.index),
                    t_s: f.capture_s,
                    arrival_s: f.arrival_s,
                    q_true: Vec::new(),
                    q_twin: twin.map_or_else(Vec::new, |tw| tw.positions.iter().copied().collect()),
                    twin_stamp_s: twin.and_then(|tw| tw.stamp_s),
                    mask_stamp_s: erase_state.mask_stamp_s,
                    score: None,
                });
            }
        }
        // The pipeline's images of the frame it erases in this update (the frame's first: it
        // is fresh there), read back at the end of the update, after the mask and the passes.
        if let Some(current) = erase_state.current.as_ref().filter(|c| c.dirty)
            && let Some((t_s, index, rgba)) = current.frame.clone()
        {
            let fk = frame_key(t_s);
            let save = replay.save_keys.contains(&fk);
            // A camera on a head: how far the mask's camera was from the truth at capture.
            if !replay.frames.get(&fk).is_some_and(|e| e.requested)
                && let (Some(head), Some(pose)) = (&scene.0.head, erase_state.camera_pose)
            {
                let truth = head.camera_at(t_s);
                let (angle, offset) = avatarm_core::vision::head::pose_error(&pose, &truth);
                let vb = erase_state.view_background.as_ref();
                replay.head_errors.push(HeadFrameError {
                    t_s,
                    angle_deg: angle.to_degrees(),
                    offset_mm: offset * 1e3,
                    speed_deg_s: head.motion.angular_speed_at(t_s).to_degrees(),
                    tracking_age_ms: erase_state
                        .head_pose_s
                        .map(|(newest, _)| (t_s - newest) * 1e3),
                    nearest_view_deg: vb.and_then(|v| v.nearest_rad).map(f64::to_degrees),
                    seen_share: vb.and_then(|v| v.seen_share),
                    view_background_ms: vb.and_then(|v| v.cpu_ms),
                    photo_angle_deg: (pose.rotation * nalgebra::Vector3::z())
                        .angle(
                            &(scene.0.believed_camera.world_from_camera.rotation
                                * nalgebra::Vector3::z()),
                        )
                        .to_degrees(),
                });
            }
            let entry = replay.frames.entry(fk).or_default();
            if !entry.requested {
                entry.requested = true;
                entry.inputs = Some(FrameInputs {
                    index,
                    t_s,
                    live: rgba,
                    background: current.background.clone(),
                    photometric: current.photometric,
                    save,
                });
                for (kind, handle) in [
                    (FramePart::Raw, targets.raw.clone()),
                    (FramePart::Mask, targets.mask.clone()),
                    (FramePart::Composite, targets.composite.clone()),
                ] {
                    spawn_capture(&mut commands, &mut replay, handle, kind, fk);
                }
            }
        }
        // True joints at capture, for frames.json.
        replay.frames.entry(k).or_default().q_true =
            Some(robot.0.true_positions().iter().copied().collect());
        replay.frame += 1;
        let msg = format!("sim {:.2}s", robot.0.time_s());
        replay.bar.set_message(msg);
        replay.bar.inc(1);
        if replay.frame >= replay.total_frames {
            replay.stepping_done = true;
            time.pause();
        }
        return;
    }
    replay.waited += 1;
    if replay.pending > 0 && replay.waited < 600 {
        return;
    }
    if replay.pending > 0 && replay.pending != usize::MAX {
        let message = format!("{} frame captures never arrived", replay.pending);
        replay.errors.push(message);
    }
    if replay.pending == usize::MAX {
        return;
    }
    let gpu = gpu_times.snapshot();
    replay.chess = chess.map(|game| game.0.moves());
    let outcome = finish(
        &replay,
        &scene,
        &robot,
        &twins,
        app_twin.0,
        &erase_state,
        &gpu,
    );
    replay.bar.finish_and_clear();
    let failed = outcome.is_err();
    if let Ok(mut slot) = replay.options.result.lock() {
        *slot = Some(outcome);
    }
    exit.write(if failed {
        AppExit::error()
    } else {
        AppExit::Success
    });
    // Write once.
    replay.pending = usize::MAX;
}

/// Scores every frame whose captures have all arrived, and saves the chosen ones.
fn score_ready(mut replay: ResMut<Replay>, scene: Res<SceneResource>) {
    let lens = replay.lens.clone();
    let ready: Vec<i64> = replay
        .frames
        .iter()
        .filter(|(_, p)| p.images.has(&PARTS) && p.inputs.is_some())
        .map(|(k, _)| *k)
        .collect();
    for k in ready {
        let Some(mut p) = replay.frames.remove(&k) else {
            continue;
        };
        let q_true = p.q_true.take().unwrap_or_default();
        match score_frame(&replay, &scene, lens.as_deref(), p) {
            Ok((score, recorded)) => {
                if let Some(mut r) = recorded {
                    r.q_true.clone_from(&q_true);
                    replay.recorded.push(r);
                }
                if let Some(r) = replay.records.iter_mut().find(|r| frame_key(r.t_s) == k) {
                    r.score = Some(score.clone());
                    r.q_true = q_true;
                }
                replay.scores.push(score);
            }
            Err(AppError::Command { message, .. }) => replay.errors.push(message),
            Err(e) => replay.errors.push(e.to_string()),
        }
    }
    // Ground truth of frames that never reached the app (dropped, or after the end).
    if let Some(&newest) = replay
        .frames
        .iter()
        .filter(|(_, p)| p.inputs.is_some())
        .map(|(k, _)| k)
        .max()
    {
        replay
            .frames
            .retain(|k, p| p.inputs.is_some() || *k > newest);
    }
}

fn score_frame(
    replay: &Replay,
    scene: &SceneResource,
    lens: Option<&DistortionMap>,
    p: Pending,
) -> Result<(FrameScore, Option<RecordedFrame>), AppError> {
    let (
        FrameImages {
            norobot: Some(mut norobot),
            silhouette: Some(silhouette),
            raw: Some((rw, rh, raw)),
            mask: Some(mask),
            composite: Some(gpu),
        },
        Some(inputs),
    ) = (p.images, p.inputs)
    else {
        return Err(AppError::command("replay", "incomplete frame"));
    };
    // The robot-free truth as the camera would have exposed it at capture (noise-free).
    scene
        .0
        .file
        .camera
        .sensor
        .apply_gain(&mut norobot, inputs.t_s);
    let k = &scene.0.believed_camera.intrinsics;
    let (w, h) = (k.width, k.height);
    let settings = scene.0.file.erase;
    let live = RgbaView::new("live frame", w, h, &inputs.live)?;
    let black = vec![0u8; inputs.live.len()];
    let bg_bytes: &[u8] = inputs
        .background
        .as_deref()
        .map_or(&black, |b| b.as_slice());
    let background = RgbaView::new("background", w, h, bg_bytes)?;
    let raw = RgbaView::new("mask twin render", rw, rh, &raw)?;
    // CPU reference on the same inputs.
    let t0 = Instant::now();
    let cpu_mask = dr::threshold_mask(&raw, w, h, &settings.ranges, settings.mask_radius(), lens)?;
    let cpu_mask_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = Instant::now();
    let alpha = dr::feather_alpha(&cpu_mask, w, h, settings.feather_px);
    let alpha_h = if settings.enabled && inputs.background.is_some() {
        settings.alpha_h
    } else {
        0.0
    };
    let cpu = dr::composite(&live, &background, &alpha, alpha_h, &inputs.photometric)?;
    let cpu_composite_ms = t1.elapsed().as_secs_f64() * 1e3;
    let gpu_mask = mask;
    let mismatch = gpu_mask
        .iter()
        .zip(&cpu_mask)
        .filter(|(a, b)| a != b)
        .count() as u64;
    let max_diff = gpu
        .chunks_exact(4)
        .zip(cpu.chunks_exact(4))
        .flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c])))
        .max()
        .unwrap_or(0);
    // Scores against the ground truth, from what the GPU produced.
    let TruthScores {
        truth,
        mask: scores,
        psnr_db: psnr,
    } = score_against_truth(
        &settings,
        alpha_h,
        (w, h),
        &gpu_mask,
        &gpu,
        &silhouette,
        &norobot,
    )
    .ok_or_else(|| AppError::command("replay", "the mask and the truth differ in size"))?;
    if inputs.save {
        let out = &replay.options.out;
        let i = inputs.index;
        let save_rgba = |name: String, data: &[u8]| -> Result<(), AppError> {
            let path = out.join(&name);
            let img =
                image::RgbaImage::from_raw(w, h, data.to_vec()).ok_or(AppError::ImageSize {
                    what: name,
                    width: w,
                    height: h,
                })?;
            image::DynamicImage::ImageRgba8(img)
                .to_rgb8()
                .save(&path)
                .map_err(|source| AppError::write_image(path, source))
        };
        save_rgba(format!("frame_{i:05}.png"), &inputs.live)?;
        save_rgba(format!("erased_{i:05}.png"), &gpu)?;
        save_rgba(format!("gt_norobot_{i:05}.png"), &norobot)?;
        let gray = |m: &[u8], name: String| -> Result<(), AppError> {
            let path = out.join(&name);
            let img = image::GrayImage::from_raw(w, h, m.iter().map(|&v| v * 255).collect())
                .ok_or(AppError::ImageSize {
                    what: name,
                    width: w,
                    height: h,
                })?;
            img.save(&path)
                .map_err(|source| AppError::write_image(path, source))
        };
        gray(&gpu_mask, format!("mask_{i:05}.png"))?;
        gray(&truth, format!("gt_silhouette_{i:05}.png"))?;
    }
    let recorded = match replay.options.record {
        Some(_) => Some(RecordedFrame {
            t_s: inputs.t_s,
            frame: png_bytes(w, h, &inputs.live, false)?,
            truth: png_bytes(w, h, &truth, true)?,
            erased: png_bytes(w, h, &gpu, false)?,
            mask: png_bytes(w, h, &gpu_mask, true)?,
            q_true: Vec::new(),
        }),
        None => None,
    };
    let score = FrameScore {
        t_s: inputs.t_s,
        mask: scores,
        psnr_robot_db: psnr,
        gpu_cpu_max_diff: max_diff,
        gpu_cpu_mask_mismatch_px: mismatch,
        cpu_mask_ms,
        cpu_composite_ms,
        photometric: inputs.photometric,
    };
    Ok((score, recorded))
}

fn finish(
    replay: &Replay,
    scene: &SceneResource,
    robot: &SimRobotState,
    twins: &Query<&RobotTwin>,
    app_twin: Entity,
    erase: &EraseState,
    gpu: &SpanTimes,
) -> Result<ReplayReport, AppError> {
    if !replay.errors.is_empty() {
        return Err(AppError::command("replay", replay.errors.join("; ")));
    }
    let wall = replay.started.map_or(0.0, |s| s.elapsed().as_secs_f64());
    if let Some(path) = &replay.options.record {
        write_recording(path, replay, scene)?;
    }
    let sim = robot.0.time_s();
    let twin = twins.get(app_twin).ok();
    let s = &scene.0;
    let k = &s.true_camera.intrinsics;
    // Frames with the robot in view carry the mask scores; all frames carry the GPU check.
    let with_robot: Vec<&FrameScore> = replay
        .scores
        .iter()
        .filter(|f| f.mask.robot_px > 0)
        .collect();
    let of_robot =
        |f: fn(&FrameScore) -> f64| -> Vec<f64> { with_robot.iter().map(|s| f(s)).collect() };
    let mask = MaskReport {
        iou_mean: mean(&of_robot(|f| f.mask.iou)),
        iou_min: with_robot.iter().map(|f| f.mask.iou).reduce(f64::min),
        leak_pct_mean: mean(&of_robot(|f| f.mask.leak_pct)),
        leak_pct_max: with_robot.iter().map(|f| f.mask.leak_pct).reduce(f64::max),
        overmask_pct_mean: mean(&of_robot(|f| f.mask.overmask_pct)),
        frames_scored: replay.scores.len(),
        frames_with_robot: with_robot.len(),
    };
    let psnrs: Vec<f64> = replay
        .scores
        .iter()
        .filter_map(|f| f.psnr_robot_db)
        .collect();
    let sim_robot = &s.file.robot.sim;
    let report = ReplayReport {
        scene: s.file.name.clone(),
        scene_file: s.path.display().to_string(),
        seed: s.file.seed,
        frames: replay.frame,
        frames_shown: replay.published,
        frames_written: replay.records.len(),
        frames_every: replay.options.frames_every,
        sim_time_s: sim,
        wall_time_s: wall,
        sim_s_per_wall_s: if wall > 0.0 { sim / wall } else { 0.0 },
        camera: ReplayCamera {
            name: s.camera_name().to_owned(),
            width: k.width,
            height: k.height,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            fps: s.file.camera.fps,
            frame_latency_s: s.file.camera.frame_latency_s,
            lens: lens_report(&s.lens, replay.lens.as_deref()),
        },
        robot: ReplayRobot {
            name: s.model.name.clone(),
            dof: s.model.dof(),
            control_rate_hz: s.file.control_rate_hz,
            sim: *sim_robot,
            twin_states_rejected: twin.map_or(0, |t| t.rejected),
            twin_last_stamp_s: twin.and_then(|t| t.stamp_s),
        },
        erase: s.file.erase,
        head: head_report(s, &replay.head_errors, &replay.scores, erase),
        background: erase.background_origin.clone(),
        mask,
        dr: DrReport {
            psnr_robot_db_mean: mean(&psnrs),
            psnr_robot_db_min: psnrs.iter().copied().reduce(f64::min),
        },
        gpu_vs_cpu: GpuVsCpu {
            max_abs_diff: replay.scores.iter().map(|f| f.gpu_cpu_max_diff).max(),
            mask_mismatch_px_max: replay
                .scores
                .iter()
                .map(|f| f.gpu_cpu_mask_mismatch_px)
                .max(),
        },
        timing_ms: stage_timings(replay, gpu),
        outputs: ReplayOutputs::default(),
        name: None,
        out: None,
        object: None,
        chess: replay.chess.clone(),
    };
    let saved: Vec<&FrameRecord> = replay
        .records
        .iter()
        .filter(|r| r.score.is_some())
        .collect();
    write_json(&replay.options.out.join("frames.json"), &saved)?;
    let mut csv = String::from("file,capture_s\n");
    for r in &saved {
        csv.push_str(&format!("{},{}\n", r.file, r.t_s));
    }
    let path = replay.options.out.join("timestamps.csv");
    std::fs::write(&path, csv).map_err(|e| AppError::write(path, e))?;
    if let Some(bg) = &erase.background {
        let path = replay.options.out.join("background.png");
        image::RgbaImage::from_raw(k.width, k.height, bg.as_ref().clone())
            .map(|img| image::DynamicImage::ImageRgba8(img).to_rgb8())
            .ok_or(AppError::ImageSize {
                what: "background".into(),
                width: k.width,
                height: k.height,
            })?
            .save(&path)
            .map_err(|source| AppError::write_image(path, source))?;
    }
    write_json(&replay.options.out.join("report.json"), &report)?;
    Ok(report)
}

/// Builds the replay's app for `scene`: the app's base without a window, one camera frame of
/// simulated time per update, rendering the room's ground truth ([`crate::app::build_app`]),
/// then [`ReplayPlugin`].
pub fn build_app(scene: &avatarm_scene::Scene, options: ReplayOptions) -> Result<App, AppError> {
    let base = crate::app::AppBase {
        ground_truth: true,
        ..crate::app::AppBase::new(crate::app::Runner::Replay)
    };
    // A chess scene plays its opening in the video: the scripted hand's game on the simulated
    // arm, the robot moving over the board (prepared before the app, so that it fails first).
    let chess = (scene.file.task.is_none() && scene.file.chess.is_some())
        .then(|| {
            crate::teleop::LiveChess::prepare(
                scene,
                &avatarm_scene::hand::HandChoice::Scripted,
                &crate::teleop::TrialLink::Simulated,
            )
        })
        .transpose()?;
    let mut app = crate::app::build_app(scene, &base)?;
    app.add_plugins(ReplayPlugin(options));
    if let Some(chess) = chess {
        chess.install(&mut app)?;
    }
    Ok(app)
}

/// Runs a replay to the end and returns its report.
pub fn run(scene: &avatarm_scene::Scene, options: ReplayOptions) -> Result<ReplayReport, AppError> {
    let out = options.out.clone();
    let mut report = run_video(scene, options)?;
    report.object = object_report(scene)?;
    if report.object.is_some() {
        write_report(&out, &report)?;
    }
    Ok(report)
}

/// Replays a scene through each of its cameras in turn: `scenes` holds the scene looked
/// through each (`Scene::load_view`, in the file's order). The simulated room is the same in
/// each replay (the scene's seed), so each camera sees the same run of the robot. Camera
/// NAME's frames and its own report go to `options.out/NAME/`; `options.out/report.json`
/// gives each camera's report under `cameras` (with its `name` and `out`) and the task's
/// `object` once. Recording (`options.record`) holds one camera: refused here.
pub fn run_views(
    scenes: &[avatarm_scene::Scene],
    options: ReplayOptions,
) -> Result<ViewsReport, AppError> {
    let Some(first) = scenes.first() else {
        return Err(AppError::command(
            "replay",
            "no camera to replay".to_owned(),
        ));
    };
    if options.record.is_some() {
        return Err(AppError::flag(
            "--record",
            format!(
                "a recording holds one camera, and the scene '{}' has {}: choose one with --view",
                first.file.name,
                scenes.len()
            ),
        ));
    }
    let mut cameras = Vec::new();
    for scene in scenes {
        let name = scene.camera_name();
        if options.progress {
            eprintln!(
                "camera '{name}' ({} of {}):",
                scene.camera_index + 1,
                scenes.len()
            );
        }
        let mut own = options.clone();
        own.out = options.out.join(name);
        own.result = Arc::default();
        let mut report = run_video(scene, own)?;
        report.name = Some(name.to_owned());
        report.out = Some(name.to_owned());
        cameras.push(report);
    }
    let report = ViewsReport {
        scene: first.file.name.clone(),
        scene_file: first.path.display().to_string(),
        seed: first.file.seed,
        cameras,
        note: "each camera replayed in turn over the same simulated run (the scene's seed); \
               cameras[i] is the report in cameras[i].out/report.json"
            .into(),
        object: object_report(first)?,
    };
    write_report(&options.out, &report)?;
    Ok(report)
}

/// The task's trials, run headless (physics and mapping, no video) after the replay: the
/// report's `object` section, `None` for a scene without a `[task]`.
fn object_report(scene: &avatarm_scene::Scene) -> Result<Option<ObjectReport>, AppError> {
    match (&scene.file.task, &scene.trial) {
        (Some(task), Some(setup)) => Ok(Some(task::object_report(task, setup)?)),
        _ => Ok(None),
    }
}

/// Writes `report` to `out/report.json`.
fn write_report(out: &Path, report: &impl Serialize) -> Result<(), AppError> {
    std::fs::create_dir_all(out).map_err(|e| AppError::write(out.to_owned(), e))?;
    write_json(&out.join("report.json"), report)
}

/// Writes `value` to `path` as pretty JSON with a final newline.
pub(crate) fn write_json(path: &Path, value: &impl Serialize) -> Result<(), AppError> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").map_err(|e| AppError::write(path, e))
}

/// One camera's replay, without the task: its report (also in `options.out/report.json`).
fn run_video(
    scene: &avatarm_scene::Scene,
    options: ReplayOptions,
) -> Result<ReplayReport, AppError> {
    let slot = options.result.clone();
    let mut app = build_app(scene, options)?;
    let exit = app.run();
    slot.lock()
        .ok()
        .and_then(|mut s| s.take())
        .unwrap_or_else(|| {
            Err(AppError::command(
                "replay",
                format!("stopped before finishing ({exit:?})"),
            ))
        })
}
