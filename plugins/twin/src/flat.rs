//! Flat silhouettes without a camera: the paper's service layer ("a digital twin in white in
//! front of a black panel, recorded by a virtual eye") at the cost of its arithmetic.
//!
//! A [`FlatView`] draws every [`FlatPart`] on its [`RenderLayers`] in the part's grey level
//! (255 the robot, 0 what hides it) through a pinhole camera into an `R8Unorm` image, cleared to
//! its own level, with a depth test and nothing else: no lighting, tonemapping, MSAA,
//! intermediate texture or copy into the target, and no Bevy camera (whose fixed cost per
//! render, on a software rasteriser, is several times a full-frame pass; see docs/erase.md).
//! One grey channel is all a flat-shaded silhouette holds: read as RGBA it is `(v, v, v, 255)`.
//!
//! Meshes are Bevy's own (the mesh allocator's buffers, position attribute only); each part's
//! world transform is its [`GlobalTransform`] of this update. Depth is reverse-Z, infinite,
//! `GreaterEqual` and `Depth32Float`, as in Bevy's 3-D pipelines; [`FlatPart::scenery`] parts
//! carry [`SCENERY_DEPTH_BIAS`] as a constant depth bias and win depth ties, as the room's
//! lit scenery does. No face is culled (see `spawn`'s double-sided twins).
//!
//! Views render in the root render graph before the cameras ([`FlatSystems::Render`]), only in
//! an update where [`FlatView::active`] is set; each render is timed on the GPU under the
//! view's name ([`crate::gpu_timing`]).

use std::collections::HashMap;
use std::num::NonZeroU64;

use avatarm_core::vision::camera::PinholeCamera;
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::camera::CameraProjection;
use bevy::camera::visibility::RenderLayers;
use bevy::core_pipeline::schedule::camera_driver;
use bevy::mesh::{MeshVertexBufferLayoutRef, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::mesh::allocator::MeshAllocator;
use bevy::render::mesh::{RenderMesh, RenderMeshBufferInfo};
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::binding_types::{
    storage_buffer_read_only_sized, uniform_buffer_sized,
};
use bevy::render::render_resource::{
    BindGroup, BindGroupEntries, BindGroupLayoutDescriptor, BindGroupLayoutEntries, Buffer,
    BufferDescriptor, BufferUsages, CachedRenderPipelineId, ColorTargetState, ColorWrites,
    CompareFunction, DepthBiasState, DepthStencilState, Extent3d, FragmentState, LoadOp,
    Operations, PipelineCache, PrimitiveState, RenderPassColorAttachment,
    RenderPassDepthStencilAttachment, RenderPassDescriptor, RenderPipelineDescriptor, ShaderStages,
    StoreOp, TextureDescriptor, TextureDimension, TextureFormat, TextureUsages, TextureView,
    TextureViewDescriptor, VertexState,
};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderGraph, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};
use bevy::shader::Shader;

use crate::camera::{PinholeProjection, SCENERY_DEPTH_BIAS, camera_transform, filled_image};
use crate::gpu_timing::{GpuClock, GpuTimingPlugin};

/// Something a [`FlatView`] draws: this entity's [`Mesh3d`] at its [`GlobalTransform`], on its
/// [`RenderLayers`] (layer 0 without), while visible in the hierarchy.
#[derive(Component, Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlatPart {
    /// The grey level it is drawn in (255: the robot, 0: what hides it).
    pub level: u8,
    /// Static scenery: wins depth ties with the robot ([`SCENERY_DEPTH_BIAS`]).
    pub scenery: bool,
}

impl FlatPart {
    /// The robot, in white.
    pub const ROBOT: Self = Self {
        level: 255,
        scenery: false,
    };
    /// Scenery that hides the robot, in black.
    pub const OCCLUDER: Self = Self {
        level: 0,
        scenery: true,
    };
}

/// A virtual eye that draws the [`FlatPart`]s on this entity's [`RenderLayers`] (layer 0
/// without) into `target`.
#[derive(Component, Debug, Clone)]
pub struct FlatView {
    /// The camera: its intrinsics must be the target's size, its pose is the eye's.
    pub camera: PinholeCamera,
    /// An `R8Unorm` render target of the camera's size ([`flat_target_image`]).
    pub target: Handle<Image>,
    /// The level the target is cleared to.
    pub clear: u8,
    /// Renders in this update (set it only when something it draws has changed).
    pub active: bool,
    /// Its name, for the GPU timing.
    pub name: String,
}

