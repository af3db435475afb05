//! Avatarm's work on a lab's recorded footage, without Bevy: what a lab already has, turned
//! into a recording ([`avatarm_record`]) that Foxglove opens and Avatarm replays (`avatarm
//! import`); what a recording gives the erase; and the camera's pose fitted to the robot in it
//! (`avatarm calibrate`).
//!
//! - [`footage`]: a folder of camera frames with the robot's joints at each (a listing, or
//!   EasyHeC's layout), the camera file and the camera's pose.
//! - [`bag`]: a ROS 1 bag (format 2.0): Image or CompressedImage, CameraInfo, JointState and
//!   `/tf`.
//! - [`recording`]: a recording's camera, a head camera's mount, the joints at any stamp and
//!   decoded frames, as `avatarm replay --recording`, `avatarm calibrate` and a robot site
//!   serving a recording read them.
//! - [`calibrate`]: the `avatarm calibrate` command (the fit itself is
//!   [`avatarm_core::vision::calibrate`]) and its typed report.
//! - [`drift`]: the drift watch: a fixed camera that moved found from its frames' edges, and
//!   its pose fitted again.
//! - [`overlay`]: a mask, edges and a reference outline drawn over a frame.
//! - [`error`]: the crate's error type ([`FootageError`]).
//!
//! Kept apart from `avatarm_record` (the format itself, read by every part of Avatarm) so that
//! the importers' dependencies (ROS 1 bags and their decoder, CSV, image decoding, Canny's
//! edges) come only with them.

pub mod bag;
pub mod calibrate;
pub mod drift;
pub mod error;
pub mod footage;
pub mod overlay;
pub mod recording;

pub use error::FootageError;
