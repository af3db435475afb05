//! Leap Motion recordings: the JSON that leapjs-playback records (Leap's WebSocket protocol v6,
//! `{"metadata", "frames": [...]}`, optionally gzip-compressed), read into [`LeapHandData`] per
//! hand per frame, the same plain data the live device gives [`leap_frame`].
//!
//! What a v6 frame carries per hand: the palm (`palmPosition`, `palmNormal`, `direction`, mm,
//! Leap frame) and per finger (`pointables`, `type` 0 thumb .. 4 pinky) the joints
//! `mcpPosition`, `pipPosition`, `dipPosition`, `tipPosition`, and in newer recordings the
//! metacarpal base `carpPosition`. What it lacks is inferred:
//!
//! - **Metacarpal bases** (`carpPosition` absent): each finger's metacarpal runs from its knuckle
//!   back along the palm's `direction`, with a length that is a fixed ratio of that finger's
//!   proximal phalanx (mean adult ratios, Buryanov & Kotiuk, "Proportions of hand segments",
//!   Int. J. Morphol. 28(3), 2010: metacarpal II–V 68.1, 64.6, 58.0, 53.7 mm over proximal
//!   phalanx 39.8, 44.6, 41.4, 32.7 mm). The thumb's metacarpal is Leap's zero-length one.
//! - **The wrist**: the mean of the four metacarpal bases; the arm runs 250 mm back from it
//!   along the palm's direction.
//!
//! **Constant bones.** A hand's bones do not change length; a tracker's estimates do a little.
//! Each bone of each hand (by Leap's hand id) takes its median length over the recording, and
//! every frame's finger is rebuilt from its knuckle outwards along the recorded bone directions
//! with those lengths (the metacarpal inwards from the knuckle).

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use avatarm_core::teleop::hand::{HandFrame, Handedness};
use nalgebra::Vector3;
use serde::Deserialize;

use crate::HandError;
use crate::leap::{LeapBone, LeapHandData, LeapMount, leap_frame};

/// Metacarpal length over proximal phalanx length, index to pinky (see the module docs).
const METACARPAL_RATIO: [f32; 4] = [68.1 / 39.8, 64.6 / 44.6, 58.0 / 41.4, 53.7 / 32.7];

/// How far the arm bone runs back from the wrist (mm); only its direction is used.
const ARM_LENGTH_MM: f32 = 250.0;

/// One recorded frame: its time and the hands in it.
#[derive(Debug, Clone, PartialEq)]
pub struct LeapRecordedFrame {
    /// Seconds since the recording's first frame (from Leap's `timestamp`, µs).
    pub t_s: f64,
    /// The hands tracked in this frame, with Leap's hand ids.
    pub hands: Vec<(i64, LeapHandData)>,
    /// Per hand (same order), the joints as recorded before anything was inferred or made
    /// constant (Leap frame, mm): the palm, then each finger's `mcpPosition`, `pipPosition`,
    /// `dipPosition` and `tipPosition`, thumb to pinky (21 points).
    pub recorded_joints: Vec<Vec<[f32; 3]>>,
}

/// A Leap recording, read and with its bone lengths made constant.
#[derive(Debug, Clone, PartialEq)]
pub struct LeapRecording {
    /// Where it was read from.
    pub path: PathBuf,
    /// Frames in time order.
    pub frames: Vec<LeapRecordedFrame>,
}

#[derive(Deserialize)]
struct RawFile {
    #[serde(default)]
    metadata: Option<RawMetadata>,
    frames: Vec<RawFrame>,
}

#[derive(Deserialize)]
struct RawMetadata {
    #[serde(rename = "protocolVersion")]
    protocol_version: Option<u32>,
}

#[derive(Deserialize)]
struct RawFrame {
    timestamp: Option<f64>,
    #[serde(default)]
    hands: Vec<RawHand>,
    #[serde(default)]
    pointables: Vec<RawPointable>,
}

