//! Robot descriptions: URDF -> a tree of links and joints, in depth-first order.
//!
//! Links and joints are stored depth-first from the root link, children in the order the file
//! lists their joints. Independent movable joints (revolute, continuous, prismatic without
//! `<mimic>`) are numbered in that same order: that numbering is the order of every joint vector
//! `q` in Avatarm. A `<mimic>` joint is not in `q`: its position is `multiplier · leader +
//! offset` (URDF spec, `<mimic>`), followed down a chain of mimics to an independent joint.
//! `floating` and `planar` joints are read as fixed at their origin (a twin stands on a table;
//! nothing tracks a base's motion), with a note in [`RobotModel::notes`].
//!
//! Mesh URIs may be relative to the URDF file, `file://` absolute paths, or `package://NAME/...`,
//! resolved through a [`PackagePath`] the way ROS resolves them through `ROS_PACKAGE_PATH`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{DVector, Isometry3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::error::{Error, Result};

mod package;
pub use package::PackagePath;
use package::resolve_mesh_uri;

mod validate;
use validate::{parse_finite, validate_xml};

/// Index of a link in [`RobotModel::links`].
pub type LinkId = usize;
/// Index of a joint in [`RobotModel::joints`].
pub type JointId = usize;

/// The joint types Avatarm models.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// Rotation about the axis, within limits.
    Revolute,
    /// Rotation about the axis, unlimited.
    Continuous,
    /// Translation along the axis, within limits.
    Prismatic,
    /// No motion.
    Fixed,
}

impl JointKind {
    /// Whether the joint has a degree of freedom.
    pub fn is_movable(self) -> bool {
        !matches!(self, JointKind::Fixed)
    }

    /// The URDF spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            JointKind::Revolute => "revolute",
            JointKind::Continuous => "continuous",
            JointKind::Prismatic => "prismatic",
            JointKind::Fixed => "fixed",
        }
    }
}

/// Position, velocity and effort limits of a joint. Unlimited values are infinite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lowest position (rad or m).
    pub lower: f64,
    /// Highest position (rad or m).
    pub upper: f64,
    /// Largest speed (rad/s or m/s).
    pub velocity: f64,
    /// Largest effort (N·m or N).
    pub effort: f64,
}

impl JointLimits {
    /// No limits at all.
    pub const UNLIMITED: JointLimits = JointLimits {
        lower: f64::NEG_INFINITY,
        upper: f64::INFINITY,
        velocity: f64::INFINITY,
        effort: f64::INFINITY,
    };

    /// Clamps a position into `[lower, upper]`.
    pub fn clamp_position(&self, q: f64) -> f64 {
        q.clamp(self.lower, self.upper)
    }
}

/// A joint between a parent and a child link.
#[derive(Debug, Clone)]
pub struct Joint {
    /// Name, as in the URDF.
    pub name: String,
    /// Type.
    pub kind: JointKind,
    /// Parent link.
    pub parent: LinkId,
    /// Child link.
    pub child: LinkId,
    /// Pose of the joint frame in the parent link frame.
    pub origin: Isometry3<f64>,
    /// Unit axis in the joint frame.
    pub axis: Unit<Vector3<f64>>,
    /// Limits.
    pub limits: JointLimits,
    /// Index into joint vectors, for independent movable joints (not for mimic joints).
    pub dof: Option<usize>,
    /// The joint this one follows, for a `<mimic>` joint.
    pub mimic: Option<Mimic>,
}

/// A `<mimic>` joint's drive: `position = multiplier · position(leader) + offset` (URDF spec).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mimic {
    /// The joint named in `<mimic joint=...>`.
    pub leader: JointId,
    /// `multiplier` (default 1).
    pub multiplier: f64,
    /// `offset` (rad or m, default 0).
    pub offset: f64,
    /// The independent joint at the end of the mimic chain, as its index in joint vectors.
    pub dof: usize,
    /// The chain composed: `position = gain · q[dof] + bias`.
    pub gain: f64,
    /// See `gain` (rad or m).
    pub bias: f64,
}

