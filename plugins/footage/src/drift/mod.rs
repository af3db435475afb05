//! The drift watch: is a fixed camera still where its pose says it is? A camera bumped in the
//! middle of a session no longer fits its calibration, and its mask slides off the robot (the
//! arm's ghost comes back along one side); this finds it from the frames themselves, and fits
//! the pose again.
//!
//! Each check (every [`DriftSettings::every_s`] of footage, off the frame path): the robot's
//! silhouette at the frame's joints is drawn through the believed pose on the CPU
//! ([`rasterize`]), its outline taken, and the frame's own image edges found (Canny's, as
//! `avatarm calibrate --edges`). The outline is slid over the edges' distance transform within
//! ±[`DriftSettings::search_px`] ([`shift::best_shift`]): the shift with the least mean
//! truncated distance (chamfer matching: Barrow et al. 1977; Borgefors 1988) is where the frame
//! shows the robot relative to where the pose draws it. A still camera whose pose fits keeps
//! that shift within the erase margin; a moved camera shifts the whole outline the same way in
//! every frame, whatever the arm does.
//!
//! [`DriftSettings::confirm`] checks in a row beyond the margin ([`DriftWatch::threshold_px`])
//! that agree with one another are a drift. The camera's turn is then fitted to those frames'
//! edges ([`turn::fit_turn`]: sub-pixel, the three angles, roll included), from the believed
//! pose turned by the small rotation that moves the image by the shift (in the optical frame,
//! a rotation ω moves the image by `δx = fx·ω_y`, `δy = −fy·ω_x`), and the watch goes on from
//! the turned pose. A camera knocked on its mount turns far more than it slides (a 1 deg turn
//! moves this room's image 8 px; a 5 mm slide at 2 m, about 1 px), and a few frames of an arm
//! that hardly moved cannot tell a slide from a turn, so only the turn is fitted; a camera moved
//! far (a new place) is calibrated again (`avatarm calibrate`). A pose that does not fit the
//! first checks at all is not watched: the watch tells a drift from a pose that never fitted by
//! the start, and says to calibrate instead.

use std::time::Instant;

use avatarm_core::robot::RobotModel;
use avatarm_core::stats::quantile;
use avatarm_core::vision::calibrate::{RobotSilhouette, distance_transform, outline, rasterize};
use avatarm_core::vision::camera::Intrinsics;
use avatarm_core::vision::distortion::Distortion;
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::FootageError;
use crate::calibrate::image_edges;

pub mod shift;
pub mod turn;
mod watch_recording;
pub use watch_recording::watch_recording;

#[cfg(test)]
mod tests;

/// How the drift watch runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DriftSettings {
    /// Footage time between checks (s): a few a second.
    pub every_s: f64,
    /// The largest shift looked for, each way (px).
    pub search_px: u32,
    /// The chamfer distance's cap (px).
    pub truncate_px: f32,
    /// The smallest threshold (px): the erase margin where it is larger.
    pub min_threshold_px: u32,
    /// Checks in a row beyond the threshold, agreeing, that make a drift.
    pub confirm: usize,
    /// Canny's low and high thresholds on the Sobel gradient's magnitude (imageproc's scale,
    /// as `avatarm calibrate --edge-thresholds`).
    pub edges: (f32, f32),
    /// A check whose model outline has fewer pixels than this (the robot out of view) is
    /// skipped.
    pub min_outline_px: usize,
    /// Outline pixels matched per check at most (thinned evenly).
    pub max_outline_samples: usize,
    /// Checks kept for the report (the latest; its counts are of all), so that a live
    /// session's report stays bounded.
    #[serde(default = "default_kept_checks")]
    pub kept_checks: usize,
}

fn default_kept_checks() -> usize {
    KEPT_CHECKS
}

impl Default for DriftSettings {
    fn default() -> Self {
        Self {
            every_s: 0.25,
            search_px: 32,
            truncate_px: 4.0,
            min_threshold_px: 3,
            confirm: 3,
            edges: (20.0, 60.0),
            min_outline_px: 100,
            max_outline_samples: 2000,
            kept_checks: KEPT_CHECKS,
        }
    }
}

