//! Erasing the robot from the live video, on the GPU (the paper's service and interaction
//! layers).
//!
//! Per camera frame:
//! 1. **Mask twin.** A twin of the robot in unlit white on [`layers::MASK_TWIN`] is posed at
//!    the joint state for the frame: the last received one, or with latency compensation the
//!    state interpolated (or extrapolated from the joint velocities) at the frame's capture
//!    time ([`JointHistory::at`]).
//! 2. **Mask camera.** A camera with the *believed* intrinsics and pose of the real camera
//!    renders that layer alone, white on black, into [`EraseTargets::raw`] (at
//!    `resolution_scale` of the camera's size).
//! 3. **Threshold pass** (`mask.wgsl`): per-channel RGBα ranges give the binary mask M(t),
//!    dilated by `dilate_px + feather_px`, into [`EraseTargets::mask`].
//! 4. **Composite pass** (`composite.wgsl`): the live frame with the background panel in front
//!    at alpha `α_H · a`, `a` the feathered mask, the background after photometric compensation;
//!    into [`EraseTargets::composite`], which is Ĩ(t) before the hand and object twin are drawn
//!    in front ([`interaction`]).
//!
//! **One update.** The three pass cameras render in camera order (mask camera, threshold,
//! composite, then the interaction camera), so a frame that arrives in an update is erased and
//! shown in that update's render. Reading a pass's image back must not use Bevy's
//! `Screenshot::image`: in the frame of a screenshot the camera renders into a temporary texture
//! copied into its image only after every camera, so the next pass would see the previous
//! frame's mask ([`avatarm_twin::readback`] reads an image back without that).
//!
//! Nothing is read back to the CPU on this path. Photometric compensation fits the background
//! to each frame on the CPU (both images are CPU data anyway) outside a conservative robot
//! region: the links' bounding spheres projected by FK ([`avatarm_core::dr::sphere_mask`]).
//! The CPU reference of steps 3–4 is [`avatarm_core::dr`].
//!
//! Modules: [`interaction`] (the panel, the object twins and the interaction camera),
//! [`gpu_timing`] (each pass timed with GPU timestamp queries).

pub mod gpu_timing;
pub mod interaction;

use std::collections::VecDeque;
use std::sync::Arc;

