//! The robot twin plugin: a URDF robot as Bevy entities, driven by joint states.
//!
//! - [`spawn_twin`] builds a root entity with one child entity per link ([`TwinLink`]); the
//!   joints stay data in the root's [`RobotTwin`] component. [`attach_visuals`] adds the link
//!   geometry as meshes on chosen [`RenderLayers`](bevy::camera::visibility::RenderLayers).
//! - [`JointStateMessage`]s update a twin; bad ones are refused and the last good state kept.
//! - [`camera::PinholeProjection`] matches a Bevy camera to pinhole intrinsics.
//! - [`readback::read_image_once`] reads a render target back without disturbing the cameras
//!   that sample it.
//!
//! - [`spawn_twin_with_visuals`] is the one way the app spawns a twin with its meshes (one
//!   clear error for a mesh that cannot be loaded); [`iso_to_transform`] and
//!   [`transform_to_iso`] the one conversion between poses and transforms.
//!
//! Modules: [`camera`] (pinhole projection, render targets), [`flat`] (flat silhouettes, the
//! mask twin's and the ground truth's, without a camera), [`gpu_timing`] (GPU time of cameras
//! and passes), [`layers`] (the render layers every plugin uses), [`readback`] (image
//! read-back), `spawn` (twin entities and meshes, re-exported here).
//!
//! Frames: Avatarm's world is the robot's world, z up, metres; link transforms are FK poses.

pub mod camera;
pub mod flat;
pub mod gpu_timing;
pub mod layers;
pub mod readback;
mod spawn;

use std::sync::Arc;

use avatarm_core::robot::RobotModel;
use bevy::prelude::*;
use bevy::transform::TransformSystems;
use nalgebra::{DVector, Isometry3};

pub use avatarm_core::robot::GeometryKind;
pub use spawn::{
    TwinAppearance, TwinAssets, TwinDetail, TwinEntities, TwinMeshCache, attach_visuals,
    spawn_twin, spawn_twin_with_visuals, to_bevy_mesh, twin_triangles,
};

/// What most users of the twin need.
pub mod prelude {
    pub use crate::camera::PinholeProjection;
    pub use crate::{
        GeometryKind, JointStateMessage, RobotTwin, RobotTwinPlugin, RobotTwinSystems,
        TwinAppearance, TwinAssets, TwinDetail, TwinLink, attach_visuals, iso_to_transform,
        spawn_twin, spawn_twin_with_visuals, transform_to_iso,
    };
}

/// Errors of the twin.
#[derive(Debug, thiserror::Error)]
pub enum TwinError {
    /// A link's mesh could not be loaded.
    #[error("robot '{robot}': {source}")]
    Mesh {
        /// The robot.
        robot: String,
        /// The link.
        link: String,
        /// Why.
        source: Box<avatarm_core::Error>,
    },
    /// A joint state that cannot be applied (sizes that do not match, a non-finite value, an
    /// unknown joint name); the twin keeps its previous state.
    #[error("joint state: {message}")]
    JointState {
        /// What is wrong.
        message: String,
    },
    /// An image read back from the GPU that cannot be used.
    #[error("image read-back: {message}")]
    Readback {
        /// What is wrong.
        message: String,
    },
}

/// The twin's system sets, in `PostUpdate` before transform propagation, in this order.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RobotTwinSystems {
    /// Reads [`JointStateMessage`]s into [`RobotTwin`] (`PostUpdate`).
    ApplyJointStates,
    /// Sets link transforms from forward kinematics (`PostUpdate`).
    PoseLinks,
}

/// Adds the twin's messages and systems.
#[derive(Default)]
pub struct RobotTwinPlugin;

