//! A Bevy camera projection built from pinhole intrinsics, render targets, and the signal that
//! a frame rendered completely ([`RenderSettled`]).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

use avatarm_core::vision::camera::PinholeCamera;
use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::camera::visibility::RenderLayers;
use bevy::camera::{CameraProjection, SubCameraView};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::diagnostic::FrameCount;
use bevy::math::Vec3A;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::render_resource::{
    Extent3d, PipelineCache, TextureDimension, TextureFormat, TextureUsages,
};
use bevy::render::renderer::{RenderGraph, RenderGraphSystems};
use bevy::render::view::Msaa;

use crate::gpu_timing::GpuTimed;
use crate::iso_to_transform;

/// Projects like [`PinholeCamera::project`]: off-centre principal point, fx ≠ fy allowed.
///
/// Use it with [`Projection::custom`] and a render target of the intrinsics' size; the camera's
/// transform comes from [`camera_transform`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeProjection {
    /// The camera (its intrinsics are used; its pose goes in the transform).
    pub camera: PinholeCamera,
    /// Near plane (m).
    pub near: f32,
    /// Far plane for culling (m); depth itself is reverse-Z, infinite.
    pub far: f32,
}

impl PinholeProjection {
    /// A projection with a 1 cm near plane and a 50 m culling distance.
    pub fn new(camera: PinholeCamera) -> Self {
        Self {
            camera,
            near: 0.01,
            far: 50.0,
        }
    }
}

/// The Bevy transform of a pinhole camera (view frame: x right, y up, looking along −z).
pub fn camera_transform(camera: &PinholeCamera) -> Transform {
    iso_to_transform(&camera.world_from_view())
}

/// Depth bias of static scenery (the simulated room's props, the mask's occluders):
/// they win depth ties with the robot. A robot face lying exactly in a desk's plane (the base's
/// underside on the desk) otherwise z-fights, speckling the frame, the truth and the mask
/// differently from run to run (measured: 109 px around the base, IoU 0.992 instead of 1.0 on
/// still frames).
pub const SCENERY_DEPTH_BIAS: f32 = 16.0;

/// A `width × height` 2-D image filled with opaque black, in `format` (one of the RGBA8
/// formats), usable as `usage` says.
pub fn rgba8_image(width: u32, height: u32, format: TextureFormat, usage: TextureUsages) -> Image {
    filled_image(width, height, format, &[0, 0, 0, 255], usage)
}

/// A `width × height` 2-D image of `format` with every pixel `pixel` (its bytes), usable as
/// `usage` says.
pub fn filled_image(
    width: u32,
    height: u32,
    format: TextureFormat,
    pixel: &[u8],
    usage: TextureUsages,
) -> Image {
    let mut image = Image::new_fill(
        Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        pixel,
        format,
        RenderAssetUsages::default(),
    );
    image.texture_descriptor.usage = usage;
    image
}

/// A render target image of the camera's size (sRGB, read back and sampled).
pub fn target_image(width: u32, height: u32) -> Image {
    rgba8_image(
        width,
        height,
        TextureFormat::Rgba8UnormSrgb,
        TextureUsages::TEXTURE_BINDING
            | TextureUsages::COPY_SRC
            | TextureUsages::COPY_DST
            | TextureUsages::RENDER_ATTACHMENT,
    )
}

/// Spawns a camera that renders `layers` of the world through `camera` into `target`, its
/// render timed on the GPU under `name` ([`GpuTimed`]).
pub fn spawn_pinhole_camera(
    commands: &mut Commands,
    camera: &PinholeCamera,
    target: Handle<Image>,
    layers: RenderLayers,
    clear: Color,
    order: isize,
    name: &str,
) -> Entity {
    commands
        .spawn((
            Name::new(name.to_owned()),
            Camera3d::default(),
            Camera {
                order,
                clear_color: ClearColorConfig::Custom(clear),
                ..default()
            },
            RenderTarget::Image(target.into()),
            Projection::custom(PinholeProjection::new(*camera)),
            camera_transform(camera),
            Tonemapping::None,
            DebandDither::Disabled,
            Msaa::Off,
            layers,
            GpuTimed(name.to_owned()),
        ))
        .id()
}

impl CameraProjection for PinholeProjection {
    fn get_clip_from_view(&self) -> Mat4 {
        let m = self.camera.clip_from_view(f64::from(self.near));
        Mat4::from_cols_array(&std::array::from_fn(|i| m.as_slice()[i] as f32))
    }

    fn get_clip_from_view_for_sub(&self, _sub_view: &SubCameraView) -> Mat4 {
        self.get_clip_from_view()
    }

    fn update(&mut self, _width: f32, _height: f32) {
        // The intrinsics fix the projection; the target is sized to them.
    }

    fn far(&self) -> f32 {
        self.far
    }

    fn get_frustum_corners(&self, z_near: f32, z_far: f32) -> [Vec3A; 8] {
        let k = &self.camera.intrinsics;
        let (w, h) = (k.width as f32, k.height as f32);
        let corner = |u: f32, v: f32, z: f32| {
            let d = z.abs();
            Vec3A::new(
                (u - 0.5 - k.cx as f32) / k.fx as f32 * d,
                -(v - 0.5 - k.cy as f32) / k.fy as f32 * d,
                z,
            )
        };
        // Raster corners: (0,0) is the top-left corner of the image.
        let ring = |z| {
            [
                corner(w, h, z),
                corner(w, 0.0, z),
                corner(0.0, 0.0, z),
                corner(0.0, h, z),
            ]
        };
        let [a, b, c, d] = ring(z_near);
        let [e, f, g, hh] = ring(z_far);
        [a, b, c, d, e, f, g, hh]
    }
}

