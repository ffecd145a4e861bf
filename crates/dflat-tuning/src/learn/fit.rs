//! The residual's fit: per window size, the measured acceleration minus the
//! parametric model's as targets, the basis of the window's velocity and
//! the modelled thrust axis as regressors, ridge regression; and the
//! held-out predictions that judge a fit.
//!
//! # Targets from poses at their own times
//!
//! The poses come at their capture times (50 Hz, 15 Hz, with noise). At
//! pose i a least-squares parabola through the window of `r = 2m + 1`
//! poses centred on it gives the velocity `v_i` and the acceleration
//! `â_i = Σ_l w_l·y_l` (weights [`parabola_weights`]). Those weights
//! annihilate constants and slopes, so `â_i = ∫ K(τ)·a(τ) dτ` for the true
//! acceleration a with the kernel `K(τ) = Σ_l w_l·(s_l − τ)₊` (∫K = 1): a
//! weighted mean of the acceleration over the window. The same weights on
//! the double integral of the model's thrust acceleration (the commands
//! through its lags, [`Prepared::virtual_position`]) give the model's
//! acceleration through the same kernel, so the target
//!
//! ```text
//! â_i − Σ_l w_l·Y_T(s_l) + D·v_i   ≈   W·φ(v_i, n_i)
//! ```
//!
//! is the residual smoothed as the measurement is, whatever the pose rate.
//! A wider window averages the pose noise (a 2 cm σ is √6·σ/δt² ≈ 120 m/s²
//! in one second difference at 50 Hz) at the price of smoothing the
//! residual: the window is chosen on held-out data.
//!
//! # Held-out prediction: the input-to-output map from a window
//!
//! From pose i: the position and velocity at `s_i` fitted to the poses of
//! the last `start_s` (one of [`START_WINDOWS_S`], each model its own,
//! chosen on the validation blocks) through the model itself (its drag and, learned,
//! its residual along the window), then the model rolled forward through
//! the commands sent — the parametric model alone, or with the residual at
//! the rolled velocity — to the next pose (one step) and to the last pose
//! within [`super::HORIZON_S`] (horizon): each model's own input-to-output
//! map from the window.

use dflat_control::learned::{Feature, LearnedResidual, basis, columns};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::data::{Pose, Run};
use super::parametric::{Inputs, Parametric};

/// Which part of the data a sample belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// Fitted on.
    Train,
    /// Chooses the window, the basis and λ.
    Validate,
    /// Reported, never used to choose.
    Test,
}

/// Length of the blocks the data are cut into \[s\]: of every five, three
/// train, one validates, one tests.
pub const BLOCK_S: f64 = 4.0;

/// The spans \[s\] of poses before a held-out start that its state may be
/// fitted from; each model is judged from its own, chosen on the
/// validation blocks (`learn`'s `best_start`). A model that explains the
/// flight affords a long window, which averages the pose noise; one that
/// leaves acceleration unexplained bends its start over a long one.
pub const START_WINDOWS_S: [f64; 6] = [0.2, 0.4, 0.8, 1.2, 1.6, 2.4];

/// The part a sample at time `t` \[s\] falls in.
pub fn part(t: f64) -> Part {
    match ((t / BLOCK_S).floor() as i64).rem_euclid(5) {
        3 => Part::Validate,
        4 => Part::Test,
        _ => Part::Train,
    }
}

/// A run with its model inputs, ready to sample.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Time of the first tick \[s\].
    pub(super) t0: f64,
    /// Control step \[s\].
    pub(super) dt: f64,
    /// The parametric model's axis and thrust per tick.
    pub inputs: Inputs,
    /// The model's thrust acceleration (with gravity, without drag) per
    /// tick [m/s², NED].
    pub(super) thrust_acc: Vec<Vector3<f64>>,
    /// Its double integral at each tick's start: position and velocity
    /// from rest at the first tick.
    pub(super) integral: Vec<(Vector3<f64>, Vector3<f64>)>,
    /// The poses captured over the ticks.
    pub poses: Vec<Pose>,
}

