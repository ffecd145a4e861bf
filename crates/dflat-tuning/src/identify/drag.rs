//! Linear drag from the horizontal motion: the acceleration that the
//! measured tilt does not explain, against the velocity.
//!
//! Model (local NED, horizontal axes, the planar model's acceleration at
//! the measured attitude):
//!
//! ```text
//! v̇_h = a_att(t) − D·v_h + c,   a_att = −g·(R13, R23)/R33
//! ```
//!
//! with D the horizontal drag \[1/s\] and c a constant offset per axis (wind,
//! attitude bias). Integrated twice over a chunk of samples (initial
//! position and velocity unknown per chunk):
//!
//! ```text
//! x(t) − I₂[a_att](t) = α + β·t − D·I₁[x](t) + c·t²/2
//! ```
//!
//! with I₁\[x\] the integral of the measured position (no differentiation of
//! noisy positions anywhere) and I₂ the double integral of a_att. The
//! affine part is projected out per chunk and (D, c_x, c_y) follow by
//! linear least squares over both axes.
//!
//! The thrust: with the vertical fit's thrust model ([`ThrustModel`]: the
//! commanded thrust, delayed and lagged by τ_T, over the hover thrust)
//! `a_att = −T·(R13, R23)` with `T = g·c_f/h`; without it (a planar
//! flight) the altitude is taken as held (`T·R33 = g`), and climbs add an
//! error of the order of z̈/g (11 % on the identification manoeuvre's
//! ±1.5 m steps).

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use super::stats::Whiteness;

/// Integration grid \[s\].
const GRID: f64 = 0.002;

/// One engaged segment's horizontal positions.
#[derive(Debug, Clone, Default)]
pub struct DragSegment {
    /// Segment start and end \[s\].
    pub span: (f64, f64),
    /// Chunks of (time \[s\], [north, east] \[m\]), each with its own initial
    /// position and velocity.
    pub chunks: Vec<Vec<(f64, [f64; 2])>>,
}

/// The specific thrust the vertical fit found: `T(t) = g·c_f(t)/h`, with
/// `c_f` the commanded normalised thrust delayed by `delay` and lagged by
/// `tau_thrust` (the vertical fit's model).
#[derive(Debug, Clone, Default)]
pub struct ThrustModel {
    /// (send time \[s\], normalised thrust) commanded, in time order.
    pub commands: Vec<(f64, f64)>,
    /// Hover thrust h (normalised, > 0).
    pub hover_thrust: f64,
    /// Thrust lag τ_T \[s\] (> 0).
    pub tau_thrust: f64,
    /// Pure delay of the command \[s\].
    pub delay: f64,
}

impl ThrustModel {
    /// The commanded thrust in effect at `t` (held between commands).
    fn commanded(&self, t: f64) -> f64 {
        let t = t - self.delay;
        let i = self.commands.partition_point(|(s, _)| *s <= t);
        if i > 0 {
            self.commands[i - 1].1
        } else {
            self.commands.first().map_or(self.hover_thrust, |c| c.1)
        }
    }
}

/// A horizontal series: (time \[s\], [north, east]).
pub type HorizontalSeries = Vec<(f64, [f64; 2])>;

/// Everything the drag fit reads.
#[derive(Debug, Clone, Default)]
pub struct DragData {
    /// (time \[s\], [roll, pitch, yaw] \[rad\]) measured, in time order.
    pub attitude: Vec<(f64, [f64; 3])>,
    /// The thrust, when the vertical fit found it; else the altitude is
    /// taken as held.
    pub thrust: Option<ThrustModel>,
    /// The rotor drag d_r \[1/s\] and the horizontal velocity across the
    /// rotor plane `(v − n·(n·v))_h` (time \[s\], [north, east] [m/s]), when
    /// the vertical fit determined d_r: the rows then fit D beside it
    /// (`v̇_h = a_att − D·v_h − d_r·q_h + c`).
    pub rotor: Option<(f64, HorizontalSeries)>,
    /// Segments with position samples.
    pub segments: Vec<DragSegment>,
    /// Gravity \[m/s²\].
    pub gravity: f64,
}

