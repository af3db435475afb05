//! `avatarm robot`: print a robot description's tree, limits and link poses.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::PathBuf;

use avatarm_core::robot::mesh::load_shape_mesh;
use avatarm_core::robot::{JointKind, LinkId, RobotModel, Shape};
use clap::Args;
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::AppError;
use crate::cli::args::packages;

/// One mesh file a link names, loaded.
#[derive(Debug, Clone)]
pub struct MeshLine {
    /// The link.
    pub link: LinkId,
    /// `visual` or `collision`.
    pub role: &'static str,
    /// The resolved file.
    pub path: std::path::PathBuf,
    /// Its triangles.
    pub triangles: usize,
}

/// Loads every mesh the robot names, or the first error naming the link, the URI and the file.
pub fn check_meshes(model: &RobotModel) -> Result<Vec<MeshLine>, avatarm_core::Error> {
    let mut lines = Vec::new();
    for (id, link) in model.links.iter().enumerate() {
        let tagged = link
            .visuals
            .iter()
            .map(|g| ("visual", g))
            .chain(link.collisions.iter().map(|g| ("collision", g)));
        for (role, g) in tagged {
            if let (Some(mesh), Shape::Mesh { path, .. }) =
                (load_shape_mesh(&link.name, &g.shape), &g.shape)
            {
                let mesh = mesh?;
                lines.push(MeshLine {
                    link: id,
                    role,
                    path: path.clone(),
                    triangles: mesh.triangle_count(),
                });
            }
        }
    }
    Ok(lines)
}

/// `mesh LINK (ROLE): FILE (N triangles)` lines, one per mesh.
pub fn mesh_text(model: &RobotModel, meshes: &[MeshLine]) -> String {
    let mut out = String::new();
    for m in meshes {
        let _ = writeln!(
            out,
            "mesh {} ({}): {} ({} triangles)",
            model.links[m.link].name,
            m.role,
            m.path.display(),
            m.triangles
        );
    }
    out
}

/// The joint/link tree with limits, mimic joints and each link's visual meshes, as text.
pub fn tree_text(model: &RobotModel, meshes: &[MeshLine]) -> String {
    let mut out = String::new();
    for note in &model.notes {
        let _ = writeln!(out, "note: {note}");
    }
    let _ = writeln!(
        out,
        "robot '{}' ({}): {} links, {} joints, {} movable",
        model.name,
        model.origin,
        model.links.len(),
        model.joints.len(),
        model.dof()
    );
    let _ = writeln!(
        out,
        "movable joints in q order: {}",
        model.dof_names().join(", ")
    );
    let visual = |link: LinkId| {
        let (n, triangles) = meshes
            .iter()
            .filter(|m| m.link == link && m.role == "visual")
            .fold((0, 0), |(n, t), m| (n + 1, t + m.triangles));
        match n {
            0 => String::new(),
            1 => format!(" [1 visual mesh, {triangles} triangles]"),
            n => format!(" [{n} visual meshes, {triangles} triangles]"),
        }
    };
    fn walk(
        model: &RobotModel,
        link: LinkId,
        prefix: &str,
        visual: &dyn Fn(LinkId) -> String,
        out: &mut String,
    ) {
        let children = &model.links[link].child_joints;
        for (k, &ji) in children.iter().enumerate() {
            let last = k + 1 == children.len();
            let j = &model.joints[ji];
            let a = j.axis;
            let limits = match j.kind {
                JointKind::Fixed => String::new(),
                JointKind::Continuous => format!(
                    ", axis [{:.3} {:.3} {:.3}], unlimited, {} rad/s",
                    a.x, a.y, a.z, j.limits.velocity
                ),
                JointKind::Revolute | JointKind::Prismatic => {
                    let (u, v, e) = if j.kind == JointKind::Revolute {
                        ("rad", "rad/s", "N·m")
                    } else {
                        ("m", "m/s", "N")
                    };
                    format!(
                        ", axis [{:.3} {:.3} {:.3}], [{}, {}] {u}, {} {v}, {} {e}",
                        a.x,
                        a.y,
                        a.z,
                        j.limits.lower,
                        j.limits.upper,
                        j.limits.velocity,
                        j.limits.effort
                    )
                }
            };
            let dof = match (j.dof, &j.mimic) {
                (Some(d), _) => format!(" q[{d}]"),
                (None, Some(m)) => format!(
                    " mimic of {} ×{} {:+}",
                    model.joints[m.leader].name, m.multiplier, m.offset
                ),
                (None, None) => String::new(),
            };
            let _ = writeln!(
                out,
                "{prefix}{} {} ({}{dof}{limits}) -> {}{}",
                if last { "└─" } else { "├─" },
                j.name,
                j.kind.as_str(),
                model.links[j.child].name,
                visual(j.child)
            );
            let next = format!("{prefix}{}", if last { "   " } else { "│  " });
            walk(model, j.child, &next, visual, out);
        }
    }
    let _ = writeln!(out, "{}{}", model.links[0].name, visual(0));
    walk(model, 0, "", &visual, &mut out);
    out
}

