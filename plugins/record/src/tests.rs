//! Round trips through a file, refusals by name, and files read by other readers.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use crate::camera::{CameraCalibration, DistortionModel};
use crate::topics;
use crate::types::{
    CompressedFrame, HEAD_POSE_SLACK_NS, HandPoses, HeadPose, ImageFormat, JointStates, LogLevel,
    ObjectTarget, Recording, RobotCommand, SafetyEvent,
};
use crate::write::RecordingWriter;

const PNG: &[u8] = b"\x89PNG\r\n\x1a\n(the rest of a png)";
const JPEG: &[u8] = &[0xff, 0xd8, 0xff, 0xe0, 1, 2, 3];

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("avatarm_record_{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    dir.join(name)
}

fn calibration() -> CameraCalibration {
    CameraCalibration {
        width: 640,
        height: 480,
        k: [600.0, 0.0, 320.0, 0.0, 601.0, 240.0, 0.0, 0.0, 1.0],
        distortion_model: DistortionModel::RationalPolynomial,
        d: vec![0.1, -0.05, 0.001, 0.002, 0.01, 0.0, 0.0, 0.0],
    }
}

#[test]
fn a_recording_reads_back_as_written() {
    let path = temp("round_trip.mcap");
    let pose = Isometry3::from_parts(
        Translation3::new(1.2, -0.1, 0.6),
        UnitQuaternion::from_euler_angles(-2.0, 0.1, 1.5),
    );
    let joints = |i: u64| JointStates {
        stamp_ns: 1_700_000_000_000_000_000 + i * 10_000_000,
        names: vec!["j1".into(), "j2".into()],
        positions: vec![0.1 * i as f64, -0.2],
        velocities: vec![0.5, 0.0],
    };
    let mut w = RecordingWriter::create(&path).expect("create");
    w.calibration(1_700_000_000_000_000_000, &calibration())
        .expect("calibration");
    w.camera_pose(1_700_000_000_000_000_000, &pose)
        .expect("pose");
    // Written out of order: read back by stamp.
    for i in [2u64, 0, 1] {
        w.joint_states(&joints(i)).expect("joints");
        let f = CompressedFrame {
            stamp_ns: 1_700_000_000_000_000_000 + i * 33_333_333,
            format: if i == 1 {
                ImageFormat::Jpeg
            } else {
                ImageFormat::Png
            },
            data: if i == 1 { JPEG.to_vec() } else { PNG.to_vec() },
        };
        w.frame(&f).expect("frame");
    }
    w.reference_mask(&CompressedFrame {
        stamp_ns: 1_700_000_000_000_000_000,
        format: ImageFormat::Png,
        data: PNG.to_vec(),
    })
    .expect("mask");
    assert_eq!(w.messages(), 9);
    // A live session's streams: the base in the world, the hand, commands, events.
    let base = Isometry3::translation(0.0, 0.0, 0.75);
    w.base_pose(1_700_000_000_000_000_000, &base).expect("base");
    let hand = HandPoses {
        stamp_ns: 1_700_000_000_005_000_000,
        hand: "right".into(),
        tracked: true,
        poses: vec![pose, base],
        radii: vec![0.01, 0.008],
    };
    w.hand(&hand).expect("hand");
    let lost = HandPoses {
        stamp_ns: 1_700_000_000_006_000_000,
        tracked: false,
        poses: vec![],
        radii: vec![],
        ..hand.clone()
    };
    w.hand(&lost).expect("untracked hand");
    let command = RobotCommand {
        stamp_ns: 1_700_000_000_010_000_000,
        names: vec!["j1".into(), "j2".into()],
        velocities: vec![0.1, -0.05],
        gripper_closed: true,
        stopping: false,
        tcp_speed: 0.12,
    };
    w.robot_command(&command).expect("command");
    let event = SafetyEvent {
        stamp_ns: 1_700_000_000_011_000_000,
        level: LogLevel::Error,
        source: "limiter".into(),
        message: "stopping: the hand is not tracked".into(),
    };
    w.safety_event(&event).expect("event");
    let target = ObjectTarget {
        stamp_ns: 1_700_000_000_010_000_000,
        world_from_object: Isometry3::from_parts(
            Translation3::new(0.6, -0.1, 0.9),
            UnitQuaternion::from_euler_angles(0.2, 0.0, 0.1),
        ),
        object_twist: [0.01, 0.0, 0.02, 0.0, 0.3, 0.0],
        twin_twist: [0.01, 0.0, 0.02, 0.0, 0.3, 0.0],
        squeeze_n: 4.5,
        grasp_rank: 6,
        contacts: 5,
        held: true,
    };
    w.object_target(&target).expect("target");
    // A NaN target, a rank above 6: refused by name, nothing written.
    let nan = ObjectTarget {
        squeeze_n: f64::NAN,
        ..target
    };
    let e = w.object_target(&nan).expect_err("a NaN target");
    assert!(e.to_string().contains("squeezing force NaN"), "{e}");
    let e = w
        .object_target(&ObjectTarget {
            grasp_rank: 7,
            ..target
        })
        .expect_err("rank 7");
    assert!(e.to_string().contains("rank 7"), "{e}");
    w.finish().expect("finish");

    let r = Recording::open(&path).expect("open");
    assert_eq!(r.calibration, Some(calibration()));
    let back = r.base_from_camera.expect("pose");
    assert!((back.translation.vector - pose.translation.vector).norm() < 1e-12);
    assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
    assert_eq!(r.frames.len(), 3);
    assert!(r.frames.windows(2).all(|w| w[0].stamp_ns < w[1].stamp_ns));
    assert_eq!(r.frames[1].format, ImageFormat::Jpeg);
    assert_eq!(r.frames[1].data, JPEG);
    assert_eq!(r.reference_masks.len(), 1);
    assert_eq!(r.joint_states, vec![joints(0), joints(1), joints(2)]);
    // Sample-and-hold lookup.
    assert_eq!(r.joints_at(1_700_000_000_015_000_000), Some(&joints(1)));
    assert_eq!(r.joints_at(1), None);
    assert!(r.other_topics.is_empty());
    assert!((r.world_from_base.expect("base").translation.z - 0.75).abs() < 1e-12);
    assert_eq!(r.hands.len(), 2);
    assert_eq!(
        (r.hands[0].hand.as_str(), r.hands[0].tracked),
        ("right", true)
    );
    assert!(r.hands[0].poses[0].rotation.angle_to(&pose.rotation) < 1e-12);
    assert_eq!(r.hands[0].radii, hand.radii);
    assert_eq!(r.hands[1], lost);
    assert_eq!(r.commands, vec![command]);
    assert_eq!(r.safety, vec![event]);
    assert_eq!(r.targets.len(), 1);
    let t = r.targets[0];
    assert_eq!(
        (t.stamp_ns, t.grasp_rank, t.contacts, t.held),
        (target.stamp_ns, 6, 5, true)
    );
    assert_eq!(
        (t.object_twist, t.twin_twist),
        (target.object_twist, target.twin_twist)
    );
    assert!(
        t.world_from_object
            .rotation
            .angle_to(&target.world_from_object.rotation)
            < 1e-12
    );
    assert!(
        (t.world_from_object.translation.vector - target.world_from_object.translation.vector)
            .norm()
            < 1e-12
    );
}