impl Plugin for RobotTwinPlugin {
    fn build(&self, app: &mut App) {
        app.add_message::<JointStateMessage>()
            .init_resource::<TwinMeshCache>()
            .configure_sets(
                PostUpdate,
                (
                    RobotTwinSystems::ApplyJointStates,
                    RobotTwinSystems::PoseLinks,
                )
                    .chain()
                    .before(TransformSystems::Propagate),
            )
            .add_systems(
                PostUpdate,
                (
                    apply_joint_states.in_set(RobotTwinSystems::ApplyJointStates),
                    pose_links.in_set(RobotTwinSystems::PoseLinks),
                ),
            );
    }
}

/// A robot twin: the model, the last good joint state, and its link entities.
#[derive(Component, Debug, Clone)]
pub struct RobotTwin {
    /// The robot.
    pub model: Arc<RobotModel>,
    /// Joint positions of the last good state (joint-vector order).
    pub positions: DVector<f64>,
    /// Joint velocities of the last good state (zeros when not reported).
    pub velocities: DVector<f64>,
    /// Timestamp of the last good state (s); `None` before the first.
    pub stamp_s: Option<f64>,
    /// Link entities, indexed like `model.links`.
    pub links: Vec<Entity>,
    /// Messages refused so far.
    pub rejected: u64,
    /// Treat joint names the robot does not have as an error (default) or skip them.
    pub strict_names: bool,
}

/// Marks an entity that belongs to the camera the app looks through now (its room views, its
/// mask twin and erase pipeline, its interaction camera and panel): a camera switch despawns
/// every such entity and the plugins spawn the next camera's (`avatarm`'s preview, key C).
#[derive(Component, Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CameraBound;

/// Marks a link entity of a twin.
#[derive(Component, Debug, Clone, Copy, PartialEq, Eq)]
pub struct TwinLink {
    /// The twin's root entity.
    pub twin: Entity,
    /// Index into the model's links.
    pub index: usize,
}

/// A joint state for one twin: names and positions (velocities optional), with a timestamp.
#[derive(Message, Debug, Clone, PartialEq)]
pub struct JointStateMessage {
    /// The twin's root entity.
    pub twin: Entity,
    /// Joint names (any subset of the movable joints).
    pub names: Vec<String>,
    /// Positions, one per name.
    pub positions: Vec<f64>,
    /// Velocities, one per name, or empty.
    pub velocities: Vec<f64>,
    /// When the state was sampled (s).
    pub stamp_s: f64,
}

impl JointStateMessage {
    /// A message naming every movable joint of `model`, in joint-vector order.
    pub fn full(
        twin: Entity,
        model: &RobotModel,
        positions: &DVector<f64>,
        velocities: &DVector<f64>,
        stamp_s: f64,
    ) -> Self {
        Self {
            twin,
            names: model.dof_names().iter().map(|s| s.to_string()).collect(),
            positions: positions.iter().copied().collect(),
            velocities: velocities.iter().copied().collect(),
            stamp_s,
        }
    }
}

impl RobotTwin {
    /// Applies a joint state, or says why it was refused (nothing changes then).
    pub fn apply(&mut self, msg: &JointStateMessage) -> Result<(), TwinError> {
        let bad = |message: String| TwinError::JointState { message };
        if msg.names.len() != msg.positions.len()
            || (!msg.velocities.is_empty() && msg.velocities.len() != msg.names.len())
        {
            return Err(bad(format!(
                "{} names, {} positions and {} velocities do not match",
                msg.names.len(),
                msg.positions.len(),
                msg.velocities.len()
            )));
        }
        if !msg.stamp_s.is_finite() {
            return Err(bad(format!("timestamp {} is not finite", msg.stamp_s)));
        }
        let mut positions = self.positions.clone();
        let mut velocities = self.velocities.clone();
        for (k, name) in msg.names.iter().enumerate() {
            let index = match self.model.dof_index(name) {
                Ok(i) => i,
                // A mimic joint (a gripper's second finger) follows its leader; ROS joint states
                // name it too.
                Err(avatarm_core::Error::MimicJoint { .. }) => continue,
                Err(_) if !self.strict_names => continue,
                Err(e) => return Err(bad(e.to_string())),
            };
            let p = msg.positions[k];
            let v = msg.velocities.get(k).copied().unwrap_or(0.0);
            if !p.is_finite() || !v.is_finite() {
                return Err(bad(format!(
                    "joint '{name}': position {p} / velocity {v} is not finite"
                )));
            }
            positions[index] = p;
            velocities[index] = v;
        }
        self.positions = positions;
        self.velocities = velocities;
        self.stamp_s = Some(msg.stamp_s);
        Ok(())
    }
}

