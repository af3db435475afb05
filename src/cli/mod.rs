//! The `avatarm` command line: a thin dispatch to one module per command, each a clap `Args`
//! struct with its own `run()` (`avatarm bench ...` under [`bench`]).
//!
//! - [`args`]: what several commands share (the package path, bundled scenes, value parsers).
//! - [`overrides`]: `--erase`, `--dilate`, ... applied to a loaded scene.

pub mod args;
pub mod bench;
pub mod calibrate;
pub mod import;
pub mod join;
pub mod overrides;
pub mod relay;
pub mod replay;
pub mod robot;
pub mod router;
pub mod run;
pub mod serve;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::AppError;

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
    Robot(robot::RobotArgs),
    /// Convert a real Leap Motion recording (leapjs-playback JSON, Leap's protocol v6, .json or
    /// .json.gz) to a .hand.jsonl of Avatarm's 26-joint skeleton, and picture one frame; or a
    /// folder of camera frames, or a ROS 1 bag, to a recording (MCAP).
    Import(import::ImportArgs),
    /// Open the desktop preview of a scene (default: assets/scenes/default.toml).
    #[command(after_help = crate::preview::keys::help())]
    Run(run::RunArgs),
    /// Replay a scene without a window: frames, ground truth and report.json in --out. With
    /// --recording: a recorded session (MCAP) through the erase instead (docs/real-footage.md).
    Replay(replay::ReplayArgs),
    /// Fit the camera's pose to the robot itself: the pose (and with --intrinsics fx, fy) that
    /// puts the robot's silhouette at the recorded joints on the recording's reference masks
    /// (or with --background on each frame's difference from an empty room, with --edges on
    /// each frame's own image edges); writes DIR/camera_pose.yaml (a head camera's
    /// DIR/camera_mount.yaml), before/after overlays and report.json (docs/real-footage.md).
    Calibrate(calibrate::CalibrateArgs),
    /// The robot site of a two-site session (Alice's desk, docs/network.md): the robot, the
    /// camera, the erase and the robot's side of the mapping, over Zenoh. Needs a scene with a
    /// [task] (default: the pouring scene).
    Serve(serve::ServeArgs),
    /// The operator's site of a two-site session (Blair, docs/network.md): the hand, the
    /// physics twin and the operator's side of the mapping, sending targets to ENDPOINT; or,
    /// with --watch, an observer.
    Join(join::JoinArgs),
    /// A Zenoh router between the sites (docs/network.md): fans the robot site's video out to
    /// many observers so the robot site sends each stream once.
    Router(router::RouterArgs),
    /// The seeded impairment relay between two sites (docs/network.md): TCP or UDP from
    /// 127.0.0.1:PORT to TO, with one-way delay, jitter, loss (UDP) and a bandwidth cap, for
    /// trying a session under a bad network where `tc netem` is not available.
    Relay(relay::RelayArgs),
    /// Measure speed against accuracy and chart it.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

/// Parses the command line and runs it; errors are printed and give exit code 1.
pub fn main() -> ExitCode {
    let ran = run(Cli::parse());
    crate::log::finish_trace();
    match ran {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<(), AppError> {
    match cli.command {
        Command::Robot(args) => args.run(),
        Command::Import(args) => args.run(),
        Command::Run(args) => args.run(),
        Command::Replay(args) => args.run(),
        Command::Calibrate(args) => args.run(),
        Command::Serve(args) => args.run(),
        Command::Join(args) => args.run(),
        Command::Router(args) => args.run(),
        Command::Relay(args) => args.run(),
        Command::Bench(bench) => bench.run(),
    }
}
