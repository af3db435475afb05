//! Teleoperation: from the operator's tracked hand to the robot's joint commands.
//!
//! - [`hand`]: the 26-joint hand skeleton (OpenXR `XrHandJointEXT` order), `.hand.jsonl`
//!   recordings, scripted hands with seeded tremor and tracking noise, and the One Euro filter.
//! - [`grasp`]: grasp matrix, internal forces, object twist from contact velocities (the paper's
//!   grasp equations).
//! - [`mapping`]: the control tick: twin twist -> real object twist -> joint velocities by the
//!   Jacobian pseudoinverse, paper and closed-loop modes, and the paper's pose RMSE.
//! - [`safety`]: the limiter every command passes through (TCP speed cap, joint limits,
//!   watchdog).

pub mod grasp;
pub mod hand;
pub mod mapping;
pub mod safety;
