//! Small numerical helpers of the fits: a 1-D minimiser, residual
//! statistics and the confidence intervals of a least-squares fit.

use nalgebra::DMatrix;
use serde::Serialize;

/// Minimises `f` on `[lo, hi]` by golden-section search (`iters` steps);
/// returns the best point seen and its value.
pub fn golden(mut f: impl FnMut(f64) -> f64, lo: f64, hi: f64, iters: usize) -> (f64, f64) {
    let r = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (lo, hi);
    let mut c = b - r * (b - a);
    let mut d = a + r * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..iters {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - r * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + r * (b - a);
            fd = f(d);
        }
    }
    if fc < fd { (c, fc) } else { (d, fd) }
}

/// Sample autocorrelation of `r` at `lag` (0 when undefined).
pub fn autocorrelation(r: &[f64], lag: usize) -> f64 {
    let n = r.len();
    if n <= lag + 1 {
        return 0.0;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    let var: f64 = r.iter().map(|v| (v - mean).powi(2)).sum();
    if var <= 0.0 {
        return 0.0;
    }
    let cov: f64 = (lag..n).map(|i| (r[i] - mean) * (r[i - lag] - mean)).sum();
    cov / var
}

/// Lags of the Ljung–Box statistic.
pub const LJUNG_BOX_LAGS: usize = 20;
/// χ²(20) at 95 %: residuals with Q below this pass as white.
pub const LJUNG_BOX_CRITICAL: f64 = 31.41;

/// How white a fit's residuals are.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Whiteness {
    /// Lag-1 autocorrelation ρ₁.
    pub lag1: f64,
    /// Ljung–Box Q over [`LJUNG_BOX_LAGS`] lags.
    pub ljung_box: f64,
    /// `ljung_box` < [`LJUNG_BOX_CRITICAL`].
    pub white: bool,
}

impl Whiteness {
    /// The statistics of residuals `r` (in time order).
    pub fn of(r: &[f64]) -> Self {
        let n = r.len() as f64;
        let q = (1..=LJUNG_BOX_LAGS)
            .filter(|k| *k < r.len())
            .map(|k| autocorrelation(r, k).powi(2) / (n - k as f64))
            .sum::<f64>()
            * n
            * (n + 2.0);
        Self {
            lag1: autocorrelation(r, 1),
            ljung_box: q,
            white: q < LJUNG_BOX_CRITICAL,
        }
    }

    /// Variance inflation of correlated residuals, (1 + ρ₁)/(1 − ρ₁) (AR(1)
    /// model), at least 1 and at most `max`.
    pub fn inflation(&self, max: f64) -> f64 {
        let rho = self.lag1.clamp(0.0, 0.999);
        ((1.0 + rho) / (1.0 - rho)).clamp(1.0, max.max(1.0))
    }
}

/// 1 − SSE / Σ(y − ȳ)² (0 when `y` has no variance).
pub fn variance_explained(y: &[f64], residuals: &[f64]) -> f64 {
    let n = y.len().max(1) as f64;
    let mean = y.iter().sum::<f64>() / n;
    let total: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
    let sse: f64 = residuals.iter().map(|r| r * r).sum();
    if total > 0.0 { 1.0 - sse / total } else { 0.0 }
}

/// 95 % half-widths of the parameters of a least-squares fit at `theta`:
/// Jacobian of `residuals` by central differences (`steps`), covariance
/// s²·(JᵀJ)⁻¹ inflated by `inflation` (correlated residuals). `None` when
/// JᵀJ is singular.
pub fn confidence_95(
    residuals: &dyn Fn(&[f64]) -> Vec<f64>,
    theta: &[f64],
    steps: &[f64],
    inflation: f64,
) -> Option<Vec<f64>> {
    let r0 = residuals(theta);
    let n = r0.len();
    let p = theta.len();
    if n <= p {
        return None;
    }
    let mut j = DMatrix::<f64>::zeros(n, p);
    for k in 0..p {
        let mut hi = theta.to_vec();
        let mut lo = theta.to_vec();
        hi[k] += steps[k];
        lo[k] -= steps[k];
        let (rh, rl) = (residuals(&hi), residuals(&lo));
        if rh.len() != n || rl.len() != n {
            return None;
        }
        for i in 0..n {
            j[(i, k)] = (rh[i] - rl[i]) / (2.0 * steps[k]);
        }
    }
    let s2 = r0.iter().map(|r| r * r).sum::<f64>() / (n - p) as f64;
    let cov = (j.transpose() * &j).try_inverse()? * (s2 * inflation);
    let out: Vec<f64> = (0..p).map(|k| 1.96 * cov[(k, k)].max(0.0).sqrt()).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_finds_a_parabola_minimum() {
        let (x, fx) = golden(|x| (x - 0.3).powi(2) + 1.0, -1.0, 2.0, 60);
        assert!((x - 0.3).abs() < 1e-6 && (fx - 1.0).abs() < 1e-9);
    }

    #[test]
    fn whiteness_tells_noise_from_a_trend() {
        // A deterministic "white" sequence (xorshift) and a smooth one.
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let noise: Vec<f64> = (0..2000)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        let smooth: Vec<f64> = (0..2000).map(|i| (i as f64 * 0.01).sin()).collect();
        let w = Whiteness::of(&noise);
        assert!(w.white && w.lag1.abs() < 0.1, "{w:?}");
        let w = Whiteness::of(&smooth);
        assert!(!w.white && w.lag1 > 0.9, "{w:?}");
        assert!(w.inflation(1e9) > 10.0);
    }

    #[test]
    fn confidence_of_a_line_fit_matches_the_textbook() {
        // y = a·x with residuals ±e alternating: sd(a) = s/√Σx².
        let x: Vec<f64> = (1..=10).map(f64::from).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, x)| 2.0 * x + if i % 2 == 0 { 0.1 } else { -0.1 })
            .collect();
        let sxx: f64 = x.iter().map(|v| v * v).sum();
        let a = x.iter().zip(&y).map(|(x, y)| x * y).sum::<f64>() / sxx;
        let res = |t: &[f64]| x.iter().zip(&y).map(|(x, y)| y - t[0] * x).collect();
        let ci = confidence_95(&res, &[a], &[1e-4], 1.0).unwrap();
        let r: Vec<f64> = res(&[a]);
        let s2 = r.iter().map(|v| v * v).sum::<f64>() / 9.0;
        assert!((ci[0] - 1.96 * (s2 / sxx).sqrt()).abs() < 1e-9);
    }
}