/// The fitted drag.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DragFit {
    /// Horizontal linear drag D \[1/s\].
    pub drag: f64,
    /// 95 % half-width of D \[1/s\].
    pub drag_ci: f64,
    /// Constant acceleration offset [north, east] \[m/s²\] (wind, bias).
    pub offset: [f64; 2],
    /// Position samples fitted (each gives two rows).
    pub samples: usize,
    /// Share of the positions' variance (after each chunk's straight line
    /// and the tilt's share) that drag and offset explain.
    pub variance_explained: f64,
    /// RMS of the residuals \[m\].
    pub rms: f64,
    /// Residual whiteness.
    pub whiteness: Whiteness,
}

/// The horizontal acceleration the attitude gives \[m/s²\]: at specific
/// thrust `thrust` \[m/s²\] when known, else at the thrust that holds the
/// altitude (`T·R33 = g`).
fn tilt_acceleration(euler: [f64; 3], g: f64, thrust: Option<f64>) -> [f64; 2] {
    let [phi, theta, psi] = euler;
    let (sf, cf) = phi.sin_cos();
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    let r13 = cp * st * cf + sp * sf;
    let r23 = sp * st * cf - cp * sf;
    let t = thrust.unwrap_or_else(|| g / (ct * cf).max(0.1));
    [-t * r13, -t * r23]
}

/// Attitude at `t`: linear between samples (yaw across ±π: the nearer).
pub(super) fn attitude_at(att: &[(f64, [f64; 3])], t: f64) -> [f64; 3] {
    let i = att.partition_point(|(s, _)| *s <= t);
    match (i.checked_sub(1).map(|j| att[j]), att.get(i)) {
        (Some((t0, a)), Some(&(t1, b))) if t1 > t0 => {
            let f = (t - t0) / (t1 - t0);
            if (b[2] - a[2]).abs() > std::f64::consts::PI {
                return if f < 0.5 { a } else { b };
            }
            std::array::from_fn(|k| a[k] + f * (b[k] - a[k]))
        }
        (Some((_, a)), _) | (None, Some(&(_, a))) => a,
        (None, None) => [0.0; 3],
    }
}

/// A series' value at `t` (a segment's positions, the velocity across the
/// rotor plane): linear between samples, held at the ends.
fn sample_at(samples: &[(f64, [f64; 2])], t: f64) -> [f64; 2] {
    let i = samples.partition_point(|(s, _)| *s <= t);
    match (i.checked_sub(1).map(|j| samples[j]), samples.get(i)) {
        (Some((t0, a)), Some(&(t1, b))) if t1 > t0 => {
            let f = (t - t0) / (t1 - t0);
            [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]
        }
        (Some((_, a)), _) | (None, Some(&(_, a))) => a,
        (None, None) => [0.0; 2],
    }
}

/// `v` minus its least-squares line in `t`.
pub(super) fn project(t: &[f64], v: &[f64]) -> Vec<f64> {
    let n = t.len() as f64;
    let (mt, mv) = (t.iter().sum::<f64>() / n, v.iter().sum::<f64>() / n);
    let stt: f64 = t.iter().map(|x| (x - mt).powi(2)).sum();
    let stv: f64 = t.iter().zip(v).map(|(x, y)| (x - mt) * (y - mv)).sum();
    let slope = if stt > 0.0 { stv / stt } else { 0.0 };
    t.iter()
        .zip(v)
        .map(|(x, y)| y - mv - slope * (x - mt))
        .collect()
}

/// One least-squares row: target, and regressors [D, c_x, c_y].
type Row = (f64, Vector3<f64>);

