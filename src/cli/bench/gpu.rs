//! `avatarm bench gpu`: the erase on the GPU, pass by pass, beside a copy of the same images.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::bench::gpu::{self as bench_gpu, GpuSweep};
use crate::cli::args::{default_scene, frame_size, packages};

/// The arguments of `avatarm bench gpu`.
#[derive(Args, Debug)]
pub struct GpuArgs {
    /// The scene file.
    scene: Option<PathBuf>,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/bench_gpu")]
    out: PathBuf,
    /// Frame sizes, WIDTHxHEIGHT.
    #[arg(long, value_delimiter = ',', value_parser = frame_size, default_values = ["640x480", "1280x720", "1920x1080"])]
    sizes: Vec<(u32, u32)>,
    /// Cameras erased per update.
    #[arg(long, value_delimiter = ',', default_values_t = [1, 2])]
    cameras: Vec<u32>,
    /// Updates timed per point (after a warm-up).
    #[arg(long, value_name = "N", default_value_t = 120)]
    frames: u32,
    /// Dilation of the mask (px).
    #[arg(long, value_name = "PX", default_value_t = 0)]
    dilate: u32,
    /// Feathering (px).
    #[arg(long, value_name = "PX", default_value_t = 0)]
    feather: u32,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
}

impl GpuArgs {
    /// Runs `avatarm bench gpu`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            scene,
            out,
            sizes,
            cameras,
            frames,
            dilate,
            feather,
            package_path,
        } = self;
        let path = scene.unwrap_or_else(default_scene);
        let scene = Scene::load(&path, &packages(package_path))?;
        let sweep = GpuSweep {
            sizes,
            cameras,
            frames,
            dilate_px: dilate,
            feather_px: feather,
            progress: true,
        };
        let outputs = bench_gpu::run_gpu(&scene, &sweep, &out)?;
        println!(
            "{:<11} {:>4} {:>10} {:>10} {:>10} {:>10} {:>9} {:>9} {:>10}  GPU clock",
            "size",
            "cams",
            "erase ms",
            "passes ms",
            "twin ms",
            "floor ms",
            "erase/fl",
            "pass/fl",
            "update ms"
        );
        for p in &outputs.points {
            println!(
                "{:<11} {:>4} {:>10.3} {:>10.3} {:>10.3} {:>10.4} {:>9.1} {:>9.1} {:>10.1}  {}",
                format!("{}x{}", p.size.0, p.size.1),
                p.cameras,
                p.erase.median,
                p.passes.median,
                p.mask_twin.median,
                p.floor.median,
                p.erase_over_floor(),
                p.passes_over_floor(),
                p.update_ms,
                p.clock.as_deref().unwrap_or("not reported (no nvidia-smi)")
            );
        }
        println!(
            "table: {}\nchart: {} and {}",
            outputs.csv.display(),
            outputs.svg.display(),
            outputs.png.display()
        );
        Ok(())
    }
}
