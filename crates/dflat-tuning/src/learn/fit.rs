//! The residual's fit: per window size, the measured acceleration minus the
//! parametric model's as targets, the basis of the velocity from the window
//! and the modelled thrust axis as regressors, ridge regression; and the
//! rollouts that judge a fit on held-out data.

use dflat_control::learned::{Feature, LearnedResidual, basis, columns};
use nalgebra::{DMatrix, DVector, Vector3};

use super::data::Run;
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

/// The part a tick at time `t` \[s\] falls in.
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
    /// Measured positions, NED \[m\].
    pub y: Vec<Vector3<f64>>,
    /// Tick times \[s\].
    pub t: Vec<f64>,
    /// The parametric model's axis and thrust per tick.
    pub inputs: Inputs,
}

impl Prepared {
    /// A run and its model inputs.
    pub fn new(run: &Run, model: &Parametric) -> Self {
        Self {
            y: run.ticks.iter().map(|t| t.y).collect(),
            t: run.ticks.iter().map(|t| t.t).collect(),
            inputs: model.inputs(run),
        }
    }
}

/// Velocity [m/s] from the window of `r` outputs ending at `k`:
/// `(y_k − y_{k−r+1}) / ((r−1)·δt)`.
pub fn window_velocity(y: &[Vector3<f64>], k: usize, r: usize, dt: f64) -> Vector3<f64> {
    (y[k] - y[k + 1 - r]) / ((r - 1) as f64 * dt)
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

/// The samples of `part` for window `r` and basis `features`: at each tick
/// k with a full window and a next output, the measured acceleration
/// `(y_{k+1} − 2y_k + y_{k−1})/δt²` minus the model's at the window's
/// velocity.
pub fn samples(
    runs: &[Prepared],
    model: &Parametric,
    r: usize,
    features: &[Feature],
    which: Part,
) -> Vec<Sample> {
    let dt = model.dt;
    let mut out = Vec::new();
    for p in runs {
        for k in r.max(2)..p.y.len().saturating_sub(1) {
            if part(p.t[k]) != which {
                continue;
            }
            let v = window_velocity(&p.y, k, r, dt);
            let n = p.inputs.axis[k];
            let thrust = p.inputs.thrust[k];
            let measured = (p.y[k + 1] - p.y[k] * 2.0 + p.y[k - 1]) / (dt * dt);
            let mut phi = [0.0; 16];
            basis(features, &v, &n, &mut phi);
            out.push(Sample {
                phi,
                target: measured - model.acceleration(&n, thrust, &v),
                speed: v.norm(),
                tilt: n.z.clamp(-1.0, 1.0).acos(),
                thrust,
            });
        }
    }
    out
}

/// Ridge regression of the targets on the first `m` basis columns: the
/// weights per NED axis. Columns are penalised by `λ·N` on their
/// standardised scale (the constant column is not penalised). `None` when
/// the normal equations are singular or there are fewer samples than 4·m.
pub fn ridge(samples: &[Sample], m: usize, lambda: f64) -> Option<[Vec<f64>; 3]> {
    let n = samples.len();
    if n < 4 * m || m == 0 {
        return None;
    }
    let mut a = DMatrix::<f64>::zeros(m, m);
    let mut b = [
        DVector::<f64>::zeros(m),
        DVector::zeros(m),
        DVector::zeros(m),
    ];
    let mut mean = vec![0.0; m];
    for s in samples {
        for i in 0..m {
            mean[i] += s.phi[i] / n as f64;
            for j in 0..=i {
                a[(i, j)] += s.phi[i] * s.phi[j];
            }
            for (axis, b) in b.iter_mut().enumerate() {
                b[i] += s.phi[i] * s.target[axis];
            }
        }
    }
    for i in 0..m {
        for j in 0..i {
            a[(j, i)] = a[(i, j)];
        }
        let var = a[(i, i)] / n as f64 - mean[i] * mean[i];
        if var > 1e-12 {
            a[(i, i)] += lambda * n as f64 * var;
        }
    }
    let chol = a.cholesky()?;
    let w = b.map(|b| chol.solve(&b).iter().copied().collect::<Vec<f64>>());
    w.iter().flatten().all(|x| x.is_finite()).then_some(w)
}

/// Sums of squared prediction errors over held-out starts.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Errors {
    /// Σ |y_{k+1} − ŷ_{k+1}|² \[m²\].
    pub one_step: f64,
    /// Σ |y_{k+H} − ŷ_{k+H}|² \[m²\].
    pub horizon: f64,
    /// Starts.
    pub count: usize,
}

impl Errors {
    /// RMS one-step error \[m\].
    pub fn one_step_rms(&self) -> f64 {
        (self.one_step / self.count.max(1) as f64).sqrt()
    }

    /// RMS horizon error \[m\].
    pub fn horizon_rms(&self) -> f64 {
        (self.horizon / self.count.max(1) as f64).sqrt()
    }
}

/// Prediction errors on `which`: from every `stride`-th tick k with its
/// window, the outputs rolled out `horizon` ticks through the commands sent
/// (`ŷ_{j+1} = 2ŷ_j − ŷ_{j−1} + δt²·a_j`, the model's acceleration plus
/// the residual's at the window's velocity over measured then predicted
/// outputs; `residual = None`: the parametric model alone, its velocity
/// from the last two outputs).
pub fn rollouts(
    runs: &[Prepared],
    model: &Parametric,
    residual: Option<&LearnedResidual>,
    which: Part,
    horizon: usize,
    stride: usize,
) -> Errors {
    let r = residual.map_or(2, |m| m.window);
    let dt = model.dt;
    let mut errors = Errors::default();
    let mut hist: Vec<Vector3<f64>> = Vec::with_capacity(r + horizon + 1);
    for p in runs {
        let mut k = r.max(2);
        while k + horizon < p.y.len() {
            if part(p.t[k]) != which || part(p.t[k + horizon]) != which {
                k += stride;
                continue;
            }
            hist.clear();
            hist.extend_from_slice(&p.y[k + 1 - r.max(2)..=k]);
            for j in 0..horizon {
                let last = hist.len() - 1;
                let v = window_velocity(&hist, last, r, dt);
                let (n, thrust) = (p.inputs.axis[k + j], p.inputs.thrust[k + j]);
                let mut a = model.acceleration(&n, thrust, &v);
                if let Some(m) = residual {
                    a += m.acceleration(&v, &n, thrust);
                }
                let next = hist[last] * 2.0 - hist[last - 1] + a * (dt * dt);
                hist.push(next);
                if j == 0 {
                    errors.one_step += (p.y[k + 1] - next).norm_squared();
                }
            }
            errors.horizon += (p.y[k + horizon] - hist[hist.len() - 1]).norm_squared();
            errors.count += 1;
            k += stride;
        }
    }
    errors
}

/// The number of basis columns of `features` (re-exported for the caller).
pub fn width(features: &[Feature]) -> usize {
    columns(features)
}