/// The projected rows of every chunk (x rows, then y rows, per chunk).
fn rows(data: &DragData) -> Vec<Row> {
    let g = data.gravity;
    let mut out = Vec::new();
    for seg in &data.segments {
        let (a, b) = seg.span;
        let samples: Vec<(f64, [f64; 2])> = seg.chunks.iter().flatten().copied().collect();
        if samples.len() < 5 || b <= a {
            continue;
        }
        let n = ((b - a) / GRID).ceil() as usize + 1;
        // Grids of I₂[a_att] and I₁[x] (trapezoids).
        let mut i2 = vec![[0.0; 2]; n];
        let mut i1p = vec![[0.0; 2]; n];
        // The lagged thrust c_f, as the vertical fit steps it.
        let lag = data
            .thrust
            .as_ref()
            .map(|m| (m, (-GRID / m.tau_thrust.max(1e-4)).exp()));
        let mut cf = lag.map(|(m, _)| m.commanded(a));
        let specific = |m: &ThrustModel, cf: f64| g * cf / m.hover_thrust;
        let rotor = |t: f64, acc: [f64; 2]| match &data.rotor {
            Some((d, q)) => {
                let q = sample_at(q, t);
                [acc[0] - d * q[0], acc[1] - d * q[1]]
            }
            None => acc,
        };
        let (mut v, mut acc_prev) = (
            [0.0; 2],
            rotor(
                a,
                tilt_acceleration(
                    attitude_at(&data.attitude, a),
                    g,
                    lag.zip(cf).map(|((m, _), c)| specific(m, c)),
                ),
            ),
        );
        let mut p_prev = sample_at(&samples, a);
        for k in 1..n {
            let t = a + k as f64 * GRID;
            if let (Some((m, e)), Some(c)) = (lag, cf.as_mut()) {
                let u = m.commanded(t - GRID / 2.0);
                *c = u + (*c - u) * e;
            }
            let acc = rotor(
                t,
                tilt_acceleration(
                    attitude_at(&data.attitude, t),
                    g,
                    lag.zip(cf).map(|((m, _), c)| specific(m, c)),
                ),
            );
            let p = sample_at(&samples, t);
            for ax in 0..2 {
                let v_next = v[ax] + 0.5 * (acc[ax] + acc_prev[ax]) * GRID;
                i2[k][ax] = i2[k - 1][ax] + 0.5 * (v[ax] + v_next) * GRID;
                v[ax] = v_next;
                i1p[k][ax] = i1p[k - 1][ax] + 0.5 * (p[ax] + p_prev[ax]) * GRID;
            }
            acc_prev = acc;
            p_prev = p;
        }
        let at = |grid: &[[f64; 2]], t: f64, ax: usize| {
            let x = ((t - a) / GRID).clamp(0.0, (n - 1) as f64);
            let k = (x.floor() as usize).min(n.saturating_sub(2));
            let f = x - k as f64;
            grid[k][ax] * (1.0 - f) + grid[(k + 1).min(n - 1)][ax] * f
        };
        for chunk in &seg.chunks {
            if chunk.len() < 5 {
                continue;
            }
            let t0 = chunk[0].0;
            let ts: Vec<f64> = chunk.iter().map(|(t, _)| t - t0).collect();
            let x2 = project(&ts, &ts.iter().map(|s| 0.5 * s * s).collect::<Vec<_>>());
            for ax in 0..2 {
                let y: Vec<f64> = chunk.iter().map(|(t, p)| p[ax] - at(&i2, *t, ax)).collect();
                let x1: Vec<f64> = chunk.iter().map(|(t, _)| -at(&i1p, *t, ax)).collect();
                let (y, x1) = (project(&ts, &y), project(&ts, &x1));
                for j in 0..ts.len() {
                    let mut r = Vector3::new(x1[j], 0.0, 0.0);
                    r[1 + ax] = x2[j];
                    out.push((y[j], r));
                }
            }
        }
    }
    out
}

