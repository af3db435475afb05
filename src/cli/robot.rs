//! `avatarm robot`: print a robot description's tree, limits and link poses.

use std::fmt::Write;

use avatarm_core::robot::mesh::load_mesh;
use avatarm_core::robot::{JointKind, LinkId, RobotModel, Shape};
use nalgebra::Isometry3;
use serde_json::{Map, Value, json};

/// Loads every mesh the robot names; returns one line per mesh, or the first error.
pub fn check_meshes(model: &RobotModel) -> Result<Vec<String>, avatarm_core::Error> {
    let mut lines = Vec::new();
    for link in &model.links {
        for g in link.visuals.iter().chain(&link.collisions) {
            if let Shape::Mesh { path, scale, .. } = &g.shape {
                let mesh = load_mesh(path, scale)?;
                lines.push(format!(
                    "{}: {} ({} triangles)",
                    link.name,
                    path.display(),
                    mesh.triangle_count()
                ));
            }
        }
    }
    Ok(lines)
}

/// The joint/link tree with limits, as text.
pub fn tree_text(model: &RobotModel) -> String {
    let mut out = String::new();
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
    fn walk(model: &RobotModel, link: LinkId, prefix: &str, out: &mut String) {
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
            let dof = j.dof.map(|d| format!(" q[{d}]")).unwrap_or_default();
            let _ = writeln!(
                out,
                "{prefix}{} {} ({}{dof}{limits}) -> {}",
                if last { "└─" } else { "├─" },
                j.name,
                j.kind.as_str(),
                model.links[j.child].name
            );
            let next = format!("{prefix}{}", if last { "   " } else { "│  " });
            walk(model, j.child, &next, out);
        }
    }
    let _ = writeln!(out, "{}", model.links[0].name);
    walk(model, 0, "", &mut out);
    out
}

/// `{"links": {name: {"translation", "rotation_xyzw"}}, ...}` at `q`, the root at the origin.
pub fn poses_json(model: &RobotModel, q: &[f64]) -> Value {
    let poses = model.forward_kinematics(&Isometry3::identity(), q);
    let mut links = Map::new();
    for (link, pose) in model.links.iter().zip(&poses) {
        let t = pose.translation.vector;
        let r = pose.rotation.coords; // [i, j, k, w]
        links.insert(
            link.name.clone(),
            json!({
                "translation": [t.x, t.y, t.z],
                "rotation_xyzw": [r.x, r.y, r.z, r.w],
            }),
        );
    }
    json!({
        "robot": model.name,
        "joints": model.dof_names(),
        "q": q,
        "links": links,
    })
}
