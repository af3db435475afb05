//! The erased video's codecs: JPEG (the default: each frame stands alone and survives loss) and
//! H.264 (Constrained Baseline, Cisco's OpenH264 through the `openh264` crate: a fraction of
//! JPEG's bandwidth, but a lost frame spoils the ones that refer to it until the next IDR).
//!
//! Both take and give RGBA8 images (row-major, 4 bytes a pixel, the read-back's layout).
//!
//! H.264 loss handling, as WebRTC does it: the stream has an IDR frame every
//! [`EncoderSettings::keyframe_interval_s`] and on request ([`VideoEncoder::encode`]'s
//! `force_keyframe`, which the robot site sets when a viewer asks on the camera's `keyframe`
//! key). A viewer's [`VideoDecoder`] follows the stream's frame numbers
//! ([`crate::msg::FrameHeader::seq`]); after a gap, a frame it cannot decode or a late join it
//! shows nothing (rather than a smeared picture) until the next IDR frame, and says so with
//! [`Decoded::NeedKeyframe`] so that the viewer can ask for one.

use image::ImageEncoder;
use openh264::decoder::Decoder;
use openh264::encoder::{
    BitRate, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, Profile,
    RateControlMode, UsageType,
};
use openh264::formats::{RgbaSliceU8, YUVBuffer, YUVSource};
use openh264::{OpenH264API, Timestamp};

use crate::NetError;
use crate::msg::{Codec, FrameHeader};

/// A JPEG encoder: the same format and quality scale, not the same speed (`avatarm bench
/// video` measures both; docs/latency.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum JpegEncoder {
    /// `jpeg-encoder`, with its SIMD paths (AVX2, chosen at run time where the CPU has it).
    #[default]
    Simd,
    /// The `image` crate's encoder (scalar): the baseline it was measured against.
    Image,
}

impl JpegEncoder {
    /// Its name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Simd => "jpeg-encoder (SIMD)",
            Self::Image => "image",
        }
    }
}

/// How the robot site codes its video.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EncoderSettings {
    /// The codec.
    pub codec: Codec,
    /// JPEG quality (1..=100).
    pub jpeg_quality: u8,
    /// Which JPEG encoder codes the frames.
    pub jpeg_encoder: JpegEncoder,
    /// H.264 target bit rate (bit/s; OpenH264's bit-rate mode).
    pub bitrate_bps: u32,
    /// The frame rate the H.264 rate control plans for (Hz): the camera's.
    pub fps: f32,
    /// The longest time between two H.264 IDR frames (s): one is forced when this long has
    /// passed since the last (viewers' requests bring one sooner).
    pub keyframe_interval_s: f64,
}

impl Default for EncoderSettings {
    fn default() -> Self {
        Self {
            codec: Codec::Jpeg,
            jpeg_quality: 85,
            jpeg_encoder: JpegEncoder::Simd,
            bitrate_bps: 2_000_000,
            fps: 30.0,
            keyframe_interval_s: 2.0,
        }
    }
}

impl EncoderSettings {
    /// Checks every field; the error names the setting.
    pub fn validate(&self) -> Result<(), NetError> {
        let bad = |what: &str, message: String| {
            Err(NetError::Config {
                what: what.into(),
                message,
            })
        };
        if !(1..=100).contains(&self.jpeg_quality) {
            return bad(
                "--jpeg-quality",
                format!("{} must be 1..=100", self.jpeg_quality),
            );
        }
        if !(10_000..=200_000_000).contains(&self.bitrate_bps) {
            return bad(
                "--bitrate",
                format!("{} bit/s must be 10 kbit/s..=200 Mbit/s", self.bitrate_bps),
            );
        }
        if !(self.fps.is_finite() && (1.0..=240.0).contains(&self.fps)) {
            return bad("fps", format!("{} Hz must be 1..=240", self.fps));
        }
        if !(self.keyframe_interval_s.is_finite()
            && (0.1..=600.0).contains(&self.keyframe_interval_s))
        {
            return bad(
                "--keyframe-interval",
                format!("{} s must be 0.1..=600", self.keyframe_interval_s),
            );
        }
        Ok(())
    }
}

