//! `avatarm replay --recording FILE.mcap --urdf DESCRIPTION`: a recording's frames and joint
//! states through the erase pipeline, as a lab's own camera saw its own robot.
//!
//! Each frame is masked at the joints the robot had at the frame's capture time (linear
//! interpolation between the recorded joint states around it), through the recording's camera
//! (its K and its pose, or `--camera` / `--pose`), with every `[erase]` option of the command
//! line. Recorded robot data rarely has an empty-room photograph, so the background H comes
//! from the footage itself unless `--background` gives one: a first pass masks every frame;
//! the pixels the masks (dilated by `--background-margin`) leave uncovered build H
//! ([`avatarm_core::dr::FootageBackground`]: per-pixel median, never-seen pixels filled from
//! their surroundings and marked); a second pass erases every frame with it. Written to `--out`:
//! `erased_NNNNN.png`, `mask_NNNNN.png`, `overlay_NNNNN.png` (the mask tinted red over the frame,
//! the reference mask's outline in green), `background.png`, `background_seen.png` (white where
//! a frame showed the pixel), `erased.mcap` (the recording's streams with Avatarm's erased frames
//! and masks beside them, which Foxglove shows side by side) and `report.json`: timing, mask
//! coverage, the GPU-vs-CPU-reference check, how much of the robot's region had a seen
//! background, and — where the recording carries reference masks — IoU, leak and overmask
//! against them.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use avatarm_core::dr::{self, BackgroundEstimate, EraseSettings, FootageBackground, RgbaView};
use avatarm_core::robot::{JointMap, PackagePath, RobotModel};
use avatarm_core::vision::camera::PinholeCamera;
use avatarm_core::vision::distortion::Distortion;
use avatarm_core::vision::head::PoseHistory;
use avatarm_erase::{
    EraseConfig, EraseLens, ErasePlugin, EraseState, EraseSystems, EraseTargets, GpuTimes,
    PASS_NAMES, SetBackground, UPLOAD_SPAN, ViewBackgroundConfig,
};
use avatarm_record::camera::{CameraCalibration, read_pose};
use avatarm_record::{CompressedFrame, HeadPose, ImageFormat, Recording, RecordingWriter};
use avatarm_twin::readback::{ImageRead, ImageReadbackPlugin, read_image_once};
use avatarm_twin::{RobotTwin, RobotTwinPlugin, TwinDetail};
use avatarm_video::{HeadTracking, LiveVideo, VideoFrame, VideoInbox, VideoPlugin, VideoSystems};
use bevy::app::ScheduleRunnerPlugin;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use nalgebra::{DVector, Isometry3};

use crate::AppError;

mod drift;
mod outputs;
use outputs::write_outputs;

pub mod report;
pub use report::{
    FrameRim, FrameVsReference, HeadMount, MountPose, RecordingBackground, RecordingCamera,
    RecordingErase, RecordingMask, RecordingOutputs, RecordingReport, RecordingTimings, RimReport,
    ViewFollowing, VsReference,
};

use avatarm_footage::overlay::overlay;
use avatarm_footage::recording::{
    decode, interpolate, joint_vectors, recording_camera, recording_mount,
};

/// What `avatarm replay --recording` is given.
#[derive(Debug, Clone)]
pub struct RecordingOptions {
    /// The recording (MCAP).
    pub recording: PathBuf,
    /// The robot's description.
    pub urdf: PathBuf,
    /// Folders searched for its `package://` URIs.
    pub packages: PackagePath,
    /// A camera file instead of the recording's calibration.
    pub camera: Option<PathBuf>,
    /// A pose file instead of the recording's camera pose.
    pub pose: Option<PathBuf>,
    /// A recording of a camera on a head: a mount file (`head_from_camera`) instead of the
    /// recording's mount.
    pub mount: Option<PathBuf>,
    /// The erase's settings.
    pub settings: EraseSettings,
    /// Where `settings.dilate_px` comes from: [`DilateFrom::Default`] lets the pose (or
    /// mount) file's `erase_margin_px` (written by `avatarm calibrate`) replace it.
    pub dilate_from: DilateFrom,
    /// H from an image file instead of from the footage.
    pub background: Option<PathBuf>,
    /// How far beyond the mask a pixel counts as possibly the robot when H is built (px).
    pub background_margin_px: u32,
    /// A recording of a camera on a head: the scene file of its room, whose boxes that are not
    /// objects are the view-following background's proxy.
    pub room: Option<PathBuf>,
    /// Watch a fixed camera for moving ([`avatarm_footage::drift`]): a move beyond the
    /// erase margin is fitted again and the new pose used from the frame that confirmed it.
    /// `None`: off.
    pub drift: Option<avatarm_footage::drift::DriftSettings>,
    /// Refine the margin's band to each frame (`--refine-edges`, on the CPU): the band's
    /// pixels that look like H are given back to the frame ([`dr::refine_band`]).
    pub refine_edges: bool,
    /// Output folder.
    pub out: PathBuf,
    /// Show a progress bar.
    pub progress: bool,
}

