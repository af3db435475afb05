//! Leap Motion (Ultraleap Gemini) as a hand source.
//!
//! The conversion from Leap's bones to Avatarm's 26-joint skeleton ([`leap_frame`]) is plain
//! Rust, always compiled and tested; the device itself ([`LeapHand`], feature `leap`) goes
//! through `leaprs` on a worker thread that owns the LeapC connection.
//!
//! Leap's tracking frame: millimetres, origin at the device, +y up from the device (desktop
//! mount), +x to the user's right, +z toward the user. [`LeapMount`] places that frame in the
//! scene (metres, z up).
//!
//! Bones to joints (OpenXR order): a finger's metacarpal, proximal, intermediate and distal
//! joints are the `prev_joint` of Leap's four bones and its tip the distal bone's
//! `next_joint`. Leap models the thumb with a zero-length metacarpal, so the thumb's OpenXR
//! metacarpal, proximal and distal joints are the `prev_joint` of Leap's proximal,
//! intermediate and distal bones. The wrist is the arm bone's `next_joint`, the palm Leap's
//! palm position. Joint frames follow Avatarm's convention: +x along the bone toward the tip,
//! +z out of the back of the hand (against Leap's palm normal). Radii are half the bone widths.

use avatarm_core::teleop::hand::{HandFrame, HandJoint, Handedness, JOINT_NAMES};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::HandError;

/// One Leap bone: its two joints (mm, Leap frame) and width (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeapBone {
    /// The joint nearer the wrist.
    pub prev: [f32; 3],
    /// The joint nearer the tip.
    pub next: [f32; 3],
    /// Width (mm).
    pub width: f32,
}

/// One tracked Leap hand, as LeapC reports it (Leap frame, mm).
#[derive(Debug, Clone, PartialEq)]
pub struct LeapHandData {
    /// Left or right.
    pub hand: Handedness,
    /// Palm centre.
    pub palm: [f32; 3],
    /// Unit normal out of the palm.
    pub palm_normal: [f32; 3],
    /// The arm bone (elbow to wrist).
    pub arm: LeapBone,
    /// Thumb, index, middle, ring, pinky; each metacarpal, proximal, intermediate, distal.
    pub digits: [[LeapBone; 4]; 5],
}

/// Where the Leap device's frame sits in the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeapMount {
    /// Scene from Leap (metres; Leap's millimetres are scaled first).
    pub scene_from_leap: Isometry3<f64>,
}

impl Default for LeapMount {
    /// A device lying on the desk facing up at the scene's origin ([`LeapMount::desk`]).
    fn default() -> Self {
        Self::placed(Self::desk(), Vector3::zeros())
    }
}

impl LeapMount {
    /// Scene from Leap for a device lying on the desk facing up, the operator facing the
    /// scene's +x: Leap's +y (out of its face) is the scene's +z, its +z (toward the operator)
    /// the scene's −x, its +x (the operator's right) the scene's −y.
    pub fn desk() -> UnitQuaternion<f64> {
        Self::rotation(Matrix3::new(
            0.0, 0.0, -1.0, //
            -1.0, 0.0, 0.0, //
            0.0, 1.0, 0.0,
        ))
    }

    /// Scene from Leap for a device on the front of a headset (the paper's head-mounted Leap),
    /// the head level and facing the scene's +x: the desk device tipped forward by 90° about
    /// its +x, so Leap's +y (out of its face) is the scene's +x (ahead), its +z the scene's +z
    /// (up), its +x still the operator's right (−y).
    pub fn head() -> UnitQuaternion<f64> {
        Self::rotation(Matrix3::new(
            0.0, 1.0, 0.0, //
            -1.0, 0.0, 0.0, //
            0.0, 0.0, 1.0,
        ))
    }