/// An app without a renderer or window (`MinimalPlugins`, assets, 10 ms per update) with the
/// asset types twins and the room's props are built from (`Mesh`, `StandardMaterial`,
/// `Image`): for testing a plugin's entities, layers and systems without a GPU.
pub fn headless_app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, AssetPlugin::default()))
        .init_asset::<Mesh>()
        .init_asset::<StandardMaterial>()
        .init_asset::<Image>()
        .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            std::time::Duration::from_millis(10),
        ));
    app
}

/// Converts a pose to a Bevy transform (f64 -> f32, unit scale). The one conversion of the
/// workspace, with [`transform_to_iso`] its inverse.
pub fn iso_to_transform(iso: &Isometry3<f64>) -> Transform {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Transform {
        translation: Vec3::new(t.x as f32, t.y as f32, t.z as f32),
        rotation: Quat::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize(),
        scale: Vec3::ONE,
    }
}

/// Converts a Bevy transform to a pose (f32 -> f64; the scale is ignored).
pub fn transform_to_iso(t: &Transform) -> Isometry3<f64> {
    let p = t.translation.as_dvec3();
    let q = t.rotation.as_dquat();
    Isometry3::from_parts(
        nalgebra::Translation3::new(p.x, p.y, p.z),
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
    )
}

/// Reads joint states into their twins; refused messages are logged and counted.
pub fn apply_joint_states(
    mut messages: MessageReader<JointStateMessage>,
    mut twins: Query<&mut RobotTwin>,
) {
    for msg in messages.read() {
        let Ok(mut twin) = twins.get_mut(msg.twin) else {
            warn!("joint state for {:?}, which is not a robot twin", msg.twin);
            continue;
        };
        if let Err(why) = twin.apply(msg) {
            twin.rejected += 1;
            // One line per refused message would flood the log at 100 Hz: log the first and
            // then every 100th.
            if twin.rejected % 100 == 1 {
                warn!(
                    "robot '{}': joint state at t={:.3}s refused ({} so far), keeping the last good state: {why}",
                    twin.model.name, msg.stamp_s, twin.rejected
                );
            }
        }
    }
}

