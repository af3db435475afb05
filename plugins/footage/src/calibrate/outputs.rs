//! What the fit leaves: every frame's IoUs and overlays before and after, the pairing check,
//! the pose (or mount) and camera files, and the report.

use std::path::PathBuf;

use avatarm_core::dr;
use avatarm_core::vision::calibrate::{CalibrationOptions, CalibrationResult, rasterize};
use nalgebra::{Isometry3, UnitQuaternion};

use super::frames::{Used, UsedFrame};
use super::{
    CalibrateOptions, CalibrateOutputs, CalibrateReport, FitCost, FittedIntrinsics, FittedPose,
    FrameIou, Inputs, IouReport, LensUsed, MAX_PAIRING_FRAMES, Pairing, PoseChange,
    SilhouetteSource, StageTime, StartReport, Uncertainty,
};
use crate::FootageError;
use crate::overlay::overlay;
use crate::recording::decode;

/// Every used frame's IoUs, and the silhouettes at the fitted pose (for the pairing check).
pub(super) struct Scored {
    /// In the used frames' order.
    pub per_frame: Vec<FrameIou>,
    /// The model's silhouette at each used frame's joints at the fitted pose (0/1).
    pub drawn: Vec<Vec<u8>>,
}

/// Every used frame before and after, at full resolution: its IoUs against the mask it is
/// scored against, and `overlay_before_NNNNN.png` / `overlay_after_NNNNN.png`.
pub(super) fn score(
    o: &CalibrateOptions,
    inputs: &Inputs,
    frames: &[UsedFrame],
    result: &CalibrationResult,
    in_fit: impl Fn(usize) -> bool,
) -> Result<Scored, FootageError> {
    let (w, h) = inputs.size;
    let mut scored = Scored {
        per_frame: Vec::with_capacity(frames.len()),
        drawn: Vec::with_capacity(frames.len()),
    };
    for f in frames {
        let triangles = &f.silhouette.triangles;
        let before = rasterize(triangles, &inputs.rough, &inputs.k, &inputs.lens);
        let after = rasterize(
            triangles,
            &result.camera_from_base,
            &result.intrinsics,
            &inputs.lens,
        );
        let iou = |m: &[u8]| {
            f.scored
                .as_deref()
                .and_then(|r| dr::mask_scores(m, r))
                .map(|s| s.iou)
        };
        let image = decode(&inputs.recording.frames[f.index], &inputs.name)?.into_raw();
        // With --edges: what the fit drew the outline to, for tuning --edge-thresholds.
        let edges = o
            .edges
            .is_some()
            .then_some(f.silhouette.observed.as_slice());
        for (tag, m) in [("before", &before), ("after", &after)] {
            let picture = overlay(&image, m, edges, f.scored.as_deref(), w);
            let picture = image::RgbaImage::from_raw(w, h, picture)
                .ok_or_else(|| FootageError::input("overlay", format!("not a {w}x{h} image")))?;
            let path = o.out.join(format!("overlay_{tag}_{:05}.png", f.index));
            picture
                .save(&path)
                .map_err(|source| FootageError::write_image(path, source))?;
        }
        scored.per_frame.push(FrameIou {
            frame: f.index,
            fit: in_fit(f.index),
            iou_before: iou(&before),
            iou_after: iou(&after),
        });
        scored.drawn.push(after);
    }
    Ok(scored)
}

