//! `avatarm bench control`: the teleoperation loop swept, object RMSE against rate and cost.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::bench::control::{self as bench_control, ControlSweep};
use crate::cli::args::{packages, pouring_scene};

/// The arguments of `avatarm bench control`.
#[derive(Args, Debug)]
pub struct ControlArgs {
    /// The scene file (needs a [task]).
    scene: Option<PathBuf>,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/bench_control")]
    out: PathBuf,
    /// Control (and physics) rates, Hz.
    #[arg(long, value_delimiter = ',', default_values_t = [50.0, 100.0, 200.0])]
    rates: Vec<f64>,
    /// Simulated command latencies, ms.
    #[arg(long = "latency-ms", value_delimiter = ',', default_values_t = [0.0, 20.0, 50.0])]
    latency_ms: Vec<f64>,
    /// TCP speed caps, m/s.
    #[arg(long, value_delimiter = ',', default_values_t = [0.1, 0.25, 0.5])]
    caps: Vec<f64>,
    /// Trials per setting and mode.
    #[arg(long, value_name = "N", default_value_t = 3)]
    trials: u32,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
}

impl ControlArgs {
    /// Runs `avatarm bench control`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            scene,
            out,
            rates,
            latency_ms,
            caps,
            trials,
            package_path,
        } = self;
        let path = scene.unwrap_or_else(pouring_scene);
        let scene = Scene::load(&path, &packages(package_path))?;
        let sweep = ControlSweep {
            rates_hz: rates,
            latencies_ms: latency_ms,
            caps,
            trials,
            progress: true,
        };
        let outputs = bench_control::run_control(&scene, &sweep, &out)?;
        let base = &outputs.points[outputs.baseline];
        println!(
            "{:<22} {:<11} {:>8} {:>7} {:>7} {:>7} {:>7} {:>8} {:>7} {:>7}  front",
            "setting",
            "mode",
            "pos mm",
            "std",
            "roll",
            "pitch",
            "yaw",
            "ms/sim s",
            "ratio",
            "tick us"
        );
        for p in &outputs.points {
            println!(
                "{:<22} {:<11} {:>8.2} {:>7.2} {:>7.2} {:>7.2} {:>7.2} {:>8.1} {:>7.3} {:>7.1}  {}",
                p.label,
                p.mode.name(),
                p.pos_rmse_mm,
                p.pos_rmse_mm_std,
                p.roll_rmse_deg,
                p.pitch_rmse_deg,
                p.yaw_rmse_deg,
                p.wall_ms_per_sim_s,
                p.cost_ratio,
                p.tick_us,
                if p.pareto { "*" } else { "" }
            );
        }
        println!(
            "ratios against '{} {}' ({:.1} ms per simulated s) of the same run; wrote {}, {}, {}",
            base.label,
            base.mode.name(),
            base.wall_ms_per_sim_s,
            outputs.csv.display(),
            outputs.svg.display(),
            outputs.png.display()
        );
        Ok(())
    }
}
