//! Helpers shared by the benches.

use std::time::Duration;

/// The median of timings (the upper one of an even count).
pub fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}
