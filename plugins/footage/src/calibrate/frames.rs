//! The frames the fit and its scores use: each one's robot at its joints (in the head's frame
//! for a camera on a head), what it is fitted to (a silhouette, or the frame's own edges) and
//! the mask it is scored against.

use avatarm_core::dr;
use avatarm_core::vision::calibrate::{SilhouetteFrame, clip_below};
use avatarm_record::{CompressedFrame, HEAD_POSE_SLACK_NS};
use nalgebra::Isometry3;

use super::{CalibrateOptions, Inputs, image_edges};
use crate::FootageError;
use crate::recording::{decode, interpolate};

/// Frames one run decodes, draws and scores at most (fit and held out).
const MAX_USED_FRAMES: usize = 300;

/// A frame used (fit or held out).
pub(super) struct UsedFrame {
    /// Its index in the recording.
    pub index: usize,
    /// The robot's triangles at its joints and what they are fitted to.
    pub silhouette: SilhouetteFrame,
    /// The mask it is scored against (0/1): its reference mask, else (fitting to silhouettes)
    /// the silhouette itself; none when fitting to edges without a reference.
    pub scored: Option<Vec<u8>>,
}

/// The frames used and, with `--background`, how well the differences matched the reference
/// masks.
pub(super) struct Used {
    /// In the recording's order.
    pub frames: Vec<UsedFrame>,
    /// Each difference's IoU against the frame's reference mask, where both exist.
    pub difference_vs_reference: Vec<f64>,
}

/// Every `--every`-th frame with a silhouette (a reference mask, a background difference or
/// edges), with the frames left out said in `notes`. Errors: too many frames, a mask
/// or frame of another size, and no frame left at all (naming what would give one).
pub(super) fn used(
    o: &CalibrateOptions,
    inputs: &Inputs,
    notes: &mut Vec<String>,
) -> Result<Used, FootageError> {
    let every = o.every.max(1);
    let references = &inputs.recording.reference_masks;
    // How many frames there are to decode and draw, before any is.
    let candidates = if inputs.background.is_some() || o.edges.is_some() {
        inputs.recording.frames.len()
    } else {
        references.len()
    };
    let count = candidates.div_ceil(every);
    if count > MAX_USED_FRAMES {
        return Err(FootageError::input(
            "--every",
            format!(
                "{count} frames to use (of {candidates} with a silhouette or edges): at most {MAX_USED_FRAMES}; thin them with --every {}",
                candidates.div_ceil(MAX_USED_FRAMES)
            ),
        ));
    }
    let mut used = Used {
        frames: Vec::new(),
        difference_vs_reference: Vec::new(),
    };
    let mut with_silhouette = 0usize;
    // A camera on a head: frames left out for want of a head pose.
    let mut outside_head = 0usize;
    for (i, f) in inputs.recording.frames.iter().enumerate() {
        let reference = references
            .iter()
            .find(|m| m.stamp_ns.abs_diff(f.stamp_ns) <= 1_000_000);
        if reference.is_none() && inputs.background.is_none() && o.edges.is_none() {
            continue;
        }
        with_silhouette += 1;
        if !(with_silhouette - 1).is_multiple_of(every) {
            continue;
        }
        let reference = match reference {
            Some(m) => Some(reference_mask(m, inputs)?),
            None => None,
        };
        let Some(observed) = observe(o, inputs, (i, f), reference.as_deref(), &mut used, notes)?
        else {
            continue;
        };
        let Some(triangles) = robot_at(o, inputs, (i, f.stamp_ns), &mut outside_head, notes) else {
            continue;
        };
        // Scored (IoUs, pairing) against the reference where there is one, fitted to
        // `observed` (a silhouette; edges score nothing).
        let scored = match reference {
            Some(r) => Some(r),
            None => o.edges.is_none().then(|| observed.clone()),
        };
        used.frames.push(UsedFrame {
            index: i,
            silhouette: SilhouetteFrame {
                triangles,
                observed,
            },
            scored,
        });
    }
    if used.frames.is_empty() {
        return Err(FootageError::input(
            &inputs.name,
            none_used(o, outside_head),
        ));
    }
    Ok(used)
}

/// Why no frame could be used, and what would give one.
fn none_used(o: &CalibrateOptions, outside_head: usize) -> String {
    if outside_head > 0 {
        format!(
            "every frame with a silhouette ({outside_head}) was captured more than {} ms outside the tracked head poses",
            HEAD_POSE_SLACK_NS / 1_000_000
        )
    } else if o.edges.is_some() {
        "no frame has an edge above the thresholds: lower --edge-thresholds".into()
    } else {
        "no frame has a reference mask (the robot's silhouette to fit): import the frames with their masks, give an empty-room photograph with --background (a fixed camera), or fit to the frames' own edges with --edges".into()
    }
}