/// Pairing: each frame's reference against the silhouette at every frame's joints, at the
/// fitted pose. A frame whose mask another frame's joints explain clearly better (by more than
/// 0.1 IoU) than its own was recorded with the wrong joints (or a wrong stamp): no pose can fit
/// it. Returns the rows and the mispaired frames (said in `notes`); skipped (said in `notes`)
/// without every frame's reference mask or with more than [`MAX_PAIRING_FRAMES`] frames.
pub(super) fn pairing(
    frames: &[UsedFrame],
    drawn: &[Vec<u8>],
    notes: &mut Vec<String>,
) -> (Vec<Pairing>, Vec<usize>) {
    let (mut rows, mut mispaired) = (Vec::new(), Vec::new());
    if frames.iter().any(|f| f.scored.is_none()) {
        notes.push(
            "the pairing check was skipped: it needs every frame's reference mask (fitted to edges)"
                .into(),
        );
        return (rows, mispaired);
    }
    if frames.len() > MAX_PAIRING_FRAMES {
        notes.push(format!(
            "the pairing check was skipped: {} frames (at most {MAX_PAIRING_FRAMES}; thin them with --every)",
            frames.len()
        ));
        return (rows, mispaired);
    }
    for (a, f) in frames.iter().enumerate() {
        let scores: Vec<f64> = drawn
            .iter()
            .map(|m| {
                f.scored
                    .as_deref()
                    .and_then(|r| dr::mask_scores(m, r))
                    .map_or(0.0, |s| s.iou)
            })
            .collect();
        let (best, best_iou) =
            scores.iter().enumerate().fold(
                (a, scores[a]),
                |b, (j, &v)| if v > b.1 { (j, v) } else { b },
            );
        let own = scores[a];
        if best != a && best_iou > own + 0.1 {
            mispaired.push(f.index);
        }
        rows.push(Pairing {
            frame: f.index,
            own_joints_iou: own,
            best_joints_frame: frames[best].index,
            best_joints_iou: best_iou,
        });
    }
    if !mispaired.is_empty() {
        notes.push(format!(
            "frames {mispaired:?}: another frame's joints fit the reference mask better than their own by more than 0.1 IoU (see pairing): the frames and joint states look mispaired, which bounds the IoU any pose reaches"
        ));
    }
    (rows, mispaired)
}

/// The change from the rough pose to the answer.
fn change(inputs: &Inputs, result: &CalibrationResult) -> Isometry3<f64> {
    result.camera_from_base * inputs.rough.inverse()
}

/// The starts reach `start_deg` and `start_m` from the rough pose: an answer far beyond them is
/// more likely a wrong basin (with `--edges`, the outline laid on other edges) than the camera:
/// said in the notes.
pub(super) fn note_far_move(
    o: &CalibrateOptions,
    inputs: &Inputs,
    result: &CalibrationResult,
    options: &CalibrationOptions,
    notes: &mut Vec<String>,
) {
    let change = change(inputs, result);
    let (moved_deg, moved_m) = (
        change.rotation.angle().to_degrees(),
        change.translation.vector.norm(),
    );
    if moved_deg > 2.0 * options.start_deg || moved_m > 3.0 * options.start_m {
        let what = if inputs.on_head { "mount" } else { "pose" };
        notes.push(format!(
            "the fit moved {moved_deg:.1} deg and {:.0} mm from the rough {what}, far beyond its starts ({} deg, {} mm): check the overlays; a closer rough {what}{} may be needed",
            1e3 * moved_m,
            options.start_deg,
            1e3 * options.start_m,
            if o.edges.is_some() {
                ", or silhouettes instead of --edges,"
            } else {
                ""
            }
        ));
    }
}

