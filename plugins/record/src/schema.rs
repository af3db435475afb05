//! The JSON schemas of the channels (Foxglove's well-known ones and Avatarm's own), written into
//! each file.

use serde_json::json;

use crate::topics;

/// The JSON Schema of each topic's messages, and its name (Foxglove's where it has one).
pub(crate) fn schema(topic: &str) -> (&'static str, serde_json::Value) {
    let time = json!({
        "type": "object",
        "title": "time",
        "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}
    });
    let numbers = json!({"type": "array", "items": {"type": "number"}});
    let xyz = json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}});
    match topic {
        topics::IMAGE | topics::REFERENCE_MASK | topics::ERASED | topics::MASK => (
            "foxglove.CompressedImage",
            json!({
                "title": "foxglove.CompressedImage",
                "description": "A compressed image",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "frame_id": {"type": "string"},
                    "data": {"type": "string", "contentEncoding": "base64"},
                    "format": {"type": "string"}
                }
            }),
        ),
        topics::CALIBRATION => (
            "foxglove.CameraCalibration",
            json!({
                "title": "foxglove.CameraCalibration",
                "description": "Camera calibration parameters",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "frame_id": {"type": "string"},
                    "width": {"type": "integer", "minimum": 0},
                    "height": {"type": "integer", "minimum": 0},
                    "distortion_model": {"type": "string"},
                    "D": numbers, "K": numbers, "R": numbers, "P": numbers
                }
            }),
        ),
        topics::TRANSFORM => (
            "foxglove.FrameTransform",
            json!({
                "title": "foxglove.FrameTransform",
                "description": "A transform between two reference frames in 3D space",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "parent_frame_id": {"type": "string"},
                    "child_frame_id": {"type": "string"},
                    "translation": xyz,
                    "rotation": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}}
                }
            }),
        ),
        topics::HAND => (
            "foxglove.PosesInFrame",
            json!({
                "title": "foxglove.PosesInFrame",
                "description": "An array of timestamped poses in a reference frame (Avatarm: a hand's joints, with its side, whether it is tracked and each joint's radius in m)",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "frame_id": {"type": "string"},
                    "poses": {"type": "array", "items": {"type": "object", "properties": {
                        "position": xyz,
                        "orientation": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}}
                    }}},
                    "hand": {"type": "string", "enum": ["left", "right"]},
                    "tracked": {"type": "boolean"},
                    "radius": numbers
                }
            }),
        ),
        topics::ROBOT_COMMAND => (
            "avatarm.JointCommand",
            json!({
                "title": "avatarm.JointCommand",
                "description": "One control tick's command to the robot: joint velocities (rad/s or m/s), the gripper, whether the safety limiter is stopping the arm, the tool-point speed (m/s)",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "name": {"type": "array", "items": {"type": "string"}},
                    "velocity": numbers,
                    "gripper_closed": {"type": "boolean"},
                    "stopping": {"type": "boolean"},
                    "tcp_speed": {"type": "number"}
                }
            }),
        ),
        topics::OBJECT_TARGET => (
            "avatarm.ObjectTarget",
            json!({
                "title": "avatarm.ObjectTarget",
                "description": "The operator's target for the real object at one control tick: its pose in frame_id (m), its twist and the twin's (m/s then rad/s), the squeezing force (N), the grasp matrix's rank, the contacts on the twin, whether the hand holds it",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "frame_id": {"type": "string"},
                    "pose": {"type": "object", "properties": {
                        "position": xyz,
                        "orientation": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}}
                    }},
                    "object_twist": numbers,
                    "twin_twist": numbers,
                    "squeeze": {"type": "number"},
                    "grasp_rank": {"type": "integer", "minimum": 0, "maximum": 6},
                    "contacts": {"type": "integer", "minimum": 0},
                    "held": {"type": "boolean"}
                }
            }),
        ),
        topics::SAFETY => (
            "foxglove.Log",
            json!({
                "title": "foxglove.Log",
                "description": "A log message",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "level": {"type": "integer", "minimum": 0, "maximum": 5},
                    "message": {"type": "string"},
                    "name": {"type": "string"},
                    "file": {"type": "string"},
                    "line": {"type": "integer", "minimum": 0}
                }
            }),
        ),
        _ => (
            "avatarm.JointState",
            json!({
                "title": "avatarm.JointState",
                "description": "The robot's joints at one instant: names, positions (rad or m), velocities (rad/s or m/s)",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "name": {"type": "array", "items": {"type": "string"}},
                    "position": numbers,
                    "velocity": numbers
                }
            }),
        ),
    }
}
