//! Summary metrics of a trial: pure functions of its logs.
//!
//! Definitions:
//!
//! * **mae / rms / mae_after** (fixed target, paper §VI, the reference
//!   trace's `mae`): over the plant-rate trace at `t ∈ [0, T)` of the TRUE
//!   position, `mean ‖e‖`, `√mean ‖e‖²`, and `mean ‖e‖` over `t ≥ after`,
//!   with `e = p − target` restricted to the selected axes (x only in 1-D:
//!   `mean |x − x_ref|`).
//! * **path error** (paper §VII-C): per tick, the distance of the TRUE
//!   position to the reference path; median, 95th percentile (linear
//!   interpolation between order statistics), max, mean.
//! * **max tilt**: the largest angle of the thrust axis from vertical,
//!   `acos(cosθ·cosφ)`, over the plant-rate trace \[deg\].
//! * **command smoothness**: mean over ticks k ≥ 1 of the Euclidean norm
//!   `√(Δθ_cmd² + Δφ_cmd²)` of the change in the command sent to the plant
//!   [deg per tick]; the per-axis alternative `max(|Δθ|, |Δφ|)` is reported
//!   too. Held commands count (Δ = 0).
//! * **saturation share**: the share of ticks where the controller or the
//!   plant clipped the command.

use serde::{Deserialize, Serialize};

use super::{FixedTarget, PlantSample, TickRecord, TickStatus};

/// Order statistics of an error sample \[m\].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Number of values.
    pub count: usize,
    /// Mean.
    pub mean: f64,
    /// Median (0.5 quantile).
    pub median: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Maximum.
    pub max: f64,
}

impl ErrorStats {
    /// Statistics of the finite values of `values`; None when there are none.
    pub fn from_values(values: impl IntoIterator<Item = f64>) -> Option<Self> {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some(Self {
            count: v.len(),
            mean: v.iter().sum::<f64>() / v.len() as f64,
            median: quantile(&v, 0.5),
            p95: quantile(&v, 0.95),
            max: v[v.len() - 1],
        })
    }
}

/// The `q`-quantile (0 ≤ q ≤ 1) of ascending `sorted` values, linearly
/// interpolated between order statistics (type 7); NaN when empty.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let h = q.clamp(0.0, 1.0) * (n - 1) as f64;
            let lo = h.floor() as usize;
            let hi = (lo + 1).min(n - 1);
            sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
        }
    }
}

/// Fixed-target errors over a plant-rate trace: `(mae, rms, mae_after)` \[m\]
/// as defined in the module docs; None where no sample falls in the window.
pub fn fixed_target_error(
    trace: &[PlantSample],
    target: &FixedTarget,
) -> (Option<f64>, Option<f64>, Option<f64>) {
    let (mut sum, mut sum2, mut n) = (0.0, 0.0, 0usize);
    let (mut sum_after, mut n_after) = (0.0, 0usize);
    for s in trace {
        let e = target.error(&s.position).norm();
        sum += e;
        sum2 += e * e;
        n += 1;
        if s.t >= target.after - 1e-12 {
            sum_after += e;
            n_after += 1;
        }
    }
    let mean = |s: f64, n: usize| (n > 0).then(|| s / n as f64);
    (
        mean(sum, n),
        mean(sum2, n).map(f64::sqrt),
        mean(sum_after, n_after),
    )
}

/// Path-error statistics over the ticks' `path_error` (finite values only).
pub fn path_error_stats(ticks: &[TickRecord]) -> Option<ErrorStats> {
    ErrorStats::from_values(ticks.iter().map(|r| r.path_error))
}

/// Largest tilt of the thrust axis from vertical over the trace \[deg\]
/// (0 for an empty trace; non-finite samples are skipped).
pub fn max_tilt_deg(trace: &[PlantSample]) -> f64 {
    trace
        .iter()
        .map(|s| s.tilt().to_degrees())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
}

/// Command smoothness `(euclidean, axis_max)` [deg per tick]: the mean over
/// ticks k ≥ 1 of `√(Δθ² + Δφ²)` and of `max(|Δθ|, |Δφ|)` of the sent
/// command; (0, 0) with fewer than two ticks.
pub fn command_smoothness(ticks: &[TickRecord]) -> (f64, f64) {
    if ticks.len() < 2 {
        return (0.0, 0.0);
    }
    let (mut euclid, mut axis) = (0.0, 0.0);
    for w in ticks.windows(2) {
        let dp = (w[1].command.pitch - w[0].command.pitch).to_degrees();
        let dr = (w[1].command.roll - w[0].command.roll).to_degrees();
        euclid += dp.hypot(dr);
        axis += dp.abs().max(dr.abs());
    }
    let n = (ticks.len() - 1) as f64;
    (euclid / n, axis / n)
}

/// Share of ticks at saturation (controller or plant clipped) [0, 1]; 0
/// for no ticks.
pub fn saturation_share(ticks: &[TickRecord]) -> f64 {
    if ticks.is_empty() {
        return 0.0;
    }
    let n = ticks
        .iter()
        .filter(|r| r.ctrl_saturated || r.plant_saturated)
        .count();
    n as f64 / ticks.len() as f64
}

/// Summary metrics of one trial (see the module docs for definitions).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Simulated time flown \[s\] (ticks · δt).
    pub duration: f64,
    /// Number of control ticks.
    pub ticks: usize,
    /// Mean fixed-target error \[m\] (None without a target).
    pub mae: Option<f64>,
    /// RMS fixed-target error \[m\].
    pub rms: Option<f64>,
    /// Mean fixed-target error after `FixedTarget::after` \[m\].
    pub mae_after: Option<f64>,
    /// Path-error statistics \[m\] (None without a path distance).
    pub path_error: Option<ErrorStats>,
    /// Largest tilt \[deg\].
    pub max_tilt_deg: f64,
    /// Mean Euclidean change of the (pitch, roll) command per tick \[deg\].
    pub smoothness_deg: f64,
    /// Mean per-axis max change of the (pitch, roll) command per tick \[deg\].
    pub smoothness_axis_max_deg: f64,
    /// Share of ticks at saturation [0, 1].
    pub saturation_share: f64,
    /// Controller errors (ticks that held the previous command).
    pub controller_errors: usize,
    /// Ticks without a measurement yet.
    pub no_measurement_ticks: usize,
    /// The error bound was exceeded or the state went non-finite.
    pub diverged: bool,
    /// Time of the first diverged tick \[s\].
    pub diverged_at: Option<f64>,
}

impl Metrics {
    /// Computes the metrics from a trial's logs.
    pub fn compute(
        ticks: &[TickRecord],
        trace: &[PlantSample],
        target: Option<&FixedTarget>,
        ctrl_dt: f64,
        controller_errors: usize,
        diverged_at: Option<f64>,
    ) -> Self {
        let (mae, rms, mae_after) =
            target.map_or((None, None, None), |t| fixed_target_error(trace, t));
        let (smoothness_deg, smoothness_axis_max_deg) = command_smoothness(ticks);
        Self {
            duration: ticks.len() as f64 * ctrl_dt,
            ticks: ticks.len(),
            mae,
            rms,
            mae_after,
            path_error: path_error_stats(ticks),
            max_tilt_deg: max_tilt_deg(trace),
            smoothness_deg,
            smoothness_axis_max_deg,
            saturation_share: saturation_share(ticks),
            controller_errors,
            no_measurement_ticks: ticks
                .iter()
                .filter(|r| r.status == TickStatus::NoMeasurement)
                .count(),
            diverged: diverged_at.is_some(),
            diverged_at,
        }
    }
}
