//! Alice's head at the operator's site: the poses a headset or a recording gives, sent to the robot
//! site at a steady rate (`camera/NAME/head`), and what the report says of them.

use super::*;

/// What this site sent of the head its viewed camera rides on.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct HeadReport {
    /// The camera.
    pub camera: String,
    /// `headset` (`--xr`) or `recording` (`--head FILE.mcap`).
    pub source: String,
    /// Poses sent.
    pub sent: u64,
    /// Poses the network refused.
    pub failed: u64,
    /// How far the head turned from the first pose sent (degrees, largest).
    pub turned_deg: f64,
    /// How far it moved from the first pose sent (mm, largest).
    pub moved_mm: f64,
}

/// Where the head of this site's camera on a head comes from.
#[derive(Debug, Clone)]
pub enum HeadSource {
    /// The headset (`--xr`): the scene's live head, which the window's XR session feeds.
    Headset(avatarm_core::vision::head::LiveHead),
    /// A recording's tracked head poses (`--head FILE.mcap`, `base_from_head`), played from
    /// the join on in real time; after the last, the head holds it.
    Recorded(Vec<avatarm_record::HeadPose>),
}

/// The most head poses sent a second: a headset's tracking rate.
pub(super) const HEAD_RATE_HZ: f64 = 90.0;

/// Sends the head of this site's camera on a head to the robot site, which draws that
/// camera's mask from it ([`avatarm_net::msg::HeadPoseMsg`]). Each pose is stamped when this
/// site takes it (the headset's newest, up to a window frame and a control tick late; a
/// recording's at its moment in the playback).
pub(super) struct HeadSender {
    pub(super) source: HeadSource,
    /// The robot's base in the scene's world (`world_from_base`: a recording's poses are in
    /// the base frame).
    pub(super) world_from_base: nalgebra::Isometry3<f64>,
    pub(super) started: Instant,
    pub(super) last_sent: Option<Instant>,
    /// The headset's poses taken when the last was sent.
    pub(super) taken: u64,
    pub(super) first: Option<nalgebra::Isometry3<f64>>,
    pub(super) report: HeadReport,
}

impl HeadSender {
    pub(super) fn new(source: HeadSource, camera: String, scene: &Scene) -> Self {
        let name = match source {
            HeadSource::Headset(_) => "headset",
            HeadSource::Recorded(_) => "recording",
        };
        Self {
            source,
            world_from_base: scene.robot_base(),
            started: Instant::now(),
            last_sent: None,
            taken: 0,
            first: None,
            report: HeadReport {
                camera,
                source: name.into(),
                ..HeadReport::default()
            },
        }
    }

    /// Sends the head's newest pose if one is due, stamped `robot_now` (the robot's clock).
    pub(super) fn send(&mut self, site: &OperatorSite, robot_now: f64) {
        let now = Instant::now();
        if self
            .last_sent
            .is_some_and(|t| (now - t).as_secs_f64() < 1.0 / HEAD_RATE_HZ)
        {
            return;
        }
        let pose = match &self.source {
            HeadSource::Headset(live) => {
                let taken = live.poses();
                if taken == self.taken {
                    return; // nothing new from the headset
                }
                self.taken = taken;
                live.latest().map(|(_, p)| p)
            }
            HeadSource::Recorded(poses) => {
                let first_ns = poses.first().map_or(0, |p| p.stamp_ns);
                let at = first_ns.saturating_add(self.started.elapsed().as_nanos() as u64);
                avatarm_record::head_at(poses, at).map(|p| self.world_from_base * p)
            }
        };
        let Some(world_from_head) = pose else { return };
        self.last_sent = Some(now);
        let m = avatarm_net::msg::HeadPoseMsg {
            v: PROTOCOL_VERSION,
            stamp_s: robot_now,
            camera: self.report.camera.clone(),
            pose: avatarm_net::msg::FrameHeader::pose_of(&world_from_head),
        };
        match site.publish_head(&m) {
            Ok(()) => {
                self.report.sent += 1;
                let first = *self.first.get_or_insert(world_from_head);
                let (angle, offset) =
                    avatarm_core::vision::head::pose_error(&world_from_head, &first);
                self.report.turned_deg = self.report.turned_deg.max(angle.to_degrees());
                self.report.moved_mm = self.report.moved_mm.max(offset * 1e3);
            }
            Err(e) => {
                if self.report.failed == 0 {
                    warn!("head: {e}");
                }
                self.report.failed += 1;
            }
        }
    }
}