impl Prepared {
    /// A run and its model inputs.
    pub fn new(run: &Run, model: &Parametric) -> Self {
        let inputs = model.inputs(run);
        let dt = model.dt;
        let at_tick: Vec<Vector3<f64>> = inputs
            .axis
            .iter()
            .zip(&inputs.thrust)
            .map(|(n, t)| model.acceleration(n, *t, &Vector3::zeros()))
            .collect();
        // Over each tick, the mean of its ends (the attitude moves through
        // the tick; the last tick holds).
        let thrust_acc: Vec<Vector3<f64>> = (0..at_tick.len())
            .map(|j| {
                let next = at_tick.get(j + 1).unwrap_or(&at_tick[j]);
                (at_tick[j] + next) * 0.5
            })
            .collect();
        let mut integral = Vec::with_capacity(thrust_acc.len() + 1);
        let (mut p, mut v) = (Vector3::zeros(), Vector3::zeros());
        for a in &thrust_acc {
            integral.push((p, v));
            p += v * dt + a * (0.5 * dt * dt);
            v += a * dt;
        }
        integral.push((p, v));
        let t0 = run.ticks.first().map_or(0.0, |t| t.t);
        let end = t0 + dt * thrust_acc.len() as f64;
        Self {
            t0,
            dt,
            inputs,
            thrust_acc,
            integral,
            poses: run
                .poses
                .iter()
                .copied()
                .filter(|p| p.t >= t0 && p.t < end)
                .collect(),
        }
    }

    /// The tick whose step contains `t` (None outside the run).
    pub fn tick_at(&self, t: f64) -> Option<usize> {
        let j = ((t - self.t0) / self.dt).floor();
        (j >= 0.0 && (j as usize) < self.thrust_acc.len()).then_some(j as usize)
    }

    /// The double integral of the model's thrust acceleration at `t`
    /// (from rest at the first tick) \[m\], and its derivative [m/s].
    pub fn virtual_position(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let j = ((t - self.t0) / self.dt)
            .floor()
            .clamp(0.0, (self.thrust_acc.len().max(1) - 1) as f64) as usize;
        let (p, v) = self.integral[j];
        let h = t - (self.t0 + j as f64 * self.dt);
        let a = self.thrust_acc.get(j).copied().unwrap_or_default();
        (p + v * h + a * (0.5 * h * h), v + a * h)
    }
}

/// Weights of a least-squares parabola through `(times[l], y_l)` at `at`:
/// `(value, slope, curvature)` rows, so `Σ w_l·y_l` is the parabola's
/// value, velocity and acceleration there. `None` for fewer than three
/// distinct times.
pub fn parabola_weights(times: &[f64], at: f64) -> Option<[Vec<f64>; 3]> {
    if times.len() < 3 {
        return None;
    }
    let scale = times
        .iter()
        .map(|t| (t - at).abs())
        .fold(0.0, f64::max)
        .max(1e-9);
    let row = |t: f64| {
        let x = (t - at) / scale;
        [1.0, x, 0.5 * x * x]
    };
    let mut ata = Matrix3::<f64>::zeros();
    for t in times {
        let r = row(*t);
        for a in 0..3 {
            for b in 0..3 {
                ata[(a, b)] += r[a] * r[b];
            }
        }
    }
    let inv = ata.try_inverse()?;
    if !inv.iter().all(|x| x.is_finite()) {
        return None;
    }
    let mut out = [
        vec![0.0; times.len()],
        vec![0.0; times.len()],
        vec![0.0; times.len()],
    ];
    for (l, t) in times.iter().enumerate() {
        let r = row(*t);
        for (k, w) in out.iter_mut().enumerate() {
            w[l] = (0..3).map(|b| inv[(k, b)] * r[b]).sum::<f64>();
        }
    }
    for w in &mut out[1] {
        *w /= scale;
    }
    for w in &mut out[2] {
        *w /= scale * scale;
    }
    Some(out)
}

/// Half-width m of a window of `r` poses (`r = 2m + 1`, at least 1).
pub fn half_width(r: usize) -> usize {
    (r.saturating_sub(1) / 2).max(1)
}

/// One regression sample: the basis row and the residual acceleration.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// The basis φ (first [`columns`] entries).
    pub phi: [f64; 16],
    /// Measured minus parametric acceleration [m/s², NED].
    pub target: Vector3<f64>,
    /// Speed of the window [m/s].
    pub speed: f64,
    /// Tilt of the modelled thrust axis \[rad\].
    pub tilt: f64,
    /// Modelled specific thrust [m/s²].
    pub thrust: f64,
}

/// One tick under a sample's kernel: its weight `∫_tick K(τ) dτ` and the
/// velocity, thrust axis and thrust there.
#[derive(Debug, Clone, Copy)]
pub struct KernelTick {
    /// The kernel's weight on the tick (the weights sum to about 1).
    pub weight: f64,
    /// Velocity at the tick's middle, from the window's parabola [m/s].
    pub v: Vector3<f64>,
    /// The model's thrust axis (unit, NED).
    pub n: Vector3<f64>,
    /// The model's specific thrust [m/s²].
    pub thrust: f64,
}

