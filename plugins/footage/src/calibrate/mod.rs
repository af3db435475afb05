//! The camera's pose fitted to the robot itself (`avatarm calibrate --recording FILE.mcap --urdf
//! DESCRIPTION`), so that the mask lands on the robot without a calibration board.
//!
//! The recording gives the frames' robot silhouettes (its reference masks, or with
//! `--background FILE` each frame's difference from an empty-room photograph,
//! [`dr::background_difference`]), the joints at each frame (interpolated to the capture
//! time) and K; the rough pose comes from `--pose FILE`,
//! `--look-at EYE,TARGET` or the recording. [`avatarm_core::vision::calibrate`] fits the pose
//! (and with `--intrinsics` fx, fy) on the `--fit` frames; the IoU of the model silhouette
//! against the reference is measured on every frame before and after, so that `--eval` frames
//! left out of the fit say how well the pose generalises. With `--edges` no silhouette is
//! needed: the fit draws the robot's outline to each frame's own image edges (Canny's), among
//! the room's ([`Observed::Edges`]); reference masks, where the recording has them, only score
//! it. Written to `--out`:
//! `camera_pose.yaml` (`base_from_camera`, a 4x4 matrix: what `--pose` and `avatarm import
//! --pose` read), `camera_info.yaml` with `--intrinsics`, `overlay_before_NNNNN.png` and
//! `overlay_after_NNNNN.png` (the model's silhouette tinted red, the reference's outline in
//! green; with `--edges` the frame's Canny edges in yellow, and each frame's edge map, white on
//! black, in `edges_NNNNN.png`), and `report.json`.
//!
//! A recording of a camera on a head (Alice's headset camera: the head's tracked poses and the
//! mount, `avatarm_record::HEAD_FRAME`) gets its *mount* fitted instead: each frame's robot is
//! put in the head's frame at the frame's capture (the tracked poses interpolated to it), where
//! one `camera_from_head` must explain every frame, and the same fit runs on it from the rough
//! mount (`--mount FILE`, or the recording's). The views from several head poses constrain it
//! better than one fixed view does. Written: `camera_mount.yaml` (`head_from_camera`: what
//! `--mount` and `avatarm replay --believed-mount` read) instead of `camera_pose.yaml`.

//!
//! The command runs in stages, each its own function: [`Inputs::load`] (the recording, the
//! description, the lens and the rough pose, every flag checked), `frames::used` (each
//! frame's silhouette or edges, and the mask it is scored against), the fit
//! ([`avatarm_core::vision::calibrate::calibrate`]), `outputs` (the IoUs and overlays before
//! and after, the pairing check, the pose and camera files) and the typed report
//! ([`CalibrateReport`]).

use std::path::PathBuf;
use std::time::Instant;

use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::vision::calibrate::{
    CalibrationOptions, Observed, RobotSilhouette, SilhouetteFrame, calibrate,
};
use avatarm_core::vision::camera::{CameraPose, Intrinsics};
use avatarm_core::vision::distortion::Distortion;
use avatarm_record::Recording;
use avatarm_record::camera::{CameraCalibration, read_pose};
use nalgebra::{DVector, Isometry3};

use crate::FootageError;
use crate::recording::{joint_vectors, recording_camera, recording_mount};

mod frames;
pub mod margin;
mod outputs;
mod report;

pub use report::{
    CalibrateOutputs, CalibrateReport, FitCost, FittedIntrinsics, FittedPose, FrameIou, IouReport,
    LensUsed, Pairing, PoseChange, SilhouetteSource, StageTime, StartReport, Uncertainty,
};

/// The pairing check draws every frame's joints against every frame's mask: up to this many.
const MAX_PAIRING_FRAMES: usize = 60;

/// Frames one fit takes at most (10 take 50 s on two cores).
const MAX_FIT_FRAMES: usize = 100;

/// The largest Sobel gradient's magnitude of 8-bit luma, in imageproc's scale (its `canny`
/// doc): a higher threshold finds no edge.
pub const MAX_SOBEL: f32 = 1141.0;

