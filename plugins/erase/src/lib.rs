//! Erasing the robot from the live video, on the GPU (the paper's service and interaction
//! layers).
//!
//! Per camera frame:
//! 1. **Mask twin.** A twin of the robot on [`layers::MASK_TWIN`], in white
//!    ([`FlatPart::ROBOT`]), with the scene's occluders in black, is posed at the joint state
//!    for the frame: the last received one, or with latency compensation the state interpolated
//!    (or extrapolated from the joint velocities) at the frame's capture time
//!    ([`JointHistory::at`]).
//! 2. **Mask render.** A [`FlatView`] with the *believed* intrinsics and pose of the real
//!    camera draws it, white on black, into [`EraseTargets::raw`] (`R8Unorm`, at
//!    `resolution_scale` of the camera's size): no Bevy camera, no lighting, tonemapping or
//!    MSAA ([`avatarm_twin::flat`]). Through a distorting lens ([`EraseConfig::distortion`])
//!    the render is the pinhole view wide enough for every ray the lens sees, and each pixel of
//!    the mask reads it where its ray lands ([`EraseLens`]): the mask is warped into the
//!    distorted image, the live frame is never resampled.
//! 3. **Threshold, dilation, feathering, composite** ([`passes`], `erase.wgsl`): per-channel
//!    RGBα ranges give the binary mask M(t), dilated by `dilate_px + feather_px` into
//!    [`EraseTargets::mask`] (`R8Unorm`); the live frame with the background panel in front at
//!    alpha `α_H · a`, `a` the feathered mask, the background after photometric compensation,
//!    into [`EraseTargets::composite`], which is Ĩ(t) before the hand and object twin are drawn
//!    in front ([`interaction`]). One to four full-target passes, by the settings.
//!
//! **One update.** The mask render and the passes run in the root render graph before every
//! camera, so a frame that arrives in an update is erased and shown in that update's render.
//! Reading a pass's image back must not use Bevy's `Screenshot::image` (it renders a camera
//! into a temporary texture copied into its image only after every camera);
//! [`avatarm_twin::readback`] reads an image back after the frame instead.
//!
//! Nothing is read back to the CPU on this path. The live frame and H are uploaded into
//! textures of the passes' own through staging buffers (not Bevy images, which would be
//! re-created on every change). Photometric compensation fits the background to each frame on
//! the CPU (both images are CPU data anyway) outside a conservative robot region: the links'
//! bounding spheres projected by FK ([`avatarm_core::dr::sphere_mask`]). The CPU reference of
//! step 3 is [`avatarm_core::dr`].
//!
//! Modules: [`interaction`] (the panel, the object twins and the interaction camera),
//! [`passes`] (the render-world passes and their uploads). GPU times of the mask render and of
//! each pass are in [`GpuTimes`] ([`avatarm_twin::gpu_timing`]).

pub mod interaction;
pub mod passes;

use std::collections::VecDeque;
use std::sync::Arc;

use avatarm_core::dr::view_background::{BackgroundViews, GeometricProxy};
use avatarm_core::dr::{self, EraseSettings, LinkSphere, Photometric, RgbaView};
use avatarm_core::robot::{JointMap, RobotModel};
use avatarm_core::vision::camera::PinholeCamera;
use avatarm_core::vision::distortion::{Distortion, DistortionMap};
use avatarm_twin::camera::rgba8_image;
use avatarm_twin::flat::{FlatPart, FlatView, flat_target_image};
use avatarm_twin::prelude::*;
use avatarm_twin::{CameraBound, layers};
use avatarm_video::{HeadTracking, LiveVideo, VideoSystems};
use bevy::camera::visibility::RenderLayers;
use bevy::prelude::*;
use bevy::render::render_resource::{TextureFormat, TextureUsages};
use nalgebra::{DVector, Isometry3};

