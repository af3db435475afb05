//! What the camera sees and how the virtual scene is laid over it.
//!
//! - [`camera`]: pinhole cameras (intrinsics + pose) and projection of world points to pixels,
//!   in the OpenCV/ROS optical convention.
//! - [`placement`]: where the object's twin goes in front of the video panel so that it covers
//!   the real object's pixels (the paper's perspective equations, for any pinhole camera).
//! - [`sensor`]: the simulated camera's sensor (noise, exposure).

pub mod calibrate;
pub mod camera;
pub mod placement;
pub mod sensor;