/// Writes `camera_pose.yaml` (`base_from_camera`) or, for a camera on a head,
/// `camera_mount.yaml` (`head_from_camera`): the answer as a 4x4 matrix; with `--intrinsics`
/// also `camera_info.yaml` (ROS's layout, the fitted fx and fy).
pub(super) fn write_files(
    o: &CalibrateOptions,
    inputs: &Inputs,
    result: &CalibrationResult,
    frames_fit: usize,
    margin: Option<&super::margin::EraseMargin>,
) -> Result<CalibrateOutputs, FootageError> {
    let (pose_file, key, frame_name) = if inputs.on_head {
        (
            "camera_mount.yaml",
            "head_from_camera",
            "the head's optical frame (x right, y down, z forward)",
        )
    } else {
        (
            "camera_pose.yaml",
            "base_from_camera",
            "the robot's base frame",
        )
    };
    let pose_path = o.out.join(pose_file);
    let m = result.camera_from_base.inverse().to_homogeneous();
    let rows: String = (0..4)
        .map(|r| {
            format!(
                "  - [{:.9}, {:.9}, {:.9}, {:.9}]\n",
                m[(r, 0)],
                m[(r, 1)],
                m[(r, 2)],
                m[(r, 3)]
            )
        })
        .collect();
    let mut text = format!(
        "# The camera's pose in {frame_name} (OpenCV optical axes: x right, y down,\n# z forward), fitted by `avatarm calibrate` to {frames_fit} frames of {}.\n{key}:\n{rows}",
        inputs.name
    );
    if let Some(m) = margin.filter(|m| !m.capped) {
        text += &format!(
            "# The erase margin this fit calls for (px; `replay --recording` dilates the mask by\n# it unless --dilate says otherwise): the model's outline within {:.1} px of the\n# frames' (95th percentile), the fit's spread {:.1} px, 1 px for the edge itself.\nerase_margin_px: {}\n",
            m.outline_p95_px, m.spread_px, m.dilate_px
        );
    }
    std::fs::write(&pose_path, text).map_err(|e| FootageError::write(&pose_path, e))?;
    let camera = if o.fit_focal {
        Some(write_intrinsics(o, inputs, result)?)
    } else {
        None
    };
    Ok(CalibrateOutputs {
        pose: pose_path.display().to_string(),
        camera: camera.map(|p| p.display().to_string()),
    })
}

/// `camera_info.yaml`: K with the fitted fx and fy, the principal point and distortion as
/// recorded.
fn write_intrinsics(
    o: &CalibrateOptions,
    inputs: &Inputs,
    result: &CalibrationResult,
) -> Result<PathBuf, FootageError> {
    let path = o.out.join("camera_info.yaml");
    let (ki, calibration) = (&result.intrinsics, &inputs.calibration);
    let text = format!(
        "# K fitted by `avatarm calibrate` (fx, fy; the principal point and distortion as recorded).\nimage_width: {}\nimage_height: {}\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [{}, 0, {}, 0, {}, {}, 0, 0, 1]\ndistortion_model: {}\ndistortion_coefficients:\n  rows: 1\n  cols: {}\n  data: [{}]\n",
        ki.width,
        ki.height,
        ki.fx,
        ki.cx,
        ki.fy,
        ki.cy,
        calibration.distortion_model.ros_name(),
        calibration.d.len(),
        calibration
            .d
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    std::fs::write(&path, text).map_err(|e| FootageError::write(&path, e))?;
    Ok(path)
}

/// What the report is made of.
pub(super) struct Parts<'a> {
    pub o: &'a CalibrateOptions,
    pub inputs: &'a Inputs,
    pub used: &'a Used,
    pub result: &'a CalibrationResult,
    pub per_frame: Vec<FrameIou>,
    pub pairing: (Vec<Pairing>, Vec<usize>),
    pub frames_fit: usize,
    pub dropped_from_fit: Vec<usize>,
    pub outputs: CalibrateOutputs,
    pub margin: Option<super::margin::EraseMargin>,
    pub notes: Vec<String>,
    pub wall_time_s: f64,
}

