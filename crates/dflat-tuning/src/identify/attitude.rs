//! One attitude axis: the first-order response with a pure delay,
//! `ẏ(t) = (k̃·u(t − d) + b − y(t))/τ`, fitted to commands `u` (held
//! between samples) and measured angles `y`.
//!
//! For a given (τ, d) the response is linear in (k̃, b) once the initial
//! angle of each chunk is taken from its first sample: the simulation is
//! exact for held commands (exponentials between switch and sample
//! instants), and (k̃, b) follow from a 2×2 least-squares problem
//! (variable projection). τ is found by golden-section search on ln τ for
//! each delay of a grid, the best delay refined the same way.

use serde::Serialize;

use super::stats::{Whiteness, confidence_95, golden, variance_explained};

/// Range of τ searched \[s\].
pub const TAU_RANGE: (f64, f64) = (0.01, 3.0);
/// Range of delays searched \[s\].
pub const DELAY_RANGE: (f64, f64) = (0.0, 0.3);
/// Delay grid step before refinement \[s\].
const DELAY_GRID: f64 = 0.005;

/// The data of one axis, in time order.
#[derive(Debug, Clone, Default)]
pub struct AxisData {
    /// (time \[s\], command \[rad\]): each held until the next.
    pub commands: Vec<(f64, f64)>,
    /// Chunks of (time \[s\], measured angle \[rad\]) samples; each chunk is
    /// simulated from its own first sample.
    pub chunks: Vec<Vec<(f64, f64)>>,
}

/// The fitted parameters of one axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AxisFit {
    /// Time constant τ \[s\].
    pub tau: f64,
    /// 95 % half-width of τ \[s\].
    pub tau_ci: f64,
    /// Gain k̃ \[-\].
    pub gain: f64,
    /// 95 % half-width of k̃.
    pub gain_ci: f64,
    /// Pure delay d \[s\].
    pub delay: f64,
    /// 95 % half-width of d \[s\].
    pub delay_ci: f64,
    /// Attitude offset b \[rad\] (trim).
    pub bias: f64,
    /// Samples fitted.
    pub samples: usize,
    /// Share of the angle's variance the model explains.
    pub variance_explained: f64,
    /// RMS of the residuals \[rad\].
    pub rms: f64,
    /// Residual whiteness.
    pub whiteness: Whiteness,
}

/// Per-sample regressors of one (τ, d): (target y − y₀·e, G, H), with
/// ŷ = y₀·e + k̃·G + b·H.
fn regressors(data: &AxisData, tau: f64, delay: f64) -> Vec<(f64, f64, f64)> {
    let mut out = Vec::new();
    let cmds = &data.commands;
    for chunk in &data.chunks {
        let Some(&(t0, y0)) = chunk.first() else {
            continue;
        };
        // The command in force at t0 − d, and the index of the next switch.
        let mut next = cmds.partition_point(|(s, _)| *s + delay <= t0);
        let mut u = if next > 0 { cmds[next - 1].1 } else { 0.0 };
        let (mut g, mut h, mut now) = (0.0, 0.0, t0);
        let advance = |to: f64, u: f64, g: &mut f64, h: &mut f64, now: &mut f64| {
            let e = (-(to - *now) / tau).exp();
            *g = u + (*g - u) * e;
            *h = 1.0 + (*h - 1.0) * e;
            *now = to;
        };
        for &(t, y) in &chunk[1..] {
            while next < cmds.len() && cmds[next].0 + delay <= t {
                let at = cmds[next].0 + delay;
                advance(at, u, &mut g, &mut h, &mut now);
                u = cmds[next].1;
                next += 1;
            }
            advance(t, u, &mut g, &mut h, &mut now);
            let e = (-(t - t0) / tau).exp();
            out.push((y - y0 * e, g, h));
        }
    }
    out
}

