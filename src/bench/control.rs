//! `avatarm bench control`: the teleoperation loop's cost against its accuracy on the pouring
//! task. Each setting of the sweep (control rate × simulated command latency × TCP speed cap,
//! for each mapping mode) runs the scene's `[task]` trials headless; the table goes to CSV and
//! the chart (RMSE against the control rate, and against the loop's wall cost with the Pareto
//! front marked) to SVG and PNG.

use std::path::{Path, PathBuf};

use avatarm_core::teleop::mapping::MappingMode;
use avatarm_mapping::pouring::{PouringTask, run_trials};
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;

use avatarm_scene::Scene;

use super::chart::{
    Chart, axes, drawing_error, legend, padded, pareto_front, register_font, save_chart,
    write_table,
};
use crate::AppError;

/// What `bench control` sweeps; every combination is one setting, run in every mode.
#[derive(Debug, Clone)]
pub struct ControlSweep {
    /// Control (and physics) rates (Hz).
    pub rates_hz: Vec<f64>,
    /// Simulated command latencies (ms); the joint-state latency stays the scene's.
    pub latencies_ms: Vec<f64>,
    /// TCP speed caps (m/s).
    pub caps: Vec<f64>,
    /// Trials per setting and mode (seeds as the task's).
    pub trials: u32,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for ControlSweep {
    fn default() -> Self {
        Self {
            rates_hz: vec![50.0, 100.0, 200.0],
            latencies_ms: vec![0.0, 20.0, 50.0],
            caps: vec![0.1, 0.25, 0.5],
            trials: 3,
            progress: false,
        }
    }
}

/// One setting in one mode, over its trials.
#[derive(Debug, Clone, Serialize)]
pub struct ControlPoint {
    /// Short name of the setting.
    pub label: String,
    /// Mapping mode.
    pub mode: MappingMode,
    /// Control rate (Hz).
    pub rate_hz: f64,
    /// Simulated command latency (ms).
    pub latency_ms: f64,
    /// TCP speed cap (m/s).
    pub cap_m_s: f64,
    /// Trials run.
    pub trials: u32,
    /// Trials in which the gripper closed.
    pub grasped: u32,
    /// Position RMSE, mean and sample std over trials (mm).
    pub pos_rmse_mm: f64,
    /// See `pos_rmse_mm`.
    pub pos_rmse_mm_std: f64,
    /// Roll, pitch and yaw RMSE, means over trials (degrees).
    pub roll_rmse_deg: f64,
    /// See `roll_rmse_deg`.
    pub pitch_rmse_deg: f64,
    /// See `roll_rmse_deg`.
    pub yaw_rmse_deg: f64,
    /// Largest commanded TCP speed (m/s).
    pub max_tcp_speed: f64,
    /// Wall time of the whole loop (hand, physics, mapping, robot) per simulated second, ms.
    pub wall_ms_per_sim_s: f64,
    /// `wall_ms_per_sim_s` over that of the baseline of the same run.
    pub cost_ratio: f64,
    /// Mean wall time of one control tick (mapping, limiter), µs.
    pub tick_us: f64,
    /// On the cost/position-RMSE Pareto front.
    pub pareto: bool,
}

/// What the sweep wrote.
#[derive(Debug, Clone)]
pub struct ControlOutputs {
    /// The points, in sweep order.
    pub points: Vec<ControlPoint>,
    /// Index of the baseline point: the scene's own rate, latency and cap in closed loop when
    /// swept, else the first.
    pub baseline: usize,
    /// The raw table.
    pub csv: PathBuf,
    /// The chart.
    pub svg: PathBuf,
    /// The chart as an image.
    pub png: PathBuf,
}

/// Runs the sweep on the scene's `[task]`, writing into `out`.
pub fn run_control(
    scene: &Scene,
    sweep: &ControlSweep,
    out: &Path,
) -> Result<ControlOutputs, AppError> {
    let (Some(task), Some(setup)) = (&scene.file.task, &scene.trial) else {
        return Err(AppError::flag(
            "bench control",
            format!(
                "scene '{}' has no [task]: bench control runs the pouring task (try \
                 assets/scenes/pouring.toml)",
                scene.file.name
            ),
        ));
    };
    let check = |name: &str, values: &[f64], ok: fn(f64) -> bool| {
        let flag = format!("--{name}");
        if values.is_empty() {
            return Err(AppError::flag(flag, "the sweep needs at least one value"));
        }
        match values.iter().find(|v| !ok(**v)) {
            Some(v) => Err(AppError::flag(flag, format!("{v} is out of range"))),
            None => Ok(()),
        }
    };
    check("rates", &sweep.rates_hz, |v| v.is_finite() && v >= 10.0)?;
    check("latency-ms", &sweep.latencies_ms, |v| {
        v.is_finite() && (0.0..=1000.0).contains(&v)
    })?;
    check("caps", &sweep.caps, |v| v.is_finite() && v > 0.0)?;
    if sweep.trials == 0 {
        return Err(AppError::flag("--trials", "at least 1"));
    }
    register_font()?;
    std::fs::create_dir_all(out).map_err(|source| AppError::Io {
        path: out.to_owned(),
        action: "create",
        source,
    })?;
    let settings: Vec<(f64, f64, f64)> = sweep
        .rates_hz
        .iter()
        .flat_map(|&r| {
            sweep
                .latencies_ms
                .iter()
                .flat_map(move |&l| sweep.caps.iter().map(move |&c| (r, l, c)))
        })
        .collect();
    let bar = crate::progress::bar(
        settings.len() as u64,
        format!("bench control {}", scene.file.name),
        sweep.progress,
    );
    let mut points = Vec::new();
    for (rate, latency_ms, cap) in settings {
        let label = format!("{rate:.0}Hz {latency_ms:.0}ms {cap}m/s");
        bar.set_message(label.clone());
        let run_task = PouringTask {
            trials: sweep.trials,
            max_tcp_speed: cap,
            ..task.clone()
        };
        let mut run_setup = setup.clone();
        run_setup.control_rate_hz = rate;
        run_setup.sim.command_latency_s = latency_ms / 1000.0;
        let modes =
            run_trials(&run_task, &run_setup, |_, _| {}).map_err(|e| AppError::BenchSetting {
                label: label.clone(),
                source: Box::new(e.into()),
            })?;
        for (mode, summary) in modes {
            let n = summary.trials.len().max(1) as f64;
            let wall: f64 = summary.trials.iter().map(|t| t.wall_s).sum();
            points.push(ControlPoint {
                label: label.clone(),
                mode,
                rate_hz: rate,
                latency_ms,
                cap_m_s: cap,
                trials: summary.trials.len() as u32,
                grasped: summary.grasped,
                pos_rmse_mm: summary.pos_rmse_m.mean * 1000.0,
                pos_rmse_mm_std: summary.pos_rmse_m.std * 1000.0,
                roll_rmse_deg: summary.roll_rmse_deg.mean,
                pitch_rmse_deg: summary.pitch_rmse_deg.mean,
                yaw_rmse_deg: summary.yaw_rmse_deg.mean,
                max_tcp_speed: summary.max_tcp_speed,
                wall_ms_per_sim_s: wall / (n * run_task.duration_s) * 1000.0,
                cost_ratio: 1.0,
                tick_us: summary.trials.iter().map(|t| t.tick_us_mean).sum::<f64>() / n,
                pareto: false,
            });
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let baseline = points
        .iter()
        .position(|p| {
            p.mode == MappingMode::ClosedLoop
                && p.rate_hz == setup.control_rate_hz
                && (p.latency_ms - setup.sim.command_latency_s * 1000.0).abs() < 1e-9
                && p.cap_m_s == task.max_tcp_speed
        })
        .unwrap_or(0);
    let base = points[baseline].wall_ms_per_sim_s;
    for p in &mut points {
        p.cost_ratio = p.wall_ms_per_sim_s / base;
    }
    let cost: Vec<f64> = points.iter().map(|p| p.wall_ms_per_sim_s).collect();
    let bad: Vec<f64> = points.iter().map(|p| p.pos_rmse_mm).collect();
    for (p, on) in points.iter_mut().zip(pareto_front(&cost, &bad)) {
        p.pareto = on;
    }
    let csv = out.join("control_speed_accuracy.csv");
    write_csv(&csv, &points)?;
    let svg = out.join("control_speed_accuracy.svg");
    let png = out.join("control_speed_accuracy.png");
    let title = format!(
        "Teleoperation loop: cost against accuracy ({}, {} trials of {} s per point)",
        scene.file.name, sweep.trials, task.duration_s
    );
    let chart = ControlChart {
        points: &points,
        title: &title,
        cap: task.max_tcp_speed,
    };
    save_chart(&chart, CHART_SIZE, &svg, &png)?;
    Ok(ControlOutputs {
        points,
        baseline,
        csv,
        svg,
        png,
    })
}

const CSV_HEADER: &str = "label,mode,rate_hz,latency_ms,cap_m_s,trials,grasped,pos_rmse_mm,\
pos_rmse_mm_std,roll_rmse_deg,pitch_rmse_deg,yaw_rmse_deg,max_tcp_speed,wall_ms_per_sim_s,\
cost_ratio,tick_us,pareto";

fn write_csv(path: &Path, points: &[ControlPoint]) -> Result<(), AppError> {
    write_table(
        path,
        CSV_HEADER,
        points.iter().map(|p| {
            format!(
                "{},{},{},{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.4},{:.2},{:.4},{:.2},{}",
                p.label,
                p.mode.name(),
                p.rate_hz,
                p.latency_ms,
                p.cap_m_s,
                p.trials,
                p.grasped,
                p.pos_rmse_mm,
                p.pos_rmse_mm_std,
                p.roll_rmse_deg,
                p.pitch_rmse_deg,
                p.yaw_rmse_deg,
                p.max_tcp_speed,
                p.wall_ms_per_sim_s,
                p.cost_ratio,
                p.tick_us,
                p.pareto
            )
        }),
    )
}

const CHART_SIZE: (u32, u32) = (1400, 620);

struct ControlChart<'a> {
    points: &'a [ControlPoint],
    title: &'a str,
    /// The task's own cap: the left panel shows the points at this cap.
    cap: f64,
}

const MODE_COLOURS: [(MappingMode, RGBColor); 2] = [
    (MappingMode::Paper, RGBColor(230, 130, 20)),
    (MappingMode::ClosedLoop, RGBColor(30, 90, 200)),
];

impl Chart for ControlChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(self.title, ("sans-serif", 22)).map_err(err)?;
        let (left, right) = root.split_horizontally(CHART_SIZE.0 / 2);
        self.by_rate(&left)?;
        self.by_cost(&right)?;
        root.present().map_err(err)
    }
}