/// Where the mask's dilation comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DilateFrom {
    /// `--dilate`: as given.
    Flag,
    /// Nothing said: the pose or mount file's margin where it has one, else the default.
    Default,
    /// The margin `avatarm calibrate` wrote into this pose or mount file.
    Calibration(PathBuf),
}

impl DilateFrom {
    /// What the report says.
    pub fn said(&self) -> String {
        match self {
            Self::Flag => "--dilate".into(),
            Self::Default => "the default (no --dilate, no erase_margin_px in a pose file)".into(),
            Self::Calibration(p) => {
                format!("erase_margin_px in {} (avatarm calibrate)", p.display())
            }
        }
    }
}

impl RecordingOptions {
    /// These options with the dilation the pose (or mount) file asks for, where `--dilate`
    /// did not say and the file has `erase_margin_px`. Errors: the file's margin is malformed.
    fn with_calibrated_margin(&self) -> Result<Self, AppError> {
        let mut o = self.clone();
        if o.dilate_from != DilateFrom::Default {
            return Ok(o);
        }
        let Some(file) = o.pose.as_ref().or(o.mount.as_ref()) else {
            return Ok(o);
        };
        if let Some(px) = avatarm_record::camera::read_erase_margin(file)? {
            o.settings.dilate_px = px;
            o.dilate_from = DilateFrom::Calibration(file.clone());
        }
        Ok(o)
    }
}

/// H built from the footage (its origin's name).
const FOOTAGE: &str = "the footage";

/// Updates for pipelines to exist before the first frame, and between the passes.
const SETTLE_UPDATES: u32 = 4;

/// Updates to wait for read-backs before giving up.
const MAX_WAIT_UPDATES: u32 = 600;