use avatarm_core::dr::{self, EraseSettings, LinkSphere, Photometric, RgbaView};
use avatarm_core::robot::{JointMap, RobotModel};
use avatarm_core::vision::camera::PinholeCamera;
use avatarm_twin::camera::{SCENERY_DEPTH_BIAS, spawn_pinhole_camera, target_image};
use avatarm_twin::layers;
use avatarm_twin::prelude::*;
use avatarm_video::{LiveVideo, VideoSystems};
use bevy::asset::embedded_asset;
use bevy::camera::RenderTarget;
use bevy::camera::visibility::RenderLayers;
use bevy::camera::{OrthographicProjection, ScalingMode};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::pbr::{Material, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::extract_component::ExtractComponent;
use bevy::render::render_resource::{AsBindGroup, ShaderType, TextureFormat, TextureUsages};
use bevy::render::view::Msaa;
use bevy::shader::ShaderRef;
use nalgebra::{DVector, Isometry3};

pub use gpu_timing::{GpuPassTimes, PASS_NAMES, PassTimes};
pub use interaction::{InteractionConfig, InteractionPlugin, InteractionTargets};

/// What most users of the erase pipeline need.
pub mod prelude {
    pub use crate::interaction::{InteractionConfig, InteractionPlugin, ObjectTwinSpec};
    pub use crate::{EraseConfig, ErasePlugin, EraseState, EraseSystems, EraseTargets};
}

/// Render order of the mask camera; the passes follow it.
const MASK_CAMERA_ORDER: isize = -20;

/// What the erase plugin needs to know. Insert it before the app starts.
#[derive(Resource, Debug, Clone)]
pub struct EraseConfig {
    /// Mask and composite options.
    pub settings: EraseSettings,
    /// The camera as the app believes it is (intrinsics + calibrated pose).
    pub camera: PinholeCamera,
    /// The mask twin's description: the robot's own, or a lighter one of the same robot.
    pub model: Arc<RobotModel>,
    /// From the joint states' vectors (the robot's description) to `model`'s.
    pub joint_map: JointMap,
    /// Which geometry of `model` the mask twin draws, and how simplified.
    pub detail: TwinDetail,
    /// The robot's base pose in the world.
    pub base: Isometry3<f64>,
    /// The twin that receives the robot's joint states (its history drives the mask twin).
    pub source_twin: Option<Entity>,
    /// Known static things that can hide the robot from the camera (the desk): drawn black in
    /// the mask camera so that M(t) follows the robot's *visible* pixels. Meshes with their
    /// world transforms.
    pub occluders: Vec<(Mesh, Transform)>,
}

/// Images of the pipeline, all at the camera's size except `raw`.
#[derive(Resource, Debug, Clone)]
pub struct EraseTargets {
    /// The mask twin rendered white on black (at `resolution_scale`).
    pub raw: Handle<Image>,
    /// M(t) after threshold and dilation (white = robot).
    pub mask: Handle<Image>,
    /// Ĩ(t): the live frame with the robot erased.
    pub composite: Handle<Image>,
    /// The live frame as uploaded for the composite.
    pub live: Handle<Image>,
    /// The background H as uploaded (after refreshes).
    pub background: Handle<Image>,
}

/// The mask twin's root entity.
#[derive(Resource, Debug, Clone, Copy)]
pub struct MaskTwin(pub Entity);

/// What the pipeline is doing now.
#[derive(Resource, Debug, Clone, Default)]
pub struct EraseState {
    /// Background H (RGBA8, the camera's size) once one is set.
    pub background: Option<Arc<Vec<u8>>>,
    /// Where it came from (file, capture time, ...).
    pub background_origin: Option<String>,
    /// The photometric model in use.
    pub photometric: Photometric,
    /// Capture time of the frame on the panel.
    pub frame_capture_s: Option<f64>,
    /// Joint time the mask twin is posed at.
    pub mask_stamp_s: Option<f64>,
    /// Frames refused (wrong size).
    pub frames_refused: u64,
    /// The conservative robot region used by the last fit (0/1 per pixel), for refresh and
    /// diagnostics.
    pub robot_region: Option<Arc<Vec<u8>>>,
    /// What the passes work on in this update.
    pub current: Option<PassInputs>,
    /// Renders of each pass so far: mask camera, threshold, composite. Each pass renders
    /// once per camera frame (and when the settings or H change), however fast the display
    /// updates: an XR headset at 72-90 Hz over a 30 fps camera does not redo the mask.
    pub renders: [u64; 3],
    /// Camera frames taken into the pipeline.
    pub frames_in: u64,
    /// H changed since the last update.
    background_changed: bool,
}

/// Marks a camera of the pipeline with the pass it renders, in render order: 0 the mask
/// camera, 1 the threshold pass, 2 the composite pass ([`PASS_NAMES`]).
#[derive(Component, ExtractComponent, Debug, Clone, Copy)]
pub struct ErasePass {
    /// The pass.
    pub stage: usize,
}

/// What the passes work on in one update: the mask camera renders the twin for `frame`, the
/// threshold pass its mask and the composite pass erases it, all in that update's render.
#[derive(Debug, Clone)]
pub struct PassInputs {
    /// The newest frame at that update (capture time, index, pixels).
    pub frame: Option<(f64, u64, Arc<Vec<u8>>)>,
    /// The photometric model fitted to it.
    pub photometric: Photometric,
    /// Background H at that update.
    pub background: Option<Arc<Vec<u8>>>,
    /// Something the passes draw changed at that update (a new frame, the settings, H); the
    /// passes render, otherwise they keep their last images.
    pub dirty: bool,
}

/// Sets the background H.
#[derive(Message, Debug, Clone)]
pub struct SetBackground {
    /// RGBA8 pixels.
    pub rgba: Arc<Vec<u8>>,
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// Where it came from, for the log and the session.
    pub origin: String,
}

/// Takes the frame now on the panel as the background H.
#[derive(Message, Debug, Clone, Copy, Default)]
pub struct CaptureBackground;

/// Recent joint states of the source twin, for latency compensation.
#[derive(Resource, Debug, Clone, Default)]
pub struct JointHistory {
    /// `(stamp, positions, velocities)`, oldest first, about one second.
    pub states: VecDeque<(f64, DVector<f64>, DVector<f64>)>,
}

impl JointHistory {
    /// Adds a state if it is newer than the last one.
    pub fn push(&mut self, stamp: f64, q: &DVector<f64>, qd: &DVector<f64>) {
        if self.states.back().is_some_and(|s| s.0 >= stamp) || !stamp.is_finite() {
            return;
        }
        self.states.push_back((stamp, q.clone(), qd.clone()));
        while self.states.front().is_some_and(|s| stamp - s.0 > 1.0) {
            self.states.pop_front();
        }
    }

    /// Joint positions at `t`: cubic Hermite between the two states around it, or the newest
    /// state extrapolated with its velocities (at most 0.25 s ahead); the oldest before it.
    pub fn at(&self, t: f64) -> Option<DVector<f64>> {
        let last = self.states.back()?;
        if t >= last.0 {
            let dt = (t - last.0).min(0.25);
            return Some(&last.1 + &last.2 * dt);
        }
        let first = self.states.front()?;
        if t <= first.0 {
            return Some(first.1.clone());
        }
        let i = self.states.partition_point(|s| s.0 <= t);
        let (a, b) = (&self.states[i - 1], &self.states[i]);
        let h = b.0 - a.0;
        let s = (t - a.0) / h;
        let (s2, s3) = (s * s, s * s * s);
        let (h00, h10, h01, h11) = (
            2.0 * s3 - 3.0 * s2 + 1.0,
            s3 - 2.0 * s2 + s,
            -2.0 * s3 + 3.0 * s2,
            s3 - s2,
        );
        Some(&a.1 * h00 + &a.2 * (h10 * h) + &b.1 * h01 + &b.2 * (h11 * h))
    }
}

/// The erase system sets (`Update`, after the video is published), in this order.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EraseSystems {
    /// Joint history, background, live frame upload, mask twin pose, photometric fit
    /// (`Update`).
    Prepare,
    /// The interaction layer: object twins follow their objects (`Update`,
    /// [`InteractionPlugin`]).
    Interaction,
}

