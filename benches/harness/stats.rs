//! Summaries of repeated timings and the equal-error speed-up. Pure functions: the tests in
//! `tests/harness_pure.rs` include this file by path.

use serde::Serialize;

/// Median and spread of repeated measurements.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    pub median: f64,
    pub min: f64,
    pub max: f64,
    /// Quartiles (linear interpolation between order statistics).
    pub p25: f64,
    pub p75: f64,
    pub n: usize,
}

/// The q-quantile of sorted values, interpolating linearly between neighbours.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let x = q * (n - 1) as f64;
            let i = (x.floor() as usize).min(n - 2);
            let f = x - i as f64;
            sorted[i] * (1.0 - f) + sorted[i + 1] * f
        }
    }
}

/// Each pair's ratio `b[i] / a[i]` (the views study: all cameras' time over one camera's, the
/// two runs of a pair side by side); pairs beyond the shorter list are left out.
pub fn pair_ratios(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(a, b)| b / a).collect()
}

/// Summary of `values` (NaNs left out); all NaN for no values.
pub fn summary(values: &[f64]) -> Summary {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    v.sort_by(f64::total_cmp);
    Summary {
        median: quantile(&v, 0.5),
        min: v.first().copied().unwrap_or(f64::NAN),
        max: v.last().copied().unwrap_or(f64::NAN),
        p25: quantile(&v, 0.25),
        p75: quantile(&v, 0.75),
        n: v.len(),
    }
}

pub fn median(values: &[f64]) -> f64 {
    summary(values).median
}

/// When a decreasing error curve first reaches a level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", content = "time", rename_all = "snake_case")]
pub enum Reach {
    /// Between two measured points: interpolated linearly in log(time), log(error).
    At(f64),
    /// Already at the first measured point: it reaches the level at this time or earlier.
    NoLaterThan(f64),
    /// Not within the measured range: it needs more than this (the last point's time).
    LaterThan(f64),
}

/// When the curve `points` (time, error), in increasing time, first has error <= `level`.
pub fn time_to_reach(points: &[(f64, f64)], level: f64) -> Option<Reach> {
    let first = points.first()?;
    if first.1 <= level {
        return Some(Reach::NoLaterThan(first.0));
    }
    for w in points.windows(2) {
        let ((t0, e0), (t1, e1)) = (w[0], w[1]);
        if e1 <= level {
            // e0 > level >= e1 > 0 on both sides of the crossing: interpolate in log-log,
            // where an error falling as t^-1/2 is a straight line.
            if e1 <= 0.0 || e0 <= e1 {
                return Some(Reach::At(t1));
            }
            let f = (e0.ln() - level.ln()) / (e0.ln() - e1.ln());
            return Some(Reach::At((t0.ln() + f * (t1.ln() - t0.ln())).exp()));
        }
    }
    Some(Reach::LaterThan(points.last()?.0))
}

/// The equal-error speed-up at one error level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SpeedUp {
    /// The error the fast method reached at `time_fast`.
    pub level: f64,
    pub time_fast: f64,
    /// When the slow method reaches the same error.
    pub slow: Reach,
    /// slow time / fast time; a lower bound for `LaterThan`, an upper one for `NoLaterThan`.
    pub speedup: f64,
    /// For `LaterThan` only: the speed-up if the slow method's error kept falling as
    /// t^-1/2 (Monte Carlo) from its last point. An estimate, not a measurement.
    pub extrapolated: Option<f64>,
}

impl SpeedUp {
    /// `12.3x`, `>= 12.3x (~40x)` or `<= 12.3x`.
    pub fn display(&self) -> String {
        match self.slow {
            Reach::At(_) => format!("{:.1}x", self.speedup),
            Reach::LaterThan(_) => match self.extrapolated {
                Some(x) => format!(">= {:.1}x (~{x:.0}x)", self.speedup),
                None => format!(">= {:.1}x", self.speedup),
            },
            Reach::NoLaterThan(_) => format!("<= {:.1}x", self.speedup),
        }
    }
}