impl ControlChart<'_> {
    fn finite(&self) -> Vec<&ControlPoint> {
        self.points
            .iter()
            .filter(|p| p.pos_rmse_mm.is_finite() && p.wall_ms_per_sim_s.is_finite())
            .collect()
    }

    /// Position RMSE against the control rate at the task's cap: one line per mode and latency.
    fn by_rate<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        let mut at_cap: Vec<&ControlPoint> = self
            .finite()
            .into_iter()
            .filter(|p| p.cap_m_s == self.cap)
            .collect();
        if at_cap.is_empty() {
            at_cap = self.finite();
        }
        let (y0, y1) = padded(at_cap.iter().map(|p| p.pos_rmse_mm));
        let mut chart = axes(
            area,
            padded(at_cap.iter().map(|p| p.rate_hz)),
            (y0.min(0.0), y1),
            &format!("control rate, Hz (cap {} m/s)", self.cap),
            "object position RMSE, mm (lower is better)",
        )?;
        let mut latencies: Vec<f64> = at_cap.iter().map(|p| p.latency_ms).collect();
        latencies.sort_by(f64::total_cmp);
        latencies.dedup();
        for (mode, colour) in MODE_COLOURS {
            for (i, &lat) in latencies.iter().enumerate() {
                let mut line: Vec<(f64, f64)> = at_cap
                    .iter()
                    .filter(|p| p.mode == mode && p.latency_ms == lat)
                    .map(|p| (p.rate_hz, p.pos_rmse_mm))
                    .collect();
                if line.is_empty() {
                    continue;
                }
                line.sort_by(|a, b| a.0.total_cmp(&b.0));
                let width = 1 + i as u32;
                let style = colour.stroke_width(width);
                chart
                    .draw_series(LineSeries::new(line.clone(), style))
                    .map_err(err)?
                    .label(format!("{} {lat:.0} ms latency", mode.name()))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
                chart
                    .draw_series(
                        line.iter()
                            .map(|&(x, y)| Circle::new((x, y), 4, colour.filled())),
                    )
                    .map_err(err)?;
            }
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    }

    /// Position RMSE against the loop's wall cost, every point, Pareto front marked.
    fn by_cost<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        let finite = self.finite();
        let (y0, y1) = padded(finite.iter().map(|p| p.pos_rmse_mm));
        let mut chart = axes(
            area,
            padded(finite.iter().map(|p| p.wall_ms_per_sim_s)),
            (y0.min(0.0), y1),
            "loop cost, wall ms per simulated s (hand, physics, mapping)",
            "object position RMSE, mm (lower is better)",
        )?;
        let mut front: Vec<&ControlPoint> = finite.iter().copied().filter(|p| p.pareto).collect();
        front.sort_by(|a, b| a.wall_ms_per_sim_s.total_cmp(&b.wall_ms_per_sim_s));
        chart
            .draw_series(LineSeries::new(
                front.iter().map(|p| (p.wall_ms_per_sim_s, p.pos_rmse_mm)),
                RED.stroke_width(2),
            ))
            .map_err(err)?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RED.stroke_width(2)));
        for (mode, colour) in MODE_COLOURS {
            chart
                .draw_series(
                    finite.iter().filter(|p| p.mode == mode).map(|p| {
                        Circle::new((p.wall_ms_per_sim_s, p.pos_rmse_mm), 5, colour.filled())
                    }),
                )
                .map_err(err)?
                .label(mode.name())
                .legend(move |(x, y)| Circle::new((x + 9, y), 5, colour.filled()));
        }
        chart
            .draw_series(front.iter().map(|p| {
                EmptyElement::at((p.wall_ms_per_sim_s, p.pos_rmse_mm))
                    + Circle::new((0, 0), 9, RED.stroke_width(2))
                    + Text::new(
                        p.label.clone(),
                        (10, -18),
                        ("sans-serif", 12).into_font().color(&BLACK),
                    )
            }))
            .map_err(err)?;
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use avatarm_core::robot::PackagePath;

    #[test]
    fn a_small_sweep_writes_the_table_and_chart_and_marks_the_front() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/pouring.toml");
        let mut scene = Scene::load(&path, &PackagePath::default()).expect("scene");
        if let Some(task) = scene.file.task.as_mut() {
            task.duration_s = 4.0;
        }
        let out = std::env::temp_dir().join(format!("avatarm_bench_ctl_{}", std::process::id()));
        let sweep = ControlSweep {
            rates_hz: vec![50.0, 100.0],
            latencies_ms: vec![20.0],
            caps: vec![0.25],
            trials: 1,
            progress: false,
        };
        let o = run_control(&scene, &sweep, &out).expect("sweep");
        // 2 rates x 1 x 1, both modes.
        assert_eq!(o.points.len(), 4);
        let base = &o.points[o.baseline];
        assert_eq!((base.rate_hz, base.mode), (100.0, MappingMode::ClosedLoop));
        assert!(o.points.iter().any(|p| p.pareto));
        for p in &o.points {
            assert!(
                p.pos_rmse_mm.is_finite() && p.wall_ms_per_sim_s > 0.0,
                "{p:?}"
            );
            assert!(p.max_tcp_speed <= 0.25 + 1e-9, "{p:?}");
        }
        let table = std::fs::read_to_string(&o.csv).expect("csv");
        assert_eq!(table.lines().count(), 5);
        assert_eq!(table.lines().next().map(|l| l.split(',').count()), Some(17));
        assert!(
            std::fs::read_to_string(&o.svg)
                .expect("svg")
                .contains("Pareto front")
        );
        let img = image::open(&o.png).expect("png").to_rgb8();
        assert_eq!(img.dimensions(), CHART_SIZE);
        assert!(img.pixels().any(|p| p.0 == [255, 0, 0]));
        // A scene without a task, and an empty axis, are refused with the reason.
        let plain = Scene::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/default.toml"),
            &PackagePath::default(),
        )
        .expect("default scene");
        let e = run_control(&plain, &sweep, &out).expect_err("no task");
        assert!(e.to_string().contains("[task]"), "{e}");
        let empty = ControlSweep {
            caps: vec![],
            ..sweep
        };
        let e = run_control(&scene, &empty, &out).expect_err("empty");
        assert!(e.to_string().contains("--caps"), "{e}");
        let _ = std::fs::remove_dir_all(&out);
    }
}
