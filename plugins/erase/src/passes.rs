//! The erase passes in the render world: the live frame and H uploaded into textures of their
//! own, then threshold, dilation, feathering and composite (`erase.wgsl`) as full-target
//! triangles with no camera, after the mask twin's flat render ([`FlatSystems::Render`]) and
//! before every camera, so that a frame is masked, erased and shown in one update.
//!
//! Passes per camera frame, by the mask's radius `r = dilate + feather` and `f = feather`:
//! one (`r = 0`: threshold and composite fused), two (`f = 0`: row maxima, then column maxima
//! and composite) or four (row maxima, column maxima into M, row sums, column sums and
//! composite). Separable windows because a square max is a row max then a column max and a box
//! sum is a row sum then a column sum: `2r + 1` loads per pixel per pass instead of
//! `(2r + 1)²` in one, the same result (edges repeat), and no workgroup tile that bounds `r`.
//!
//! Each pass, and the uploads' copies, are timed on the GPU ([`avatarm_twin::gpu_timing`]),
//! named by [`EraseJob::label`] and [`PASS_NAMES`]; the CPU side of an upload (the copy into
//! a staging buffer) is recorded as `upload (CPU)`.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

use avatarm_core::dr::{EraseSettings, Photometric};
use avatarm_core::vision::distortion::{DistortionMap, NO_TEXEL};
use avatarm_twin::flat::FlatSystems;
use avatarm_twin::gpu_timing::{GpuClock, GpuTimes};
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::core_pipeline::FullscreenShader;
use bevy::core_pipeline::schedule::camera_driver;
use bevy::prelude::*;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::binding_types::{texture_2d, uniform_buffer};
use bevy::render::render_resource::{
    BindGroup, BindGroupEntries, BindGroupLayoutDescriptor, BindGroupLayoutEntries, Buffer,
    BufferDescriptor, BufferUsages, CachedRenderPipelineId, ColorTargetState, ColorWrites,
    Extent3d, FragmentState, LoadOp, Operations, PipelineCache, RenderPassColorAttachment,
    RenderPassDescriptor, RenderPipelineDescriptor, ShaderStages, ShaderType, StoreOp,
    TexelCopyBufferInfo, TexelCopyBufferLayout, TexelCopyTextureInfo, Texture, TextureDescriptor,
    TextureDimension, TextureFormat, TextureSampleType, TextureUsages, TextureView,
    TextureViewDescriptor, UniformBuffer,
};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderGraph, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};
use bevy::shader::Shader;

/// The passes' span names, in order: the mask twin's flat render, the row and column maxima,
/// the row sums and the composite (which also thresholds, and takes the column maxima or sums,
/// when a pass before it is left out).
pub const PASS_NAMES: [&str; 5] = [
    "mask twin",
    "dilate rows",
    "dilate columns",
    "feather rows",
    "composite",
];

/// The span of the live frame's and H's copies from their staging buffers (GPU).
pub const UPLOAD_SPAN: &str = "upload";

/// The span of the same uploads' copies into the staging buffers (CPU, ms of this thread).
pub const UPLOAD_CPU_SPAN: &str = "upload (CPU)";

/// The span of [`EraseJob::measure_floor`]'s copy.
pub const FLOOR_SPAN: &str = "copy floor";

/// One camera's erase work for this update (main world; extracted in every update that has
/// something to upload or render).
#[derive(Component, Debug, Clone)]
pub struct EraseJob {
    /// Prefix of the job's span names (empty for a single camera).
    pub label: String,
    /// The mask twin's flat render (`R8Unorm`, at `resolution_scale`).
    pub raw: Handle<Image>,
    /// M(t) (`R8Unorm`, 0 or 1, the camera's size).
    pub mask: Handle<Image>,
    /// Ĩ(t) (`Rgba8UnormSrgb` with an `Rgba8Unorm` view, the camera's size).
    pub composite: Handle<Image>,
    /// What the passes compute.
    pub params: EraseParams,
    /// Run the passes in this update.
    pub render: bool,
    /// A new live frame to upload in this update (RGBA8, the camera's size).
    pub frame: Option<Arc<Vec<u8>>>,
    /// A new background H to upload in this update (RGBA8, the camera's size).
    pub background: Option<Arc<Vec<u8>>>,
    /// The lens map the mask reads the render through (uploaded once; `None`: a pinhole, and
    /// [`EraseParams::lens`] is 0).
    pub lens: Option<Arc<DistortionMap>>,
    /// After the passes, also time ([`FLOOR_SPAN`]) a plain GPU copy of the images they read
    /// (the mask twin's render, the live frame and H) into scratch textures: the memory floor
    /// `avatarm bench gpu` compares the passes with. Off in the app.
    pub measure_floor: bool,
}