/// Replays the recording; returns the report (also written to `out/report.json`).
pub fn run_recording(o: &RecordingOptions) -> Result<RecordingReport, AppError> {
    let started = Instant::now();
    let o = &o.with_calibrated_margin()?;
    let mut input = Input::load(o)?;
    // A fixed camera that moved: the pose at each frame, as a head's track with no mount.
    let moved = drift::watch(o, &mut input)?;
    let head_mount = input
        .head_mount
        .or(moved.as_ref().map(|_| Isometry3::identity()));
    std::fs::create_dir_all(&o.out).map_err(|source| AppError::Io {
        path: o.out.clone(),
        action: "create",
        source,
    })?;
    let file_background = match &o.background {
        Some(path) => Some(load_background(path, input.size)?),
        None => None,
    };
    let result = Arc::new(Mutex::new(None));
    let mut app = App::new();
    app.add_plugins((
        crate::app::headless_plugins(),
        ScheduleRunnerPlugin::run_loop(Duration::ZERO),
        RobotTwinPlugin,
        VideoPlugin,
        ImageReadbackPlugin,
    ))
    .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        1.0 / 30.0,
    )));
    let model = input.model.clone();
    let n = model.dof();
    let source = app
        .world_mut()
        .spawn((
            Name::new("recorded robot"),
            RobotTwin {
                model: model.clone(),
                positions: DVector::zeros(n),
                velocities: DVector::zeros(n),
                stamp_s: None,
                links: Vec::new(),
                rejected: 0,
                strict_names: true,
            },
        ))
        .id();
    let mut settings = o.settings;
    // Each frame's joints are interpolated to its capture time here, so the mask twin takes the
    // newest state as it is.
    settings.latency_compensation = false;
    // A camera on a head: the head's pose at each frame's capture (handed over with it).
    settings.pose_compensation = true;
    let (w, h) = input.size;
    app.insert_resource(LiveVideo::new("recording", 1e9))
        .insert_resource(EraseConfig {
            settings,
            camera: input.camera,
            distortion: input.lens,
            joint_map: JointMap::new(&model, &model),
            model: model.clone(),
            detail: TwinDetail::default(),
            base: Isometry3::identity(),
            source_twin: Some(source),
            occluders: Vec::new(),
            head_mount,
            view_background: input.view_background.clone(),
        })
        .add_plugins(ErasePlugin)
        .insert_resource(Driver {
            head: input
                .head_mount
                .map(|_| input.recording.head_poses.clone())
                .or(moved)
                .unwrap_or_default(),
            frames: input.frames.clone(),
            q: input.q.clone(),
            source,
            size: (w, h),
            margin_px: o.background_margin_px,
            phase: if file_background.is_some() {
                Phase::Settle(SETTLE_UPDATES, Pass::Erase)
            } else {
                Phase::Settle(SETTLE_UPDATES, Pass::Mask)
            },
            pending_background: file_background.map(|rgba| (rgba, "file".to_owned())),
            view_background: input.view_background.is_some(),
            background: None,
            stretches: stretches(
                &input
                    .drift
                    .iter()
                    .flat_map(|d| &d.refits)
                    .map(|r| (r.first_beyond_frame, r.detected_frame))
                    .collect::<Vec<_>>(),
                input.frames.len(),
            ),
            later_backgrounds: Vec::new(),
            resume: 0,
            shown: None,
            outputs: vec![FrameOutput::default(); input.frames.len()],
            pending: 0,
            waited: 0,
            errors: Vec::new(),
            bar: crate::progress::bar(
                2 * input.frames.len() as u64,
                "replay recording",
                o.progress,
            ),
            result: result.clone(),
        })
        .add_systems(Update, feed.in_set(VideoSystems::Receive))
        .add_systems(Update, request.after(EraseSystems::Prepare));
    app.run();
    let finished = result
        .lock()
        .ok()
        .and_then(|mut r| r.take())
        .ok_or_else(|| {
            AppError::command(
                "replay --recording",
                "the recording's replay stopped before it finished",
            )
        })?;
    let Finished {
        outputs,
        background,
        times,
        errors,
    } = finished;
    if !errors.is_empty() {
        return Err(AppError::command("replay --recording", errors.join("; ")));
    }
    write_outputs(o, &input, &outputs, &background, &times, started)
}

/// The recording's streams, checked and put in the description's terms.
struct Input {
    recording: Recording,
    model: Arc<RobotModel>,
    camera: PinholeCamera,
    /// The camera's lens (honoured by the mask unless `[erase] lens_distortion` is off).
    lens: Distortion,
    /// The mask's lens map (the pipeline builds the same).
    lens_map: EraseLens,
    calibration: CameraCalibration,
    size: (u32, u32),
    /// The frames, by capture time.
    frames: Vec<CompressedFrame>,
    /// Each frame's joints (the description's q order) at its capture time.
    q: Vec<DVector<f64>>,
    /// Each frame's reference mask (0/1 per pixel), where the recording has one.
    references: Vec<Option<Vec<u8>>>,
    /// What the replay could not honour.
    notes: Vec<String>,
    /// A camera on a head: the mount (`head_from_camera`); the head's poses are the
    /// recording's.
    head_mount: Option<Isometry3<f64>>,
    /// `--room`: the background follows the view, through the room's boxes in the base frame.
    view_background: Option<ViewBackgroundConfig>,
    /// The drift watch's report, where it ran.
    drift: Option<avatarm_footage::drift::DriftReport>,
}