impl Joint {
    /// The joint's position in the joint vector `q` (0 for fixed joints and for entries that
    /// `q` is too short to hold); a mimic joint's comes from its leader.
    pub fn position(&self, q: &[f64]) -> f64 {
        if let Some(d) = self.dof {
            return q.get(d).copied().unwrap_or(0.0);
        }
        match &self.mimic {
            Some(m) => m.gain * q.get(m.dof).copied().unwrap_or(0.0) + m.bias,
            None => 0.0,
        }
    }

    /// The joint-vector entry that drives this joint and `∂position/∂q[entry]`: `(dof, 1)` for an
    /// independent joint, `(leader's dof, gain)` for a mimic joint, `None` for a fixed joint.
    pub fn drive(&self) -> Option<(usize, f64)> {
        self.dof
            .map(|d| (d, 1.0))
            .or_else(|| self.mimic.map(|m| (m.dof, m.gain)))
    }

    /// The child link frame relative to the parent link frame at joint position `q`.
    pub fn transform(&self, q: f64) -> Isometry3<f64> {
        match self.kind {
            JointKind::Fixed => self.origin,
            JointKind::Revolute | JointKind::Continuous => {
                self.origin * UnitQuaternion::from_axis_angle(&self.axis, q)
            }
            JointKind::Prismatic => self.origin * Translation3::from(self.axis.into_inner() * q),
        }
    }
}

/// A geometric primitive or mesh of a link.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// Box with full side lengths.
    Box {
        /// Side lengths along x, y, z (m).
        size: Vector3<f64>,
    },
    /// Cylinder along the local z axis, centred on the origin.
    Cylinder {
        /// Radius (m).
        radius: f64,
        /// Length along z (m).
        length: f64,
    },
    /// Capsule along the local z axis (URDF 1.1).
    Capsule {
        /// Radius (m).
        radius: f64,
        /// Length of the cylindrical part (m).
        length: f64,
    },
    /// Sphere.
    Sphere {
        /// Radius (m).
        radius: f64,
    },
    /// Triangle mesh from a file.
    Mesh {
        /// The URI as written in the URDF.
        uri: String,
        /// The resolved file.
        path: PathBuf,
        /// Scale along x, y, z.
        scale: Vector3<f64>,
    },
}

/// One `<visual>` or `<collision>` element.
#[derive(Debug, Clone)]
pub struct Geometry {
    /// Optional element name.
    pub name: Option<String>,
    /// Pose in the link frame.
    pub origin: Isometry3<f64>,
    /// The shape.
    pub shape: Shape,
    /// Colour from the element's material or a named robot-level material (linear-ish sRGB, 0..1).
    pub rgba: Option<[f32; 4]>,
}

/// Which geometry elements of a link: `<visual>` (what a camera sees) or `<collision>`
/// (coarser, often primitives).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GeometryKind {
    /// The `<visual>` elements.
    #[default]
    Visual,
    /// The `<collision>` elements.
    Collision,
}

impl Link {
    /// The link's `<visual>` or `<collision>` elements.
    pub fn geometry(&self, kind: GeometryKind) -> &[Geometry] {
        match kind {
            GeometryKind::Visual => &self.visuals,
            GeometryKind::Collision => &self.collisions,
        }
    }
}

/// A link of the robot.
#[derive(Debug, Clone)]
pub struct Link {
    /// Name, as in the URDF.
    pub name: String,
    /// The joint whose child this link is (`None` for the root).
    pub parent_joint: Option<JointId>,
    /// Joints whose parent this link is, in file order.
    pub child_joints: Vec<JointId>,
    /// Visual geometry.
    pub visuals: Vec<Geometry>,
    /// Collision geometry.
    pub collisions: Vec<Geometry>,
}

/// A robot: links and joints in depth-first order from the root link (index 0).
#[derive(Debug, Clone)]
pub struct RobotModel {
    /// The robot's name.
    pub name: String,
    /// Links, depth-first; `links[0]` is the root.
    pub links: Vec<Link>,
    /// Joints, depth-first (joint `i` is visited before the subtree of its child).
    pub joints: Vec<Joint>,
    /// Movable joints in joint-vector order.
    pub dofs: Vec<JointId>,
    /// Where it was loaded from (a path or `<string>`), for messages.
    pub origin: String,
    /// What was read other than as written (a `floating` or `planar` joint read as fixed), one
    /// line each, for the user to see.
    pub notes: Vec<String>,
}