/// The passes' uniforms (`erase.wgsl`'s `EraseParams`).
#[derive(ShaderType, Debug, Clone, Copy, PartialEq, Default)]
pub struct EraseParams {
    /// Lower bounds of the RGBα ranges (8-bit levels).
    pub lo: Vec4,
    /// Upper bounds.
    pub hi: Vec4,
    /// Per-channel gain of H (w unused).
    pub gain: Vec4,
    /// Per-channel offset of H (full scale; w unused).
    pub offset: Vec4,
    /// Size of the mask twin's render (px).
    pub raw_size: UVec2,
    /// Size of the frame (px).
    pub size: UVec2,
    /// The mask's square dilation radius, `dilate + feather` (px).
    pub radius: i32,
    /// Feathering radius (px).
    pub feather: i32,
    /// Opacity of the background panel; 0 while erasing is off or there is no H.
    pub alpha_h: f32,
    /// 1: each pixel reads the mask render at its lens map's texel (the render is the map's
    /// pinhole); 0: at its nearest texel by scale.
    pub lens: u32,
}

impl EraseParams {
    /// The uniforms for `settings`, a photometric model, whether H exists, and the sizes of the
    /// mask twin's render and of the frame.
    pub fn new(
        settings: &EraseSettings,
        photometric: &Photometric,
        have_background: bool,
        raw_size: UVec2,
        size: UVec2,
    ) -> Self {
        Self {
            lo: Vec4::from_array(settings.ranges.map(|r| f32::from(r[0]))),
            hi: Vec4::from_array(settings.ranges.map(|r| f32::from(r[1]))),
            gain: Vec3::from_array(photometric.gain).extend(1.0),
            offset: Vec3::from_array(photometric.offset).extend(0.0),
            raw_size,
            size,
            radius: settings.mask_radius() as i32,
            feather: settings.feather_px as i32,
            alpha_h: if settings.enabled && have_background {
                settings.alpha_h
            } else {
                0.0
            },
            lens: 0,
        }
    }

    /// The same, the mask read through a lens map (`true`) or by scale.
    pub fn through_lens(self, lens: bool) -> Self {
        Self {
            lens: u32::from(lens),
            ..self
        }
    }

    /// The passes these uniforms need, in order (indices into [`PASS_NAMES`], the mask twin's
    /// render left out).
    pub fn passes(&self) -> &'static [Pass] {
        match (self.radius > 0, self.feather > 0) {
            (false, _) => &[Pass::CompositeThreshold],
            (true, false) => &[Pass::DilateRows, Pass::CompositeDilated],
            (true, true) => &[
                Pass::DilateRows,
                Pass::DilateColumns,
                Pass::FeatherRows,
                Pass::CompositeFeathered,
            ],
        }
    }
}

/// One full-target pass of `erase.wgsl`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Pass {
    /// Threshold and composite in one (`r = 0`).
    CompositeThreshold,
    /// Row maxima of the thresholded twin.
    DilateRows,
    /// Column maxima and composite in one (`f = 0`).
    CompositeDilated,
    /// Column maxima: M.
    DilateColumns,
    /// Row sums of M.
    FeatherRows,
    /// Column sums and composite.
    CompositeFeathered,
}

impl Pass {
    const ALL: [Pass; 6] = [
        Pass::CompositeThreshold,
        Pass::DilateRows,
        Pass::CompositeDilated,
        Pass::DilateColumns,
        Pass::FeatherRows,
        Pass::CompositeFeathered,
    ];

