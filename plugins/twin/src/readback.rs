//! Reading a render target image back to the CPU once, without disturbing the cameras.
//!
//! Bevy's `Screenshot::image` is no way to read a render target that another camera samples:
//! for the frame of the screenshot it points the rendering camera at a temporary texture and
//! copies that into the image only after every camera has rendered. A camera that samples the
//! image in that frame sees the previous frame's content, and an image whose camera does not
//! render that frame becomes black. [`read_image_once`] copies the image itself after the
//! frame's cameras instead (Bevy's [`Readback`]), for exactly one frame.
//!
//! [`direct`]: the same read back in the render world right after its frame, handed over on the
//! render thread (the robot site's video: no update lost on the way to the encoder).

pub mod direct;

use bevy::image::TextureFormatPixelInfo;
use bevy::prelude::*;
use bevy::render::gpu_readback::{Readback, ReadbackComplete};

use crate::TwinError;

/// An image read back from the GPU, triggered on the entity [`read_image_once`] returns.
#[derive(EntityEvent, Debug, Clone)]
pub struct ImageRead {
    /// The readback's entity (despawned after this event).
    pub entity: Entity,
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// Bytes per pixel of the texture's format (1 for `R8Unorm`, 4 for RGBA8).
    pub bytes_per_pixel: usize,
    /// The texture's bytes, rows packed (no alignment padding), in its own format.
    pub data: Vec<u8>,
}

/// Turns [`read_image_once`] requests into one-frame readbacks.
#[derive(Default)]
pub struct ImageReadbackPlugin;

impl Plugin for ImageReadbackPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<ReadbackStats>()
            .add_systems(First, stop_after_one_frame)
            .add_observer(deliver_image);
    }
}

/// Images read back so far, and their bytes (what the read-backs cost the GPU-to-CPU link).
#[derive(Resource, Debug, Clone, Default)]
pub struct ReadbackStats {
    /// Images delivered.
    pub images: u64,
    /// Their bytes.
    pub bytes: u64,
}

/// A pending one-frame readback of an image.
#[derive(Component, Debug)]
struct ReadOnce {
    image: Handle<Image>,
    /// The request has been through one extraction (it was spawned in an earlier update).
    submitted: bool,
}

/// Reads `image` back as rendered at the end of this update (every camera of the frame
/// included). Observe [`ImageRead`] on the returned entity; it is despawned after delivery.
/// Needs [`ImageReadbackPlugin`].
pub fn read_image_once<'a>(commands: &'a mut Commands, image: Handle<Image>) -> EntityCommands<'a> {
    commands.spawn((
        Readback::texture(image.clone()),
        ReadOnce {
            image,
            submitted: false,
        },
    ))
}

/// A request spawned in an update is extracted (and copied) at the end of it; without its
/// [`Readback`] from the next update on, it is not copied again.
fn stop_after_one_frame(mut commands: Commands, mut pending: Query<(Entity, &mut ReadOnce)>) {
    for (entity, mut once) in &mut pending {
        if !once.submitted {
            once.submitted = true;
            commands.entity(entity).remove::<Readback>();
        }
    }
}

fn deliver_image(
    done: On<ReadbackComplete>,
    pending: Query<&ReadOnce>,
    images: Res<Assets<Image>>,
    mut stats: ResMut<ReadbackStats>,
    mut commands: Commands,
) {
    let entity = done.entity;
    let Ok(once) = pending.get(entity) else {
        return;
    };
    stats.images += 1;
    stats.bytes += done.data.len() as u64;
    match read_image(&done.data, images.get(&once.image)) {
        Ok((width, height, bytes_per_pixel, data)) => commands.trigger(ImageRead {
            entity,
            width,
            height,
            bytes_per_pixel,
            data,
        }),
        Err(e) => warn!("{e}"),
    }
    // After the trigger: the entity carries the caller's observer.
    commands.entity(entity).despawn();
}

/// The image's size, bytes per pixel and packed bytes out of a readback of it.
fn read_image(data: &[u8], image: Option<&Image>) -> Result<(u32, u32, usize, Vec<u8>), TwinError> {
    let bad = |message: String| TwinError::Readback { message };
    let image = image.ok_or_else(|| bad("the image was removed before its data arrived".into()))?;
    let descriptor = &image.texture_descriptor;
    let size = descriptor.size;
    let pixel = descriptor.format.pixel_size().map_err(|_| {
        bad(format!(
            "format {:?} has no fixed pixel size",
            descriptor.format
        ))
    })?;
    let packed = unpad_rows(data, size.width, size.height, pixel).ok_or_else(|| {
        bad(format!(
            "{} bytes do not hold a {}x{} image",
            data.len(),
            size.width,
            size.height
        ))
    })?;
    Ok((size.width, size.height, pixel, packed))
}

/// Rows of `width * pixel` bytes out of a copy whose rows are aligned to 256 bytes (wgpu's
/// `COPY_BYTES_PER_ROW_ALIGNMENT`); `None` when `data` is too short.
pub(crate) fn unpad_rows(data: &[u8], width: u32, height: u32, pixel: usize) -> Option<Vec<u8>> {
    let row = width as usize * pixel;
    let stride = row.div_ceil(256) * 256;
    let height = height as usize;
    if height == 0 || data.len() < stride * (height - 1) + row {
        return None;
    }
    if stride == row {
        return Some(data[..row * height].to_vec());
    }
    let mut out = Vec::with_capacity(row * height);
    for r in 0..height {
        out.extend_from_slice(&data[r * stride..r * stride + row]);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::unpad_rows;

    #[test]
    fn rows_lose_their_alignment_padding() {
        // 3 px of RGBA8 = 12 bytes per row, padded to 256.
        let mut data = vec![0u8; 256 * 2];
        data[..12].copy_from_slice(&[1; 12]);
        data[256..268].copy_from_slice(&[2; 12]);
        let out = unpad_rows(&data, 3, 2, 4).unwrap();
        assert_eq!(out, [[1u8; 12], [2u8; 12]].concat());
        // Rows already a multiple of 256 bytes come back as they are.
        let packed: Vec<u8> = (0..=255).chain(0..=255).collect();
        assert_eq!(unpad_rows(&packed, 64, 2, 4).unwrap(), packed);
        // Too short for the last row.
        assert!(unpad_rows(&data[..260], 3, 2, 4).is_none());
    }
}
