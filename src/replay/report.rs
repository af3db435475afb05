//! The replay's report (`report.json`), typed: [`ReplayReport`] for one camera,
//! [`ViewsReport`] for a scene replayed through each of its cameras; and how its parts are
//! made (the stages' timings, spreads and means, the lens and a moving head's figures).
//! Read back with `serde_json::from_str`.

use std::collections::BTreeMap;

use avatarm_core::dr::EraseSettings;
use avatarm_core::stats::Spread;
use serde::Deserialize;

use super::*;
use crate::replay::task::ObjectReport;

/// Times (ms) or another series summarised: median, p95, largest and count; `None` (null)
/// when nothing was measured.
pub type Times = Option<Spread>;

/// One camera's replay of a scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayReport {
    /// The scene's name.
    pub scene: String,
    /// Its file.
    pub scene_file: String,
    /// Its seed.
    pub seed: u64,
    /// Camera frames replayed.
    pub frames: u64,
    /// Frames the erase published.
    pub frames_shown: u64,
    /// Frames saved as images.
    pub frames_written: usize,
    /// Every N-th frame saved.
    pub frames_every: u32,
    /// Simulated time (s).
    pub sim_time_s: f64,
    /// Wall time (s).
    pub wall_time_s: f64,
    /// Simulated seconds per wall second.
    pub sim_s_per_wall_s: f64,
    /// The camera replayed.
    pub camera: ReplayCamera,
    /// The robot.
    pub robot: ReplayRobot,
    /// The scene's `[erase]` settings.
    pub erase: EraseSettings,
    /// A camera on a head: its motion, tracking and the mask camera's error; `None` for a
    /// fixed camera.
    pub head: Option<HeadReport>,
    /// Where H came from.
    pub background: Option<String>,
    /// The erased region against the true silhouette, over the frames with the robot in view.
    pub mask: MaskReport,
    /// The erased frame against the room without the robot, in the robot's region.
    pub dr: DrReport,
    /// The GPU passes against the CPU reference on the same inputs.
    pub gpu_vs_cpu: GpuVsCpu,
    /// The erase's stages.
    pub timing_ms: StageTimings,
    /// The files' names in the output folder.
    pub outputs: ReplayOutputs,
    /// Replayed through one of several cameras: its name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Replayed through one of several cameras: its folder (relative to the views' report).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub out: Option<String>,
    /// The scene's `[task]` trials.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<ObjectReport>,
    /// A `[chess]` scene: the game the video shows (the scripted hand playing the opening on
    /// the simulated arm, intent on, no delay), each move measured as `avatarm bench chess`
    /// measures it (a move not reached by the end has no grasp or placement).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chess: Option<Vec<avatarm_mapping::chess::MoveResult>>,
}

/// A scene replayed through each of its cameras in turn.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewsReport {
    /// The scene's name.
    pub scene: String,
    /// Its file.
    pub scene_file: String,
    /// Its seed.
    pub seed: u64,
    /// Each camera's report, in the scene's order.
    pub cameras: Vec<ReplayReport>,
    /// How to read it.
    pub note: String,
    /// The scene's `[task]` trials (once).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<ObjectReport>,
}

/// The camera replayed: intrinsics (px), rate and lens.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayCamera {
    /// Its name in the scene.
    pub name: String,
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// Focal length in x (px).
    pub fx: f64,
    /// Focal length in y (px).
    pub fy: f64,
    /// Principal point x (px).
    pub cx: f64,
    /// Principal point y (px).
    pub cy: f64,
    /// Frames per second.
    pub fps: f64,
    /// Capture to arrival (s).
    pub frame_latency_s: f64,
    /// Its lens and how the mask honoured it.
    pub lens: LensReport,
}