/// The threshold pass's material.
#[derive(Asset, TypePath, AsBindGroup, Debug, Clone)]
pub struct MaskMaterial {
    /// Ranges and sizes.
    #[uniform(0)]
    pub params: MaskParams,
    /// The mask twin's render.
    #[texture(1)]
    pub raw: Handle<Image>,
}

/// Uniforms of the threshold pass.
#[derive(ShaderType, Debug, Clone, Copy)]
pub struct MaskParams {
    /// Lower bounds of the RGBα ranges (8-bit levels).
    pub lo: Vec4,
    /// Upper bounds.
    pub hi: Vec4,
    /// Size of the raw render.
    pub raw_size: UVec2,
    /// Size of the mask.
    pub full_size: UVec2,
    /// Square dilation radius (px).
    pub radius: u32,
}

impl Material for MaskMaterial {
    fn fragment_shader() -> ShaderRef {
        "embedded://avatarm_erase/mask.wgsl".into()
    }
}

/// The composite pass's material.
#[derive(Asset, TypePath, AsBindGroup, Debug, Clone)]
pub struct CompositeMaterial {
    /// Photometric model, alpha, feathering.
    #[uniform(0)]
    pub params: CompositeParams,
    /// I(t).
    #[texture(1)]
    pub live: Handle<Image>,
    /// H.
    #[texture(2)]
    pub background: Handle<Image>,
    /// M(t).
    #[texture(3)]
    pub mask: Handle<Image>,
}

/// Uniforms of the composite pass.
#[derive(ShaderType, Debug, Clone, Copy)]
pub struct CompositeParams {
    /// Per-channel gain of the background (w unused).
    pub gain: Vec4,
    /// Per-channel offset (full scale; w unused).
    pub offset: Vec4,
    /// Frame size.
    pub size: UVec2,
    /// Background panel opacity; 0 while erasing is off or there is no background.
    pub alpha_h: f32,
    /// Feathering radius (px).
    pub feather: u32,
}

