//! `avatarm bench twin`: how much twin the mask needs. The camera sees the real robot (its full
//! visual meshes); the app's mask twin can be lighter. Each variant (the visual meshes, the
//! collision geometry, the meshes simplified to a fraction of their triangles, a primitive
//! description of the same robot) is a headless replay of the scene with the arm moving at the
//! TCP speed cap, scored against the simulated room's ground truth: mask IoU, leak, overmask,
//! the dilation that brings the leak to 1 % or less, and the mask twin's GPU time and
//! triangle count. Table to CSV, chart (GPU time against leak, Pareto front) to SVG and PNG.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use avatarm_core::dr;
use avatarm_core::robot::kinematics::pose_difference;
use avatarm_core::robot::trajectory::{JointTrajectory, Keyframe};
use avatarm_core::robot::{GeometryKind, LinkId, PackagePath, RobotModel};
use avatarm_scene::{Scene, TwinSpec};
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;

use super::EraseFigures;
use super::chart::{
    Chart, axes, drawing_error, front_line, legend, padded, pareto_front, point_labels,
    register_font, save_chart, write_table,
};
use crate::AppError;
use crate::replay::{self, ReplayOptions};

/// One mask twin to measure.
#[derive(Debug, Clone, PartialEq)]
pub struct TwinVariant {
    /// Short name (`visual`, `collision`, `keep 10%`, `sawyer_lite`).
    pub label: String,
    /// The scene's `[twin]` for it.
    pub spec: TwinSpec,
}

impl TwinVariant {
    /// Parses `visual`, `collision`, `keep:F` (fraction of the visual meshes' triangles kept)
    /// or `urdf:PATH` (another description of the robot, joints matched by name).
    pub fn parse(text: &str) -> Result<Self, AppError> {
        let bad = |why: String| AppError::flag("--variants", format!("'{text}': {why}"));
        let spec = match text.split_once(':') {
            None if text == "visual" => TwinSpec {
                keep_triangles: 1.0,
                ..TwinSpec::default()
            },
            None if text == "collision" => TwinSpec {
                geometry: GeometryKind::Collision,
                keep_triangles: 1.0,
                ..TwinSpec::default()
            },
            Some(("keep", f)) => {
                let keep: f64 = f
                    .parse()
                    .map_err(|_| bad(format!("'{f}' is not a number")))?;
                if !(keep > 0.0 && keep <= 1.0) {
                    return Err(bad(format!("{keep} must be in (0, 1]")));
                }
                TwinSpec {
                    keep_triangles: keep,
                    ..TwinSpec::default()
                }
            }
            Some(("urdf", path)) => TwinSpec {
                urdf: Some(PathBuf::from(path)),
                keep_triangles: 1.0,
                ..TwinSpec::default()
            },
            _ => {
                return Err(bad(
                    "expected visual, collision, keep:FRACTION or urdf:PATH".into(),
                ));
            }
        };
        let label = match (&spec.urdf, spec.geometry) {
            (Some(p), _) => p
                .file_stem()
                .map_or_else(|| p.display().to_string(), |s| s.to_string_lossy().into()),
            (None, GeometryKind::Collision) => "collision".into(),
            (None, GeometryKind::Visual) if spec.keep_triangles < 1.0 => {
                format!("keep {}%", spec.keep_triangles * 100.0)
            }
            (None, GeometryKind::Visual) => "visual".into(),
        };
        Ok(Self { label, spec })
    }
}

