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
//! - [`chess`]: the paper's chess scene through the robot: virtual to real grasp and the real
//!   pieces' placement against the one-way delay, with and without the intent estimate.
//! - [`chart`]: what all share: the Pareto front and the charts' house style.

pub mod chart;
pub mod chess;
pub mod control;
pub mod dr;
pub mod gpu;
pub mod head;
pub mod network;
pub mod twin;
pub mod video;

use crate::AppError;
use crate::replay::ReplayReport;

/// The figures every replay-based bench charts, read from the replay's report: each one
/// refused (naming it and the bench) when the replay did not measure it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EraseFigures {
    /// Mean mask IoU against the true silhouette.
    pub iou_mean: f64,
    /// Mean leak (%).
    pub leak_pct_mean: f64,
    /// Largest leak of a frame (%).
    pub leak_pct_max: f64,
    /// Mean overmask (%).
    pub overmask_pct_mean: f64,
    /// Mean PSNR in the robot's region (dB).
    pub psnr_db_mean: f64,
    /// Wall time per app update (ms).
    pub frame_ms: avatarm_core::stats::Spread,
}

impl EraseFigures {
    /// The figures of `report`; `bench` names the bench in the error.
    pub(crate) fn of(report: &ReplayReport, bench: &'static str) -> Result<Self, AppError> {
        let need = |value: Option<f64>, what: &str| {
            value.ok_or_else(|| AppError::command(bench, format!("the report has no {what}")))
        };
        Ok(Self {
            iou_mean: need(report.mask.iou_mean, "mask.iou_mean")?,
            leak_pct_mean: need(report.mask.leak_pct_mean, "mask.leak_pct_mean")?,
            leak_pct_max: need(report.mask.leak_pct_max, "mask.leak_pct_max")?,
            overmask_pct_mean: need(report.mask.overmask_pct_mean, "mask.overmask_pct_mean")?,
            psnr_db_mean: need(report.dr.psnr_robot_db_mean, "dr.psnr_robot_db_mean")?,
            frame_ms: report.timing_ms.frame.ok_or_else(|| {
                AppError::command(bench, "the report has no timing_ms.frame".to_owned())
            })?,
        })
    }

    /// `times`' median, or the error naming `what` and the bench.
    pub(crate) fn median(
        times: crate::replay::report::Times,
        what: &str,
        bench: &'static str,
    ) -> Result<f64, AppError> {
        times
            .map(|t| t.median)
            .ok_or_else(|| AppError::command(bench, format!("the report has no {what}")))
    }
}