impl Input {
    fn load(o: &RecordingOptions) -> Result<Self, AppError> {
        let recording = Recording::open(&o.recording)?;
        let name = o.recording.display().to_string();
        let bad = |message: String| AppError::recording(name.to_owned(), message);
        let (calibration, intrinsics) = recording_camera(&recording, o.camera.as_deref(), &name)?;
        let size = (intrinsics.width, intrinsics.height);
        let mut notes = Vec::new();
        // A camera on a head: each frame's camera is the head's pose at its capture times the
        // mount.
        let pose_flag = o.pose.as_ref().map(|_| "--pose");
        let head = recording_mount(
            &recording,
            o.mount.as_deref(),
            pose_flag,
            "--believed-mount",
            &name,
        )?;
        let base_from_camera = match (&o.pose, head) {
            (_, Some(mount)) => {
                let first = recording.frames.first().map_or(0, |f| f.stamp_ns);
                recording.head_at(first).unwrap_or_default() * mount
            }
            (Some(path), None) => read_pose(path)?,
            (None, None) => recording.base_from_camera.ok_or_else(|| {
                bad("the recording has no camera pose: give one with --pose FILE".into())
            })?,
        };
        if head.is_some() {
            let outside = recording
                .frames
                .iter()
                .filter(|f| !recording.head_covers(f.stamp_ns, avatarm_record::HEAD_POSE_SLACK_NS))
                .count();
            if outside > 0 {
                notes.push(format!(
                    "{outside} frames were captured more than {} ms outside the tracked head poses: their masks are drawn at the nearest pose",
                    avatarm_record::HEAD_POSE_SLACK_NS / 1_000_000
                ));
            }
            if !o.settings.pose_compensation {
                notes.push(
                    "pose compensation cannot be switched off for a recording: each frame is handed over with the head's pose at its capture".into(),
                );
            }
            notes.push(if o.room.is_some() {
                "the camera rides on a head: each frame's mask is drawn at the tracked head's pose at its capture times the mount; the background follows the view: the frames' pixels the robot cannot cover are kept as views and re-projected into each frame through the room's boxes (--room), so what stands off those planes (the bottle, the glass) lands displaced by parallax; where no view saw a pixel, the footage's median fills it".into()
            } else {
                "the camera rides on a head: each frame's mask is drawn at the tracked head's pose at its capture times the mount; the background built from the footage is one image for every view, so where the head turned the erased pixels show the wrong part of the room (the masks and their scores are not affected; --room SCENE makes it follow the view)".into()
            });
        }
        let view_background = match (&o.room, head) {
            (None, _) => None,
            (Some(_), None) => {
                return Err(AppError::flag(
                    "--room",
                    format!(
                        "{name}: the recording's camera is fixed, not on a head: its one background H serves every frame"
                    ),
                ));
            }
            (Some(path), Some(_)) => Some(room_background(
                path,
                &o.packages,
                recording.world_from_base,
                &mut notes,
            )?),
        };
        let lens = Distortion::from_ros(calibration.distortion_model.ros_name(), &calibration.d)?;
        // The mask's lens map, checked before any frame is decoded.
        let lens_map = EraseLens::new(&intrinsics, &lens, &o.settings)?;
        if let Some(m) = lens_map.0.as_ref().filter(|m| m.unmapped + m.outside > 0) {
            notes.push(format!(
                "the lens does not invert at {} pixels and the mask's render misses {} more: those pixels are never masked",
                m.unmapped, m.outside
            ));
        }
        if !lens.is_none() && !o.settings.lens_distortion {
            notes.push(format!(
                "the camera's {} distortion is ignored (lens_distortion off): the mask is a pinhole projection",
                calibration.distortion_model.ros_name()
            ));
        }
        let camera = PinholeCamera {
            intrinsics,
            world_from_camera: base_from_camera,
        };
        let model = Arc::new(RobotModel::from_urdf_file(&o.urdf, &o.packages)?);
        let states = joint_vectors(&recording, &model, &name, &mut notes)?;
        let frames = recording.frames.clone();
        let q = frames
            .iter()
            .map(|f| interpolate(&states, f.stamp_ns))
            .collect();
        let references = frames
            .iter()
            .map(|f| {
                recording
                    .reference_masks
                    .iter()
                    .find(|m| m.stamp_ns.abs_diff(f.stamp_ns) <= 1_000_000)
                    .map(|m| {
                        let img = decode(m, &name)?;
                        if img.dimensions() != size {
                            return Err(bad(format!(
                                "the reference mask at {} ns is {}x{}, the frames {}x{}",
                                m.stamp_ns,
                                img.width(),
                                img.height(),
                                size.0,
                                size.1
                            )));
                        }
                        Ok(dr::binarise(&img.into_raw(), 4))
                    })
                    .transpose()
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            recording,
            model,
            camera,
            lens,
            lens_map,
            calibration,
            size,
            frames,
            q,
            references,
            notes,
            head_mount: head,
            view_background,
            drift: None,
        })
    }
}

