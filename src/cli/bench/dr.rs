//! `avatarm bench dr`: the erase's settings swept, frame cost against leak and PSNR.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::bench::dr::{self as bench_dr, DrSweep};
use crate::cli::args::{default_scene, packages};
use crate::cli::overrides::on_off;

/// The arguments of `avatarm bench dr`.
#[derive(Args, Debug)]
pub struct DrArgs {
    /// The scene file.
    scene: Option<PathBuf>,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/bench_dr")]
    out: PathBuf,
    /// Mask resolution scales.
    #[arg(long, value_delimiter = ',', default_values_t = [1.0, 0.5, 0.25])]
    scales: Vec<f64>,
    /// Dilations (px).
    #[arg(long, value_delimiter = ',', default_values_t = [0, 4])]
    dilate: Vec<u32>,
    /// Feathering widths (px).
    #[arg(long, value_delimiter = ',', default_values_t = [0, 2])]
    feather: Vec<u32>,
    /// Latency compensation settings (off, on).
    #[arg(long, value_delimiter = ',', value_parser = on_off, default_values_t = [false, true])]
    latency: Vec<bool>,
    /// Simulated seconds replayed per setting.
    #[arg(long, value_name = "S", default_value_t = 1.5)]
    duration: f64,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
}

impl DrArgs {
    /// Runs `avatarm bench dr`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            scene,
            out,
            scales,
            dilate,
            feather,
            latency,
            duration,
            package_path,
        } = self;
        let path = scene.unwrap_or_else(default_scene);
        let scene = Scene::load(&path, &packages(package_path))?;
        let sweep = DrSweep {
            scales,
            dilate,
            feather,
            latency,
            duration_s: duration,
            progress: true,
        };
        let outputs = bench_dr::run_dr(&scene, &sweep, &out)?;
        let base = &outputs.points[outputs.baseline];
        println!(
            "{:<22} {:>9} {:>7} {:>12} {:>8} {:>8} {:>8}  front (frame cost / erase GPU time)",
            "setting", "frame ms", "ratio", "erase GPU ms", "leak %", "over %", "PSNR dB"
        );
        for p in &outputs.points {
            let front = |leak: bool, psnr: bool| match (leak, psnr) {
                (true, true) => "leak, PSNR",
                (true, false) => "leak",
                (false, true) => "PSNR",
                (false, false) => "-",
            };
            let front = format!(
                "{} / {}",
                front(p.pareto_leak, p.pareto_psnr),
                front(p.pareto_leak_gpu, p.pareto_psnr_gpu)
            );
            let erase_gpu = match (p.gpu_mask_ms, p.gpu_composite_ms) {
                (Some(m), Some(c)) => format!("{:.1}", m + c),
                _ => "-".into(),
            };
            println!(
                "{:<22} {:>9.1} {:>7.3} {:>12} {:>8.3} {:>8.2} {:>8.2}  {front}",
                p.label,
                p.frame_ms_median,
                p.frame_cost_ratio,
                erase_gpu,
                p.leak_pct_mean,
                p.overmask_pct_mean,
                p.psnr_db_mean
            );
        }
        println!(
            "ratios against '{}' ({:.1} ms) of the same run; wrote {}, {}, {}",
            base.label,
            base.frame_ms_median,
            outputs.csv.display(),
            outputs.svg.display(),
            outputs.png.display()
        );
        Ok(())
    }
}