    fn entry_point(self) -> &'static str {
        match self {
            Pass::CompositeThreshold => "composite_threshold",
            Pass::DilateRows => "dilate_rows",
            Pass::CompositeDilated => "composite_dilated",
            Pass::DilateColumns => "dilate_columns",
            Pass::FeatherRows => "feather_rows",
            Pass::CompositeFeathered => "composite_feathered",
        }
    }

    /// Its span name ([`PASS_NAMES`]).
    pub fn name(self) -> &'static str {
        match self {
            Pass::DilateRows => PASS_NAMES[1],
            Pass::DilateColumns => PASS_NAMES[2],
            Pass::FeatherRows => PASS_NAMES[3],
            _ => PASS_NAMES[4],
        }
    }

    fn targets(self) -> &'static [TextureFormat] {
        match self {
            Pass::CompositeThreshold | Pass::CompositeDilated => {
                &[TextureFormat::Rgba8Unorm, TextureFormat::R8Unorm]
            }
            Pass::CompositeFeathered => &[TextureFormat::Rgba8Unorm],
            Pass::DilateRows | Pass::DilateColumns => &[TextureFormat::R8Unorm],
            Pass::FeatherRows => &[TextureFormat::R16Float],
        }
    }
}

/// Renders the [`EraseJob`]s: added by [`crate::ErasePlugin`] (one job, its camera), or by an
/// app that spawns jobs of its own (`avatarm bench gpu`: several cameras) with
/// [`avatarm_twin::flat::FlatRenderPlugin`] before it.
pub struct ErasePassesPlugin;

impl Plugin for ErasePassesPlugin {
    fn build(&self, app: &mut App) {
        embedded_asset!(app, "erase.wgsl");
        // The mask's view renders first, and the GPU timing must exist before its times are.
        avatarm_twin::flat::add_flat_render(app);
        let times = app.world().get_resource::<GpuTimes>().cloned();
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        render_app
            .init_resource::<ExtractedJobs>()
            .insert_resource(UploadTimes(times))
            .add_systems(RenderStartup, init_erase_pipelines)
            .add_systems(ExtractSchedule, extract_jobs)
            .add_systems(
                Render,
                prepare_jobs.in_set(RenderSystems::PrepareBindGroups),
            )
            .add_systems(
                RenderGraph,
                render_jobs.after(FlatSystems::Render).before(camera_driver),
            );
    }
}

/// Where the CPU side of the uploads is recorded.
#[derive(Resource)]
struct UploadTimes(Option<GpuTimes>);

/// The jobs with work this frame, and every job entity (one idle this frame keeps its GPU
/// state: its uploaded background, its lens texture).
#[derive(Resource, Default)]
struct ExtractedJobs(Vec<(Entity, EraseJob)>, Vec<Entity>);

fn extract_jobs(mut extracted: ResMut<ExtractedJobs>, jobs: Extract<Query<(Entity, &EraseJob)>>) {
    extracted.0.clear();
    extracted.1.clear();
    for (entity, job) in &jobs {
        extracted.1.push(entity);
        if job.render || job.frame.is_some() || job.background.is_some() {
            extracted.0.push((entity, job.clone()));
        }
    }
}

/// An RGBA8 texture the CPU fills through a staging buffer of 256-byte aligned rows.
struct Upload {
    texture: Texture,
    view: TextureView,
    staging: Buffer,
    bytes_per_row: u32,
    /// The staging buffer holds new data to copy this frame.
    pending: bool,
}

impl Upload {
    fn new(device: &RenderDevice, label: &'static str, size: UVec2) -> Self {
        let bytes_per_row = (size.x * 4).div_ceil(256) * 256;
        let texture = device.create_texture(&TextureDescriptor {
            label: Some(label),
            size: extent(size),
            mip_level_count: 1,
            sample_count: 1,
            dimension: TextureDimension::D2,
            format: TextureFormat::Rgba8Unorm,
            usage: TextureUsages::TEXTURE_BINDING
                | TextureUsages::COPY_DST
                | TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&TextureViewDescriptor::default());
        let staging = device.create_buffer(&BufferDescriptor {
            label: Some(label),
            size: u64::from(bytes_per_row) * u64::from(size.y),
            usage: BufferUsages::COPY_SRC | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self {
            texture,
            view,
            staging,
            bytes_per_row,
            pending: false,
        }
    }

    /// Copies `rgba` (tightly packed rows of `width` px) into the staging buffer; `false` when
    /// its size is not the texture's.
    fn write(&mut self, queue: &RenderQueue, rgba: &[u8], size: UVec2) -> bool {
        let row = size.x as usize * 4;
        if rgba.len() != row * size.y as usize {
            return false;
        }
        if row == self.bytes_per_row as usize {
            queue.write_buffer(&self.staging, 0, rgba);
        } else {
            let stride = self.bytes_per_row as usize;
            let mut padded = vec![0u8; stride * size.y as usize];
            for (dst, src) in padded.chunks_exact_mut(stride).zip(rgba.chunks_exact(row)) {
                dst[..row].copy_from_slice(src);
            }
            queue.write_buffer(&self.staging, 0, &padded);
        }
        self.pending = true;
        true
    }

    fn copy(&mut self, encoder: &mut bevy::render::render_resource::CommandEncoder, size: UVec2) {
        if !std::mem::take(&mut self.pending) {
            return;
        }
        encoder.copy_buffer_to_texture(
            TexelCopyBufferInfo {
                buffer: &self.staging,
                layout: TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.bytes_per_row),
                    rows_per_image: Some(size.y),
                },
            },
            TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: default(),
                aspect: default(),
            },
            extent(size),
        );
    }
}