    fn rotation(m: Matrix3<f64>) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
    }

    /// The device's frame turned by `scene_from_leap` (a rotation such as [`Self::desk`]) with
    /// its origin at `device_at` (scene, m).
    pub fn placed(scene_from_leap: UnitQuaternion<f64>, device_at: Vector3<f64>) -> Self {
        Self {
            scene_from_leap: Isometry3::from_parts(Translation3::from(device_at), scene_from_leap),
        }
    }

    /// The device turned by `scene_from_leap`, placed so that the Leap-frame point `anchor_mm`
    /// (millimetres, e.g. a hand at rest above the device) lands on `at` (scene, m).
    pub fn anchored(
        scene_from_leap: UnitQuaternion<f64>,
        anchor_mm: Vector3<f64>,
        at: Vector3<f64>,
    ) -> Self {
        Self::placed(scene_from_leap, at - scene_from_leap * (anchor_mm * 1e-3))
    }

    /// The mount that puts the wrist of `hand` (a Leap hand in Leap's frame) at `wrist_pose`
    /// in the scene, in Avatarm's hand-frame convention (+x from the wrist toward the fingers,
    /// +z out of the back of the hand, as [`avatarm_core::teleop::hand::skeleton`]): how a
    /// recording is placed where a task's hand starts. The hand's direction is its wrist to the
    /// middle finger's knuckle, square to Leap's palm normal. Errors name the vector that has
    /// no direction.
    pub fn with_wrist_pose(
        hand: &LeapHandData,
        wrist_pose: &Isometry3<f64>,
    ) -> Result<Self, HandError> {
        let f = |p: [f32; 3]| Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        let bad = |what: &str| HandError::BadTrackerFrame {
            tracker: "Leap",
            what: what.to_owned(),
            message: "no direction".to_owned(),
        };
        let normal = f(hand.palm_normal)
            .try_normalize(1e-9)
            .ok_or_else(|| bad("palm normal"))?;
        let along = f(hand.digits[2][1].prev) - f(hand.arm.next);
        let along = (along - normal * along.dot(&normal))
            .try_normalize(1e-9)
            .ok_or_else(|| bad("palm direction"))?;
        // Columns: toward the fingers, the third axis, out of the back of the hand.
        let frame =
            |x: Vector3<f64>, back: Vector3<f64>| Matrix3::from_columns(&[x, back.cross(&x), back]);
        let leap = frame(along, -normal);
        let scene = wrist_pose.rotation.to_rotation_matrix().into_inner();
        let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
            scene * leap.transpose(),
        ));
        let wrist = f(hand.arm.next) * 1e-3;
        Ok(Self {
            scene_from_leap: Isometry3::from_parts(
                Translation3::from(wrist_pose.translation.vector - r * wrist),
                r,
            ),
        })
    }
}

/// Converts one Leap hand at app time `t_s` into a frame in the scene. Errors name the bone
/// when a number is not finite or a bone has no length where one is needed.
pub fn leap_frame(
    data: &LeapHandData,
    mount: &LeapMount,
    t_s: f64,
) -> Result<HandFrame, HandError> {
    let bad = |what: String, message: &str| HandError::BadTrackerFrame {
        tracker: "Leap",
        what,
        message: message.to_owned(),
    };
    const DIGITS: [&str; 5] = ["thumb", "index", "middle", "ring", "pinky"];
    const BONES: [&str; 4] = ["metacarpal", "proximal", "intermediate", "distal"];
    let to_scene = |p: [f32; 3]| -> Vector3<f64> {
        let v = Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])) * 1e-3;
        (mount.scene_from_leap * v).coords
    };
    let finite = |what: String, v: &[f32]| {
        if v.iter().all(|x| x.is_finite()) {
            Ok(())
        } else {
            Err(bad(what, "not finite"))
        }
    };
    finite("palm".into(), &data.palm)?;
    finite("palm normal".into(), &data.palm_normal)?;
    finite("arm".into(), &[data.arm.prev, data.arm.next].concat())?;
    for (d, digit) in data.digits.iter().enumerate() {
        for (b, bone) in digit.iter().enumerate() {
            finite(
                format!("{} {}", DIGITS[d], BONES[b]),
                &[&bone.prev[..], &bone.next[..], &[bone.width]].concat(),
            )?;
        }
    }
    let back = -(mount.scene_from_leap.rotation
        * Vector3::new(
            f64::from(data.palm_normal[0]),
            f64::from(data.palm_normal[1]),
            f64::from(data.palm_normal[2]),
        ))
    .try_normalize(1e-9)
    .ok_or_else(|| bad("palm normal".into(), "zero length"))?;
    // Joint positions, their bone direction (toward the tip) and radius, in OpenXR order.
    let mut points: Vec<(Vector3<f64>, Vector3<f64>, f64)> = Vec::with_capacity(26);
    let wrist = to_scene(data.arm.next);
    let middle_base = to_scene(data.digits[2][1].prev);
    let palm_dir = middle_base - wrist;
    let palm_radius = f64::from(data.digits[2][1].width) * 1e-3 / 2.0;
    points.push((to_scene(data.palm), palm_dir, palm_radius));
    points.push((wrist, palm_dir, palm_radius));
    for (d, digit) in data.digits.iter().enumerate() {
        // The thumb's OpenXR joints start at Leap's proximal bone.
        let bones: &[LeapBone] = if d == 0 { &digit[1..] } else { &digit[..] };
        for bone in bones {
            let (a, b) = (to_scene(bone.prev), to_scene(bone.next));
            points.push((a, b - a, f64::from(bone.width) * 1e-3 / 2.0));
        }
        let last = bones[bones.len() - 1];
        let (a, b) = (to_scene(last.prev), to_scene(last.next));
        points.push((b, b - a, f64::from(last.width) * 1e-3 / 2.0));
    }
    debug_assert_eq!(points.len(), JOINT_NAMES.len());
    let joints = points
        .iter()
        .zip(JOINT_NAMES)
        .map(|(&(p, along, radius), name)| {
            let x = along
                .try_normalize(1e-6)
                .ok_or_else(|| bad(format!("bone at {name}"), "zero length"))?;
            let z = (back - x * back.dot(&x))
                .try_normalize(1e-6)
                .ok_or_else(|| bad(format!("bone at {name}"), "along the palm normal"))?;
            let y = z.cross(&x);
            let r = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
            Ok(HandJoint {
                pose: Isometry3::from_parts(
                    Translation3::from(p),
                    UnitQuaternion::from_rotation_matrix(&r),
                ),
                radius: radius.max(1e-3),
            })
        })
        .collect::<Result<Vec<_>, HandError>>()?;
    let frame = HandFrame {
        t_s,
        hand: data.hand,
        tracked: true,
        joints,
    };
    frame.validate()?;
    Ok(frame)
}

