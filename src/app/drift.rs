//! The drift watch of a live camera (`run` and `serve` with a webcam, a recording played live
//! or a ROS 2 camera): a few frames a second, with the joints their mask was drawn at, go to a
//! worker thread ([`avatarm_footage::drift::DriftWatch`], off the frame path: a frame is
//! skipped while the worker is busy); a move it confirms is fitted again there, and the pose it
//! fits replaces the erase's (and the interaction layer's) camera from the next update on.

use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};

use avatarm_erase::{EraseConfig, EraseState, EraseSystems, InteractionConfig, MaskTwin};
use avatarm_footage::drift::{DriftRefit, DriftReport, DriftSettings, DriftWatch};
use avatarm_twin::RobotTwin;
use avatarm_video::LiveVideo;
use bevy::prelude::*;
use nalgebra::Isometry3;

/// The live watch's settings: a check every half second (each costs tens of milliseconds of
/// one core, beside the renderer), the rest as a replay's.
pub fn live_settings() -> DriftSettings {
    DriftSettings {
        every_s: 0.5,
        ..DriftSettings::default()
    }
}

/// Adds the watch for a fixed camera (none for a camera on a head, which moves by design).
pub struct DriftWatchPlugin(pub DriftSettings);

/// The watch's state in the app: the worker's channels, the last frame sent, what it found.
#[derive(Resource)]
pub struct LiveDriftWatch {
    jobs: SyncSender<Job>,
    found: Mutex<Receiver<Found>>,
    every_s: f64,
    last_sent_s: Option<f64>,
    /// The worker's report so far (every check and refit), for the status line and reports.
    pub report: Arc<Mutex<Option<DriftReport>>>,
    /// The refits applied, in order.
    pub applied: Vec<DriftRefit>,
}

impl LiveDriftWatch {
    /// The status line's words: the checks so far and the moves found.
    pub fn line(&self) -> String {
        // Read under the lock, not copied: the report holds the session's latest checks.
        let Ok(report) = self.report.lock() else {
            return "drift watch: its report is unreadable (the worker failed)".into();
        };
        match (report.as_ref(), self.applied.last()) {
            (None, _) => "drift watch: no check yet".into(),
            (Some(r), None) if !r.watched => format!("drift watch: {}", r.note),
            (Some(r), None) => format!(
                "drift watch: {} checks, the camera within {:.0} px of its pose",
                r.checks_total, r.threshold_px
            ),
            (Some(r), Some(last)) => format!(
                "drift watch: {} checks; the CAMERA MOVED {} time(s), fitted again (last {:.2} deg, at frame {})",
                r.checks_total,
                self.applied.len(),
                last.moved_deg,
                last.detected_frame
            ),
        }
    }
}

/// A frame for the worker.
struct Job {
    index: u64,
    capture_s: f64,
    width: u32,
    height: u32,
    rgba: Arc<Vec<u8>>,
    q: Vec<f64>,
}

/// A move the worker confirmed and the pose it fitted (`camera_from_base`).
type Found = (DriftRefit, Isometry3<f64>);

impl Plugin for DriftWatchPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(DriftSettingsRes(self.0))
            .add_systems(Startup, start)
            .add_systems(Update, (send, apply).chain().after(EraseSystems::Prepare))
            .add_systems(Last, say_at_exit);
    }
}

/// Starts the worker from the erase's configuration (its believed camera, lens, margin and
/// the mask twin's description).
fn start(
    mut commands: Commands,
    config: Option<Res<EraseConfig>>,
    settings: Res<DriftSettingsRes>,
) {
    let Some(config) = config else {
        return;
    };
    if config.head_mount.is_some() {
        info!("drift watch: off (the camera rides on a head: it moves by design)");
        return;
    }
    let settings = settings.0;
    let (jobs, inbox) = sync_channel::<Job>(1);
    let (tell, found) = sync_channel::<Found>(4);
    let report = Arc::new(Mutex::new(None));
    let shared = report.clone();
    let model = config.model.clone();
    let k = config.camera.intrinsics;
    let lens = config.distortion;
    let camera_from_base = (config.base.inverse() * config.camera.world_from_camera).inverse();
    let margin = config.settings.dilate_px;
    let spawned = std::thread::Builder::new()
        .name("drift watch".into())
        .spawn(move || {
            let silhouette =
                match avatarm_core::vision::calibrate::RobotSilhouette::new(&model, 6000) {
                    Ok(s) => s,
                    Err(e) => return error!("drift watch: {e}"),
                };
            let mut watch = match DriftWatch::new(
                &model,
                &silhouette,
                (k, lens),
                camera_from_base,
                margin,
                settings,
            ) {
                Ok(w) => w,
                Err(e) => return error!("drift watch: {e}"),
            };
            for job in inbox {
                let Some(image) =
                    image::RgbaImage::from_raw(job.width, job.height, job.rgba.to_vec())
                else {
                    continue;
                };
                let stamp_ns = (job.capture_s.max(0.0) * 1e9) as u64;
                match watch.check(job.index as usize, stamp_ns, &image, &job.q) {
                    Ok(Some(refit)) => {
                        // Waits for room rather than lose a pose the worker now believes.
                        if tell
                            .send((refit.clone(), watch.camera_from_base()))
                            .is_err()
                        {
                            return;
                        }
                    }
                    Ok(None) => {}
                    Err(e) => warn!("drift watch: {e}"),
                }
                if let Ok(mut r) = shared.lock() {
                    *r = Some(watch.report());
                }
            }
        });
    if let Err(e) = spawned {
        error!("drift watch: the worker thread did not start: {e}");
        return;
    }
    info!(
        "drift watch: on, a frame every {:.2} s against the camera's pose (a move beyond {} px is fitted again)",
        settings.every_s,
        margin.max(settings.min_threshold_px)
    );
    commands.insert_resource(LiveDriftWatch {
        jobs,
        found: Mutex::new(found),
        every_s: settings.every_s,
        last_sent_s: None,
        report,
        applied: Vec::new(),
    });
}

