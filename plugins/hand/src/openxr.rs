//! OpenXR hand tracking (XR_EXT_hand_tracking) as a hand source.
//!
//! The app's XR mode reads the 26 hand joints that `bevy_mod_xr` locates each frame and pushes
//! them through a [`HandInbox`]; this module converts them ([`xr_frame`]) and is plain Rust,
//! tested without a runtime.
//!
//! OpenXR's tracking space: metres, +y up, −z ahead of where the user faced when the space was
//! set, +x to the right; the same axes as Leap's, so [`XrMount`]'s default turns them the same
//! way into the scene (z up, the user facing +x). OpenXR joint frames point −z along the bone
//! toward the tip with +y out of the back of the hand; Avatarm's point +x along the bone and +z
//! out of the back, a fixed turn of each joint frame. The joints already come in OpenXR's order,
//! which is Avatarm's.

use std::sync::{Arc, Mutex};

use avatarm_core::teleop::hand::{HandFrame, HandJoint, Handedness, JOINT_NAMES};
use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::leap::LeapMount;
use crate::{HandError, HandSource};

/// One located joint, as the runtime gives it (tracking space).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct XrJoint {
    /// Position (m).
    pub position: [f32; 3],
    /// Orientation as a quaternion x, y, z, w.
    pub orientation: [f32; 4],
    /// Radius (m).
    pub radius: f32,
    /// The runtime tracks both the position and the orientation now.
    pub tracked: bool,
}

/// Where OpenXR's tracking space sits in the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct XrMount {
    /// Scene from tracking space (metres).
    pub scene_from_xr: Isometry3<f64>,
}

impl Default for XrMount {
    /// Tracking +y is the scene's +z, tracking −z (ahead) the scene's +x; at the origin.
    fn default() -> Self {
        Self {
            scene_from_xr: LeapMount::default().scene_from_leap,
        }
    }
}