pub use avatarm_twin::gpu_timing::{GpuTimes, SpanTimes};
pub use interaction::{InteractionConfig, InteractionPlugin, InteractionTargets};
pub use passes::{
    EraseJob, EraseParams, ErasePassesPlugin, FLOOR_SPAN, PASS_NAMES, UPLOAD_CPU_SPAN, UPLOAD_SPAN,
};

/// What most users of the erase pipeline need.
pub mod prelude {
    pub use crate::interaction::{InteractionConfig, InteractionPlugin, ObjectTwinSpec};
    pub use crate::{EraseConfig, ErasePlugin, EraseState, EraseSystems, EraseTargets};
}

/// What the erase plugin needs to know. Insert it before the app starts.
#[derive(Resource, Debug, Clone)]
pub struct EraseConfig {
    /// Mask and composite options.
    pub settings: EraseSettings,
    /// The camera as the app believes it is (intrinsics + calibrated pose).
    pub camera: PinholeCamera,
    /// Its lens distortion (honoured unless `settings.lens_distortion` is off).
    pub distortion: Distortion,
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
    /// the mask's view so that M(t) follows the robot's *visible* pixels. Meshes with their
    /// world transforms.
    pub occluders: Vec<(Mesh, Transform)>,
    /// The camera rides on a head (Alice's headset camera): its pose is the tracked head's
    /// ([`HeadTracking`]) times this mount (`head_from_camera`, as calibrated), at the frame's
    /// capture time with `settings.pose_compensation`, else at the newest tracked pose;
    /// `camera`'s pose is used until a tracked pose arrives. `None`: a fixed camera.
    pub head_mount: Option<Isometry3<f64>>,
    /// A camera on a head: the background follows the view, re-projected from captured views
    /// ([`ViewBackgroundConfig`]); `None`: the one H serves every frame.
    pub view_background: Option<ViewBackgroundConfig>,
}

/// A background that follows a moving camera
/// ([`avatarm_core::dr::view_background`]): the `[background]` image and each frame's pixels
/// the robot cannot cover (its links' bounding spheres, grown by the mask's radius) are kept as
/// views, and each frame's H is re-projected from them into the frame's camera where the robot
/// may be; elsewhere H is the frame itself.
#[derive(Debug, Clone)]
pub struct ViewBackgroundConfig {
    /// The room as rectangles (the scene's desk, wall and floor boxes).
    pub proxy: GeometricProxy,
    /// Views kept.
    pub max_views: usize,
    /// A frame becomes a view this far (rad) from every kept one.
    pub min_separation_rad: f64,
    /// CPU threads that re-project the views (0: one per core; the image is the same).
    pub threads: usize,
}

/// The view-following background's state.
#[derive(Debug, Clone)]
pub struct ViewBackground {
    /// The kept views.
    pub views: BackgroundViews,
    /// The `[background]` image (the fallback where no view sees a pixel).
    pub seed: Option<Arc<Vec<u8>>>,
    /// For the frame on the panel: the share of the robot's region some view saw (0..1).
    pub seen_share: Option<f64>,
    /// For the frame on the panel: the angle (rad) between its camera's axis and the nearest
    /// kept view's.
    pub nearest_rad: Option<f64>,
    /// For the frame on the panel: the CPU time of offering it and making its H (ms).
    pub cpu_ms: Option<f64>,
}

/// The mask's lens map: `Some` when the camera's lens distorts and the settings honour it
/// (fixed at start-up: the mask render's size follows it).
#[derive(Resource, Debug, Clone, Default)]
pub struct EraseLens(pub Option<Arc<DistortionMap>>);

impl EraseLens {
    /// The map of a camera with intrinsics `k` and lens `lens` at `settings` (`None`: a
    /// pinhole or the lens ignored). Errors: a lens that inverts nowhere on the image's border.
    pub fn new(
        k: &avatarm_core::vision::camera::Intrinsics,
        lens: &Distortion,
        settings: &EraseSettings,
    ) -> avatarm_core::Result<Self> {
        if lens.is_none() || !settings.lens_distortion {
            return Ok(Self(None));
        }
        let map = DistortionMap::new(k, lens, settings.resolution_scale)?;
        Ok(Self(Some(Arc::new(map))))
    }

