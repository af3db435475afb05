//! One pass over a bag's messages, whatever its container, into the recording: the topics
//! picked, each message decoded by its [`Dialect`] and kept, then the recording written.

use std::collections::BTreeMap;
use std::path::Path;

use avatarm_core::tf::{FrameLink, chain};
use avatarm_record::camera::{CameraCalibration, read_calibration, read_pose};
use avatarm_record::{CompressedFrame, JointStates, RecordingWriter};
use nalgebra::Isometry3;

use super::messages::{
    CameraInfo, CompressedImage, Image, JointState, Stamped, TfMessage, as_silhouette,
    compressed_frame, raw_frame, size_of,
};
use super::{BagOptions, BagSummary, Dialect, bag_error, pick};
use crate::FootageError;

/// The topics picked and what their messages gave so far.
pub(super) struct Importer<'a, D: Dialect> {
    o: &'a BagOptions,
    format: String,
    /// Every topic: its type.
    topics: BTreeMap<String, String>,
    image_topic: String,
    mask_topic: Option<String>,
    info_topic: Option<String>,
    joints_topic: String,
    counts: BTreeMap<String, usize>,
    frames: Vec<CompressedFrame>,
    masks: Vec<CompressedFrame>,
    image_frame: String,
    info: Option<CameraInfo<D::Header>>,
    skipped_states: usize,
    bad_links: Vec<String>,
    states: Vec<JointStates>,
    links: Vec<FrameLink>,
}

impl<'a, D: Dialect> Importer<'a, D> {
    /// Picks the topics among the bag's (`topics`: topic -> type) as `o` asks; `format` names
    /// the container in the summary.
    pub(super) fn new(
        o: &'a BagOptions,
        format: impl Into<String>,
        topics: BTreeMap<String, String>,
    ) -> Result<Self, FootageError> {
        let path = o.bag.as_path();
        let t = D::TYPES;
        let images = [t.image, t.compressed];
        // The mask topic is not a candidate for the frames.
        let mut candidates = topics.clone();
        if let Some(m) = &o.mask_topic {
            candidates.remove(m);
        }
        let image_topic = pick(
            path,
            &candidates,
            o.image_topic.as_deref(),
            &images,
            "--image-topic",
            true,
        )?
        .unwrap_or_default()
        .to_owned();
        let mask_topic = match &o.mask_topic {
            Some(m) => {
                pick(path, &topics, Some(m), &images, "--mask-topic", true)?.map(str::to_owned)
            }
            None => None,
        };
        // With --camera the bag's CameraInfo is not read (a RealSense bag has several).
        let info_topic = if o.camera.is_some() {
            None
        } else {
            pick(
                path,
                &topics,
                o.camera_info_topic.as_deref(),
                &[t.camera_info],
                "--camera-info-topic",
                true,
            )?
            .map(str::to_owned)
        };
        let joints_topic = pick(
            path,
            &topics,
            o.joint_states_topic.as_deref(),
            &[t.joint_state],
            "--joint-states-topic",
            true,
        )?
        .unwrap_or_default()
        .to_owned();
        Ok(Self {
            o,
            format: format.into(),
            topics,
            image_topic,
            mask_topic,
            info_topic,
            joints_topic,
            counts: BTreeMap::new(),
            frames: Vec::new(),
            masks: Vec::new(),
            image_frame: String::new(),
            info: None,
            skipped_states: 0,
            bad_links: Vec::new(),
            states: Vec::new(),
            links: Vec::new(),
        })
    }

    fn path(&self) -> &Path {
        &self.o.bag
    }