#[derive(Deserialize)]
struct RawHand {
    id: i64,
    #[serde(rename = "type")]
    kind: String,
    #[serde(rename = "palmPosition")]
    palm_position: [f32; 3],
    #[serde(rename = "palmNormal")]
    palm_normal: [f32; 3],
    direction: [f32; 3],
}

#[derive(Deserialize)]
struct RawPointable {
    #[serde(rename = "handId")]
    hand_id: i64,
    #[serde(rename = "type")]
    kind: Option<i64>,
    #[serde(default)]
    tool: bool,
    #[serde(rename = "carpPosition")]
    carp: Option<[f32; 3]>,
    #[serde(rename = "mcpPosition")]
    mcp: Option<[f32; 3]>,
    #[serde(rename = "pipPosition")]
    pip: Option<[f32; 3]>,
    #[serde(rename = "dipPosition")]
    dip: Option<[f32; 3]>,
    #[serde(rename = "tipPosition")]
    tip: Option<[f32; 3]>,
    #[serde(default)]
    width: f32,
}

fn v(p: [f32; 3]) -> Vector3<f32> {
    Vector3::from(p)
}

fn a(v: Vector3<f32>) -> [f32; 3] {
    [v.x, v.y, v.z]
}

impl LeapRecording {
    /// Reads a recording (`.json`, or gzip `.json.gz`). Errors name the file and, for a frame
    /// that cannot be used, the frame number, the hand and the finger.
    pub fn open(path: &Path) -> Result<Self, HandError> {
        let io = |source| HandError::Io {
            path: path.to_owned(),
            source,
        };
        let bytes = std::fs::read(path).map_err(io)?;
        let text = if bytes.starts_with(&[0x1f, 0x8b]) {
            let mut out = String::new();
            flate2::read::GzDecoder::new(&bytes[..])
                .read_to_string(&mut out)
                .map_err(io)?;
            out
        } else {
            String::from_utf8(bytes)
                .map_err(|e| io(std::io::Error::new(std::io::ErrorKind::InvalidData, e)))?
        };
        Self::parse(&text, path)
    }