/// Which frames (Bevy's [`FrameCount`] as the render world saw it) ended their rendering with
/// no pipeline still being compiled: every draw of such a frame had its pipeline, so what it
/// rendered is complete. Shared by the main and the render world ([`RenderSettledPlugin`]).
#[derive(Resource, Debug, Clone, Default)]
pub struct RenderSettled(Arc<SettledFrames>);

/// The record behind [`RenderSettled`].
#[derive(Debug, Default)]
struct SettledFrames {
    /// The newest complete frame (0 before the first).
    last_complete: AtomicU32,
    /// The newest incomplete frames, oldest first, at most [`RenderSettled::INCOMPLETE_KEPT`].
    incomplete: Mutex<VecDeque<u32>>,
}

impl RenderSettled {
    /// Incomplete frames remembered for [`RenderSettled::completed`] (about a minute at 60
    /// updates a second).
    pub const INCOMPLETE_KEPT: usize = 4096;

    /// The frame number the render of this update carries, read from the main world's
    /// [`FrameCount`] before Bevy's `update_frame_count` (in `Last`) adds one to it: the number
    /// that [`RenderSettled::completed`] answers for once this update has rendered.
    pub fn this_update_frame(count: &FrameCount) -> u32 {
        count.0.wrapping_add(1)
    }

    /// The newest complete frame (0 before the first).
    pub fn last_complete_frame(&self) -> u32 {
        self.0.last_complete.load(Ordering::Acquire)
    }

    /// Notes that `frame` rendered completely (the render world does, after each frame).
    pub fn note_complete(&self, frame: u32) {
        self.0.last_complete.fetch_max(frame, Ordering::AcqRel);
    }

    /// Notes that `frame` rendered with a pipeline still compiling (what it drew may miss
    /// meshes).
    pub fn note_incomplete(&self, frame: u32) {
        let mut incomplete = self.incomplete();
        incomplete.push_back(frame);
        while incomplete.len() > Self::INCOMPLETE_KEPT {
            incomplete.pop_front();
        }
    }

    /// Whether `frame` itself rendered completely: a complete frame has been noted at or after
    /// it and it is not among the incomplete ones remembered. (A later complete frame alone
    /// does not make an earlier one complete: a view spawned later compiles its pipelines
    /// then.) Frames older than the incomplete ones remembered count as complete when a later
    /// frame was.
    pub fn completed(&self, frame: u32) -> bool {
        let last = self.last_complete_frame();
        last > 0 && frame <= last && !self.incomplete().contains(&frame)
    }

    fn incomplete(&self) -> std::sync::MutexGuard<'_, VecDeque<u32>> {
        // A render thread that panicked while holding it left a whole list.
        self.0
            .incomplete
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// Keeps [`RenderSettled`] up to date. Added by the plugins that render a view only when what
/// it shows changes ([`add_render_settled`]).
pub struct RenderSettledPlugin;

/// Adds [`RenderSettledPlugin`] unless it is there already.
pub fn add_render_settled(app: &mut App) {
    if !app.is_plugin_added::<RenderSettledPlugin>() {
        app.add_plugins(RenderSettledPlugin);
    }
}

impl Plugin for RenderSettledPlugin {
    fn build(&self, app: &mut App) {
        let settled = RenderSettled::default();
        app.insert_resource(settled.clone());
        if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
            render_app.insert_resource(settled).add_systems(
                RenderGraph,
                note_complete_frame.in_set(RenderGraphSystems::Finish),
            );
        }
    }
}

fn note_complete_frame(
    cache: Res<PipelineCache>,
    frame: Res<FrameCount>,
    settled: Res<RenderSettled>,
) {
    if cache.waiting_pipelines().next().is_none() {
        settled.note_complete(frame.0);
    } else {
        settled.note_incomplete(frame.0);
    }
}

#[cfg(test)]
mod tests {
    use super::RenderSettled;

    /// A frame is complete when it was not noted incomplete and a frame at or after it was
    /// complete; incomplete frames past the record's length are forgotten.
    #[test]
    fn each_frame_s_own_completion_is_kept() {
        let settled = RenderSettled::default();
        assert!(!settled.completed(0) && !settled.completed(1));
        settled.note_incomplete(1);
        settled.note_complete(2);
        settled.note_incomplete(3);
        settled.note_complete(4);
        assert_eq!(settled.last_complete_frame(), 4);
        assert!(!settled.completed(1) && settled.completed(2));
        assert!(!settled.completed(3) && settled.completed(4));
        assert!(!settled.completed(5), "not rendered yet");
        let kept = RenderSettled::INCOMPLETE_KEPT as u32;
        for frame in 5..5 + kept {
            settled.note_incomplete(frame);
        }
        settled.note_complete(5 + kept);
        assert!(settled.completed(1) && settled.completed(3), "forgotten");
        assert!(!settled.completed(5) && !settled.completed(4 + kept));
    }
}
