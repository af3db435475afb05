//! Avatarm's pure core: everything that is maths, not ECS.
//!
//! - [`robot`]: robot descriptions from URDF ([`robot::RobotModel`]), meshes, forward
//!   kinematics and Jacobians, IK and joint trajectories.
//! - [`vision`]: pinhole cameras, the camera's sensor model, and where the object's twin is
//!   placed in front of the video panel (the paper's perspective equations).
//! - [`dr`]: diminished reality on the CPU: mask, feathering, composite, photometric fit and
//!   scores; the reference the GPU passes are checked against.
//! - [`teleop`]: the hand skeleton and hand sources, grasp maths, the mapping tick and the
//!   safety limiter.
//! - [`sim`]: the simulated robot (command latency, first-order response, limits, delayed joint
//!   states) that stands in for the real arm.
//! - [`tf`]: a transform tree as ROS's tf2 keeps one, and poses chained through it.
//! - [`stats`]: quantiles and [`stats::Spread`] (median, p95, largest) of measured series.
//! - [`rng`]: a small seeded generator so that every replay is reproducible.
//! - [`shared_data`]: where the real robot descriptions and footage beside the checkout are.
//! - [`error`]: the crate's error type.
//!
//! Nothing here imports Bevy; time is always an argument.

pub mod dr;
pub mod error;
pub mod rng;
pub mod robot;
pub mod shared_data;
pub mod sim;
pub mod stats;
pub mod teleop;
pub mod tf;
pub mod vision;

pub use error::{Error, Result};

/// The types most users of the core need.
pub mod prelude {
    pub use crate::error::{Error, Result};
    pub use crate::robot::ik::{DlsSettings, IkStep, dls_step};
    pub use crate::robot::kinematics::Frame;
    pub use crate::robot::{JointKind, LinkId, RobotModel, Shape};
    pub use crate::sim::{JointCommand, JointState, SimRobot, SimRobotParams};
    pub use crate::vision::camera::{CameraPose, Intrinsics, PinholeCamera};
}
