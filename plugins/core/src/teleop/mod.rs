//! Teleoperation: from the operator's tracked hand to the robot's joint commands.
//!
//! - [`hand`]: the 26-joint hand skeleton (OpenXR `XrHandJointEXT` order), `.hand.jsonl`
//!   recordings, scripted hands with seeded tremor and tracking noise, and the One Euro filter.
//! - [`grasp`]: grasp matrix, internal forces, object twist from contact velocities (the paper's
//!   grasp equations).
//! - [`mapping`]: the control tick: twin twist -> real object twist -> joint velocities by the
//!   Jacobian pseudoinverse, paper and closed-loop modes, and the paper's pose RMSE.
//! - [`intent`]: which object the hand reaches for (goal inference over the candidates).
//! - [`pick_place`]: the robot's side of a pick-and-place task with several objects (the
//!   chess scene): pre-grasp from the intent, the clearance path, grasp, carry and place.
//! - [`safety`]: the limiter every command passes through (TCP speed cap, joint limits,
//!   watchdog).

pub mod grasp;
pub mod hand;
pub mod intent;
pub mod mapping;
pub mod pick_place;
pub mod safety;