impl Material for CompositeMaterial {
    fn fragment_shader() -> ShaderRef {
        "embedded://avatarm_erase/composite.wgsl".into()
    }
}

/// Materials of the two passes.
#[derive(Resource, Debug, Clone)]
pub struct EraseMaterials {
    /// Threshold pass.
    pub mask: Handle<MaskMaterial>,
    /// Composite pass.
    pub composite: Handle<CompositeMaterial>,
}

/// Adds the mask twin, the mask camera, the two passes and the systems that feed them. Needs
/// [`RobotTwinPlugin`], [`avatarm_video::VideoPlugin`] and an [`EraseConfig`].
#[derive(Default)]
pub struct ErasePlugin;

impl Plugin for ErasePlugin {
    fn build(&self, app: &mut App) {
        embedded_asset!(app, "mask.wgsl");
        embedded_asset!(app, "composite.wgsl");
        app.add_plugins((
            MaterialPlugin::<MaskMaterial>::default(),
            MaterialPlugin::<CompositeMaterial>::default(),
            gpu_timing::PassTimingPlugin,
        ))
        .add_message::<SetBackground>()
        .add_message::<CaptureBackground>()
        .init_resource::<EraseState>()
        .init_resource::<JointHistory>()
        .configure_sets(
            Update,
            (
                EraseSystems::Prepare.after(VideoSystems::Publish),
                EraseSystems::Interaction.after(EraseSystems::Prepare),
            ),
        )
        .add_systems(Startup, setup)
        .add_systems(
            Update,
            (record_history, set_background, prepare_frame, gate_passes)
                .chain()
                .in_set(EraseSystems::Prepare),
        );
    }
}

/// An RGBA8 image the CPU writes and the GPU samples as raw 8-bit values (not sRGB-decoded).
pub fn upload_image(width: u32, height: u32) -> Image {
    avatarm_twin::camera::rgba8_image(
        width,
        height,
        TextureFormat::Rgba8Unorm,
        TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_DST,
    )
}

/// Spawns an orthographic camera that draws one full-target quad with `material` into
/// `target` as pass `stage` (rendered after the passes before it); the quad's fragment shader
/// works in pixel coordinates.
fn spawn_pass<M: Material>(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    material: Handle<M>,
    target: Handle<Image>,
    layer: usize,
    name: &str,
    stage: usize,
) {
    let layers = RenderLayers::layer(layer);
    commands.spawn((
        Name::new(format!("{name} quad")),
        Mesh3d(meshes.add(Rectangle::new(1.0, 1.0))),
        MeshMaterial3d(material),
        Transform::default(),
        layers.clone(),
    ));
    commands.spawn((
        Name::new(name.to_owned()),
        Camera3d::default(),
        Camera {
            // After the mask camera (order MASK_CAMERA_ORDER) and the passes before it.
            order: MASK_CAMERA_ORDER + stage as isize,
            clear_color: ClearColorConfig::Custom(Color::BLACK),
            ..default()
        },
        RenderTarget::Image(target.into()),
        Projection::Orthographic(OrthographicProjection {
            scaling_mode: ScalingMode::Fixed {
                width: 1.0,
                height: 1.0,
            },
            near: -1.0,
            far: 1.0,
            ..OrthographicProjection::default_3d()
        }),
        Transform::default(),
        Tonemapping::None,
        DebandDither::Disabled,
        Msaa::Off,
        layers,
        ErasePass { stage },
    ));
}

