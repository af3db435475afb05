//! The standard messages a bag import reads, in their wire order, and their pictures.
//!
//! ROS 1 and ROS 2 lay these messages out field for field alike except for `std_msgs/Header`
//! (ROS 1: `seq`, `stamp` as `secs`/`nsecs`, `frame_id`; ROS 2: `stamp` as `sec`/`nanosec`,
//! `frame_id`), so each message is generic over its header and each wire format
//! ([`super::ros1`], [`super::ros2`]) gives its own.

use avatarm_record::{CompressedFrame, ImageFormat};
use serde::Deserialize;

/// A message header: its stamp and the frame its data is in.
pub(super) trait Stamped {
    /// The stamp (ns since the Unix epoch); `received_ns` (the bag's receive time) where the
    /// header's is zero or before the epoch.
    fn stamp_ns(&self, received_ns: u64) -> u64;
    /// The `frame_id`.
    fn frame_id(&self) -> &str;
}

/// `sensor_msgs/Image`.
#[derive(Deserialize)]
pub(super) struct Image<H> {
    pub header: H,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: u8,
    pub step: u32,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/CompressedImage`.
#[derive(Deserialize)]
pub(super) struct CompressedImage<H> {
    pub header: H,
    pub format: String,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

#[derive(Deserialize)]
pub(super) struct RegionOfInterest {
    _x_offset: u32,
    _y_offset: u32,
    _height: u32,
    _width: u32,
    _do_rectify: bool,
}

/// `sensor_msgs/CameraInfo`.
#[derive(Deserialize)]
pub(super) struct CameraInfo<H> {
    pub header: H,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    _r: [f64; 9],
    _p: [f64; 12],
    _binning_x: u32,
    _binning_y: u32,
    _roi: RegionOfInterest,
}

/// `sensor_msgs/JointState`.
#[derive(Deserialize)]
pub(super) struct JointState<H> {
    pub header: H,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    _effort: Vec<f64>,
}

/// `geometry_msgs/Vector3`.
#[derive(Deserialize)]
pub(super) struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Deserialize)]
pub(super) struct QuaternionMsg {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

/// `geometry_msgs/Transform`.
#[derive(Deserialize)]
pub(super) struct Transform {
    pub translation: Vector3,
    pub rotation: QuaternionMsg,
}

/// `geometry_msgs/TransformStamped`.
#[derive(Deserialize)]
pub(super) struct TransformStamped<H> {
    pub header: H,
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`.
#[derive(Deserialize)]
pub(super) struct TfMessage<H> {
    pub transforms: Vec<TransformStamped<H>>,
}

/// A silhouette with every non-zero pixel at 255 (a label mask of 0/1 is common), as PNG.
pub(super) fn as_silhouette(frame: CompressedFrame, at: &str) -> Result<CompressedFrame, String> {
    let luma = image::load_from_memory(&frame.data)
        .map_err(|e| format!("{at}: the mask does not decode: {e}"))?
        .to_luma16();
    let (w, h) = luma.dimensions();
    let bytes: Vec<u8> = luma
        .pixels()
        .map(|p| if p.0[0] != 0 { 255 } else { 0 })
        .collect();
    let picture =
        image::GrayImage::from_raw(w, h, bytes).ok_or_else(|| format!("{at}: {w}x{h}"))?;
    Ok(CompressedFrame {
        stamp_ns: frame.stamp_ns,
        format: ImageFormat::Png,
        data: png_of(&picture.into(), at)?,
    })
}

fn png_of(picture: &image::DynamicImage, at: &str) -> Result<Vec<u8>, String> {
    let mut png = Vec::new();
    picture
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| format!("{at}: PNG encoding failed: {e}"))?;
    Ok(png)
}

/// A `CompressedImage` as recorded (JPEG or PNG), with its frame_id.
pub(super) fn compressed_frame<H: Stamped>(
    m: CompressedImage<H>,
    at: &str,
    received_ns: u64,
) -> Result<(CompressedFrame, String), String> {
    let format = ImageFormat::of_bytes(&m.data).ok_or_else(|| {
        format!(
            "{at}: format '{}': the data is neither JPEG nor PNG",
            m.format
        )
    })?;
    Ok((
        CompressedFrame {
            stamp_ns: m.header.stamp_ns(received_ns),
            format,
            data: m.data,
        },
        m.header.frame_id().to_owned(),
    ))
}

