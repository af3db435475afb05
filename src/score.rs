//! The capture-and-score path shared by the replay ([`crate::replay`]) and the preview's live
//! scores ([`crate::preview::live_scores`]): images of one camera frame read back from the GPU
//! as they arrive (the room's ground truth at capture, the pipeline's mask and composite), keyed
//! by the frame's capture time, then scored against the simulated room's truth.

use avatarm_core::dr::{self, EraseSettings, MaskScores};
use avatarm_sim::SimCameras;
use avatarm_twin::readback::{ImageRead, read_image_once};
use bevy::prelude::*;

/// A camera frame's key: its capture time in whole microseconds (frames are keyed by time
/// because the room's truth and the pipeline's images of one frame are read back in different
/// updates).
pub fn frame_key(t_s: f64) -> i64 {
    (t_s * 1e6).round() as i64
}

/// One of the images of a frame that is read back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FramePart {
    /// The simulated room without the robot, at capture (RGBA8).
    NoRobot,
    /// The robot's true silhouette, white on black, at capture (stored as a 0/1 mask).
    Silhouette,
    /// The mask twin's flat render before thresholding (stored as RGBA8 `(v, v, v, 255)`, at
    /// the mask's resolution).
    Raw,
    /// The mask pass's output M(t) (stored as a 0/1 mask).
    Mask,
    /// The composite Ĩ(t) (RGBA8).
    Composite,
}

/// A frame's read-back images as they arrive.
#[derive(Debug, Default, Clone)]
pub struct FrameImages {
    /// [`FramePart::NoRobot`].
    pub norobot: Option<Vec<u8>>,
    /// [`FramePart::Silhouette`]: 0/1 per pixel.
    pub silhouette: Option<Vec<u8>>,
    /// [`FramePart::Raw`] (RGBA8), with its width and height (px).
    pub raw: Option<(u32, u32, Vec<u8>)>,
    /// [`FramePart::Mask`]: 0/1 per pixel.
    pub mask: Option<Vec<u8>>,
    /// [`FramePart::Composite`].
    pub composite: Option<Vec<u8>>,
}

impl FrameImages {
    /// Stores an arrived image of `bytes_per_pixel` channels: masks as 0/1 per pixel, the
    /// mask twin's render as RGBA8.
    pub fn put(
        &mut self,
        part: FramePart,
        (width, height): (u32, u32),
        bytes_per_pixel: usize,
        data: Vec<u8>,
    ) {
        match part {
            FramePart::NoRobot => self.norobot = Some(data),
            FramePart::Silhouette => self.silhouette = Some(dr::binarise(&data, bytes_per_pixel)),
            FramePart::Raw if bytes_per_pixel == 1 => {
                self.raw = Some((width, height, dr::grey_to_rgba(&data)));
            }
            FramePart::Raw => self.raw = Some((width, height, data)),
            FramePart::Mask => self.mask = Some(dr::binarise(&data, bytes_per_pixel)),
            FramePart::Composite => self.composite = Some(data),
        }
    }

    /// Whether every one of `parts` has arrived.
    pub fn has(&self, parts: &[FramePart]) -> bool {
        parts.iter().all(|p| match p {
            FramePart::NoRobot => self.norobot.is_some(),
            FramePart::Silhouette => self.silhouette.is_some(),
            FramePart::Raw => self.raw.is_some(),
            FramePart::Mask => self.mask.is_some(),
            FramePart::Composite => self.composite.is_some(),
        })
    }
}

/// A resource that collects frames' read-back images.
pub trait FrameStore: Resource + Component<Mutability = bevy::ecs::component::Mutable> {
    /// Where an image of the frame `key` goes when it arrives; `None` drops it (the frame was
    /// given up).
    fn arrived(&mut self, key: i64) -> Option<&mut FrameImages>;
}

/// Reads `image` back once, at the end of this update's rendering, into the frame `key` of the
/// store `S`.
pub fn request_part<S: FrameStore>(
    commands: &mut Commands,
    image: Handle<Image>,
    part: FramePart,
    key: i64,
) {
    read_image_once(commands, image).observe(move |read: On<ImageRead>, mut store: ResMut<S>| {
        if let Some(images) = store.arrived(key) {
            images.put(
                part,
                (read.width, read.height),
                read.bytes_per_pixel,
                read.data.clone(),
            );
        }
    });
}

/// Reads the simulated room's ground-truth view `part` ([`FramePart::NoRobot`] or
/// [`FramePart::Silhouette`]; nothing for another part or a room without it) back once into
/// the frame `key` of the store `S`, as the camera gives it (through its lens,
/// [`SimCameras::camera_image`]).
pub fn request_truth<S: FrameStore>(
    commands: &mut Commands,
    cameras: &SimCameras,
    part: FramePart,
    key: i64,
) {
    let handle = match part {
        FramePart::NoRobot => cameras.no_robot.clone(),
        FramePart::Silhouette => cameras.silhouette.clone(),
        _ => None,
    };
    let Some(handle) = handle else {
        return;
    };
    let cameras = cameras.clone();
    read_image_once(commands, handle).observe(move |read: On<ImageRead>, mut store: ResMut<S>| {
        let size = (read.width, read.height, read.bytes_per_pixel);
        let nearest = part == FramePart::Silhouette;
        let image = cameras.camera_image(size, read.data.clone(), nearest);
        // It arrived either way (the store counts what it waits for).
        let Some(images) = store.arrived(key) else {
            return;
        };
        match image {
            Ok((width, height, data)) => {
                images.put(part, (width, height), read.bytes_per_pixel, data);
            }
            Err(e) => error!("ground truth: {e}"),
        }
    });
}

/// What the GPU's mask and composite score against the simulated room's ground truth.
#[derive(Debug, Clone)]
pub struct TruthScores {
    /// The true robot silhouette (0/1 per pixel).
    pub truth: Vec<u8>,
    /// Erased region against it.
    pub mask: MaskScores,
    /// PSNR of Ĩ(t) against the robot-free room inside it (dB).
    pub psnr_db: Option<f64>,
}

/// Scores a frame's GPU mask (0/1 per pixel) and composite (RGBA8) against the true
/// silhouette (0/1 per pixel) and the robot-free room (RGBA8, the sensor's gain applied): the
/// erased region is where the feathered mask times `alpha_h` reaches one half. `None` when the
/// sizes differ.
pub fn score_against_truth(
    settings: &EraseSettings,
    alpha_h: f32,
    (w, h): (u32, u32),
    gpu_mask: &[u8],
    composite: &[u8],
    silhouette: &[u8],
    norobot: &[u8],
) -> Option<TruthScores> {
    let gpu_alpha = dr::feather_alpha(gpu_mask, w, h, settings.feather_px);
    let erased: Vec<u8> = gpu_alpha
        .iter()
        .map(|&a| u8::from(a * alpha_h >= 0.5))
        .collect();
    let truth = silhouette.to_vec();
    let mask = dr::mask_scores(&erased, &truth)?;
    let psnr_db = dr::psnr_in(composite, norobot, &truth);
    Some(TruthScores {
        truth,
        mask,
        psnr_db,
    })
}