#[test]
fn a_camera_on_a_head_reads_back_as_its_head_poses_and_mount() {
    let path = temp("head.mcap");
    let head = |i: u64| HeadPose {
        stamp_ns: 1_000_000_000 + i * 10_000_000,
        base_from_head: Isometry3::from_parts(
            Translation3::new(0.1 * i as f64, -1.0, 0.5),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.1 * i as f64),
        ),
    };
    let mount = Isometry3::translation(0.0, -0.03, 0.08);
    let mut w = RecordingWriter::create(&path).expect("create");
    w.camera_mount(1_000_000_000, &mount).expect("mount");
    for i in [1u64, 0, 2] {
        w.head_pose(&head(i)).expect("head");
    }
    let nan = HeadPose {
        stamp_ns: 5,
        base_from_head: Isometry3::translation(f64::NAN, 0.0, 0.0),
    };
    let e = w.head_pose(&nan).expect_err("NaN");
    assert!(e.to_string().contains("head pose at 5 ns"), "{e}");
    w.finish().expect("finish");
    let r = Recording::open(&path).expect("open");
    assert!(r.camera_on_head());
    assert_eq!(r.base_from_camera, None);
    assert_eq!(r.head_poses.len(), 3);
    assert!(
        r.head_poses
            .windows(2)
            .all(|w| w[0].stamp_ns < w[1].stamp_ns)
    );
    assert!(r.other_topics.is_empty(), "{:?}", r.other_topics);
    // Halfway between the first two: 5 cm and 0.05 rad along; outside, the nearest.
    let mid = r.head_at(1_005_000_000).expect("head");
    assert!((mid.translation.x - 0.05).abs() < 1e-12);
    assert!((mid.rotation.euler_angles().2 - 0.05).abs() < 1e-12);
    assert_eq!(r.head_at(0), Some(head(0).base_from_head));
    // The poses span 1.00-1.02 s: 50 ms either side is covered, not more.
    assert!(r.head_covers(1_010_000_000, 0) && r.head_covers(955_000_000, HEAD_POSE_SLACK_NS));
    assert!(!r.head_covers(945_000_000, HEAD_POSE_SLACK_NS));
    assert!(!r.head_covers(1_071_000_000, HEAD_POSE_SLACK_NS));
    let camera = r.camera_at(1_020_000_000).expect("camera");
    let expected = head(2).base_from_head * mount;
    assert!((camera.translation.vector - expected.translation.vector).norm() < 1e-12);
    assert!(camera.rotation.angle_to(&expected.rotation) < 1e-12);
}

