//! Where the real data beside the checkout is (`../shared/data`: real robot descriptions laid
//! out as ROS packages, real camera frames), for the tests, benches and scenes that use it.
//!
//! A clone without it (a user's fork on GitHub) skips those tests, saying what is missing; the
//! descriptions come from their makers (`sawyer_robot` and `intera_common` of Rethink Robotics,
//! `example-robot-data` on PyPI).

use std::path::PathBuf;

/// The environment variable that overrides where the data is.
pub const ENV: &str = "AVATARM_SHARED_DATA";

/// The real data is not where it was looked for (its message is a test's skip message).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "no real data at {} (set {ENV} to a folder with ros/ and real/; see the README's 'Real robots')",
    .looked.display()
)]
pub struct NoSharedData {
    /// The folder looked for.
    pub looked: PathBuf,
}

impl NoSharedData {
    /// Says that `test` is skipped for want of the data ([`say_skipped`]).
    pub fn skip(&self, test: &str) {
        say_skipped(test, self);
    }
}

/// Says that `test` was skipped and why, as `SKIPPED test: why` on the process's own standard
/// error: written past the test harness's capture (which takes only `print!` and `eprint!`),
/// so that a test that could not run shows in the run's log instead of passing silently.
pub fn say_skipped(test: &str, why: &dyn std::fmt::Display) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr().lock(), "SKIPPED {test}: {why}");
}

/// The data folder: `$AVATARM_SHARED_DATA`, else `../shared/data` beside the repository root;
/// the error names the folder looked for.
pub fn shared_data() -> Result<PathBuf, NoSharedData> {
    let dir = std::env::var_os(ENV)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
    if dir.join("ros").is_dir() {
        Ok(dir)
    } else {
        Err(NoSharedData { looked: dir })
    }
}

/// The folder holding the real robot packages (`ros/`), to use as a package path.
pub fn ros_packages() -> Result<PathBuf, NoSharedData> {
    shared_data().map(|d| d.join("ros"))
}
