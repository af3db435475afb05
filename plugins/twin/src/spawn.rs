//! Building a twin's entities and meshes from a robot model.

use std::collections::HashMap;
use std::f32::consts::FRAC_PI_2;
use std::sync::Arc;

use avatarm_core::robot::mesh::{TriMesh, load_mesh};
use avatarm_core::robot::{Geometry, RobotModel, Shape};
use bevy::asset::RenderAssetUsages;
use bevy::camera::visibility::RenderLayers;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use nalgebra::{DVector, Isometry3};

use crate::{RobotTwin, TwinError, TwinLink, iso_to_transform};

/// How the twin looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TwinAppearance {
    /// Lit, in the URDF's material colours (grey where none is given).
    Urdf,
    /// Unlit, one flat colour: white for the mask, black for occluders.
    Unlit(Color),
}

/// Which geometry of each link to draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GeometrySource {
    /// The `<visual>` elements.
    #[default]
    Visual,
    /// The `<collision>` elements (coarser; a fallback for unsupported visual meshes).
    Collision,
}

/// Meshes and materials already built, shared by all twins (a robot's mesh files load once).
#[derive(Resource, Default, Debug)]
pub struct TwinMeshCache {
    meshes: HashMap<String, Handle<Mesh>>,
    materials: HashMap<String, Handle<StandardMaterial>>,
}

/// The twin's entities.
#[derive(Debug, Clone)]
pub struct TwinEntities {
    /// The root, carrying [`RobotTwin`]; its transform is the robot's base pose.
    pub root: Entity,
    /// One entity per link, children of the root.
    pub links: Vec<Entity>,
}

/// Spawns a twin's root and link entities (no meshes: see [`attach_visuals`]).
pub fn spawn_twin(
    commands: &mut Commands,
    model: Arc<RobotModel>,
    base: &Isometry3<f64>,
) -> TwinEntities {
    let root = commands
        .spawn((
            Name::new(format!("robot twin {}", model.name)),
            iso_to_transform(base),
            Visibility::default(),
        ))
        .id();
    let zero: Vec<f64> = vec![0.0; model.dof()];
    let poses = model.forward_kinematics(&Isometry3::identity(), &zero);
    let links: Vec<Entity> = model
        .links
        .iter()
        .enumerate()
        .map(|(index, link)| {
            commands
                .spawn((
                    Name::new(link.name.clone()),
                    TwinLink { twin: root, index },
                    iso_to_transform(&poses[index]),
                    Visibility::default(),
                    ChildOf(root),
                ))
                .id()
        })
        .collect();
    let n = model.dof();
    commands.entity(root).insert(RobotTwin {
        model,
        positions: DVector::zeros(n),
        velocities: DVector::zeros(n),
        stamp_s: None,
        links: links.clone(),
        rejected: 0,
        strict_names: true,
    });
    TwinEntities { root, links }
}

/// Adds each link's geometry as mesh entities on `layers`.
#[expect(
    clippy::too_many_arguments,
    reason = "the asset stores and the look are separate inputs"
)]
pub fn attach_visuals(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    materials: &mut Assets<StandardMaterial>,
    cache: &mut TwinMeshCache,
    model: &RobotModel,
    twin: &TwinEntities,
    appearance: TwinAppearance,
    source: GeometrySource,
    layers: &RenderLayers,
) -> Result<(), TwinError> {
    for (link, &entity) in model.links.iter().zip(&twin.links) {
        let geometry = match source {
            GeometrySource::Visual => &link.visuals,
            GeometrySource::Collision => &link.collisions,
        };
        for g in geometry {
            let (mesh, transform) =
                mesh_for(meshes, cache, g).map_err(|source| TwinError::Mesh {
                    robot: model.name.clone(),
                    link: link.name.clone(),
                    source: Box::new(source),
                })?;
            let material = material_for(materials, cache, g, appearance);
            commands.spawn((
                Mesh3d(mesh),
                MeshMaterial3d(material),
                transform,
                layers.clone(),
                ChildOf(entity),
            ));
        }
    }
    Ok(())
}

