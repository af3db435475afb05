//! `avatarm bench`: speed charted against accuracy, as ratios against a baseline measured in the
//! same run.
//!
//! - [`dr`]: the erase pipeline's settings (mask scale, dilation, feathering, latency
//!   compensation) on a scene: frame cost and erase GPU time against leak and PSNR.
//! - [`control`]: the teleoperation loop (control rate, command latency, TCP speed cap) on a
//!   scene's pouring task: object RMSE against rate and loop cost.
//! - [`twin`]: how detailed the mask twin must be (visual, collision, simplified meshes, a
//!   primitive description): mask GPU time and triangles against leak and needed dilation.
//! - [`gpu`]: the erase's GPU time per pass at several frame sizes and camera counts, against a
//!   plain copy of the same images (the floor) measured in the same run.
//! - [`network`]: the pouring task across two sites through the impairment relay: object RMSE
//!   against one-way delay and loss, with the paper's RMSE as a line.
//! - [`video`]: the erased video's codecs (JPEG qualities, H.264 bit rates) at several frame
//!   sizes: PSNR after coding against bit rate, encode and decode time, as ratios against
//!   JPEG at quality 85 measured in the same run.
//! - [`head`]: a camera on a moving head (Alice's headset camera): leak against the head's
//!   angular speed and tracking latency, with and without pose compensation, and against an
//!   error in the camera's mount.
//! - [`chart`]: what all share: the Pareto front and the charts' house style.

pub mod chart;
pub mod control;
pub mod dr;
pub mod gpu;
pub mod head;
pub mod network;
pub mod twin;
pub mod video;
