//! `avatarm bench chess`: the paper's chess scene, intent against none at each one-way delay.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::bench::chess::run_chess_bench;
use crate::cli::args::{bundled_scene, packages};

/// The arguments of `avatarm bench chess`.
#[derive(Args, Debug)]
pub struct ChessArgs {
    /// The scene file (needs a [chess]; default: the bundled chess scene).
    scene: Option<PathBuf>,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/bench_chess")]
    out: PathBuf,
    /// Trials per case (default: the scene's).
    #[arg(long, value_name = "N")]
    trials: Option<u32>,
    /// One-way delays, ms (default: the scene's).
    #[arg(long = "delay-ms", value_delimiter = ',')]
    delay_ms: Option<Vec<f64>>,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
}

impl ChessArgs {
    /// Runs `avatarm bench chess`.
    pub fn run(self) -> Result<(), AppError> {
        let path = self.scene.unwrap_or_else(|| bundled_scene("chess.toml"));
        let scene = Scene::load(&path, &packages(self.package_path))?;
        let out = run_chess_bench(&scene, self.trials, self.delay_ms, true, &self.out)?;
        println!(
            "{:<10} {:>8} {:>8} {:>9} {:>9} {:>9} {:>9} {:>8} {:>6} {:>8} {:>8}",
            "case",
            "delay ms",
            "correct",
            "grasp ms",
            "p95",
            "place mm",
            "p95",
            "wrong pg",
            "touch",
            "carry mm",
            "wall s"
        );
        for c in &out.report.conditions {
            let s = &c.summary;
            println!(
                "{:<10} {:>8.0} {:>8} {:>9.0} {:>9.0} {:>9.2} {:>9.2} {:>8} {:>6} {:>8.2} {:>8.1}",
                if c.intent { "intent" } else { "no intent" },
                c.delay_ms,
                format!("{}/{}", s.correct, s.moves),
                s.grasp_delay_ms.median,
                s.grasp_delay_ms.p95,
                s.place_error_mm.median,
                s.place_error_mm.p95,
                s.wrong_pregrasps,
                s.touches,
                s.carry_pos_rmse_mm,
                s.wall_s
            );
        }
        super::wrote(&[&out.csv, &out.json, &out.svg, &out.png]);
        Ok(())
    }
}