/// The robot of the replay.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayRobot {
    /// The description's name.
    pub name: String,
    /// Degrees of freedom.
    pub dof: usize,
    /// The control rate (Hz).
    pub control_rate_hz: f64,
    /// The simulated arm's timing.
    pub sim: avatarm_core::sim::SimRobotParams,
    /// Joint states the app's twin refused.
    pub twin_states_rejected: u64,
    /// The stamp of the newest joint state the twin took (s).
    pub twin_last_stamp_s: Option<f64>,
}

/// A camera's lens: its model and coefficients, whether the mask honoured it and the size of
/// the mask's pinhole render.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LensReport {
    /// ROS's name of the model.
    pub model: String,
    /// Its coefficients (OpenCV's order).
    pub coefficients: Vec<f64>,
    /// Whether the mask was drawn through it.
    pub honoured: bool,
    /// The mask's pinhole render (width, height; px).
    pub mask_render: Option<[u32; 2]>,
    /// Pixels never masked: past a barrel's fold.
    pub pixels_unmapped: Option<usize>,
    /// Pixels beyond the render's 3x cap.
    pub pixels_outside_render: Option<usize>,
}

/// The erased region against the true silhouette, over the frames with the robot in view
/// (`None` where no frame had it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MaskReport {
    /// Mean intersection over union.
    pub iou_mean: Option<f64>,
    /// Smallest IoU of a frame.
    pub iou_min: Option<f64>,
    /// Mean share of the robot's pixels left in the frame (%).
    pub leak_pct_mean: Option<f64>,
    /// Largest leak of a frame (%).
    pub leak_pct_max: Option<f64>,
    /// Mean share of the erased region outside the robot (%).
    pub overmask_pct_mean: Option<f64>,
    /// Frames scored.
    pub frames_scored: usize,
    /// Of them, frames with the robot in view.
    pub frames_with_robot: usize,
}

/// The erased frame against the room without the robot, in the robot's region (dB).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DrReport {
    /// Mean PSNR.
    pub psnr_robot_db_mean: Option<f64>,
    /// Smallest PSNR of a frame.
    pub psnr_robot_db_min: Option<f64>,
}

/// The GPU passes against the CPU reference on the same inputs (`None`: no frame compared).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GpuVsCpu {
    /// Largest difference of the composites (8-bit levels).
    pub max_abs_diff: Option<u8>,
    /// Most pixels where the masks differ in one frame.
    pub mask_mismatch_px_max: Option<u64>,
}

/// `timing_ms`: the erase's stages per camera frame (ms), on the GPU where it has timestamp
/// queries, else the CPU reference; see `note`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageTimings {
    /// The mask twin's render and the dilation passes.
    pub mask: Times,
    /// Feathering and the composite.
    pub composite: Times,
    /// All of the erase's passes.
    pub erase: Times,
    /// The GPU copies of the live frame and H.
    pub upload: Times,
    /// The CPU copies into their staging buffers.
    pub upload_cpu: Times,
    /// Wall time per app update.
    pub frame: Times,
    /// `gpu`, or `cpu reference: ` and why.
    pub source: String,
    /// Each erase pass.
    pub gpu_passes: BTreeMap<String, TimedRenders>,
    /// Every other timed render.
    pub gpu_views: BTreeMap<String, TimedRenders>,
    /// `avatarm_core::dr` on the same frames.
    pub cpu_reference: CpuReference,
    /// How to read it.
    pub note: String,
}

/// One timed render's times.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimedRenders {
    /// Its GPU time (ms).
    pub ms: Times,
    /// Renders timed.
    pub renders_timed: usize,
}

/// The CPU reference's times (ms).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CpuReference {
    /// Threshold and dilation.
    pub mask: Times,
    /// Feathering and composite.
    pub composite: Times,
}

/// The files a replay writes (their name patterns).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayOutputs {
    /// The frames as the app received them.
    pub frames: String,
    /// The erased frames.
    pub erased: String,
    /// The masks.
    pub mask: String,
    /// The room without the robot.
    pub ground_truth_no_robot: String,
    /// The robot's true silhouette.
    pub ground_truth_silhouette: String,
    /// The saved frames with their times, joints and scores.
    pub frame_list: String,
    /// The frames as a recorded video source.
    pub timestamps: String,
    /// H at the end.
    pub background: String,
}

