//! `avatarm bench dr`: the erase pipeline's cost against its accuracy. Each setting of the
//! sweep (mask resolution scale × dilation × feathering × latency compensation) is a headless
//! replay of the scene scored against the simulated room's ground truth; the table goes to CSV
//! and the chart (cost against leak and against PSNR, Pareto fronts marked) to SVG and PNG.

use std::path::{Path, PathBuf};

use avatarm_scene::Scene;
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

/// What `bench dr` sweeps; every combination is one point.
#[derive(Debug, Clone)]
pub struct DrSweep {
    /// Mask render resolution scales.
    pub scales: Vec<f64>,
    /// Dilations (px).
    pub dilate: Vec<u32>,
    /// Feathering widths (px).
    pub feather: Vec<u32>,
    /// Latency compensation off and/or on.
    pub latency: Vec<bool>,
    /// Simulated seconds replayed per point.
    pub duration_s: f64,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for DrSweep {
    fn default() -> Self {
        Self {
            scales: vec![1.0, 0.5, 0.25],
            dilate: vec![0, 4],
            feather: vec![0, 2],
            latency: vec![false, true],
            duration_s: 1.5,
            progress: false,
        }
    }
}

/// One setting and what it measured.
#[derive(Debug, Clone, Serialize)]
pub struct DrPoint {
    /// Short name of the setting.
    pub label: String,
    /// Mask resolution scale.
    pub resolution_scale: f64,
    /// Dilation (px).
    pub dilate_px: u32,
    /// Feathering (px).
    pub feather_px: u32,
    /// Latency compensation.
    pub latency_compensation: bool,
    /// Median wall time of one app update (all cameras and passes), ms.
    pub frame_ms_median: f64,
    /// 95th percentile of the same, ms.
    pub frame_ms_p95: f64,
    /// `frame_ms_median` over that of the baseline setting of the same run.
    pub frame_cost_ratio: f64,
    /// Median GPU time of the mask twin + dilation passes per camera frame, ms (`None` when
    /// the device has no timestamp queries).
    pub gpu_mask_ms: Option<f64>,
    /// Median GPU time of the feathering and composite passes, ms.
    pub gpu_composite_ms: Option<f64>,
    /// Median CPU reference threshold + dilation time, ms.
    pub cpu_mask_ms: f64,
    /// Median CPU reference feather + composite time, ms.
    pub cpu_composite_ms: f64,
    /// Mean IoU of the mask with the true silhouette.
    pub iou_mean: f64,
    /// Mean leak, % of robot pixels.
    pub leak_pct_mean: f64,
    /// Worst leak, % of robot pixels.
    pub leak_pct_max: f64,
    /// Mean over-masking, % of robot pixels.
    pub overmask_pct_mean: f64,
    /// Mean PSNR in the true robot region, dB.
    pub psnr_db_mean: f64,
    /// On the cost/leak Pareto front.
    pub pareto_leak: bool,
    /// On the cost/PSNR Pareto front.
    pub pareto_psnr: bool,
    /// On the Pareto front of erase GPU time against leak.
    pub pareto_leak_gpu: bool,
    /// On the Pareto front of erase GPU time against PSNR.
    pub pareto_psnr_gpu: bool,
}

impl DrPoint {
    /// GPU time of the whole erase per camera frame (mask twin, dilation, feathering, composite),
    /// ms; NaN without GPU times.
    pub fn erase_gpu_ms(&self) -> f64 {
        match (self.gpu_mask_ms, self.gpu_composite_ms) {
            (Some(m), Some(c)) => m + c,
            _ => f64::NAN,
        }
    }
}

/// What the sweep wrote.
#[derive(Debug, Clone)]
pub struct DrOutputs {
    /// The points, in sweep order.
    pub points: Vec<DrPoint>,
    /// Index of the baseline point (full resolution, no dilation, no feathering, no
    /// compensation: the paper's setting) when swept, else the first.
    pub baseline: usize,
    /// The raw table.
    pub csv: PathBuf,
    /// The chart.
    pub svg: PathBuf,
    /// The chart as an image.
    pub png: PathBuf,
}

/// Runs the sweep on `scene`, writing into `out` (one replay folder per point under `runs/`).
pub fn run_dr(scene: &Scene, sweep: &DrSweep, out: &Path) -> Result<DrOutputs, AppError> {
    if !(sweep.duration_s.is_finite() && sweep.duration_s > 0.0) {
        return Err(AppError::flag(
            "--duration",
            format!("{} must be > 0", sweep.duration_s),
        ));
    }
    let settings: Vec<(f64, u32, u32, bool)> = sweep
        .scales
        .iter()
        .flat_map(|&s| {
            sweep.dilate.iter().flat_map(move |&d| {
                sweep
                    .feather
                    .iter()
                    .flat_map(move |&f| sweep.latency.iter().map(move |&l| (s, d, f, l)))
            })
        })
        .collect();
    if settings.is_empty() {
        return Err(AppError::flag(
            "bench dr",
            "the sweep is empty: every axis needs at least one value",
        ));
    }
    // Fail on a bad value before minutes of replays.
    for &(s, d, f, l) in &settings {
        let mut e = scene.file.erase;
        (
            e.resolution_scale,
            e.dilate_px,
            e.feather_px,
            e.latency_compensation,
        ) = (s, d, f, l);
        e.validate("bench dr")?;
    }
    // Fonts before the replays, for the same reason.
    register_font()?;
    std::fs::create_dir_all(out).map_err(|source| AppError::Io {
        path: out.to_owned(),
        action: "create",
        source,
    })?;
    let bar = crate::progress::bar(
        settings.len() as u64,
        format!("bench dr {}", scene.file.name),
        sweep.progress,
    );
    let mut points = Vec::with_capacity(settings.len());
    for (s, d, f, l) in settings {
        let label = format!("x{s} d{d} f{f} {}", if l { "LC" } else { "noLC" });
        bar.set_message(label.clone());
        let mut run = scene.clone();
        run.file.duration_s = sweep.duration_s;
        // The video pipeline only: the scene's teleoperation trials are `bench control`'s.
        run.file.task = None;
        let e = &mut run.file.erase;
        (
            e.resolution_scale,
            e.dilate_px,
            e.feather_px,
            e.latency_compensation,
        ) = (s, d, f, l);
        let dir = out
            .join("runs")
            .join(label.replace(' ', "_").replace('.', "p"));
        let mut options = ReplayOptions::new(dir);
        options.frames_every = u32::MAX;
        let in_setting = |source: AppError| AppError::BenchSetting {
            label: label.clone(),
            source: Box::new(source),
        };
        let report = replay::run(&run, options).map_err(in_setting)?;
        let figures = EraseFigures::of(&report, "bench dr").map_err(in_setting)?;
        let on_gpu = report.timing_ms.source == "gpu";
        let median = |times, what| EraseFigures::median(times, what, "bench dr");
        let gpu = |times, what| on_gpu.then(|| median(times, what)).transpose();
        let cpu = &report.timing_ms.cpu_reference;
        points.push(DrPoint {
            label: label.clone(),
            resolution_scale: s,
            dilate_px: d,
            feather_px: f,
            latency_compensation: l,
            frame_ms_median: figures.frame_ms.median,
            frame_ms_p95: figures.frame_ms.p95,
            frame_cost_ratio: 1.0,
            gpu_mask_ms: gpu(report.timing_ms.mask, "timing_ms.mask").map_err(in_setting)?,
            gpu_composite_ms: gpu(report.timing_ms.composite, "timing_ms.composite")
                .map_err(in_setting)?,
            cpu_mask_ms: median(cpu.mask, "timing_ms.cpu_reference.mask").map_err(in_setting)?,
            cpu_composite_ms: median(cpu.composite, "timing_ms.cpu_reference.composite")
                .map_err(in_setting)?,
            iou_mean: figures.iou_mean,
            leak_pct_mean: figures.leak_pct_mean,
            leak_pct_max: figures.leak_pct_max,
            overmask_pct_mean: figures.overmask_pct_mean,
            psnr_db_mean: figures.psnr_db_mean,
            pareto_leak: false,
            pareto_psnr: false,
            pareto_leak_gpu: false,
            pareto_psnr_gpu: false,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    let baseline = points
        .iter()
        .position(|p| {
            p.resolution_scale == 1.0
                && p.dilate_px == 0
                && p.feather_px == 0
                && !p.latency_compensation
        })
        .unwrap_or(0);
    let base_ms = points[baseline].frame_ms_median;
    for p in &mut points {
        p.frame_cost_ratio = p.frame_ms_median / base_ms;
    }
    let cost: Vec<f64> = points.iter().map(|p| p.frame_ms_median).collect();
    let leak: Vec<f64> = points.iter().map(|p| p.leak_pct_mean).collect();
    let psnr: Vec<f64> = points.iter().map(|p| -p.psnr_db_mean).collect();
    let gpu: Vec<f64> = points.iter().map(DrPoint::erase_gpu_ms).collect();
    let (front_leak, front_psnr) = (pareto_front(&cost, &leak), pareto_front(&cost, &psnr));
    let (gpu_leak, gpu_psnr) = (pareto_front(&gpu, &leak), pareto_front(&gpu, &psnr));
    for (i, p) in points.iter_mut().enumerate() {
        p.pareto_leak = front_leak[i];
        p.pareto_psnr = front_psnr[i];
        p.pareto_leak_gpu = gpu_leak[i];
        p.pareto_psnr_gpu = gpu_psnr[i];
    }
    let csv = out.join("dr_speed_accuracy.csv");
    write_csv(&csv, &points)?;
    let svg = out.join("dr_speed_accuracy.svg");
    let png = out.join("dr_speed_accuracy.png");
    let title = format!(
        "Erase pipeline: cost against accuracy ({}, {} s per setting)",
        scene.file.name, sweep.duration_s
    );
    plot(&points, &title, &svg, &png)?;
    Ok(DrOutputs {
        points,
        baseline,
        csv,
        svg,
        png,
    })
}

const CSV_HEADER: &str = "label,resolution_scale,dilate_px,feather_px,latency_compensation,\
frame_ms_median,frame_ms_p95,frame_cost_ratio,gpu_mask_ms,gpu_composite_ms,cpu_mask_ms,\
cpu_composite_ms,iou_mean,\
leak_pct_mean,leak_pct_max,overmask_pct_mean,psnr_db_mean,pareto_leak,pareto_psnr,\
pareto_leak_gpu,pareto_psnr_gpu";

fn write_csv(path: &Path, points: &[DrPoint]) -> Result<(), AppError> {
    write_table(
        path,
        CSV_HEADER,
        points.iter().map(|p| {
            format!(
            "{},{},{},{},{},{:.3},{:.3},{:.4},{},{},{:.4},{:.4},{:.5},{:.5},{:.5},{:.5},{:.3},{},{},{},{}",
            p.label,
            p.resolution_scale,
            p.dilate_px,
            p.feather_px,
            p.latency_compensation,
            p.frame_ms_median,
            p.frame_ms_p95,
            p.frame_cost_ratio,
            p.gpu_mask_ms.map_or(String::new(), |v| format!("{v:.4}")),
            p.gpu_composite_ms.map_or(String::new(), |v| format!("{v:.4}")),
            p.cpu_mask_ms,
            p.cpu_composite_ms,
            p.iou_mean,
            p.leak_pct_mean,
            p.leak_pct_max,
            p.overmask_pct_mean,
            p.psnr_db_mean,
            p.pareto_leak,
            p.pareto_psnr,
            p.pareto_leak_gpu,
            p.pareto_psnr_gpu
        )
        }),
    )
}

const CHART_SIZE: (u32, u32) = (1400, 620);

struct DrChart<'a> {
    points: &'a [DrPoint],
    title: &'a str,
}

impl Chart for DrChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        draw(root, self.points, self.title)
    }
}

/// Draws the chart to `svg` and `png`.
pub fn plot(points: &[DrPoint], title: &str, svg: &Path, png: &Path) -> Result<(), AppError> {
    save_chart(&DrChart { points, title }, chart_size(points), svg, png)
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    points: &[DrPoint],
    title: &str,
) -> Result<(), AppError>
where
    DB::ErrorType: 'static,
{
    let err = drawing_error::<DB::ErrorType>;
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, ("sans-serif", 24)).map_err(err)?;
    let rows = root.split_evenly((chart_rows(points), 1));
    let costs = [
        Axis {
            desc: "frame cost, ms (median wall time per update)",
            x: |p| p.frame_ms_median,
            fronts: [|p| p.pareto_leak, |p| p.pareto_psnr],
        },
        Axis {
            desc: "erase GPU time, ms per camera frame (mask twin + passes)",
            x: DrPoint::erase_gpu_ms,
            fronts: [|p| p.pareto_leak_gpu, |p| p.pareto_psnr_gpu],
        },
    ];
    for (row, axis) in rows.iter().zip(&costs) {
        let (left, right) = row.split_horizontally(CHART_SIZE.0 / 2);
        panel(
            &left,
            points,
            axis,
            "leak, % of robot pixels (lower is better)",
            |p| p.leak_pct_mean,
            axis.fronts[0],
            SeriesLabelPosition::UpperRight,
        )?;
        panel(
            &right,
            points,
            axis,
            "PSNR in the robot region, dB (higher is better)",
            |p| p.psnr_db_mean,
            axis.fronts[1],
            SeriesLabelPosition::LowerRight,
        )?;
    }
    root.present().map_err(err)
}

