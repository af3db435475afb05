//! A transform tree as ROS's tf2 keeps one (`tf2_msgs/TFMessage` on `/tf` and `/tf_static`):
//! links `parent -> child`, each the child frame's pose in the parent frame at a stamp, and the
//! pose of one frame in another chained through them. Frame names are compared without a
//! leading `/` (tf2 dropped it; ROS 1 bags still carry it).

use std::collections::{HashMap, VecDeque};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// One link of the tree: `parent_from_child` (the child frame's pose in the parent frame; m)
/// at `stamp_ns` (ns since the Unix epoch; 0 for a static transform, which holds at any time).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameLink {
    /// The parent frame (`header.frame_id`), without a leading `/`.
    pub parent: String,
    /// The child frame (`child_frame_id`), without a leading `/`.
    pub child: String,
    /// When it holds (ns; 0: always).
    pub stamp_ns: u64,
    /// The child's pose in the parent frame.
    pub parent_from_child: Isometry3<f64>,
}

impl FrameLink {
    /// A link from a `geometry_msgs/Transform`'s fields: `translation` (m) and the rotation as
    /// a quaternion `[x, y, z, w]`. Errors (what the transform holds, for the caller to name
    /// where): a value that is not finite, or a quaternion whose norm is off 1 by more than
    /// 1e-3 (stricter than tf2, which warns past 0.01 on the squared norm and normalises).
    pub fn new(
        parent: &str,
        child: &str,
        stamp_ns: u64,
        translation: [f64; 3],
        quaternion_xyzw: [f64; 4],
    ) -> Result<Self, String> {
        let [x, y, z, w] = quaternion_xyzw;
        let norm = (x * x + y * y + z * z + w * w).sqrt();
        if translation
            .iter()
            .chain(&quaternion_xyzw)
            .any(|v| !v.is_finite())
            || (norm - 1.0).abs() > 1e-3
        {
            return Err(format!(
                "{parent} -> {child} (translation {translation:?}, quaternion norm {norm})"
            ));
        }
        Ok(Self {
            parent: parent.trim_start_matches('/').to_owned(),
            child: child.trim_start_matches('/').to_owned(),
            stamp_ns,
            parent_from_child: Isometry3::from_parts(
                Translation3::from(translation),
                UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
            ),
        })
    }
}

/// `base_from_target`: the pose of frame `target` in frame `base`, chained through `links`
/// (a breadth-first search of the tree, each link walked either way), each link at its
/// transform nearest `near_ns` (a static link's stamp 0 counts as the epoch, so where one edge
/// is on `/tf` and `/tf_static` both, `/tf`'s wins, as a republished calibration should).
/// `None` where no chain joins them. A frame is its own pose's frame: `chain(.., "a", "a",
/// ..)` is the identity.
pub fn chain(
    links: &[FrameLink],
    base: &str,
    target: &str,
    near_ns: u64,
) -> Option<Isometry3<f64>> {
    let (base, target) = (base.trim_start_matches('/'), target.trim_start_matches('/'));
    // Per edge, the transform nearest `near_ns`.
    let mut edges: HashMap<(&str, &str), (u64, Isometry3<f64>)> = HashMap::new();
    for l in links {
        let d = l.stamp_ns.abs_diff(near_ns);
        let e = edges
            .entry((l.parent.as_str(), l.child.as_str()))
            .or_insert((d, l.parent_from_child));
        if d < e.0 {
            *e = (d, l.parent_from_child);
        }
    }
    let mut from: HashMap<&str, Isometry3<f64>> = HashMap::from([(base, Isometry3::identity())]);
    let mut queue = VecDeque::from([base]);
    while let Some(frame) = queue.pop_front() {
        let here = from[frame];
        if frame == target {
            return Some(here);
        }
        for ((parent, child), (_, t)) in &edges {
            let (next, step) = if *parent == frame {
                (*child, *t)
            } else if *child == frame {
                (*parent, t.inverse())
            } else {
                continue;
            };
            if !from.contains_key(next) {
                from.insert(next, here * step);
                queue.push_back(next);
            }
        }
    }
    None
}

/// The frames `links` name, sorted, each once (for a message saying what the tree holds).
pub fn frames(links: &[FrameLink]) -> Vec<&str> {
    let mut frames: Vec<&str> = links
        .iter()
        .flat_map(|l| [l.parent.as_str(), l.child.as_str()])
        .collect();
    frames.sort_unstable();
    frames.dedup();
    frames
}

#[cfg(test)]
mod tests {
    use nalgebra::{Point3, Vector3};

    use super::*;

    fn link(parent: &str, child: &str, stamp_ns: u64, t: [f64; 3], yaw: f64) -> FrameLink {
        let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
        let (v, w) = (q.imag(), q.scalar());
        FrameLink::new(parent, child, stamp_ns, t, [v.x, v.y, v.z, w]).expect("a good link")
    }

    #[test]
    fn a_pose_is_chained_both_ways_through_the_tree_at_the_nearest_stamp() {
        let links = [
            link("/world", "base", 0, [1.0, 0.0, 0.0], 0.0),
            link(
                "world",
                "camera_link",
                0,
                [0.0, 2.0, 0.0],
                std::f64::consts::FRAC_PI_2,
            ),
            link("camera_link", "camera_optical", 0, [0.0, 0.0, 0.5], 0.0),
            // A moving link: the one nearest the stamp asked for is taken.
            link("base", "tool", 1_000, [0.0, 0.0, 1.0], 0.0),
            link("base", "tool", 2_000, [0.0, 0.0, 2.0], 0.0),
        ];
        let p = chain(&links, "base", "/camera_optical", 0).expect("joined");
        // The optical frame's origin: world (0, 2, 0.5), in base: (-1, 2, 0.5).
        let origin = p * Point3::origin();
        assert!(
            (origin - Point3::new(-1.0, 2.0, 0.5)).norm() < 1e-12,
            "{origin}"
        );
        // Its x axis is the world's y (the camera link turned a quarter about z).
        assert!((p * Vector3::x() - Vector3::y()).norm() < 1e-12);
        let tool =
            |near| (chain(&links, "base", "tool", near).expect("joined") * Point3::origin()).z;
        assert_eq!((tool(1_100), tool(1_900)), (1.0, 2.0));
        // Backwards: the base in the optical frame is the inverse.
        let back = chain(&links, "camera_optical", "base", 0).expect("joined");
        assert!((back * p).translation.vector.norm() < 1e-12);
        assert_eq!(
            chain(&links, "base", "base", 0),
            Some(Isometry3::identity())
        );
        assert_eq!(chain(&links, "base", "elsewhere", 0), None);
        // An edge on /tf and /tf_static both: /tf's.
        let mut both = links.to_vec();
        both.push(link(
            "camera_link",
            "camera_optical",
            5_000,
            [0.0, 0.0, 0.7],
            0.0,
        ));
        let p = chain(&both, "world", "camera_optical", 4_000).expect("joined");
        assert!((p.translation.vector.z - 0.7).abs() < 1e-12, "{p}");
        assert_eq!(
            frames(&links),
            ["base", "camera_link", "camera_optical", "tool", "world"]
        );
    }

    #[test]
    fn a_transform_not_finite_or_not_a_unit_quaternion_is_refused_naming_its_frames() {
        let bad = [
            ([f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]),
            ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]),
            ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.1]),
            ([0.0, f64::INFINITY, 0.0], [0.0, 0.0, 0.0, 1.0]),
        ];
        for (t, q) in bad {
            let e = FrameLink::new("base", "cam", 0, t, q).expect_err("refused");
            assert!(e.starts_with("base -> cam"), "{e}");
        }
    }
}