impl Default for ReplayOutputs {
    fn default() -> Self {
        Self {
            frames: "frame_NNNNN.png".into(),
            erased: "erased_NNNNN.png".into(),
            mask: "mask_NNNNN.png".into(),
            ground_truth_no_robot: "gt_norobot_NNNNN.png".into(),
            ground_truth_silhouette: "gt_silhouette_NNNNN.png".into(),
            frame_list: "frames.json".into(),
            timestamps: "timestamps.csv".into(),
            background: "background.png".into(),
        }
    }
}

/// A camera on a head: its motion and tracking, and how far each frame's mask camera was from
/// the true camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeadReport {
    /// The head's fastest turn (deg/s).
    pub peak_speed_deg_s: f64,
    /// Its turn rate at the frames (deg/s).
    pub speed_deg_s_at_frames: Times,
    /// The head tracker's model.
    pub tracking: HeadTrackingReport,
    /// Whether the mask camera took the head's pose at the frame's capture.
    pub pose_compensation: bool,
    /// The mask camera's rotation error (deg).
    pub mask_camera_error_deg: Times,
    /// Its translation error (mm).
    pub mask_camera_error_mm: Times,
    /// The newest tracked pose's age at each frame (ms).
    pub newest_tracked_pose_age_ms: Times,
    /// Frames measured.
    pub frames: usize,
    /// The view-following background, where the scene has one.
    pub view_background: Option<ViewBackgroundReport>,
    /// PSNR in the robot's region by the frame camera's angle from the photograph's.
    pub psnr_by_angle_from_photo: Vec<AngleBin>,
}

/// The head tracker's model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeadTrackingReport {
    /// Poses per second.
    pub rate_hz: f64,
    /// Capture to arrival (s).
    pub latency_s: f64,
    /// Position noise (mm).
    pub position_sigma_mm: f64,
    /// Angle noise (deg).
    pub angle_sigma_deg: f64,
}

/// The view-following background's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewBackgroundReport {
    /// Views kept.
    pub views_kept: usize,
    /// Views offered.
    pub views_offered: u64,
    /// Blank frames refused as views.
    pub blank_frames_refused: u64,
    /// When the kept views were taken (s).
    pub view_times_s: Vec<f64>,
    /// Mean share of the robot's region some view saw.
    pub seen_share_of_robot_region: Option<f64>,
    /// The angle to the nearest view captured before each frame (deg).
    pub nearest_view_deg: Times,
    /// Its CPU time per frame (ms).
    pub cpu_ms: Times,
    /// PSNR in the robot's region by that angle.
    pub psnr_by_nearest_view: Vec<AngleBin>,
}

/// Frames whose angle lies in `angle_deg` (deg, from inclusive, to exclusive), and their PSNR.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AngleBin {
    /// The bin's bounds (deg).
    pub angle_deg: [f64; 2],
    /// Frames in it.
    pub frames: usize,
    /// Their mean PSNR in the robot's region (dB).
    pub psnr_robot_db_mean: Option<f64>,
}