    /// The mask render's intrinsics: the lens map's pinhole, else the camera's at the settings'
    /// scale.
    pub fn raw_intrinsics(&self, config: &EraseConfig) -> avatarm_core::vision::camera::Intrinsics {
        match &self.0 {
            Some(map) => map.pinhole,
            None => config
                .camera
                .intrinsics
                .scaled(config.settings.resolution_scale),
        }
    }
}

/// Images of the pipeline, all at the camera's size except `raw`.
#[derive(Resource, Debug, Clone)]
pub struct EraseTargets {
    /// The mask twin rendered white on black (`R8Unorm`, at `resolution_scale`).
    pub raw: Handle<Image>,
    /// M(t) after threshold and dilation (`R8Unorm`, 1 = robot).
    pub mask: Handle<Image>,
    /// Ĩ(t): the live frame with the robot erased (`Rgba8UnormSrgb`).
    pub composite: Handle<Image>,
}

/// The mask twin's root entity, and the entity carrying its [`FlatView`] and [`EraseJob`].
#[derive(Resource, Debug, Clone, Copy)]
pub struct MaskTwin(pub Entity);

/// The entity carrying the pipeline's [`FlatView`] (the mask render) and [`EraseJob`].
#[derive(Resource, Debug, Clone, Copy)]
pub struct ErasePipeline(pub Entity);

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
    /// The camera pose the mask was drawn from for the frame on the panel (`world_from_camera`):
    /// the head's pose times the mount for a camera on a head, else the configured one.
    pub camera_pose: Option<Isometry3<f64>>,
    /// For a camera on a head: the stamp of the newest tracked pose used for it, and the time
    /// the mask's head pose was taken at (the frame's capture time with pose compensation).
    pub head_pose_s: Option<(f64, f64)>,
    /// Frames refused (wrong size).
    pub frames_refused: u64,
    /// The conservative robot region used by the last fit (0/1 per pixel), for refresh and
    /// diagnostics.
    pub robot_region: Option<Arc<Vec<u8>>>,
    /// What the passes work on in this update.
    pub current: Option<PassInputs>,
    /// A camera on a head with a view-following background ([`EraseConfig::view_background`]).
    pub view_background: Option<ViewBackground>,
    /// Renders of the pipeline so far (the mask render and every pass). It renders once per
    /// camera frame (and when the settings or H change), however fast the display updates: an
    /// XR headset at 72-90 Hz over a 30 fps camera does not redo the mask.
    pub renders: u64,
    /// Camera frames taken into the pipeline.
    pub frames_in: u64,
    /// H changed since the last update.
    background_changed: bool,
    /// The H last handed to the passes (they upload it when it changes).
    uploaded_background: Option<Arc<Vec<u8>>>,
}

/// What the passes work on in one update: the mask's view draws the twin for `frame`, the
/// passes threshold it and erase the frame, all in that update's render.
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
    /// The camera pose it was taken from (`world_from_camera`), for a camera on a head whose
    /// view-following background takes it as a view; `None`: the camera's configured pose.
    pub camera_pose: Option<Isometry3<f64>>,
    /// It is one camera's picture of the room (at `camera_pose`), which a view-following
    /// background keeps as a view. `false`: a blend of many views (a moving camera's footage
    /// median), only the fallback where no view saw a pixel.
    pub one_view: bool,
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

/// Adds the mask twin, its flat render, the passes and the systems that feed them. Needs
/// [`RobotTwinPlugin`], [`avatarm_video::VideoPlugin`] and an [`EraseConfig`].
#[derive(Default)]
pub struct ErasePlugin;

impl Plugin for ErasePlugin {
    fn build(&self, app: &mut App) {
        app.add_plugins(ErasePassesPlugin)
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
            .add_systems(Startup, spawn_pipeline)
            .add_systems(
                Update,
                (record_history, set_background, prepare_frame, gate_passes)
                    .chain()
                    .in_set(EraseSystems::Prepare),
            );
    }
}

