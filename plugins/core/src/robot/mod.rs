//! The robot: its description, kinematics and motion.
//!
//! - [`urdf`] (re-exported here): robot descriptions loaded from URDF (through `urdf-rs`), with
//!   mesh URIs resolved through a package search path, as a tree of links and joints in
//!   depth-first order ([`RobotModel`]).
//! - [`mesh`]: triangle meshes from STL, OBJ and glTF/GLB files.
//! - [`kinematics`]: forward kinematics of every link and geometric Jacobians.
//! - [`ik`]: damped-least-squares velocity IK with joint position and velocity limits, and a
//!   pose solver built on it.
//! - [`trajectory`]: minimum-jerk joint trajectories through keyframes.

pub mod ik;
pub mod kinematics;
pub mod mesh;
pub mod trajectory;
pub mod urdf;

pub use urdf::*;
