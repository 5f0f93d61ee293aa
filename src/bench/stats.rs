//! Medians and timed runs.

use std::hint::black_box;
use std::time::Instant;

use super::BenchError;

/// Median of a sample (mean of the middle two for an even count); NaN if empty.
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        (s[n / 2 - 1] + s[n / 2]) / 2.0
    }
}

/// Time `f` `runs` times after one warm-up run, in milliseconds.
pub(super) fn time_runs<T>(
    runs: usize,
    mut f: impl FnMut() -> Result<T, BenchError>,
) -> Result<Vec<f64>, BenchError> {
    black_box(f()?);
    let mut out = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t = Instant::now();
        let v = f()?;
        out.push(t.elapsed().as_secs_f64() * 1e3);
        black_box(v);
    }
    Ok(out)
}

/// Run `f` once, then `runs` times timed: the median milliseconds of the timed runs and the
/// last result.
pub(super) fn time_median<T>(
    runs: usize,
    mut f: impl FnMut() -> Result<T, BenchError>,
) -> Result<(f64, T), BenchError> {
    let mut last = f()?;
    let mut ms = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t = Instant::now();
        last = black_box(f()?);
        ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok((median(&ms), last))
}