/// The image Ĩ(t) is rendered into: sRGB for the panels that sample it, written through an
/// `Rgba8Unorm` view (its bytes are the composite's 8-bit values), read back.
pub fn composite_image(width: u32, height: u32) -> Image {
    let mut image = rgba8_image(
        width,
        height,
        TextureFormat::Rgba8UnormSrgb,
        TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_SRC | TextureUsages::RENDER_ATTACHMENT,
    );
    image.texture_descriptor.view_formats = &[TextureFormat::Rgba8Unorm];
    image
}

/// The pipeline for the configured camera ([`EraseConfig`]): the mask twin with the occluders,
/// the mask's [`FlatView`] and [`EraseJob`], their images ([`EraseTargets`]), the lens map and
/// a view-following background's state in [`EraseState`]. Its entities are marked
/// [`CameraBound`]. Runs at start-up; a camera switch despawns them, resets [`EraseState`] and
/// runs it again for the next camera.
pub fn spawn_pipeline(
    mut commands: Commands,
    config: Res<EraseConfig>,
    mut twin_assets: TwinAssets,
    mut images: ResMut<Assets<Image>>,
    mut state: ResMut<EraseState>,
) {
    let k = config.camera.intrinsics;
    if let Some(v) = &config.view_background {
        if !config.distortion.is_none() {
            warn!(
                "erase: the view-following background re-projects through a pinhole; with a distorting lens the one H serves every frame"
            );
        } else {
            match BackgroundViews::new(
                k.width,
                k.height,
                v.proxy.clone(),
                v.max_views,
                v.min_separation_rad,
            ) {
                Ok(mut views) => {
                    views.threads = v.threads;
                    let s = &config.settings;
                    if s.photometric || s.background_refresh > 0.0 {
                        warn!(
                            "erase: photometric compensation and background refresh have no effect with the view-following background (its H is the frame itself outside the robot's region)"
                        );
                    }
                    state.view_background = Some(ViewBackground {
                        views,
                        seed: None,
                        seen_share: None,
                        nearest_rad: None,
                        cpu_ms: None,
                    });
                }
                Err(e) => error!("erase: {e}; the one H serves every frame"),
            }
        }
    }
    let lens = EraseLens::new(&k, &config.distortion, &config.settings).unwrap_or_else(|e| {
        error!("erase: {e}; the mask is drawn as a pinhole's");
        EraseLens(None)
    });
    if let Some(m) = lens.0.as_ref().filter(|m| m.unmapped + m.outside > 0) {
        warn!(
            "erase: the lens does not invert at {} pixels and the mask's render misses {} more: those pixels are never masked",
            m.unmapped, m.outside
        );
    }
    let raw_k = lens.raw_intrinsics(&config);
    let layer = RenderLayers::layer(layers::MASK_TWIN);
    let twin = spawn_twin_with_visuals(
        &mut commands,
        &mut twin_assets,
        &config.model,
        &config.base,
        TwinAppearance::Flat(FlatPart::ROBOT),
        config.detail,
        &layer,
        "mask twin",
    );
    commands.entity(twin.root).insert(CameraBound);
    commands.insert_resource(MaskTwin(twin.root));
    for (mesh, transform) in &config.occluders {
        commands.spawn((
            Name::new("mask occluder"),
            Mesh3d(twin_assets.meshes.add(mesh.clone())),
            FlatPart::OCCLUDER,
            *transform,
            layer.clone(),
            CameraBound,
        ));
    }
    let raw = images.add(flat_target_image(raw_k.width, raw_k.height));
    let mask = images.add(flat_target_image(k.width, k.height));
    let composite = images.add(composite_image(k.width, k.height));
    let mask_camera = PinholeCamera {
        intrinsics: raw_k,
        world_from_camera: config.camera.world_from_camera,
    };
    let s = &config.settings;
    let pipeline = commands
        .spawn((
            Name::new("erase pipeline"),
            CameraBound,
            FlatView {
                camera: mask_camera,
                target: raw.clone(),
                clear: 0,
                active: true,
                name: PASS_NAMES[0].to_owned(),
            },
            layer,
            EraseJob {
                label: String::new(),
                raw: raw.clone(),
                mask: mask.clone(),
                composite: composite.clone(),
                params: EraseParams::new(
                    s,
                    &Photometric::default(),
                    false,
                    UVec2::new(raw_k.width, raw_k.height),
                    UVec2::new(k.width, k.height),
                ),
                render: true,
                frame: None,
                background: None,
                lens: lens.0.clone(),
                measure_floor: false,
            },
        ))
        .id();
    commands.insert_resource(lens);
    commands.insert_resource(ErasePipeline(pipeline));
    commands.insert_resource(EraseTargets {
        raw,
        mask,
        composite,
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
    head: Res<HeadTracking>,
    mut state: ResMut<EraseState>,
) {
    let k = config.camera.intrinsics;
    let mut new: Option<SetBackground> = None;
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
        new = Some(msg.clone());
    }
    if capture.read().count() > 0 {
        match &live.frame {
            Some(f) if (f.width, f.height) == (k.width, k.height) => {
                new = Some(SetBackground {
                    rgba: f.rgba.clone(),
                    width: f.width,
                    height: f.height,
                    origin: format!("live frame captured at {:.3} s", f.capture_s),
                    // A camera on a head: where it was at the frame's capture.
                    camera_pose: config
                        .head_mount
                        .and_then(|mount| Some(head.history.at(f.capture_s)? * mount)),
                    one_view: true,
                });
            }
            Some(_) => error!("background capture: the live frame's size does not match"),
            None => warn!("background capture: no live frame yet"),
        }
    }
    if let Some(SetBackground {
        rgba,
        origin,
        camera_pose: pose,
        one_view,
        ..
    }) = new
    {
        info!("background H set from {origin}");
        // A camera on a head: the image is a view of the room from where the camera was.
        let camera = PinholeCamera {
            intrinsics: k,
            world_from_camera: pose.unwrap_or(config.camera.world_from_camera),
        };
        if let Some(vb) = state.view_background.as_mut() {
            vb.seed = Some(rgba.clone());
        }
        if let Some(vb) = state.view_background.as_mut().filter(|_| one_view) {
            let offered = RgbaView::new("background", k.width, k.height, &rgba)
                .and_then(|view| vb.views.set_photograph(&camera, &view, -1.0));
            if let Err(e) = offered {
                warn!("view-following background: {e}");
            }
        }
        state.background_changed = true;
        state.background = Some(rgba);
        state.background_origin = Some(origin);
    }
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
#[expect(
    clippy::too_many_lines,
    reason = "one camera frame's inputs to the erase in one system (the mask camera's pose, the lens, latency compensation, H, the photometric fit)"
)]
fn prepare_frame(
    config: Res<EraseConfig>,
    live: Res<LiveVideo>,
    history: Res<JointHistory>,
    pipeline: Option<Res<ErasePipeline>>,
    mask_twin: Option<Res<MaskTwin>>,
    (spheres, lens, head): (
        Option<Res<RobotSpheres>>,
        Option<Res<EraseLens>>,
        Res<HeadTracking>,
    ),
    mut state: ResMut<EraseState>,
    mut twins: Query<&mut RobotTwin>,
    mut jobs: Query<(&mut EraseJob, &mut FlatView)>,
) {
    let (Some(pipeline), Some(mask_twin), Some(spheres), Some(lens)) =
        (pipeline, mask_twin, spheres, lens)
    else {
        return;
    };
    let Ok((mut job, mut view)) = jobs.get_mut(pipeline.0) else {
        return;
    };
    // Uploads are handed over for one update only.
    job.frame = None;
    job.background = None;
    let s = config.settings;
    let k = config.camera.intrinsics;
    let mut frame = live.frame.as_ref().filter(|_| live.fresh);
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
        // The update goes on without it (settings or H may still have changed).
        frame = None;
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
    // The camera the mask is drawn from: a camera on a head at the head's pose for this frame.
    let mut camera = config.camera;
    // The camera is where the frame was taken from: fixed, or a tracked head's pose for it.
    let mut camera_known = config.head_mount.is_none();
    if let (Some(f), Some(mount)) = (frame, config.head_mount) {
        let at = if s.pose_compensation {
            head.history.at(f.capture_s).map(|p| (p, f.capture_s))
        } else {
            head.history.latest().map(|(t, p)| (p, t))
        };
        match at {
            Some((world_from_head, at_s)) => {
                camera.world_from_camera = world_from_head * mount;
                camera_known = true;
                let newest = head.history.latest().map_or(at_s, |l| l.0);
                state.head_pose_s = Some((newest, at_s));
            }
            None => warn_once!(
                "erase: no tracked head pose yet; the mask is drawn from the camera's configured pose"
            ),
        }
    } else if let (Some(pose), Some(_)) = (state.camera_pose, config.head_mount) {
        // Between frames a camera on a head stays where the last frame put it.
        camera.world_from_camera = pose;
    }
    // The mask is drawn from it: a head's pose for this frame, or a fixed camera's configured
    // pose (which the drift watch moves when the camera was bumped).
    if view.camera.world_from_camera != camera.world_from_camera {
        view.camera.world_from_camera = camera.world_from_camera;
    }
    if frame.is_some() {
        state.camera_pose = Some(camera.world_from_camera);
    }
    let dirty = frame.is_some() || config.is_changed() || state.background_changed;
    state.background_changed = false;
    if let Some(f) = frame {
        state.frames_in += 1;
        job.frame = Some(f.rgba.clone());
        state.frame_capture_s = Some(f.capture_s);
        let mut photometric = state.photometric;
        let fit = s.photometric || s.background_refresh > 0.0;
        if state.view_background.is_some() || (state.background.is_some() && fit) {
            let q = twins
                .get(mask_twin.0)
                .map(|t| t.positions.iter().copied().collect::<Vec<_>>())
                .unwrap_or_default();
            let poses = config.model.forward_kinematics(&config.base, &q);
            let margin = f64::from(s.mask_radius()) + 6.0;
            let region = match &lens.0 {
                // Through the lens: the region in the pinhole render, read where each pixel's
                // ray lands, then grown by the mask's radius in the camera's own pixels (a
                // margin in the render's pixels shrinks where the lens compresses the image).
                Some(map) => {
                    let pinhole = PinholeCamera {
                        intrinsics: map.pinhole,
                        world_from_camera: camera.world_from_camera,
                    };
                    let slack = 6.0 * s.resolution_scale + 1.0;
                    let region = dr::sphere_mask(&pinhole, &poses, &spheres.0, slack);
                    match map.remap_nearest("robot region", &region, 1) {
                        Ok(r) => dr::dilate(&r, k.width, k.height, s.mask_radius()),
                        Err(_) => vec![1; (k.width * k.height) as usize],
                    }
                }
                None => dr::sphere_mask(&camera, &poses, &spheres.0, margin),
            };
            // A frame becomes a view only where its camera and the robot's region are known: the
            // mask twin posed at joints of the frame's time, the camera at a tracked pose (else
            // the robot's pixels would be kept as the room's).
            let robot_known = state
                .mask_stamp_s
                .is_some_and(|m| (m - f.capture_s).abs() <= 0.1);
            let offer = camera_known && robot_known;
            if let Some(vb) = state.view_background.as_mut() {
                match follow_view(vb, &camera, f, &region, offer) {
                    Ok(h) => {
                        state.background = Some(Arc::new(h));
                    }
                    Err(e) => warn!("view-following background: {e}"),
                }
            }
            if let Some(bg) = state.background.clone()
                && fit
            {
                let views = RgbaView::new("live frame", k.width, k.height, &f.rgba).and_then(|l| {
                    RgbaView::new("background", k.width, k.height, &bg).map(|b| (l, b))
                });
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
            }
            state.robot_region = Some(Arc::new(region));
        }
        state.photometric = photometric;
    }
    // This update's inputs: the mask render and the passes work on them in this update.
    // The frame on the panel: this update's, else the last one taken (a refused frame is not).
    let on_panel = frame
        .map(|f| (f.capture_s, f.index, f.rgba.clone()))
        .or_else(|| state.current.as_ref().and_then(|c| c.frame.clone()));
    let current = PassInputs {
        frame: on_panel,
        photometric: state.photometric,
        background: state.background.clone(),
        dirty,
    };
    if let Some(bg) = &current.background
        && !state
            .uploaded_background
            .as_ref()
            .is_some_and(|u| Arc::ptr_eq(u, bg))
    {
        job.background = Some(bg.clone());
        state.uploaded_background = Some(bg.clone());
    }
    if dirty {
        let raw = lens.raw_intrinsics(&config);
        job.params = EraseParams::new(
            &s,
            &current.photometric,
            current.background.is_some(),
            UVec2::new(raw.width, raw.height),
            UVec2::new(k.width, k.height),
        );
    }
    state.current = Some(current);
}

