//! `avatarm bench twin`: how much twin the mask needs, mask GPU time against leak.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::bench::twin::{self as bench_twin, TwinSweep, TwinVariant};
use crate::cli::args::{bundled, bundled_scene, packages};

/// The arguments of `avatarm bench twin`.
#[derive(Args, Debug)]
pub struct TwinArgs {
    /// The scene file.
    scene: Option<PathBuf>,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/bench_twin")]
    out: PathBuf,
    /// The twins: visual, collision, keep:FRACTION, urdf:PATH (default: visual, collision,
    /// keep:0.5, keep:0.1, keep:0.02, and the bundled sawyer_lite for a Sawyer).
    #[arg(long, value_delimiter = ',', value_name = "TWIN")]
    variants: Vec<String>,
    /// Simulated seconds replayed per twin.
    #[arg(long, value_name = "S", default_value_t = 2.0)]
    duration: f64,
    /// TCP speed the arm's timeline is retimed to, m/s (the paper's cap).
    #[arg(long = "tcp-speed", value_name = "M_PER_S", default_value_t = 0.25)]
    tcp_speed: f64,
    /// Score every N-th camera frame for the dilation analysis.
    #[arg(long = "frames-every", value_name = "N", default_value_t = 2)]
    frames_every: u32,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
}

impl TwinArgs {
    /// Runs `avatarm bench twin`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            scene,
            out,
            variants,
            duration,
            tcp_speed,
            frames_every,
            package_path,
        } = self;
        let path = scene.unwrap_or_else(|| bundled_scene("sawyer_real.toml"));
        let packages = packages(package_path);
        let scene = Scene::load(&path, &packages)?;
        let mut sweep = TwinSweep {
            duration_s: duration,
            tcp_speed,
            frames_every,
            packages,
            progress: true,
            ..TwinSweep::default()
        };
        if variants.is_empty() {
            let lite = bundled("robots", "sawyer_lite/sawyer_lite.urdf");
            if scene.model.name == "sawyer" && lite.is_file() {
                sweep
                    .variants
                    .push(TwinVariant::parse(&format!("urdf:{}", lite.display()))?);
            }
        } else {
            sweep.variants = variants
                .iter()
                .map(|v| TwinVariant::parse(v))
                .collect::<Result<_, _>>()?;
        }
        let outputs = bench_twin::run_twin(&scene, &sweep, &out)?;
        println!(
            "TCP peak {:.3} m/s in the scene, timeline x{:.2}: {:.3} m/s peak in the replayed {} s",
            outputs.scene_tcp_speed, outputs.time_scale, outputs.window_tcp_speed, duration
        );
        println!(
            "{:<14} {:>10} {:>13} {:>9} {:>7} {:>8} {:>8} {:>8} {:>8} {:>13}  front",
            "twin",
            "triangles",
            "mask GPU ms",
            "frame ms",
            "ratio",
            "IoU",
            "leak %",
            "over %",
            "PSNR dB",
            "dilate <=1%"
        );
        for p in &outputs.points {
            println!(
                "{:<14} {:>10} {:>13} {:>9.1} {:>7.3} {:>8.4} {:>8.3} {:>8.3} {:>8.2} {:>13}  {}",
                p.label,
                p.triangles,
                p.gpu_mask_twin_ms.map_or("-".into(), |v| format!("{v:.2}")),
                p.frame_ms_median,
                p.frame_cost_ratio,
                p.iou_mean,
                p.leak_pct_mean,
                p.overmask_pct_mean,
                p.psnr_db_mean,
                p.dilate_for_1pct.map_or("-".into(), |d| format!("{d} px")),
                if p.pareto { "yes" } else { "-" }
            );
        }
        println!(
            "ratios against '{}' of the same run; wrote {}, {}, {}",
            outputs.points[0].label,
            outputs.csv.display(),
            outputs.svg.display(),
            outputs.png.display()
        );
        Ok(())
    }
}