/// What `avatarm calibrate` is given.
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// The recording (MCAP) with reference masks.
    pub recording: PathBuf,
    /// The robot's description.
    pub urdf: PathBuf,
    /// Folders searched for its `package://` URIs.
    pub packages: PackagePath,
    /// A camera file instead of the recording's calibration.
    pub camera: Option<PathBuf>,
    /// The rough pose from a file.
    pub pose: Option<PathBuf>,
    /// The rough pose as the camera's eye and a point it looks at, in the base frame (m).
    pub look_at: Option<([f64; 3], [f64; 3])>,
    /// A camera on a head: the rough mount from a file (`head_from_camera`), else the
    /// recording's.
    pub mount: Option<PathBuf>,
    /// Frames the fit uses (inclusive ranges of indices); every frame with a silhouette when
    /// empty (a reference mask, or with `background` every frame).
    pub fit: Vec<(usize, usize)>,
    /// Only every N-th frame with a silhouette is used at all (fit and measured).
    pub every: usize,
    /// Also fit fx and fy.
    pub fit_focal: bool,
    /// Keep the fit's frames the pairing check finds mispaired (by default the pose is
    /// fitted again without them while two frames remain).
    pub keep_mispaired: bool,
    /// Triangles the robot's silhouette is drawn with.
    pub budget: usize,
    /// The robot's geometry below this height in the base frame (m) is hidden (the table it
    /// stands on) and cut from the silhouette.
    pub hidden_below: Option<f64>,
    /// An empty-room photograph of the same camera: the silhouettes are each frame's
    /// difference from it instead of the reference masks.
    pub background: Option<PathBuf>,
    /// The difference (8-bit levels, any channel) that counts as the robot.
    pub background_threshold: u8,
    /// Fit to each frame's image edges instead of silhouettes: Canny's low and high
    /// thresholds on the Sobel gradient's magnitude of the blurred luma (imageproc's scale: a
    /// clean step of N 8-bit levels gives about 2N to 4N; at most 1141, `MAX_SOBEL`).
    pub edges: Option<(f32, f32)>,
    /// Output folder.
    pub out: PathBuf,
}

/// What the fit works from, loaded and checked.
struct Inputs {
    /// The recording's path, as given (errors and the report name it so).
    name: String,
    recording: Recording,
    calibration: CameraCalibration,
    k: Intrinsics,
    /// The frames' size (px).
    size: (u32, u32),
    /// The camera rides on a head: the fit is of the mount, each frame's robot in the head's
    /// frame.
    on_head: bool,
    /// The rough `camera_from_base` (for a camera on a head, `camera_from_head`).
    rough: Isometry3<f64>,
    model: RobotModel,
    /// The lens: every projected vertex goes through it, in the fit and in the IoUs.
    lens: Distortion,
    /// The joint states in the description's order, by stamp.
    states: Vec<(u64, DVector<f64>)>,
    silhouette: RobotSilhouette,
    /// `--background`'s photograph (RGBA8).
    background: Option<Vec<u8>>,
}

impl Inputs {
    /// Reads the recording, the description and the photograph, and checks every flag against
    /// them and each other; what the user should know goes to `notes`.
    fn load(o: &CalibrateOptions, notes: &mut Vec<String>) -> Result<Self, FootageError> {
        let name = o.recording.display().to_string();
        let recording = Recording::open(&o.recording)?;
        let (calibration, k) = recording_camera(&recording, o.camera.as_deref(), &name)?;
        let size = (k.width, k.height);
        // A camera on a head: the fit is of the mount. Each frame's robot is put in the head's
        // frame at the frame's capture, so that one camera_from_head explains every frame.
        let pose_flag = match (&o.pose, &o.look_at) {
            (Some(_), _) => Some("--pose"),
            (None, Some(_)) => Some("--look-at"),
            (None, None) => None,
        };
        let head_from_camera =
            recording_mount(&recording, o.mount.as_deref(), pose_flag, "--mount", &name)?;
        let on_head = head_from_camera.is_some();
        check_flags(o, on_head, &name)?;
        let base_from_camera = match (head_from_camera, &o.pose, &o.look_at) {
            (Some(mount), _, _) => mount,
            (None, Some(path), _) => read_pose(path)?,
            (None, None, Some((eye, target))) => CameraPose {
                eye: *eye,
                target: *target,
                up: [0.0, 0.0, 1.0],
            }
            .to_isometry()?,
            (None, None, None) => recording.base_from_camera.ok_or_else(|| {
                FootageError::input(
                    &name,
                    "no rough pose: give --pose FILE or --look-at EYE,TARGET (the recording has none)",
                )
            })?,
        };
        let model = RobotModel::from_urdf_file(&o.urdf, &o.packages)?;
        let lens = Distortion::from_ros(calibration.distortion_model.ros_name(), &calibration.d)?;
        let states = joint_vectors(&recording, &model, &name, notes)?;
        let silhouette = RobotSilhouette::new(&model, o.budget)?;
        let background = match &o.background {
            Some(path) => Some(read_background(path, size)?),
            None => None,
        };
        Ok(Self {
            name,
            recording,
            calibration,
            k,
            size,
            on_head,
            rough: base_from_camera.inverse(),
            model,
            lens,
            states,
            silhouette,
            background,
        })
    }
}

