//! `avatarm bench head`: leak against a moving head's speed, tracking latency, pose
//! compensation and mount error.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::cli::args::{bundled_scene, frame_size, packages};
use crate::cli::overrides::{EraseOverrides, on_off};

/// The arguments of `avatarm bench head`.
#[derive(Args, Debug)]
pub struct HeadArgs {
    /// The scene file (needs [camera.head] with a sweep).
    scene: Option<PathBuf>,
    /// The scene's camera NAME (one of its [[cameras]]; default: its first camera on a
    /// head).
    #[arg(long, value_name = "NAME")]
    view: Option<String>,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/bench_head")]
    out: PathBuf,
    /// The head's peak angular speeds (degrees/s).
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 15.0, 30.0, 60.0])]
    speeds: Vec<f64>,
    /// Head tracking latencies (ms).
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 20.0, 50.0, 100.0])]
    latencies: Vec<f64>,
    /// Pose compensation settings (off, on).
    #[arg(long, value_delimiter = ',', value_parser = on_off, default_values_t = [false, true])]
    compensation: Vec<bool>,
    /// Errors put into the camera's mount (degrees of yaw), compensated, at --mount-speed
    /// and --mount-latency; the flag with no value for none.
    #[arg(long, value_delimiter = ',', num_args = 0.., default_values_t = [0.0, 0.5, 1.0, 2.0])]
    mount_errors: Vec<f64>,
    /// The head's speed for the mount series (degrees/s).
    #[arg(long, value_name = "DEG_S", default_value_t = 30.0)]
    mount_speed: f64,
    /// The tracking latency for the mount series (ms).
    #[arg(long, value_name = "MS", default_value_t = 20.0)]
    mount_latency: f64,
    /// Background views kept, one point each at --mount-speed and --mount-latency: 0 (the
    /// empty room's photograph as it is), 1 (re-projected into each view), more (with views
    /// from the frames); the flag with no value for none.
    #[arg(long, value_delimiter = ',', num_args = 0.., default_values_t = [0, 1, 8])]
    background_views: Vec<usize>,
    /// Simulated seconds replayed per point.
    #[arg(long, value_name = "S", default_value_t = 2.0)]
    duration: f64,
    /// Run the scene's camera at WIDTHxHEIGHT pixels (its field of view kept).
    #[arg(long = "camera-size", value_name = "WxH", value_parser = frame_size)]
    camera_size: Option<(u32, u32)>,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
}

impl HeadArgs {
    /// Runs `avatarm bench head`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            scene,
            view,
            out,
            speeds,
            latencies,
            compensation,
            mount_errors,
            mount_speed,
            mount_latency,
            background_views,
            duration,
            camera_size,
            package_path,
        } = self;
        let path = scene.unwrap_or_else(|| bundled_scene("head_camera.toml"));
        let packages = packages(package_path);
        let mut scene = Scene::load_view(&path, &packages, view.as_deref())?;
        if view.is_none() && scene.head.is_none() {
            // The first camera on a head, where the first is fixed.
            for name in scene.cameras.clone().iter().skip(1) {
                let other = Scene::load_view(&path, &packages, Some(name))?;
                if other.head.is_some() {
                    scene = other;
                    break;
                }
            }
        }
        EraseOverrides {
            camera_size,
            ..Default::default()
        }
        .apply(&mut scene)?;
        let sweep = crate::bench::head::HeadSweep {
            speeds_deg_s: speeds,
            latencies_ms: latencies,
            compensation,
            mount_errors_deg: mount_errors,
            mount_speed_deg_s: mount_speed,
            mount_latency_ms: mount_latency,
            background_views,
            duration_s: duration,
            progress: true,
        };
        let outputs = crate::bench::head::run_head(&scene, &sweep, &out)?;
        println!(
            "{:>8} {:>8} {:>6} {:>8} {:>6} {:>8} {:>8} {:>8} {:>8} {:>11} {:>9}",
            "deg/s",
            "track ms",
            "comp",
            "mount°",
            "views",
            "IoU",
            "leak %",
            "max %",
            "PSNR dB",
            "cam err °",
            "frame ms"
        );
        for p in &outputs.points {
            println!(
                "{:>8} {:>8} {:>6} {:>8} {:>6} {:>8.4} {:>8.3} {:>8.3} {:>8.2} {:>11.3} {:>9.1}",
                p.speed_deg_s,
                p.latency_ms,
                if p.compensation { "on" } else { "off" },
                p.mount_error_deg,
                p.background_views,
                p.iou_mean,
                p.leak_pct_mean,
                p.leak_pct_max,
                p.psnr_db_mean,
                p.camera_error_deg_median,
                p.frame_ms_median
            );
        }
        super::wrote(&[&outputs.csv, &outputs.svg, &outputs.png]);
        Ok(())
    }
}