/// The assets a twin's visuals are built into.
#[derive(bevy::ecs::system::SystemParam)]
pub struct TwinAssets<'w> {
    /// Meshes.
    pub meshes: ResMut<'w, Assets<Mesh>>,
    /// Materials.
    pub materials: ResMut<'w, Assets<StandardMaterial>>,
    /// Meshes and materials already built.
    pub cache: ResMut<'w, TwinMeshCache>,
}

/// Spawns a twin of `model` at `base` with its visual geometry on `layers`: the one way every
/// twin of the app is made (the app's twin, the mask twin, the simulated robot and its
/// silhouette). A mesh that cannot be loaded is the same clear error everywhere: logged naming
/// the `role`, the robot, the link and the file, and the app exits with an error (a twin with
/// a missing link would erase the wrong pixels).
pub fn spawn_twin_with_visuals(
    commands: &mut Commands,
    assets: &mut TwinAssets,
    model: &Arc<RobotModel>,
    base: &Isometry3<f64>,
    appearance: TwinAppearance,
    layers: &RenderLayers,
    role: &str,
) -> TwinEntities {
    let twin = spawn_twin(commands, Arc::clone(model), base);
    if let Err(e) = attach_visuals(
        commands,
        &mut assets.meshes,
        &mut assets.materials,
        &mut assets.cache,
        model,
        &twin,
        appearance,
        GeometrySource::Visual,
        layers,
    ) {
        error!("{role}: {e}");
        commands.queue(|world: &mut World| {
            world.write_message(AppExit::error());
        });
    }
    twin
}

fn material_for(
    materials: &mut Assets<StandardMaterial>,
    cache: &mut TwinMeshCache,
    g: &Geometry,
    appearance: TwinAppearance,
) -> Handle<StandardMaterial> {
    let (key, material) = match appearance {
        TwinAppearance::Urdf => {
            let [r, gr, b, a] = g.rgba.unwrap_or([0.6, 0.6, 0.6, 1.0]);
            (
                format!("urdf {r} {gr} {b} {a}"),
                StandardMaterial {
                    base_color: Color::srgba(r, gr, b, a),
                    perceptual_roughness: 0.55,
                    metallic: 0.05,
                    ..default()
                },
            )
        }
        TwinAppearance::Unlit(color) => (
            format!("unlit {color:?}"),
            StandardMaterial {
                base_color: color,
                unlit: true,
                ..default()
            },
        ),
    };
    cache
        .materials
        .entry(key)
        .or_insert_with(|| materials.add(material))
        .clone()
}

fn mesh_for(
    meshes: &mut Assets<Mesh>,
    cache: &mut TwinMeshCache,
    g: &Geometry,
) -> Result<(Handle<Mesh>, Transform), avatarm_core::Error> {
    let origin = iso_to_transform(&g.origin);
    // Bevy's cylinders and capsules run along y; URDF's along z.
    let z_up = Transform::from_rotation(Quat::from_rotation_x(FRAC_PI_2));
    let (key, transform) = match &g.shape {
        Shape::Cylinder { .. } | Shape::Capsule { .. } => (format!("{:?}", g.shape), origin * z_up),
        _ => (format!("{:?}", g.shape), origin),
    };
    if let Some(h) = cache.meshes.get(&key) {
        return Ok((h.clone(), transform));
    }
    let mesh: Mesh = match &g.shape {
        Shape::Box { size } => Cuboid::new(size.x as f32, size.y as f32, size.z as f32).into(),
        Shape::Cylinder { radius, length } => Cylinder::new(*radius as f32, *length as f32).into(),
        Shape::Capsule { radius, length } => Capsule3d::new(*radius as f32, *length as f32).into(),
        Shape::Sphere { radius } => Sphere::new(*radius as f32).into(),
        Shape::Mesh { path, scale, .. } => to_bevy_mesh(load_mesh(path, scale)?),
    };
    let handle = meshes.add(mesh);
    cache.meshes.insert(key, handle.clone());
    Ok((handle, transform))
}

/// Converts a loaded triangle mesh; flat normals are computed when the file has none.
pub fn to_bevy_mesh(tri: TriMesh) -> Mesh {
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, tri.positions)
    .with_inserted_indices(Indices::U32(tri.indices));
    match tri.normals {
        Some(n) => mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, n),
        None => {
            mesh.duplicate_vertices();
            mesh.compute_flat_normals();
        }
    }
    mesh
}
