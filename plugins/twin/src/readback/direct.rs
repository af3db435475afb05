//! Reading an image back in the render world, right after the frame that drew it, and handing
//! its bytes straight to whoever waits for them (a video encoder's thread), with no trip
//! through the main world.
//!
//! Bevy's [`bevy::render::gpu_readback::Readback`] (and [`super::read_image_once`] on it) maps
//! the copy after the frame, notices the mapping at a later frame's poll and triggers the main
//! world at a later extraction: a frame erased in update N reaches the main world in update N+3
//! (measured at the robot site, docs/latency.md). Here the copy is submitted after the frame's
//! own commands, the render thread waits for it (`PollType::Wait`: the GPU's time for the frame
//! and the copy, which the frame needs anyway) and calls the request's `deliver` on the render
//! thread: the frame is in the encoder's hands in the update it was drawn in (the next one's
//! with Bevy's pipelined rendering, whose render of update N runs beside update N+1).

use std::time::Duration;

use bevy::diagnostic::FrameCount;
use bevy::image::TextureFormatPixelInfo;
use bevy::prelude::*;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::{
    Buffer, BufferDescriptor, BufferUsages, CommandEncoderDescriptor, MapMode, PollType,
    TexelCopyBufferInfo, TexelCopyBufferLayout,
};
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy::render::{ExtractSchedule, MainWorld, Render, RenderApp, RenderSystems};

use crate::TwinError;

/// An image's bytes, rows packed (no alignment padding), in its texture's format.
#[derive(Debug, Clone)]
pub struct ImageBytes {
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// Bytes per pixel of the texture's format (4 for RGBA8).
    pub bytes_per_pixel: usize,
    /// `width * height * bytes_per_pixel` bytes, top row first.
    pub data: Vec<u8>,
}

/// What a [`DirectRead`] hands its bytes (or why there are none) to, on the render thread.
pub type Deliver = Box<dyn FnOnce(Result<ImageBytes, TwinError>) + Send + Sync>;

/// A request to read `image` back as this update's frame draws it.
pub struct DirectRead {
    /// The image.
    pub image: Handle<Image>,
    /// The frame it is for: [`RenderSettled::this_update_frame`] of the update that asks. A
    /// request rendered in another frame (a renderer that skipped frames) is refused.
    ///
    /// [`RenderSettled::this_update_frame`]: crate::camera::RenderSettled::this_update_frame
    pub frame: u32,
    /// Called once on the render thread with its bytes; it should be quick (send them on).
    pub deliver: Deliver,
}

/// The main world's requests of this update ([`DirectRead`]); taken at the extraction.
#[derive(Resource, Default)]
pub struct DirectReadQueue(pub Vec<DirectRead>);

/// The requests extracted with this frame (render world).
#[derive(Resource, Default)]
struct ExtractedReads(Vec<DirectRead>);

/// Copy buffers unmapped after use, for the next frames of the same size (render world).
#[derive(Resource, Default)]
struct SpareBuffers(Vec<Buffer>);

/// Spare buffers kept at most.
const SPARE_BUFFERS: usize = 4;

/// Serves [`DirectReadQueue`]: each request is read back after its frame and delivered on the
/// render thread.
#[derive(Default)]
pub struct DirectReadbackPlugin;

impl Plugin for DirectReadbackPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<DirectReadQueue>();
        if let Some(render) = app.get_sub_app_mut(RenderApp) {
            render
                .init_resource::<ExtractedReads>()
                .init_resource::<SpareBuffers>()
                .add_systems(ExtractSchedule, take_requests)
                .add_systems(Render, read_back.in_set(RenderSystems::Cleanup));
        } else {
            // Nothing renders: each request is refused in the next update.
            app.add_systems(First, refuse_unrendered);
        }
    }
}

/// The longest the render thread waits for a frame's copy before the request is refused (a
/// stalled GPU must not hang the app).
pub const MAX_WAIT: Duration = Duration::from_secs(1);

fn refuse_unrendered(mut queue: ResMut<DirectReadQueue>) {
    for request in queue.0.drain(..) {
        (request.deliver)(Err(TwinError::Readback {
            message: "nothing renders in this app".into(),
        }));
    }
}