/// `avatarm robot --json`: the description's joints, a configuration, the mimic joints' positions
/// there and every link's pose, the root at the origin. Read back with `serde_json::from_str`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotReport {
    /// The description's name.
    pub robot: String,
    /// The joints that take a value, in q's order.
    pub joints: Vec<String>,
    /// The configuration (rad or m, by joint).
    pub q: Vec<f64>,
    /// Each mimic joint, by name.
    pub mimic: BTreeMap<String, MimicReport>,
    /// What the loader noted about the description.
    pub notes: Vec<String>,
    /// Each link's pose in the root's frame, by name.
    pub links: BTreeMap<String, LinkPose>,
}

/// A mimic joint at the configuration: `position = multiplier * leader + offset` (URDF's
/// `<mimic>`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MimicReport {
    /// The joint it follows.
    pub leader: String,
    /// URDF's multiplier.
    pub multiplier: f64,
    /// URDF's offset (rad or m).
    pub offset: f64,
    /// Its position (rad or m).
    pub position: f64,
}

/// A link's pose in the root's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LinkPose {
    /// Translation (m).
    pub translation: [f64; 3],
    /// Rotation as a unit quaternion (x, y, z, w).
    pub rotation_xyzw: [f64; 4],
}

/// The [`RobotReport`] of `model` at `q`.
pub fn robot_report(model: &RobotModel, q: &[f64]) -> RobotReport {
    let poses = model.forward_kinematics(&Isometry3::identity(), q);
    let links = model
        .links
        .iter()
        .zip(&poses)
        .map(|(link, pose)| {
            let t = pose.translation.vector;
            let r = pose.rotation.coords; // [i, j, k, w]
            (
                link.name.clone(),
                LinkPose {
                    translation: [t.x, t.y, t.z],
                    rotation_xyzw: [r.x, r.y, r.z, r.w],
                },
            )
        })
        .collect();
    let positions = model.joint_positions(q);
    let mimic = model
        .joints
        .iter()
        .zip(&positions)
        .filter_map(|(j, &position)| {
            let m = j.mimic.as_ref()?;
            Some((
                j.name.clone(),
                MimicReport {
                    leader: model.joints[m.leader].name.clone(),
                    multiplier: m.multiplier,
                    offset: m.offset,
                    position,
                },
            ))
        })
        .collect();
    RobotReport {
        robot: model.name.clone(),
        joints: model.dof_names().into_iter().map(str::to_owned).collect(),
        q: q.to_vec(),
        mimic,
        notes: model.notes.clone(),
        links,
    }
}

/// The arguments of `avatarm robot`.
#[derive(Args, Debug)]
pub struct RobotArgs {
    /// The URDF file.
    urdf: PathBuf,
    /// Folder searched for package://NAME/... URIs (repeatable; ROS_PACKAGE_PATH is added).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
    /// Joint values: v1,v2,... in the printed q order, or name=value,... (others are 0).
    #[arg(long, value_name = "Q", allow_hyphen_values = true)]
    q: Option<String>,
    /// Print link poses at q as JSON instead of the tree.
    #[arg(long)]
    json: bool,
}

impl RobotArgs {
    /// Runs `avatarm robot`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            urdf,
            package_path,
            q,
            json,
        } = self;
        let model = RobotModel::from_urdf_file(&urdf, &packages(package_path))?;
        let meshes = check_meshes(&model)?;
        let q = model
            .parse_q(q.as_deref().unwrap_or(""))
            .map_err(|e| AppError::flag("--q", e.to_string()))?;
        let q: Vec<f64> = q.iter().copied().collect();
        if json {
            let text = serde_json::to_string_pretty(&robot_report(&model, &q))?;
            println!("{text}");
        } else {
            print!("{}", tree_text(&model, &meshes));
            print!("{}", mesh_text(&model, &meshes));
        }
        Ok(())
    }
}