    /// Parses recording text as if read from `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, HandError> {
        let bad = |message: String| HandError::BadRecording {
            path: path.to_owned(),
            message,
        };
        let raw: RawFile = serde_json::from_str(text)
            .map_err(|e| bad(format!("not a Leap recording (JSON with \"frames\"): {e}")))?;
        if let Some(version) = raw.metadata.as_ref().and_then(|m| m.protocol_version)
            && version < 6
        {
            return Err(bad(format!(
                "Leap protocol version {version}; versions 6 and later carry the finger joints this reads"
            )));
        }
        let mut frames = Vec::with_capacity(raw.frames.len());
        let mut t0 = None;
        let mut last_us = f64::NEG_INFINITY;
        for (i, f) in raw.frames.iter().enumerate() {
            let us = f
                .timestamp
                .filter(|t| t.is_finite())
                .ok_or_else(|| bad(format!("frame {i}: no finite \"timestamp\"")))?;
            if us <= last_us {
                return Err(bad(format!(
                    "frame {i}: timestamp {us} µs is not after the previous frame's {last_us} µs"
                )));
            }
            last_us = us;
            let t0 = *t0.get_or_insert(us);
            let mut hands = Vec::with_capacity(f.hands.len());
            let mut recorded_joints = Vec::with_capacity(f.hands.len());
            for h in &f.hands {
                let data = hand_data(h, &f.pointables)
                    .map_err(|m| bad(format!("frame {i}, {} hand {}: {m}", h.kind, h.id)))?;
                let mut joints = vec![data.palm];
                for digit in &data.digits {
                    joints.extend([digit[1].prev, digit[2].prev, digit[3].prev, digit[3].next]);
                }
                recorded_joints.push(joints);
                hands.push((h.id, data));
            }
            frames.push(LeapRecordedFrame {
                t_s: (us - t0) * 1e-6,
                hands,
                recorded_joints,
            });
        }
        if frames.iter().all(|f| f.hands.is_empty()) {
            return Err(HandError::Empty {
                path: path.to_owned(),
            });
        }
        let mut recording = Self {
            path: path.to_owned(),
            frames,
        };
        recording.make_bones_constant();
        Ok(recording)
    }

    /// Gives every bone of every hand its median length over the recording (module docs).
    fn make_bones_constant(&mut self) {
        let mut lengths: HashMap<(i64, usize, usize), Vec<f32>> = HashMap::new();
        for f in &self.frames {
            for (id, h) in &f.hands {
                for (d, digit) in h.digits.iter().enumerate() {
                    for (b, bone) in digit.iter().enumerate() {
                        lengths
                            .entry((*id, d, b))
                            .or_default()
                            .push((v(bone.next) - v(bone.prev)).norm());
                    }
                }
            }
        }
        let median: HashMap<(i64, usize, usize), f32> = lengths
            .into_iter()
            .map(|(k, mut l)| {
                l.sort_by(f32::total_cmp);
                (k, l[l.len() / 2])
            })
            .collect();
        for f in &mut self.frames {
            for (id, h) in &mut f.hands {
                for (d, digit) in h.digits.iter_mut().enumerate() {
                    // The metacarpal inwards from the knuckle.
                    let m = &mut digit[0];
                    let inward = v(m.prev) - v(m.next);
                    if let Some(dir) = inward.try_normalize(1e-6) {
                        m.prev = a(v(m.next) + dir * median[&(*id, d, 0)]);
                    }
                    // The phalanges outwards from the knuckle.
                    for b in 1..4 {
                        let start = v(digit[b - 1].next);
                        let along = v(digit[b].next) - v(digit[b].prev);
                        digit[b].prev = a(start);
                        if let Some(dir) = along.try_normalize(1e-6) {
                            digit[b].next = a(start + dir * median[&(*id, d, b)]);
                        } else {
                            digit[b].next = a(start);
                        }
                    }
                }
                // The wrist follows the metacarpal bases it is the mean of.
                let wrist = (1..5).map(|d| v(h.digits[d][0].prev)).sum::<Vector3<f32>>() / 4.0;
                let back = v(h.arm.prev) - v(h.arm.next);
                h.arm.next = a(wrist);
                h.arm.prev = a(wrist + back);
            }
        }
    }

    /// The frames of one hand (`hand`, or the first hand of the recording when `None`) in the
    /// scene through `mount`, on the recording's clock; frames where that hand is not tracked
    /// are left out (a tracker sends nothing then). Errors name the frame.
    pub fn hand_frames(
        &self,
        hand: Option<Handedness>,
        mount: &LeapMount,
    ) -> Result<Vec<HandFrame>, HandError> {
        let wanted = hand.or_else(|| {
            self.frames
                .iter()
                .find_map(|f| f.hands.first().map(|(_, h)| h.hand))
        });
        let mut out = Vec::with_capacity(self.frames.len());
        for (i, f) in self.frames.iter().enumerate() {
            let Some((_, data)) = f.hands.iter().find(|(_, h)| Some(h.hand) == wanted) else {
                continue;
            };
            let frame = leap_frame(data, mount, f.t_s).map_err(|e| HandError::BadRecording {
                path: self.path.clone(),
                message: format!("frame {i}: {e}"),
            })?;
            out.push(frame);
        }
        if out.is_empty() {
            return Err(HandError::BadRecording {
                path: self.path.clone(),
                message: format!(
                    "no {} hand in the recording",
                    match wanted {
                        Some(Handedness::Left) => "left",
                        _ => "right",
                    }
                ),
            });
        }
        Ok(out)
    }
}