fn take_requests(mut main: ResMut<MainWorld>, mut extracted: ResMut<ExtractedReads>) {
    if let Some(mut queue) = main.get_resource_mut::<DirectReadQueue>() {
        extracted.0.append(&mut queue.0);
    }
}

/// After the frame's commands: one copy per request, one submission, one wait, each delivered.
fn read_back(
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    images: Res<RenderAssets<GpuImage>>,
    frame: Option<Res<FrameCount>>,
    mut extracted: ResMut<ExtractedReads>,
    mut spare: ResMut<SpareBuffers>,
) {
    if extracted.0.is_empty() {
        return;
    }
    let bad = |message: String| TwinError::Readback { message };
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor {
        label: Some("avatarm direct readback"),
    });
    let mut copies = Vec::new();
    let rendering = frame.map(|f| f.0);
    for request in extracted.0.drain(..) {
        if rendering.is_some_and(|f| f != request.frame) {
            (request.deliver)(Err(bad(format!(
                "asked in frame {}, rendered in frame {}",
                request.frame,
                rendering.unwrap_or_default()
            ))));
            continue;
        }
        let Some(gpu) = images.get(&request.image) else {
            (request.deliver)(Err(bad("the image is not on the GPU yet".into())));
            continue;
        };
        let descriptor = &gpu.texture_descriptor;
        let Ok(pixel) = descriptor.format.pixel_size() else {
            (request.deliver)(Err(bad(format!(
                "format {:?} has no fixed pixel size",
                descriptor.format
            ))));
            continue;
        };
        let size = descriptor.size;
        if size.width == 0 || size.height == 0 || size.depth_or_array_layers != 1 {
            (request.deliver)(Err(bad(format!(
                "a {}x{}x{} texture is not one image",
                size.width, size.height, size.depth_or_array_layers
            ))));
            continue;
        }
        let stride = (size.width as usize * pixel).div_ceil(256) * 256;
        let bytes = (stride * size.height as usize) as u64;
        let buffer = match spare.0.iter().position(|b| b.size() == bytes) {
            Some(i) => spare.0.swap_remove(i),
            None => device.create_buffer(&BufferDescriptor {
                label: Some("avatarm direct readback"),
                size: bytes,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        };
        encoder.copy_texture_to_buffer(
            gpu.texture.as_image_copy(),
            TexelCopyBufferInfo {
                buffer: &buffer,
                layout: TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(stride as u32),
                    rows_per_image: None,
                },
            },
            size,
        );
        copies.push((request, buffer, size, pixel));
    }
    if copies.is_empty() {
        return;
    }
    let submission = queue.submit([encoder.finish()]);
    let mapped: Vec<_> = copies
        .iter()
        .map(|(_, buffer, _, _)| {
            let (tx, rx) = std::sync::mpsc::channel();
            buffer.slice(..).map_async(MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
            rx
        })
        .collect();
    let waited = device.poll(PollType::Wait {
        submission_index: Some(submission),
        timeout: Some(MAX_WAIT),
    });
    for ((request, buffer, size, pixel), rx) in copies.into_iter().zip(mapped) {
        let result = match (&waited, rx.try_recv()) {
            (Err(e), _) => Err(bad(format!("waiting for the GPU: {e}"))),
            (Ok(_), Ok(Ok(()))) => {
                let mapped = buffer.slice(..).get_mapped_range();
                let packed = super::unpad_rows(&mapped, size.width, size.height, pixel);
                let len = mapped.len();
                drop(mapped);
                buffer.unmap();
                if spare.0.len() < SPARE_BUFFERS {
                    spare.0.push(buffer);
                }
                packed
                    .map(|data| ImageBytes {
                        width: size.width,
                        height: size.height,
                        bytes_per_pixel: pixel,
                        data,
                    })
                    .ok_or_else(|| bad(format!("{len} bytes do not hold the image")))
            }
            (Ok(_), Ok(Err(e))) => Err(bad(format!("mapping the copy: {e}"))),
            (Ok(_), Err(_)) => Err(bad("the copy was not mapped after the wait".into())),
        };
        (request.deliver)(result);
    }
}