/// One coded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodedFrame {
    /// The coded bytes (a JPEG file, or one H.264 access unit in Annex B).
    pub bytes: Vec<u8>,
    /// It decodes on its own (JPEG always; H.264 IDR).
    pub keyframe: bool,
    /// Its number in the stream (from 0).
    pub seq: u64,
    /// The stream's identity (one per encoder: a restarted robot site starts another).
    pub stream: u64,
}

enum EncoderKind {
    Jpeg,
    H264(Box<Encoder>),
}

/// Codes one camera's frames, in order.
pub struct VideoEncoder {
    settings: EncoderSettings,
    kind: EncoderKind,
    seq: u64,
    stream: u64,
    last_keyframe_s: Option<f64>,
}

impl std::fmt::Debug for VideoEncoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VideoEncoder")
            .field("settings", &self.settings)
            .field("seq", &self.seq)
            .finish_non_exhaustive()
    }
}

fn codec_error(what: &str, message: impl std::fmt::Display) -> NetError {
    NetError::Invalid {
        what: what.into(),
        message: message.to_string(),
    }
}

/// Checks an RGBA8 image's size against its buffer: `width * height * 4` bytes, both sides
/// 1..=8192, and even for H.264 (its 4:2:0 chroma is half the size each way).
fn check_image(codec: Codec, rgba: &[u8], width: u32, height: u32) -> Result<(), NetError> {
    let sides = (1..=8192).contains(&width) && (1..=8192).contains(&height);
    let even = codec != Codec::H264 || (width.is_multiple_of(2) && height.is_multiple_of(2));
    if !sides || !even || rgba.len() != width as usize * height as usize * 4 {
        return Err(codec_error(
            "frame to encode",
            format!(
                "{width}x{height} with {} bytes (RGBA8: width*height*4 bytes, sides 1..=8192{})",
                rgba.len(),
                if codec == Codec::H264 {
                    ", even for h264"
                } else {
                    ""
                }
            ),
        ));
    }
    Ok(())
}

/// One RGBA8 frame (checked: `width * height * 4` bytes) as a baseline JPEG at `quality`.
fn encode_jpeg(
    encoder: JpegEncoder,
    quality: u8,
    rgba: &[u8],
    width: u32,
    height: u32,
) -> Result<Vec<u8>, NetError> {
    let mut bytes = Vec::new();
    match encoder {
        JpegEncoder::Simd => {
            let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
                return Err(codec_error(
                    "jpeg encoder",
                    format!("{width}x{height} is larger than JPEG's 65535x65535"),
                ));
            };
            let mut jpeg = jpeg_encoder::Encoder::new(&mut bytes, quality);
            // Full-resolution colour (4:4:4), as the `image` crate's encoder codes it: the
            // same picture for the same quality, faster (`avatarm bench video`).
            jpeg.set_sampling_factor(jpeg_encoder::SamplingFactor::R_4_4_4);
            jpeg.encode(rgba, w, h, jpeg_encoder::ColorType::Rgba)
                .map_err(|e| codec_error("jpeg encoder", e))?;
        }
        JpegEncoder::Image => {
            let rgb: Vec<u8> = rgba
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality)
                .write_image(&rgb, width, height, image::ExtendedColorType::Rgb8)
                .map_err(|e| codec_error("jpeg encoder", e))?;
        }
    }
    Ok(bytes)
}