/// A pose's window of `r` poses centred on it, smoothed: the velocity
/// there, the residual target and the kernel it is taken through. None
/// where the window leaves the run or spans a gap.
#[derive(Debug, Clone)]
pub struct Smoothed {
    /// Capture time \[s\].
    pub t: f64,
    /// Velocity [m/s].
    pub v: Vector3<f64>,
    /// Measured minus parametric acceleration through the kernel [m/s²].
    pub target: Vector3<f64>,
    /// The model's thrust axis at `t` (unit, NED).
    pub n: Vector3<f64>,
    /// The model's specific thrust at `t` [m/s²].
    pub thrust: f64,
    /// The ticks under the kernel.
    pub kernel: Vec<KernelTick>,
}

impl Smoothed {
    /// The residual's prediction of the target: `Σ_j K_j·ρ(v_j, n_j)`
    /// (unfaded; planar: horizontal).
    pub fn predicted(&self, residual: &LearnedResidual, spatial: bool) -> Vector3<f64> {
        let mut a = self.kernel.iter().fold(Vector3::zeros(), |s, k| {
            s + residual.residual(&k.v, &k.n) * k.weight
        });
        if !spatial {
            a.z = 0.0;
        }
        a
    }

    /// The basis through the kernel: `Σ_j K_j·φ(v_j, n_j)` into `out`.
    pub fn basis(&self, features: &[Feature], out: &mut [f64; 16]) {
        *out = [0.0; 16];
        let mut phi = [0.0; 16];
        for k in &self.kernel {
            let m = basis(features, &k.v, &k.n, &mut phi);
            for i in 0..m {
                out[i] += k.weight * phi[i];
            }
        }
    }
}

/// `∫_a^b (s − τ)₊ dτ` over `[a, b] ∩ [lo, s]`.
fn ramp_integral(a: f64, b: f64, lo: f64, s: f64) -> f64 {
    let (a, b) = (a.max(lo), b.min(s));
    if b <= a {
        0.0
    } else {
        0.5 * ((s - a).powi(2) - (s - b).powi(2))
    }
}

/// The smoothed windows of `r` poses of a run's `which` part. The
/// parabola's acceleration weights `w_l` give `â = ∫K(τ)·a(τ) dτ` with
/// `K(τ) = Σ_l w_l·(s_l − τ)₊` on the window; the target is `â` less the
/// model's thrust acceleration through the same weights plus its drag
/// through the same kernel, and the residual is compared through the
/// kernel too ([`Smoothed::predicted`]): no smoothing bias to first
/// order, however wide the window.
pub fn smoothed(p: &Prepared, model: &Parametric, r: usize, which: Part) -> Vec<Smoothed> {
    let m = half_width(r);
    let mut out = Vec::new();
    let mut times = Vec::with_capacity(2 * m + 1);
    if p.poses.len() < 2 * m + 1 {
        return out;
    }
    // The window may not span more than twice its nominal length (a gap).
    let spacing = (p.poses[p.poses.len() - 1].t - p.poses[0].t) / (p.poses.len() - 1) as f64;
    for i in m..p.poses.len() - m {
        let s = p.poses[i].t;
        if part(s) != which {
            continue;
        }
        let w = &p.poses[i - m..=i + m];
        let (lo, hi) = (w[0].t, w[2 * m].t);
        if hi - lo > 2.0 * (2 * m) as f64 * spacing {
            continue;
        }
        let (Some(j), Some(j0), Some(j1)) = (p.tick_at(s), p.tick_at(lo), p.tick_at(hi)) else {
            continue;
        };
        times.clear();
        times.extend(w.iter().map(|q| q.t));
        let Some([_, wv, wa]) = parabola_weights(&times, s) else {
            continue;
        };
        let mut v = Vector3::zeros();
        let mut a = Vector3::zeros();
        let mut model_a = Vector3::zeros();
        for (l, q) in w.iter().enumerate() {
            v += q.y * wv[l];
            a += q.y * wa[l];
            model_a += p.virtual_position(q.t).0 * wa[l];
        }
        if !model.spatial {
            // The altitude is held: the vertical velocity is noise.
            (v.z, a.z) = (0.0, 0.0);
        }
        let mut kernel = Vec::with_capacity(j1 - j0 + 1);
        let mut drag = Vector3::zeros();
        for k in j0..=j1 {
            let (ta, tb) = (p.t0 + k as f64 * p.dt, p.t0 + (k + 1) as f64 * p.dt);
            let weight: f64 = w
                .iter()
                .zip(&wa)
                .map(|(q, wl)| wl * ramp_integral(ta, tb, lo, q.t))
                .sum();
            let mid = 0.5 * (ta.max(lo) + tb.min(hi));
            let vk = v + a * (mid - s);
            drag += model.drag(&p.inputs.axis[k], &vk) * weight;
            kernel.push(KernelTick {
                weight,
                v: vk,
                n: p.inputs.axis[k],
                thrust: p.inputs.thrust[k],
            });
        }
        let mut target = a - model_a + drag;
        if !model.spatial {
            target.z = 0.0;
        }
        out.push(Smoothed {
            t: s,
            v,
            target,
            n: p.inputs.axis[j],
            thrust: p.inputs.thrust[j],
            kernel,
        });
    }
    out
}