/// What `bench twin` measures.
#[derive(Debug, Clone)]
pub struct TwinSweep {
    /// The twins.
    pub variants: Vec<TwinVariant>,
    /// Simulated seconds replayed per variant.
    pub duration_s: f64,
    /// The TCP speed the scene's timeline is retimed to (m/s): the paper's cap.
    pub tcp_speed: f64,
    /// Score every N-th camera frame's mask for the dilation analysis.
    pub frames_every: u32,
    /// Largest dilation tried (px).
    pub max_dilate: u32,
    /// Folders for `package://` URIs of `urdf:` variants.
    pub packages: PackagePath,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for TwinSweep {
    fn default() -> Self {
        Self {
            variants: ["visual", "collision", "keep:0.5", "keep:0.1", "keep:0.02"]
                .iter()
                .map(|v| TwinVariant::parse(v).expect("built-in variant"))
                .collect(),
            duration_s: 2.0,
            tcp_speed: 0.25,
            frames_every: 2,
            max_dilate: 32,
            packages: PackagePath::default(),
            progress: false,
        }
    }
}

/// One twin and what it measured.
#[derive(Debug, Clone, Serialize)]
pub struct TwinPoint {
    /// The variant.
    pub label: String,
    /// Triangles the mask twin draws.
    pub triangles: usize,
    /// Median GPU time of the mask twin's flat render, ms (`None` without timestamp queries).
    pub gpu_mask_twin_ms: Option<f64>,
    /// Median wall time of one app update, ms.
    pub frame_ms_median: f64,
    /// `frame_ms_median` over that of the first variant of the same run.
    pub frame_cost_ratio: f64,
    /// Mean IoU of the mask (no dilation) with the true silhouette.
    pub iou_mean: f64,
    /// Mean leak, % of robot pixels.
    pub leak_pct_mean: f64,
    /// Worst leak, % of robot pixels.
    pub leak_pct_max: f64,
    /// Mean overmask, % of robot pixels.
    pub overmask_pct_mean: f64,
    /// Mean PSNR of the erased frame in the true robot region, dB.
    pub psnr_db_mean: f64,
    /// Smallest dilation (px) with a mean leak of 1 % or less over the scored frames (`None`:
    /// not within `max_dilate`).
    pub dilate_for_1pct: Option<u32>,
    /// On the Pareto front of GPU time (or frame cost without GPU times) against leak.
    pub pareto: bool,
}

/// What the sweep wrote.
#[derive(Debug, Clone)]
pub struct TwinOutputs {
    /// The points, in sweep order.
    pub points: Vec<TwinPoint>,
    /// The scene's peak TCP speed before retiming, m/s.
    pub scene_tcp_speed: f64,
    /// The factor the timeline's times were multiplied by.
    pub time_scale: f64,
    /// The TCP's peak speed within the replayed window after retiming, m/s.
    pub window_tcp_speed: f64,
    /// The raw table.
    pub csv: PathBuf,
    /// The chart.
    pub svg: PathBuf,
    /// The chart as an image.
    pub png: PathBuf,
}

/// Peak linear speed (m/s) of `link` along `trajectory` over `[0, until_s]`, by central
/// differences of forward kinematics at 100 Hz.
pub fn peak_link_speed(
    model: &RobotModel,
    trajectory: &JointTrajectory,
    link: LinkId,
    until_s: f64,
) -> f64 {
    let dt = 0.01;
    let base = nalgebra::Isometry3::identity();
    // One FK per sample; consecutive samples give the speed between them.
    let poses: Vec<_> = (0..=(until_s / dt).ceil() as usize)
        .filter_map(|k| trajectory.sample(k as f64 * dt))
        .map(|q| model.forward_kinematics(&base, q.as_slice())[link])
        .collect();
    poses
        .windows(2)
        .map(|w| pose_difference(&w[0], &w[1]).fixed_rows::<3>(0).norm() / dt)
        .fold(0.0, f64::max)
}

/// Runs every variant on `scene` (its timeline retimed so that the TCP's peak over the whole
/// scene is `sweep.tcp_speed`; the peak within the replayed window is reported beside it),
/// writing into `out`.
#[expect(
    clippy::too_many_lines,
    reason = "the sweep's loop over the twins around one measurement, then the chart and the table"
)]
pub fn run_twin(scene: &Scene, sweep: &TwinSweep, out: &Path) -> Result<TwinOutputs, AppError> {
    if !(sweep.duration_s.is_finite() && sweep.duration_s > 0.0) {
        return Err(AppError::flag(
            "--duration",
            format!("{} must be > 0", sweep.duration_s),
        ));
    }
    if !(sweep.tcp_speed.is_finite() && sweep.tcp_speed > 0.0) {
        return Err(AppError::flag(
            "--tcp-speed",
            format!("{} must be > 0", sweep.tcp_speed),
        ));
    }
    if sweep.variants.is_empty() {
        return Err(AppError::flag("--variants", "no twin to measure"));
    }
    // Load every variant's description before minutes of replays.
    let mut twins = Vec::with_capacity(sweep.variants.len());
    for v in &sweep.variants {
        let model = match &v.spec.urdf {
            None => Arc::clone(&scene.model),
            Some(path) => {
                let twin = RobotModel::from_urdf_file(path, &sweep.packages)
                    .map_err(|e| AppError::flag("--variants", format!("'{}': {e}", v.label)))?;
                // As the scene's [twin] urdf: posed by the robot's joint names.
                let missing = avatarm_core::robot::JointMap::new(&scene.model, &twin).missing;
                if !missing.is_empty() {
                    return Err(AppError::flag(
                        "--variants",
                        format!(
                            "'{}' has movable joints that the robot '{}' does not: {} (the twin must be the same robot)",
                            v.label,
                            scene.model.name,
                            missing.join(", ")
                        ),
                    ));
                }
                Arc::new(twin)
            }
        };
        let detail = crate::app::twin_detail(&v.spec);
        let triangles = avatarm_twin::twin_triangles(&model, detail)
            .map_err(|e| AppError::flag("--variants", format!("'{}': {e}", v.label)))?;
        twins.push((model, triangles));
    }
    register_font()?;
    std::fs::create_dir_all(out).map_err(|source| AppError::Io {
        path: out.to_owned(),
        action: "create",
        source,
    })?;

    // The arm at the speed cap: retime the timeline so the TCP's peak speed is the cap.
    let tcp = scene
        .trial
        .as_ref()
        .map_or_else(|| scene.model.tip_link(), |t| t.tcp);
    let scene_tcp_speed =
        peak_link_speed(&scene.model, &scene.trajectory, tcp, scene.file.duration_s);
    let time_scale = if scene_tcp_speed > 0.0 {
        scene_tcp_speed / sweep.tcp_speed
    } else {
        1.0
    };
    let retimed = JointTrajectory::new(
        scene
            .trajectory
            .keyframes()
            .iter()
            .map(|k| Keyframe {
                t_s: k.t_s * time_scale,
                q: k.q.clone(),
            })
            .collect(),
    );
    let window_tcp_speed = peak_link_speed(&scene.model, &retimed, tcp, sweep.duration_s);

    let bar = crate::progress::bar(
        sweep.variants.len() as u64,
        format!("bench twin {}", scene.file.name),
        sweep.progress,
    );
    let mut points = Vec::with_capacity(sweep.variants.len());
    for (v, (model, triangles)) in sweep.variants.iter().zip(twins) {
        bar.set_message(v.label.clone());
        let mut run = scene.clone();
        run.file.duration_s = sweep.duration_s;
        run.file.task = None;
        run.trial = None;
        run.file.twin = v.spec.clone();
        run.twin_model = model;
        run.trajectory = retimed.clone();
        // The mask as the twin draws it: no dilation, no feathering.
        run.file.erase.dilate_px = 0;
        run.file.erase.feather_px = 0;
        let dir = out
            .join("runs")
            .join(v.label.replace([' ', '%'], "_").replace('.', "p"));
        // A fresh folder: the dilation analysis reads every mask in it.
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|source| AppError::Io {
                path: dir.clone(),
                action: "clear",
                source,
            })?;
        }
        let mut options = ReplayOptions::new(dir.clone());
        options.frames_every = sweep.frames_every.max(1);
        let in_setting = |source: AppError| AppError::BenchSetting {
            label: v.label.clone(),
            source: Box::new(source),
        };
        let report = replay::run(&run, options).map_err(in_setting)?;
        let figures = EraseFigures::of(&report, "bench twin").map_err(in_setting)?;
        let on_gpu = report.timing_ms.source == "gpu";
        let gpu_mask_twin_ms = on_gpu
            .then(|| {
                report
                    .timing_ms
                    .gpu_passes
                    .get("mask twin")
                    .and_then(|p| p.ms)
                    .map(|t| t.median)
            })
            .flatten();
        let leaks = leak_by_dilation_in(&dir, sweep.max_dilate).map_err(in_setting)?;
        points.push(TwinPoint {
            label: v.label.clone(),
            triangles,
            gpu_mask_twin_ms,
            frame_ms_median: figures.frame_ms.median,
            frame_cost_ratio: 1.0,
            iou_mean: figures.iou_mean,
            leak_pct_mean: figures.leak_pct_mean,
            leak_pct_max: figures.leak_pct_max,
            overmask_pct_mean: figures.overmask_pct_mean,
            psnr_db_mean: figures.psnr_db_mean,
            dilate_for_1pct: leaks.iter().position(|&l| l <= 1.0).map(|d| d as u32),
            pareto: false,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    let base_ms = points[0].frame_ms_median;
    for p in &mut points {
        p.frame_cost_ratio = p.frame_ms_median / base_ms;
    }
    let cost: Vec<f64> = points.iter().map(TwinPoint::cost_ms).collect();
    let leak: Vec<f64> = points.iter().map(|p| p.leak_pct_mean).collect();
    for (p, on) in points.iter_mut().zip(pareto_front(&cost, &leak)) {
        p.pareto = on;
    }
    let csv = out.join("twin_detail.csv");
    write_csv(&csv, &points)?;
    let (svg, png) = (out.join("twin_detail.svg"), out.join("twin_detail.png"));
    let title = format!(
        "Mask twin detail: mask GPU time against leak ({}, TCP at {} m/s, {} s per twin)",
        scene.file.name, sweep.tcp_speed, sweep.duration_s
    );
    save_chart(
        &TwinChart {
            points: &points,
            title: &title,
        },
        CHART_SIZE,
        &svg,
        &png,
    )?;
    Ok(TwinOutputs {
        points,
        scene_tcp_speed,
        time_scale,
        window_tcp_speed,
        csv,
        svg,
        png,
    })
}

impl TwinPoint {
    /// The cost axis: the mask twin's GPU time, else the frame's wall time.
    pub fn cost_ms(&self) -> f64 {
        self.gpu_mask_twin_ms.unwrap_or(self.frame_ms_median)
    }
}

/// Mean leak (%) at each dilation `0..=max` over the frames a replay saved in `dir`
/// (`mask_N.png` against `gt_silhouette_N.png`), frames without robot pixels left out.
pub fn leak_by_dilation_in(dir: &Path, max: u32) -> Result<Vec<f64>, AppError> {
    let mut sums = vec![0.0; max as usize + 1];
    let mut frames = 0usize;
    let entries = std::fs::read_dir(dir).map_err(|source| AppError::Io {
        path: dir.to_owned(),
        action: "read",
        source,
    })?;
    let mut masks: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("mask_") && n.ends_with(".png"))
        })
        .collect();
    masks.sort();
    for mask_path in masks {
        let name = mask_path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .replacen("mask_", "gt_silhouette_", 1);
        let gray = |path: &Path| -> Result<image::GrayImage, AppError> {
            Ok(image::open(path)
                .map_err(|source| AppError::Image {
                    path: path.to_owned(),
                    action: "read",
                    source,
                })?
                .to_luma8())
        };
        let (m, t) = (gray(&mask_path)?, gray(&dir.join(&name))?);
        let (w, h) = m.dimensions();
        let bin = |img: &image::GrayImage| {
            img.pixels()
                .map(|p| u8::from(p.0[0] > 127))
                .collect::<Vec<u8>>()
        };
        if t.dimensions() != (w, h) {
            return Err(AppError::command(
                "bench twin",
                format!(
                    "{} is {}x{} but its mask is {w}x{h}",
                    dir.join(&name).display(),
                    t.width(),
                    t.height()
                ),
            ));
        }
        if let Some(leaks) = dr::leak_by_dilation(&bin(&m), &bin(&t), w, h, max) {
            for (s, l) in sums.iter_mut().zip(leaks) {
                *s += l;
            }
            frames += 1;
        }
    }
    if frames == 0 {
        return Err(AppError::command(
            "bench twin",
            format!(
                "{}: no saved frame shows the robot, so no dilation can be measured",
                dir.display()
            ),
        ));
    }
    Ok(sums.into_iter().map(|s| s / frames as f64).collect())
}