/// The drift watch's settings, for the start-up system.
#[derive(Resource, Clone, Copy)]
struct DriftSettingsRes(DriftSettings);

/// Says what the watch found when the app exits.
fn say_at_exit(watch: Option<Res<LiveDriftWatch>>, mut exit: MessageReader<AppExit>) {
    if let Some(watch) = watch
        && exit.read().count() > 0
    {
        info!("{}", watch.line());
        if let Some(report) = watch.report.lock().ok().and_then(|r| r.clone()) {
            let last: Vec<String> = report
                .checks
                .iter()
                .rev()
                .take(10)
                .rev()
                .map(|c| match &c.shift {
                    Some(s) => format!(
                        "{} at {:.2} s: {:+.0},{:+.0} px{}",
                        c.frame,
                        c.stamp_ns as f64 * 1e-9,
                        s.shift_px[0],
                        s.shift_px[1],
                        if c.beyond { " beyond" } else { "" }
                    ),
                    None => format!("{}: too little outline", c.frame),
                })
                .collect();
            info!(
                "drift watch, the last checks (frame at capture: shift): {}",
                last.join("; ")
            );
        }
    }
}

/// Hands the worker the frame published in this update with the joints the erase drew its
/// mask at (once the robot's joints have arrived), when one is due and the worker is free.
fn send(
    watch: Option<ResMut<LiveDriftWatch>>,
    live: Res<LiveVideo>,
    mask_twin: Option<Res<MaskTwin>>,
    twins: Query<&RobotTwin>,
    state: Res<EraseState>,
) {
    let (Some(mut watch), Some(mask_twin)) = (watch, mask_twin) else {
        return;
    };
    // Before the first joint state the mask twin stands at zeros: no outline to check.
    if state.mask_stamp_s.is_none() {
        return;
    }
    let Some(frame) = live.frame.as_ref().filter(|_| live.fresh) else {
        return;
    };
    if watch
        .last_sent_s
        .is_some_and(|last| frame.capture_s - last < watch.every_s)
    {
        return;
    }
    let Some(twin) = twins.get(mask_twin.0).ok().filter(|t| t.stamp_s.is_some()) else {
        return;
    };
    let job = Job {
        index: frame.index,
        capture_s: frame.capture_s,
        width: frame.width,
        height: frame.height,
        rgba: frame.rgba.clone(),
        q: twin.positions.iter().copied().collect(),
    };
    match watch.jobs.try_send(job) {
        Ok(()) => watch.last_sent_s = Some(frame.capture_s),
        // Busy: this frame is skipped (the watch never holds the frame path).
        Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {}
    }
}

/// Puts a pose the worker fitted into the erase's and the interaction layer's camera.
fn apply(
    watch: Option<ResMut<LiveDriftWatch>>,
    mut config: ResMut<EraseConfig>,
    interaction: Option<ResMut<InteractionConfig>>,
) {
    let Some(mut watch) = watch else {
        return;
    };
    let next = match watch.found.lock().map(|r| r.try_recv()) {
        Ok(Ok(found)) => found,
        Ok(Err(TryRecvError::Empty | TryRecvError::Disconnected)) | Err(_) => return,
    };
    let (refit, camera_from_base) = next;
    let world_from_camera = config.base * camera_from_base.inverse();
    config.camera.world_from_camera = world_from_camera;
    if let Some(mut interaction) = interaction {
        interaction.real_camera.world_from_camera = world_from_camera;
    }
    warn!(
        "drift watch: the camera moved (the robot's outline {:.0},{:.0} px off from frame {} on): its turn fitted again on frames {:?} ({:.2} deg from the pose before, {:.2} s), used from now on",
        refit.shift_px[0],
        refit.shift_px[1],
        refit.first_beyond_frame,
        refit.frames,
        refit.moved_deg,
        refit.refit_s
    );
    watch.applied.push(refit);
}