/// A camera on a head: offers the frame's pixels outside the robot's `region` as a view (when
/// `offer`: its camera and the robot's region are known), and
/// returns the frame's H: the views re-projected into `camera` inside the region (the
/// `[background]` image where none sees a pixel), the frame itself outside it (where H is
/// never shown).
fn follow_view(
    vb: &mut ViewBackground,
    camera: &PinholeCamera,
    frame: &avatarm_video::VideoFrame,
    region: &[u8],
    offer: bool,
) -> avatarm_core::Result<Vec<u8>> {
    let started = std::time::Instant::now();
    let k = camera.intrinsics;
    let live = RgbaView::new("live frame", k.width, k.height, &frame.rgba)?;
    // How far this view is from those captured before it.
    vb.nearest_rad = vb.views.nearest_angle(camera);
    if offer {
        let blank = vb.views.blank();
        vb.views.offer(camera, &live, region, frame.capture_s)?;
        if blank == 0 && vb.views.blank() > 0 {
            info!(
                "background views: frame {} is blank (one colour: the camera not streaming yet?); not kept",
                frame.index
            );
        }
    }
    let mut fallback = frame.rgba.as_ref().clone();
    if let Some(seed) = vb.seed.as_ref().filter(|s| s.len() == fallback.len()) {
        for (i, &r) in region.iter().enumerate() {
            if r > 0 {
                fallback[i * 4..i * 4 + 4].copy_from_slice(&seed[i * 4..i * 4 + 4]);
            }
        }
    }
    let out = vb.views.render(camera, Some(fallback), Some(region))?;
    let inside = region.iter().filter(|&&r| r > 0).count();
    let seen = region
        .iter()
        .zip(&out.seen)
        .filter(|(r, s)| **r > 0 && **s > 0)
        .count();
    vb.seen_share = (inside > 0).then(|| seen as f64 / inside as f64);
    vb.cpu_ms = Some(started.elapsed().as_secs_f64() * 1e3);
    Ok(out.rgba)
}

/// Renders the mask and the passes only in an update with something new to draw (a camera
/// frame, new settings or H); before the first update of the pipeline, they render.
fn gate_passes(
    mut state: ResMut<EraseState>,
    pipeline: Option<Res<ErasePipeline>>,
    mut views: Query<(&mut FlatView, &mut EraseJob)>,
) {
    let Some((mut view, mut job)) = pipeline.and_then(|p| views.get_mut(p.0).ok()) else {
        return;
    };
    let active = state.current.as_ref().is_none_or(|s| s.dirty);
    if view.active != active {
        view.active = active;
    }
    job.render = active;
    if active {
        state.renders += 1;
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
