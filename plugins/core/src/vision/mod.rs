//! What the camera sees and how the virtual scene is laid over it.
//!
//! - [`camera`]: pinhole cameras (intrinsics + pose) and projection of world points to pixels,
//!   in the OpenCV/ROS optical convention.
//! - [`placement`]: where the object's twin goes in front of the video panel so that it covers
//!   the real object's pixels (the paper's perspective equations, for any pinhole camera).
//! - [`distortion`]: lens distortion (OpenCV's plumb_bob, rational_polynomial, equidistant).
//! - [`calibrate`]: the camera's pose fitted to the robot's silhouettes.
//! - [`sensor`]: the simulated camera's sensor (noise, exposure).
//! - [`head`]: a camera that moves with a head: the head's motion, its tracking, the tracked
//!   poses' history (pose compensation).

pub mod calibrate;
pub mod camera;
pub mod distortion;
pub mod head;
pub mod placement;
pub mod sensor;