/// The view-following background of `--room SCENE`: the scene's boxes that are not objects
/// (desk, wall, floor), moved into the recording's base frame by the recording's
/// `world_from_base` (else the scene's robot base, said in `notes`); the scene's
/// `[camera.head.background]` views and separation where it has them (more than 0 views), else
/// their defaults, and its threads.
/// Errors: the scene does not load, or has no such box.
fn room_background(
    path: &Path,
    packages: &PackagePath,
    world_from_base: Option<Isometry3<f64>>,
    notes: &mut Vec<String>,
) -> Result<ViewBackgroundConfig, AppError> {
    let scene = avatarm_scene::Scene::load(path, packages)?;
    let world_from_base = world_from_base.unwrap_or_else(|| {
        notes.push(format!(
            "the recording has no robot base in the world: the room of {} is placed by its own robot base",
            path.display()
        ));
        scene.robot_base()
    });
    let proxy = crate::app::room_proxy(&scene, &world_from_base.inverse());
    if proxy.rects.is_empty() {
        return Err(AppError::flag(
            "--room",
            format!(
                "{}: no box that is not an object (a desk, a wall, a floor): no room to re-project the views through",
                path.display()
            ),
        ));
    }
    let defaults = avatarm_scene::spec::HeadBackgroundSpec::default();
    let (max_views, min_separation_rad) = scene
        .head
        .as_ref()
        .filter(|h| h.background_views > 0)
        .map_or(
            (
                defaults.views as usize,
                defaults.min_separation_deg.to_radians(),
            ),
            |h| (h.background_views, h.background_separation_rad),
        );
    // The threads whatever the views: a scene may set them alone.
    let threads = scene
        .head
        .as_ref()
        .map_or(defaults.threads as usize, |h| h.background_threads);
    Ok(ViewBackgroundConfig {
        proxy,
        max_views,
        min_separation_rad,
        threads,
    })
}

fn load_background(path: &Path, size: (u32, u32)) -> Result<Arc<Vec<u8>>, AppError> {
    let img = image::open(path)
        .map_err(|source| AppError::Image {
            path: path.to_owned(),
            action: "read",
            source,
        })?
        .to_rgba8();
    if img.dimensions() != size {
        return Err(AppError::flag(
            "--background",
            format!(
                "{} is {}x{}, the frames {}x{}",
                path.display(),
                img.width(),
                img.height(),
                size.0,
                size.1
            ),
        ));
    }
    Ok(Arc::new(img.into_raw()))
}

/// Which pass the replay is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pass {
    /// Every frame masked (no H yet).
    Mask,
    /// Every frame erased with H.
    Erase,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Updates to wait, then the pass.
    Settle(u32, Pass),
    /// The pass, at this frame.
    Run(Pass, usize),
    /// Every frame handed over; waiting for the read-backs.
    Drain(Pass),
    /// Finished: the results are handed back in this update.
    Done,
    /// The results were handed back; the app is quitting.
    Exited,
}

/// One frame's read-back images.
#[derive(Debug, Clone, Default)]
struct FrameOutput {
    /// M(t) of the mask pass (0/1), for H.
    first_mask: Option<Vec<u8>>,
    /// M(t) of the erase pass (0/1).
    mask: Option<Vec<u8>>,
    /// Ĩ(t) (RGBA8).
    composite: Option<Vec<u8>>,
    /// The mask twin's render (RGBA8 as the CPU reference reads it), for the reference check.
    raw: Option<(u32, u32, Vec<u8>)>,
    /// The live frame and H the passes had (for the CPU reference).
    inputs: Option<ErasedInputs>,
    /// A view-following background: the share of the robot's region some view saw, and how
    /// far (rad) the nearest kept view looked from this frame's camera.
    view: Option<(Option<f64>, Option<f64>)>,
}

/// The live frame, H (if any) and the photometric model a frame was erased with.
type ErasedInputs = (Arc<Vec<u8>>, Option<Arc<Vec<u8>>>, dr::Photometric);

/// What the app hands back.
struct Finished {
    outputs: Vec<FrameOutput>,
    background: Option<(BackgroundEstimate, String)>,
    times: avatarm_erase::SpanTimes,
    errors: Vec<String>,
}

