//! Avatarm's pure core: everything that is maths, not ECS.
//!
//! - [`robot`]: robot descriptions loaded from URDF (through `urdf-rs`), with mesh URIs resolved
//!   through a package search path, as a tree of links and joints in depth-first order.
//! - [`kinematics`]: forward kinematics of every link and geometric Jacobians.
//! - [`ik`]: damped-least-squares velocity IK with joint position and velocity limits.
//! - [`mesh`]: triangle meshes from STL, OBJ and glTF/GLB files.
//! - [`camera`]: pinhole cameras (intrinsics + pose) and projection of world points to pixels.
//! - [`dr`]: diminished reality on the CPU: mask, feathering, composite, photometric fit and
//!   scores; the reference the GPU passes are checked against.
//! - [`placement`]: where the object's twin goes in front of the video panel so that it covers
//!   the real object's pixels (the paper's perspective equations, for any pinhole camera).
//! - [`sim`]: the simulated robot (command latency, first-order response, limits, delayed joint
//!   states) that stands in for the real arm.
//! - [`rng`]: a small seeded generator so that every replay is reproducible.
//!
//! Nothing here imports Bevy; time is always an argument.

pub mod camera;
pub mod dr;
pub mod error;
pub mod grasp;
pub mod hand;
pub mod ik;
pub mod kinematics;
pub mod mapping;
pub mod mesh;
pub mod placement;
pub mod rng;
pub mod robot;
pub mod safety;
pub mod sensor;
pub mod sim;
pub mod trajectory;

pub use error::{Error, Result};

/// The types most users of the core need.
pub mod prelude {
    pub use crate::camera::{CameraPose, Intrinsics, PinholeCamera};
    pub use crate::error::{Error, Result};
    pub use crate::ik::{DlsSettings, IkStep, dls_step};
    pub use crate::kinematics::Frame;
    pub use crate::robot::{JointKind, LinkId, RobotModel, Shape};
    pub use crate::sim::{JointCommand, JointState, SimRobot, SimRobotParams};
}