#[cfg(feature = "leap")]
pub use device::{LeapHand, LeapOptions};

#[cfg(feature = "leap")]
mod device {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::mpsc::{Receiver, TryRecvError, channel};
    use std::sync::{Arc, Mutex};
    use std::time::Instant;

    use avatarm_core::teleop::hand::{HandFrame, Handedness};
    use bevy::log::{error, info, warn};
    use leaprs::{Connection, ConnectionConfig, EventRef, HandType};

    use super::{LeapBone, LeapHandData, LeapMount, leap_frame};
    use crate::{HandError, HandSource};

    /// What the Leap source tracks.
    #[derive(Debug, Clone, Copy)]
    pub struct LeapOptions {
        /// The hand to follow.
        pub hand: Handedness,
        /// Where the device sits in the scene.
        pub mount: LeapMount,
        /// No answer from the tracking service within this long is reported (s).
        pub service_timeout_s: f64,
    }

    impl Default for LeapOptions {
        fn default() -> Self {
            Self {
                hand: Handedness::Right,
                mount: LeapMount::default(),
                service_timeout_s: 3.0,
            }
        }
    }

    enum Message {
        Hand(Instant, Box<LeapHandData>),
        Lost(Instant),
        Problem(String),
    }

    /// Leap Motion hands through the Ultraleap tracking service (LeapC), polled on a worker
    /// thread. Without a service or a device it logs what is missing once and yields no
    /// frames: the app goes on without a hand.
    pub struct LeapHand {
        options: LeapOptions,
        /// In a mutex only to make the source `Sync`; `poll` has `&mut self` and never locks.
        rx: Mutex<Receiver<Message>>,
        /// App time minus wall time, fixed at the first poll.
        clock: Option<(Instant, f64)>,
        latest: Option<HandFrame>,
        stopped: bool,
        /// Tells the worker to close the connection and end.
        stop: Arc<AtomicBool>,
    }

    impl Drop for LeapHand {
        fn drop(&mut self) {
            self.stop.store(true, Ordering::Relaxed);
        }
    }

    impl LeapHand {
        /// Starts the worker. Fails only when the thread cannot start; a missing service or
        /// device is reported from the worker, and the source then stays silent.
        pub fn start(options: LeapOptions) -> Result<Self, HandError> {
            let (tx, rx) = channel();
            let timeout = options.service_timeout_s;
            let stop = Arc::new(AtomicBool::new(false));
            let stop_worker = Arc::clone(&stop);
            std::thread::Builder::new()
                .name("leap".into())
                .spawn(move || worker(&tx, timeout, &stop_worker))
                .map_err(|e| HandError::Device {
                    source_name: "Leap",
                    message: format!("cannot start the worker thread: {e}"),
                })?;
            Ok(Self {
                options,
                rx: Mutex::new(rx),
                clock: None,
                latest: None,
                stopped: false,
                stop,
            })
        }
    }

