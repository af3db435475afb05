//! `avatarm replay --recording`'s report (`report.json`), typed. Read back with
//! `serde_json::from_str`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::replay::report::{GpuVsCpu, LensReport, Times};

/// A recording's replay through the erase.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingReport {
    /// The recording, as given.
    pub recording: String,
    /// The robot description's name.
    pub robot: String,
    /// Frames erased.
    pub frames: usize,
    /// Their size (width, height; px).
    pub size: [u32; 2],
    /// The camera the mask was drawn through.
    pub camera: RecordingCamera,
    /// The erase's settings.
    pub erase: RecordingErase,
    /// Where H came from and how much of the robot's region it saw.
    pub background: RecordingBackground,
    /// The mask's coverage, and its scores against the recording's reference masks.
    pub mask: RecordingMask,
    /// The GPU passes against the CPU reference on the same inputs.
    pub gpu_vs_cpu: GpuVsCpu,
    /// The erase's GPU passes.
    pub timing_ms: RecordingTimings,
    /// The drift watch (a fixed camera that moved, found and fitted again); `None` when off.
    #[serde(default)]
    pub drift: Option<avatarm_footage::drift::DriftReport>,
    /// The whole command's wall time (s).
    pub wall_time_s: f64,
    /// What the user should know (joints never named, the background's origin, ...).
    pub notes: Vec<String>,
    /// Files written besides the images.
    pub outputs: RecordingOutputs,
}

/// The recording's camera (px), lens and, for a camera on a head, its mount.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingCamera {
    /// Focal length in x.
    pub fx: f64,
    /// Focal length in y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
    /// ROS's name of the lens model.
    pub distortion_model: String,
    /// The lens and how the mask honoured it.
    pub lens: LensReport,
    /// A camera on a head: the head poses and the mount used.
    pub head: Option<HeadMount>,
}

/// A camera on a head.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeadMount {
    /// Tracked head poses in the recording.
    pub head_poses: usize,
    /// The mount used.
    pub head_from_camera: MountPose,
}

/// `head_from_camera` (OpenCV optical axes).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MountPose {
    /// Translation (m).
    pub translation: [f64; 3],
    /// Rotation (x, y, z, w).
    pub quaternion_xyzw: [f64; 4],
}

/// The erase's settings used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingErase {
    /// The mask's dilation (px).
    pub dilate_px: u32,
    /// Where it comes from: `--dilate`, the calibration's margin in a pose file, the default.
    pub dilate_from: String,
    /// The alpha ramp's width (px).
    pub feather_px: u32,
    /// The mask twin's render scale.
    pub resolution_scale: f64,
    /// Whether H's brightness followed the live frame's.
    pub photometric: bool,
    /// Whether the margin's band was refined to each frame (`--refine-edges`): the band's
    /// pixels that look like H given back ([`avatarm_core::dr::refine_band`]).
    #[serde(default)]
    pub refine_edges: bool,
}

/// Where H came from. Built from the footage: how much of the robot's region some frame
/// showed (the rest filled from the surroundings).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingBackground {
    /// `the footage`, the photograph's path, or a room's views; `None` with none.
    pub source: Option<String>,
    /// How far beyond the masks a pixel counted as possibly the robot (px).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub margin_px: Option<u32>,
    /// Of the pixels any frame's mask covered, the share whose background some frame showed
    /// (%).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_region_seen_pct: Option<f64>,
    /// The share of the frame filled from the surroundings (%).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub filled_pct_of_frame: Option<f64>,
    /// How to read it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// A camera on a head with `--room`: the view-following background.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view_following: Option<ViewFollowing>,
}

/// The view-following background of a camera on a head.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewFollowing {
    /// The room's scene file.
    pub room: Option<String>,
    /// The room's boxes used as the proxy.
    pub proxy_rects: usize,
    /// Views kept at most.
    pub max_views: usize,
    /// The least angle between two kept views (deg).
    pub min_separation_deg: f64,
    /// Of the robot's region, the mean share some view saw (%).
    pub robot_region_seen_pct_mean: Option<f64>,
    /// The angle to the nearest view at each frame (deg).
    pub nearest_view_deg: Times,
    /// How to read it.
    pub note: String,
}

/// The mask's coverage and scores.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingMask {
    /// The mean share of the frame masked (%).
    pub coverage_pct_mean: Option<f64>,
    /// Against the recording's reference masks, where it has them.
    pub vs_reference: VsReference,
    /// What the erased frames still show of the robot just outside the mask (no reference
    /// needed); `None` with no background to tell the robot from.
    #[serde(default)]
    pub rim: Option<RimReport>,
}

/// The rim: robot-coloured pixels left in a ring outside the erased region
/// ([`avatarm_core::dr::rim_score`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RimReport {
    /// The ring's width (px).
    pub ring_px: u32,
    /// Levels by which a pixel differs from H' to count as not the background.
    pub difference_levels: u8,
    /// Frames scored (those with enough robot pixels to learn its colours from).
    pub frames_scored: usize,
    /// Mean share of the ring shown robot-coloured (%).
    pub rim_pct_mean: Option<f64>,
    /// The largest share of a frame (%).
    pub rim_pct_max: Option<f64>,
    /// Where the recording has reference masks: the mean share of the ring that is the robot
    /// by them (%), the truth the rim estimates.
    #[serde(default)]
    pub truth_pct_mean: Option<f64>,
    /// Each scored frame.
    pub per_frame: Vec<FrameRim>,
    /// How to read it.
    pub note: String,
}

/// One frame's rim.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrameRim {
    /// The frame's index.
    pub frame: usize,
    /// The ring's pixels whose H is known.
    pub ring_px: u64,
    /// Those shown robot-coloured.
    pub rim_px: u64,
    /// Their share (%).
    pub rim_pct: f64,
    /// By the reference mask, where there is one: the share of the ring that is the robot
    /// (%).
    #[serde(default)]
    pub truth_pct: Option<f64>,
}

/// The erased region against the reference masks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VsReference {
    /// Frames with a reference mask.
    pub frames_scored: usize,
    /// Mean intersection over union.
    pub iou_mean: Option<f64>,
    /// Smallest IoU of a frame.
    pub iou_min: Option<f64>,
    /// Mean share of the robot's pixels left (%).
    pub leak_pct_mean: Option<f64>,
    /// Mean share of the erased region outside the robot (%).
    pub overmask_pct_mean: Option<f64>,
    /// Each scored frame.
    pub per_frame: Vec<FrameVsReference>,
}

/// One frame's scores against its reference mask.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrameVsReference {
    /// The frame's index.
    pub frame: usize,
    /// Its capture stamp (ns).
    pub stamp_ns: u64,
    /// Intersection over union.
    pub iou: f64,
    /// Share of the robot's pixels left (%).
    pub leak_pct: f64,
    /// Share of the erased region outside the robot (%).
    pub overmask_pct: f64,
    /// The reference's robot pixels.
    pub robot_px: u64,
}

/// The erase's GPU passes (ms).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingTimings {
    /// Each pass's times.
    pub gpu_passes: BTreeMap<String, Times>,
    /// The uploads of the frame and H.
    pub upload: Times,
    /// `gpu`, or why not.
    pub source: String,
}

/// Files written besides the images.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingOutputs {
    /// The erased session as a recording.
    pub mcap: String,
}