impl DriftSettings {
    /// Errors: a setting out of range, named.
    pub fn validate(&self) -> Result<(), FootageError> {
        let bad = |what: &str, message: String| Err(FootageError::input(what, message));
        if !(self.every_s.is_finite() && self.every_s >= 0.0) {
            return bad(
                "drift.every_s",
                format!("{}: give seconds >= 0", self.every_s),
            );
        }
        if !(1..=200).contains(&self.search_px) {
            return bad(
                "drift.search_px",
                format!("{}: give 1 to 200", self.search_px),
            );
        }
        if !(self.truncate_px.is_finite() && self.truncate_px >= 1.0) {
            return bad(
                "drift.truncate_px",
                format!("{}: give at least 1", self.truncate_px),
            );
        }
        if self.kept_checks == 0 {
            return bad("drift.kept_checks", "0: give at least 1 check".into());
        }
        if self.confirm == 0 {
            return bad("drift.confirm", "0: give at least 1 check".into());
        }
        let (low, high) = self.edges;
        if !(low.is_finite() && high.is_finite() && low > 0.0 && low <= high) {
            return bad("drift.edges", format!("{low},{high}: give 0 < LOW <= HIGH"));
        }
        Ok(())
    }
}

/// One check's finding.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriftCheck {
    /// The frame's index in the recording (or the live source's count).
    pub frame: usize,
    /// Its capture stamp (ns).
    pub stamp_ns: u64,
    /// The best shift, its cost and the cost at the pose; `None` when the model's outline
    /// was too short to tell (the robot out of view).
    pub shift: Option<shift::OutlineShift>,
    /// The shift is beyond the threshold.
    pub beyond: bool,
    /// The check's own time (ms): drawing, edges, distance transform and the search.
    pub check_ms: f64,
}

/// A drift found and the pose fitted again.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriftRefit {
    /// The check that confirmed it: its frame and stamp (ns).
    pub detected_frame: usize,
    /// The confirming check's capture stamp (ns).
    pub detected_stamp_ns: u64,
    /// The first check beyond the threshold in the run that confirmed it.
    pub first_beyond_frame: usize,
    /// Its capture stamp (ns).
    pub first_beyond_stamp_ns: u64,
    /// The last check within the threshold before it (ns): the camera moved after this.
    pub last_fitting_stamp_ns: Option<u64>,
    /// The confirming checks' median shift (px).
    pub shift_px: [f64; 2],
    /// The frames fitted to.
    pub frames: Vec<usize>,
    /// The camera's move from the pose before, rotation (deg).
    pub moved_deg: f64,
    /// The same, translation (mm).
    pub moved_mm: f64,
    /// Mean truncated chamfer distance over the fitted frames (px, the outline drawn at each
    /// pose): at the pose before.
    pub cost_before_px: f64,
    /// At the pose turned by the shift alone.
    pub cost_turned_px: f64,
    /// At the fitted turn.
    pub cost_refit_px: f64,
    /// The refit's wall time (s).
    pub refit_s: f64,
    /// The pose from then on: `base_from_camera`, a 4x4 matrix by rows (m).
    pub base_from_camera: [[f64; 4]; 4],
}

/// The watch over a whole recording or session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriftReport {
    /// The pose was watched (else `note` says why not).
    pub watched: bool,
    /// How it went, in words.
    pub note: String,
    /// The settings.
    pub settings: DriftSettings,
    /// A shift beyond this is a move (px): the erase margin, at least the settings' minimum.
    pub threshold_px: f64,
    /// The latest checks (at most [`DriftSettings::kept_checks`]).
    pub checks: Vec<DriftCheck>,
    /// Checks made in all.
    #[serde(default)]
    pub checks_total: usize,
    /// Of those, the ones that saw enough of the robot's outline to measure a shift.
    #[serde(default)]
    pub checks_measured: usize,
    /// Every drift found, in order.
    pub refits: Vec<DriftRefit>,
    /// The kept checks' own time (ms): median and 95th percentile.
    pub check_ms_median: Option<f64>,
    /// 95th percentile of the same.
    pub check_ms_p95: Option<f64>,
}

/// Checks a watch keeps for its report by default ([`DriftSettings::kept_checks`]): 16 min
/// of a live session at two checks a second.
pub const KEPT_CHECKS: usize = 2000;