/// An `R8Unorm` image a [`FlatView`] renders into, sampled by later passes and read back.
pub fn flat_target_image(width: u32, height: u32) -> Image {
    filled_image(
        width,
        height,
        TextureFormat::R8Unorm,
        &[0],
        TextureUsages::RENDER_ATTACHMENT
            | TextureUsages::TEXTURE_BINDING
            | TextureUsages::COPY_SRC
            | TextureUsages::COPY_DST,
    )
}

/// The flat renderer's system set (root render graph, before the cameras): passes that sample
/// a flat view's image go after it.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FlatSystems {
    /// Every active [`FlatView`] renders (`RenderGraph`).
    Render,
}

/// Draws [`FlatView`]s. Added by the plugins that use it ([`add_flat_render`]).
pub struct FlatRenderPlugin;

/// Adds [`FlatRenderPlugin`] (and [`GpuTimingPlugin`]) unless they are there already.
pub fn add_flat_render(app: &mut App) {
    if !app.is_plugin_added::<FlatRenderPlugin>() {
        app.add_plugins(FlatRenderPlugin);
    }
}

impl Plugin for FlatRenderPlugin {
    fn build(&self, app: &mut App) {
        embedded_asset!(app, "flat.wgsl");
        if !app.is_plugin_added::<GpuTimingPlugin>() {
            app.add_plugins(GpuTimingPlugin);
        }
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        render_app
            .init_resource::<ExtractedFlat>()
            .configure_sets(RenderGraph, FlatSystems::Render.before(camera_driver))
            .add_systems(RenderStartup, init_flat_pipelines)
            .add_systems(ExtractSchedule, extract_flat)
            .add_systems(
                Render,
                prepare_flat.in_set(RenderSystems::PrepareBindGroups),
            )
            .add_systems(RenderGraph, render_flat_views.in_set(FlatSystems::Render));
    }
}

/// A view as extracted for this frame.
struct ExtractedView {
    entity: Entity,
    name: String,
    clip_from_world: Mat4,
    target: AssetId<Image>,
    clear: f64,
    layers: RenderLayers,
    size: UVec2,
}

/// A part as extracted for this frame.
struct ExtractedPart {
    mesh: AssetId<Mesh>,
    world_from_local: Mat4,
    level: f32,
    scenery: bool,
    layers: RenderLayers,
}

/// What the active views draw this frame.
#[derive(Resource, Default)]
struct ExtractedFlat {
    views: Vec<ExtractedView>,
    parts: Vec<ExtractedPart>,
    /// Every flat view entity, active or not: the GPU state of one that is gone is dropped.
    existing: Vec<Entity>,
}

/// The clip-from-world matrix of a pinhole camera, as a Bevy camera with
/// [`PinholeProjection`] at [`camera_transform`] computes it (f32, reverse-Z, infinite).
pub fn clip_from_world(camera: &PinholeCamera) -> Mat4 {
    let clip_from_view = PinholeProjection::new(*camera).get_clip_from_view();
    clip_from_view * camera_transform(camera).to_matrix().inverse()
}

/// A flat part as the extraction reads it.
type PartQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Mesh3d,
        &'static GlobalTransform,
        &'static FlatPart,
        Option<&'static RenderLayers>,
        &'static InheritedVisibility,
    ),
>;

fn extract_flat(
    mut extracted: ResMut<ExtractedFlat>,
    views: Extract<Query<(Entity, &FlatView, Option<&RenderLayers>)>>,
    parts: Extract<PartQuery>,
) {
    extracted.views.clear();
    extracted.parts.clear();
    extracted.existing.clear();
    for (entity, view, layers) in &views {
        extracted.existing.push(entity);
        if !view.active {
            continue;
        }
        let k = &view.camera.intrinsics;
        extracted.views.push(ExtractedView {
            entity,
            name: view.name.clone(),
            clip_from_world: clip_from_world(&view.camera),
            target: view.target.id(),
            clear: f64::from(view.clear) / 255.0,
            layers: layers.cloned().unwrap_or_default(),
            size: UVec2::new(k.width, k.height),
        });
    }
    if extracted.views.is_empty() {
        return;
    }
    for (mesh, transform, part, layers, visible) in &parts {
        if !visible.get() {
            continue;
        }
        extracted.parts.push(ExtractedPart {
            mesh: mesh.id(),
            world_from_local: transform.to_matrix(),
            level: f32::from(part.level) / 255.0,
            scenery: part.scenery,
            layers: layers.cloned().unwrap_or_default(),
        });
    }
}