/// The samples of `part` for window `r` and basis `features`.
pub fn samples(
    runs: &[Prepared],
    model: &Parametric,
    r: usize,
    features: &[Feature],
    which: Part,
) -> Vec<Sample> {
    let mut out = Vec::new();
    for p in runs {
        for s in smoothed(p, model, r, which) {
            let mut phi = [0.0; 16];
            s.basis(features, &mut phi);
            out.push(Sample {
                phi,
                target: s.target,
                speed: s.v.norm(),
                tilt: s.n.z.clamp(-1.0, 1.0).acos(),
                thrust: s.thrust,
            });
        }
    }
    out
}

/// A ridge fit: the weights per NED axis and their 95 % half-widths.
#[derive(Debug, Clone, PartialEq)]
pub struct Ridge {
    /// Weights, one row per NED axis.
    pub weights: [Vec<f64>; 3],
    /// 95 % half-width of each weight: `1.96·σ_axis·√(r·[(ΦᵀΦ + Λ)⁻¹]_ii)`
    /// (the residual's σ per axis; `r`, the window, for the overlap of
    /// neighbouring samples' windows).
    pub half_width: [Vec<f64>; 3],
}

/// Ridge regression of the targets on the basis of `features` over samples
/// of window `r`: the weights per NED axis and their intervals.
///
/// **One weight per group, shared by the horizontal axes.** Each axis's
/// residual is its own components of the groups, `ρ_x = w_v·v_x +
/// w_q·|v|·v_x + w_r·(v − n·(n·v))_x` (a constant likewise, per axis, when
/// the basis has one), and x and y share `w`: the rows of both axes are
/// one regression. z (the spatial model) has its own weights. Drag acts
/// against the velocity, and an airframe symmetric about its thrust axis
/// drags the same way whichever way it flies horizontally (the rotor
/// plane's coupling through the tilt is in its group's columns); in the
/// world frame that is the one form a yawing vehicle keeps. What it buys
/// (`dflat experiment learned`, `tests/e2e_learned.rs`, docs/results.md):
///
/// * a fit coupled across the axes found forces the aerodynamics do not
///   have (from 38 s of a racing line along x, a lateral force of
///   −0.0076·v_x);
/// * a fit per axis left the lateral axis of that racing line, which saw
///   speed only in the turns, to split its drag between `v_y` and the
///   rotor plane's `(v − n·(n·v))_y` with the rotor drag's sign wrong;
/// * shared, the lateral axis has the forward axis's well-determined
///   weights: the lab's study had 10 (coupled), 7 (per axis) and 4
///   (shared) of its 54 cells outside the budgets.
///
/// Columns are penalised by `λ·N` on their standardised scale (the
/// constant column is not penalised). `None` when the normal equations are
/// singular or there are fewer samples than four per unknown.
pub fn ridge(samples: &[Sample], features: &[Feature], lambda: f64, r: usize) -> Option<Ridge> {
    let m = columns(features);
    // Each fit: the axes whose rows it stacks, and its unknowns (per axis,
    // the basis column an unknown multiplies in that axis's rows).
    let mut horizontal = Vec::new();
    let mut vertical = Vec::new();
    let mut col = 0;
    for f in features {
        if f.columns() == 1 {
            horizontal.push([Some(col), None, None]);
            horizontal.push([None, Some(col), None]);
            vertical.push([None, None, Some(col)]);
        } else {
            horizontal.push([Some(col), Some(col + 1), None]);
            vertical.push([None, None, Some(col + 2)]);
        }
        col += f.columns();
    }
    if samples.len() < 4 * horizontal.len() || m == 0 {
        return None;
    }
    let mut weights: [Vec<f64>; 3] = std::array::from_fn(|_| vec![0.0; m]);
    let mut half_width: [Vec<f64>; 3] = std::array::from_fn(|_| vec![f64::INFINITY; m]);
    for (axes, unknowns) in [(&[0, 1][..], horizontal), (&[2][..], vertical)] {
        let (w, hw) = fit_rows(samples, axes, &unknowns, lambda, r)?;
        for (u, cols) in unknowns.iter().enumerate() {
            for (axis, c) in cols.iter().enumerate() {
                if let Some(c) = c {
                    weights[axis][*c] = w[u];
                    half_width[axis][*c] = hw[u];
                }
            }
        }
    }
    Some(Ridge {
        weights,
        half_width,
    })
}

