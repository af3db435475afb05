//! Building a twin's entities and meshes from a robot model.

use std::collections::HashMap;
use std::f32::consts::FRAC_PI_2;
use std::sync::Arc;

use avatarm_core::robot::mesh::{TriMesh, load_shape_mesh};
use avatarm_core::robot::{Geometry, GeometryKind, RobotModel, Shape};
use bevy::asset::RenderAssetUsages;
use bevy::camera::visibility::RenderLayers;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use nalgebra::{DVector, Isometry3};

use crate::flat::FlatPart;
use crate::{RobotTwin, TwinError, TwinLink, iso_to_transform};

/// How the twin looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TwinAppearance {
    /// Lit, in the URDF's material colours (grey where none is given).
    Urdf,
    /// Unlit, one flat colour: white for the mask, black for occluders.
    Unlit(Color),
    /// Lit, in the mesh file's own material colours (where the URDF gives none).
    VertexColors,
    /// No material: drawn by [`crate::flat::FlatView`]s only, in one grey level (the mask
    /// twin, the ground truth's silhouette).
    Flat(FlatPart),
}

/// How much of a description a twin draws: which geometry, and what fraction of each mesh's
/// triangles (simplified by [`TriMesh::simplified`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwinDetail {
    /// `<visual>` or `<collision>` elements.
    pub geometry: GeometryKind,
    /// Fraction of each mesh's triangles kept, in (0, 1].
    pub keep_triangles: f32,
}

impl Default for TwinDetail {
    fn default() -> Self {
        Self {
            geometry: GeometryKind::Visual,
            keep_triangles: 1.0,
        }
    }
}

/// Meshes and materials already built, shared by all twins (a robot's mesh files load once).
#[derive(Resource, Default, Debug)]
pub struct TwinMeshCache {
    meshes: HashMap<String, (Handle<Mesh>, bool)>,
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
    detail: TwinDetail,
    layers: &RenderLayers,
) -> Result<(), TwinError> {
    for (link, &entity) in model.links.iter().zip(&twin.links) {
        for g in link.geometry(detail.geometry) {
            // The file's own colours only where the URDF gives none, and never on a flat twin.
            let vertex_colors = appearance == TwinAppearance::Urdf && g.rgba.is_none();
            let (mesh, transform, coloured) = mesh_for(
                meshes,
                cache,
                &link.name,
                g,
                vertex_colors,
                detail.keep_triangles,
            )
            .map_err(|source| TwinError::Mesh {
                robot: model.name.clone(),
                link: link.name.clone(),
                source: Box::new(source),
            })?;
            let appearance = match appearance {
                // White under the vertex colours, which Bevy multiplies in.
                TwinAppearance::Urdf if coloured => TwinAppearance::VertexColors,
                other => other,
            };
            let mut part =
                commands.spawn((Mesh3d(mesh), transform, layers.clone(), ChildOf(entity)));
            match appearance {
                TwinAppearance::Flat(flat) => part.insert(flat),
                lit => part.insert(MeshMaterial3d(material_for(materials, cache, g, lit))),
            };
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

/// Spawns a twin of `model` at `base` with its geometry at `detail` on `layers`: the one way
/// every twin of the app is made (the app's twin, the mask twin, the simulated robot and its
/// silhouette). A mesh that cannot be loaded is the same clear error everywhere: logged naming
/// the `role`, the robot, the link, the URI and the file, and the app exits with an error (a
/// twin with a missing link would erase the wrong pixels).
#[expect(
    clippy::too_many_arguments,
    reason = "where, how it looks and how detailed are separate inputs"
)]
pub fn spawn_twin_with_visuals(
    commands: &mut Commands,
    assets: &mut TwinAssets,
    model: &Arc<RobotModel>,
    base: &Isometry3<f64>,
    appearance: TwinAppearance,
    detail: TwinDetail,
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
        detail,
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
                    ..double_sided()
                },
            )
        }
        TwinAppearance::VertexColors => (
            "vertex colours".to_owned(),
            StandardMaterial {
                base_color: Color::WHITE,
                perceptual_roughness: 0.55,
                metallic: 0.05,
                ..double_sided()
            },
        ),
        // Flat parts take no material (attach_visuals); asked for one, it is the unlit white.
        TwinAppearance::Flat(_) => {
            return material_for(materials, cache, g, TwinAppearance::Unlit(Color::WHITE));
        }
        TwinAppearance::Unlit(color) => (
            format!("unlit {color:?}"),
            StandardMaterial {
                base_color: color,
                unlit: true,
                ..double_sided()
            },
        ),
    };
    cache
        .materials
        .entry(key)
        .or_insert_with(|| materials.add(material))
        .clone()
}