struct Raw<'a> {
    origin: &'a str,
    base_dir: Option<&'a Path>,
    packages: &'a PackagePath,
    /// Packages already looked for (a search may walk a whole workspace).
    found: std::cell::RefCell<HashMap<String, Option<PathBuf>>>,
}

impl RobotModel {
    /// Loads a URDF file; relative mesh paths are relative to the file's folder.
    pub fn from_urdf_file(path: &Path, packages: &PackagePath) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_owned(),
            source,
        })?;
        let origin = path.display().to_string();
        Self::parse(
            &text,
            &Raw {
                origin: &origin,
                base_dir: path.parent(),
                packages,
                found: Default::default(),
            },
        )
    }

    /// Parses URDF text. Relative mesh paths resolve against `base_dir` when given.
    pub fn from_urdf_str(
        text: &str,
        base_dir: Option<&Path>,
        packages: &PackagePath,
    ) -> Result<Self> {
        Self::parse(
            text,
            &Raw {
                origin: "<string>",
                base_dir,
                packages,
                found: Default::default(),
            },
        )
    }

    fn parse(text: &str, raw: &Raw<'_>) -> Result<Self> {
        validate_xml(text, raw.origin)?;
        let urdf = urdf_rs::read_from_string(text).map_err(|e| Error::MalformedUrdf {
            origin: raw.origin.to_owned(),
            message: e.to_string(),
        })?;
        build(urdf, raw)
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.dofs.len()
    }

    /// Finds a link by name.
    pub fn link_id(&self, name: &str) -> Result<LinkId> {
        self.links
            .iter()
            .position(|l| l.name == name)
            .ok_or_else(|| Error::UnknownLinkName {
                name: name.to_owned(),
            })
    }

    /// Finds a movable joint's index in joint vectors by name; a mimic joint's name is an
    /// [`Error::MimicJoint`] naming its leader.
    pub fn dof_index(&self, name: &str) -> Result<usize> {
        if let Some(i) = self.dofs.iter().position(|&j| self.joints[j].name == name) {
            return Ok(i);
        }
        if let Some(m) = self
            .joints
            .iter()
            .find(|j| j.name == name)
            .and_then(|j| j.mimic)
        {
            return Err(Error::MimicJoint {
                name: name.to_owned(),
                leader: self.joints[m.leader].name.clone(),
            });
        }
        Err(Error::UnknownJoint {
            name: name.to_owned(),
            known: self.dof_names().join(", "),
        })
    }

    /// Positions of every joint (index = [`JointId`]) at joint vector `q`, mimic joints from
    /// their leaders.
    pub fn joint_positions(&self, q: &[f64]) -> Vec<f64> {
        self.joints.iter().map(|j| j.position(q)).collect()
    }

    /// Names of the movable joints, in joint-vector order.
    pub fn dof_names(&self) -> Vec<&str> {
        self.dofs
            .iter()
            .map(|&j| self.joints[j].name.as_str())
            .collect()
    }

    /// Limits of the movable joints, in joint-vector order.
    pub fn dof_limits(&self) -> Vec<JointLimits> {
        self.dofs.iter().map(|&j| self.joints[j].limits).collect()
    }

    /// The last link of the longest chain from the root: the tip of a serial arm.
    pub fn tip_link(&self) -> LinkId {
        let depth = |mut l: LinkId| {
            let mut d = 0;
            while let Some(j) = self.links[l].parent_joint {
                d += 1;
                l = self.joints[j].parent;
            }
            d
        };
        (0..self.links.len())
            .max_by_key(|&l| (depth(l), std::cmp::Reverse(l)))
            .unwrap_or(0)
    }

    /// Parses a joint vector: `v1,v2,...` in joint-vector order (missing trailing values are 0)
    /// or `name=value,...` (unnamed joints are 0). Empty text gives all zeros.
    pub fn parse_q(&self, text: &str) -> Result<DVector<f64>> {
        let mut q = DVector::zeros(self.dof());
        let items: Vec<&str> = text
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .collect();
        if items.iter().any(|s| s.contains('=')) {
            for item in items {
                let (name, value) = item.split_once('=').ok_or_else(|| Error::NotANumber {
                    what: "joint vector (mixing name=value and plain values)".into(),
                    text: item.to_owned(),
                })?;
                let i = self.dof_index(name.trim())?;
                q[i] = parse_finite(value.trim(), &format!("joint '{}'", name.trim()))?;
            }
        } else {
            if items.len() > self.dof() {
                return Err(Error::JointCount {
                    expected: self.dof(),
                    got: items.len(),
                });
            }
            for (i, item) in items.iter().enumerate() {
                q[i] = parse_finite(item, &format!("joint '{}'", self.dof_names()[i]))?;
            }
        }
        Ok(q)
    }

    /// Checks a joint vector's length and that every value is finite.
    pub fn check_q(&self, q: &DVector<f64>) -> Result<()> {
        if q.len() != self.dof() {
            return Err(Error::JointCount {
                expected: self.dof(),
                got: q.len(),
            });
        }
        for (i, v) in q.iter().enumerate() {
            if !v.is_finite() {
                return Err(Error::NonFinite {
                    what: format!("joint '{}'", self.dof_names()[i]),
                    value: *v,
                });
            }
        }
        Ok(())
    }
}

