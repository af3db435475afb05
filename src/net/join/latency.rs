//! The erased video's latency by stage, as `join` measures it from each frame's stamps.

use avatarm_core::stats::Spread;
use avatarm_net::msg::FrameHeader;
use serde::{Deserialize, Serialize};

/// Latency of the erased video by stage (ms, robot clock): captured → arrived in the robot
/// site's app → erased (read back) → sent → received → decoded; and the robot site's app
/// updates each frame waited between arriving and being handed to the encoder.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct VideoLatency {
    /// Frames received.
    pub frames: u64,
    /// The codec of the last frame (`jpeg` or `h264`).
    pub codec: String,
    /// Frames refused (bad header or image).
    pub refused: u64,
    /// Frames decoded and shown.
    pub shown: u64,
    /// Keyframes received.
    pub keyframes: u64,
    /// H.264 frames not shown for want of a keyframe (joined mid-stream, or a frame they
    /// refer to was lost).
    pub waiting_for_keyframe: u64,
    /// Keyframes asked of the robot site.
    pub keyframe_requests: u64,
    /// Frame numbers missing from the stream (lost on the way).
    pub lost: u64,
    /// H.264 frames just older than one already shown (reordered or duplicated), dropped.
    pub stale: u64,
    /// Coded bytes received.
    pub bytes: u64,
    /// Frames received per second.
    pub fps: f64,
    /// Bit rate (Mbit/s).
    pub mbit_s: f64,
    /// Capture → erased (read back).
    pub erase_ms: Spread,
    /// Capture → arrived in the robot site's app (the camera's driver, the player or the
    /// simulated camera's latency and read-back).
    pub arrive_ms: Spread,
    /// Arrived → erased and read back (the robot site's app).
    pub app_ms: Spread,
    /// Frames by the robot site's app updates they waited between arriving and being handed
    /// to the encoder: `[0]` handed over in the update they arrived in, `[1]` in the next, ...,
    /// the last entry counting those that waited that long or longer.
    pub waited_updates: Vec<u64>,
    /// The most updates a frame waited.
    pub waited_updates_max: u64,
    /// Frames whose robot-site stamps are out of the stages' order (captured, arrived, erased,
    /// sent): a clock or stamping fault at the robot site; 0.
    pub stamps_out_of_order: u64,
    /// Erased → coded and sent.
    pub encode_ms: Spread,
    /// Sent → received (the network).
    pub network_ms: Spread,
    /// Decoding here.
    pub decode_ms: Spread,
    /// Capture → decoded here (glass to glass but the display).
    pub total_ms: Spread,
    /// How far the frames' cameras moved from the first frame's (a camera on a head): the
    /// largest rotation (degrees) and translation (mm).
    pub camera_turned_deg: f64,
    /// The largest translation (mm).
    pub camera_moved_mm: f64,
}

/// [`VideoLatency::waited_updates`]' entries: 0 to 7 updates, then 8 or more.
const WAITED_UPDATES_KEPT: usize = 9;

/// The shown frames' stages (ms), for [`VideoLatency`].
#[derive(Default)]
pub(super) struct Stages {
    pub(super) erase: Vec<f64>,
    pub(super) arrive: Vec<f64>,
    pub(super) in_app: Vec<f64>,
    pub(super) encode: Vec<f64>,
    pub(super) network: Vec<f64>,
    pub(super) decode: Vec<f64>,
    pub(super) total: Vec<f64>,
}

impl Stages {
    /// A shown frame's stages (its header's stamps, received (s, robot clock), decoding here)
    /// into `video`'s counts.
    /// Returns the frame's capture → decoded (ms).
    pub(super) fn note(
        &mut self,
        video: &mut VideoLatency,
        h: &FrameHeader,
        received: f64,
        decode_ms: f64,
    ) -> f64 {
        video.shown += 1;
        if !(h.capture_s <= h.arrived_s && h.arrived_s <= h.erased_s && h.erased_s <= h.sent_s) {
            video.stamps_out_of_order += 1;
        }
        Spread::push(&mut self.erase, (h.erased_s - h.capture_s) * 1e3);
        Spread::push(&mut self.arrive, (h.arrived_s - h.capture_s) * 1e3);
        Spread::push(&mut self.in_app, (h.erased_s - h.arrived_s) * 1e3);
        let waited = h.handed_update.saturating_sub(h.arrived_update);
        let bucket = (waited as usize).min(WAITED_UPDATES_KEPT - 1);
        if video.waited_updates.len() <= bucket {
            video.waited_updates.resize(bucket + 1, 0);
        }
        video.waited_updates[bucket] += 1;
        video.waited_updates_max = video.waited_updates_max.max(waited);
        Spread::push(&mut self.encode, (h.sent_s - h.erased_s) * 1e3);
        Spread::push(&mut self.network, (received - h.sent_s) * 1e3);
        Spread::push(&mut self.decode, decode_ms);
        let total = (received - h.capture_s) * 1e3 + decode_ms;
        Spread::push(&mut self.total, total);
        total
    }
}