fn setup(
    mut commands: Commands,
    config: Res<EraseConfig>,
    mut twin_assets: TwinAssets,
    mut mask_materials: ResMut<Assets<MaskMaterial>>,
    mut composite_materials: ResMut<Assets<CompositeMaterial>>,
    mut images: ResMut<Assets<Image>>,
) {
    let k = config.camera.intrinsics;
    let raw_k = k.scaled(config.settings.resolution_scale);
    let twin = spawn_twin_with_visuals(
        &mut commands,
        &mut twin_assets,
        &config.model,
        &config.base,
        TwinAppearance::Unlit(Color::WHITE),
        config.detail,
        &RenderLayers::layer(layers::MASK_TWIN),
        "mask twin",
    );
    commands.insert_resource(MaskTwin(twin.root));
    let black = twin_assets.materials.add(StandardMaterial {
        base_color: Color::BLACK,
        unlit: true,
        depth_bias: SCENERY_DEPTH_BIAS,
        ..default()
    });
    for (mesh, transform) in &config.occluders {
        commands.spawn((
            Name::new("mask occluder"),
            Mesh3d(twin_assets.meshes.add(mesh.clone())),
            MeshMaterial3d(black.clone()),
            *transform,
            RenderLayers::layer(layers::MASK_TWIN),
        ));
    }

    let raw = images.add(target_image(raw_k.width, raw_k.height));
    let mask = images.add(target_image(k.width, k.height));
    let composite = images.add(target_image(k.width, k.height));
    let live = images.add(upload_image(k.width, k.height));
    let background = images.add(upload_image(k.width, k.height));
    let mask_camera = PinholeCamera {
        intrinsics: raw_k,
        world_from_camera: config.camera.world_from_camera,
    };
    let mask_camera = spawn_pinhole_camera(
        &mut commands,
        &mask_camera,
        raw.clone(),
        RenderLayers::layer(layers::MASK_TWIN),
        Color::BLACK,
        MASK_CAMERA_ORDER,
        "mask camera",
    );
    commands.entity(mask_camera).insert(ErasePass { stage: 0 });
    let s = &config.settings;
    let mask_material = mask_materials.add(MaskMaterial {
        params: MaskParams {
            lo: Vec4::from_array(s.ranges.map(|r| f32::from(r[0]))),
            hi: Vec4::from_array(s.ranges.map(|r| f32::from(r[1]))),
            raw_size: UVec2::new(raw_k.width, raw_k.height),
            full_size: UVec2::new(k.width, k.height),
            radius: s.mask_radius(),
        },
        raw: raw.clone(),
    });
    let composite_material = composite_materials.add(CompositeMaterial {
        params: composite_params(s, &Photometric::default(), false),
        live: live.clone(),
        background: background.clone(),
        mask: mask.clone(),
    });
    spawn_pass(
        &mut commands,
        &mut twin_assets.meshes,
        mask_material.clone(),
        mask.clone(),
        layers::MASK_PASS,
        "threshold pass",
        1,
    );
    spawn_pass(
        &mut commands,
        &mut twin_assets.meshes,
        composite_material.clone(),
        composite.clone(),
        layers::COMPOSITE_PASS,
        "composite pass",
        2,
    );
    commands.insert_resource(EraseMaterials {
        mask: mask_material,
        composite: composite_material,
    });
    commands.insert_resource(EraseTargets {
        raw,
        mask,
        composite,
        live,
        background,
    });
    let (spheres, notes) = dr::link_spheres(&config.model);
    for n in notes {
        warn!("photometric compensation: {n}");
    }
    commands.insert_resource(RobotSpheres(spheres));
}

/// Bounding spheres of the robot's links, for the conservative robot region.
#[derive(Resource, Debug, Clone)]
struct RobotSpheres(Vec<LinkSphere>);

/// The composite uniforms for settings, a photometric model and whether H exists.
pub fn composite_params(
    s: &EraseSettings,
    photometric: &Photometric,
    have_background: bool,
) -> CompositeParams {
    CompositeParams {
        gain: Vec3::from_array(photometric.gain).extend(1.0),
        offset: Vec3::from_array(photometric.offset).extend(0.0),
        size: UVec2::ZERO,
        alpha_h: if s.enabled && have_background {
            s.alpha_h
        } else {
            0.0
        },
        feather: s.feather_px,
    }
}

fn record_history(
    config: Res<EraseConfig>,
    twins: Query<&RobotTwin>,
    mut history: ResMut<JointHistory>,
) {
    let Some(twin) = config.source_twin.and_then(|e| twins.get(e).ok()) else {
        return;
    };
    if let Some(stamp) = twin.stamp_s {
        history.push(stamp, &twin.positions, &twin.velocities);
    }
}

