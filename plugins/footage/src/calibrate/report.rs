//! `avatarm calibrate`'s report (`report.json`), typed: what the fit was given, what it found,
//! how sure it is and what it wrote. Read back with `serde_json::from_str`.

use serde::{Deserialize, Serialize};

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrateReport {
    /// The recording, as given.
    pub recording: String,
    /// The robot description's name.
    pub robot: String,
    /// Triangles the robot's silhouette is drawn with.
    pub triangles: usize,
    /// Geometry below this height in the base frame was cut (m).
    pub hidden_below_m: Option<f64>,
    /// The lens the outlines were projected through.
    pub distortion: LensUsed,
    /// Frames with a silhouette (or edges) used at all (fit and held out).
    pub frames_used: usize,
    /// What the fit drew the model's outline to.
    pub silhouettes: SilhouetteSource,
    /// Frames in the fit.
    pub frames_fit: usize,
    /// Frames asked for that the fit left out as mispaired (the pairing check), fitted again
    /// without them.
    #[serde(default)]
    pub dropped_from_fit: Vec<usize>,
    /// The model silhouette's IoU against the reference masks before and after.
    pub iou: IouReport,
    /// `fixed`, or that the camera rides on a head (the fit is then the mount).
    pub camera: String,
    /// Tracked head poses in the recording.
    pub head_poses: usize,
    /// A fixed camera: its fitted pose in the robot's base frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_from_camera: Option<FittedPose>,
    /// A camera on a head: the fitted mount in the head's frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub head_from_camera: Option<FittedPose>,
    /// How far the fit moved the rough pose.
    pub change_from_rough: PoseChange,
    /// The intrinsics after the fit (as recorded unless fitted).
    pub intrinsics: FittedIntrinsics,
    /// The fit's cost at the rough pose and at the answer.
    pub cost_px: FitCost,
    /// How far other good starts ended from the answer.
    pub uncertainty: Uncertainty,
    /// The erase margin the fit calls for (written beside the pose as `erase_margin_px`);
    /// `None` when no outline could be measured.
    pub margin: Option<super::margin::EraseMargin>,
    /// Each frame's reference against every frame's joints (empty when skipped: see `notes`).
    pub pairing: Vec<Pairing>,
    /// Frames whose mask another frame's joints explain clearly better than their own.
    pub mispaired_frames: Vec<usize>,
    /// Cost evaluations in all.
    pub evaluations: u64,
    /// The fit's coarse-to-fine stages.
    pub stages: Vec<StageTime>,
    /// The whole command's wall time (s).
    pub wall_time_s: f64,
    /// What the user should know: frames left out, joints never named, suspicious answers.
    pub notes: Vec<String>,
    /// Files written.
    pub outputs: CalibrateOutputs,
}

impl CalibrateReport {
    /// The fitted pose: the mount for a camera on a head, else the camera's pose.
    pub fn pose(&self) -> Option<&FittedPose> {
        self.head_from_camera
            .as_ref()
            .or(self.base_from_camera.as_ref())
    }
}

/// The lens model and coefficients (ROS's names) and whether it was applied.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LensUsed {
    /// `plumb_bob`, `rational_polynomial`, `equidistant` or `none`.
    pub model: String,
    /// Its coefficients (ROS's D).
    pub coefficients: Vec<f64>,
    /// False for a pinhole camera.
    pub applied: bool,
}

/// Where the silhouettes (or edges) came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SilhouetteSource {
    /// `reference masks`, `background difference` or the image edges.
    pub source: String,
    /// `--edges`: Canny's low and high thresholds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub canny_thresholds: Option<[f32; 2]>,
    /// `--background`: the photograph.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub background: Option<String>,
    /// `--background`: the difference that counts as the robot (8-bit levels).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threshold: Option<u8>,
    /// `--background`: the differences' mean IoU against the reference masks, where both exist.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iou_vs_reference_mean: Option<f64>,
}

/// Mean IoUs before and after, on the fit's frames and on those held out (none where no frame
/// of the kind has a reference mask).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IouReport {
    /// Fit frames, at the rough pose.
    pub fit_before: Option<f64>,
    /// Fit frames, at the answer.
    pub fit_after: Option<f64>,
    /// Held-out frames, at the rough pose.
    pub held_out_before: Option<f64>,
    /// Held-out frames, at the answer.
    pub held_out_after: Option<f64>,
    /// Every frame used.
    pub per_frame: Vec<FrameIou>,
}

/// One frame's IoUs (none without a reference mask).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameIou {
    /// The frame's index in the recording.
    pub frame: usize,
    /// In the fit (else held out).
    pub fit: bool,
    /// At the rough pose.
    pub iou_before: Option<f64>,
    /// At the answer.
    pub iou_after: Option<f64>,
}

/// A fitted pose: `parent_from_camera`, OpenCV optical axes (x right, y down, z forward).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FittedPose {
    /// Translation (m).
    pub translation: [f64; 3],
    /// Rotation as a unit quaternion (x, y, z, w).
    pub quaternion_xyzw: [f64; 4],
    /// The same rotation as roll, pitch, yaw (rad; nalgebra's `euler_angles`).
    pub rpy: [f64; 3],
}

/// The change from the rough pose to the answer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseChange {
    /// Rotation angle (deg).
    pub rotation_deg: f64,
    /// Translation (mm).
    pub translation_mm: f64,
}

/// The intrinsics after the fit (px).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FittedIntrinsics {
    /// Focal length in x.
    pub fx: f64,
    /// Focal length in y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
    /// Whether fx and fy were fitted (`--intrinsics`).
    pub fitted: bool,
}

/// The mean truncated chamfer distance between the outlines at half resolution (px).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitCost {
    /// At the rough pose.
    pub rough: f64,
    /// At the answer.
    pub fitted: f64,
}

/// How far the answer may be off: the starts' spread.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Uncertainty {
    /// The largest rotation between the answer and another start that ended within 10 % of
    /// its cost (deg).
    pub spread_deg: f64,
    /// The same for translation (mm).
    pub spread_mm: f64,
    /// Each start: its offset from the rough pose and where it ended.
    pub starts: Vec<StartReport>,
    /// How to read the figures.
    pub note: String,
}

/// One start of the fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StartReport {
    /// Its rotation offset from the rough pose (roll, pitch, yaw, deg).
    pub start_deg: [f64; 3],
    /// Its translation offset (m).
    pub start_m: [f64; 3],
    /// The cost it ended at (px).
    pub cost_px: f64,
}

/// One frame's reference mask against the silhouettes at every frame's joints.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pairing {
    /// The frame.
    pub frame: usize,
    /// IoU with its own joints.
    pub own_joints_iou: f64,
    /// The frame whose joints fit its mask best.
    pub best_joints_frame: usize,
    /// That IoU.
    pub best_joints_iou: f64,
}

/// One stage of the fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageTime {
    /// `coarse`, `fine` or `full`.
    pub stage: String,
    /// Its wall time (s).
    pub seconds: f64,
    /// Its cost evaluations.
    pub evaluations: u64,
}

/// The files written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrateOutputs {
    /// `camera_pose.yaml` or `camera_mount.yaml`.
    pub pose: String,
    /// `camera_info.yaml` with `--intrinsics`.
    pub camera: Option<String>,
}