/// Where the watch stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// No check has fitted yet: the pose's fit is still to be seen.
    Starting,
    /// The pose fitted a check: drifts are watched for.
    Watching,
    /// The first checks were all beyond: the pose never fitted; no move is confirmed until a
    /// check fits (a pose off from the start is not refitted as if it had moved).
    NeverFitted,
}

/// A check beyond the threshold, kept for the refit.
struct Beyond {
    frame: usize,
    stamp_ns: u64,
    shift: [f64; 2],
    triangles: Vec<[Point3<f64>; 3]>,
    field: Vec<f32>,
}

/// The watch over one fixed camera: feed it frames with their joints ([`DriftWatch::check`]);
/// it keeps the pose it believes ([`DriftWatch::camera_from_base`]).
pub struct DriftWatch<'a> {
    model: &'a RobotModel,
    silhouette: &'a RobotSilhouette,
    k: Intrinsics,
    lens: Distortion,
    settings: DriftSettings,
    threshold_px: f64,
    camera_from_base: Isometry3<f64>,
    phase: Phase,
    streak: Vec<Beyond>,
    last_fitting_ns: Option<u64>,
    last_check_ns: Option<u64>,
    checks: std::collections::VecDeque<DriftCheck>,
    checks_total: usize,
    checks_measured: usize,
    refits: Vec<DriftRefit>,
}

impl<'a> DriftWatch<'a> {
    /// A watch of the camera `k` (with lens `lens`) believed at `camera_from_base` (base
    /// points into the optical frame), whose mask is dilated by `margin_px`. Errors: bad
    /// settings.
    pub fn new(
        model: &'a RobotModel,
        silhouette: &'a RobotSilhouette,
        (k, lens): (Intrinsics, Distortion),
        camera_from_base: Isometry3<f64>,
        margin_px: u32,
        settings: DriftSettings,
    ) -> Result<Self, FootageError> {
        settings.validate()?;
        Ok(Self {
            model,
            silhouette,
            k,
            lens,
            settings,
            threshold_px: f64::from(margin_px.max(settings.min_threshold_px)),
            camera_from_base,
            phase: Phase::Starting,
            streak: Vec::new(),
            last_fitting_ns: None,
            last_check_ns: None,
            checks: std::collections::VecDeque::new(),
            checks_total: 0,
            checks_measured: 0,
            refits: Vec::new(),
        })
    }

    /// The pose believed now (base points into the optical frame).
    pub fn camera_from_base(&self) -> Isometry3<f64> {
        self.camera_from_base
    }

    /// A shift beyond this is a move (px).
    pub fn threshold_px(&self) -> f64 {
        self.threshold_px
    }

    /// Whether a frame captured at `stamp_ns` is due a check ([`DriftSettings::every_s`]
    /// after the last).
    pub fn due(&self, stamp_ns: u64) -> bool {
        self.last_check_ns.is_none_or(|last| {
            stamp_ns.saturating_sub(last) as f64 >= self.settings.every_s * 1e9 - 1e3
        })
    }