/// Rows of the chart: frame cost, and erase GPU time when the passes were timed.
fn chart_rows(points: &[DrPoint]) -> usize {
    if points.iter().any(|p| p.erase_gpu_ms().is_finite()) {
        2
    } else {
        1
    }
}

/// The chart's size for these points.
pub fn chart_size(points: &[DrPoint]) -> (u32, u32) {
    (CHART_SIZE.0, CHART_SIZE.1 * chart_rows(points) as u32)
}

/// A row's cost axis and its points' Pareto flags (against leak, against PSNR).
struct Axis {
    desc: &'static str,
    x: fn(&DrPoint) -> f64,
    fronts: [fn(&DrPoint) -> bool; 2],
}

fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    points: &[DrPoint],
    axis: &Axis,
    y_desc: &str,
    y: impl Fn(&DrPoint) -> f64,
    front: impl Fn(&DrPoint) -> bool,
    legend_at: SeriesLabelPosition,
) -> Result<(), AppError>
where
    DB::ErrorType: 'static,
{
    let err = drawing_error::<DB::ErrorType>;
    let x = axis.x;
    let finite: Vec<&DrPoint> = points
        .iter()
        .filter(|p| x(p).is_finite() && y(p).is_finite())
        .collect();
    let mut chart = axes(
        area,
        padded(finite.iter().map(|p| x(p))),
        padded(finite.iter().map(|p| y(p))),
        axis.desc,
        y_desc,
    )?;
    let on_front: Vec<&DrPoint> = finite.iter().copied().filter(|p| front(p)).collect();
    front_line(&mut chart, on_front.iter().map(|p| (x(p), y(p))).collect())?;
    for (on, color, name) in [
        (false, RGBColor(230, 130, 20), "latency compensation off"),
        (true, RGBColor(30, 90, 200), "latency compensation on"),
    ] {
        chart
            .draw_series(
                finite
                    .iter()
                    .filter(|p| p.latency_compensation == on)
                    .map(|p| Circle::new((x(p), y(p)), 5, color.filled())),
            )
            .map_err(err)?
            .label(name)
            .legend(move |(x, y)| Circle::new((x + 9, y), 5, color.filled()));
    }
    chart
        .draw_series(
            on_front
                .iter()
                .map(|p| Circle::new((x(p), y(p)), 9, RED.stroke_width(2))),
        )
        .map_err(err)?;
    point_labels(
        &mut chart,
        on_front.iter().map(|p| ((x(p), y(p)), p.label.clone())),
    )?;
    legend(&mut chart, legend_at)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(label: &str, ms: f64, leak: f64, psnr: f64, lc: bool) -> DrPoint {
        DrPoint {
            label: label.into(),
            resolution_scale: 1.0,
            dilate_px: 0,
            feather_px: 0,
            latency_compensation: lc,
            frame_ms_median: ms,
            frame_ms_p95: ms,
            frame_cost_ratio: 1.0,
            gpu_mask_ms: Some(ms / 10.0),
            gpu_composite_ms: Some(1.0),
            cpu_mask_ms: 0.1,
            cpu_composite_ms: 1.0,
            iou_mean: 0.99,
            leak_pct_mean: leak,
            leak_pct_max: leak,
            overmask_pct_mean: 0.1,
            psnr_db_mean: psnr,
            pareto_leak: true,
            pareto_psnr: lc,
            pareto_leak_gpu: lc,
            pareto_psnr_gpu: true,
        }
    }

    #[test]
    fn chart_and_table_are_written() {
        let dir = std::env::temp_dir().join(format!("avatarm_chart_{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let points = [
            point("a", 100.0, 2.0, 30.0, false),
            point("b", 120.0, 0.5, 40.0, true),
            point("c", 90.0, f64::NAN, 20.0, true),
        ];
        let (svg, png) = (dir.join("c.svg"), dir.join("c.png"));
        plot(&points, "test chart", &svg, &png).expect("plot");
        // Without GPU times (no timestamp queries) only the frame-cost row is drawn.
        let mut untimed = points.clone();
        for p in &mut untimed {
            p.gpu_composite_ms = None;
        }
        assert_eq!(chart_size(&untimed), CHART_SIZE);
        let text = std::fs::read_to_string(&svg).expect("svg");
        assert!(
            text.contains("<svg")
                && text.contains("Pareto front")
                && text.contains("erase GPU time"),
            "{text}"
        );
        let img = image::open(&png).expect("png").to_rgb8();
        // Two rows: frame cost and erase GPU time (the test points have GPU times).
        assert_eq!(img.dimensions(), (CHART_SIZE.0, 2 * CHART_SIZE.1));
        // Not blank: the points and the front are drawn in colour.
        assert!(img.pixels().any(|p| p.0 == [255, 0, 0]));
        let csv = dir.join("t.csv");
        write_csv(&csv, &points).expect("csv");
        let table = std::fs::read_to_string(&csv).expect("csv");
        assert_eq!(table.lines().count(), 4);
        assert!(table.lines().all(|l| l.split(',').count() == 21), "{table}");
        // No GPU time (a device without timestamp queries) is an empty cell, not a number.
        write_csv(&csv, &untimed).expect("csv");
        let table = std::fs::read_to_string(&csv).expect("csv");
        assert!(
            table
                .lines()
                .nth(1)
                .is_some_and(|l| l.contains(",10.0000,,")),
            "{table}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