/// How to fill another description's joint vector from this one's, by joint name: for a twin
/// built from a different description of the same robot (a lighter one for the mask, say).
///
/// Each movable joint of the target takes the position of the source's joint of the same name
/// (an independent joint, or a mimic joint through its leader); a target joint the source does
/// not have stays at 0 clamped into its limits.
#[derive(Debug, Clone, PartialEq)]
pub struct JointMap {
    /// Per target movable joint: `(source dof, gain, bias)`, or `None` for a joint the source
    /// does not have.
    drives: Vec<Option<(usize, f64, f64)>>,
    /// Per target movable joint, the value used when the source has none.
    rest: Vec<f64>,
    /// Target joints the source does not have, by name.
    pub missing: Vec<String>,
}

impl JointMap {
    /// The map from `source`'s joint vectors to `target`'s.
    pub fn new(source: &RobotModel, target: &RobotModel) -> Self {
        let mut drives = Vec::with_capacity(target.dof());
        let mut rest = Vec::with_capacity(target.dof());
        let mut missing = Vec::new();
        for &j in &target.dofs {
            let joint = &target.joints[j];
            let found = source.joints.iter().find(|s| s.name == joint.name);
            let drive = found.and_then(|s| match (s.dof, s.mimic) {
                (Some(d), _) => Some((d, 1.0, 0.0)),
                (None, Some(m)) => Some((m.dof, m.gain, m.bias)),
                (None, None) => None,
            });
            if drive.is_none() {
                missing.push(joint.name.clone());
            }
            drives.push(drive);
            rest.push(joint.limits.clamp_position(0.0));
        }
        Self {
            drives,
            rest,
            missing,
        }
    }

    /// The target's joint vector at the source's `q` (entries `q` lacks read as 0).
    pub fn apply(&self, q: &[f64]) -> DVector<f64> {
        DVector::from_iterator(
            self.drives.len(),
            self.drives.iter().zip(&self.rest).map(|(d, rest)| match d {
                Some((dof, gain, bias)) => gain * q.get(*dof).copied().unwrap_or(0.0) + bias,
                None => *rest,
            }),
        )
    }
}

fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = p.xyz.0;
    let [r, pi, ya] = p.rpy.0;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_euler_angles(r, pi, ya)),
    )
}