#[test]
fn bad_values_are_refused_before_they_are_written() {
    let path = temp("refused.mcap");
    let mut w = RecordingWriter::create(&path).expect("create");
    let e = w
        .joint_states(&JointStates {
            stamp_ns: 1,
            names: vec!["a".into(), "b".into()],
            positions: vec![0.0, f64::NAN],
            velocities: vec![],
        })
        .expect_err("NaN");
    assert!(e.to_string().contains("joint 'b' has NaN"), "{e}");
    let e = w
        .joint_states(&JointStates {
            stamp_ns: 1,
            names: vec!["a".into()],
            positions: vec![0.0, 1.0],
            velocities: vec![],
        })
        .expect_err("lengths");
    assert!(e.to_string().contains("1 names, 2 positions"), "{e}");
    let e = w
        .frame(&CompressedFrame {
            stamp_ns: 1,
            format: ImageFormat::Jpeg,
            data: PNG.to_vec(),
        })
        .expect_err("not jpeg");
    assert!(e.to_string().contains("not jpeg"), "{e}");
    let e = w
        .robot_command(&RobotCommand {
            stamp_ns: 1,
            names: vec!["j1".into()],
            velocities: vec![f64::NAN],
            gripper_closed: false,
            stopping: true,
            tcp_speed: 0.0,
        })
        .expect_err("a NaN command");
    assert!(e.to_string().contains("joint 'j1' has NaN"), "{e}");
    let e = w
        .hand(&HandPoses {
            stamp_ns: 1,
            hand: "right".into(),
            tracked: true,
            poses: vec![],
            radii: vec![],
        })
        .expect_err("tracked, no joints");
    assert!(e.to_string().contains("0 poses"), "{e}");
    let mut bad = calibration();
    bad.d.pop();
    let e = w.calibration(0, &bad).expect_err("7 of 8");
    assert!(e.to_string().contains("7 coefficients"), "{e}");
    assert_eq!(w.messages(), 0);
    w.finish().expect("finish");
    let r = Recording::open(&path).expect("an empty recording");
    assert!(r.frames.is_empty() && r.calibration.is_none());
}

/// A file written by another writer: one message `data` on the joint-state topic, its
/// channel's metadata `metadata`.
fn raw_joint_states(name: &str, metadata: &BTreeMap<String, String>, data: &[u8]) -> PathBuf {
    let path = temp(name);
    let file = File::create(&path).expect("create");
    let mut w = mcap::Writer::new(BufWriter::new(file)).expect("writer");
    let schema = w
        .add_schema("avatarm.JointState", "jsonschema", b"{}")
        .expect("schema");
    let channel_id = w
        .add_channel(schema, topics::JOINT_STATES, "json", metadata)
        .expect("channel");
    let header = mcap::records::MessageHeader {
        channel_id,
        sequence: 0,
        log_time: 0,
        publish_time: 0,
    };
    w.write_to_known_channel(&header, data).expect("message");
    w.finish().expect("finish");
    path
}

#[test]
fn damaged_or_foreign_files_are_refused_by_name() {
    // Not MCAP.
    let path = temp("not.mcap");
    std::fs::write(&path, b"hello").expect("write");
    let e = Recording::open(&path).expect_err("not mcap");
    assert!(e.to_string().contains("not a readable MCAP file"), "{e}");
    // Another format version, and a message that is not its schema.
    let v2 = BTreeMap::from([("avatarm_format".to_owned(), "2".to_owned())]);
    let path = raw_joint_states("foreign.mcap", &v2, b"{}");
    let e = Recording::open(&path).expect_err("format 2");
    assert!(e.to_string().contains("format 2"), "{e}");
    let path = raw_joint_states(
        "bad_message.mcap",
        &BTreeMap::new(),
        br#"{"timestamp": {"sec": 1, "nsec": 0}, "name": ["a"], "position": [1.0, 2.0]}"#,
    );
    let e = Recording::open(&path).expect_err("sizes");
    assert!(
        e.to_string()
            .contains("/joint_states, message 0: 1 names, 2 positions"),
        "{e}"
    );
}
