//! Where the real data beside the checkout is (`../shared/data`: real robot descriptions laid
//! out as ROS packages, real camera frames), for the tests, benches and scenes that use it.
//!
//! A clone without it (a user's fork on GitHub) skips those tests, saying what is missing; the
//! descriptions come from their makers (`sawyer_robot` and `intera_common` of Rethink Robotics,
//! `example-robot-data` on PyPI).

use std::path::PathBuf;

/// The environment variable that overrides where the data is.
pub const ENV: &str = "AVATARM_SHARED_DATA";

/// The data folder: `$AVATARM_SHARED_DATA`, else `../shared/data` beside the repository root;
/// `Err` names the folder looked for, for a test's skip message.
pub fn shared_data() -> Result<PathBuf, String> {
    let dir = std::env::var_os(ENV)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
    if dir.join("ros").is_dir() {
        Ok(dir)
    } else {
        Err(format!(
            "no real data at {} (set {ENV} to a folder with ros/ and real/; see the README's 'Real robots')",
            dir.display()
        ))
    }
}

/// The folder holding the real robot packages (`ros/`), to use as a package path.
pub fn ros_packages() -> Result<PathBuf, String> {
    shared_data().map(|d| d.join("ros"))
}