/// A reference mask decoded to 0/1, refused unless it is the frames' size.
fn reference_mask(m: &CompressedFrame, inputs: &Inputs) -> Result<Vec<u8>, FootageError> {
    let mask = decode(m, &inputs.name)?;
    if mask.dimensions() != inputs.size {
        return Err(FootageError::input(
            &inputs.name,
            format!(
                "the reference mask at {} ns is not {}x{}",
                m.stamp_ns, inputs.size.0, inputs.size.1
            ),
        ));
    }
    Ok(dr::binarise(&mask.into_raw(), 4))
}

/// What frame `i` is fitted to: its Canny edges (`--edges`, each map written to
/// `edges_NNNNN.png`), its difference from `--background`, or its reference mask. `None` (said
/// in the notes) for a frame with no edge, or whose difference is no silhouette.
fn observe(
    o: &CalibrateOptions,
    inputs: &Inputs,
    (i, f): (usize, &CompressedFrame),
    reference: Option<&[u8]>,
    used: &mut Used,
    notes: &mut Vec<String>,
) -> Result<Option<Vec<u8>>, FootageError> {
    let size = inputs.size;
    match (&inputs.background, o.edges) {
        (_, Some((low, high))) => {
            let frame = decode(f, &inputs.name)?;
            if frame.dimensions() != size {
                return Err(FootageError::input(
                    &inputs.name,
                    format!(
                        "the frame at {} ns is {}x{}, the camera {}x{}",
                        f.stamp_ns,
                        frame.width(),
                        frame.height(),
                        size.0,
                        size.1
                    ),
                ));
            }
            let edges = image_edges(&frame, (low, high));
            // Written before the fit, for tuning the thresholds by eye even when the fit is
            // refused or stopped.
            let map = edges.iter().map(|&v| 255 * v).collect();
            if let Some(map) = image::GrayImage::from_raw(size.0, size.1, map) {
                let path = o.out.join(format!("edges_{i:05}.png"));
                map.save(&path)
                    .map_err(|source| FootageError::write_image(path, source))?;
            }
            if !edges.contains(&1) {
                notes.push(format!(
                    "frame {i}: no edge above --edge-thresholds {low},{high}: left out"
                ));
                return Ok(None);
            }
            Ok(Some(edges))
        }
        (Some(bg), None) => {
            let frame = decode(f, &inputs.name)?;
            let frame = dr::RgbaView::new("frame", size.0, size.1, frame.as_raw())?;
            let bg = dr::RgbaView::new("--background", size.0, size.1, bg)?;
            let m = dr::background_difference(&frame, &bg, o.background_threshold, 2)?;
            // An exposure change or someone in view makes the whole frame differ; a robot out
            // of view leaves nothing: neither is a silhouette to fit.
            let coverage = m.iter().filter(|&&v| v > 0).count() as f64 / m.len() as f64;
            if !(0.001..=0.5).contains(&coverage) {
                notes.push(format!(
                    "frame {i}: {:.1} % of it differs from the background: left out (an exposure change, something else in view, or no robot)",
                    100.0 * coverage
                ));
                return Ok(None);
            }
            if let Some(s) = reference.and_then(|r| dr::mask_scores(&m, r)) {
                used.difference_vs_reference.push(s.iou);
            }
            Ok(Some(m))
        }
        (None, None) => Ok(reference.map(<[u8]>::to_vec)),
    }
}

/// The robot's triangles at the frame's joints (interpolated to its capture), cut below
/// `--hidden-below`; for a camera on a head, in the head's frame at the capture. `None` (said
/// in the notes, counted in `outside_head`) for a frame captured outside the tracked head
/// poses.
fn robot_at(
    o: &CalibrateOptions,
    inputs: &Inputs,
    (i, stamp_ns): (usize, u64),
    outside_head: &mut usize,
    notes: &mut Vec<String>,
) -> Option<Vec<[nalgebra::Point3<f64>; 3]>> {
    let q = interpolate(&inputs.states, stamp_ns);
    let mut triangles = inputs
        .silhouette
        .at(&inputs.model, &Isometry3::identity(), q.as_slice());
    if let Some(z) = o.hidden_below {
        triangles = clip_below(&triangles, z);
    }
    if inputs.on_head {
        if !inputs.recording.head_covers(stamp_ns, HEAD_POSE_SLACK_NS) {
            *outside_head += 1;
            notes.push(format!(
                "frame {i}: captured more than {} ms outside the tracked head poses: left out",
                HEAD_POSE_SLACK_NS / 1_000_000
            ));
            return None;
        }
        // The robot as the head saw it at the frame's capture.
        let head_from_base = inputs
            .recording
            .head_at(stamp_ns)
            .unwrap_or_default()
            .inverse();
        for t in &mut triangles {
            for v in t.iter_mut() {
                *v = head_from_base * *v;
            }
        }
    }
    Some(triangles)
}