/// One part's entry in the draws buffer (`flat.wgsl`'s `Draw`).
#[derive(Clone, Copy)]
struct DrawEntry {
    world_from_local: Mat4,
    level: f32,
}

const DRAW_BYTES: u64 = 80;
const VIEW_BYTES: u64 = 64;

impl DrawEntry {
    fn bytes(&self, out: &mut Vec<u8>) {
        for v in self.world_from_local.to_cols_array() {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in [self.level, 0.0, 0.0, 0.0] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

/// A view's GPU resources, kept between frames.
struct ViewGpu {
    size: UVec2,
    depth: TextureView,
    uniform: Buffer,
    /// The bind group and the draws buffer's generation it binds.
    bind_group: Option<(BindGroup, u64)>,
}

/// A draw of this frame: the part's index in the draws buffer and its pipeline.
struct PreparedDraw {
    part: u32,
    mesh: AssetId<Mesh>,
    pipeline: CachedRenderPipelineId,
}

/// Pipelines (one per vertex layout and depth bias), per-view resources, this frame's draws.
#[derive(Resource)]
struct FlatPipelines {
    layout: BindGroupLayoutDescriptor,
    shader: Handle<Shader>,
    pipelines: HashMap<(MeshVertexBufferLayoutRef, bool), CachedRenderPipelineId>,
    views: HashMap<Entity, ViewGpu>,
    /// The draws buffer, its size (bytes) and generation (bumped on each reallocation).
    draws: Option<(Buffer, u64, u64)>,
    /// Per extracted view (same order): its draws.
    frame: Vec<Vec<PreparedDraw>>,
    warned: bool,
}

fn init_flat_pipelines(mut commands: Commands, asset_server: Res<AssetServer>) {
    let layout = BindGroupLayoutDescriptor::new(
        "flat silhouette",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::VERTEX,
            (
                uniform_buffer_sized(false, NonZeroU64::new(VIEW_BYTES)),
                storage_buffer_read_only_sized(false, NonZeroU64::new(DRAW_BYTES)),
            ),
        ),
    );
    commands.insert_resource(FlatPipelines {
        layout,
        shader: load_embedded_asset!(asset_server.as_ref(), "flat.wgsl"),
        pipelines: HashMap::new(),
        views: HashMap::new(),
        draws: None,
        frame: Vec::new(),
        warned: false,
    });
}

impl FlatPipelines {
    /// The pipeline for a mesh layout and depth bias, queued on first use.
    fn pipeline(
        &mut self,
        cache: &PipelineCache,
        layout: &MeshVertexBufferLayoutRef,
        scenery: bool,
    ) -> Option<CachedRenderPipelineId> {
        if let Some(id) = self.pipelines.get(&(layout.clone(), scenery)) {
            return Some(*id);
        }
        let buffer = layout
            .0
            .get_layout(&[Mesh::ATTRIBUTE_POSITION.at_shader_location(0)])
            .ok()?;
        let id = cache.queue_render_pipeline(RenderPipelineDescriptor {
            label: Some("flat silhouette".into()),
            layout: vec![self.layout.clone()],
            vertex: VertexState {
                shader: self.shader.clone(),
                entry_point: Some("vertex".into()),
                buffers: vec![buffer],
                ..default()
            },
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                entry_point: Some("fragment".into()),
                targets: vec![Some(ColorTargetState {
                    format: TextureFormat::R8Unorm,
                    blend: None,
                    write_mask: ColorWrites::ALL,
                })],
                ..default()
            }),
            primitive: PrimitiveState {
                topology: PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..default()
            },
            depth_stencil: Some(DepthStencilState {
                format: TextureFormat::Depth32Float,
                depth_write_enabled: Some(true),
                depth_compare: Some(CompareFunction::GreaterEqual),
                stencil: default(),
                bias: DepthBiasState {
                    constant: if scenery {
                        SCENERY_DEPTH_BIAS as i32
                    } else {
                        0
                    },
                    slope_scale: 0.0,
                    clamp: 0.0,
                },
            }),
            ..default()
        });
        self.pipelines.insert((layout.clone(), scenery), id);
        Some(id)
    }
}

