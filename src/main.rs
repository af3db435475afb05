//! `avatarm`: the command line (robot check, desktop preview, headless replay).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use avatarm::preview::PreviewOptions;
use avatarm::replay::ReplayOptions;
use avatarm::scene::Scene;
use avatarm::{Mode, build_app, robot_info};
use avatarm_core::robot::{PackagePath, RobotModel};
use clap::{Parser, Subcommand};

/// Avatarm: manipulate real objects through a robot arm hidden from view.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Check a robot description: joint/link tree, limits, meshes, link poses at q.
    Robot {
        /// The URDF file.
        urdf: PathBuf,
        /// Folder searched for package://NAME/... URIs (repeatable; ROS_PACKAGE_PATH is added).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
        /// Joint values: v1,v2,... in the printed q order, or name=value,... (others are 0).
        #[arg(long, value_name = "Q", allow_hyphen_values = true)]
        q: Option<String>,
        /// Print link poses at q as JSON instead of the tree.
        #[arg(long)]
        json: bool,
    },
    /// Open the desktop preview of a scene (default: assets/scenes/default.toml).
    ///
    /// Keys: Esc quits, F12 saves a screenshot.
    Run {
        /// The scene file.
        scene: Option<PathBuf>,
        /// Start an OpenXR session; without a runtime the preview window is used.
        #[arg(long)]
        xr: bool,
        /// Quit after N frames.
        #[arg(long, value_name = "N")]
        frames: Option<u32>,
        /// Save a screenshot of the window at the last frame.
        #[arg(long, value_name = "PATH")]
        screenshot: Option<PathBuf>,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
    },
    /// Replay a scene without a window: frames, ground truth and report.json in --out.
    Replay {
        /// The scene file.
        scene: PathBuf,
        /// Run without a window (replays are always headless; accepted for clarity).
        #[arg(long)]
        headless: bool,
        /// Output folder.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Save every N-th camera frame.
        #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        frames_every: u32,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
    },
}

fn packages(dirs: Vec<PathBuf>) -> PackagePath {
    let mut p = PackagePath(dirs);
    if let Ok(env) = std::env::var("ROS_PACKAGE_PATH") {
        p.extend_from_env_list(&env);
    }
    p
}

fn default_scene() -> PathBuf {
    let local = Path::new("assets/scenes/default.toml");
    if local.is_file() {
        local.to_owned()
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/default.toml")
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.command {
        Command::Robot {
            urdf,
            package_path,
            q,
            json,
        } => {
            let model = RobotModel::from_urdf_file(&urdf, &packages(package_path))
                .map_err(|e| e.to_string())?;
            let meshes = robot_info::check_meshes(&model).map_err(|e| e.to_string())?;
            let q = model
                .parse_q(q.as_deref().unwrap_or(""))
                .map_err(|e| format!("--q: {e}"))?;
            let q: Vec<f64> = q.iter().copied().collect();
            if json {
                let text = serde_json::to_string_pretty(&robot_info::poses_json(&model, &q))
                    .map_err(|e| e.to_string())?;
                println!("{text}");
            } else {
                print!("{}", robot_info::tree_text(&model));
                for line in meshes {
                    println!("mesh {line}");
                }
            }
            Ok(())
        }
        Command::Run {
            scene,
            xr,
            frames,
            screenshot,
            package_path,
        } => {
            let path = scene.unwrap_or_else(default_scene);
            let scene = Scene::load(&path, &packages(package_path)).map_err(|e| e.to_string())?;
            let mode = Mode::Preview(PreviewOptions {
                frames,
                screenshot,
                xr,
                fixed_timestep: frames.is_some(),
            });
            let exit = build_app(&scene, &mode).run();
            if exit.is_error() {
                return Err("the preview stopped with an error (see the log above)".into());
            }
            Ok(())
        }
        Command::Replay {
            scene,
            headless: _,
            out,
            frames_every,
            package_path,
        } => {
            let scene = Scene::load(&scene, &packages(package_path)).map_err(|e| e.to_string())?;
            let mut options = ReplayOptions::new(out.clone());
            options.frames_every = frames_every;
            options.progress = true;
            let report = avatarm::replay::run(&scene, options)?;
            eprintln!(
                "replayed '{}': {} frames, {:.2} s simulated in {:.2} s ({:.2} sim s per wall s); report: {}",
                scene.file.name,
                report["frames"],
                report["sim_time_s"].as_f64().unwrap_or(0.0),
                report["wall_time_s"].as_f64().unwrap_or(0.0),
                report["sim_s_per_wall_s"].as_f64().unwrap_or(0.0),
                out.join("report.json").display()
            );
            Ok(())
        }
    }
}