/// The least-squares (k̃, b) of regressors and the residuals.
fn solve_linear(reg: &[(f64, f64, f64)]) -> ([f64; 2], Vec<f64>) {
    let (mut gg, mut gh, mut hh, mut gz, mut hz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(z, g, h) in reg {
        gg += g * g;
        gh += g * h;
        hh += h * h;
        gz += g * z;
        hz += h * z;
    }
    // A whisker of ridge keeps b = 0 when H carries no information.
    let hh = hh + 1e-9 * (gg + hh + 1e-12);
    let det = gg * hh - gh * gh;
    let (k, b) = if det.abs() > 1e-300 {
        ((gz * hh - hz * gh) / det, (gg * hz - gh * gz) / det)
    } else {
        (0.0, 0.0)
    };
    let r = reg.iter().map(|&(z, g, h)| z - k * g - b * h).collect();
    ([k, b], r)
}

/// Residuals of the full parameter vector (τ, d, k̃, b).
fn residuals(data: &AxisData, theta: &[f64]) -> Vec<f64> {
    regressors(data, theta[0], theta[1])
        .iter()
        .map(|&(z, g, h)| z - theta[2] * g - theta[3] * h)
        .collect()
}

fn sse(data: &AxisData, tau: f64, delay: f64) -> f64 {
    let (_, r) = solve_linear(&regressors(data, tau, delay));
    r.iter().map(|v| v * v).sum()
}

/// The best τ for a delay: (τ, SSE).
fn best_tau(data: &AxisData, delay: f64) -> (f64, f64) {
    let (ln_tau, s) = golden(
        |ln_tau| sse(data, ln_tau.exp(), delay),
        TAU_RANGE.0.ln(),
        TAU_RANGE.1.ln(),
        40,
    );
    (ln_tau.exp(), s)
}

/// Fits one axis. `None` when there are fewer than 20 samples.
pub fn fit_axis(data: &AxisData) -> Option<AxisFit> {
    let n: usize = data.chunks.iter().map(|c| c.len().saturating_sub(1)).sum();
    if n < 20 || data.commands.is_empty() {
        return None;
    }
    let steps = ((DELAY_RANGE.1 - DELAY_RANGE.0) / DELAY_GRID).round() as usize;
    let (mut delay, mut best) = (DELAY_RANGE.0, f64::INFINITY);
    for i in 0..=steps {
        let d = DELAY_RANGE.0 + i as f64 * DELAY_GRID;
        let (_, s) = best_tau(data, d);
        if s < best {
            (delay, best) = (d, s);
        }
    }
    let (d, _) = golden(
        |d| best_tau(data, d).1,
        (delay - DELAY_GRID).max(DELAY_RANGE.0),
        (delay + DELAY_GRID).min(DELAY_RANGE.1),
        30,
    );
    delay = d;
    let (tau, _) = best_tau(data, delay);
    let reg = regressors(data, tau, delay);
    let ([gain, bias], r) = solve_linear(&reg);
    // The measured angles in the residuals' order (each chunk's first
    // sample is the initial condition, not fitted).
    let targets: Vec<f64> = data
        .chunks
        .iter()
        .filter(|c| !c.is_empty())
        .flat_map(|c| c[1..].iter().map(|(_, y)| *y))
        .collect();
    let whiteness = Whiteness::of(&r);
    let theta = [tau, delay, gain, bias];
    let ci = confidence_95(
        &|t: &[f64]| residuals(data, t),
        &theta,
        &[tau * 1e-3, 5e-4, gain.abs().max(0.1) * 1e-4, 1e-5],
        whiteness.inflation(n as f64 / 10.0),
    )
    .unwrap_or(vec![f64::INFINITY; 4]);
    let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt();
    Some(AxisFit {
        tau,
        tau_ci: ci[0],
        gain,
        gain_ci: ci[2],
        delay,
        delay_ci: ci[1],
        bias,
        samples: n,
        variance_explained: variance_explained(&targets, &r),
        rms,
        whiteness,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A plant with τ, k̃, d and bias b driven by a held command that
    /// switches every `hold` seconds, integrated finely, sampled at 50 Hz.
    fn synthetic(tau: f64, k: f64, d: f64, b: f64, seed: u64) -> AxisData {
        let mut s = seed | 1;
        let mut rnd = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let dt = 0.001;
        let commands: Vec<(f64, f64)> = (0..1000)
            .map(|i| (i as f64 * 0.02, 0.3 * rnd() + 0.1 * (i as f64 * 0.05).sin()))
            .collect();
        let u_at = |t: f64| {
            let i = commands.partition_point(|(s, _)| *s <= t);
            if i == 0 { 0.0 } else { commands[i - 1].1 }
        };
        let mut y = b;
        let mut samples = Vec::new();
        let mut t = 0.0;
        let mut next_sample = 0.0;
        while t < 19.9 {
            if t >= next_sample - 1e-9 {
                samples.push((t, y));
                next_sample += 0.02;
            }
            // Exact step for the held command over dt.
            let u = u_at(t - d);
            let e = (-dt / tau).exp();
            y = (k * u + b) + (y - (k * u + b)) * e;
            t += dt;
        }
        let chunks = samples.chunks(250).map(<[_]>::to_vec).collect();
        AxisData { commands, chunks }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(12))]
        #[test]
        fn recovers_tau_gain_and_delay(
            tau in 0.08f64..0.6,
            k in 0.6f64..1.4,
            d in 0.0f64..0.12,
            b in -0.02f64..0.02,
            seed in 1u64..1000,
        ) {
            let fit = fit_axis(&synthetic(tau, k, d, b, seed)).unwrap();
            prop_assert!((fit.tau - tau).abs() < 0.02 * tau + 0.002, "{fit:?} vs τ {tau}");
            prop_assert!((fit.gain - k).abs() < 0.01 * k, "{fit:?} vs k {k}");
            prop_assert!((fit.delay - d).abs() < 0.003, "{fit:?} vs d {d}");
            prop_assert!(fit.variance_explained > 0.999, "{fit:?}");
            prop_assert!(fit.tau_ci.is_finite() && fit.delay_ci.is_finite());
        }
    }

    #[test]
    fn too_few_samples_is_none() {
        let mut data = synthetic(0.2, 1.0, 0.0, 0.0, 3);
        data.chunks = vec![data.chunks[0][..10].to_vec()];
        assert!(fit_axis(&data).is_none());
    }
}