/// No back-face culling: real description meshes often mix triangle windings (and a link seen
/// through a gap shows its inside), so a culled twin has holes where the robot has none, in
/// the silhouette the mask is made of as much as in the picture.
fn double_sided() -> StandardMaterial {
    StandardMaterial {
        double_sided: true,
        cull_mode: None,
        ..default()
    }
}

/// A primitive shape as Bevy tessellates it (`None` for a mesh file).
fn primitive_mesh(shape: &Shape) -> Option<Mesh> {
    Some(match shape {
        Shape::Box { size } => Cuboid::new(size.x as f32, size.y as f32, size.z as f32).into(),
        Shape::Cylinder { radius, length } => Cylinder::new(*radius as f32, *length as f32).into(),
        Shape::Capsule { radius, length } => Capsule3d::new(*radius as f32, *length as f32).into(),
        Shape::Sphere { radius } => Sphere::new(*radius as f32).into(),
        Shape::Mesh { .. } => return None,
    })
}

/// The mesh of a geometry of `link` (built once per shape, colouring and detail), its transform
/// in the link, and whether it carries the file's vertex colours (only when asked and the file
/// has some).
fn mesh_for(
    meshes: &mut Assets<Mesh>,
    cache: &mut TwinMeshCache,
    link: &str,
    g: &Geometry,
    vertex_colors: bool,
    keep_triangles: f32,
) -> Result<(Handle<Mesh>, Transform, bool), avatarm_core::Error> {
    let origin = iso_to_transform(&g.origin);
    // Bevy's cylinders and capsules run along y; URDF's along z.
    let z_up = Transform::from_rotation(Quat::from_rotation_x(FRAC_PI_2));
    let transform = match &g.shape {
        Shape::Cylinder { .. } | Shape::Capsule { .. } => origin * z_up,
        _ => origin,
    };
    let vertex_colors = vertex_colors && matches!(g.shape, Shape::Mesh { .. });
    let key = format!(
        "{:?} colours {vertex_colors} keep {keep_triangles}",
        g.shape
    );
    if let Some((h, coloured)) = cache.meshes.get(&key) {
        return Ok((h.clone(), transform, *coloured));
    }
    let (mesh, coloured) = match primitive_mesh(&g.shape) {
        Some(mesh) => (mesh, false),
        None => {
            let mut tri = load_shape_mesh(link, &g.shape)
                .transpose()?
                .unwrap_or_default()
                .simplified(keep_triangles);
            if !vertex_colors {
                tri.colors = None;
            }
            let coloured = tri.colors.is_some();
            (to_bevy_mesh(tri), coloured)
        }
    };
    let handle = meshes.add(mesh);
    cache.meshes.insert(key, (handle.clone(), coloured));
    Ok((handle, transform, coloured))
}

/// Triangles a twin at `detail` draws (meshes loaded and simplified, primitives as Bevy
/// tessellates them), or the first mesh error naming the link and URI.
pub fn twin_triangles(
    model: &RobotModel,
    detail: TwinDetail,
) -> Result<usize, avatarm_core::Error> {
    let mut total = 0;
    for link in &model.links {
        for g in link.geometry(detail.geometry) {
            total += match primitive_mesh(&g.shape) {
                Some(mesh) => mesh.indices().map_or(0, |i| i.len() / 3),
                None => load_shape_mesh(&link.name, &g.shape)
                    .transpose()?
                    .map_or(0, |tri| {
                        tri.simplified(detail.keep_triangles).triangle_count()
                    }),
            };
        }
    }
    Ok(total)
}

/// Converts a loaded triangle mesh; flat normals are computed when the file has none. The
/// file's colours (sRGB, as URDF's) become the linear vertex colours Bevy multiplies the
/// material's base colour by.
pub fn to_bevy_mesh(tri: TriMesh) -> Mesh {
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, tri.positions)
    .with_inserted_indices(Indices::U32(tri.indices));
    if let Some(colors) = tri.colors {
        let linear: Vec<[f32; 4]> = colors
            .iter()
            .map(|&[r, g, b, a]| Color::srgba(r, g, b, a).to_linear().to_f32_array())
            .collect();
        mesh.insert_attribute(Mesh::ATTRIBUTE_COLOR, linear);
    }
    match tri.normals {
        Some(n) => mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, n),
        None => {
            mesh.duplicate_vertices();
            mesh.compute_flat_normals();
        }
    }
    mesh
}