/// The flags that cannot go together, or are out of range.
fn check_flags(o: &CalibrateOptions, on_head: bool, name: &str) -> Result<(), FootageError> {
    if o.edges.is_some() && o.background.is_some() {
        return Err(FootageError::input(
            "--edges",
            "fits to the frames' own edges: give it or --background, not both",
        ));
    }
    if let Some((low, high)) = o.edges
        && !(low.is_finite() && high.is_finite() && low > 0.0 && low <= high && high <= MAX_SOBEL)
    {
        return Err(FootageError::input(
            "--edge-thresholds",
            format!(
                "{low},{high}: give LOW,HIGH with 0 < LOW <= HIGH <= {MAX_SOBEL} (the Sobel gradient's magnitude)"
            ),
        ));
    }
    if on_head && o.background.is_some() {
        return Err(FootageError::input(
            "--background",
            format!(
                "{name}: the camera rides on a head, so one photograph is not its empty room: fit to the recording's reference masks"
            ),
        ));
    }
    Ok(())
}

/// `--background`'s photograph as RGBA8, refused unless it is the frames' size.
fn read_background(path: &std::path::Path, size: (u32, u32)) -> Result<Vec<u8>, FootageError> {
    let image = image::open(path).map_err(|source| FootageError::Image {
        path: path.to_owned(),
        action: "read",
        source,
    })?;
    if (image.width(), image.height()) != size {
        return Err(FootageError::input(
            "--background",
            format!(
                "{} is {}x{}, the frames {}x{}",
                path.display(),
                image.width(),
                image.height(),
                size.0,
                size.1
            ),
        ));
    }
    Ok(image.to_rgba8().into_raw())
}