    /// Checks one frame (RGBA8, the camera's size) at the robot's joints `q` (the model's q
    /// order) captured at `stamp_ns`; returns the refit when this check confirmed a drift
    /// (the new pose is then [`DriftWatch::camera_from_base`]). Errors: a frame of another
    /// size, joints not finite or of another count, a refit the fit refused.
    pub fn check(
        &mut self,
        frame: usize,
        stamp_ns: u64,
        rgba: &image::RgbaImage,
        q: &[f64],
    ) -> Result<Option<&DriftRefit>, FootageError> {
        let (w, h) = (self.k.width as usize, self.k.height as usize);
        let what = format!("drift watch, frame {frame}");
        if rgba.dimensions() != (self.k.width, self.k.height) {
            return Err(FootageError::input(
                what,
                format!("{}x{}, the camera {w}x{h}", rgba.width(), rgba.height()),
            ));
        }
        if q.len() != self.model.dof() || q.iter().any(|v| !v.is_finite()) {
            return Err(FootageError::input(
                what,
                format!("joints {q:?}: give {} finite values", self.model.dof()),
            ));
        }
        let started = Instant::now();
        self.last_check_ns = Some(stamp_ns);
        let triangles = self.silhouette.at(self.model, &Isometry3::identity(), q);
        let edges = image_edges(rgba, self.settings.edges);
        let field = distance_transform(&edges, w, h);
        let found = self.shift_of(&triangles, &field, &self.camera_from_base);
        let beyond = found
            .is_some_and(|s| s.cost_px < s.cost_at_pose_px && norm(s.shift_px) > self.threshold_px);
        while self.checks.len() >= self.settings.kept_checks {
            self.checks.pop_front();
        }
        self.checks.push_back(DriftCheck {
            frame,
            stamp_ns,
            shift: found,
            beyond,
            check_ms: 1e3 * started.elapsed().as_secs_f64(),
        });
        self.checks_total += 1;
        self.checks_measured += usize::from(found.is_some());
        let Some(found) = found else {
            return Ok(None);
        };
        match (self.phase, beyond) {
            (Phase::NeverFitted, true) => return Ok(None),
            // A check that fits (also after a start that did not: the first frames' joints
            // late, say) starts the watch.
            (_, false) => {
                self.phase = Phase::Watching;
                self.streak.clear();
                self.last_fitting_ns = Some(stamp_ns);
                return Ok(None);
            }
            (Phase::Starting, true) => {
                if self.checks_measured >= self.settings.confirm {
                    self.phase = Phase::NeverFitted;
                }
                return Ok(None);
            }
            (Phase::Watching, true) => {}
        }
        self.streak.push(Beyond {
            frame,
            stamp_ns,
            shift: found.shift_px,
            triangles,
            field,
        });
        // A run of checks that disagree (a frame recorded with the wrong joints, a person in
        // front of the arm) is no move of the camera: the oldest is dropped until they agree.
        let agree_px = (self.threshold_px / 2.0).max(2.0);
        while !self.streak.is_empty() {
            let median = median_shift(&self.streak);
            if self
                .streak
                .iter()
                .all(|b| norm([b.shift[0] - median[0], b.shift[1] - median[1]]) <= agree_px)
            {
                break;
            }
            self.streak.remove(0);
        }
        if self.streak.len() < self.settings.confirm {
            return Ok(None);
        }
        // The streak is spent either way: a fit that failed is not run again on every later
        // check.
        let refit = self.refit();
        self.streak.clear();
        self.refits.push(refit?);
        Ok(self.refits.last())
    }

    /// The best shift of the model's outline (the triangles through `pose`) over the edges'
    /// distance field; `None` when the outline is too short.
    fn shift_of(
        &self,
        triangles: &[[Point3<f64>; 3]],
        field: &[f32],
        pose: &Isometry3<f64>,
    ) -> Option<shift::OutlineShift> {
        let (w, h) = (self.k.width as usize, self.k.height as usize);
        let samples = self.samples(triangles, pose);
        if samples.len()
            < self
                .settings
                .min_outline_px
                .min(self.settings.max_outline_samples)
        {
            return None;
        }
        shift::best_shift(
            &samples,
            field,
            (w, h),
            self.settings.search_px,
            self.settings.truncate_px,
        )
    }

    /// The model's outline pixels through `pose`, thinned.
    fn samples(&self, triangles: &[[Point3<f64>; 3]], pose: &Isometry3<f64>) -> Vec<(i32, i32)> {
        let (w, h) = (self.k.width as usize, self.k.height as usize);
        let mask = rasterize(triangles, pose, &self.k, &self.lens);
        shift::outline_samples(
            &outline(&mask, w, h),
            w,
            h,
            self.settings.max_outline_samples,
        )
    }

    /// The mean chamfer cost at no shift over the streak's frames, the model through `pose`.
    fn cost_over_streak(&self, pose: &Isometry3<f64>) -> f64 {
        let size = (self.k.width as usize, self.k.height as usize);
        let costs: Vec<f64> = self
            .streak
            .iter()
            .map(|b| {
                shift::chamfer(
                    &self.samples(&b.triangles, pose),
                    &b.field,
                    size,
                    (0, 0),
                    self.settings.truncate_px,
                )
            })
            .collect();
        costs.iter().sum::<f64>() / costs.len().max(1) as f64
    }