const CSV_HEADER: &str = "label,triangles,gpu_mask_twin_ms,frame_ms_median,frame_cost_ratio,\
iou_mean,leak_pct_mean,leak_pct_max,overmask_pct_mean,psnr_db_mean,dilate_for_1pct,pareto";

fn write_csv(path: &Path, points: &[TwinPoint]) -> Result<(), AppError> {
    write_table(
        path,
        CSV_HEADER,
        points.iter().map(|p| {
            format!(
                "{},{},{},{:.3},{:.4},{:.5},{:.5},{:.5},{:.5},{:.3},{},{}",
                p.label,
                p.triangles,
                p.gpu_mask_twin_ms
                    .map_or(String::new(), |v| format!("{v:.4}")),
                p.frame_ms_median,
                p.frame_cost_ratio,
                p.iou_mean,
                p.leak_pct_mean,
                p.leak_pct_max,
                p.overmask_pct_mean,
                p.psnr_db_mean,
                p.dilate_for_1pct.map_or(String::new(), |d| d.to_string()),
                p.pareto
            )
        }),
    )
}

const CHART_SIZE: (u32, u32) = (1400, 620);

struct TwinChart<'a> {
    points: &'a [TwinPoint],
    title: &'a str,
}

impl Chart for TwinChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(self.title, ("sans-serif", 22)).map_err(err)?;
        let (left, right) = root.split_horizontally(CHART_SIZE.0 / 2);
        let timed = self.points.iter().all(|p| p.gpu_mask_twin_ms.is_some());
        let x_desc = if timed {
            "mask twin GPU time, ms per frame"
        } else {
            "frame cost, ms (no GPU timestamps)"
        };
        panel(
            &left,
            self.points,
            x_desc,
            "leak without dilation, % of robot pixels",
            |p| p.leak_pct_mean,
        )?;
        panel(
            &right,
            self.points,
            x_desc,
            "dilation for leak <= 1 %, px",
            |p| p.dilate_for_1pct.map_or(f64::NAN, f64::from),
        )?;
        root.present().map_err(err)
    }
}

fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    points: &[TwinPoint],
    x_desc: &str,
    y_desc: &str,
    y: impl Fn(&TwinPoint) -> f64,
) -> Result<(), AppError>
where
    DB::ErrorType: 'static,
{
    let err = drawing_error::<DB::ErrorType>;
    let x = TwinPoint::cost_ms;
    let finite: Vec<&TwinPoint> = points
        .iter()
        .filter(|p| x(p).is_finite() && y(p).is_finite())
        .collect();
    // Room on the right for the labels, which are written right of their points.
    let (x_lo, x_hi) = padded(finite.iter().map(|p| x(p)));
    let mut chart = axes(
        area,
        (x_lo, x_hi + 0.2 * (x_hi - x_lo)),
        padded(finite.iter().map(|p| y(p))),
        x_desc,
        y_desc,
    )?;
    let cost: Vec<f64> = finite.iter().map(|p| x(p)).collect();
    let bad: Vec<f64> = finite.iter().map(|p| y(p)).collect();
    let on_front: Vec<(f64, f64)> = finite
        .iter()
        .zip(pareto_front(&cost, &bad))
        .filter(|(_, on)| *on)
        .map(|(p, _)| (x(p), y(p)))
        .collect();
    front_line(&mut chart, on_front)?;
    let blue = RGBColor(30, 90, 200);
    chart
        .draw_series(
            finite
                .iter()
                .map(|p| Circle::new((x(p), y(p)), 6, blue.filled())),
        )
        .map_err(err)?
        .label("mask twin")
        .legend(move |(x, y)| Circle::new((x + 9, y), 5, blue.filled()));
    point_labels(
        &mut chart,
        finite
            .iter()
            .map(|p| ((x(p), y(p)), format!("{} ({} tri)", p.label, p.triangles))),
    )?;
    legend(&mut chart, SeriesLabelPosition::UpperRight)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variants_parse_and_bad_ones_name_the_flag() {
        assert_eq!(TwinVariant::parse("visual").unwrap().label, "visual");
        let c = TwinVariant::parse("collision").unwrap();
        assert_eq!(c.spec.geometry, GeometryKind::Collision);
        let k = TwinVariant::parse("keep:0.1").unwrap();
        assert_eq!((k.label.as_str(), k.spec.keep_triangles), ("keep 10%", 0.1));
        assert_eq!(
            TwinVariant::parse("visual").unwrap().spec.keep_triangles,
            1.0
        );
        let u = TwinVariant::parse("urdf:assets/robots/sawyer_lite/sawyer_lite.urdf").unwrap();
        assert_eq!(u.label, "sawyer_lite");
        for bad in ["keep:0", "keep:2", "keep:x", "sideways"] {
            let e = TwinVariant::parse(bad).unwrap_err().to_string();
            assert!(e.contains("--variants") && e.contains(bad), "{e}");
        }
    }

    #[test]
    fn the_table_and_chart_are_written() {
        let dir = std::env::temp_dir().join(format!("avatarm_twin_chart_{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let point = |label: &str, tri: usize, ms: f64, leak: f64, d: Option<u32>| TwinPoint {
            label: label.into(),
            triangles: tri,
            gpu_mask_twin_ms: Some(ms),
            frame_ms_median: 10.0 * ms,
            frame_cost_ratio: 1.0,
            iou_mean: 0.99,
            leak_pct_mean: leak,
            leak_pct_max: leak,
            overmask_pct_mean: 0.2,
            psnr_db_mean: 40.0,
            dilate_for_1pct: d,
            pareto: false,
        };
        let points = [
            point("visual", 240_000, 70.0, 0.01, Some(0)),
            point("keep 10%", 24_000, 12.0, 0.8, Some(0)),
            point("collision", 600, 3.0, 9.0, None),
        ];
        let chart = TwinChart {
            points: &points,
            title: "test",
        };
        let (svg, png) = (dir.join("t.svg"), dir.join("t.png"));
        save_chart(&chart, CHART_SIZE, &svg, &png).expect("chart");
        let text = std::fs::read_to_string(&svg).expect("svg");
        assert!(
            text.contains("Pareto front") && text.contains("keep 10%"),
            "{text}"
        );
        let csv = dir.join("t.csv");
        write_csv(&csv, &points).expect("csv");
        let table = std::fs::read_to_string(&csv).expect("csv");
        assert_eq!(table.lines().count(), 4);
        assert!(table.lines().all(|l| l.split(',').count() == 12), "{table}");
        // Not reached within the largest dilation: an empty cell.
        assert!(
            table.lines().nth(3).is_some_and(|l| l.contains(",,")),
            "{table}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