/// Fits the pose (or a head camera's mount); writes the pose file, the overlays and
/// `out/report.json`, and returns the report. `progress(done, total)` is told of the fit's
/// evaluations as they go.
///
/// Errors: every flag, file and recording content that cannot be used, named
/// ([`FootageError`]); the fit's own refusals ([`FootageError::Core`]).
pub fn run(
    o: &CalibrateOptions,
    progress: impl FnMut(usize, usize),
) -> Result<CalibrateReport, FootageError> {
    let started = Instant::now();
    let mut notes = Vec::new();
    let inputs = Inputs::load(o, &mut notes)?;
    if o.edges.is_some() {
        // For the edge maps, written as they are found.
        std::fs::create_dir_all(&o.out).map_err(|e| FootageError::create(&o.out, e))?;
    }
    let used = frames::used(o, &inputs, &mut notes)?;
    let asked = |i: usize| o.fit.is_empty() || o.fit.iter().any(|&(a, b)| (a..=b).contains(&i));
    std::fs::create_dir_all(&o.out).map_err(|e| FootageError::create(&o.out, e))?;
    let options = CalibrationOptions {
        observed: if o.edges.is_some() {
            Observed::Edges
        } else {
            Observed::Silhouette
        },
        fit_focal: o.fit_focal,
        distortion: inputs.lens,
        ..CalibrationOptions::default()
    };
    // The fit, and again without the fit's frames the pairing check finds mispaired (their
    // joints belong to another image: no pose fits them, and they pull the fit off the
    // others), while at least two frames remain.
    let mut dropped: Vec<usize> = Vec::new();
    let mut progress = progress;
    let (fit, result, scored, pairing) = loop {
        let in_fit = |i: usize| asked(i) && !dropped.contains(&i);
        let fit: Vec<SilhouetteFrame> = used
            .frames
            .iter()
            .filter(|f| in_fit(f.index))
            .map(|f| f.silhouette.clone())
            .collect();
        check_fit(&fit, &used.frames)?;
        let result = calibrate(&fit, &inputs.k, &inputs.rough, &options, &mut progress)?;
        let scored = outputs::score(o, &inputs, &used.frames, &result, in_fit)?;
        let mut pairing_notes = Vec::new();
        let pairing = outputs::pairing(&used.frames, &scored.drawn, &mut pairing_notes);
        let newly: Vec<usize> = pairing.1.iter().copied().filter(|&i| in_fit(i)).collect();
        if o.keep_mispaired || newly.is_empty() || fit.len() - newly.len() < 2 {
            notes.extend(pairing_notes);
            if !o.keep_mispaired && !newly.is_empty() {
                notes.push(format!(
                    "frames {newly:?} of the fit look mispaired but stay in it: fewer than two frames would remain without them"
                ));
            }
            break (fit, result, scored, pairing);
        }
        notes.push(format!(
            "frames {newly:?} of the fit look mispaired (pairing): fitted again without them{}",
            if dropped.is_empty() {
                ""
            } else {
                " and those dropped before"
            }
        ));
        dropped.extend(newly);
    };
    if !dropped.is_empty() {
        dropped.sort_unstable();
        notes.push(format!(
            "the pose is fitted without the mispaired frames {dropped:?} (--keep-mispaired keeps them in the fit)"
        ));
        let cleared: Vec<usize> = dropped
            .iter()
            .copied()
            .filter(|i| !pairing.1.contains(i))
            .collect();
        if !cleared.is_empty() {
            notes.push(format!(
                "frames {cleared:?}, dropped at an earlier fit's pose, are not found mispaired at the final one (a fit pulled off by the others misjudged them, or they are close calls): they are measured for the margin but not fitted"
            ));
        }
    }
    outputs::note_far_move(o, &inputs, &result, &options, &mut notes);
    let (w, h) = inputs.size;
    let margin = margin::erase_margin(
        &used.frames,
        &scored.drawn,
        &pairing.1,
        (w as usize, h as usize),
        o.edges.is_some(),
        &result,
    );
    match &margin {
        None => notes.push("no outline could be measured: no erase margin is written beside the pose (replay then dilates by --dilate, 0 by default)".into()),
        Some(m) if m.capped => notes.push(format!(
            "the fit calls for an erase margin beyond {} px, or its starts' answers lie more than {} px apart (its outline p95 {:.1} px, its spread over starts {:.1} px): too uncertain to erase with, so none is written beside the pose; check the overlays and fit again (a closer rough pose, frames that carry their own joints)",
            margin::MAX_MARGIN_PX, margin::MAX_SPREAD_PX, m.outline_p95_px, m.spread_px
        )),
        Some(_) => {}
    }
    let files = outputs::write_files(o, &inputs, &result, fit.len(), margin.as_ref())?;
    let report = outputs::report(&outputs::Parts {
        o,
        inputs: &inputs,
        used: &used,
        result: &result,
        per_frame: scored.per_frame,
        pairing,
        frames_fit: fit.len(),
        dropped_from_fit: dropped,
        outputs: files,
        margin,
        notes,
        wall_time_s: started.elapsed().as_secs_f64(),
    });
    let path = o.out.join("report.json");
    let text = serde_json::to_string_pretty(&report)?;
    std::fs::write(&path, text + "\n").map_err(|e| FootageError::write(path, e))?;
    Ok(report)
}

/// The fit's frames: some, and not so many that each evaluation costs too much.
fn check_fit(fit: &[SilhouetteFrame], used: &[frames::UsedFrame]) -> Result<(), FootageError> {
    if let ([first, ..], [.., last]) = (used, used)
        && fit.is_empty()
    {
        return Err(FootageError::input(
            "--fit",
            format!(
                "no frame with a silhouette (or edges) in that range (frames {} to {})",
                first.index, last.index
            ),
        ));
    }
    if fit.len() > MAX_FIT_FRAMES {
        return Err(FootageError::input(
            "--every",
            format!(
                "{} frames to fit: at most {MAX_FIT_FRAMES} (each costs every evaluation); thin them with --every N or pick them with --fit",
                fit.len()
            ),
        ));
    }
    Ok(())
}

/// The frame's image edges, 0/1 per pixel (top row first): Canny's detector on its luma
/// (`imageproc::edges::canny`: a Gaussian of σ 1.4, Sobel gradients, non-maximum suppression,
/// then hysteresis between `low` and `high` on the gradient's magnitude, in imageproc's scale,
/// [`MAX_SOBEL`] at most).
pub(crate) fn image_edges(frame: &image::RgbaImage, (low, high): (f32, f32)) -> Vec<u8> {
    let grey = image::imageops::grayscale(frame);
    imageproc::edges::canny(&grey, low, high)
        .into_raw()
        .into_iter()
        .map(|v| u8::from(v != 0))
        .collect()
}
