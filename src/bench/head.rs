//! `avatarm bench head`: how well the robot is erased from a camera on a moving head (Alice's
//! headset camera). Each point is a headless replay of a scene with `[camera.head]` whose head
//! sweeps at a peak angular speed, its tracking delayed by a latency, with pose compensation on
//! or off; a second series puts an error into the camera's mount. Each replay is scored
//! against the simulated room's ground truth; the table goes to CSV and the chart (leak against
//! head speed, and against the mount's error) to SVG and PNG.

use std::path::{Path, PathBuf};

use avatarm_core::vision::head::perturbed_mount;
use avatarm_scene::Scene;
use nalgebra::Vector3;
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;

use super::EraseFigures;
use super::chart::{
    Chart, LogPanel, axes, drawing_error, legend, log_axes, padded, save_chart, write_table,
};
use crate::AppError;
use crate::replay::{self, ReplayOptions};

/// What `bench head` sweeps.
#[derive(Debug, Clone)]
pub struct HeadSweep {
    /// Peak angular speeds of the head's sweep (degrees/s).
    pub speeds_deg_s: Vec<f64>,
    /// Head tracking latencies (ms).
    pub latencies_ms: Vec<f64>,
    /// Pose compensation off and/or on.
    pub compensation: Vec<bool>,
    /// Errors put into the mount (degrees, a yaw about the head's vertical), each at
    /// `mount_speed_deg_s` and `mount_latency_ms` with compensation on; empty: none.
    pub mount_errors_deg: Vec<f64>,
    /// The head's speed for the mount series (degrees/s).
    pub mount_speed_deg_s: f64,
    /// The tracking latency for the mount series (ms).
    pub mount_latency_ms: f64,
    /// Background views kept, each a point at `mount_speed_deg_s` and `mount_latency_ms`,
    /// compensated: 0 (the empty room's photograph as it is, as for a fixed camera), 1 (that
    /// photograph re-projected into each view), more (with views captured from the frames);
    /// empty: none.
    pub background_views: Vec<usize>,
    /// Simulated seconds replayed per point.
    pub duration_s: f64,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for HeadSweep {
    fn default() -> Self {
        Self {
            speeds_deg_s: vec![0.0, 15.0, 30.0, 60.0],
            latencies_ms: vec![0.0, 20.0, 50.0, 100.0],
            compensation: vec![false, true],
            mount_errors_deg: vec![0.0, 0.5, 1.0, 2.0],
            mount_speed_deg_s: 30.0,
            mount_latency_ms: 20.0,
            background_views: vec![0, 1, 8],
            duration_s: 2.0,
            progress: false,
        }
    }
}

/// One point and what it measured.
#[derive(Debug, Clone, Serialize)]
pub struct HeadPoint {
    /// Peak angular speed of the head (degrees/s).
    pub speed_deg_s: f64,
    /// Head tracking latency (ms).
    pub latency_ms: f64,
    /// Pose compensation.
    pub compensation: bool,
    /// Error put into the mount (degrees).
    pub mount_error_deg: f64,
    /// Background views kept (0: the photograph as it is).
    pub background_views: usize,
    /// Mean IoU of the mask with the true silhouette.
    pub iou_mean: f64,
    /// Mean leak, % of the robot's pixels left unmasked.
    pub leak_pct_mean: f64,
    /// Worst frame's leak (%).
    pub leak_pct_max: f64,
    /// Mean over-masking (% of the robot's pixels).
    pub overmask_pct_mean: f64,
    /// Mean PSNR of the erased frame in the true robot region (dB): how well the background
    /// replaces the robot.
    pub psnr_db_mean: f64,
    /// Median angle between the mask's camera and the true camera (degrees).
    pub camera_error_deg_median: f64,
    /// 95th percentile of the same.
    pub camera_error_deg_p95: f64,
    /// Median wall time of one app update (ms).
    pub frame_ms_median: f64,
    /// The background's PSNR in the robot's region against the angle between the frame's
    /// camera and the photograph's (degrees): `(bin low, bin high, frames, mean dB)`.
    pub psnr_by_photo_angle: Vec<(f64, f64, usize, f64)>,
}

/// What the sweep wrote.
#[derive(Debug, Clone)]
pub struct HeadOutputs {
    /// The points, in sweep order (the speed series, then the mount series).
    pub points: Vec<HeadPoint>,
    /// The table.
    pub csv: PathBuf,
    /// The chart.
    pub svg: PathBuf,
    /// The chart as an image.
    pub png: PathBuf,
}

/// Runs the sweep on `scene` (which needs a `[camera.head]` with a sweep), writing into `out`
/// (one replay folder per point under `runs/`).
#[expect(
    clippy::too_many_lines,
    reason = "the sweep's loops over latency, speed, compensation and mount error around one measurement"
)]
pub fn run_head(scene: &Scene, sweep: &HeadSweep, out: &Path) -> Result<HeadOutputs, AppError> {
    let amplitude = scene
        .file
        .camera
        .head
        .as_ref()
        .and_then(|h| h.sweep)
        .map(|w| w.amplitude_deg);
    let Some(amplitude) = amplitude else {
        return Err(AppError::flag(
            "SCENE",
            format!(
                "the scene '{}' (camera '{}') has no [camera.head] sweep to vary (assets/scenes/head_camera.toml has one)",
                scene.file.name,
                scene.camera_name()
            ),
        ));
    };
    if !(sweep.duration_s.is_finite() && sweep.duration_s > 0.0) {
        return Err(AppError::flag(
            "--duration",
            format!("{} must be > 0", sweep.duration_s),
        ));
    }
    let check = |flag: &str, v: f64, hi: f64| {
        if v.is_finite() && (0.0..=hi).contains(&v) {
            Ok(())
        } else {
            Err(AppError::flag(flag, format!("{v} is not within 0..={hi}")))
        }
    };
    for &v in &sweep.speeds_deg_s {
        check("--speeds", v, 720.0)?;
        if v > 0.0 && amplitude <= 0.0 {
            return Err(AppError::flag(
                "--speeds",
                "the scene's sweep has no amplitude to move through",
            ));
        }
    }
    for &v in &sweep.latencies_ms {
        check("--latencies", v, 2000.0)?;
    }
    for &v in &sweep.mount_errors_deg {
        check("--mount-errors", v, 30.0)?;
    }
    check("--mount-speed", sweep.mount_speed_deg_s, 720.0)?;
    check("--mount-latency", sweep.mount_latency_ms, 2000.0)?;
    let views = scene.head.as_ref().map_or(0, |h| h.background_views);
    for &v in &sweep.background_views {
        if v > 32 {
            return Err(AppError::flag(
                "--background-views",
                format!("{v} is not within 0..=32"),
            ));
        }
    }
    let mut settings: Vec<(f64, f64, bool, f64, usize)> = Vec::new();
    for &v in &sweep.speeds_deg_s {
        for &l in &sweep.latencies_ms {
            for &c in &sweep.compensation {
                settings.push((v, l, c, 0.0, views));
            }
        }
    }
    let (ms, ml) = (sweep.mount_speed_deg_s, sweep.mount_latency_ms);
    let extra = sweep
        .mount_errors_deg
        .iter()
        .map(|&e| (ms, ml, true, e, views))
        .chain(
            sweep
                .background_views
                .iter()
                .map(|&b| (ms, ml, true, 0.0, b)),
        );
    for point in extra {
        // A point may be in the speed series already.
        if !settings.contains(&point) {
            settings.push(point);
        }
    }
    if settings.is_empty() {
        return Err(AppError::flag("bench head", "the sweep is empty"));
    }
    super::chart::register_font()?;
    std::fs::create_dir_all(out).map_err(|source| AppError::Io {
        path: out.to_owned(),
        action: "create",
        source,
    })?;
    let bar = crate::progress::bar(
        settings.len() as u64,
        format!("bench head {}", scene.file.name),
        sweep.progress,
    );
    let mut points = Vec::with_capacity(settings.len());
    for (speed, latency_ms, compensation, mount_error, background_views) in settings {
        let label = format!(
            "v{speed} l{latency_ms} {} m{mount_error} b{background_views}",
            if compensation { "PC" } else { "noPC" }
        );
        bar.set_message(label.clone());
        let in_setting = |source: AppError| AppError::BenchSetting {
            label: label.clone(),
            source: Box::new(source),
        };
        let mut run = head_variant(
            scene,
            sweep.duration_s,
            speed,
            latency_ms,
            compensation,
            mount_error,
        )
        .map_err(in_setting)?;
        if let Some(head) = run.head.as_mut() {
            head.background_views = background_views;
        }
        let dir = out
            .join("runs")
            .join(label.replace(' ', "_").replace('.', "p"));
        let mut options = ReplayOptions::new(dir);
        options.frames_every = u32::MAX;
        let report = replay::run(&run, options).map_err(in_setting)?;
        let figures = EraseFigures::of(&report, "bench head").map_err(in_setting)?;
        let camera_error = report
            .head
            .as_ref()
            .and_then(|h| h.mask_camera_error_deg)
            .ok_or_else(|| {
                in_setting(AppError::command(
                    "bench head",
                    "the report has no head.mask_camera_error_deg".to_owned(),
                ))
            })?;
        points.push(HeadPoint {
            speed_deg_s: speed,
            latency_ms,
            compensation,
            mount_error_deg: mount_error,
            iou_mean: figures.iou_mean,
            leak_pct_mean: figures.leak_pct_mean,
            leak_pct_max: figures.leak_pct_max,
            overmask_pct_mean: figures.overmask_pct_mean,
            psnr_db_mean: figures.psnr_db_mean,
            camera_error_deg_median: camera_error.median,
            camera_error_deg_p95: camera_error.p95,
            frame_ms_median: figures.frame_ms.median,
            background_views,
            psnr_by_photo_angle: report
                .head
                .as_ref()
                .map(|head| {
                    head.psnr_by_angle_from_photo
                        .iter()
                        .filter_map(|r| {
                            Some((
                                r.angle_deg[0],
                                r.angle_deg[1],
                                r.frames,
                                r.psnr_robot_db_mean?,
                            ))
                        })
                        .collect()
                })
                .unwrap_or_default(),
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    let csv = out.join("head_erase.csv");
    write_table(
        &csv,
        "speed_deg_s,latency_ms,pose_compensation,mount_error_deg,background_views,iou_mean,\
leak_pct_mean,leak_pct_max,overmask_pct_mean,psnr_db_mean,camera_error_deg_median,\
camera_error_deg_p95,frame_ms_median,psnr_db_by_photo_angle",
        points.iter().map(|p| {
            let bins: Vec<String> = p
                .psnr_by_photo_angle
                .iter()
                .map(|(lo, hi, n, db)| format!("{lo}-{hi}deg:{n}:{db:.2}"))
                .collect();
            format!(
                "{},{},{},{},{},{:.5},{:.4},{:.4},{:.4},{:.3},{:.4},{:.4},{:.2},{}",
                p.speed_deg_s,
                p.latency_ms,
                p.compensation,
                p.mount_error_deg,
                p.background_views,
                p.iou_mean,
                p.leak_pct_mean,
                p.leak_pct_max,
                p.overmask_pct_mean,
                p.psnr_db_mean,
                p.camera_error_deg_median,
                p.camera_error_deg_p95,
                p.frame_ms_median,
                bins.join(" ")
            )
        }),
    )?;
    let svg = out.join("head_erase.svg");
    let png = out.join("head_erase.png");
    let title = format!(
        "Erasing from a camera on a moving head ({}, {} s per point)",
        scene.file.name, sweep.duration_s
    );
    let chart = HeadChart {
        points: &points,
        title: &title,
        mount_speed: sweep.mount_speed_deg_s,
        mount_latency: sweep.mount_latency_ms,
        views,
    };
    let size = (1800, 620);
    save_chart(&chart, size, &svg, &png)?;
    Ok(HeadOutputs {
        points,
        csv,
        svg,
        png,
    })
}

/// `scene` for one point: the video pipeline only (no task), `duration_s` long, the head's
/// sweep at `speed` degrees/s, its tracking `latency_ms` late, compensation on or off, and the
/// believed mount turned by `mount_error_deg` about the head's vertical (its y axis).
pub fn head_variant(
    scene: &Scene,
    duration_s: f64,
    speed: f64,
    latency_ms: f64,
    compensation: bool,
    mount_error_deg: f64,
) -> Result<Scene, AppError> {
    let mut run = scene.clone();
    run.file.duration_s = duration_s;
    run.file.task = None;
    run.trial = None;
    run.file.erase.pose_compensation = compensation;
    let overrides = crate::cli::overrides::EraseOverrides {
        head_speed: Some(speed),
        tracking_latency_ms: Some(latency_ms),
        ..Default::default()
    };
    overrides.apply(&mut run)?;
    if let Some(head) = run.head.as_mut() {
        head.believed_mount = perturbed_mount(
            &head.mount,
            &Vector3::y(),
            mount_error_deg.to_radians(),
            &Vector3::zeros(),
        );
        run.believed_camera.world_from_camera = head.believed_camera_at(0.0);
    }
    Ok(run)
}

struct HeadChart<'a> {
    points: &'a [HeadPoint],
    title: &'a str,
    mount_speed: f64,
    mount_latency: f64,
    /// The scene's background views (the speed and mount series').
    views: usize,
}

/// The log axis's range over `values` (and the 1 % goal), clamped above 0.
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .chain([1.0])
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    (lo.max(1e-3) / 2.0, hi * 2.0)
}

impl Chart for HeadChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(self.title, ("sans-serif", 20)).map_err(err)?;
        let panels = root.split_evenly((1, 3));
        let speed_series: Vec<&HeadPoint> = self
            .points
            .iter()
            .filter(|p| p.mount_error_deg == 0.0 && p.background_views == self.views)
            .collect();
        // Leak against head speed: one colour per latency, thick with compensation.
        let x = padded(speed_series.iter().map(|p| p.speed_deg_s));
        let y = log_range(speed_series.iter().map(|p| p.leak_pct_mean));
        let mut chart = log_axes(
            &panels[0],
            x,
            y,
            "head's peak angular speed (deg/s)",
            "mean leak (% of the robot's pixels, log)",
        )?;
        goal_line(&mut chart, x)?;
        let mut latencies: Vec<f64> = speed_series.iter().map(|p| p.latency_ms).collect();
        latencies.sort_by(f64::total_cmp);
        latencies.dedup();
        for (i, &latency) in latencies.iter().enumerate() {
            for compensation in [true, false] {
                let mut line: Vec<(f64, f64)> = speed_series
                    .iter()
                    .filter(|p| p.latency_ms == latency && p.compensation == compensation)
                    .map(|p| (p.speed_deg_s, p.leak_pct_mean.max(y.0)))
                    .collect();
                if line.is_empty() {
                    continue;
                }
                line.sort_by(|a, b| a.0.total_cmp(&b.0));
                let (width, how) = if compensation {
                    (3, "pose compensation")
                } else {
                    (1, "newest pose")
                };
                let name = format!("tracking {latency} ms, {how}");
                dotted_line(&mut chart, &line, Palette99::pick(i).to_rgba(), width, name)?;
            }
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        // Leak against the mount's error.
        let mounts: Vec<&HeadPoint> = self
            .points
            .iter()
            .filter(|p| {
                p.speed_deg_s == self.mount_speed
                    && p.latency_ms == self.mount_latency
                    && p.compensation
                    && p.background_views == self.views
            })
            .collect();
        if mounts.len() > 1 {
            let x = padded(mounts.iter().map(|p| p.mount_error_deg));
            let y = log_range(mounts.iter().map(|p| p.leak_pct_mean));
            let mut chart = log_axes(
                &panels[1],
                x,
                y,
                "error in the camera's mount (deg of yaw)",
                "mean leak (%, log)",
            )?;
            let mut line: Vec<(f64, f64)> = mounts
                .iter()
                .map(|p| (p.mount_error_deg, p.leak_pct_mean.max(y.0)))
                .collect();
            line.sort_by(|a, b| a.0.total_cmp(&b.0));
            line.dedup_by(|a, b| a.0 == b.0);
            goal_line(&mut chart, x)?;
            let name = format!(
                "mount error: {} deg/s, tracking {} ms, compensated",
                self.mount_speed, self.mount_latency
            );
            dotted_line(&mut chart, &line, RED.to_rgba(), 3, name)?;
            legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        }
        // The background's PSNR against how far the view is from the photograph's.
        let backgrounds: Vec<&HeadPoint> = self
            .points
            .iter()
            .filter(|p| {
                p.speed_deg_s == self.mount_speed
                    && p.latency_ms == self.mount_latency
                    && p.compensation
                    && p.mount_error_deg == 0.0
                    && !p.psnr_by_photo_angle.is_empty()
            })
            .collect();
        if !backgrounds.is_empty() {
            let mid = |b: &(f64, f64, usize, f64)| (b.0 + b.1.min(2.0 * b.0.max(1.0))) / 2.0;
            let x = padded(
                backgrounds
                    .iter()
                    .flat_map(|p| p.psnr_by_photo_angle.iter().map(mid)),
            );
            let y = padded(
                backgrounds
                    .iter()
                    .flat_map(|p| p.psnr_by_photo_angle.iter().map(|b| b.3)),
            );
            let mut chart = axes(
                &panels[2],
                (0.0_f64.min(x.0), x.1),
                y,
                "angle from the empty room's photograph (deg)",
                "PSNR in the robot's region (dB)",
            )?;
            for (i, p) in backgrounds.iter().enumerate() {
                let line: Vec<(f64, f64)> = p
                    .psnr_by_photo_angle
                    .iter()
                    .map(|b| (mid(b), b.3))
                    .collect();
                let name = match p.background_views {
                    0 => "the photograph as it is".to_owned(),
                    1 => "the photograph re-projected".to_owned(),
                    n => format!("re-projected, {} views from the frames", n - 1),
                };
                dotted_line(&mut chart, &line, Palette99::pick(i + 5).to_rgba(), 2, name)?;
            }
            legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
        Ok(())
    }
}

/// The 1 % leak goal as a black line across `x`.
fn goal_line<'a, DB: DrawingBackend + 'a>(
    chart: &mut LogPanel<'a, DB>,
    x: (f64, f64),
) -> Result<(), AppError>
where
    DB::ErrorType: 'static,
{
    chart
        .draw_series(LineSeries::new(
            [(x.0, 1.0), (x.1, 1.0)],
            BLACK.stroke_width(1),
        ))
        .map_err(drawing_error)?
        .label("goal: 1 %")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK));
    Ok(())
}

