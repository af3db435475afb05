//! `avatarm bench network`: the pouring task across two sites under delay and loss.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::cli::args::{mapping_mode, packages, pouring_scene};

/// The arguments of `avatarm bench network`.
#[derive(Args, Debug)]
pub struct NetworkArgs {
    /// The scene (default: the pouring scene).
    scene: Option<PathBuf>,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/bench_network")]
    out: PathBuf,
    /// One-way delays (ms).
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 25.0, 50.0, 100.0, 200.0])]
    delays: Vec<f64>,
    /// Datagram loss (%): 0 runs over TCP, more over UDP.
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 1.0, 5.0])]
    losses: Vec<f64>,
    /// Mapping modes (paper, closed_loop).
    #[arg(long, value_delimiter = ',', value_parser = mapping_mode, default_values = ["paper", "closed_loop"])]
    modes: Vec<avatarm_core::teleop::mapping::MappingMode>,
    /// Trials per point (the task's seeded hands).
    #[arg(long, value_name = "N", default_value_t = 10)]
    trials: u32,
    /// The robot site's watchdog timeout (s).
    #[arg(long = "target-timeout", value_name = "S", default_value_t = 0.5)]
    target_timeout: f64,
    /// Folder searched for package://NAME/... URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
}

impl NetworkArgs {
    /// Runs `avatarm bench network`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            scene,
            out,
            delays,
            losses,
            modes,
            trials,
            target_timeout,
            package_path,
        } = self;
        crate::log::init_log_quiet();
        let path = scene.unwrap_or_else(pouring_scene);
        let scene = Scene::load(&path, &packages(package_path))?;
        let sweep = crate::bench::network::NetworkSweep {
            delays_ms: delays,
            losses_pct: losses,
            modes,
            trials,
            target_timeout_s: target_timeout,
            progress: true,
        };
        let outputs = crate::bench::network::run_network(&scene, &sweep, &out)?;
        println!(
            "{:<11} {:>8} {:>6} {:>9} {:>7} {:>7} {:>7} {:>6} {:>8} {:>7}",
            "mode",
            "delay ms",
            "loss %",
            "pos mm",
            "std",
            "roll",
            "yaw",
            "stops",
            "age ms",
            "failed"
        );
        let mut seen = Vec::new();
        for t in &outputs.trials {
            let key = (t.mode, t.delay_ms.to_bits(), t.loss_pct.to_bits());
            if seen.contains(&key) {
                continue;
            }
            seen.push(key);
            let cell: Vec<_> = outputs
                .trials
                .iter()
                .filter(|u| (u.mode, u.delay_ms.to_bits(), u.loss_pct.to_bits()) == key)
                .collect();
            let (pos, std) = crate::bench::network::mean_std(cell.iter().map(|u| u.pos_rmse_mm));
            let (roll, _) = crate::bench::network::mean_std(cell.iter().map(|u| u.roll_rmse_deg));
            let (yaw, _) = crate::bench::network::mean_std(cell.iter().map(|u| u.yaw_rmse_deg));
            let stops: usize = cell.iter().map(|u| u.stops_after_grasp).sum();
            let (age, _) = crate::bench::network::mean_std(cell.iter().map(|u| u.target_age_ms));
            let failed = cell
                .iter()
                .filter(|u| u.failed.is_some() || !u.grasped)
                .count();
            println!(
                "{:<11} {:>8} {:>6} {:>9.2} {:>7.2} {:>7.2} {:>7.2} {:>6} {:>8.1} {:>7}",
                t.mode.name(),
                t.delay_ms,
                t.loss_pct,
                pos,
                std,
                roll,
                yaw,
                stops,
                age,
                failed
            );
        }
        super::wrote(&[&outputs.csv, &outputs.svg, &outputs.png]);
        Ok(())
    }
}
