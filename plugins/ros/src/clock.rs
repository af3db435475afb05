//! The robot's clock on Avatarm's: the offset from joint-state arrivals (a minimum-delay filter).

use std::collections::VecDeque;

/// Maps the robot's clock onto Avatarm's from arrival times.
///
/// Each joint state gives `arrival − stamp` = clock offset + transport delay; the delay is
/// never negative, so the smallest value over a window (here the last `window` samples) is
/// the offset plus the smallest delay, and jitter only ever adds to a sample (the "minimum
/// filter" of network clock estimation, as NTP's clock filter). Its `jitter` is the spread
/// (the 95th percentile minus the minimum) of the same window.
#[derive(Debug, Clone)]
pub struct ClockOffset {
    samples: VecDeque<f64>,
    window: usize,
}

impl ClockOffset {
    /// An estimator over the last `window` samples (at least 1).
    pub fn new(window: usize) -> Self {
        Self {
            samples: VecDeque::with_capacity(window.max(1)),
            window: window.max(1),
        }
    }

    /// Adds one sample: when it arrived (Avatarm's clock, s) and its stamp (the robot's, s).
    /// Non-finite values are ignored.
    pub fn add(&mut self, arrival_s: f64, stamp_s: f64) {
        let d = arrival_s - stamp_s;
        if !d.is_finite() {
            return;
        }
        if self.samples.len() == self.window {
            self.samples.pop_front();
        }
        self.samples.push_back(d);
    }

    /// Avatarm's clock minus the robot's (s), `None` before the first sample.
    pub fn offset_s(&self) -> Option<f64> {
        self.samples.iter().copied().reduce(f64::min)
    }

    /// The spread of `arrival − stamp` over the window (s): how much later than the fastest
    /// sample the others arrived (95th percentile).
    pub fn jitter_s(&self) -> Option<f64> {
        let min = self.offset_s()?;
        let mut d: Vec<f64> = self.samples.iter().map(|v| v - min).collect();
        d.sort_by(f64::total_cmp);
        avatarm_core::stats::quantile(&d, 0.95)
    }

    /// A robot stamp (s) on Avatarm's clock, `None` before the first sample.
    pub fn to_app(&self, stamp_s: f64) -> Option<f64> {
        Some(stamp_s + self.offset_s()?)
    }
}
