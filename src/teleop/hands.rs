//! The live task's hand sources: scripted, desktop, OpenXR's tracked hands, a Leap device or
//! recording, a file.

use super::*;

/// The hand source `choice` names for a trial (`script`: its scripted hand, whose first wrist
/// pose is where the other sources start), polled at `rate_hz` when scripted; the desktop hand also gives its key-driven state. `None`
/// for OpenXR hand tracking, which comes from an app's XR view ([`xr_inbox`]). Errors when a
/// recording cannot be read, a device cannot start or a feature is left out of this build.
pub(crate) fn hand_source(
    scene: &Scene,
    choice: &HandChoice,
    script: &avatarm_core::teleop::hand::HandScript,
    rate_hz: f64,
) -> Result<(Option<ActiveHand>, Option<DesktopHand>), AppError> {
    let start = script.wrist_at(0.0).0;
    Ok(match choice {
        HandChoice::Scripted => (
            Some(ActiveHand::new(ScriptedHand::new(script.clone(), rate_hz))),
            None,
        ),
        HandChoice::Desktop => {
            let desktop = DesktopHand::new(start);
            (Some(ActiveHand::new(desktop.inbox.clone())), Some(desktop))
        }
        HandChoice::Xr => (None, None),
        HandChoice::Leap => (Some(leap_hand(&start, &scene.file.leap)?), None),
        HandChoice::File(path) => (
            Some(ActiveHand::new(avatarm_hand::RecordedHand::open(path)?)),
            None,
        ),
        HandChoice::LeapRecording { path, hand } => (
            Some(leap_recording(path, *hand, &start, &scene.file.leap)?),
            None,
        ),
    })
}

/// OpenXR hand tracking's frames (the app's XR view pushes them), its tracking space placed so
/// that a hand held at rest lands on the trial's `start`. Errors without the XR view.
#[cfg(feature = "xr")]
pub(crate) fn xr_inbox(app: &mut App, start: &Isometry3<f64>) -> Result<HandInbox, AppError> {
    let mut xr = app
        .world_mut()
        .get_resource_mut::<crate::preview::xr::XrHand>()
        .ok_or_else(|| AppError::flag("--hand xr", "needs XR mode (--xr or xr = true)"))?;
    // A hand held 35 cm ahead at 1 m above the tracking origin (seated, stage space) lands
    // on the trial's start pose.
    let rest = Vector3::new(0.0, 1.0, -0.35);
    let r = xr.mount.scene_from_xr.rotation;
    xr.mount.scene_from_xr = Isometry3::from_parts(
        nalgebra::Translation3::from(start.translation.vector - r * rest),
        r,
    );
    Ok(xr.inbox.clone())
}

/// Errors: this build has no XR view.
#[cfg(not(feature = "xr"))]
pub(crate) fn xr_inbox(_: &mut App, _: &Isometry3<f64>) -> Result<HandInbox, AppError> {
    Err(AppError::flag(
        "--hand xr",
        "this avatarm was built without the xr feature",
    ))
}

/// The scene rotation of a Leap mounted as `kind` (`[leap] mount`); `None` for `first_wrist`.
pub(super) fn leap_rotation(kind: LeapMountKind) -> Option<nalgebra::UnitQuaternion<f64>> {
    use avatarm_hand::leap::LeapMount;
    match kind {
        LeapMountKind::Desk => Some(LeapMount::desk()),
        LeapMountKind::Head => Some(LeapMount::head()),
        LeapMountKind::FirstWrist => None,
    }
}

/// Where a Leap device sits for `spec` (`[leap]`): at `device_at`, else placed so that
/// `rest_mm` (Leap frame) lands on `start`.
pub(super) fn leap_mount(
    spec: &LeapSpec,
    rotation: nalgebra::UnitQuaternion<f64>,
    rest_mm: Vector3<f64>,
    start: &Isometry3<f64>,
) -> avatarm_hand::leap::LeapMount {
    use avatarm_hand::leap::LeapMount;
    match spec.device_at {
        Some(at) => LeapMount::placed(rotation, Vector3::from(at)),
        None => LeapMount::anchored(rotation, rest_mm, start.translation.vector),
    }
}

#[cfg(feature = "leap")]
pub(super) fn leap_hand(start: &Isometry3<f64>, spec: &LeapSpec) -> Result<ActiveHand, AppError> {
    use avatarm_hand::leap::{LeapHand, LeapOptions};
    let rotation = leap_rotation(spec.mount).ok_or_else(|| {
        AppError::flag(
            "leap.mount",
            "first_wrist places a recording; a live Leap is mounted on the desk or the head",
        )
    })?;
    // A hand at rest: 20 cm above a desk device, 35 cm ahead of and 20 cm below a head-mounted
    // one (Leap's +y out of the device's face, +z up on the head).
    let rest = match spec.mount {
        LeapMountKind::Head => Vector3::new(0.0, 350.0, -200.0),
        _ => Vector3::new(0.0, 200.0, 0.0),
    };
    let hand = LeapHand::start(LeapOptions {
        mount: leap_mount(spec, rotation, rest, start),
        ..LeapOptions::default()
    })?;
    Ok(ActiveHand::new(hand))
}

/// A Leap recording's `hand` (default: the first one it shows) from a device mounted as `spec`
/// says: its first wrist at the task's start position (`desk`, `head`) or pose (`first_wrist`),
/// or the device at `device_at`.
pub(super) fn leap_recording(
    path: &std::path::Path,
    hand: Option<avatarm_core::teleop::hand::Handedness>,
    start: &Isometry3<f64>,
    spec: &LeapSpec,
) -> Result<ActiveHand, AppError> {
    use avatarm_hand::leap::LeapMount;
    use avatarm_hand::leap_recording::LeapRecording;
    let recording = LeapRecording::open(path)?;
    let first = recording
        .frames
        .iter()
        .find_map(|f| {
            f.hands
                .iter()
                .find(|(_, h)| hand.is_none_or(|side| h.hand == side))
        })
        .map(|(_, h)| h.clone())
        .ok_or_else(|| {
            AppError::flag(
                "--hand",
                format!("{}: no such hand in the recording", path.display()),
            )
        })?;
    let mount = match leap_rotation(spec.mount) {
        None => LeapMount::with_wrist_pose(&first, start)?,
        Some(rotation) => {
            let wrist = first.arm.next.map(f64::from);
            leap_mount(spec, rotation, Vector3::from(wrist), start)
        }
    };
    let frames = recording.hand_frames(Some(first.hand), &mount)?;
    Ok(ActiveHand::new(avatarm_hand::RecordedHand::from_frames(
        format!(
            "Leap recording {} ({} mount)",
            path.display(),
            spec.mount.name()
        ),
        frames,
    )?))
}

#[cfg(not(feature = "leap"))]
pub(super) fn leap_hand(_: &Isometry3<f64>, _: &LeapSpec) -> Result<ActiveHand, AppError> {
    Err(AppError::flag(
        "--hand leap",
        "this avatarm was built without the leap feature; rebuild with `cargo build --features \
         leap` (needs the Ultraleap SDK, docs/hardware.md)",
    ))
}