impl VideoEncoder {
    /// An encoder with these settings. Errors name the setting, or OpenH264's refusal.
    pub fn new(settings: EncoderSettings) -> Result<Self, NetError> {
        settings.validate()?;
        let kind = match settings.codec {
            Codec::Jpeg => EncoderKind::Jpeg,
            Codec::H264 => {
                // One IDR at the start, the rest when `encode` forces them (on time or on a
                // viewer's request): no IDR frames of OpenH264's own on scene changes. It holds
                // the bit rate only if it may skip frames.
                let config = EncoderConfig::new()
                    .scene_change_detect(false)
                    .profile(Profile::Baseline)
                    .usage_type(UsageType::CameraVideoRealTime)
                    .rate_control_mode(RateControlMode::Bitrate)
                    .bitrate(BitRate::from_bps(settings.bitrate_bps))
                    .max_frame_rate(FrameRate::from_hz(settings.fps))
                    .skip_frames(true)
                    .intra_frame_period(IntraFramePeriod::from_num_frames(0));
                let encoder = Encoder::with_api_config(OpenH264API::from_source(), config)
                    .map_err(|e| codec_error("h264 encoder", e))?;
                EncoderKind::H264(Box::new(encoder))
            }
        };
        // Any value that differs between two encoders: the clock's nanoseconds and the
        // process id, mixed, below MAX_SEQ.
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        let stream = (nanos ^ (u64::from(std::process::id()) << 32)) % crate::msg::MAX_SEQ;
        Ok(Self {
            settings,
            kind,
            seq: 0,
            stream,
            last_keyframe_s: None,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &EncoderSettings {
        &self.settings
    }

    /// Codes one RGBA8 frame captured at `now_s` (s, any clock that only goes forward); an
    /// H.264 frame is an IDR frame when `force_keyframe`, when it is the first, or when the
    /// keyframe interval has passed. The rate control plans with the frames' real times
    /// (`now_s`), not the nominal frame rate. `Ok(None)`: H.264's rate control skipped the
    /// frame to hold the bit rate (only ever a P frame; viewers keep showing the one before).
    /// Errors for a buffer that does not match its size, or a frame the codec refuses
    /// (OpenH264 takes 16x16 up to 3840x2160); the stream's numbering goes on only for frames
    /// coded.
    pub fn encode(
        &mut self,
        rgba: &[u8],
        width: u32,
        height: u32,
        now_s: f64,
        force_keyframe: bool,
    ) -> Result<Option<EncodedFrame>, NetError> {
        check_image(self.settings.codec, rgba, width, height)?;
        let (bytes, keyframe) = match &mut self.kind {
            EncoderKind::Jpeg => (
                encode_jpeg(
                    self.settings.jpeg_encoder,
                    self.settings.jpeg_quality,
                    rgba,
                    width,
                    height,
                )?,
                true,
            ),
            EncoderKind::H264(encoder) => {
                let due = self
                    .last_keyframe_s
                    .is_none_or(|t| now_s - t >= self.settings.keyframe_interval_s || now_s < t);
                if force_keyframe || due {
                    encoder.force_intra_frame();
                }
                let yuv = YUVBuffer::from_rgba8_source(RgbaSliceU8::new(
                    rgba,
                    (width as usize, height as usize),
                ));
                let millis = (now_s.max(0.0) * 1e3).min(1e15) as u64;
                let stream = encoder
                    .encode_at(&yuv, Timestamp::from_millis(millis))
                    .map_err(|e| codec_error("h264 encoder", e))?;
                let kind = stream.frame_type();
                let bytes = stream.to_vec();
                if kind == FrameType::Skip {
                    return Ok(None);
                }
                if bytes.is_empty() || kind == FrameType::Invalid {
                    return Err(codec_error(
                        "h264 encoder",
                        format!("frame type {kind:?} with {} bytes", bytes.len()),
                    ));
                }
                (bytes, kind == FrameType::IDR)
            }
        };
        if keyframe && self.settings.codec == Codec::H264 {
            self.last_keyframe_s = Some(now_s);
        }
        let seq = self.seq;
        self.seq += 1;
        Ok(Some(EncodedFrame {
            bytes,
            keyframe,
            seq,
            stream: self.stream,
        }))
    }
}

/// What a viewer's decoder gives for one received frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    /// The picture: RGBA8, `width * height * 4` bytes.
    Image {
        /// Width (pixels).
        width: u32,
        /// Height (pixels).
        height: u32,
        /// The pixels.
        rgba: Vec<u8>,
    },
    /// An H.264 frame that cannot be shown: a frame it refers to was lost (or the viewer
    /// joined after it, or it did not decode). Nothing is shown until the next IDR frame; ask
    /// the robot site for one.
    NeedKeyframe {
        /// Why: which frame numbers are missing, or the decoder's error.
        reason: String,
    },
    /// An H.264 frame older than one already decoded in its stream (reordered or duplicated
    /// on the way): dropped, the stream goes on.
    Stale,
}

/// Decodes one camera's received frames (either codec; a stream may switch).
pub struct VideoDecoder {
    h264: Option<Decoder>,
    /// The stream being decoded.
    stream: Option<u64>,
    /// The next H.264 frame number expected, when the stream is decodable.
    next_seq: Option<u64>,
}

impl std::fmt::Debug for VideoDecoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VideoDecoder")
            .field("next_seq", &self.next_seq)
            .finish_non_exhaustive()
    }
}