    /// Fits the camera's turn again to the streak's frames, from the pose turned by their
    /// median shift.
    fn refit(&mut self) -> Result<DriftRefit, FootageError> {
        let started = Instant::now();
        let shift = median_shift(&self.streak);
        let by_shift = UnitQuaternion::from_scaled_axis(Vector3::new(
            -shift[1] / self.k.fy,
            shift[0] / self.k.fx,
            0.0,
        ));
        let turn_by = |r: UnitQuaternion<f64>, pose: &Isometry3<f64>| {
            Isometry3::from_parts(nalgebra::Translation3::identity(), r) * pose
        };
        let before = self.camera_from_base;
        let turned = turn_by(by_shift, &before);
        let frames: Vec<turn::TurnFrame> = self
            .streak
            .iter()
            .map(|b| turn::TurnFrame {
                rays: turn::rays(&self.samples(&b.triangles, &turned), &self.k, &self.lens),
                field: turn::smoothed(&b.field, (self.k.width as usize, self.k.height as usize)),
            })
            .collect();
        let (fitted, _) = turn::fit_turn(
            &frames,
            &self.k,
            &self.lens,
            self.settings.truncate_px,
            2.0 / self.k.fx.max(self.k.fy),
        )?;
        let pose = turn_by(fitted, &turned);
        let cost_before_px = self.cost_over_streak(&before);
        let cost_turned_px = self.cost_over_streak(&turned);
        let cost_refit_px = self.cost_over_streak(&pose);
        self.camera_from_base = pose;
        let moved = pose * before.inverse();
        let first = &self.streak[0];
        let last = &self.streak[self.streak.len() - 1];
        let base_from_camera = pose.inverse().to_homogeneous();
        Ok(DriftRefit {
            detected_frame: last.frame,
            detected_stamp_ns: last.stamp_ns,
            first_beyond_frame: first.frame,
            first_beyond_stamp_ns: first.stamp_ns,
            last_fitting_stamp_ns: self.last_fitting_ns,
            shift_px: shift,
            frames: self.streak.iter().map(|b| b.frame).collect(),
            moved_deg: moved.rotation.angle().to_degrees(),
            moved_mm: 1e3 * moved.translation.vector.norm(),
            cost_before_px,
            cost_turned_px,
            cost_refit_px,
            refit_s: started.elapsed().as_secs_f64(),
            base_from_camera: std::array::from_fn(|r| {
                std::array::from_fn(|c| base_from_camera[(r, c)])
            }),
        })
    }

    /// The report of the checks (the latest [`DriftSettings::kept_checks`], the counts of all)
    /// and every refit so far.
    pub fn report(&self) -> DriftReport {
        let mut ms: Vec<f64> = self.checks.iter().map(|c| c.check_ms).collect();
        ms.sort_by(f64::total_cmp);
        let measured = self.checks_measured;
        let note = match self.phase {
            Phase::NeverFitted => format!(
                "not watched: the pose fitted none of the {measured} checks (the robot's outline sits more than {:.0} px from the frames' edges): calibrate the camera first (avatarm calibrate --edges); the watch tells a moved camera from a pose that fits",
                self.threshold_px
            ),
            Phase::Starting if measured == 0 => {
                "not watched: no check saw enough of the robot's outline".into()
            }
            _ if self.refits.is_empty() => format!(
                "{} checks, {measured} measured: the camera stayed within {:.0} px of its pose",
                self.checks_total, self.threshold_px
            ),
            _ => format!(
                "{} checks, {measured} measured: the camera moved {} time(s); the pose was fitted again each time and used from the frame that confirmed it",
                self.checks_total,
                self.refits.len()
            ),
        };
        DriftReport {
            watched: self.phase != Phase::NeverFitted && measured > 0,
            note,
            settings: self.settings,
            threshold_px: self.threshold_px,
            checks: self.checks.iter().cloned().collect(),
            checks_total: self.checks_total,
            checks_measured: self.checks_measured,
            refits: self.refits.clone(),
            check_ms_median: quantile(&ms, 0.5),
            check_ms_p95: quantile(&ms, 0.95),
        }
    }
}

fn norm(v: [f64; 2]) -> f64 {
    v[0].hypot(v[1])
}

/// The per-axis median of the streak's shifts.
fn median_shift(streak: &[Beyond]) -> [f64; 2] {
    std::array::from_fn(|axis| {
        let mut v: Vec<f64> = streak.iter().map(|b| b.shift[axis]).collect();
        v.sort_by(f64::total_cmp);
        quantile(&v, 0.5).unwrap_or(0.0)
    })
}
