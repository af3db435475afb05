//! Props: the objects in the room, the real objects the user manipulates among them.

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

/// A bottle's body is the lower 68 % of its height; the neck is the rest.
pub const BOTTLE_BODY_FRACTION: f64 = 0.68;
/// A bottle's neck radius as a fraction of its body radius.
pub const BOTTLE_NECK_RADIUS_FRACTION: f64 = 0.38;

/// A prop's shape (z up; the pose puts the shape's base centre on the table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum PropShape {
    /// A box, sizes along x, y, z (m), resting on its base.
    Box {
        /// Sizes.
        size: [f64; 3],
    },
    /// An upright cylinder.
    Cylinder {
        /// Radius (m).
        radius: f64,
        /// Height (m).
        height: f64,
    },
    /// A bottle: a cylinder body and a narrower neck ([`BOTTLE_BODY_FRACTION`],
    /// [`BOTTLE_NECK_RADIUS_FRACTION`]).
    Bottle {
        /// Body radius (m).
        radius: f64,
        /// Total height (m).
        height: f64,
    },
    /// A sphere resting on the table.
    Sphere {
        /// Radius (m).
        radius: f64,
    },
}

impl PropShape {
    /// Whether every size is a finite number above zero.
    pub fn sizes_are_positive(&self) -> bool {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        match *self {
            Self::Box { size } => size.into_iter().all(ok),
            Self::Cylinder { radius, height } | Self::Bottle { radius, height } => {
                ok(radius) && ok(height)
            }
            Self::Sphere { radius } => ok(radius),
        }
    }

    /// Radius and height (m) of an upright round shape (a bottle or a cylinder), the shapes a
    /// gripper holds by their side; `None` for the others.
    pub fn upright_round(&self) -> Option<(f64, f64)> {
        match *self {
            Self::Bottle { radius, height } | Self::Cylinder { radius, height } => {
                Some((radius, height))
            }
            _ => None,
        }
    }
}

/// An object in the room.
#[derive(Debug, Clone, PartialEq)]
pub struct Prop {
    /// Name (unique in the scene).
    pub name: String,
    /// Shape.
    pub shape: PropShape,
    /// Pose of the base centre in the world.
    pub pose: Isometry3<f64>,
    /// Colour (sRGB, alpha).
    pub rgba: [f32; 4],
}

/// The prop named `name` and its index in `props`.
pub fn find_prop<'a>(props: &'a [Prop], name: &str) -> Option<(usize, &'a Prop)> {
    props.iter().enumerate().find(|(_, p)| p.name == name)
}