/// One v6 hand and its fingers as [`LeapHandData`] (Leap frame, mm), inferring what is absent.
fn hand_data(h: &RawHand, pointables: &[RawPointable]) -> Result<LeapHandData, String> {
    let hand = match h.kind.as_str() {
        "left" => Handedness::Left,
        "right" => Handedness::Right,
        other => return Err(format!("type '{other}' is not left or right")),
    };
    let finite = |what: &str, p: &[f32; 3]| {
        if p.iter().all(|x| x.is_finite()) {
            Ok(())
        } else {
            Err(format!("{what} {p:?} is not finite"))
        }
    };
    finite("palmPosition", &h.palm_position)?;
    finite("palmNormal", &h.palm_normal)?;
    finite("direction", &h.direction)?;
    let direction = v(h.direction)
        .try_normalize(1e-6)
        .ok_or("direction has no length")?;
    const NAMES: [&str; 5] = ["thumb", "index", "middle", "ring", "pinky"];
    let mut digits = [[LeapBone {
        prev: [0.0; 3],
        next: [0.0; 3],
        width: 0.0,
    }; 4]; 5];
    for (d, name) in NAMES.iter().enumerate() {
        let p = pointables
            .iter()
            .find(|p| p.hand_id == h.id && !p.tool && p.kind == Some(d as i64))
            .ok_or_else(|| format!("no {name} (pointable of type {d})"))?;
        let joint = |what: &str, j: Option<[f32; 3]>| -> Result<Vector3<f32>, String> {
            let j = j.ok_or_else(|| format!("{name}: no {what}"))?;
            finite(&format!("{name} {what}"), &j)?;
            Ok(v(j))
        };
        let (mcp, pip, dip, tip) = (
            joint("mcpPosition", p.mcp)?,
            joint("pipPosition", p.pip)?,
            joint("dipPosition", p.dip)?,
            joint("tipPosition", p.tip)?,
        );
        if !(p.width.is_finite() && p.width > 0.0) {
            return Err(format!(
                "{name}: width {} is not a positive number",
                p.width
            ));
        }
        let carp = match (d, p.carp) {
            // Leap's thumb metacarpal has no length.
            (0, _) => mcp,
            (_, Some(c)) => joint("carpPosition", Some(c))?,
            (_, None) => mcp - direction * (pip - mcp).norm() * METACARPAL_RATIO[d - 1],
        };
        let bone = |prev: Vector3<f32>, next: Vector3<f32>| LeapBone {
            prev: a(prev),
            next: a(next),
            width: p.width,
        };
        digits[d] = [
            bone(carp, mcp),
            bone(mcp, pip),
            bone(pip, dip),
            bone(dip, tip),
        ];
    }
    let wrist = (1..5).map(|d| v(digits[d][0].prev)).sum::<Vector3<f32>>() / 4.0;
    Ok(LeapHandData {
        hand,
        palm: h.palm_position,
        palm_normal: h.palm_normal,
        arm: LeapBone {
            prev: a(wrist - direction * ARM_LENGTH_MM),
            next: a(wrist),
            width: digits[2][1].width * 3.0,
        },
        digits,
    })
}

#[cfg(test)]
mod tests {
    use avatarm_core::shared_data::shared_data;
    use avatarm_core::teleop::hand::JOINT_NAMES;

    use super::*;

    fn recordings() -> Option<Vec<PathBuf>> {
        match shared_data() {
            Ok(dir) => Some(
                ["grab", "pinch", "three-claps", "waiting-short"]
                    .iter()
                    .map(|n| dir.join(format!("real/leap/{n}.json.gz")))
                    .collect(),
            ),
            Err(why) => {
                eprintln!("skipped: {why}");
                None
            }
        }
    }

    /// The bone between two joints of a converted frame (mm).
    fn length_mm(f: &HandFrame, a: usize, b: usize) -> f64 {
        (f.joints[a].pose.translation.vector - f.joints[b].pose.translation.vector).norm() * 1e3
    }