#[derive(Resource)]
struct Driver {
    /// A camera on a head: the recording's head poses, by stamp.
    head: Vec<HeadPose>,
    frames: Vec<CompressedFrame>,
    q: Vec<DVector<f64>>,
    source: Entity,
    size: (u32, u32),
    margin_px: u32,
    phase: Phase,
    /// H to hand to the pipeline at the next pass's start, and where it came from.
    pending_background: Option<(Arc<Vec<u8>>, String)>,
    /// The background follows the view ([`RecordingOptions::room`]): the footage's median is
    /// a blend of many views, only the fallback where no view saw a pixel.
    view_background: bool,
    background: Option<(BackgroundEstimate, String)>,
    /// Each stretch the camera stood still (the drift watch's moves): the frame its H is handed
    /// over at (the first seen moved) and the frames H is built from (those masked at the
    /// stretch's own pose: the frames between the first seen moved and the one that confirmed
    /// it were masked at the old pose, so they build no H).
    stretches: Vec<(usize, std::ops::Range<usize>)>,
    /// The later stretches' H from the footage, by their first frame, handed over there.
    later_backgrounds: Vec<(usize, Arc<Vec<u8>>)>,
    /// The frame a pass goes on from after settling (a new H mid-pass).
    resume: usize,
    /// The frame handed over in this update: its index and pass.
    shown: Option<(usize, Pass)>,
    outputs: Vec<FrameOutput>,
    pending: usize,
    waited: u32,
    errors: Vec<String>,
    bar: indicatif::ProgressBar,
    result: Arc<Mutex<Option<Finished>>>,
}

/// Hands the next frame to the video and its joints to the recorded robot's twin, and moves
/// between the passes.
#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn feed(
    mut d: ResMut<Driver>,
    mut inbox: ResMut<VideoInbox>,
    mut twins: Query<&mut RobotTwin>,
    mut set_background: MessageWriter<SetBackground>,
    time: Res<Time<Fixed>>,
    times: Res<GpuTimes>,
    mut exit: MessageWriter<AppExit>,
    (targets, mut head): (Option<Res<EraseTargets>>, ResMut<HeadTracking>),
) {
    let d = &mut *d;
    d.shown = None;
    if targets.is_none() {
        return;
    }
    let now = time.elapsed_secs_f64();
    match d.phase {
        Phase::Settle(0, pass) => {
            if let Some((rgba, origin)) = d.pending_background.take() {
                // A file is one picture (taken where the first frame's camera is); the
                // footage's median of a moving camera is no one view's.
                let one_view = !(d.view_background && origin == FOOTAGE);
                set_background.write(SetBackground {
                    rgba,
                    width: d.size.0,
                    height: d.size.1,
                    origin: format!("{origin} (recording replay)"),
                    camera_pose: None,
                    one_view,
                });
                // H reaches the pipeline in the next update.
                d.phase = Phase::Settle(1, pass);
                return;
            }
            d.phase = Phase::Run(pass, d.resume);
            hand_over(d, &mut inbox, &mut twins, &mut head, now);
        }
        Phase::Settle(k, pass) => d.phase = Phase::Settle(k - 1, pass),
        // A stretch after the camera moved: its own H first.
        Phase::Run(Pass::Erase, i) if d.later_backgrounds.first().is_some_and(|b| b.0 == i) => {
            let (_, rgba) = d.later_backgrounds.remove(0);
            d.pending_background = Some((rgba, FOOTAGE.into()));
            d.resume = i;
            d.phase = Phase::Settle(0, Pass::Erase);
        }
        Phase::Run(..) => hand_over(d, &mut inbox, &mut twins, &mut head, now),
        Phase::Drain(pass) => {
            d.waited += 1;
            if d.pending > 0 && d.waited < MAX_WAIT_UPDATES {
                return;
            }
            if d.pending > 0 {
                d.errors
                    .push(format!("{} frame read-backs never arrived", d.pending));
            }
            match pass {
                Pass::Mask if d.errors.is_empty() => match still_backgrounds(d) {
                    Ok(mut estimates) => {
                        let first = estimates.remove(0).1;
                        d.later_backgrounds = estimates
                            .into_iter()
                            .map(|(from, e)| (from, Arc::new(e.rgba)))
                            .collect();
                        let rgba = Arc::new(first.rgba.clone());
                        d.pending_background = Some((rgba, FOOTAGE.into()));
                        d.background = Some((first, FOOTAGE.into()));
                        d.resume = 0;
                        d.phase = Phase::Settle(SETTLE_UPDATES, Pass::Erase);
                    }
                    Err(e) => {
                        d.errors.push(e);
                        d.phase = Phase::Done;
                    }
                },
                _ => d.phase = Phase::Done,
            }
        }
        Phase::Done | Phase::Exited => {}
    }
    if d.phase == Phase::Done {
        d.phase = Phase::Exited;
        d.bar.finish_and_clear();
        if let Ok(mut slot) = d.result.lock() {
            *slot = Some(Finished {
                outputs: std::mem::take(&mut d.outputs),
                background: d.background.take(),
                times: times.snapshot(),
                errors: std::mem::take(&mut d.errors),
            });
        }
        exit.write(AppExit::Success);
    }

    fn hand_over(
        d: &mut Driver,
        inbox: &mut VideoInbox,
        twins: &mut Query<&mut RobotTwin>,
        head: &mut HeadTracking,
        now: f64,
    ) {
        let Phase::Run(pass, i) = d.phase else {
            return;
        };
        let Some(frame) = d.frames.get(i) else {
            d.phase = Phase::Drain(pass);
            d.waited = 0;
            return;
        };
        let image = match image::load_from_memory(&frame.data) {
            Ok(img) => img.to_rgba8(),
            Err(e) => {
                d.errors
                    .push(format!("frame {i} at {} ns: {e}", frame.stamp_ns));
                d.phase = Phase::Done;
                return;
            }
        };
        let (w, h) = image.dimensions();
        let index = i as u64 + if pass == Pass::Erase { 1 << 32 } else { 0 };
        let pushed = inbox.push(VideoFrame {
            index,
            capture_s: now,
            arrival_s: now,
            width: w,
            height: h,
            rgba: Arc::new(image.into_raw()),
        });
        if let Err(e) = pushed {
            d.errors.push(format!("frame {i}: {e}"));
            d.phase = Phase::Done;
            return;
        }
        if !d.head.is_empty() {
            // The head's pose at the frame's capture (interpolated between the tracked poses
            // around it, as `avatarm calibrate` takes it), at the app's clock's `now`, the
            // frame's capture here: the mask's camera is that pose times the mount.
            head.history = PoseHistory::default();
            if let Some(pose) = avatarm_record::head_at(&d.head, frame.stamp_ns) {
                head.history.push(now, pose);
            }
        }
        if let Ok(mut twin) = twins.get_mut(d.source) {
            twin.positions.clone_from(&d.q[i]);
            twin.velocities = DVector::zeros(d.q[i].len());
            twin.stamp_s = Some(now);
        }
        d.shown = Some((i, pass));
        d.phase = Phase::Run(pass, i + 1);
        d.bar.inc(1);
    }
}

