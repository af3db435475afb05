//! `avatarm bench ...`: speed against accuracy, each measured and charted by a command of its own.

pub mod chess;
pub mod control;
pub mod dr;
pub mod gpu;
pub mod head;
pub mod network;
pub mod twin;
pub mod video;

use clap::Subcommand;

use crate::AppError;

/// The benches: each measures speed against accuracy and charts it.
#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Erase from a camera on a moving head (default scene: head_camera, Alice's headset
    /// camera): leak against the head's peak angular speed for each tracking latency, with and
    /// without pose compensation, and against an error in the camera's mount:
    /// DIR/head_erase.{svg,png,csv}.
    Head(head::HeadArgs),
    /// Sweep the erase pipeline's settings on a scene (default: the default scene, whose arm
    /// reaches, lifts and pours: the pouring scene's arm rests during its video) and chart
    /// frame cost against leak and PSNR: DIR/dr_speed_accuracy.{svg,png,csv}.
    Dr(dr::DrArgs),
    /// Measure how much twin the mask needs on a scene (default: sawyer_real, the real Sawyer):
    /// each mask twin (visual meshes, collision geometry, meshes simplified, a primitive
    /// description) with the arm retimed to the TCP speed cap; chart mask GPU time against leak
    /// and the dilation for leak <= 1 %: DIR/twin_detail.{svg,png,csv}.
    Twin(twin::TwinArgs),
    /// Time the erase on the GPU, pass by pass, at several frame sizes and for one or several
    /// cameras, beside a plain copy of the same images measured in the same run (the floor):
    /// DIR/gpu_erase.{csv,svg,png}. The scene (default: the default scene) gives the robot,
    /// the camera's pose and field of view, and the erase settings.
    Gpu(gpu::GpuArgs),
    /// Play the paper's chess scene through the robot (default: the bundled chess scene):
    /// every move of its opening, each trial with intent off and on at each one-way delay;
    /// virtual grasp to real grasp and the real pieces' placement error against the delay:
    /// DIR/chess.{csv,json,svg,png} (docs/chess.md).
    Chess(chess::ChessArgs),
    /// Sweep the teleoperation loop on a scene's pouring task (default: the pouring scene):
    /// control rate x simulated command latency x TCP speed cap, both mapping modes, and chart
    /// object position RMSE against rate and loop cost: DIR/control_speed_accuracy.{svg,png,csv}.
    Control(control::ControlArgs),
    /// The pouring task across two sites (robot site and operator in this process, over Zenoh
    /// through the seeded impairment relay; docs/network.md): object RMSE against one-way
    /// delay and loss, both mapping modes, with the paper's RMSE as a line. CSV, SVG, PNG.
    Network(network::NetworkArgs),
    /// The erased video's codecs (docs/network.md): a recording's erased frames (`avatarm
    /// replay SCENE --record`) coded with JPEG and H.264 at each frame size; PSNR after
    /// coding against bit rate, encode and decode time, as ratios against JPEG at quality 85.
    /// CSV, SVG, PNG.
    Video(video::VideoArgs),
}

impl BenchCommand {
    /// Runs the bench.
    pub fn run(self) -> Result<(), AppError> {
        match self {
            Self::Head(args) => args.run(),
            Self::Dr(args) => args.run(),
            Self::Twin(args) => args.run(),
            Self::Gpu(args) => args.run(),
            Self::Chess(args) => args.run(),
            Self::Control(args) => args.run(),
            Self::Network(args) => args.run(),
            Self::Video(args) => args.run(),
        }
    }
}

/// Says which files a bench wrote: `wrote A, B and C`.
fn wrote(files: &[&std::path::Path]) {
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    match names.split_last() {
        Some((last, [])) => println!("wrote {last}"),
        Some((last, rest)) => println!("wrote {} and {last}", rest.join(", ")),
        None => {}
    }
}