    /// All four real recordings: frames in time order, left and right kept, unit orientations,
    /// and every bone of the converted skeleton within 2 mm of its median over the recording.
    #[test]
    fn real_recordings_convert_to_steady_skeletons() {
        let Some(paths) = recordings() else { return };
        for path in paths {
            let rec = LeapRecording::open(&path).unwrap_or_else(|e| panic!("{e}"));
            let name = path.display();
            assert!(rec.frames.windows(2).all(|w| w[1].t_s > w[0].t_s), "{name}");
            let sides: Vec<Handedness> = rec
                .frames
                .iter()
                .flat_map(|f| f.hands.iter().map(|(_, h)| h.hand))
                .collect();
            for side in [Handedness::Left, Handedness::Right] {
                if !sides.contains(&side) {
                    continue;
                }
                // In Leap's own axes and millimetres, to compare with the recorded joints.
                let leap = LeapMount {
                    scene_from_leap: nalgebra::Isometry3::identity(),
                };
                let frames = rec.hand_frames(Some(side), &leap).unwrap();
                assert!(frames.iter().all(|f| f.hand == side && f.tracked), "{name}");
                let recorded: Vec<&Vec<[f32; 3]>> = rec
                    .frames
                    .iter()
                    .filter_map(|f| {
                        let k = f.hands.iter().position(|(_, h)| h.hand == side)?;
                        Some(&f.recorded_joints[k])
                    })
                    .collect();
                assert_eq!(recorded.len(), frames.len());
                // Each finger's chain: metacarpal .. tip, 5 joints (4 for the thumb).
                let (mut worst, mut moved, mut off_axis) = (0.0f64, 0.0f64, 0.0f64);
                let mut start = 2;
                for (digit, len) in [4usize, 5, 5, 5, 5].into_iter().enumerate() {
                    // The recorded knuckle, joints and tip against the skeleton's: making the
                    // bones constant moves them only a little.
                    let first = if digit == 0 { start } else { start + 1 };
                    for (f, rec_joints) in frames.iter().zip(&recorded) {
                        for k in 0..4 {
                            let r = rec_joints[1 + 4 * digit + k];
                            let r = nalgebra::Vector3::new(
                                f64::from(r[0]),
                                f64::from(r[1]),
                                f64::from(r[2]),
                            ) * 1e-3;
                            let p = f.joints[first + k].pose.translation.vector;
                            moved = moved.max((p - r).norm() * 1e3);
                        }
                    }
                    for b in start..start + len - 1 {
                        // Each joint's +x runs along its bone toward the tip.
                        for f in &frames {
                            let along = f.joints[b + 1].pose.translation.vector
                                - f.joints[b].pose.translation.vector;
                            let x = f.joints[b].pose.rotation * nalgebra::Vector3::x();
                            off_axis = off_axis.max(x.angle(&along).to_degrees());
                        }
                        let mut l: Vec<f64> =
                            frames.iter().map(|f| length_mm(f, b, b + 1)).collect();
                        l.sort_by(f64::total_cmp);
                        let median = l[l.len() / 2];
                        for x in &l {
                            worst = worst.max((x - median).abs());
                        }
                    }
                    start += len;
                }
                assert_eq!(start, JOINT_NAMES.len());
                eprintln!(
                    "{name} {side:?}: bones within {worst:.3} mm of their medians, joints moved at most {moved:.2} mm from the recorded ones, +x at most {off_axis:.3}° off its bone"
                );
                assert!(
                    worst <= 2.0,
                    "{name} {side:?}: a bone strays {worst} mm from its median"
                );
                assert!(moved <= 10.0, "{name} {side:?}: a joint moved {moved} mm");
                assert!(
                    off_axis < 0.01,
                    "{name} {side:?}: +x {off_axis}° off its bone"
                );
            }
        }
    }

