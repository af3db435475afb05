//! `avatarm bench video`: the erased video's codecs, PSNR against bit rate and coding time.

use std::path::PathBuf;

use clap::Args;

use crate::AppError;
use crate::cli::args::frame_size;

/// The arguments of `avatarm bench video`.
#[derive(Args, Debug)]
pub struct VideoArgs {
    /// The recording (MCAP): its erased frames, else its camera frames.
    #[arg(long, value_name = "FILE.mcap")]
    recording: PathBuf,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/bench_video")]
    out: PathBuf,
    /// Frame sizes, WIDTHxHEIGHT (the frames are cropped to each aspect and scaled).
    #[arg(long, value_delimiter = ',', value_parser = frame_size, default_values = ["640x480", "1280x720"])]
    sizes: Vec<(u32, u32)>,
    /// JPEG qualities.
    #[arg(long, value_delimiter = ',', default_values_t = [50u8, 70, 85, 95])]
    jpeg: Vec<u8>,
    /// H.264 target bit rates (Mbit/s).
    #[arg(long, value_delimiter = ',', default_values_t = [0.5, 1.0, 2.0, 4.0, 8.0])]
    h264: Vec<f64>,
    /// The camera's frame rate (Hz).
    #[arg(long, value_name = "HZ", default_value_t = 30.0)]
    fps: f64,
    /// Seconds between H.264 IDR frames.
    #[arg(long = "keyframe-interval", value_name = "S", default_value_t = 2.0)]
    keyframe_interval: f64,
    /// Frames coded (the recording's first; looped when it has fewer).
    #[arg(long, value_name = "N", default_value_t = 90)]
    frames: usize,
}

impl VideoArgs {
    /// Runs `avatarm bench video`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            recording,
            out,
            sizes,
            jpeg,
            h264,
            fps,
            keyframe_interval,
            frames,
        } = self;
        let sweep = crate::bench::video::VideoSweep {
            sizes,
            jpeg_qualities: jpeg,
            h264_mbit_s: h264,
            fps,
            keyframe_interval_s: keyframe_interval,
            frames,
            progress: true,
        };
        let sources = crate::bench::video::source_frames(&recording, frames)?;
        let outputs = crate::bench::video::run_video(&sources, &sweep, &out)?;
        println!("{} frames from {}", sweep.frames, recording.display());
        println!(
            "{:<7} {:<10} {:<5} {:>7} {:>8} {:>7} {:>8} {:>8} {:>8} {:>8} {:>7} {:>8} {:>5}",
            "source",
            "size",
            "codec",
            "setting",
            "Mbit/s",
            "x jpeg",
            "key kB",
            "delta kB",
            "enc ms",
            "dec ms",
            "PSNR",
            "min PSNR",
            "skip"
        );
        for p in &outputs.points {
            println!(
                "{:<7} {:<10} {:<5} {:>7} {:>8.2} {:>7.3} {:>8.1} {:>8.1} {:>8.2} {:>8.2} {:>7.2} {:>8.2} {:>5}",
                p.source,
                format!("{}x{}", p.width, p.height),
                p.codec,
                p.setting,
                p.mbit_s,
                p.rate_ratio,
                p.keyframe_kb,
                p.delta_kb,
                p.encode_ms.median,
                p.decode_ms.median,
                p.psnr_db,
                p.psnr_min_db,
                p.skipped
            );
        }
        super::wrote(&[&outputs.csv, &outputs.svg, &outputs.png]);
        Ok(())
    }
}