/// Poses every link of changed twins by forward kinematics.
pub fn pose_links(
    twins: Query<&RobotTwin, Changed<RobotTwin>>,
    mut links: Query<&mut Transform, With<TwinLink>>,
) {
    for twin in &twins {
        let q: Vec<f64> = twin.positions.iter().copied().collect();
        let poses = twin.model.forward_kinematics(&Isometry3::identity(), &q);
        for (entity, pose) in twin.links.iter().zip(&poses) {
            if let Ok(mut t) = links.get_mut(*entity) {
                *t = iso_to_transform(pose);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use avatarm_core::robot::PackagePath;

    fn app_with_twin() -> (App, Entity, Arc<RobotModel>) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../assets/robots/sawyer_lite/sawyer_lite.urdf");
        let model = Arc::new(RobotModel::from_urdf_file(&path, &PackagePath::default()).unwrap());
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, TransformPlugin, RobotTwinPlugin));
        let base = Isometry3::translation(0.0, 0.0, 0.75);
        let twin = spawn_twin(&mut app.world_mut().commands(), model.clone(), &base).root;
        app.update();
        (app, twin, model)
    }

    fn send(app: &mut App, msg: JointStateMessage) {
        app.world_mut().write_message(msg);
        app.update();
    }

    #[test]
    fn joint_states_pose_the_links_by_fk() {
        let (mut app, twin, model) = app_with_twin();
        let q = DVector::from_vec(vec![0.3, -0.9, 0.1, 1.6, -0.2, 0.7, 1.1, 0.01, 0.01]);
        send(
            &mut app,
            JointStateMessage::full(twin, &model, &q, &DVector::zeros(9), 1.0),
        );
        let tip = model.link_id("right_gripper_tip").unwrap();
        let entity = app.world().get::<RobotTwin>(twin).unwrap().links[tip];
        let global = app.world().get::<GlobalTransform>(entity).unwrap();
        let qv: Vec<f64> = q.iter().copied().collect();
        let expected = model.forward_kinematics(&Isometry3::translation(0.0, 0.0, 0.75), &qv)[tip];
        let got = global.translation();
        let e = expected.translation.vector;
        assert!((got - Vec3::new(e.x as f32, e.y as f32, e.z as f32)).length() < 1e-5);
    }

    #[test]
    fn bad_states_are_refused_and_the_last_good_one_kept() {
        let (mut app, twin, model) = app_with_twin();
        let good = DVector::from_vec(vec![0.2; 9]);
        send(
            &mut app,
            JointStateMessage::full(twin, &model, &good, &DVector::zeros(9), 1.0),
        );
        let mut nan = JointStateMessage::full(twin, &model, &good, &DVector::zeros(9), 2.0);
        nan.positions[3] = f64::NAN;
        send(&mut app, nan);
        let unknown = JointStateMessage {
            twin,
            names: vec!["head_pan".into()],
            positions: vec![1.0],
            velocities: vec![],
            stamp_s: 3.0,
        };
        send(&mut app, unknown.clone());
        let state = app.world().get::<RobotTwin>(twin).unwrap();
        assert_eq!(state.positions, good);
        assert_eq!(state.stamp_s, Some(1.0));
        assert_eq!(state.rejected, 2);
        // With strict names off, unknown joints are skipped and the rest applies.
        app.world_mut()
            .get_mut::<RobotTwin>(twin)
            .unwrap()
            .strict_names = false;
        let mut partial = unknown;
        partial.names.push("right_j0".into());
        partial.positions.push(-0.5);
        send(&mut app, partial);
        let state = app.world().get::<RobotTwin>(twin).unwrap();
        assert_eq!(state.positions[0], -0.5);
        assert_eq!(state.positions[1], 0.2);
    }

    /// ../shared/cases/09: the follower is posed from its leader; a joint state naming it (as
    /// ROS's do) is not refused.
    #[test]
    fn a_mimic_joint_follows_and_its_state_is_skipped() {
        let urdf = r#"<robot name="m"><link name="base"/><link name="l1"/><link name="l2"/>
          <joint name="lead" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
            <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
          <joint name="follow" type="revolute"><parent link="l1"/><child link="l2"/>
            <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-4" upper="4" effort="1" velocity="1"/>
            <mimic joint="lead" multiplier="2" offset="0.1"/></joint></robot>"#;
        let model =
            Arc::new(RobotModel::from_urdf_str(urdf, None, &PackagePath::default()).unwrap());
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, TransformPlugin, RobotTwinPlugin));
        let twin = spawn_twin(
            &mut app.world_mut().commands(),
            model.clone(),
            &Isometry3::identity(),
        )
        .root;
        app.update();
        send(
            &mut app,
            JointStateMessage {
                twin,
                names: vec!["lead".into(), "follow".into()],
                positions: vec![0.3, 0.7],
                velocities: vec![],
                stamp_s: 1.0,
            },
        );
        let state = app.world().get::<RobotTwin>(twin).unwrap();
        assert_eq!(
            (state.rejected, state.positions.as_slice()),
            (0, &[0.3][..])
        );
        let l2 = state.links[model.link_id("l2").unwrap()];
        let rotation = app.world().get::<GlobalTransform>(l2).unwrap().rotation();
        // The follower at 2 * 0.3 + 0.1 on top of the leader's 0.3.
        let (axis, angle) = rotation.to_axis_angle();
        assert!((axis.z * angle - 1.0).abs() < 1e-5, "{axis} {angle}");
    }

    /// The preview twin wears the mesh file's material colours where the URDF gives none (and
    /// the URDF's where it does); the mask twin draws no colour at all.
    #[test]
    fn the_preview_twin_wears_the_mesh_colours_and_the_mask_twin_white() {
        use bevy::ecs::system::RunSystemOnce;
        let dir = std::env::temp_dir().join(format!("avatarm_twin_colours_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("part.dae"),
            r##"<?xml version="1.0"?><COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<asset><unit meter="1"/><up_axis>Z_UP</up_axis></asset>
<library_effects><effect id="fx"><profile_COMMON><technique sid="c"><phong><diffuse><color>0.9 0.5 0.1 1</color></diffuse></phong></technique></profile_COMMON></effect></library_effects>
<library_materials><material id="orange"><instance_effect url="#fx"/></material></library_materials>
<library_geometries><geometry id="g"><mesh>
<source id="p"><float_array id="pa" count="9">0 0 0 0.1 0 0 0 0.1 0</float_array><technique_common><accessor source="#pa" count="3" stride="3"><param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>
<vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
<triangles material="m" count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>
</mesh></geometry></library_geometries>
<library_visual_scenes><visual_scene id="s"><node id="n"><instance_geometry url="#g"><bind_material><technique_common><instance_material symbol="m" target="#orange"/></technique_common></bind_material></instance_geometry></node></visual_scene></library_visual_scenes>
<scene><instance_visual_scene url="#s"/></scene></COLLADA>"##,
        )
        .unwrap();
        let urdf = r#"<robot name="c">
          <link name="plain"><visual><geometry><mesh filename="part.dae"/></geometry></visual></link>
          <link name="painted"><visual><geometry><mesh filename="part.dae"/></geometry>
            <material name="blue"><color rgba="0 0 1 1"/></material></visual></link>
          <joint name="j" type="fixed"><parent link="plain"/><child link="painted"/></joint></robot>"#;
        let model =
            Arc::new(RobotModel::from_urdf_str(urdf, Some(&dir), &PackagePath::default()).unwrap());
        for (appearance, plain_coloured) in [
            (TwinAppearance::Urdf, true),
            (TwinAppearance::Unlit(Color::WHITE), false),
        ] {
            let mut app = headless_app();
            app.init_resource::<TwinMeshCache>();
            let m = model.clone();
            let twin = app
                .world_mut()
                .run_system_once(move |mut commands: Commands, mut assets: TwinAssets| {
                    spawn_twin_with_visuals(
                        &mut commands,
                        &mut assets,
                        &m,
                        &Isometry3::identity(),
                        appearance,
                        TwinDetail::default(),
                        &bevy::camera::visibility::RenderLayers::layer(1),
                        "test twin",
                    )
                })
                .unwrap();
            app.update();
            let world = app.world_mut();
            let mut parts = world.query::<(&Mesh3d, &ChildOf)>();
            let world = &*world;
            let mut coloured = |link: usize| {
                let (mesh, _) = parts
                    .iter(world)
                    .find(|(_, parent)| parent.parent() == twin.links[link])
                    .expect("the link's mesh");
                world
                    .resource::<Assets<Mesh>>()
                    .get(&mesh.0)
                    .expect("mesh asset")
                    .contains_attribute(Mesh::ATTRIBUTE_COLOR)
            };
            assert_eq!(coloured(0), plain_coloured, "{appearance:?}: plain");
            assert!(!coloured(1), "{appearance:?}: the URDF's material wins");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
