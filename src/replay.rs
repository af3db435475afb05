//! Headless scene replay: fixed timestep, virtual time, frames and `report.json` written to a
//! folder. The same scene and seed give the same frames.
//!
//! Each app update is one camera frame (`1 / camera.fps` of virtual time); the robot steps in
//! `FixedUpdate` at the control rate. Every `frames_every`-th frame the real camera's image (with
//! the sensor model applied) is saved as `frame_NNNNN.png`, with the ground truth beside it:
//! `gt_norobot_NNNNN.png` (the room without the robot) and `gt_silhouette_NNNNN.png` (the robot's
//! visible pixels in white). `frames.json` lists each saved frame's time and the true and believed
//! joint positions.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use avatarm_core::rng::Rng;
use avatarm_sim::{SimCameras, SimRobotState};
use avatarm_twin::RobotTwin;
use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use serde_json::json;

use crate::{AppTwin, SceneResource};

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
    pub result: Arc<Mutex<Option<Result<serde_json::Value, String>>>>,
}

impl ReplayOptions {
    /// Options writing to `out`, every frame saved, no progress bar.
    pub fn new(out: PathBuf) -> Self {
        Self {
            out,
            frames_every: 1,
            progress: false,
            result: Arc::default(),
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
    /// The robot's true joint positions at capture.
    pub q_true: Vec<f64>,
    /// The app twin's joint positions at capture (last received joint state).
    pub q_twin: Vec<f64>,
    /// Timestamp of that joint state.
    pub twin_stamp_s: Option<f64>,
}

#[derive(Resource)]
struct Replay {
    options: ReplayOptions,
    total_frames: u64,
    frame: u64,
    warmup_left: u32,
    stepping_done: bool,
    pending: usize,
    waited: u32,
    records: Vec<FrameRecord>,
    errors: Vec<String>,
    started: Option<Instant>,
    bar: ProgressBar,
    seed: u64,
}

/// Kinds of saved image.
#[derive(Debug, Clone, Copy)]
enum Capture {
    Camera,
    NoRobot,
    Silhouette,
}

impl Plugin for ReplayPlugin {
    fn build(&self, app: &mut App) {
        let scene = &app.world().resource::<SceneResource>().0;
        let total_frames = (scene.file.duration_s * scene.file.camera.fps)
            .round()
            .max(1.0) as u64;
        let bar = if self.0.progress {
            let bar = ProgressBar::new(total_frames);
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix} [{bar:40}] {pos}/{len} frames, {elapsed} ({msg})",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar.set_prefix(format!("replay {}", scene.file.name));
            bar
        } else {
            ProgressBar::hidden()
        };
        app.insert_resource(Replay {
            options: self.0.clone(),
            total_frames,
            frame: 0,
            warmup_left: 3,
            stepping_done: false,
            pending: 0,
            waited: 0,
            records: Vec::new(),
            errors: Vec::new(),
            started: None,
            bar,
            seed: scene.file.seed,
        })
        .add_systems(Startup, pause_for_warmup)
        .add_systems(Last, drive_replay);
    }
}

fn pause_for_warmup(mut time: ResMut<Time<Virtual>>, replay: Res<Replay>) {
    time.pause();
    if let Err(e) = std::fs::create_dir_all(&replay.options.out) {
        error!(
            "{}: cannot create output folder: {e}",
            replay.options.out.display()
        );
    }
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn drive_replay(
    mut commands: Commands,
    mut replay: ResMut<Replay>,
    mut time: ResMut<Time<Virtual>>,
    cameras: Option<Res<SimCameras>>,
    robot: Option<Res<SimRobotState>>,
    app_twin: Option<Res<AppTwin>>,
    twins: Query<&RobotTwin>,
    scene: Res<SceneResource>,
    mut exit: MessageWriter<AppExit>,
) {
    let (Some(cameras), Some(robot), Some(app_twin)) = (cameras, robot, app_twin) else {
        return;
    };
    if replay.warmup_left > 0 {
        // A few frames for render targets and pipelines to exist before time starts.
        replay.warmup_left -= 1;
        if replay.warmup_left == 0 {
            time.unpause();
            replay.started = Some(Instant::now());
        }
        return;
    }
    if !replay.stepping_done {
        let k = replay.frame;
        if k.is_multiple_of(u64::from(replay.options.frames_every.max(1))) {
            let t = robot.0.time_s();
            let twin = twins.get(app_twin.0).ok();
            replay.records.push(FrameRecord {
                index: k,
                file: format!("frame_{k:05}.png"),
                t_s: t,
                arrival_s: t + scene.0.file.camera.frame_latency_s,
                q_true: robot.0.true_positions().iter().copied().collect(),
                q_twin: twin.map_or_else(Vec::new, |tw| tw.positions.iter().copied().collect()),
                twin_stamp_s: twin.and_then(|tw| tw.stamp_s),
            });
            let mut targets = vec![(Capture::Camera, cameras.real.clone())];
            targets.extend(cameras.no_robot.clone().map(|h| (Capture::NoRobot, h)));
            targets.extend(cameras.silhouette.clone().map(|h| (Capture::Silhouette, h)));
            for (kind, handle) in targets {
                replay.pending += 1;
                commands.spawn(Screenshot::image(handle)).observe(
                    move |captured: On<ScreenshotCaptured>,
                          mut replay: ResMut<Replay>,
                          scene: Res<SceneResource>| {
                        let result = save_capture(&replay, &scene, kind, k, t, &captured.image);
                        replay.pending = replay.pending.saturating_sub(1);
                        if let Err(e) = result {
                            replay.errors.push(e);
                        }
                    },
                );
            }
        }
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
    if replay.pending > 0 {
        let message = format!("{} frame captures never arrived", replay.pending);
        replay.errors.push(message);
    }
    let outcome = finish(&replay, &scene, &robot, &twins, app_twin.0);
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

fn save_capture(
    replay: &Replay,
    scene: &SceneResource,
    kind: Capture,
    k: u64,
    t_s: f64,
    image: &Image,
) -> Result<(), String> {
    let dynamic = image
        .clone()
        .try_into_dynamic()
        .map_err(|e| format!("frame {k}: cannot convert the capture: {e:?}"))?;
    let (name, out) = match kind {
        Capture::Camera => {
            let mut rgba = dynamic.to_rgba8();
            let mut rng = Rng::stream(replay.seed, k);
            // The same capture time as frames.json records.
            scene.0.file.camera.sensor.apply(&mut rgba, t_s, &mut rng);
            (
                format!("frame_{k:05}.png"),
                image::DynamicImage::ImageRgba8(rgba).to_rgb8().into(),
            )
        }
        Capture::NoRobot => (format!("gt_norobot_{k:05}.png"), dynamic.to_rgb8().into()),
        Capture::Silhouette => {
            let mut gray = dynamic.to_luma8();
            for p in gray.pixels_mut() {
                p.0[0] = if p.0[0] > 127 { 255 } else { 0 };
            }
            (
                format!("gt_silhouette_{k:05}.png"),
                image::DynamicImage::ImageLuma8(gray),
            )
        }
    };
    let path = replay.options.out.join(name);
    out.save(&path)
        .map_err(|e| format!("{}: cannot write: {e}", path.display()))
}

fn finish(
    replay: &Replay,
    scene: &SceneResource,
    robot: &SimRobotState,
    twins: &Query<&RobotTwin>,
    app_twin: Entity,
) -> Result<serde_json::Value, String> {
    if !replay.errors.is_empty() {
        return Err(replay.errors.join("; "));
    }
    let wall = replay.started.map_or(0.0, |s| s.elapsed().as_secs_f64());
    let sim = robot.0.time_s();
    let twin = twins.get(app_twin).ok();
    let s = &scene.0;
    let k = &s.true_camera.intrinsics;
    let report = json!({
        "scene": s.file.name,
        "scene_file": s.path.display().to_string(),
        "seed": s.file.seed,
        "frames": replay.frame,
        "frames_written": replay.records.len(),
        "frames_every": replay.options.frames_every,
        "sim_time_s": sim,
        "wall_time_s": wall,
        "sim_s_per_wall_s": if wall > 0.0 { sim / wall } else { 0.0 },
        "camera": {
            "width": k.width, "height": k.height,
            "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
            "fps": s.file.camera.fps,
            "frame_latency_s": s.file.camera.frame_latency_s,
        },
        "robot": {
            "name": s.model.name,
            "dof": s.model.dof(),
            "control_rate_hz": s.file.control_rate_hz,
            "sim": {
                "command_latency_s": s.file.robot.sim.command_latency_s,
                "time_constant_s": s.file.robot.sim.time_constant_s,
                "state_rate_hz": s.file.robot.sim.state_rate_hz,
                "state_latency_s": s.file.robot.sim.state_latency_s,
            },
            "twin_states_rejected": twin.map_or(0, |t| t.rejected),
            "twin_last_stamp_s": twin.and_then(|t| t.stamp_s),
        },
        "outputs": {
            "frames": "frame_NNNNN.png",
            "ground_truth_no_robot": "gt_norobot_NNNNN.png",
            "ground_truth_silhouette": "gt_silhouette_NNNNN.png",
            "frame_list": "frames.json",
        },
    });
    let write = |name: &str, value: &serde_json::Value| {
        let path = replay.options.out.join(name);
        let text = serde_json::to_string_pretty(value).map_err(|e| e.to_string())?;
        std::fs::write(&path, text + "\n")
            .map_err(|e| format!("{}: cannot write: {e}", path.display()))
    };
    write("frames.json", &json!(replay.records))?;
    write("report.json", &report)?;
    Ok(report)
}

/// Runs a replay to the end and returns its report.
pub fn run(
    scene: &crate::scene::Scene,
    options: ReplayOptions,
) -> Result<serde_json::Value, String> {
    let slot = options.result.clone();
    let mut app = crate::build_app(scene, &crate::Mode::Headless(options));
    let exit = app.run();
    slot.lock()
        .ok()
        .and_then(|mut s| s.take())
        .unwrap_or_else(|| Err(format!("the replay stopped before finishing ({exit:?})")))
}
