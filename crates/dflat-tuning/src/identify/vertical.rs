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
//!
//! With the velocity across the rotor plane given ([`VerticalData::rotor`]:
//! `q = (v − n·(n·v))_z`, n = R·e3 the measured thrust axis, v the
//! positions' velocity), the rotor drag d_r joins 1/h as a second linear
//! parameter: `z̈ = g − (g/h)·c_f·cosθ·cosφ − d_r·q`, so
//! `z − ½g·t² = α + β·t − g·I₂/h − d_r·J₂` with J₂ the double integral of
//! q. A vehicle tilted into its motion has `q ≈ −v·sinθ·cosθ` (NED: up):
//! its rotor drag lifts it, which the thrust alone cannot explain.

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
    /// (time \[s\], `q = (v − n·(n·v))_z` \[m/s\]): the velocity across
    /// the rotor plane, vertical part, in time order; empty: no rotor drag
    /// fitted.
    pub rotor: Vec<(f64, f64)>,
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
    /// Rotor drag d_r \[1/s\] and its 95 % half-width, when
    /// [`VerticalData::rotor`] was given.
    pub drag_rotor: Option<super::Estimate>,
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

/// One chunk's columns with its affine part projected out: the target Ỹ,
/// the thrust's regressor X̃ (of 1/h) and the rotor drag's W̃ (of d_r;
/// empty without [`VerticalData::rotor`]).
type Chunk = (Vec<f64>, Vec<f64>, Vec<f64>);

/// Per chunk: (Ỹ, X̃, W̃).
fn projected(data: &VerticalData, tau_t: f64) -> Vec<Chunk> {
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
        // The rotor's double integral J₂ of q on the same grid.
        let rotor = !data.rotor.is_empty();
        let (mut j1, mut j2) = (0.0, 0.0);
        let mut q_prev = if rotor { interp(&data.rotor, a) } else { 0.0 };
        let mut j2_grid = Vec::with_capacity(if rotor { n } else { 0 });
        if rotor {
            j2_grid.push(0.0);
        }
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
            if rotor {
                let q = interp(&data.rotor, t);
                let j1_next = j1 + 0.5 * (q + q_prev) * GRID;
                j2 += 0.5 * (j1 + j1_next) * GRID;
                j1 = j1_next;
                q_prev = q;
                j2_grid.push(j2);
            }
        }
        let on_grid = |grid: &[f64], t: f64| {
            let x = ((t - a) / GRID).clamp(0.0, (n - 1) as f64);
            let k = (x.floor() as usize).min(n.saturating_sub(2));
            let f = x - k as f64;
            grid[k] * (1.0 - f) + grid[(k + 1).min(n - 1)] * f
        };
        let i2_at = |t: f64| on_grid(&i2_grid, t);
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
            let ws = if rotor {
                let ws: Vec<f64> = chunk.iter().map(|(t, _)| -on_grid(&j2_grid, *t)).collect();
                project(&ts, &ws)
            } else {
                Vec::new()
            };
            out.push((project(&ts, &ys), project(&ts, &xs), ws));
        }
    }
    out
}

/// The least-squares fit at one τ_T.
struct Solved {
    /// 1/h.
    beta: f64,
    /// d_r \[1/s\] (0 without the rotor column).
    rotor: f64,
    /// Residuals \[m\].
    r: Vec<f64>,
    /// Variances of (1/h, d_r) per unit residual variance: the diagonal
    /// of the normal matrix's inverse.
    var: [f64; 2],
    /// Σỹ².
    syy: f64,
}