    /// One message on `topic` (serialised as the dialect's), received at `received_ns`.
    pub(super) fn message(
        &mut self,
        topic: &str,
        data: &[u8],
        received_ns: u64,
    ) -> Result<(), FootageError> {
        let n = self.counts.entry(topic.to_owned()).or_default();
        let at = format!("{topic}, message {}", *n);
        *n += 1;
        let kind = self.topics.get(topic).cloned().unwrap_or_default();
        let t = D::TYPES;
        let fail = |message: String| bag_error(&self.o.bag, message);
        let decode = |e: String| fail(format!("{at}: not a {kind}: {e}"));
        let is_mask = self.mask_topic.as_deref() == Some(topic);
        if topic == self.image_topic || is_mask {
            let (frame, frame_id) = if kind == t.compressed {
                let m: CompressedImage<D::Header> = D::decode(data).map_err(decode)?;
                compressed_frame(m, &at, received_ns)
            } else {
                let m: Image<D::Header> = D::decode(data).map_err(decode)?;
                raw_frame(m, &at, received_ns)
            }
            .map_err(fail)?;
            if is_mask {
                self.masks.push(as_silhouette(frame, &at).map_err(fail)?);
            } else {
                if self.image_frame.is_empty() {
                    self.image_frame = frame_id;
                }
                self.frames.push(frame);
            }
        } else if Some(topic) == self.info_topic.as_deref() {
            let m: CameraInfo<D::Header> = D::decode(data).map_err(decode)?;
            if self.info.is_none() {
                self.info = Some(m);
            }
        } else if topic == self.joints_topic {
            let s: JointState<D::Header> = D::decode(data).map_err(decode)?;
            if let Some(s) = joint_states(s, &at, received_ns).map_err(fail)? {
                self.states.push(s);
            } else {
                self.skipped_states += 1;
            }
        } else if kind == t.tf {
            // A transform message that does not decode fails the import only where the pose
            // is chained from /tf; otherwise it is left out and said.
            let tf: TfMessage<D::Header> = match D::decode(data) {
                Ok(tf) => tf,
                Err(e) if self.o.pose.is_some() || self.o.base_frame.is_none() => {
                    self.bad_links.push(format!("{at}: not a {kind}: {e}"));
                    return Ok(());
                }
                Err(e) => return Err(decode(e)),
            };
            let is_static = topic == "/tf_static";
            for t in tf.transforms {
                let (p, q) = (&t.transform.translation, &t.transform.rotation);
                let stamp = if is_static {
                    0
                } else {
                    t.header.stamp_ns(received_ns)
                };
                // A bad transform is left out, and said if the pose needed its link.
                match FrameLink::new(
                    t.header.frame_id(),
                    &t.child_frame_id,
                    stamp,
                    [p.x, p.y, p.z],
                    [q.x, q.y, q.z, q.w],
                ) {
                    Ok(link) => self.links.push(link),
                    Err(what) => self.bad_links.push(format!("{at}: {what}")),
                }
            }
        }
        Ok(())
    }

    /// The frames checked (stamps, sizes), the calibration and the pose found, the recording
    /// written to `o.out`.
    pub(super) fn finish(mut self) -> Result<BagSummary, FootageError> {
        let image_topic = self.image_topic.clone();
        if self.frames.is_empty() {
            return Err(bag_error(
                self.path(),
                format!("{image_topic} has no messages"),
            ));
        }
        self.frames.sort_by_key(|f| f.stamp_ns);
        if let Some(w) = self
            .frames
            .windows(2)
            .find(|w| w[0].stamp_ns == w[1].stamp_ns)
        {
            return Err(bag_error(
                self.path(),
                format!(
                    "{image_topic}: two frames share the stamp {} ns",
                    w[0].stamp_ns
                ),
            ));
        }
        let size = self.check_sizes()?;
        if self.states.is_empty() {
            return Err(bag_error(
                self.path(),
                format!("{} has no messages", self.joints_topic),
            ));
        }
        self.states.sort_by_key(|s| s.stamp_ns);
        let (calibration, camera_frame) = self.calibration(size)?;
        let t0 = self.frames[0].stamp_ns;
        let (pose, pose_source) = self.pose(camera_frame, t0)?;
        let mut out = RecordingWriter::create(&self.o.out)?;
        out.calibration(t0, &calibration)?;
        if let Some(p) = &pose {
            out.camera_pose(t0, p)?;
        }
        for f in &self.frames {
            out.frame(f)?;
        }
        for m in &self.masks {
            out.reference_mask(m)?;
        }
        for s in &self.states {
            out.joint_states(s)?;
        }
        out.finish()?;
        let mut names: Vec<String> = Vec::new();
        for s in &self.states {
            for n in &s.names {
                if !names.contains(n) {
                    names.push(n.clone());
                }
            }
        }
        let listed: Vec<(String, String, usize)> = self
            .topics
            .iter()
            .map(|(t, k)| {
                (
                    t.clone(),
                    k.clone(),
                    self.counts.get(t).copied().unwrap_or(0),
                )
            })
            .collect();
        let mut notes = Vec::new();
        if self.skipped_states > 0 {
            notes.push(format!(
                "{} joint states on {} had no positions and were left out",
                self.skipped_states, self.joints_topic
            ));
        }
        if !self.bad_links.is_empty() {
            notes.push(format!(
                "transforms left out (not finite, not unit, or not decoded): {}",
                self.bad_links.join("; ")
            ));
        }
        Ok(BagSummary {
            frames: self.frames.len(),
            masks: self.masks.len(),
            joint_states: self.states.len(),
            size,
            duration_s: (self.frames[self.frames.len() - 1].stamp_ns - t0) as f64 * 1e-9,
            joints: names,
            pose: pose_source,
            format: self.format,
            topics: listed,
            notes,
        })
    }