/// For each point of the fast method's curve, how much longer the slow method needs to
/// reach the same error. Curves are (time, error) in increasing time.
pub fn equal_error_speedups(fast: &[(f64, f64)], slow: &[(f64, f64)]) -> Vec<SpeedUp> {
    fast.iter()
        .filter(|(t, e)| *t > 0.0 && e.is_finite())
        .filter_map(|&(t, e)| {
            let reach = time_to_reach(slow, e)?;
            let (ts, extrapolated) = match reach {
                Reach::At(x) | Reach::NoLaterThan(x) => (x, None),
                Reach::LaterThan(x) => {
                    let &(tl, el) = slow.last()?;
                    (x, (e > 0.0).then(|| tl * (el / e).powi(2) / t))
                }
            };
            Some(SpeedUp { level: e, time_fast: t, slow: reach, speedup: ts / t, extrapolated })
        })
        .collect()
}

/// `WIDTHxHEIGHT`, both at least 1.
pub fn parse_image_size(text: &str) -> Result<(u32, u32), String> {
    let parse = |s: &str| s.trim().parse::<u32>().ok().filter(|&v| v > 0);
    match text.split_once(['x', 'X']).and_then(|(w, h)| Some((parse(w)?, parse(h)?))) {
        Some(size) => Ok(size),
        None => Err(format!("`{text}` is not an image size; write WIDTHxHEIGHT, e.g. 7680x4320")),
    }
}

/// What an error costs a renderer, fitted to its runs of a series of budgets (steps or
/// samples per pixel): wall time = `start` + N `per_sample` and error^2 = `noise`^2 / N +
/// `floor`^2. `noise` is the error one sample would have; `noise`^2 `per_sample` is the time
/// the noise alone needs to reach an error, up to a constant, so two renderers' values of it
/// say which gets there first once both are past their start-up and above their floors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CostModel {
    /// Seconds before the first sample (process, set-up, and what the fit cannot tell
    /// apart from them).
    pub start: f64,
    /// Seconds a sample.
    pub per_sample: f64,
    pub noise: f64,
    pub floor: f64,
    /// The runs fitted.
    pub runs: usize,
}

impl CostModel {
    /// noise^2 x milliseconds a sample: the lower, the faster to an error.
    pub fn noise_time(&self) -> f64 {
        self.noise * self.noise * self.per_sample * 1e3
    }
}

/// Fits `CostModel` to (budget, seconds, error) runs, the runs of the largest budgets only:
/// those of at least a fiftieth of the largest (below that, start-up and the first samples'
/// transients dominate). The time by least squares; error^2 against 1 / N by least squares
/// weighted by 1 / error^4 (each run's relative misfit counts alike), with the floor set to
/// 0 where the best one would be negative. None with fewer than three such runs, or where
/// the fit leaves no positive time a sample or noise.
pub fn cost_model(runs: &[(f64, f64, f64)]) -> Option<CostModel> {
    let largest = runs.iter().filter(|r| r.2.is_finite() && r.2 > 0.0).map(|r| r.0).fold(0.0, f64::max);
    let used: Vec<(f64, f64, f64)> = runs
        .iter()
        .copied()
        .filter(|&(n, t, e)| n >= largest / 50.0 && n > 0.0 && t.is_finite() && e.is_finite() && e > 0.0)
        .collect();
    if used.len() < 3 {
        return None;
    }
    // Least squares of y = a + b x with weights w: (a, b).
    let line = |points: &[(f64, f64, f64)]| -> Option<(f64, f64)> {
        let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(x, y, w) in points {
            sw += w;
            sx += w * x;
            sy += w * y;
            sxx += w * x * x;
            sxy += w * x * y;
        }
        let det = sw * sxx - sx * sx;
        (det.abs() > f64::EPSILON * sw * sxx).then(|| ((sy * sxx - sx * sxy) / det, (sw * sxy - sx * sy) / det))
    };
    let (start, per_sample) = line(&used.iter().map(|&(n, t, _)| (n, t, 1.0)).collect::<Vec<_>>())?;
    let squares: Vec<(f64, f64, f64)> = used.iter().map(|&(n, _, e)| (1.0 / n, e * e, e.powi(-4))).collect();
    let (mut floor2, mut noise2) = line(&squares)?;
    if floor2 < 0.0 {
        // No floor: error^2 = noise^2 / N alone.
        let (sxy, sxx) = squares.iter().fold((0.0, 0.0), |(a, b), &(x, y, w)| (a + w * x * y, b + w * x * x));
        (floor2, noise2) = (0.0, sxy / sxx);
    }
    (per_sample > 0.0 && noise2 > 0.0).then(|| CostModel {
        start,
        per_sample,
        noise: noise2.sqrt(),
        floor: floor2.sqrt(),
        runs: used.len(),
    })
}
