//! The one progress-bar style of every long command (replays, trials, bench sweeps).

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar of `len` steps with `prefix` before it, on stderr; hidden when `show` is
/// false (indicatif also hides it when stderr is not a terminal).
pub fn bar(len: u64, prefix: impl Into<String>, show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template(
            "{prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} eta {eta} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_prefix(prefix.into());
    bar
}