/// A named line through `line` with a dot at each point.
fn dotted_line<'a, DB: DrawingBackend + 'a, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    line: &[(f64, f64)],
    colour: RGBAColor,
    width: u32,
    name: String,
) -> Result<(), AppError>
where
    DB::ErrorType: 'static,
    CT: CoordTranslate<From = (f64, f64)>,
{
    let style = colour.stroke_width(width);
    chart
        .draw_series(LineSeries::new(line.iter().copied(), style))
        .map_err(drawing_error)?
        .label(name)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
    chart
        .draw_series(line.iter().map(|&p| Circle::new(p, 4, colour.filled())))
        .map_err(drawing_error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> Scene {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/head_camera.toml");
        Scene::load(&path, &Default::default()).expect("head scene")
    }

    #[test]
    fn a_variant_sets_speed_latency_compensation_and_the_mount_error() {
        let s = scene();
        let v = head_variant(&s, 1.5, 60.0, 50.0, false, 2.0).expect("variant");
        let head = v.head.as_ref().expect("head");
        assert!((head.motion.peak_angular_speed(5.0).to_degrees() - 60.0).abs() < 0.6);
        assert_eq!(head.tracking.latency_s, 0.05);
        assert!(!v.file.erase.pose_compensation);
        assert_eq!(v.file.duration_s, 1.5);
        assert!(v.file.task.is_none());
        let (angle, offset) =
            avatarm_core::vision::head::pose_error(&head.mount, &head.believed_mount);
        assert!((angle.to_degrees() - 2.0).abs() < 1e-9 && offset < 1e-12);
        let (angle, _) = avatarm_core::vision::head::pose_error(
            &v.believed_camera.world_from_camera,
            &v.true_camera.world_from_camera,
        );
        assert!((angle.to_degrees() - 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_scene_without_a_head_sweep_is_refused_by_name() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/default.toml");
        let s = Scene::load(&path, &Default::default()).expect("scene");
        let e =
            run_head(&s, &HeadSweep::default(), Path::new("/nonexistent")).expect_err("no head");
        assert!(e.to_string().contains("no [camera.head] sweep"), "{e}");
        let e = run_head(
            &scene(),
            &HeadSweep {
                speeds_deg_s: vec![f64::NAN],
                ..HeadSweep::default()
            },
            Path::new("/nonexistent"),
        )
        .expect_err("NaN speed");
        assert!(e.to_string().contains("--speeds"), "{e}");
    }
}