/// Avatarm's joint frame in OpenXR's: +x along the bone is OpenXR's −z, +z out of the back of
/// the hand is OpenXR's +y.
fn joint_turn() -> UnitQuaternion<f64> {
    let m = Matrix3::from_columns(&[
        Vector3::new(0.0, 0.0, -1.0),
        Vector3::new(-1.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
    ]);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// Converts the 26 joints of one hand at app time `t_s` into a frame in the scene. A hand with
/// any joint not tracked is an untracked frame (the watchdog stops the robot on those); a
/// number that is not finite is an error naming the joint.
pub fn xr_frame(
    joints: &[XrJoint],
    hand: Handedness,
    mount: &XrMount,
    t_s: f64,
) -> Result<HandFrame, HandError> {
    let bad = |what: String, message: String| HandError::BadTrackerFrame {
        tracker: "OpenXR hand",
        what,
        message,
    };
    if joints.len() != JOINT_NAMES.len() {
        return Err(bad(
            "joints".into(),
            format!("{} joints, expected {}", joints.len(), JOINT_NAMES.len()),
        ));
    }
    if joints.iter().any(|j| !j.tracked) {
        return Ok(HandFrame {
            t_s,
            hand,
            tracked: false,
            joints: Vec::new(),
        });
    }
    let turn = joint_turn();
    let joints = joints
        .iter()
        .zip(JOINT_NAMES)
        .map(|(j, name)| {
            let numbers = j.position.iter().chain(&j.orientation).chain([&j.radius]);
            if !numbers.into_iter().all(|v| v.is_finite()) {
                return Err(bad(format!("joint {name}"), "not finite".into()));
            }
            let [x, y, z, w] = j.orientation.map(f64::from);
            let q = UnitQuaternion::try_new(Quaternion::new(w, x, y, z), 1e-6)
                .ok_or_else(|| bad(format!("joint {name}"), "zero-length orientation".into()))?;
            let p = Vector3::from(j.position.map(f64::from));
            let in_xr = Isometry3::from_parts(Translation3::from(p), q * turn);
            Ok(HandJoint {
                pose: mount.scene_from_xr * in_xr,
                radius: f64::from(j.radius).max(1e-3),
            })
        })
        .collect::<Result<Vec<_>, HandError>>()?;
    let frame = HandFrame {
        t_s,
        hand,
        tracked: true,
        joints,
    };
    frame.validate()?;
    Ok(frame)
}

/// A hand source fed from elsewhere in the app (the XR hand, the desktop hand): whoever holds
/// a clone pushes frames with [`HandInbox::push`], the active hand polls the newest.
#[derive(Clone, Debug)]
pub struct HandInbox {
    name: String,
    slot: Arc<Mutex<Option<HandFrame>>>,
}

impl HandInbox {
    /// An empty inbox named `name` (for messages).
    pub fn new(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            slot: Arc::default(),
        }
    }

    /// Replaces the waiting frame with `frame`.
    pub fn push(&self, frame: HandFrame) {
        if let Ok(mut slot) = self.slot.lock() {
            *slot = Some(frame);
        }
    }
}

impl HandSource for HandInbox {
    fn name(&self) -> &str {
        &self.name
    }

    fn poll(&mut self, now_s: f64) -> Option<HandFrame> {
        let mut slot = self.slot.lock().ok()?;
        if slot.as_ref().is_some_and(|f| f.t_s <= now_s) {
            slot.take()
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight_hand() -> Vec<XrJoint> {
        // Every joint looking down OpenXR's −z (identity orientation), fingers ahead.
        (0..26)
            .map(|i| XrJoint {
                position: [0.0, 1.0, -0.3 - 0.01 * i as f32],
                orientation: [0.0, 0.0, 0.0, 1.0],
                radius: 0.008,
                tracked: true,
            })
            .collect()
    }

    #[test]
    fn joints_land_in_the_scene_with_avatarm_frames() {
        let frame = xr_frame(
            &straight_hand(),
            Handedness::Right,
            &XrMount::default(),
            1.5,
        )
        .expect("a good hand converts");
        assert!(frame.tracked);
        assert_eq!(frame.joints.len(), 26);
        let palm = &frame.joints[0].pose;
        // Tracking (0, 1, -0.3): 0.3 m ahead and 1 m up.
        assert!((palm.translation.vector - Vector3::new(0.3, 0.0, 1.0)).norm() < 1e-6);
        // The bone points ahead (scene +x), the back of the hand up (scene +z).
        let x = palm.rotation * Vector3::x();
        let z = palm.rotation * Vector3::z();
        assert!((x - Vector3::x()).norm() < 1e-6, "bone axis {x}");
        assert!((z - Vector3::z()).norm() < 1e-6, "back of hand {z}");
        assert!((frame.joints[5].radius - 0.008).abs() < 1e-9);
    }

    #[test]
    fn bad_joints_are_named_and_lost_tracking_is_untracked() {
        let mut hand = straight_hand();
        hand[10].position[1] = f32::NAN;
        let e = xr_frame(&hand, Handedness::Left, &XrMount::default(), 0.0)
            .expect_err("NaN is refused");
        assert!(e.to_string().contains(JOINT_NAMES[10]), "{e}");
        let mut hand = straight_hand();
        hand[3].tracked = false;
        let f = xr_frame(&hand, Handedness::Left, &XrMount::default(), 0.0).expect("untracked");
        assert!(!f.tracked && f.joints.is_empty());
        let e = xr_frame(&hand[..20], Handedness::Left, &XrMount::default(), 0.0)
            .expect_err("short hand");
        assert!(e.to_string().contains("20 joints"), "{e}");
    }

    #[test]
    fn the_inbox_hands_over_the_newest_frame_once() {
        let inbox = HandInbox::new("test");
        let mut source = inbox.clone();
        assert!(source.poll(1.0).is_none());
        for t in [0.1, 0.2] {
            inbox.push(HandFrame {
                t_s: t,
                hand: Handedness::Right,
                tracked: false,
                joints: Vec::new(),
            });
        }
        assert!(source.poll(0.15).is_none(), "not yet captured at 0.15 s");
        assert_eq!(source.poll(0.3).map(|f| f.t_s), Some(0.2));
        assert!(source.poll(0.4).is_none());
    }
}