impl Default for VideoDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl VideoDecoder {
    /// A decoder waiting for its first frame.
    pub fn new() -> Self {
        Self {
            h264: None,
            stream: None,
            next_seq: None,
        }
    }

    /// Decodes one frame with its (checked) header. Errors for a frame that is not what its
    /// header says (another codec, another size, undecodable JPEG); an H.264 frame that
    /// cannot be shown is [`Decoded::NeedKeyframe`], not an error.
    pub fn decode(&mut self, header: &FrameHeader, payload: &[u8]) -> Result<Decoded, NetError> {
        let what = || format!("frame {} of camera '{}'", header.index, header.camera);
        let codec = Codec::from_name(&header.codec)
            .ok_or_else(|| codec_error(&what(), format!("codec '{}'", header.codec)))?;
        let image = match codec {
            Codec::Jpeg => {
                let img = image::load_from_memory_with_format(payload, image::ImageFormat::Jpeg)
                    .map_err(|e| codec_error(&what(), format!("jpeg: {e}")))?;
                (img.width(), img.height(), img.into_rgba8().into_raw())
            }
            Codec::H264 => match self.decode_h264(header, payload) {
                Ok(Some(image)) => image,
                Ok(None) => return Ok(Decoded::Stale),
                Err(reason) => {
                    self.next_seq = None;
                    return Ok(Decoded::NeedKeyframe { reason });
                }
            },
        };
        let (width, height, rgba) = image;
        if (width, height) != (header.width, header.height) {
            return Err(codec_error(
                &what(),
                format!(
                    "decodes to {width}x{height}, the header says {}x{}",
                    header.width, header.height
                ),
            ));
        }
        Ok(Decoded::Image {
            width,
            height,
            rgba,
        })
    }

    /// An H.264 frame in order: `Ok(None)` for a stale one (dropped), `Err` says why it
    /// cannot be shown.
    fn decode_h264(
        &mut self,
        header: &FrameHeader,
        payload: &[u8],
    ) -> Result<Option<(u32, u32, Vec<u8>)>, String> {
        if self.stream != Some(header.stream) {
            // Another stream (the robot site restarted, or the first): begun by its IDR.
            self.stream = Some(header.stream);
            self.next_seq = None;
        }
        match self.next_seq {
            // Behind: reordered or duplicated on the way.
            Some(n) if header.seq < n => return Ok(None),
            Some(n) if header.seq > n && !header.keyframe => {
                return Err(format!("frames {n}..={} were lost", header.seq - 1));
            }
            None if !header.keyframe => {
                return Err(format!(
                    "frame {} needs the frames before it (joined mid-stream or after a loss)",
                    header.seq
                ));
            }
            _ => {}
        }
        if self.h264.is_none() || header.keyframe {
            // A fresh decoder at each IDR: nothing of a broken stream carries over.
            self.h264 = Some(
                Decoder::with_api_config(OpenH264API::from_source(), Default::default())
                    .map_err(|e| format!("h264 decoder: {e}"))?,
            );
        }
        let Some(decoder) = self.h264.as_mut() else {
            return Err("no h264 decoder".into());
        };
        let picture = decoder
            .decode(payload)
            .map_err(|e| format!("h264: {e}"))?
            .ok_or_else(|| format!("frame {} gave no picture", header.seq))?;
        let (w, h) = picture.dimensions();
        let mut rgba = vec![0; w * h * 4];
        picture.write_rgba8(&mut rgba);
        // `seq` is at most MAX_SEQ (the header's check): no overflow.
        self.next_seq = Some(header.seq.saturating_add(1));
        Ok(Some((w as u32, h as u32, rgba)))
    }
}

