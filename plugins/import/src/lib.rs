//! Avatarm's importers, without Bevy: what a lab already has, turned into a recording
//! ([`avatarm_record`]) that Foxglove opens and Avatarm replays (`avatarm import`).
//!
//! - [`footage`]: a folder of camera frames with the robot's joints at each (a listing, or
//!   EasyHeC's layout), the camera file and the camera's pose.
//! - [`bag`]: a ROS 1 bag (format 2.0): Image or CompressedImage, CameraInfo, JointState and
//!   `/tf`.
//! - [`error`]: the crate's error type ([`ImportError`]).
//!
//! Kept apart from `avatarm_record` (the format itself, read by every part of Avatarm) so that
//! the importers' dependencies (ROS 1 bags and their decoder, CSV, image decoding) come only
//! with them.

pub mod bag;
pub mod error;
pub mod footage;

pub use error::ImportError;