#[expect(
    clippy::too_many_lines,
    reason = "one pass over the validated XML: links, joints and visuals in depth-first order, each part reading the maps the parts before it fill"
)]
fn build(urdf: urdf_rs::Robot, raw: &Raw<'_>) -> Result<RobotModel> {
    let origin = raw.origin.to_owned();
    if urdf.links.is_empty() {
        return Err(Error::NoLinks { origin });
    }
    let mut link_index: HashMap<&str, usize> = HashMap::new();
    for (i, l) in urdf.links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), i).is_some() {
            return Err(Error::DuplicateName {
                origin,
                element: "link",
                name: l.name.clone(),
            });
        }
    }
    let mut seen_joints: HashMap<&str, ()> = HashMap::new();
    // parent_of[link] = joint (file index) whose child it is.
    let mut parent_of: Vec<Option<usize>> = vec![None; urdf.links.len()];
    let mut children_of: Vec<Vec<usize>> = vec![Vec::new(); urdf.links.len()];
    for (ji, j) in urdf.joints.iter().enumerate() {
        if seen_joints.insert(j.name.as_str(), ()).is_some() {
            return Err(Error::DuplicateName {
                origin,
                element: "joint",
                name: j.name.clone(),
            });
        }
        let find = |name: &str, role| {
            link_index
                .get(name)
                .copied()
                .ok_or_else(|| Error::UnknownLink {
                    origin: origin.clone(),
                    joint: j.name.clone(),
                    role,
                    link: name.to_owned(),
                })
        };
        let p = find(&j.parent.link, "parent")?;
        let c = find(&j.child.link, "child")?;
        if let Some(prev) = parent_of[c] {
            return Err(Error::Loop {
                origin,
                link: j.child.link.clone(),
                detail: format!(
                    "it is the child of both '{}' and '{}'",
                    urdf.joints[prev].name, j.name
                ),
            });
        }
        parent_of[c] = Some(ji);
        children_of[p].push(ji);
    }
    let roots: Vec<usize> = (0..urdf.links.len())
        .filter(|&l| parent_of[l].is_none())
        .collect();
    if roots.len() > 1 {
        return Err(Error::SeveralRoots {
            origin,
            count: roots.len(),
            roots: roots
                .iter()
                .map(|&l| urdf.links[l].name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    let Some(&root) = roots.first() else {
        return Err(Error::Loop {
            origin,
            link: urdf.links[0].name.clone(),
            detail: "every link is some joint's child, so there is no root".into(),
        });
    };

    // Depth-first order: links, and joints in the order their child is visited.
    let mut link_order = Vec::with_capacity(urdf.links.len());
    let mut joint_order = Vec::with_capacity(urdf.joints.len());
    let mut stack = vec![root];
    while let Some(l) = stack.pop() {
        link_order.push(l);
        for &ji in children_of[l].iter().rev() {
            stack.push(link_index[urdf.joints[ji].child.link.as_str()]);
        }
        // Record this link's parent joint in visit order.
        if let Some(ji) = parent_of[l] {
            joint_order.push(ji);
        }
    }
    if link_order.len() != urdf.links.len() {
        let stray = (0..urdf.links.len())
            .find(|l| !link_order.contains(l))
            .unwrap_or(0);
        return Err(Error::Loop {
            origin,
            link: urdf.links[stray].name.clone(),
            detail: "it is on a cycle of joints not connected to the root".into(),
        });
    }
    let new_link: HashMap<usize, usize> = link_order
        .iter()
        .enumerate()
        .map(|(new, &old)| (old, new))
        .collect();
    let new_joint: HashMap<usize, usize> = joint_order
        .iter()
        .enumerate()
        .map(|(new, &old)| (old, new))
        .collect();

    let materials: HashMap<&str, [f32; 4]> = urdf
        .materials
        .iter()
        .filter_map(|m| m.color.as_ref().map(|c| (m.name.as_str(), rgba(&c.rgba))))
        .collect();

    let mut joints = Vec::with_capacity(joint_order.len());
    let mut dofs = Vec::new();
    let mut notes = Vec::new();
    for &old in &joint_order {
        let j = &urdf.joints[old];
        let kind = match &j.joint_type {
            urdf_rs::JointType::Revolute => JointKind::Revolute,
            urdf_rs::JointType::Continuous => JointKind::Continuous,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            urdf_rs::JointType::Fixed => JointKind::Fixed,
            urdf_rs::JointType::Floating | urdf_rs::JointType::Planar => {
                notes.push(format!(
                    "joint '{}' is {}: read as fixed at its <origin> (the twin stands still; \
                     nothing tracks that motion)",
                    j.name,
                    if matches!(j.joint_type, urdf_rs::JointType::Floating) {
                        "floating"
                    } else {
                        "planar"
                    }
                ));
                JointKind::Fixed
            }
            other => {
                return Err(Error::BadJoint {
                    origin,
                    joint: j.name.clone(),
                    message: format!("type {other:?} is not supported"),
                });
            }
        };
        let bad = |message: String| Error::BadJoint {
            origin: origin.clone(),
            joint: j.name.clone(),
            message,
        };
        let numbers = j.origin.xyz.0.iter().chain(j.origin.rpy.0.iter());
        if numbers.clone().any(|v| !v.is_finite()) {
            return Err(bad("<origin> has a value that is not finite".into()));
        }
        let axis = Vector3::from(j.axis.xyz.0);
        let axis = if kind.is_movable() {
            Unit::try_new(axis, 1e-9)
                .filter(|a| a.iter().all(|v| v.is_finite()))
                .ok_or_else(|| bad(format!("<axis xyz> {axis:?} has no direction")))?
        } else {
            Unit::try_new(axis, 1e-9).unwrap_or(Vector3::z_axis())
        };
        let l = &j.limit;
        let unlimited_if_zero = |v: f64| if v > 0.0 { v } else { f64::INFINITY };
        let limits = match kind {
            JointKind::Revolute | JointKind::Prismatic => {
                if !(l.lower.is_finite() && l.upper.is_finite()) || l.lower > l.upper {
                    return Err(bad(format!(
                        "<limit> lower {} and upper {} must be finite with lower <= upper",
                        l.lower, l.upper
                    )));
                }
                JointLimits {
                    lower: l.lower,
                    upper: l.upper,
                    velocity: unlimited_if_zero(l.velocity),
                    effort: unlimited_if_zero(l.effort),
                }
            }
            JointKind::Continuous => JointLimits {
                velocity: unlimited_if_zero(l.velocity),
                effort: unlimited_if_zero(l.effort),
                ..JointLimits::UNLIMITED
            },
            JointKind::Fixed => JointLimits::UNLIMITED,
        };
        let is_mimic = kind.is_movable() && j.mimic.is_some();
        let dof = (kind.is_movable() && !is_mimic).then(|| {
            dofs.push(joints.len());
            dofs.len() - 1
        });
        joints.push(Joint {
            name: j.name.clone(),
            kind,
            parent: new_link[&link_index[j.parent.link.as_str()]],
            child: new_link[&link_index[j.child.link.as_str()]],
            origin: pose(&j.origin),
            axis,
            limits,
            dof,
            mimic: None,
        });
    }
    resolve_mimics(&urdf, &joint_order, &mut joints, &origin)?;

    let mut links = Vec::with_capacity(link_order.len());
    for &old in &link_order {
        let l = &urdf.links[old];
        let geometry = |g: &urdf_rs::Geometry,
                        o: &urdf_rs::Pose,
                        name: &Option<String>,
                        material: Option<&urdf_rs::Material>| {
            let shape = shape(g, &l.name, raw)?;
            let rgba = material.and_then(|m| {
                m.color
                    .as_ref()
                    .map(|c| rgba(&c.rgba))
                    .or_else(|| materials.get(m.name.as_str()).copied())
            });
            Ok::<_, Error>(Geometry {
                name: name.clone(),
                origin: pose(o),
                shape,
                rgba,
            })
        };
        let visuals = l
            .visual
            .iter()
            .map(|v| geometry(&v.geometry, &v.origin, &v.name, v.material.as_ref()))
            .collect::<Result<Vec<_>>>()?;
        let collisions = l
            .collision
            .iter()
            .map(|c| geometry(&c.geometry, &c.origin, &c.name, None))
            .collect::<Result<Vec<_>>>()?;
        links.push(Link {
            name: l.name.clone(),
            parent_joint: parent_of[old].map(|ji| new_joint[&ji]),
            child_joints: children_of[old].iter().map(|ji| new_joint[ji]).collect(),
            visuals,
            collisions,
        });
    }
    Ok(RobotModel {
        name: urdf.name,
        links,
        joints,
        dofs,
        origin,
        notes,
    })
}

/// Fills [`Joint::mimic`] of every movable `<mimic>` joint: its leader by name, and the chain of
/// leaders followed to an independent joint with the gains and offsets composed
/// (`a = m₁·b + o₁`, `b = m₂·c + o₂` ⇒ `a = m₁m₂·c + m₁o₂ + o₁`). A leader that does not
/// exist or is fixed, a non-finite multiplier or offset, and a chain that loops are errors
/// naming the joints.
fn resolve_mimics(
    urdf: &urdf_rs::Robot,
    joint_order: &[usize],
    joints: &mut [Joint],
    origin: &str,
) -> Result<()> {
    let by_name: HashMap<&str, JointId> = joints
        .iter()
        .enumerate()
        .map(|(i, j)| (j.name.as_str(), i))
        .collect();
    // Direct links first: (leader, multiplier, offset) per mimic joint.
    let mut direct: Vec<Option<(JointId, f64, f64)>> = vec![None; joints.len()];
    for (new, &old) in joint_order.iter().enumerate() {
        let (Some(m), true) = (&urdf.joints[old].mimic, joints[new].kind.is_movable()) else {
            continue;
        };
        let bad = |message: String| Error::BadJoint {
            origin: origin.to_owned(),
            joint: joints[new].name.clone(),
            message,
        };
        let leader = *by_name.get(m.joint.as_str()).ok_or_else(|| {
            bad(format!(
                "<mimic joint=\"{}\">: the robot has no joint named '{}'",
                m.joint, m.joint
            ))
        })?;
        if !joints[leader].kind.is_movable() {
            return Err(bad(format!(
                "<mimic joint=\"{}\">: '{}' is a fixed joint, which cannot be followed",
                m.joint, m.joint
            )));
        }
        let multiplier = m.multiplier.unwrap_or(1.0);
        let offset = m.offset.unwrap_or(0.0);
        if !(multiplier.is_finite() && offset.is_finite()) {
            return Err(bad(format!(
                "<mimic>: multiplier {multiplier} and offset {offset} must be finite"
            )));
        }
        direct[new] = Some((leader, multiplier, offset));
    }
    for i in 0..joints.len() {
        let Some((leader, multiplier, offset)) = direct[i] else {
            continue;
        };
        let (mut gain, mut bias, mut at) = (1.0, 0.0, i);
        let mut chain = vec![joints[i].name.clone()];
        while let Some((next, m, o)) = direct[at] {
            // position(at) = m · position(next) + o.
            bias += gain * o;
            gain *= m;
            at = next;
            if chain.len() > joints.len() || at == i {
                chain.push(joints[at].name.clone());
                return Err(Error::BadJoint {
                    origin: origin.to_owned(),
                    joint: joints[i].name.clone(),
                    message: format!(
                        "<mimic> joints follow each other in a loop: {}",
                        chain.join(" -> ")
                    ),
                });
            }
            chain.push(joints[at].name.clone());
        }
        let Some(dof) = joints[at].dof else {
            return Err(Error::BadJoint {
                origin: origin.to_owned(),
                joint: joints[i].name.clone(),
                message: format!(
                    "<mimic> chain {} ends at a joint without a degree of freedom",
                    chain.join(" -> ")
                ),
            });
        };
        joints[i].mimic = Some(Mimic {
            leader,
            multiplier,
            offset,
            dof,
            gain,
            bias,
        });
    }
    Ok(())
}

fn rgba(v: &urdf_rs::Vec4) -> [f32; 4] {
    v.0.map(|c| c as f32)
}

fn shape(g: &urdf_rs::Geometry, link: &str, raw: &Raw<'_>) -> Result<Shape> {
    Ok(match g {
        urdf_rs::Geometry::Box { size } => Shape::Box {
            size: Vector3::from(size.0),
        },
        urdf_rs::Geometry::Cylinder { radius, length } => Shape::Cylinder {
            radius: *radius,
            length: *length,
        },
        urdf_rs::Geometry::Capsule { radius, length } => Shape::Capsule {
            radius: *radius,
            length: *length,
        },
        urdf_rs::Geometry::Sphere { radius } => Shape::Sphere { radius: *radius },
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let scale = scale
                .as_ref()
                .map_or(Vector3::repeat(1.0), |s| Vector3::from(s.0));
            // Negative components mirror the mesh (fine: the loader flips the winding); 0 or a
            // non-finite value flattens or breaks it.
            if scale.iter().any(|v| !v.is_finite() || *v == 0.0) {
                return Err(Error::BadGeometry {
                    origin: raw.origin.to_owned(),
                    link: link.to_owned(),
                    message: format!(
                        "mesh '{filename}': <mesh scale=\"{} {} {}\"> must be finite and non-zero on every axis",
                        scale.x, scale.y, scale.z
                    ),
                });
            }
            Shape::Mesh {
                uri: filename.clone(),
                path: resolve_mesh_uri(filename, link, raw)?,
                scale,
            }
        }
    })
}

#[cfg(test)]
mod tests;