/// PSNR (dB) of the RGB channels of two RGBA8 images of the same size, capped at 100 dB;
/// `None` when the sizes differ.
pub fn psnr_rgba(a: &[u8], b: &[u8]) -> Option<f64> {
    avatarm_core::dr::scores::psnr(a, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A desk-like test picture: gradients and a square that moves `t` pixels.
    fn picture(width: u32, height: u32, t: u32) -> Vec<u8> {
        let mut rgba = Vec::with_capacity((width * height * 4) as usize);
        for y in 0..height {
            for x in 0..width {
                let inside =
                    (x + 64 - t % 64).abs_diff(width / 2) < 40 && y.abs_diff(height / 2) < 40;
                let (r, g, b) = if inside {
                    (220, 40, 40)
                } else {
                    ((x * 255 / width) as u8, (y * 255 / height) as u8, 128)
                };
                rgba.extend_from_slice(&[r, g, b, 255]);
            }
        }
        rgba
    }

    /// Both JPEG encoders code the same picture to within JPEG's loss at quality 85, and both
    /// decode with the viewer's decoder.
    #[test]
    fn both_jpeg_encoders_give_the_picture_back() {
        let rgba = picture(160, 120, 3);
        let sizes: Vec<usize> = [JpegEncoder::Simd, JpegEncoder::Image]
            .into_iter()
            .map(|encoder| {
                let bytes = encode_jpeg(encoder, 85, &rgba, 160, 120).expect("coded");
                let back = image::load_from_memory(&bytes).expect("decoded").to_rgba8();
                assert_eq!(back.dimensions(), (160, 120));
                let psnr = psnr_rgba(&rgba, back.as_raw()).expect("same size");
                assert!(psnr > 30.0, "{}: {psnr} dB", encoder.name());
                bytes.len()
            })
            .collect();
        assert!(
            sizes[0] < 2 * sizes[1] && sizes[1] < 2 * sizes[0],
            "{sizes:?}"
        );
        let e = encode_jpeg(JpegEncoder::Simd, 85, &[0; 4], 70_000, 1).expect_err("too wide");
        assert!(e.to_string().contains("65535"), "{e}");
    }

    fn header(codec: Codec, f: &EncodedFrame, index: u64) -> FrameHeader {
        FrameHeader {
            v: crate::msg::PROTOCOL_VERSION,
            camera: "desk".into(),
            index,
            codec: codec.name().into(),
            seq: f.seq,
            stream: f.stream,
            keyframe: f.keyframe,
            width: 160,
            height: 120,
            capture_s: 0.0,
            arrived_s: 0.0,
            erased_s: 0.0,
            sent_s: 0.0,
            arrived_update: 0,
            handed_update: 0,
            camera_pose: FrameHeader::pose_of(&nalgebra::Isometry3::identity()),
        }
    }

    fn settings(codec: Codec) -> EncoderSettings {
        EncoderSettings {
            codec,
            bitrate_bps: 1_000_000,
            ..EncoderSettings::default()
        }
    }

    #[test]
    fn both_codecs_round_trip_a_moving_picture() {
        for codec in [Codec::Jpeg, Codec::H264] {
            let mut enc = VideoEncoder::new(settings(codec)).unwrap();
            let mut dec = VideoDecoder::new();
            for i in 0..20u32 {
                let src = picture(160, 120, i * 2);
                let f = enc
                    .encode(&src, 160, 120, f64::from(i) / 30.0, false)
                    .unwrap()
                    .expect("not skipped at this rate");
                assert_eq!(f.seq, u64::from(i));
                assert_eq!(
                    f.keyframe,
                    codec == Codec::Jpeg || i == 0,
                    "{codec} frame {i}"
                );
                match dec
                    .decode(&header(codec, &f, u64::from(i)), &f.bytes)
                    .unwrap()
                {
                    Decoded::Image {
                        width,
                        height,
                        rgba,
                    } => {
                        assert_eq!((width, height), (160, 120));
                        let psnr = psnr_rgba(&src, &rgba).unwrap();
                        assert!(psnr > 28.0, "{codec} frame {i}: {psnr:.1} dB");
                    }
                    other => panic!("{codec} frame {i}: {other:?}"),
                }
            }
        }
    }

    #[test]
    fn an_h264_viewer_waits_for_a_keyframe_after_a_loss_and_recovers() {
        let mut enc = VideoEncoder::new(settings(Codec::H264)).unwrap();
        let mut dec = VideoDecoder::new();
        let frames: Vec<EncodedFrame> = (0..8u32)
            .map(|i| {
                // Frame 5 is forced to be an IDR frame, as on a viewer's request.
                enc.encode(&picture(160, 120, i), 160, 120, f64::from(i) / 30.0, i == 5)
                    .unwrap()
                    .expect("not skipped at this rate")
            })
            .collect();
        assert!(frames[5].keyframe && !frames[4].keyframe && !frames[6].keyframe);
        let mut shown = Vec::new();
        // Frame 2 is lost; 3 and 4 cannot be shown; 5 (IDR) onwards can.
        for (i, f) in frames.iter().enumerate() {
            if i == 2 {
                continue;
            }
            match dec
                .decode(&header(Codec::H264, f, i as u64), &f.bytes)
                .unwrap()
            {
                Decoded::Image { .. } => shown.push(i),
                Decoded::NeedKeyframe { reason } => {
                    assert!(i == 3 || i == 4, "frame {i}: {reason}");
                    if i == 3 {
                        assert!(reason.contains("frames 2..=2 were lost"), "{reason}");
                    }
                }
                Decoded::Stale => panic!("frame {i} taken as stale"),
            }
        }
        assert_eq!(shown, vec![0, 1, 5, 6, 7]);
        // A duplicated or reordered frame is dropped; the stream goes on.
        let d = dec.decode(&header(Codec::H264, &frames[6], 6), &frames[6].bytes);
        assert_eq!(d.unwrap(), Decoded::Stale);
        // The robot site restarted: a new stream from 0, begun by its IDR frame.
        let mut again = VideoEncoder::new(settings(Codec::H264)).unwrap();
        for i in 0..2u32 {
            let f = again
                .encode(&picture(160, 120, i), 160, 120, f64::from(i) / 30.0, false)
                .unwrap()
                .expect("not skipped at this rate");
            let d = dec.decode(&header(Codec::H264, &f, u64::from(i)), &f.bytes);
            assert!(
                matches!(d, Ok(Decoded::Image { .. })),
                "restart frame {i}: {d:?}"
            );
        }
        // A viewer joining at frame 6 waits too.
        let mut late = VideoDecoder::new();
        let d = late
            .decode(&header(Codec::H264, &frames[6], 6), &frames[6].bytes)
            .unwrap();
        assert!(matches!(d, Decoded::NeedKeyframe { .. }), "{d:?}");
    }

    #[test]
    fn the_keyframe_interval_is_kept() {
        let mut enc = VideoEncoder::new(EncoderSettings {
            keyframe_interval_s: 0.5,
            ..settings(Codec::H264)
        })
        .unwrap();
        let keys: Vec<u32> = (0..40u32)
            .filter(|&i| {
                enc.encode(&picture(160, 120, i), 160, 120, f64::from(i) / 30.0, false)
                    .unwrap()
                    .expect("not skipped at this rate")
                    .keyframe
            })
            .collect();
        assert_eq!(keys, vec![0, 15, 30]);
    }

    #[test]
    fn bad_frames_and_settings_are_refused_by_name() {
        let mut enc = VideoEncoder::new(settings(Codec::H264)).unwrap();
        let e = enc.encode(&[0; 10], 160, 120, 0.0, false).unwrap_err();
        assert!(e.to_string().contains("160x120 with 10 bytes"), "{e}");
        let odd = vec![0; 161 * 121 * 4];
        let e = enc.encode(&odd, 161, 121, 0.0, false).unwrap_err();
        assert!(e.to_string().contains("even for h264"), "{e}");
        let e = VideoEncoder::new(EncoderSettings {
            jpeg_quality: 0,
            ..EncoderSettings::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("--jpeg-quality"), "{e}");
        let e = VideoEncoder::new(EncoderSettings {
            keyframe_interval_s: f64::NAN,
            ..EncoderSettings::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("--keyframe-interval"), "{e}");
        // Garbage in either codec: an error or a wait for a keyframe, never a panic.
        let mut dec = VideoDecoder::new();
        let f = EncodedFrame {
            bytes: vec![0xAB; 5000],
            keyframe: true,
            seq: 0,
            stream: 1,
        };
        assert!(dec.decode(&header(Codec::Jpeg, &f, 0), &f.bytes).is_err());
        let d = dec.decode(&header(Codec::H264, &f, 0), &f.bytes);
        assert!(
            !matches!(d, Ok(Decoded::Image { .. })),
            "garbage decoded to a picture: {d:?}"
        );
        // A frame that decodes to another size than its header says.
        let mut jpeg = VideoEncoder::new(settings(Codec::Jpeg)).unwrap();
        let f = jpeg
            .encode(&picture(160, 120, 0), 160, 120, 0.0, false)
            .unwrap()
            .expect("jpeg never skips");
        let mut h = header(Codec::Jpeg, &f, 0);
        h.width = 320;
        let e = dec.decode(&h, &f.bytes).unwrap_err();
        assert!(e.to_string().contains("header says 320x120"), "{e}");
    }
}