/// Fits D and the offsets. `None` with fewer than 50 samples or when the
/// velocity does not vary enough to separate drag from the offset.
pub fn fit_drag(data: &DragData) -> Option<DragFit> {
    let rows = rows(data);
    let n = rows.len();
    if n < 100 {
        return None;
    }
    let mut ata = Matrix3::zeros();
    let mut atb = Vector3::zeros();
    let mut syy = 0.0;
    for (y, r) in &rows {
        ata += r * r.transpose();
        atb += *y * r;
        syy += y * y;
    }
    let inv = ata.try_inverse()?;
    let theta = inv * atb;
    if !theta.iter().all(|v| v.is_finite()) {
        return None;
    }
    let residuals: Vec<f64> = rows.iter().map(|(y, r)| y - r.dot(&theta)).collect();
    let sse: f64 = residuals.iter().map(|v| v * v).sum();
    let whiteness = Whiteness::of(&residuals);
    let inflation = whiteness.inflation(n as f64 / 10.0);
    let s2 = sse / (n - 3) as f64;
    let sd = (s2 * inflation * inv[(0, 0)]).sqrt();
    Some(DragFit {
        drag: theta[0],
        drag_ci: 1.96 * sd,
        offset: [theta[1], theta[2]],
        samples: n / 2,
        variance_explained: if syy > 0.0 { 1.0 - sse / syy } else { 0.0 },
        rms: (sse / n as f64).sqrt(),
        whiteness,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 20 s simulated flights' data: `samples` in chunks of 150, one
    /// segment, the altitude held (no thrust model).
    fn one_segment(
        attitude: Vec<(f64, [f64; 3])>,
        samples: &[(f64, [f64; 2])],
        g: f64,
    ) -> DragData {
        DragData {
            attitude,
            thrust: None,
            rotor: None,
            segments: vec![DragSegment {
                span: (0.0, 19.999),
                chunks: samples.chunks(150).map(|c| c.to_vec()).collect(),
            }],
            gravity: g,
        }
    }

    /// A simulated flight with known drag and offset: the fit recovers them.
    #[test]
    fn recovers_drag_from_a_simulated_flight() {
        let (g, drag, offset) = (9.81, 0.3, [0.2, -0.1]);
        let dt = 0.001;
        let (mut p, mut v) = ([0.0f64; 2], [0.0f64; 2]);
        let mut attitude = Vec::new();
        let mut samples = Vec::new();
        let psi: f64 = 0.4;
        for k in 0..20_000 {
            let t = k as f64 * dt;
            let euler = [0.15 * (0.9 * t).sin(), 0.2 * (0.6 * t).cos(), psi];
            if k % 10 == 0 {
                attitude.push((t, euler));
            }
            if k % 20 == 0 {
                samples.push((t, p));
            }
            let a = tilt_acceleration(euler, g, None);
            for ax in 0..2 {
                p[ax] += dt * v[ax];
                v[ax] += dt * (a[ax] - drag * v[ax] + offset[ax]);
            }
        }
        let data = one_segment(attitude, &samples, g);
        let fit = fit_drag(&data).expect("fit");
        assert!((fit.drag - drag).abs() < 0.01, "{fit:?}");
        assert!((fit.offset[0] - offset[0]).abs() < 0.02, "{fit:?}");
        assert!(
            fit.drag_ci.is_finite() && fit.variance_explained > 0.99,
            "{fit:?}"
        );
    }

    /// Climbs and descents (the thrust away from T·R33 = g): with the
    /// vertical fit's thrust model the drag comes back and the fit explains
    /// the motion; taking the altitude as held leaves the thrust's share
    /// unexplained and the drag further off.
    #[test]
    fn the_thrust_model_removes_the_climb_bias() {
        let (g, drag, h) = (9.81, 0.3, 0.42);
        let dt = 0.001;
        let (mut p, mut v) = ([0.0f64; 2], [0.0f64; 2]);
        let (mut attitude, mut samples, mut commands) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..20_000 {
            let t = k as f64 * dt;
            let euler = [0.15 * (0.9 * t).sin(), 0.2 * (0.6 * t).cos(), 0.4];
            let r33 = euler[0].cos() * euler[1].cos();
            // 25 % more or less thrust than holding the altitude needs,
            // in phase with the pitch (as a climbing corner is).
            let thrust = g / r33 * (1.0 + 0.25 * (0.6 * t).cos());
            if k % 10 == 0 {
                attitude.push((t, euler));
                commands.push((t, h * thrust / g));
            }
            if k % 20 == 0 {
                samples.push((t, p));
            }
            let a = tilt_acceleration(euler, g, Some(thrust));
            for ax in 0..2 {
                p[ax] += dt * v[ax];
                v[ax] += dt * (a[ax] - drag * v[ax]);
            }
        }
        let mut data = one_segment(attitude, &samples, g);
        let held = fit_drag(&data).expect("fit");
        data.thrust = Some(ThrustModel {
            commands,
            hover_thrust: h,
            tau_thrust: 1e-3,
            delay: 0.0,
        });
        let modelled = fit_drag(&data).expect("fit");
        assert!((modelled.drag - drag).abs() < 0.005, "{modelled:?}");
        assert!(modelled.variance_explained > 0.999, "{modelled:?}");
        // Held, the thrust's share is a residual the fit cannot explain
        // (and the drag is off by more).
        assert!(held.rms > 10.0 * modelled.rms, "{held:?} vs {modelled:?}");
        assert!(
            (held.drag - drag).abs() > 2.0 * (modelled.drag - drag).abs(),
            "{held:?} vs {modelled:?}"
        );
    }
}
