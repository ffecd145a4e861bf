//! The vertical motion of the spatial model: hover thrust h and thrust
//! time constant τ_T from the commanded normalised thrust c, the measured
//! tilt and the measured altitude z (NED, down):
//!
//! ```text
//! z̈ = g − (g/h)·c_f(t)·cosθ·cosφ,   ċ_f = (c(t − d) − c_f)/τ_T
//! ```
//!
//! For a given τ_T, z is linear in 1/h plus an affine term per chunk
//! (initial altitude and climb rate): with I₂ the double integral of
//! `c_f·cosθ·cosφ`, `z − ½g·t² = α + β·t − g·I₂(t)/h`. The affine part is
//! projected out per chunk and 1/h follows in closed form; τ_T by
//! golden-section search on ln τ_T.

use serde::Serialize;

use super::drag::project;
use super::stats::{Whiteness, golden};

/// Range of τ_T searched \[s\].
pub const TAU_THRUST_RANGE: (f64, f64) = (0.005, 1.0);
/// Integration grid of c_f and its integrals \[s\].
const GRID: f64 = 0.002;

/// The data of one engaged segment, in time order.
#[derive(Debug, Clone, Default)]
pub struct VerticalSegment {
    /// Segment start and end \[s\].
    pub span: (f64, f64),
    /// Chunks of (time \[s\], z \[m\]) samples, each with its own initial
    /// altitude and climb rate.
    pub chunks: Vec<Vec<(f64, f64)>>,
}

/// Everything the vertical fit reads.
#[derive(Debug, Clone, Default)]
pub struct VerticalData {
    /// (time \[s\], normalised thrust command): each held until the next.
    pub thrust: Vec<(f64, f64)>,
    /// (time \[s\], cosθ·cosφ) from the measured attitude.
    pub tilt_cos: Vec<(f64, f64)>,
    /// Segments with position samples.
    pub segments: Vec<VerticalSegment>,
    /// Pure delay of the commands \[s\] (the attitude fit's).
    pub delay: f64,
    /// Gravity \[m/s²\].
    pub gravity: f64,
}

/// The fitted vertical parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct VerticalFit {
    /// Hover thrust h (normalised).
    pub hover_thrust: f64,
    /// 95 % half-width of h.
    pub hover_thrust_ci: f64,
    /// Thrust time constant τ_T \[s\].
    pub tau_thrust: f64,
    /// 95 % half-width of τ_T \[s\] (infinite when the data do not
    /// determine it).
    pub tau_thrust_ci: f64,
    /// Position samples fitted.
    pub samples: usize,
    /// Share of the altitude's variance (after each chunk's straight line)
    /// the thrust explains.
    pub variance_explained: f64,
    /// RMS of the residuals \[m\].
    pub rms: f64,
    /// Residual whiteness.
    pub whiteness: Whiteness,
}

fn interp(series: &[(f64, f64)], t: f64) -> f64 {
    let i = series.partition_point(|(s, _)| *s <= t);
    match (i.checked_sub(1).map(|j| series[j]), series.get(i)) {
        (Some((t0, v0)), Some(&(t1, v1))) if t1 > t0 => v0 + (v1 - v0) * (t - t0) / (t1 - t0),
        (Some((_, v)), _) | (None, Some(&(_, v))) => v,
        (None, None) => 1.0,
    }
}

fn held(series: &[(f64, f64)], t: f64) -> f64 {
    let i = series.partition_point(|(s, _)| *s <= t);
    if i > 0 {
        series[i - 1].1
    } else {
        series.first().map_or(0.0, |s| s.1)
    }
}

/// Per chunk: (Ỹ, X̃) with the chunk's affine part projected out.
fn projected(data: &VerticalData, tau_t: f64) -> Vec<(Vec<f64>, Vec<f64>)> {
    let g = data.gravity;
    let mut out = Vec::new();
    for seg in &data.segments {
        let (a, b) = seg.span;
        let n = ((b - a) / GRID).ceil() as usize + 1;
        let e = (-GRID / tau_t).exp();
        let mut cf = held(&data.thrust, a - data.delay);
        let (mut i1, mut i2) = (0.0, 0.0);
        let mut w_prev = cf * interp(&data.tilt_cos, a);
        let mut i2_grid = Vec::with_capacity(n);
        i2_grid.push(0.0);
        for k in 1..n {
            let t = a + k as f64 * GRID;
            let c = held(&data.thrust, t - GRID / 2.0 - data.delay);
            cf = c + (cf - c) * e;
            let w = cf * interp(&data.tilt_cos, t);
            let i1_next = i1 + 0.5 * (w + w_prev) * GRID;
            i2 += 0.5 * (i1 + i1_next) * GRID;
            i1 = i1_next;
            w_prev = w;
            i2_grid.push(i2);
        }
        let i2_at = |t: f64| {
            let x = ((t - a) / GRID).clamp(0.0, (n - 1) as f64);
            let k = (x.floor() as usize).min(n.saturating_sub(2));
            let f = x - k as f64;
            i2_grid[k] * (1.0 - f) + i2_grid[(k + 1).min(n - 1)] * f
        };
        for chunk in &seg.chunks {
            if chunk.len() < 5 {
                continue;
            }
            let t0 = chunk[0].0;
            let ys: Vec<f64> = chunk
                .iter()
                .map(|(t, z)| z - 0.5 * g * (t - t0).powi(2))
                .collect();
            let xs: Vec<f64> = chunk.iter().map(|(t, _)| -g * i2_at(*t)).collect();
            let ts: Vec<f64> = chunk.iter().map(|(t, _)| t - t0).collect();
            out.push((project(&ts, &ys), project(&ts, &xs)));
        }
    }
    out
}