    /// The two-handed recording gives each hand on request; the default is the first seen.
    #[test]
    fn two_hands_are_told_apart() {
        let Some(paths) = recordings() else { return };
        let rec = LeapRecording::open(&paths[2]).unwrap();
        assert!(rec.frames.iter().all(|f| f.hands.len() == 2));
        let mount = LeapMount::default();
        let left = rec.hand_frames(Some(Handedness::Left), &mount).unwrap();
        let right = rec.hand_frames(Some(Handedness::Right), &mount).unwrap();
        assert_eq!(left.len(), right.len());
        // Leap's +x is the user's right; the default mount turns it to the scene's -y.
        let palm_y = |f: &HandFrame| f.joints[0].pose.translation.y;
        assert!(palm_y(&left[0]) > palm_y(&right[0]));
        let one = LeapRecording::open(&paths[0]).unwrap();
        let e = one
            .hand_frames(Some(Handedness::Left), &mount)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("grab.json.gz") && e.contains("no left hand"),
            "{e}"
        );
    }

    /// RMS distance (mm) of every joint from its own path smoothed by a centred moving average
    /// of ±`half` frames: the tremor and tracking noise of the hand.
    fn jitter_mm(frames: &[HandFrame], half: usize) -> f64 {
        let (mut sum, mut n) = (0.0, 0usize);
        for i in half..frames.len().saturating_sub(half) {
            for j in 0..frames[i].joints.len() {
                let mean = (i - half..=i + half)
                    .map(|k| frames[k].joints[j].pose.translation.vector)
                    .sum::<nalgebra::Vector3<f64>>()
                    / (2 * half + 1) as f64;
                sum += (frames[i].joints[j].pose.translation.vector - mean).norm_squared();
                n += 1;
            }
        }
        (sum / n.max(1) as f64).sqrt() * 1e3
    }

    /// The delay (s) that best aligns `filtered` with `raw`: the shift of the raw path, in 1 ms
    /// steps up to 200 ms, that minimises the RMS joint distance (raw interpolated linearly).
    fn lag_s(raw: &[HandFrame], filtered: &[HandFrame]) -> f64 {
        (0..=200)
            .map(|ms| {
                let shift = f64::from(ms) * 1e-3;
                let (mut sum, mut n) = (0.0, 0usize);
                for f in filtered {
                    let t = f.t_s - shift;
                    // The raw frames around t.
                    let k = raw.partition_point(|r| r.t_s <= t);
                    if k == 0 || k >= raw.len() {
                        continue;
                    }
                    let (a, b) = (&raw[k - 1], &raw[k]);
                    let s = (t - a.t_s) / (b.t_s - a.t_s).max(1e-9);
                    for j in 0..f.joints.len() {
                        let (pa, pb) = (
                            a.joints[j].pose.translation.vector,
                            b.joints[j].pose.translation.vector,
                        );
                        let p = pa + (pb - pa) * s;
                        sum += (f.joints[j].pose.translation.vector - p).norm_squared();
                        n += 1;
                    }
                }
                (shift, sum / n.max(1) as f64)
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(0.0, |(shift, _)| shift)
    }

    /// Real human motion through the hand filter: its jitter before and after, and the lag it
    /// adds (docs/hand.md). The filter must cut the jitter of the still hand and lag under
    /// 100 ms.
    #[test]
    fn the_hand_filter_on_real_motion() {
        let Some(paths) = recordings() else { return };
        for path in [&paths[3], &paths[0]] {
            let raw = LeapRecording::open(path)
                .unwrap()
                .hand_frames(None, &LeapMount::default())
                .unwrap();
            let mut filter = avatarm_core::teleop::hand::HandFilter::new(Default::default());
            let filtered: Vec<HandFrame> = raw
                .iter()
                .map(|f| {
                    let mut f = f.clone();
                    filter.apply(&mut f);
                    f
                })
                .collect();
            let rate = (raw.len() - 1) as f64 / (raw[raw.len() - 1].t_s - raw[0].t_s);
            let half = (0.05 * rate).round().max(1.0) as usize;
            let (before, after) = (jitter_mm(&raw, half), jitter_mm(&filtered, half));
            let lag = lag_s(&raw, &filtered);
            eprintln!(
                "{}: {} frames at {rate:.0} Hz; jitter {before:.3} mm raw, {after:.3} mm filtered; filter lag {:.0} ms",
                path.display(),
                raw.len(),
                lag * 1e3
            );
            assert!(after < before, "{}: {after} >= {before}", path.display());
            assert!(lag < 0.1, "{}: lag {lag}", path.display());
        }
    }

    /// A tracker whose phalanges change length between frames (real Leap v6 recordings do not:
    /// theirs measure 0.000 mm of spread): each bone ends at its median length, along the
    /// recorded direction, from the recorded knuckle.
    #[test]
    fn bones_that_change_length_are_made_constant() {
        let frame = |t: u32, stretch: f32| {
            let fingers: Vec<String> = (0..5)
                .map(|d| {
                    let x = 20.0 * d as f32;
                    let j = |k: f32| format!("[{x}, 200, {}]", -20.0 - k * stretch);
                    format!(
                        r#"{{"handId": 1, "type": {d}, "width": 18, "mcpPosition": {}, "pipPosition": {}, "dipPosition": {}, "tipPosition": {}}}"#,
                        j(0.0),
                        j(1.0),
                        j(2.0),
                        j(3.0)
                    )
                })
                .collect();
            format!(
                r#"{{"timestamp": {t}, "hands": [{{"id": 1, "type": "right", "palmPosition": [40, 200, 30], "palmNormal": [0, -1, 0], "direction": [0, 0, -1]}}], "pointables": [{}]}}"#,
                fingers.join(",")
            )
        };
        // Phalanges of 30, 34 and 31 mm: the median is 31.
        let text = format!(
            r#"{{"frames": [{}, {}, {}]}}"#,
            frame(0, 30.0),
            frame(10_000, 34.0),
            frame(20_000, 31.0)
        );
        let rec = LeapRecording::parse(&text, Path::new("stretchy.json")).unwrap();
        for f in &rec.frames {
            let h = &f.hands[0].1;
            for digit in &h.digits {
                for bone in &digit[1..] {
                    let length = (v(bone.next) - v(bone.prev)).norm();
                    assert!((length - 31.0).abs() < 1e-3, "{length}");
                }
                // From the recorded knuckle, which does not move.
                assert_eq!(digit[1].prev[2], -20.0);
            }
        }
    }

    #[test]
    fn bad_recordings_are_named() {
        let path = Path::new("x.json");
        let frame = |t: &str, extra: &str| {
            format!(
                r#"{{"timestamp": {t}, "hands": [{{"id": 1, "type": "right", "palmPosition": [0, 200, 0], "palmNormal": [0, -1, 0], "direction": [0, 0, -1]}}], "pointables": [{extra}]}}"#
            )
        };
        let e = LeapRecording::parse("{}", path).unwrap_err().to_string();
        assert!(e.contains("x.json") && e.contains("frames"), "{e}");
        let e = LeapRecording::parse(&format!(r#"{{"frames": [{}]}}"#, frame("1", "")), path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("frame 0, right hand 1: no thumb"), "{e}");
        let e = LeapRecording::parse(r#"{"frames": [{"timestamp": 2}, {"timestamp": 1}]}"#, path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("frame 1: timestamp 1 µs is not after"), "{e}");
        let e = LeapRecording::parse(
            r#"{"metadata": {"protocolVersion": 3}, "frames": []}"#,
            path,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("protocol version 3"), "{e}");
        let e = LeapRecording::parse(r#"{"frames": [{"timestamp": 1}]}"#, path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no hand frames"), "{e}");
    }
}
