//! The interaction layer: what the user sees. The composite Ĩ(t) on a video panel that spans
//! the camera's frustum, and the object twins in front of it, placed by the paper's
//! perspective equations ([`avatarm_core::vision::placement`]) so that each covers its real object's
//! pixels. The interaction camera renders [`layers::INTERACTION`] into
//! [`InteractionTargets::view`]; the preview shows that image, and the XR mode the same panel.

use avatarm_core::vision::camera::PinholeCamera;
use avatarm_core::vision::placement::{panel_corners, place_twin};
use avatarm_twin::camera::{spawn_pinhole_camera, target_image};
use avatarm_twin::{CameraBound, iso_to_transform, layers};
use bevy::asset::embedded_asset;
use bevy::camera::visibility::RenderLayers;
use bevy::pbr::{Material, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::AsBindGroup;
use bevy::shader::ShaderRef;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::EraseTargets;

/// An object whose digital twin is drawn in front of the panel.
#[derive(Debug, Clone)]
pub struct ObjectTwinSpec {
    /// Name.
    pub name: String,
    /// Meshes with their transforms relative to the object's frame.
    pub parts: Vec<(Mesh, Transform)>,
    /// The real object's pose in the world (robot frame).
    pub world_from_object: Isometry3<f64>,
    /// Colour (sRGB, alpha).
    pub rgba: [f32; 4],
}

/// The interaction layer's layout. Insert before the app starts.
#[derive(Resource, Debug, Clone)]
pub struct InteractionConfig {
    /// The interaction camera: the real camera's intrinsics at the believed pose by default.
    pub camera: PinholeCamera,
    /// The real camera as the app believes it (for placing object twins).
    pub real_camera: PinholeCamera,
    /// Distance of the video panel from the interaction camera (m).
    pub panel_distance_m: f64,
    /// Depth of the object twins in front of the interaction camera (m); less than the panel's.
    pub object_depth_m: f64,
    /// The objects.
    pub objects: Vec<ObjectTwinSpec>,
}

/// The interaction camera's image, Ĩ(t) with the object twins.
#[derive(Resource, Debug, Clone)]
pub struct InteractionTargets {
    /// The view.
    pub view: Handle<Image>,
}

/// The video panel's material: its image as it is, unlit (`video_panel.wgsl`). Bevy's
/// `StandardMaterial`, even unlit, runs the whole PBR fragment; on a software rasteriser that
/// made the interaction camera the dearest view of a replay (measured: 55-67 ms of GPU time at
/// 640x480 on llvmpipe).
#[derive(Asset, TypePath, AsBindGroup, Debug, Clone)]
pub struct VideoPanelMaterial {
    /// What the panel shows (Ĩ(t)).
    #[texture(0)]
    #[sampler(1)]
    pub image: Handle<Image>,
}

impl Material for VideoPanelMaterial {
    fn fragment_shader() -> ShaderRef {
        "embedded://avatarm_erase/video_panel.wgsl".into()
    }
}

/// Marks an object twin; `index` into [`InteractionConfig::objects`].
#[derive(Component, Debug, Clone, Copy)]
pub struct ObjectTwin {
    /// Index of the object.
    pub index: usize,
    /// Uniform scale from the placement.
    pub scale: f64,
}

/// Spawns the panel, the object twins, a light and the interaction camera. Needs
/// [`crate::ErasePlugin`] (it shows [`EraseTargets::composite`]).
#[derive(Default)]
pub struct InteractionPlugin;

impl Plugin for InteractionPlugin {
    fn build(&self, app: &mut App) {
        embedded_asset!(app, "video_panel.wgsl");
        app.add_plugins(MaterialPlugin::<VideoPanelMaterial>::default())
            .add_systems(PostStartup, spawn_interaction)
            .add_systems(
                Update,
                (
                    follow_moving_camera,
                    follow_objects.run_if(resource_changed::<InteractionConfig>),
                )
                    .chain()
                    .in_set(crate::EraseSystems::Interaction),
            );
    }
}

/// Where an object's twin is drawn (world, scale included): the paper's placement for the
/// object's pose, in front of the interaction camera.
pub fn twin_transform(
    config: &InteractionConfig,
    object: &ObjectTwinSpec,
) -> Result<(Transform, f64), avatarm_core::Error> {
    let depth = config.object_depth_m.min(0.9 * config.panel_distance_m);
    let placement = place_twin(&config.real_camera, &object.world_from_object, depth)?;
    let world_from_twin = config.camera.world_from_camera * placement.camera_from_twin;
    Ok((
        iso_to_transform(&world_from_twin).with_scale(Vec3::splat(placement.scale as f32)),
        placement.scale,
    ))
}

/// A camera on a head: the twins are placed for the camera the frame on the panel was erased
/// with (the object as that frame shows it).
fn follow_moving_camera(
    erase: Option<Res<crate::EraseConfig>>,
    state: Option<Res<crate::EraseState>>,
    mut config: ResMut<InteractionConfig>,
) {
    let (Some(erase), Some(state)) = (erase, state) else {
        return;
    };
    if erase.head_mount.is_none() {
        return;
    }
    if let Some(pose) = state.camera_pose
        && config.real_camera.world_from_camera != pose
    {
        config.real_camera.world_from_camera = pose;
    }
}

/// Moves the twins when their objects move (the live teleoperation moves the twin the hand
/// holds).
fn follow_objects(
    config: Res<InteractionConfig>,
    mut twins: Query<(&mut ObjectTwin, &mut Transform)>,
) {
    for (mut twin, mut transform) in &mut twins {
        let Some(object) = config.objects.get(twin.index) else {
            continue;
        };
        if let Ok((t, scale)) = twin_transform(&config, object)
            && *transform != t
        {
            *transform = t;
            twin.scale = scale;
        }
    }
}

/// The interaction layer for the configured camera ([`InteractionConfig`]): the video panel
/// showing [`EraseTargets::composite`], the object twins, a light and the interaction camera
/// ([`InteractionTargets`]), each marked [`CameraBound`]. Runs after start-up; a camera switch
/// despawns them and runs it again for the next camera.
pub fn spawn_interaction(
    mut commands: Commands,
    config: Res<InteractionConfig>,
    erase: Option<Res<EraseTargets>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut panels: ResMut<Assets<VideoPanelMaterial>>,
    mut images: ResMut<Assets<Image>>,
) {
    let Some(erase) = erase else {
        error!("interaction layer: the erase plugin is not running; no panel");
        return;
    };
    let layer = RenderLayers::layer(layers::INTERACTION);
    let cam = &config.camera;
    let k = cam.intrinsics;
    // The panel spans the real camera's frustum at its distance, seen from the interaction
    // camera's centre (same normalised coordinates, whatever the interaction focal length).
    let d = config.panel_distance_m;
    let c = panel_corners(&config.real_camera.intrinsics, d);
    let centre = nalgebra::center(&c[0], &c[2]);
    let (width, height) = ((c[1] - c[0]).norm(), (c[3] - c[0]).norm());
    // Rectangle faces +z with +y up; the optical frame has y down, z forward.
    let flip = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let world_from_panel =
        cam.world_from_camera * Isometry3::from_parts(Translation3::from(centre.coords), flip);
    commands.spawn((
        Name::new("video panel"),
        Mesh3d(meshes.add(Rectangle::new(width as f32, height as f32))),
        MeshMaterial3d(panels.add(VideoPanelMaterial {
            image: erase.composite.clone(),
        })),
        iso_to_transform(&world_from_panel),
        layer.clone(),
        CameraBound,
    ));
    for (index, object) in config.objects.iter().enumerate() {
        let (transform, scale) = match twin_transform(&config, object) {
            Ok(p) => p,
            Err(e) => {
                warn!("object '{}': {e}; its twin is not drawn", object.name);
                continue;
            }
        };
        let material = materials.add(StandardMaterial {
            base_color: Color::srgba(
                object.rgba[0],
                object.rgba[1],
                object.rgba[2],
                object.rgba[3],
            ),
            perceptual_roughness: 0.6,
            ..default()
        });
        let root = commands
            .spawn((
                Name::new(format!("object twin: {}", object.name)),
                ObjectTwin { index, scale },
                transform,
                Visibility::default(),
                CameraBound,
            ))
            .id();
        for (mesh, local) in &object.parts {
            commands.spawn((
                Mesh3d(meshes.add(mesh.clone())),
                MeshMaterial3d(material.clone()),
                *local,
                layer.clone(),
                ChildOf(root),
            ));
        }
    }
    commands.spawn((
        DirectionalLight {
            illuminance: 6000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        iso_to_transform(&cam.world_from_view()),
        layer.clone(),
        CameraBound,
    ));
    let view = images.add(target_image(k.width, k.height));
    let camera = spawn_pinhole_camera(
        &mut commands,
        cam,
        view.clone(),
        layer,
        Color::BLACK,
        -17,
        "interaction camera",
    );
    commands.entity(camera).insert(CameraBound);
    commands.insert_resource(InteractionTargets { view });
}