fn set_background(
    mut set: MessageReader<SetBackground>,
    mut capture: MessageReader<CaptureBackground>,
    config: Res<EraseConfig>,
    live: Res<LiveVideo>,
    mut state: ResMut<EraseState>,
) {
    let k = config.camera.intrinsics;
    let mut new: Option<(Arc<Vec<u8>>, String)> = None;
    for msg in set.read() {
        if (msg.width, msg.height) != (k.width, k.height)
            || msg.rgba.len() != (k.width * k.height * 4) as usize
        {
            error!(
                "background from {}: {}x{} ({} bytes) does not match the camera's {}x{}; ignored",
                msg.origin,
                msg.width,
                msg.height,
                msg.rgba.len(),
                k.width,
                k.height
            );
            continue;
        }
        new = Some((msg.rgba.clone(), msg.origin.clone()));
    }
    if capture.read().count() > 0 {
        match &live.frame {
            Some(f) if (f.width, f.height) == (k.width, k.height) => {
                new = Some((
                    f.rgba.clone(),
                    format!("live frame captured at {:.3} s", f.capture_s),
                ));
            }
            Some(_) => error!("background capture: the live frame's size does not match"),
            None => warn!("background capture: no live frame yet"),
        }
    }
    if let Some((rgba, origin)) = new {
        info!("background H set from {origin}");
        state.background_changed = true;
        state.background = Some(rgba);
        state.background_origin = Some(origin);
    }
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn prepare_frame(
    config: Res<EraseConfig>,
    live: Res<LiveVideo>,
    history: Res<JointHistory>,
    targets: Option<Res<EraseTargets>>,
    passes: Option<Res<EraseMaterials>>,
    mask_twin: Option<Res<MaskTwin>>,
    spheres: Option<Res<RobotSpheres>>,
    mut state: ResMut<EraseState>,
    mut twins: Query<&mut RobotTwin>,
    mut images: ResMut<Assets<Image>>,
    mut composite_materials: ResMut<Assets<CompositeMaterial>>,
) {
    let (Some(targets), Some(passes), Some(mask_twin), Some(spheres)) =
        (targets, passes, mask_twin, spheres)
    else {
        return;
    };
    let s = config.settings;
    let k = config.camera.intrinsics;
    let frame = live.frame.as_ref().filter(|_| live.fresh);
    if let Some(f) = frame
        && (f.width, f.height) != (k.width, k.height)
    {
        state.frames_refused += 1;
        if state.frames_refused % 100 == 1 {
            error!(
                "video source '{}': frame {} is {}x{} but the camera is calibrated at {}x{}; frame ignored ({} so far)",
                live.source, f.index, f.width, f.height, k.width, k.height, state.frames_refused
            );
        }
        return;
    }
    // The joint state the mask twin is drawn at.
    let target = match (frame, s.latency_compensation) {
        (Some(f), true) => history.at(f.capture_s).map(|q| (q, f.capture_s)),
        (_, false) => history.states.back().map(|b| (b.1.clone(), b.0)),
        (None, true) => None,
    };
    if let Some((q, stamp)) = target
        && let Ok(mut twin) = twins.get_mut(mask_twin.0)
        && twin.stamp_s != Some(stamp)
    {
        let q = config.joint_map.apply(q.as_slice());
        let limits = config.model.dof_limits();
        let q = DVector::from_iterator(
            q.len(),
            q.iter().enumerate().map(|(i, v)| match limits.get(i) {
                Some(l) if l.lower <= l.upper => v.clamp(l.lower, l.upper),
                _ => *v,
            }),
        );
        if q.iter().all(|v| v.is_finite()) {
            twin.positions = q;
            twin.stamp_s = Some(stamp);
            state.mask_stamp_s = Some(stamp);
        }
    }
    let dirty = frame.is_some() || config.is_changed() || state.background_changed;
    state.background_changed = false;
    if let Some(f) = frame {
        state.frames_in += 1;
        if let Some(mut image) = images.get_mut(&targets.live) {
            image.data = Some(f.rgba.as_ref().clone());
        }
        state.frame_capture_s = Some(f.capture_s);
        let mut photometric = state.photometric;
        if let Some(bg) = state.background.clone()
            && (s.photometric || s.background_refresh > 0.0)
        {
            let q = twins
                .get(mask_twin.0)
                .map(|t| t.positions.iter().copied().collect::<Vec<_>>())
                .unwrap_or_default();
            let poses = config.model.forward_kinematics(&config.base, &q);
            let margin = f64::from(s.mask_radius()) + 6.0;
            let region = dr::sphere_mask(&config.camera, &poses, &spheres.0, margin);
            let views = RgbaView::new("live frame", k.width, k.height, &f.rgba)
                .and_then(|l| RgbaView::new("background", k.width, k.height, &bg).map(|b| (l, b)));
            match views {
                Ok((l, b)) => {
                    if s.photometric {
                        match dr::fit_photometric(&l, &b, Some(&region), 4) {
                            Ok(p) => photometric = p,
                            Err(e) => warn!("photometric fit: {e}"),
                        }
                    }
                    if s.background_refresh > 0.0 {
                        let free: Vec<u8> = region.iter().map(|&r| u8::from(r == 0)).collect();
                        let mut next = bg.as_ref().clone();
                        dr::refresh_background(
                            &mut next,
                            &l,
                            &free,
                            s.background_refresh,
                            &photometric,
                        );
                        state.background = Some(Arc::new(next));
                    }
                }
                Err(e) => warn!("photometric compensation: {e}"),
            }
            state.robot_region = Some(Arc::new(region));
        }
        state.photometric = photometric;
    }
    // This update's inputs: all three passes render them in this update's frame.
    let current = PassInputs {
        frame: live
            .frame
            .as_ref()
            .map(|f| (f.capture_s, f.index, f.rgba.clone())),
        photometric: state.photometric,
        background: state.background.clone(),
        dirty,
    };
    if !dirty {
        state.current = Some(current);
        return;
    }
    if let Some(bg) = &current.background
        && let Some(mut image) = images.get_mut(&targets.background)
        && image.data.as_deref() != Some(bg.as_slice())
    {
        image.data = Some(bg.as_ref().clone());
    }
    if let Some(mut m) = composite_materials.get_mut(&passes.composite) {
        let mut params = composite_params(&s, &current.photometric, current.background.is_some());
        params.size = UVec2::new(k.width, k.height);
        m.params = params;
    }
    state.current = Some(current);
}

/// Renders the passes only in an update with something new to draw (a camera frame, new
/// settings or H); before the first update of the pipeline, every pass renders.
fn gate_passes(mut state: ResMut<EraseState>, mut passes: Query<(&ErasePass, &mut Camera)>) {
    let active = state.current.as_ref().is_none_or(|s| s.dirty);
    for (pass, mut camera) in &mut passes {
        if camera.is_active != active {
            camera.is_active = active;
        }
        if active && let Some(n) = state.renders.get_mut(pass.stage.min(2)) {
            *n += 1;
        }
    }
}

/// Switches erasure on or off at run time (the preview's key); returns the new state.
pub fn toggle_erasure(config: &mut EraseConfig) -> bool {
    config.settings.enabled = !config.settings.enabled;
    config.settings.enabled
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn history_interpolates_and_extrapolates() {
        let mut h = JointHistory::default();
        let v = |x: f64| DVector::from_vec(vec![x]);
        // q = t^2 sampled at 0, 0.1, 0.2 with exact velocities 2t.
        for t in [0.0, 0.1, 0.2] {
            h.push(t, &v(t * t), &v(2.0 * t));
        }
        h.push(0.15, &v(9.0), &v(9.0)); // out of order: ignored
        assert_eq!(h.states.len(), 3);
        let q = h.at(0.15).expect("inside")[0];
        assert!(
            (q - 0.0225).abs() < 1e-12,
            "Hermite is exact on a quadratic: {q}"
        );
        let q = h.at(0.3).expect("ahead")[0];
        assert!((q - (0.04 + 0.4 * 0.1)).abs() < 1e-12);
        assert_eq!(h.at(-1.0).expect("before")[0], 0.0);
        let far = h.at(10.0).expect("ahead")[0];
        assert!(
            (far - (0.04 + 0.4 * 0.25)).abs() < 1e-12,
            "capped at 0.25 s"
        );
        assert!(JointHistory::default().at(0.0).is_none());
    }
}

#[cfg(test)]
mod headless_tests;