fn extent(size: UVec2) -> Extent3d {
    Extent3d {
        width: size.x.max(1),
        height: size.y.max(1),
        depth_or_array_layers: 1,
    }
}

/// One job's GPU resources, kept between frames.
struct JobGpu {
    size: UVec2,
    live: Upload,
    background: Upload,
    /// Row maxima (`R8Unorm`).
    rows: TextureView,
    /// Row sums (`R16Float`).
    sums: TextureView,
    params: UniformBuffer<EraseParams>,
    /// This frame's passes with their bind groups and targets, when the job renders.
    frame: Vec<(Pass, BindGroup, Vec<TextureView>)>,
    /// [`EraseJob::measure_floor`]'s sources and scratch copies, this frame.
    floor: Vec<(Texture, Texture)>,
    /// Scratch textures of the floor's copies, kept between frames.
    scratch: Vec<Texture>,
    /// The last H uploaded: uploaded again when the textures are made anew (a new size).
    background_data: Option<Arc<Vec<u8>>>,
    /// The lens map's texels (`Rg16Uint`, the frame's size; 1x1 without a lens) and the map
    /// they came from.
    lens: (TextureView, Option<Arc<DistortionMap>>),
}

/// The lens map's texels as an `Rg16Uint` texture (1x1 of [`NO_TEXEL`]s without one).
fn lens_texture(
    device: &RenderDevice,
    queue: &RenderQueue,
    map: Option<&DistortionMap>,
) -> TextureView {
    let (size, texels) = match map {
        Some(m) => (
            UVec2::new(m.image.width, m.image.height),
            m.texels.as_slice(),
        ),
        None => (UVec2::ONE, &[[NO_TEXEL; 2]][..]),
    };
    let texture = device.create_texture(&TextureDescriptor {
        label: Some("erase: lens map"),
        size: extent(size),
        mip_level_count: 1,
        sample_count: 1,
        dimension: TextureDimension::D2,
        format: TextureFormat::Rg16Uint,
        usage: TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let bytes: Vec<u8> = texels
        .iter()
        .flat_map(|t| [t[0].to_le_bytes(), t[1].to_le_bytes()])
        .flatten()
        .collect();
    queue.write_texture(
        texture.as_image_copy(),
        &bytes,
        TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(size.x * 4),
            rows_per_image: Some(size.y),
        },
        extent(size),
    );
    texture.create_view(&TextureViewDescriptor::default())
}

#[derive(Resource)]
struct ErasePipelines {
    layout: BindGroupLayoutDescriptor,
    pipelines: HashMap<Pass, CachedRenderPipelineId>,
    jobs: HashMap<Entity, JobGpu>,
    warned: bool,
}

fn init_erase_pipelines(
    mut commands: Commands,
    asset_server: Res<AssetServer>,
    fullscreen: Res<FullscreenShader>,
    cache: Res<PipelineCache>,
) {
    let texture = || texture_2d(TextureSampleType::Float { filterable: false });
    let texels = texture_2d(TextureSampleType::Uint);
    let layout = BindGroupLayoutDescriptor::new(
        "erase passes",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (
                uniform_buffer::<EraseParams>(false),
                texture(),
                texture(),
                texture(),
                texture(),
                texels,
            ),
        ),
    );
    let shader: Handle<Shader> = load_embedded_asset!(asset_server.as_ref(), "erase.wgsl");
    let pipelines = Pass::ALL
        .iter()
        .map(|&pass| {
            let id = cache.queue_render_pipeline(RenderPipelineDescriptor {
                label: Some(format!("erase: {}", pass.entry_point()).into()),
                layout: vec![layout.clone()],
                vertex: fullscreen.to_vertex_state(),
                fragment: Some(FragmentState {
                    shader: shader.clone(),
                    entry_point: Some(pass.entry_point().into()),
                    targets: pass
                        .targets()
                        .iter()
                        .map(|&format| {
                            Some(ColorTargetState {
                                format,
                                blend: None,
                                write_mask: ColorWrites::ALL,
                            })
                        })
                        .collect(),
                    ..default()
                }),
                ..default()
            });
            (pass, id)
        })
        .collect();
    commands.insert_resource(ErasePipelines {
        layout,
        pipelines,
        jobs: HashMap::new(),
        warned: false,
    });
}