/// A raw `Image` as PNG (RGB, or grey repeated), with its frame_id: `rgb8`, `bgr8`, `rgba8`,
/// `bgra8`, `mono8`, `8UC1`, `8UC3` (as BGR), `8UC4` (as BGRA), `mono16`/`16UC1` (the high
/// byte); rows `step` bytes apart.
pub(super) fn raw_frame<H: Stamped>(
    m: Image<H>,
    at: &str,
    received_ns: u64,
) -> Result<(CompressedFrame, String), String> {
    let (w, h) = (m.width as usize, m.height as usize);
    if w == 0 || h == 0 {
        return Err(format!("{at}: an empty image ({w}x{h})"));
    }
    let (channels, bytes) = match m.encoding.as_str() {
        "rgb8" | "bgr8" | "8UC3" => (3, 1),
        "rgba8" | "bgra8" | "8UC4" => (4, 1),
        "mono8" | "8UC1" => (1, 1),
        "mono16" | "16UC1" => (1, 2),
        other => {
            return Err(format!(
                "{at}: encoding '{other}' is not read (rgb8, bgr8, rgba8, bgra8, mono8, mono16, 8UC1, 8UC3, 8UC4, 16UC1)"
            ));
        }
    };
    let step = m.step as usize;
    // Sizes from the message's header: checked, a crafted one may overflow.
    let row = w.checked_mul(channels * bytes);
    let needed = row.and_then(|row| step.checked_mul(h - 1)?.checked_add(row));
    let (Some(row), Some(needed)) = (row, needed) else {
        return Err(format!(
            "{at}: {w}x{h} {} with step {step}: sizes past this machine's range",
            m.encoding
        ));
    };
    if step < row || m.data.len() < needed {
        return Err(format!(
            "{at}: {w}x{h} {} needs a step of at least {row} bytes and {needed} bytes of data; the message has step {step} and {} bytes",
            m.encoding,
            m.data.len()
        ));
    }
    let mut rgb = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        let line = &m.data[y * step..y * step + row];
        match (m.encoding.as_str(), bytes) {
            ("rgb8", _) => rgb.extend_from_slice(line),
            ("bgr8" | "8UC3", _) => line
                .chunks_exact(3)
                .for_each(|p| rgb.extend([p[2], p[1], p[0]])),
            ("rgba8", _) => line
                .chunks_exact(4)
                .for_each(|p| rgb.extend([p[0], p[1], p[2]])),
            ("bgra8" | "8UC4", _) => line
                .chunks_exact(4)
                .for_each(|p| rgb.extend([p[2], p[1], p[0]])),
            (_, 1) => line.iter().for_each(|&v| rgb.extend([v, v, v])),
            _ => line.chunks_exact(2).for_each(|p| {
                let v = if m.is_bigendian != 0 {
                    u16::from_be_bytes([p[0], p[1]])
                } else {
                    u16::from_le_bytes([p[0], p[1]])
                };
                let v = (v >> 8) as u8;
                rgb.extend([v, v, v]);
            }),
        }
    }
    let picture = image::RgbImage::from_raw(m.width, m.height, rgb)
        .ok_or_else(|| format!("{at}: {w}x{h} does not fit its pixels"))?;
    Ok((
        CompressedFrame {
            stamp_ns: m.header.stamp_ns(received_ns),
            format: ImageFormat::Png,
            data: png_of(&picture.into(), at)?,
        },
        m.header.frame_id().to_owned(),
    ))
}

/// An image's size (px), read from its header alone.
pub(super) fn size_of(f: &CompressedFrame, at: &str) -> Result<(u32, u32), String> {
    image::ImageReader::new(std::io::Cursor::new(&f.data))
        .with_guessed_format()
        .map_err(|e| format!("{at}: {e}"))?
        .into_dimensions()
        .map_err(|e| format!("{at}: the image does not decode: {e}"))
}