    fn worker(tx: &std::sync::mpsc::Sender<Message>, timeout_s: f64, stop: &AtomicBool) {
        let mut connection = match Connection::create(ConnectionConfig::default()) {
            Ok(c) => c,
            Err(e) => {
                let _ = tx.send(Message::Problem(format!(
                    "Leap: cannot create a LeapC connection: {e}"
                )));
                return;
            }
        };
        if let Err(e) = connection.open() {
            let _ = tx.send(Message::Problem(format!(
                "Leap: cannot open the LeapC connection: {e}"
            )));
            return;
        }
        let started = Instant::now();
        let (mut service, mut device, mut warned) = (false, false, false);
        while !stop.load(Ordering::Relaxed) {
            match connection.poll(100) {
                Ok(message) => match message.event() {
                    EventRef::Connection(_) => service = true,
                    EventRef::Device(_) => device = true,
                    EventRef::ConnectionLost(_) => {
                        service = false;
                        let _ = tx.send(Message::Problem(
                            "Leap: the tracking service went away".into(),
                        ));
                    }
                    EventRef::Tracking(e) => {
                        device = true;
                        let now = Instant::now();
                        let hands = e.hands();
                        if hands.is_empty() && tx.send(Message::Lost(now)).is_err() {
                            return;
                        }
                        for h in hands {
                            if tx.send(Message::Hand(now, Box::new(convert(&h)))).is_err() {
                                return;
                            }
                        }
                    }
                    _ => {}
                },
                Err(_) => {
                    // Timeouts: nothing to read.
                }
            }
            if !warned && started.elapsed().as_secs_f64() > timeout_s && !(service && device) {
                warned = true;
                let what = if service {
                    "the Ultraleap tracking service runs but reports no device (is the Leap \
                     Motion plugged in?)"
                } else {
                    "no Ultraleap tracking service answered (install Ultraleap Gemini and \
                     start its service; docs/hardware.md)"
                };
                if tx.send(Message::Problem(format!("Leap: {what}"))).is_err() {
                    return;
                }
            }
        }
    }

    fn bone(b: &leaprs::BoneRef) -> LeapBone {
        LeapBone {
            prev: b.prev_joint().array(),
            next: b.next_joint().array(),
            width: b.width,
        }
    }

    fn convert(h: &leaprs::HandRef) -> LeapHandData {
        let digits = h.digits();
        let palm = h.palm();
        LeapHandData {
            hand: match h.hand_type() {
                HandType::Left => Handedness::Left,
                HandType::Right => Handedness::Right,
            },
            palm: palm.position().array(),
            palm_normal: palm.normal().array(),
            arm: bone(&h.arm()),
            digits: std::array::from_fn(|d| {
                let bones = digits[d].bones();
                std::array::from_fn(|b| bone(&bones[b]))
            }),
        }
    }

    impl HandSource for LeapHand {
        fn name(&self) -> &str {
            "Leap Motion"
        }

