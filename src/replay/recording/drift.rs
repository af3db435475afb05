//! `replay --recording`'s drift watch: a fixed camera that moved during the recording, found
//! from the frames and fitted again ([`avatarm_footage::drift`]), before the erase's passes.

use avatarm_record::HeadPose;
use nalgebra::DVector;

use super::{Input, RecordingOptions};
use crate::AppError;

/// Watches the recording's fixed camera (with `o.drift`); the report goes to `input.drift`
/// (and a line to its notes). Returns the pose at each frame, as a track of "head" poses with
/// no mount, where a move was found; `None` where the pose held, the watch is off or the
/// camera rides on a head (said in the notes).
pub(super) fn watch(
    o: &RecordingOptions,
    input: &mut Input,
) -> Result<Option<Vec<HeadPose>>, AppError> {
    let Some(settings) = o.drift else {
        return Ok(None);
    };
    if input.head_mount.is_some() {
        input.notes.push(
            "the drift watch watches a fixed camera: a camera on a head moves by design".into(),
        );
        return Ok(None);
    }
    let name = o.recording.display().to_string();
    let bar = crate::progress::bar(input.frames.len() as u64, "drift watch", o.progress);
    let q: &[DVector<f64>] = &input.q;
    let (report, poses) = avatarm_footage::drift::watch_recording(
        (&input.frames, q),
        &input.model,
        (input.camera.intrinsics, input.lens),
        input.camera.world_from_camera,
        o.settings.dilate_px,
        settings,
        (&name, |done, _| bar.set_position(done as u64)),
    )?;
    bar.finish_and_clear();
    input.notes.push(format!("drift watch: {}", report.note));
    let moved = !report.refits.is_empty();
    if moved && o.background.is_none() {
        let starts: Vec<String> = report
            .refits
            .iter()
            .map(|r| r.first_beyond_frame.to_string())
            .collect();
        input.notes.push(format!(
            "the background H from the footage is built for each stretch the camera stood still (new stretches from frames {}); the report's background figures are the first stretch's",
            starts.join(", ")
        ));
    }
    input.drift = Some(report);
    Ok(moved.then(|| {
        input
            .frames
            .iter()
            .zip(poses)
            .map(|(f, base_from_camera)| HeadPose {
                stamp_ns: f.stamp_ns,
                base_from_head: base_from_camera,
            })
            .collect()
    }))
}