    /// Every frame and mask the first frame's size (read from the headers alone).
    fn check_sizes(&self) -> Result<(u32, u32), FootageError> {
        let image_topic = &self.image_topic;
        let size = size_of(&self.frames[0], &format!("{image_topic}, the first frame"))
            .map_err(|m| bag_error(self.path(), m))?;
        let masks_topic = self.mask_topic.clone().unwrap_or_default();
        let frames_at = self
            .frames
            .iter()
            .enumerate()
            .map(|(i, f)| (image_topic, i, f));
        let masks_at = self
            .masks
            .iter()
            .enumerate()
            .map(|(i, f)| (&masks_topic, i, f));
        for (topic, i, f) in frames_at.chain(masks_at) {
            let at = format!("{topic}, message {i}");
            let s = size_of(f, &at).map_err(|m| bag_error(self.path(), m))?;
            if s != size {
                return Err(bag_error(
                    self.path(),
                    format!(
                        "{at}: {}x{}, the first frame {}x{}",
                        s.0, s.1, size.0, size.1
                    ),
                ));
            }
        }
        Ok(size)
    }

    /// The calibration (`--camera` or CameraInfo) and the camera's frame the pose chains to
    /// (CameraInfo's, the optical frame; else the frames').
    fn calibration(
        &mut self,
        size: (u32, u32),
    ) -> Result<(CameraCalibration, String), FootageError> {
        let info_topic = self.info_topic.clone().unwrap_or_default();
        let mut camera_frame = String::new();
        let calibration = match (&self.o.camera, self.info.take()) {
            (Some(file), _) => read_calibration(file, Some(size))?,
            (None, Some(i)) => {
                i.header.frame_id().clone_into(&mut camera_frame);
                let c = CameraCalibration::from_camera_info(
                    i.width,
                    i.height,
                    i.k,
                    &i.distortion_model,
                    i.d,
                )
                .map_err(|m| bag_error(self.path(), format!("{info_topic}: {}", m.0)))?;
                if (c.width, c.height) != size {
                    return Err(bag_error(
                        self.path(),
                        format!(
                            "{info_topic}: the calibration is for {}x{} images, the frames are {}x{}",
                            c.width, c.height, size.0, size.1
                        ),
                    ));
                }
                c
            }
            (None, None) => {
                return Err(bag_error(
                    self.path(),
                    format!("{info_topic} has no messages: give --camera FILE"),
                ));
            }
        };
        if camera_frame.is_empty() {
            camera_frame.clone_from(&self.image_frame);
        }
        Ok((calibration, camera_frame.trim_start_matches('/').to_owned()))
    }

    /// `base_from_camera` (`--pose`, or chained through `/tf` from `--base-frame` at the
    /// first frame's stamp `t0`) and where it came from.
    fn pose(
        &self,
        camera_frame: String,
        t0: u64,
    ) -> Result<(Option<Isometry3<f64>>, String), FootageError> {
        Ok(match (&self.o.pose, &self.o.base_frame) {
            (Some(file), _) => (Some(read_pose(file)?), format!("--pose {}", file.display())),
            (None, Some(base)) => {
                if camera_frame.is_empty() {
                    return Err(FootageError::input(
                        "--base-frame",
                        "the camera's frames have no frame_id to chain the pose to",
                    ));
                }
                let base = base.trim_start_matches('/');
                let pose = chain(&self.links, base, &camera_frame, t0).ok_or_else(|| {
                    let frames = avatarm_core::tf::frames(&self.links);
                    let left_out = if self.bad_links.is_empty() {
                        String::new()
                    } else {
                        format!(
                            "; left out as not finite or not unit: {}",
                            self.bad_links.join("; ")
                        )
                    };
                    FootageError::input(
                        "--base-frame",
                        format!(
                            "/tf does not connect {base} to the camera's frame {camera_frame} (frames in /tf and /tf_static: {}){left_out}",
                            frames.join(", ")
                        ),
                    )
                })?;
                (Some(pose), format!("/tf: {base} -> {camera_frame}"))
            }
            (None, None) if !self.links.is_empty() => (
                None,
                format!("not written: give --base-frame to chain it from /tf to {camera_frame}"),
            ),
            (None, None) => (
                None,
                "not in the bag (avatarm calibrate can find it)".to_owned(),
            ),
        })
    }
}

/// A joint state with positions (`None`: efforts or velocities alone, which the message
/// allows), its velocities kept where there is one finite value per joint.
fn joint_states<H: Stamped>(
    s: JointState<H>,
    at: &str,
    received_ns: u64,
) -> Result<Option<JointStates>, String> {
    if s.position.is_empty() {
        return Ok(None);
    }
    if s.position.len() != s.name.len() {
        return Err(format!(
            "{at}: {} positions for {} names",
            s.position.len(),
            s.name.len()
        ));
    }
    if let Some((name, v)) = s.name.iter().zip(&s.position).find(|(_, v)| !v.is_finite()) {
        return Err(format!("{at}: joint '{name}': {v} is not finite"));
    }
    let velocities = if s.velocity.len() == s.name.len() && s.velocity.iter().all(|v| v.is_finite())
    {
        s.velocity
    } else {
        Vec::new()
    };
    Ok(Some(JointStates {
        stamp_ns: s.header.stamp_ns(received_ns),
        names: s.name,
        positions: s.position,
        velocities,
    }))
}