/// The stretches the camera stood still over `n` frames, from the drift watch's moves (each
/// the frame first seen moved and the frame that confirmed it, in order): the frame each
/// stretch's H is handed over at, and the frames it is built from (never empty where there are
/// frames: a stretch too short for its own falls back to all of its frames).
fn stretches(moves: &[(usize, usize)], n: usize) -> Vec<(usize, std::ops::Range<usize>)> {
    let mut out = Vec::new();
    let (mut switch, mut from) = (0, 0);
    for &(first_seen, confirmed) in moves {
        out.push((switch, from..first_seen.max(from)));
        (switch, from) = (first_seen, confirmed);
    }
    out.push((switch, from.min(n)..n));
    let ends: Vec<usize> = out.iter().skip(1).map(|s| s.0).chain([n]).collect();
    for ((switch, frames), end) in out.iter_mut().zip(ends) {
        if frames.start >= frames.end {
            *frames = *switch..end.max(*switch + 1).min(n);
        }
    }
    out
}

/// H from the footage for each stretch the camera stood still, by the frame it is handed over
/// at (at least one).
fn still_backgrounds(d: &Driver) -> Result<Vec<(usize, BackgroundEstimate)>, String> {
    d.stretches
        .iter()
        .map(|(switch, frames)| Ok((*switch, footage_background(d, frames.clone())?)))
        .collect()
}

