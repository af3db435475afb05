//! What a command printed, for the tests' checks and failure messages.

use std::process::Output;

/// `out`'s standard output then its standard error, as text.
pub fn printed(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}