        fn poll(&mut self, now_s: f64) -> Option<HandFrame> {
            let (wall0, app0) = *self.clock.get_or_insert((Instant::now(), now_s));
            let app_time = |at: Instant| app0 + at.saturating_duration_since(wall0).as_secs_f64();
            let rx = match self.rx.get_mut() {
                Ok(rx) => rx,
                Err(poisoned) => poisoned.into_inner(),
            };
            loop {
                match rx.try_recv() {
                    Ok(Message::Hand(at, data)) if data.hand == self.options.hand => {
                        match leap_frame(&data, &self.options.mount, app_time(at)) {
                            Ok(f) => self.latest = Some(f),
                            Err(e) => warn!("{e}"),
                        }
                    }
                    Ok(Message::Hand(..)) => {}
                    Ok(Message::Lost(at)) => {
                        self.latest = Some(HandFrame {
                            t_s: app_time(at),
                            hand: self.options.hand,
                            tracked: false,
                            joints: Vec::new(),
                        });
                    }
                    Ok(Message::Problem(p)) => error!("{p}; going on without a hand"),
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => {
                        if !self.stopped {
                            self.stopped = true;
                            info!("Leap: the worker stopped; no more hand frames");
                        }
                        break;
                    }
                }
            }
            self.latest.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat right hand over the device, palm down, fingers toward −z (away from the user).
    fn flat_hand() -> LeapHandData {
        let bone = |x: f32, z0: f32, z1: f32, w: f32| LeapBone {
            prev: [x, 200.0, z0],
            next: [x, 200.0, z1],
            width: w,
        };
        let finger = |x: f32| {
            [
                bone(x, 0.0, -60.0, 18.0),
                bone(x, -60.0, -100.0, 17.0),
                bone(x, -100.0, -125.0, 16.0),
                bone(x, -125.0, -145.0, 15.0),
            ]
        };
        LeapHandData {
            hand: Handedness::Right,
            palm: [0.0, 200.0, -40.0],
            palm_normal: [0.0, -1.0, 0.0],
            arm: bone(0.0, 250.0, 0.0, 60.0),
            digits: [
                [
                    bone(-40.0, -10.0, -10.0, 20.0),
                    bone(-40.0, -10.0, -45.0, 20.0),
                    bone(-40.0, -45.0, -75.0, 19.0),
                    bone(-40.0, -75.0, -100.0, 18.0),
                ],
                finger(-20.0),
                finger(0.0),
                finger(20.0),
                finger(40.0),
            ],
        }
    }

    #[test]
    fn leap_bones_become_the_openxr_skeleton_in_the_scene() {
        let f = leap_frame(&flat_hand(), &LeapMount::default(), 1.5).expect("frame");
        assert_eq!(f.joints.len(), 26);
        assert!(f.tracked && f.t_s == 1.5);
        let at = |i: usize| f.joints[i].pose.translation.vector;
        // 200 mm above the device: 0.2 m up in the scene.
        assert!((at(1).z - 0.2).abs() < 1e-9, "wrist {:?}", at(1));
        // Fingers point away from the user (Leap −z): the scene's +x.
        let index_tip = 10;
        assert!(
            (at(index_tip).x - 0.145).abs() < 1e-6,
            "{:?}",
            at(index_tip)
        );
        // The thumb skips Leap's zero-length metacarpal: its first joint is the proximal
        // bone's start, its tip the distal bone's end.
        assert!((at(2).x - 0.010).abs() < 1e-6 && (at(5).x - 0.100).abs() < 1e-6);
        // Joint frames: +x toward the tip, +z out of the back of the hand (up: palm down).
        let r = f.joints[8].pose.rotation;
        assert!((r * Vector3::x() - Vector3::x()).norm() < 1e-6);
        assert!((r * Vector3::z() - Vector3::z()).norm() < 1e-6);
        // Radii are half the widths, in metres.
        assert!((f.joints[7].radius - 0.0085).abs() < 1e-9);
    }

    #[test]
    fn a_bad_leap_hand_is_named_not_passed_on() {
        let mut nan = flat_hand();
        nan.digits[3][2].next[1] = f32::NAN;
        let e = leap_frame(&nan, &LeapMount::default(), 0.0).expect_err("NaN");
        assert!(e.to_string().contains("ring intermediate"), "{e}");
        let mut flat = flat_hand();
        flat.palm_normal = [0.0; 3];
        let e = leap_frame(&flat, &LeapMount::default(), 0.0).expect_err("no normal");
        assert!(e.to_string().contains("palm normal"), "{e}");
        let mut short = flat_hand();
        short.digits[1][3].next = short.digits[1][3].prev;
        let e = leap_frame(&short, &LeapMount::default(), 0.0).expect_err("zero bone");
        assert!(e.to_string().contains("index"), "{e}");
    }

    #[test]
    fn desk_and_head_mounts_turn_the_device_as_it_sits() {
        for r in [LeapMount::desk(), LeapMount::head()] {
            let m = r.to_rotation_matrix().into_inner();
            assert!((m.determinant() - 1.0).abs() < 1e-12, "a proper rotation");
            // Leap's +x is the operator's right, the scene's −y, on either mount.
            assert!((r * Vector3::x() + Vector3::y()).norm() < 1e-12);
        }
        // Desk: out of the device's face is up; head: ahead, with Leap's +z up.
        assert!((LeapMount::desk() * Vector3::y() - Vector3::z()).norm() < 1e-12);
        assert!((LeapMount::head() * Vector3::y() - Vector3::x()).norm() < 1e-12);
        assert!((LeapMount::head() * Vector3::z() - Vector3::z()).norm() < 1e-12);
        // The same Leap-frame hand seen by a head-mounted device is ahead of the face, its
        // palm toward the operator (Leap's −y is the scene's −x), its fingers down (Leap's −z).
        let at = Vector3::new(0.3, -0.1, 1.2);
        let mount = LeapMount::anchored(LeapMount::head(), Vector3::new(0.0, 200.0, 0.0), at);
        let f = leap_frame(&flat_hand(), &mount, 0.0).expect("frame");
        assert!((f.joints[1].pose.translation.vector - at).norm() < 1e-9);
        let tip = f.joints[10].pose.translation.vector - at;
        assert!(tip.z < -0.14, "fingers point down: {tip:?}");
        let back = f.joints[0].pose.rotation * Vector3::z();
        assert!(
            (back - Vector3::x()).norm() < 1e-6,
            "back of the hand ahead: {back:?}"
        );
        assert_eq!(
            LeapMount::default(),
            LeapMount::placed(LeapMount::desk(), Vector3::zeros())
        );
    }
}