fn prepare_flat(
    extracted: Res<ExtractedFlat>,
    pipelines: Option<ResMut<FlatPipelines>>,
    cache: Res<PipelineCache>,
    meshes: Res<RenderAssets<RenderMesh>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    images: Res<RenderAssets<GpuImage>>,
) {
    let Some(mut p) = pipelines else {
        return;
    };
    p.frame.clear();
    // A view despawned (a camera switch) leaves its depth texture and buffers behind otherwise.
    p.views.retain(|e, _| extracted.existing.contains(e));
    if extracted.views.is_empty() {
        return;
    }
    // Every part once in the draws buffer; each view draws those on its layers.
    let mut bytes = Vec::with_capacity(extracted.parts.len() * DRAW_BYTES as usize);
    for part in &extracted.parts {
        DrawEntry {
            world_from_local: part.world_from_local,
            level: part.level,
        }
        .bytes(&mut bytes);
    }
    if bytes.is_empty() {
        bytes.resize(DRAW_BYTES as usize, 0);
    }
    let needed = bytes.len() as u64;
    if p.draws.as_ref().is_none_or(|(_, size, _)| *size < needed) {
        let size = needed.next_power_of_two().max(DRAW_BYTES * 64);
        let buffer = device.create_buffer(&BufferDescriptor {
            label: Some("flat silhouette draws"),
            size,
            usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let generation = p.draws.as_ref().map_or(0, |d| d.2 + 1);
        p.draws = Some((buffer, size, generation));
    }
    let Some((draws, generation)) = p.draws.as_ref().map(|(b, _, g)| (b.clone(), *g)) else {
        return;
    };
    queue.write_buffer(&draws, 0, &bytes);
    let layout = cache.get_bind_group_layout(&p.layout);
    let mut frame = Vec::with_capacity(extracted.views.len());
    for view in &extracted.views {
        // Not prepared yet (the first frames): nothing to draw into, nothing to say.
        let target = images
            .get(view.target)
            .map(|i| (i.texture.width(), i.texture.height()));
        let size_ok = target == Some((view.size.x, view.size.y));
        let state = p.views.entry(view.entity).or_insert_with(|| ViewGpu {
            size: UVec2::ZERO,
            depth: depth_texture(&device, UVec2::ONE),
            uniform: device.create_buffer(&BufferDescriptor {
                label: Some("flat silhouette view"),
                size: VIEW_BYTES,
                usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            bind_group: None,
        });
        if state.size != view.size {
            state.size = view.size;
            state.depth = depth_texture(&device, view.size);
        }
        let m: Vec<u8> = view
            .clip_from_world
            .to_cols_array()
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        queue.write_buffer(&state.uniform, 0, &m);
        // A view that did not render when the draws buffer was reallocated still binds the old
        // one: rebuilt by generation, not by this frame's reallocation.
        if state.bind_group.as_ref().is_none_or(|b| b.1 != generation) {
            let group = device.create_bind_group(
                "flat silhouette",
                &layout,
                &BindGroupEntries::sequential((
                    state.uniform.as_entire_binding(),
                    draws.as_entire_binding(),
                )),
            );
            state.bind_group = Some((group, generation));
        }
        let mut list = Vec::new();
        if size_ok {
            for (i, part) in extracted.parts.iter().enumerate() {
                if !part.layers.intersects(&view.layers) {
                    continue;
                }
                let Some(mesh) = meshes.get(part.mesh) else {
                    continue;
                };
                if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
                    if !p.warned {
                        warn!(
                            "flat view '{}': a mesh that is not a triangle list is not drawn",
                            view.name
                        );
                        p.warned = true;
                    }
                    continue;
                }
                let layout = mesh.layout.clone();
                if let Some(pipeline) = p.pipeline(&cache, &layout, part.scenery) {
                    list.push(PreparedDraw {
                        part: i as u32,
                        mesh: part.mesh,
                        pipeline,
                    });
                }
            }
        } else if let Some((w, h)) = target
            && !p.warned
        {
            warn!(
                "flat view '{}': its target is {w}x{h}, not the camera's {}x{}; not drawn",
                view.name, view.size.x, view.size.y
            );
            p.warned = true;
        }
        frame.push(list);
    }
    p.frame = frame;
}

fn depth_texture(device: &RenderDevice, size: UVec2) -> TextureView {
    device
        .create_texture(&TextureDescriptor {
            label: Some("flat silhouette depth"),
            size: Extent3d {
                width: size.x.max(1),
                height: size.y.max(1),
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: TextureDimension::D2,
            format: TextureFormat::Depth32Float,
            usage: TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        })
        .create_view(&TextureViewDescriptor::default())
}

#[expect(clippy::too_many_arguments, reason = "a render system's inputs")]
fn render_flat_views(
    extracted: Res<ExtractedFlat>,
    pipelines: Option<Res<FlatPipelines>>,
    cache: Res<PipelineCache>,
    meshes: Res<RenderAssets<RenderMesh>>,
    allocator: Res<MeshAllocator>,
    images: Res<RenderAssets<GpuImage>>,
    mut clock: Option<ResMut<GpuClock>>,
    mut ctx: RenderContext,
) {
    let Some(p) = pipelines else {
        return;
    };
    for (view, draws) in extracted.views.iter().zip(&p.frame) {
        let (Some(target), Some(state)) = (images.get(view.target), p.views.get(&view.entity))
        else {
            continue;
        };
        let Some((bind_group, _)) = &state.bind_group else {
            continue;
        };
        // Every draw's pipeline, mesh and buffers, or nothing: a view missing a part (its
        // pipeline still compiling) keeps its last image rather than a silhouette with holes.
        let ready: Option<Vec<_>> = draws
            .iter()
            .map(|d| {
                let pipeline = cache.get_render_pipeline(d.pipeline)?;
                let mesh = meshes.get(d.mesh)?;
                let vertices = allocator.mesh_vertex_slice(&d.mesh)?;
                let indices = match &mesh.buffer_info {
                    RenderMeshBufferInfo::Indexed {
                        count,
                        index_format,
                    } => Some((allocator.mesh_index_slice(&d.mesh)?, *count, *index_format)),
                    RenderMeshBufferInfo::NonIndexed => None,
                };
                Some((d.part, pipeline, mesh.vertex_count, vertices, indices))
            })
            .collect();
        let Some(ready) = ready else {
            continue;
        };
        let encoder = ctx.command_encoder();
        let span = clock.as_mut().and_then(|c| c.begin(encoder, &view.name));
        {
            let mut pass = encoder.begin_render_pass(&RenderPassDescriptor {
                label: Some("flat silhouette"),
                color_attachments: &[Some(RenderPassColorAttachment {
                    view: &target.texture_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: Operations {
                        load: LoadOp::Clear(wgpu::Color {
                            r: view.clear,
                            g: 0.0,
                            b: 0.0,
                            a: 1.0,
                        }),
                        store: StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(RenderPassDepthStencilAttachment {
                    view: &state.depth,
                    depth_ops: Some(Operations {
                        load: LoadOp::Clear(0.0),
                        store: StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &**bind_group, &[]);
            for (part, pipeline, vertex_count, vertices, indices) in ready {
                pass.set_pipeline(pipeline);
                pass.set_vertex_buffer(0, *vertices.buffer.slice(..));
                let instances = part..part + 1;
                match indices {
                    Some((indices, count, format)) => {
                        pass.set_index_buffer(*indices.buffer.slice(..), format);
                        pass.draw_indexed(
                            indices.range.start..indices.range.start + count,
                            vertices.range.start as i32,
                            instances,
                        );
                    }
                    None => pass.draw(
                        vertices.range.start..vertices.range.start + vertex_count,
                        instances,
                    ),
                }
            }
        }
        if let (Some(c), Some(span)) = (clock.as_mut(), span) {
            c.end(ctx.command_encoder(), span);
        }
    }
}