/// The mean of `values`, `None` when there is none.
pub(crate) fn mean(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// `timing_ms`: the erase's mask (the mask twin's render and the dilation passes) and
/// composite (feathering and the composite, which thresholds too when nothing dilates) per
/// camera frame, timed on the GPU when the device has timestamp queries, else the CPU
/// reference; each pass, the uploads and every other timed view (the room's cameras, the
/// ground truth, the interaction camera) beside them.
pub(super) fn stage_timings(replay: &Replay, gpu: &SpanTimes) -> StageTimings {
    let cpu_mask: Vec<f64> = replay.scores.iter().map(|f| f.cpu_mask_ms).collect();
    let cpu_comp: Vec<f64> = replay.scores.iter().map(|f| f.cpu_composite_ms).collect();
    let since = |name: &str| {
        gpu.since(
            name,
            replay.gpu_measured_at_start.get(name).copied().unwrap_or(0),
        )
    };
    let passes: Vec<(&str, Vec<f64>)> = PASS_NAMES
        .iter()
        .map(|&name| (name, since(name)))
        .filter(|(_, ms)| !ms.is_empty())
        .collect();
    // The n-th render of each pass works on the same camera frame (a frame's spans arrive
    // together or not at all).
    let per_frame = |names: &[&str]| -> Vec<f64> {
        let chosen: Vec<&Vec<f64>> = passes
            .iter()
            .filter(|(n, _)| names.contains(n))
            .map(|(_, ms)| ms)
            .collect();
        let n = chosen.iter().map(|v| v.len()).min().unwrap_or(0);
        (0..n).map(|i| chosen.iter().map(|v| v[i]).sum()).collect()
    };
    let gpu_mask = per_frame(&PASS_NAMES[..3]);
    let gpu_comp = per_frame(&PASS_NAMES[3..]);
    let gpu_erase = per_frame(&PASS_NAMES);
    let on_gpu = !gpu_mask.is_empty() && !gpu_comp.is_empty();
    let source = match (&gpu.unavailable, on_gpu) {
        (_, true) => "gpu".to_string(),
        (Some(why), false) => format!("cpu reference: {why}"),
        (None, false) => "cpu reference: no GPU pass time arrived".to_string(),
    };
    let entry = |ms: &[f64]| TimedRenders {
        ms: Spread::some_of(ms),
        renders_timed: ms.len(),
    };
    let gpu_passes = passes
        .iter()
        .map(|(name, ms)| (name.to_string(), entry(ms)))
        .collect();
    let gpu_views = gpu
        .spans
        .keys()
        .filter(|k| !PASS_NAMES.contains(&k.as_str()) && *k != UPLOAD_SPAN && *k != UPLOAD_CPU_SPAN)
        .map(|name| (name.clone(), entry(&since(name))))
        .collect();
    StageTimings {
        mask: Spread::some_of(if on_gpu { &gpu_mask } else { &cpu_mask }),
        composite: Spread::some_of(if on_gpu { &gpu_comp } else { &cpu_comp }),
        erase: Spread::some_of(&gpu_erase),
        upload: Spread::some_of(&since(UPLOAD_SPAN)),
        upload_cpu: Spread::some_of(&since(UPLOAD_CPU_SPAN)),
        frame: Spread::some_of(&replay.frame_ms),
        source,
        gpu_passes,
        gpu_views,
        cpu_reference: CpuReference {
            mask: Spread::some_of(&cpu_mask),
            composite: Spread::some_of(&cpu_comp),
        },
        note: "mask: the mask twin's flat render plus the dilation passes; composite: the feathering and composite passes (the composite thresholds too when nothing dilates); erase: all of them; each the GPU time between timestamps written around the pass (source \"gpu\"), or the CPU reference of the same steps when the device has no timestamp queries; upload: the GPU copies of the live frame and H from their staging buffers, upload_cpu: the CPU copies into them; gpu_views: every other timed render (cameras and flat views) in this replay; cpu_reference: avatarm_core::dr on the same frame; frame: wall time per app update, all cameras included".into(),
    }
}

/// The report's account of the camera's lens: its model and coefficients, whether the mask
/// honoured it and the size of the mask's pinhole render.
pub(crate) fn lens_report(lens: &Distortion, map: Option<&DistortionMap>) -> LensReport {
    LensReport {
        model: lens.ros_name().to_owned(),
        coefficients: lens.coefficients().to_vec(),
        honoured: map.is_some(),
        mask_render: map.map(|m| [m.pinhole.width, m.pinhole.height]),
        // Pixels never masked: past a barrel's fold, or beyond the render's 3x cap.
        pixels_unmapped: map.map(|m| m.unmapped),
        pixels_outside_render: map.map(|m| m.outside),
    }
}

/// The `head` section of a replay's report (null for a fixed camera): the head's motion and
/// tracking, and how far each frame's mask camera was from the true camera.
pub(super) fn head_report(
    s: &avatarm_scene::Scene,
    errors: &[HeadFrameError],
    scores: &[FrameScore],
    erase: &EraseState,
) -> Option<HeadReport> {
    let head = s.head.as_ref()?;
    // The background's PSNR in the robot's region against how far the frame's camera was from
    // the nearest view captured before it.
    let psnr_at: std::collections::HashMap<i64, f64> = scores
        .iter()
        .filter_map(|f| f.psnr_robot_db.map(|p| (frame_key(f.t_s), p)))
        .collect();
    let by_angle = |angle: &dyn Fn(&HeadFrameError) -> Option<f64>| -> Vec<AngleBin> {
        let bins = [
            (0.0, 1.0),
            (1.0, 2.0),
            (2.0, 4.0),
            (4.0, 8.0),
            (8.0, 16.0),
            (16.0, 180.0),
        ];
        bins.iter()
            .filter_map(|&(lo, hi)| {
                let psnrs: Vec<f64> = errors
                    .iter()
                    .filter(|e| angle(e).is_some_and(|a| a >= lo && a < hi))
                    .filter_map(|e| psnr_at.get(&frame_key(e.t_s)).copied())
                    .collect();
                (!psnrs.is_empty()).then(|| AngleBin {
                    angle_deg: [lo, hi],
                    frames: psnrs.len(),
                    psnr_robot_db_mean: mean(&psnrs),
                })
            })
            .collect()
    };
    let seen: Vec<f64> = errors.iter().filter_map(|e| e.seen_share).collect();
    let nearest: Vec<f64> = errors.iter().filter_map(|e| e.nearest_view_deg).collect();
    let cpu: Vec<f64> = errors.iter().filter_map(|e| e.view_background_ms).collect();
    let view_background = erase
        .view_background
        .as_ref()
        .map(|vb| ViewBackgroundReport {
            views_kept: vb.views.len(),
            views_offered: vb.views.offered(),
            blank_frames_refused: vb.views.blank(),
            view_times_s: vb.views.times(),
            seen_share_of_robot_region: mean(&seen),
            nearest_view_deg: Spread::some_of(&nearest),
            cpu_ms: Spread::some_of(&cpu),
            psnr_by_nearest_view: by_angle(&|e| e.nearest_view_deg),
        });
    let angles: Vec<f64> = errors.iter().map(|e| e.angle_deg).collect();
    let offsets: Vec<f64> = errors.iter().map(|e| e.offset_mm).collect();
    let ages: Vec<f64> = errors.iter().filter_map(|e| e.tracking_age_ms).collect();
    let speeds: Vec<f64> = errors.iter().map(|e| e.speed_deg_s).collect();
    let t = &head.tracking;
    Some(HeadReport {
        peak_speed_deg_s: head
            .motion
            .peak_angular_speed(s.file.duration_s)
            .to_degrees(),
        speed_deg_s_at_frames: Spread::some_of(&speeds),
        tracking: HeadTrackingReport {
            rate_hz: t.rate_hz,
            latency_s: t.latency_s,
            position_sigma_mm: t.position_sigma_m * 1e3,
            angle_sigma_deg: t.angle_sigma_rad.to_degrees(),
        },
        pose_compensation: s.file.erase.pose_compensation,
        mask_camera_error_deg: Spread::some_of(&angles),
        mask_camera_error_mm: Spread::some_of(&offsets),
        newest_tracked_pose_age_ms: Spread::some_of(&ages),
        frames: errors.len(),
        view_background,
        psnr_by_angle_from_photo: by_angle(&|e| Some(e.photo_angle_deg)),
    })
}