fn target_view(
    device: &RenderDevice,
    label: &'static str,
    format: TextureFormat,
    size: UVec2,
) -> TextureView {
    device
        .create_texture(&TextureDescriptor {
            label: Some(label),
            size: extent(size),
            mip_level_count: 1,
            sample_count: 1,
            dimension: TextureDimension::D2,
            format,
            usage: TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
        .create_view(&TextureViewDescriptor::default())
}

#[expect(
    clippy::too_many_lines,
    reason = "the render world's preparation of every erase job in one system: uploads, bind groups and the passes' settings share the job's state"
)]
fn prepare_jobs(
    extracted: Res<ExtractedJobs>,
    pipelines: Option<ResMut<ErasePipelines>>,
    cache: Res<PipelineCache>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    images: Res<RenderAssets<GpuImage>>,
    uploads: Res<UploadTimes>,
) {
    let Some(mut p) = pipelines else {
        return;
    };
    let p = &mut *p;
    // A job despawned (a camera switch) leaves its textures and buffers behind otherwise.
    p.jobs.retain(|e, _| extracted.1.contains(e));
    let layout = cache.get_bind_group_layout(&p.layout);
    for (entity, job) in &extracted.0 {
        let size = job.params.size;
        let gpu = p.jobs.entry(*entity).or_insert_with(|| JobGpu {
            size: UVec2::ZERO,
            live: Upload::new(&device, "erase: live frame", UVec2::ONE),
            background: Upload::new(&device, "erase: background", UVec2::ONE),
            rows: target_view(
                &device,
                "erase: row maxima",
                TextureFormat::R8Unorm,
                UVec2::ONE,
            ),
            sums: target_view(
                &device,
                "erase: row sums",
                TextureFormat::R16Float,
                UVec2::ONE,
            ),
            params: UniformBuffer::default(),
            frame: Vec::new(),
            floor: Vec::new(),
            scratch: Vec::new(),
            background_data: None,
            lens: (lens_texture(&device, &queue, None), None),
        });
        let same_lens = match (&gpu.lens.1, &job.lens) {
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            (None, None) => true,
            _ => false,
        };
        if !same_lens {
            gpu.lens = (
                lens_texture(&device, &queue, job.lens.as_deref()),
                job.lens.clone(),
            );
        }
        let resized = gpu.size != size;
        if resized {
            gpu.size = size;
            gpu.live = Upload::new(&device, "erase: live frame", size);
            gpu.background = Upload::new(&device, "erase: background", size);
            gpu.rows = target_view(&device, "erase: row maxima", TextureFormat::R8Unorm, size);
            gpu.sums = target_view(&device, "erase: row sums", TextureFormat::R16Float, size);
        }
        if let Some(rgba) = &job.background {
            gpu.background_data = Some(rgba.clone());
        }
        let background = job.background.clone().or_else(|| {
            // New textures (a new size) start black: H again.
            resized.then(|| gpu.background_data.clone()).flatten()
        });
        let started = Instant::now();
        let mut bad = Vec::new();
        if let Some(rgba) = &job.frame
            && !gpu.live.write(&queue, rgba, size)
        {
            bad.push("live frame");
        }
        if let Some(rgba) = &background
            && !gpu.background.write(&queue, rgba, size)
        {
            bad.push("background");
        }
        if job.frame.is_some() || background.is_some() {
            let ms = started.elapsed().as_secs_f64() * 1e3;
            if let Some(times) = &uploads.0 {
                times.record(&format!("{}{UPLOAD_CPU_SPAN}", job.label), ms);
            }
        }
        if !bad.is_empty() && !p.warned {
            error!(
                "erase{}: {} not {}x{} RGBA8; not uploaded",
                job.label,
                bad.join(" and "),
                size.x,
                size.y
            );
            p.warned = true;
        }
        gpu.frame.clear();
        gpu.floor.clear();
        if !job.render {
            continue;
        }
        let (Some(raw), Some(mask), Some(composite)) = (
            images.get(&job.raw),
            images.get(&job.mask),
            images.get(&job.composite),
        ) else {
            continue;
        };
        // The lens map is read only when it fits the frame and the render.
        let lens = job.lens.as_ref().is_some_and(|m| {
            UVec2::new(m.image.width, m.image.height) == size
                && UVec2::new(m.pinhole.width, m.pinhole.height) == job.params.raw_size
        });
        if job.lens.is_some() && !lens && !p.warned {
            error!(
                "erase{}: the lens map does not fit the frame or the mask's render; the mask is read by scale",
                job.label
            );
            p.warned = true;
        }
        gpu.params.set(job.params.through_lens(lens));
        gpu.params.write_buffer(&device, &queue);
        let Some(params) = gpu.params.binding() else {
            continue;
        };
        // Ĩ's bytes are the 8-bit values: written through a linear view of the sRGB image.
        let erased = composite.texture.create_view(&TextureViewDescriptor {
            format: Some(TextureFormat::Rgba8Unorm),
            ..default()
        });
        let mask_view = mask.texture_view.clone();
        for &pass in job.params.passes() {
            let (previous, targets): (&TextureView, Vec<TextureView>) = match pass {
                Pass::CompositeThreshold => {
                    (&raw.texture_view, vec![erased.clone(), mask_view.clone()])
                }
                Pass::DilateRows => (&raw.texture_view, vec![gpu.rows.clone()]),
                Pass::CompositeDilated => (&gpu.rows, vec![erased.clone(), mask_view.clone()]),
                Pass::DilateColumns => (&gpu.rows, vec![mask_view.clone()]),
                Pass::FeatherRows => (&mask.texture_view, vec![gpu.sums.clone()]),
                Pass::CompositeFeathered => (&gpu.sums, vec![erased.clone()]),
            };
            let bind_group = device.create_bind_group(
                "erase pass",
                &layout,
                &BindGroupEntries::sequential((
                    params.clone(),
                    &raw.texture_view,
                    &gpu.live.view,
                    &gpu.background.view,
                    previous,
                    &gpu.lens.0,
                )),
            );
            gpu.frame.push((pass, bind_group, targets));
        }
        if job.measure_floor {
            let sources = [
                raw.texture.clone(),
                gpu.live.texture.clone(),
                gpu.background.texture.clone(),
            ];
            let stale = gpu.scratch.len() != sources.len()
                || gpu
                    .scratch
                    .iter()
                    .zip(&sources)
                    .any(|(a, b)| a.size() != b.size() || a.format() != b.format());
            if stale {
                gpu.scratch = sources
                    .iter()
                    .map(|s| {
                        device.create_texture(&TextureDescriptor {
                            label: Some("erase: copy floor"),
                            size: s.size(),
                            mip_level_count: 1,
                            sample_count: 1,
                            dimension: TextureDimension::D2,
                            format: s.format(),
                            usage: TextureUsages::COPY_DST,
                            view_formats: &[],
                        })
                    })
                    .collect();
            }
            gpu.floor = sources
                .into_iter()
                .zip(gpu.scratch.iter().cloned())
                .collect();
        }
    }
}

