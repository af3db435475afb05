//! Scripted scene replays rendered for real (software Vulkan is enough), the command line, the
//! preview and scene validation: a module per topic, the helpers they share here.

mod bench;
mod chess;
mod erase;
mod preview;
mod robot;
#[cfg(feature = "ros")]
mod ros;
mod schedule;

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::support::{output, python_mcap};

use avatarm::replay::report::{HeadReport, ReplayReport, Times, ViewBackgroundReport};
use avatarm::replay::{self, ReplayOptions};
use avatarm::scene::Scene;
use avatarm_core::robot::{PackagePath, Shape};
use nalgebra::{Isometry3, Point3};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn default_scene() -> Scene {
    Scene::load(
        &root().join("assets/scenes/default.toml"),
        &PackagePath::default(),
    )
    .expect("the default scene loads")
}

fn out_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// A bench's CSV table, cells found by column name.
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
    text: String,
}

impl Table {
    fn read(path: &Path) -> Self {
        let text =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let split = |l: &str| l.split(',').map(str::to_owned).collect::<Vec<_>>();
        let mut lines = text.lines();
        let header = split(lines.next().unwrap_or_default());
        let rows = lines.map(split).collect();
        Self { header, rows, text }
    }

    fn cell(&self, row: usize, name: &str) -> &str {
        let i = self.header.iter().position(|h| h == name);
        let i = i.unwrap_or_else(|| panic!("no column {name}: {}", self.text));
        &self.rows[row][i]
    }

    fn number(&self, row: usize, name: &str) -> f64 {
        self.cell(row, name)
            .parse()
            .unwrap_or_else(|_| panic!("{name} of row {row} is not a number: {}", self.text))
    }
}

/// The standard output of a command that must have succeeded (else its output in the panic).
fn succeeded(out: &std::process::Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn load_rgb(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Runs `avatarm run ARGS` under Xvfb; returns the log (stdout and stderr) after checking it
/// succeeded without a panic.
fn run_preview(args: &[&str], out: &Path) -> String {
    run_preview_with(args, out, &[])
}

/// [`run_preview`] with environment variables.
fn run_preview_with(args: &[&str], out: &Path, env: &[(&str, &str)]) -> String {
    let run = Command::new("xvfb-run")
        .envs(env.iter().copied())
        .args(["-a", "-s", "-screen 0 1280x720x24"])
        .arg(env!("CARGO_BIN_EXE_avatarm"))
        .arg("run")
        .args(args)
        // No OpenXR runtime, even where a developer has one installed.
        .env("XR_RUNTIME_JSON", out.join("no_runtime.json"))
        .current_dir(root())
        .output()
        .expect("xvfb-run starts (scripts/setup.sh installs it)");
    let log = output::printed(&run);
    assert!(run.status.success(), "avatarm run {args:?} failed:\n{log}");
    assert!(!log.contains("panicked"), "{log}");
    log
}

/// The numbers in the first log line that contains `marker`, from the marker on.
fn numbers_after(log: &str, marker: &str) -> Vec<f64> {
    let (_, rest) = log
        .lines()
        .find_map(|l| l.split_once(marker))
        .unwrap_or_else(|| panic!("no line with '{marker}':\n{log}"));
    rest.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
        .filter_map(|w| w.parse().ok())
        .collect()
}

fn scene(name: &str) -> Scene {
    Scene::load(
        &root().join(format!("assets/scenes/{name}.toml")),
        &PackagePath::default(),
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The figure a report must have; else the panic names it.
fn some<T>(value: Option<T>, what: &str) -> T {
    value.unwrap_or_else(|| panic!("the report has no {what}"))
}

/// A series' median the report must have.
fn median(times: Times, what: &str) -> f64 {
    some(times, what).median
}

/// The head camera's section the report must have.
fn head(report: &ReplayReport) -> &HeadReport {
    some(report.head.as_ref(), "head")
}

/// The view-following background's section the report must have.
fn view_background(report: &ReplayReport) -> &ViewBackgroundReport {
    some(
        head(report).view_background.as_ref(),
        "head.view_background",
    )
}

fn run(scene: &Scene, name: &str) -> ReplayReport {
    let mut options = ReplayOptions::new(out_dir(name));
    options.frames_every = 1000;
    let report = replay::run(scene, options).unwrap_or_else(|e| panic!("{name}: {e}"));
    eprintln!(
        "{name}: mask {:?} dr {:?} gpu_vs_cpu {:?} timing {:?}",
        report.mask, report.dr, report.gpu_vs_cpu, report.timing_ms
    );
    // The GPU passes agree with the CPU reference on the same inputs.
    let gpu = &report.gpu_vs_cpu;
    assert!(
        some(gpu.max_abs_diff, "gpu_vs_cpu.max_abs_diff") <= 1,
        "{name}: {gpu:?}"
    );
    assert_eq!(gpu.mask_mismatch_px_max, Some(0), "{name}");
    assert!(report.mask.frames_scored >= 20, "{name}: {:?}", report.mask);
    report
}