/// (1/h, residuals, Σx̃², Σỹ²) for one τ_T.
fn solve(data: &VerticalData, tau_t: f64) -> (f64, Vec<f64>, f64, f64) {
    let chunks = projected(data, tau_t);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for (y, x) in &chunks {
        for (a, b) in y.iter().zip(x) {
            sxx += b * b;
            sxy += a * b;
            syy += a * a;
        }
    }
    let beta = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let r = chunks
        .iter()
        .flat_map(|(y, x)| y.iter().zip(x).map(move |(a, b)| a - beta * b))
        .collect();
    (beta, r, sxx, syy)
}

fn sse(data: &VerticalData, tau_t: f64) -> f64 {
    solve(data, tau_t).1.iter().map(|v| v * v).sum()
}

/// Fits hover thrust and τ_T. `None` with fewer than 50 samples or when
/// the thrust does not explain the altitude (1/h not positive).
pub fn fit_vertical(data: &VerticalData) -> Option<VerticalFit> {
    let (ln_tau, _) = golden(
        |l| sse(data, l.exp()),
        TAU_THRUST_RANGE.0.ln(),
        TAU_THRUST_RANGE.1.ln(),
        40,
    );
    let tau_t = ln_tau.exp();
    let (beta, r, sxx, syy) = solve(data, tau_t);
    let n = r.len();
    if n < 50 || beta <= 0.0 || !beta.is_finite() {
        return None;
    }
    let whiteness = Whiteness::of(&r);
    let inflation = whiteness.inflation(n as f64 / 10.0);
    let s0: f64 = r.iter().map(|v| v * v).sum();
    let s2 = s0 / (n - 2) as f64;
    let beta_sd = (s2 * inflation / sxx).sqrt();
    let hover = 1.0 / beta;
    // τ_T from the curvature of the profile SSE (1/h re-fitted).
    let dt = 0.05 * tau_t;
    let curvature =
        (sse(data, tau_t + dt) - 2.0 * s0 + sse(data, (tau_t - dt).max(1e-4))) / (dt * dt);
    let tau_ci = if curvature > 0.0 {
        1.96 * (2.0 * s2 * inflation / curvature).sqrt()
    } else {
        f64::INFINITY
    };
    Some(VerticalFit {
        hover_thrust: hover,
        hover_thrust_ci: 1.96 * beta_sd * hover * hover,
        tau_thrust: tau_t,
        tau_thrust_ci: tau_ci,
        samples: n,
        variance_explained: if syy > 0.0 { 1.0 - s0 / syy } else { 0.0 },
        rms: (s0 / n as f64).sqrt(),
        whiteness,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Altitude of a vehicle with hover h, lag τ_T and delay d under a
    /// thrust command that steps every 0.5 s, at 50 Hz, with ±σ noise.
    fn synthetic(h: f64, tau_t: f64, d: f64, sigma: f64) -> VerticalData {
        let g = 9.81;
        let thrust: Vec<(f64, f64)> = (0..1000)
            .map(|i| {
                let t = i as f64 * 0.02;
                (
                    t,
                    h * (1.0 + 0.08 * ((t * 2.0).floor() as i64 % 3 - 1) as f64),
                )
            })
            .collect();
        let tilt_cos: Vec<(f64, f64)> = (0..1000)
            .map(|i| (i as f64 * 0.02, (0.1 * (i as f64 * 0.01).sin()).cos()))
            .collect();
        let (mut z, mut v, mut cf) = (-10.0, 0.0, h);
        let dt = 0.0005;
        let mut samples = Vec::new();
        let mut s = 0x1234_5678u64;
        let mut t = 0.0;
        let mut next = 0.0;
        while t < 19.0 {
            if t >= next - 1e-9 {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let noise = sigma * ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 3.46;
                samples.push((t, z + noise));
                next += 0.02;
            }
            let c = held(&thrust, t - d);
            cf += (c - cf) / tau_t * dt;
            let a = g - g / h * cf * interp(&tilt_cos, t);
            z += v * dt + 0.5 * a * dt * dt;
            v += a * dt;
            t += dt;
        }
        VerticalData {
            thrust,
            tilt_cos,
            segments: vec![VerticalSegment {
                span: (0.0, 19.0),
                chunks: samples.chunks(150).map(<[_]>::to_vec).collect(),
            }],
            delay: d,
            gravity: g,
        }
    }

    #[test]
    fn recovers_hover_thrust_and_lag() {
        for (h, tau_t) in [(0.42, 0.04), (0.6, 0.15)] {
            let fit = fit_vertical(&synthetic(h, tau_t, 0.04, 0.0)).unwrap();
            assert!((fit.hover_thrust - h).abs() < 0.002 * h, "{fit:?}");
            assert!((fit.tau_thrust - tau_t).abs() < 0.1 * tau_t, "{fit:?}");
            assert!(fit.variance_explained > 0.99, "{fit:?}");
        }
    }

    #[test]
    fn noise_widens_the_interval_but_keeps_the_hover_thrust() {
        let fit = fit_vertical(&synthetic(0.42, 0.04, 0.04, 0.02)).unwrap();
        assert!((fit.hover_thrust - 0.42).abs() < 0.01, "{fit:?}");
        assert!(
            fit.hover_thrust_ci > 0.0 && fit.hover_thrust_ci < 0.02,
            "{fit:?}"
        );
    }
}
