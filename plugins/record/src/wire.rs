//! The messages as they are on the wire: Foxglove's JSON encoding of its well-known schemas (times
//! as `{sec, nsec}`, bytes in base64), and the conversions to and from the types.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct Time {
    pub(crate) sec: u32,
    pub(crate) nsec: u32,
}

impl Time {
    pub(crate) fn of(ns: u64) -> Self {
        Self {
            sec: u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
            nsec: (ns % 1_000_000_000) as u32,
        }
    }

    pub(crate) fn ns(&self) -> u64 {
        u64::from(self.sec) * 1_000_000_000 + u64::from(self.nsec)
    }
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireImage {
    pub(crate) timestamp: Time,
    pub(crate) frame_id: String,
    pub(crate) data: String,
    pub(crate) format: String,
}

#[derive(Debug, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub(crate) struct WireCalibration {
    pub(crate) timestamp: Time,
    pub(crate) frame_id: String,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) distortion_model: String,
    pub(crate) D: Vec<f64>,
    pub(crate) K: Vec<f64>,
    pub(crate) R: Vec<f64>,
    pub(crate) P: Vec<f64>,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireVector3 {
    pub(crate) x: f64,
    pub(crate) y: f64,
    pub(crate) z: f64,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireQuaternion {
    pub(crate) x: f64,
    pub(crate) y: f64,
    pub(crate) z: f64,
    pub(crate) w: f64,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireTransform {
    pub(crate) timestamp: Time,
    pub(crate) parent_frame_id: String,
    pub(crate) child_frame_id: String,
    pub(crate) translation: WireVector3,
    pub(crate) rotation: WireQuaternion,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WirePose {
    pub(crate) position: WireVector3,
    pub(crate) orientation: WireQuaternion,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireHand {
    pub(crate) timestamp: Time,
    pub(crate) frame_id: String,
    pub(crate) poses: Vec<WirePose>,
    pub(crate) hand: String,
    pub(crate) tracked: bool,
    pub(crate) radius: Vec<f64>,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireCommand {
    pub(crate) timestamp: Time,
    pub(crate) name: Vec<String>,
    pub(crate) velocity: Vec<f64>,
    pub(crate) gripper_closed: bool,
    pub(crate) stopping: bool,
    pub(crate) tcp_speed: f64,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireObjectTarget {
    pub(crate) timestamp: Time,
    pub(crate) frame_id: String,
    pub(crate) pose: WirePose,
    pub(crate) object_twist: [f64; 6],
    pub(crate) twin_twist: [f64; 6],
    pub(crate) squeeze: f64,
    pub(crate) grasp_rank: u8,
    pub(crate) contacts: u32,
    pub(crate) held: bool,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireLog {
    pub(crate) timestamp: Time,
    pub(crate) level: u8,
    pub(crate) message: String,
    pub(crate) name: String,
    pub(crate) file: String,
    pub(crate) line: u32,
}

pub(crate) fn wire_pose(p: &Isometry3<f64>) -> WirePose {
    let (t, q) = (p.translation.vector, p.rotation);
    WirePose {
        position: WireVector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: WireQuaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// The pose of `translation` and `rotation`, or what is wrong with them.
pub(crate) fn pose_of(t: &WireVector3, q: &WireQuaternion) -> Result<Isometry3<f64>, String> {
    let t = Vector3::new(t.x, t.y, t.z);
    let q = Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = q.norm();
    if !(t.iter().all(|v| v.is_finite()) && norm.is_finite() && (norm - 1.0).abs() < 1e-3) {
        return Err(format!(
            "translation {t:?}, rotation of norm {norm}: not a pose"
        ));
    }
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// What is wrong with an object target's values, if anything.
pub(crate) fn object_target_fault(
    pose: &Isometry3<f64>,
    object_twist: &[f64; 6],
    twin_twist: &[f64; 6],
    squeeze_n: f64,
    grasp_rank: u8,
) -> Option<String> {
    if !finite_pose(pose) {
        return Some(format!("pose {pose:?} is not finite"));
    }
    if let Some(v) = object_twist.iter().find(|v| !v.is_finite()) {
        return Some(format!("the object's twist has {v}"));
    }
    if let Some(v) = twin_twist.iter().find(|v| !v.is_finite()) {
        return Some(format!("the twin's twist has {v}"));
    }
    if !squeeze_n.is_finite() {
        return Some(format!("squeezing force {squeeze_n} N"));
    }
    if grasp_rank > 6 {
        return Some(format!("grasp matrix rank {grasp_rank}, above 6"));
    }
    None
}

pub(crate) fn finite_pose(p: &Isometry3<f64>) -> bool {
    p.translation.vector.iter().all(|v| v.is_finite())
        && p.rotation.coords.iter().all(|v| v.is_finite())
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct WireJointState {
    pub(crate) timestamp: Time,
    pub(crate) name: Vec<String>,
    pub(crate) position: Vec<f64>,
    #[serde(default)]
    pub(crate) velocity: Vec<f64>,
}
