//! Summaries of measured series: a nearest-rank quantile and [`Spread`] (median, 95th
//! percentile, largest, count), the one way every report, bench and status line in Avatarm
//! states a latency or an error.

use serde::{Deserialize, Serialize};

/// The `q` quantile (`0 ≤ q ≤ 1`) of `sorted` (ascending, finite), by the nearest rank
/// `round((n − 1)·q)`; `None` when `sorted` is empty or `q` is outside `[0, 1]` or NaN.
///
/// ```
/// use avatarm_core::stats::quantile;
/// let v = [1.0, 2.0, 3.0, 4.0, 5.0];
/// assert_eq!(quantile(&v, 0.5), Some(3.0));
/// assert_eq!(quantile(&v, 0.95), Some(5.0));
/// assert_eq!(quantile(&[], 0.5), None);
/// ```
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() || !(0.0..=1.0).contains(&q) {
        return None;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted.get(i).copied()
}

/// Median, 95th percentile and largest of a series, in the series' unit (ms, mm, ...), over
/// its finite values (nearest rank, [`quantile`]).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, Default, PartialEq)]
pub struct Spread {
    /// Median.
    pub median: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Largest.
    pub max: f64,
    /// Finite samples summarised.
    pub n: usize,
}

impl Spread {
    /// The most samples a series kept for a spread holds (an hour at 120 a second), so a long
    /// session's memory stays bounded; later samples are not kept.
    pub const MAX_SAMPLES: usize = 432_000;

    /// Appends `value` to `series` while it holds fewer than [`Spread::MAX_SAMPLES`].
    pub fn push(series: &mut Vec<f64>, value: f64) {
        if series.len() < Self::MAX_SAMPLES {
            series.push(value);
        }
    }

    /// Of `values` (any order; NaN and infinities left out); all zero with `n = 0` when none
    /// is finite.
    ///
    /// ```
    /// use avatarm_core::stats::Spread;
    /// let s = Spread::of(&[3.0, f64::NAN, 1.0, 2.0]);
    /// assert_eq!((s.median, s.max, s.n), (2.0, 3.0, 3));
    /// ```
    pub fn of(values: &[f64]) -> Self {
        Self::some_of(values).unwrap_or_default()
    }

    /// Of `values` as [`Spread::of`], `None` when none is finite.
    pub fn some_of(values: &[f64]) -> Option<Self> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        v.sort_by(f64::total_cmp);
        Some(Self {
            median: quantile(&v, 0.5)?,
            p95: quantile(&v, 0.95)?,
            max: *v.last()?,
            n: v.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_nearest_rank_is_taken_and_bad_quantiles_refused() {
        let v: Vec<f64> = (1..=20).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.0), Some(1.0));
        assert_eq!(quantile(&v, 1.0), Some(20.0));
        // round(19 · 0.95) = round(18.05) = 18: the 19th value.
        assert_eq!(quantile(&v, 0.95), Some(19.0));
        assert_eq!(quantile(&v, 1.5), None);
        assert_eq!(quantile(&v, f64::NAN), None);
    }

    #[test]
    fn a_series_of_nothing_finite_has_no_spread() {
        assert_eq!(Spread::some_of(&[f64::NAN, f64::INFINITY]), None);
        assert_eq!(Spread::of(&[]), Spread::default());
        let mut series = Vec::new();
        Spread::push(&mut series, 1.0);
        assert_eq!(series, [1.0]);
    }
}