/// (1/h, d_r) by least squares on the projected chunks at one τ_T.
fn solve(data: &VerticalData, tau_t: f64) -> Solved {
    let chunks = projected(data, tau_t);
    let rotor = !data.rotor.is_empty();
    let (mut sxx, mut sxw, mut sww, mut sxy, mut swy, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (y, x, w) in &chunks {
        for (j, (a, b)) in y.iter().zip(x).enumerate() {
            let c = if rotor { w[j] } else { 0.0 };
            sxx += b * b;
            sxw += b * c;
            sww += c * c;
            sxy += a * b;
            swy += a * c;
            syy += a * a;
        }
    }
    let det = sxx * sww - sxw * sxw;
    let (beta, d, var) = if rotor && det > 1e-12 * sxx * sww {
        (
            (sww * sxy - sxw * swy) / det,
            (sxx * swy - sxw * sxy) / det,
            [sww / det, sxx / det],
        )
    } else if sxx > 0.0 {
        (sxy / sxx, 0.0, [1.0 / sxx, f64::INFINITY])
    } else {
        (0.0, 0.0, [f64::INFINITY; 2])
    };
    let r = chunks
        .iter()
        .flat_map(|(y, x, w)| {
            y.iter()
                .zip(x)
                .enumerate()
                .map(move |(j, (a, b))| a - beta * b - if w.is_empty() { 0.0 } else { d * w[j] })
        })
        .collect();
    Solved {
        beta,
        rotor: d,
        r,
        var,
        syy,
    }
}

fn sse(data: &VerticalData, tau_t: f64) -> f64 {
    solve(data, tau_t).r.iter().map(|v| v * v).sum()
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
    let Solved {
        beta,
        rotor,
        r,
        var,
        syy,
    } = solve(data, tau_t);
    let n = r.len();
    if n < 50 || beta <= 0.0 || !beta.is_finite() {
        return None;
    }
    let whiteness = Whiteness::of(&r);
    let inflation = whiteness.inflation(n as f64 / 10.0);
    let s0: f64 = r.iter().map(|v| v * v).sum();
    let parameters = if data.rotor.is_empty() { 2 } else { 3 };
    let s2 = s0 / (n - parameters) as f64;
    let beta_sd = (s2 * inflation * var[0]).sqrt();
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
        drag_rotor: (!data.rotor.is_empty()).then(|| super::Estimate {
            value: rotor,
            ci: 1.96 * (s2 * inflation * var[1]).sqrt(),
        }),
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
        synthetic_rotor(h, tau_t, d, sigma, 0.0)
    }

    /// [`synthetic`] with rotor drag `d_r` \[1/s\]: the velocity across the
    /// rotor plane's vertical part swings as a vehicle's tilted into a
    /// motion that reverses every 6 s, `q = −3·sin(t)·|sin(π·t/6)|` [m/s],
    /// and the data carry it (at 50 Hz).
    fn synthetic_rotor(h: f64, tau_t: f64, d: f64, sigma: f64, d_r: f64) -> VerticalData {
        let q = |t: f64| -3.0 * t.sin() * (std::f64::consts::PI * t / 6.0).sin().abs();
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
            let a = g - g / h * cf * interp(&tilt_cos, t) - d_r * q(t);
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
            rotor: if d_r > 0.0 {
                (0..1000)
                    .map(|i| (i as f64 * 0.02, q(i as f64 * 0.02)))
                    .collect()
            } else {
                Vec::new()
            },
            delay: d,
            gravity: g,
        }
    }

    /// The rotor drag's lift is fitted beside the thrust: d_r and h come
    /// back (to 3 % and 0.5 %) with 2 cm of pose noise, the interval
    /// covers d_r; without the rotor column the same altitude gives a
    /// worse fit and the hover thrust further off.
    #[test]
    fn recovers_the_rotor_drag_beside_the_hover_thrust() {
        for d_r in [0.2, 0.5] {
            let data = synthetic_rotor(0.42, 0.04, 0.04, 0.02, d_r);
            let fit = fit_vertical(&data).unwrap();
            let e = fit.drag_rotor.expect("rotor fitted");
            assert!((e.value - d_r).abs() < 0.03 * d_r, "{fit:?}");
            assert!((e.value - d_r).abs() <= e.ci && e.ci < 0.2 * d_r, "{fit:?}");
            assert!((fit.hover_thrust - 0.42).abs() < 0.005 * 0.42, "{fit:?}");
            let without = fit_vertical(&VerticalData {
                rotor: Vec::new(),
                ..data
            })
            .unwrap();
            assert!(without.drag_rotor.is_none());
            assert!(without.rms > 2.0 * fit.rms, "{without:?} against {fit:?}");
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