fn render_jobs(
    extracted: Res<ExtractedJobs>,
    pipelines: Option<ResMut<ErasePipelines>>,
    cache: Res<PipelineCache>,
    mut clock: Option<ResMut<GpuClock>>,
    mut ctx: RenderContext,
) {
    let Some(mut p) = pipelines else {
        return;
    };
    let p = &mut *p;
    for (entity, job) in &extracted.0 {
        let Some(gpu) = p.jobs.get_mut(entity) else {
            continue;
        };
        let size = gpu.size;
        if gpu.live.pending || gpu.background.pending {
            let encoder = ctx.command_encoder();
            let span = clock
                .as_mut()
                .and_then(|c| c.begin(encoder, &format!("{}{UPLOAD_SPAN}", job.label)));
            gpu.live.copy(encoder, size);
            gpu.background.copy(encoder, size);
            if let (Some(c), Some(span)) = (clock.as_mut(), span) {
                c.end(encoder, span);
            }
        }
        // Every pipeline must be ready, or none of this frame's passes runs (a half-erased
        // frame would be worse than the last one).
        let ready: Option<Vec<_>> = gpu
            .frame
            .iter()
            .map(|(pass, _, _)| {
                p.pipelines
                    .get(pass)
                    .and_then(|id| cache.get_render_pipeline(*id))
            })
            .collect();
        let Some(ready) = ready else {
            continue;
        };
        for ((pass, bind_group, targets), pipeline) in gpu.frame.iter().zip(ready) {
            let encoder = ctx.command_encoder();
            let span = clock
                .as_mut()
                .and_then(|c| c.begin(encoder, &format!("{}{}", job.label, pass.name())));
            {
                let attachments: Vec<Option<RenderPassColorAttachment>> = targets
                    .iter()
                    .map(|view| {
                        Some(RenderPassColorAttachment {
                            view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: Operations {
                                load: LoadOp::Clear(wgpu::Color::BLACK),
                                store: StoreOp::Store,
                            },
                        })
                    })
                    .collect();
                let mut render = encoder.begin_render_pass(&RenderPassDescriptor {
                    label: Some("erase pass"),
                    color_attachments: &attachments,
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                render.set_pipeline(pipeline);
                render.set_bind_group(0, &**bind_group, &[]);
                render.draw(0..3, 0..1);
            }
            if let (Some(c), Some(span)) = (clock.as_mut(), span) {
                c.end(ctx.command_encoder(), span);
            }
        }
        if !gpu.floor.is_empty() {
            let encoder = ctx.command_encoder();
            let span = clock
                .as_mut()
                .and_then(|c| c.begin(encoder, &format!("{}{FLOOR_SPAN}", job.label)));
            for (source, scratch) in &gpu.floor {
                encoder.copy_texture_to_texture(
                    source.as_image_copy(),
                    scratch.as_image_copy(),
                    source.size(),
                );
            }
            if let (Some(c), Some(span)) = (clock.as_mut(), span) {
                c.end(encoder, span);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(dilate_px: u32, feather_px: u32, enabled: bool) -> EraseParams {
        let settings = EraseSettings {
            dilate_px,
            feather_px,
            enabled,
            ..EraseSettings::default()
        };
        EraseParams::new(
            &settings,
            &Photometric::default(),
            true,
            UVec2::new(320, 240),
            UVec2::new(640, 480),
        )
    }

    #[test]
    fn the_settings_choose_the_fewest_passes() {
        assert_eq!(params(0, 0, true).passes(), [Pass::CompositeThreshold]);
        assert_eq!(
            params(3, 0, true).passes(),
            [Pass::DilateRows, Pass::CompositeDilated]
        );
        // Feathering alone still dilates by its width (the mask's radius is dilate + feather).
        let p = params(0, 2, true);
        assert_eq!((p.radius, p.feather), (2, 2));
        assert_eq!(
            p.passes(),
            [
                Pass::DilateRows,
                Pass::DilateColumns,
                Pass::FeatherRows,
                Pass::CompositeFeathered
            ]
        );
        // Each pass writes what the next one reads, and the composite is the last.
        for (d, f) in [(0, 0), (3, 0), (3, 2)] {
            let passes = params(d, f, true).passes();
            assert_eq!(passes.last().map(|p| p.name()), Some("composite"));
        }
    }

    #[test]
    fn the_uniforms_carry_the_settings() {
        let p = params(1, 0, true);
        assert_eq!(p.lo, Vec4::splat(240.0));
        assert_eq!(p.hi, Vec4::splat(255.0));
        assert_eq!(
            (p.raw_size, p.size),
            (UVec2::new(320, 240), UVec2::new(640, 480))
        );
        assert_eq!(p.alpha_h, 1.0);
        // Erasing off, or no H: nothing is replaced.
        assert_eq!(params(1, 0, false).alpha_h, 0.0);
        let settings = EraseSettings::default();
        let none = EraseParams::new(
            &settings,
            &Photometric::default(),
            false,
            UVec2::ONE,
            UVec2::ONE,
        );
        assert_eq!(none.alpha_h, 0.0);
        assert_eq!(none.gain, Vec4::ONE);
    }
}