/// The report of a finished fit.
pub(super) fn report(p: &Parts) -> CalibrateReport {
    let (o, inputs, result) = (p.o, p.inputs, p.result);
    let mean = |fit: bool, iou: fn(&FrameIou) -> Option<f64>| -> Option<f64> {
        let v: Vec<f64> = p
            .per_frame
            .iter()
            .filter(|f| f.fit == fit)
            .filter_map(iou)
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    // For a camera on a head, "base" is the head: the pose is the mount.
    let pose = fitted_pose(&result.camera_from_base.inverse());
    let change = change(inputs, result);
    let calibration = &inputs.calibration;
    CalibrateReport {
        recording: inputs.name.clone(),
        robot: inputs.model.name.clone(),
        triangles: inputs.silhouette.triangle_count(),
        hidden_below_m: o.hidden_below,
        distortion: LensUsed {
            model: calibration.distortion_model.ros_name().to_owned(),
            coefficients: calibration.d.clone(),
            applied: !inputs.lens.is_none(),
        },
        frames_used: p.used.frames.len(),
        silhouettes: silhouette_source(o, &p.used.difference_vs_reference),
        frames_fit: p.frames_fit,
        dropped_from_fit: p.dropped_from_fit.clone(),
        iou: IouReport {
            fit_before: mean(true, |f| f.iou_before),
            fit_after: mean(true, |f| f.iou_after),
            held_out_before: mean(false, |f| f.iou_before),
            held_out_after: mean(false, |f| f.iou_after),
            per_frame: p.per_frame.clone(),
        },
        camera: if inputs.on_head {
            "on a head: the fit is the mount (head_from_camera)"
        } else {
            "fixed"
        }
        .to_owned(),
        head_poses: inputs.recording.head_poses.len(),
        base_from_camera: (!inputs.on_head).then_some(pose),
        head_from_camera: inputs.on_head.then_some(pose),
        change_from_rough: PoseChange {
            rotation_deg: change.rotation.angle().to_degrees(),
            translation_mm: 1e3 * change.translation.vector.norm(),
        },
        intrinsics: FittedIntrinsics {
            fx: result.intrinsics.fx,
            fy: result.intrinsics.fy,
            cx: result.intrinsics.cx,
            cy: result.intrinsics.cy,
            fitted: o.fit_focal,
        },
        cost_px: FitCost {
            rough: result.rough_cost_px,
            fitted: result.cost_px,
        },
        uncertainty: uncertainty(result),
        pairing: p.pairing.0.clone(),
        mispaired_frames: p.pairing.1.clone(),
        evaluations: result.evaluations,
        stages: ["coarse", "fine", "full"]
            .iter()
            .enumerate()
            .map(|(i, stage)| StageTime {
                stage: (*stage).to_owned(),
                seconds: result.stage_seconds[i],
                evaluations: result.stage_evaluations[i],
            })
            .collect(),
        wall_time_s: p.wall_time_s,
        notes: p.notes.clone(),
        outputs: p.outputs.clone(),
        margin: p.margin.clone(),
    }
}

/// `parent_from_camera` as the report gives it.
fn fitted_pose(pose: &Isometry3<f64>) -> FittedPose {
    let q: UnitQuaternion<f64> = pose.rotation;
    let t = pose.translation.vector;
    let rpy = q.euler_angles();
    FittedPose {
        translation: [t.x, t.y, t.z],
        quaternion_xyzw: [q.i, q.j, q.k, q.w],
        rpy: [rpy.0, rpy.1, rpy.2],
    }
}

/// What the outline was drawn to.
fn silhouette_source(o: &CalibrateOptions, difference_vs_reference: &[f64]) -> SilhouetteSource {
    let none = SilhouetteSource {
        source: "reference masks".into(),
        canny_thresholds: None,
        background: None,
        threshold: None,
        iou_vs_reference_mean: None,
    };
    match (&o.background, o.edges) {
        (_, Some((low, high))) => SilhouetteSource {
            source: "image edges (Canny): no silhouette; IoUs against reference masks where the recording has them".into(),
            canny_thresholds: Some([low, high]),
            ..none
        },
        (Some(path), None) => SilhouetteSource {
            source: "background difference".into(),
            background: Some(path.display().to_string()),
            threshold: Some(o.background_threshold),
            iou_vs_reference_mean: (!difference_vs_reference.is_empty()).then(|| {
                difference_vs_reference.iter().sum::<f64>() / difference_vs_reference.len() as f64
            }),
            ..none
        },
        (None, None) => none,
    }
}

/// The starts and their spread.
fn uncertainty(result: &CalibrationResult) -> Uncertainty {
    Uncertainty {
        spread_deg: result.spread_deg_mm.0,
        spread_mm: result.spread_deg_mm.1,
        starts: result
            .starts
            .iter()
            .map(|s| StartReport {
                start_deg: s.start.0,
                start_m: s.start.1,
                cost_px: s.cost_px,
            })
            .collect(),
        note: "cost_px: the mean truncated chamfer distance between the outlines at half resolution (with --edges, from the model's outline to the nearest image edge); spread: the largest difference between the answer and another start that ended within 10 % of its cost".into(),
    }
}