/// Builds H from the mask pass over the frames in `range`: each frame's pixels its mask, grown
/// by the margin, leaves.
fn footage_background(
    d: &Driver,
    range: std::ops::Range<usize>,
) -> Result<BackgroundEstimate, String> {
    let (w, h) = d.size;
    let keep = range.len().clamp(1, 32);
    let mut b = FootageBackground::new(w, h, keep).map_err(|e| e.to_string())?;
    for (i, (frame, out)) in d
        .frames
        .iter()
        .zip(&d.outputs)
        .enumerate()
        .skip(range.start)
        .take(range.len())
    {
        let mask = out
            .first_mask
            .as_ref()
            .ok_or_else(|| format!("frame {i}: its mask never arrived"))?;
        let image = image::load_from_memory(&frame.data)
            .map_err(|e| format!("frame {i}: {e}"))?
            .to_rgba8();
        let covered = dr::dilate(mask, w, h, d.margin_px);
        let view = RgbaView::new("frame", w, h, image.as_raw()).map_err(|e| e.to_string())?;
        b.add(&view, &covered).map_err(|e| e.to_string())?;
    }
    Ok(b.estimate())
}

/// Reads back the pipeline's images of the frame handed over in this update.
fn request(
    mut commands: Commands,
    mut d: ResMut<Driver>,
    state: Res<EraseState>,
    targets: Option<Res<EraseTargets>>,
) {
    let (Some((i, pass)), Some(targets)) = (d.shown, targets) else {
        return;
    };
    let Some(current) = state.current.as_ref().filter(|c| c.dirty) else {
        return;
    };
    let Some((_, index, live)) = &current.frame else {
        return;
    };
    if *index & ((1 << 32) - 1) != i as u64 {
        d.errors.push(format!(
            "frame {i}: the pipeline erased frame {index} instead"
        ));
        return;
    }
    let parts: &[(Part, &Handle<Image>)] = match pass {
        Pass::Mask => &[(Part::FirstMask, &targets.mask)],
        Pass::Erase => &[
            (Part::Mask, &targets.mask),
            (Part::Composite, &targets.composite),
            (Part::Raw, &targets.raw),
        ],
    };
    if pass == Pass::Erase {
        d.outputs[i].inputs = Some((
            live.clone(),
            current.background.clone(),
            current.photometric,
        ));
        d.outputs[i].view = state
            .view_background
            .as_ref()
            .map(|v| (v.seen_share, v.nearest_rad));
    }
    for &(part, handle) in parts {
        d.pending += 1;
        read_image_once(&mut commands, handle.clone()).observe(
            move |read: On<ImageRead>, mut d: ResMut<Driver>| {
                d.pending = d.pending.saturating_sub(1);
                let out = &mut d.outputs[i];
                let data = read.data.clone();
                match part {
                    Part::FirstMask => {
                        out.first_mask = Some(dr::binarise(&data, read.bytes_per_pixel));
                    }
                    Part::Mask => out.mask = Some(dr::binarise(&data, read.bytes_per_pixel)),
                    Part::Composite => out.composite = Some(data),
                    Part::Raw => {
                        let rgba = if read.bytes_per_pixel == 1 {
                            dr::grey_to_rgba(&data)
                        } else {
                            data
                        };
                        out.raw = Some((read.width, read.height, rgba));
                    }
                }
            },
        );
    }
}

#[derive(Debug, Clone, Copy)]
enum Part {
    FirstMask,
    Mask,
    Composite,
    Raw,
}

use avatarm_core::stats::Spread;

#[cfg(test)]
mod tests {
    use super::stretches;

    #[test]
    fn each_still_stretch_builds_its_background_from_its_own_pose_s_frames() {
        // No move: one stretch, every frame.
        assert_eq!(stretches(&[], 10), vec![(0, 0..10)]);
        // Seen moved at 4, confirmed at 6: frames 4 and 5 were masked at the old pose and
        // build no H; the new H is handed over at 4.
        assert_eq!(stretches(&[(4, 6)], 10), vec![(0, 0..4), (4, 6..10)]);
        // A second move seen before the first one's confirmed frame: that stretch has no frame
        // masked at its own pose and falls back to its own frames.
        assert_eq!(
            stretches(&[(4, 6), (5, 8)], 10),
            vec![(0, 0..4), (4, 4..5), (5, 8..10)]
        );
        // Confirmed at the last frame: that frame alone.
        assert_eq!(stretches(&[(4, 9)], 10), vec![(0, 0..4), (4, 9..10)]);
    }
}