/// One ridge fit over the rows of `axes` (each sample gives one row per
/// axis) on `unknowns` (one or more; per axis, the basis column an unknown
/// multiplies there): the unknowns' values and their 95 % half-widths.
fn fit_rows(
    samples: &[Sample],
    axes: &[usize],
    unknowns: &[[Option<usize>; 3]],
    lambda: f64,
    r: usize,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let k = unknowns.len();
    let n = samples.len() * axes.len();
    let row = |s: &Sample, axis: usize, out: &mut [f64]| {
        for (u, cols) in unknowns.iter().enumerate() {
            out[u] = cols[axis].map_or(0.0, |c| s.phi[c]);
        }
    };
    let mut a = DMatrix::<f64>::zeros(k, k);
    let mut b = DVector::<f64>::zeros(k);
    let mut mean = vec![0.0; k];
    let mut x = vec![0.0; k];
    for s in samples {
        for &axis in axes {
            row(s, axis, &mut x);
            for i in 0..k {
                mean[i] += x[i] / n as f64;
                for j in 0..=i {
                    a[(i, j)] += x[i] * x[j];
                }
                b[i] += x[i] * s.target[axis];
            }
        }
    }
    for i in 0..k {
        for j in 0..i {
            a[(j, i)] = a[(i, j)];
        }
        let var = a[(i, i)] / n as f64 - mean[i] * mean[i];
        if var > 1e-12 {
            a[(i, i)] += lambda * n as f64 * var;
        } else if a[(i, i)] <= 1e-12 * n as f64 {
            // A column the data never moved (the planar model's vertical
            // velocity): its weight stays 0.
            a[(i, i)] += n as f64;
        }
    }
    let chol = a.cholesky()?;
    let w = chol.solve(&b);
    if !w.iter().all(|x| x.is_finite()) {
        return None;
    }
    let inv = chol.inverse();
    let dof = (n - k).max(1) as f64;
    let mut sse = 0.0;
    for s in samples {
        for &axis in axes {
            row(s, axis, &mut x);
            let fit: f64 = x.iter().zip(w.iter()).map(|(x, w)| x * w).sum();
            sse += (s.target[axis] - fit).powi(2);
        }
    }
    let var = sse / dof;
    let hw = (0..k)
        .map(|i| 1.96 * (var * r as f64 * inv[(i, i)]).max(0.0).sqrt())
        .collect();
    Some((w.iter().copied().collect(), hw))
}

/// RMS acceleration [m/s²] the model leaves of the smoothed targets: the
/// parametric model's (the targets themselves) without `residual`, else
/// what the residual (unfaded) leaves. Planar: horizontal only. NaN
/// without samples.
pub fn acceleration_error(
    held_out: &[Smoothed],
    residual: Option<&LearnedResidual>,
    spatial: bool,
) -> f64 {
    combined(&acceleration_error_per_axis(held_out, residual, spatial))
}

/// The RMS error over the axes of [`acceleration_error_per_axis`]'s
/// per-axis errors [m/s²]: `√Σ e_axis²` (what [`acceleration_error`]
/// gives).
pub fn combined(per_axis: &[f64; 3]) -> f64 {
    per_axis.iter().map(|e| e * e).sum::<f64>().sqrt()
}

/// [`acceleration_error`] per NED axis (x, y, z; z 0 planar) [m/s²].
pub fn acceleration_error_per_axis(
    held_out: &[Smoothed],
    residual: Option<&LearnedResidual>,
    spatial: bool,
) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for s in held_out {
        let mut e = s.target;
        if let Some(m) = residual {
            e -= s.predicted(m, spatial);
        }
        for (axis, acc) in sum.iter_mut().enumerate() {
            if spatial || axis < 2 {
                *acc += e[axis] * e[axis];
            }
        }
    }
    sum.map(|v| (v / held_out.len() as f64).sqrt())
}

pub use super::horizon::{Errors, rollouts};

/// The number of basis columns of `features` (re-exported for the caller).
pub fn width(features: &[Feature]) -> usize {
    columns(features)
}
