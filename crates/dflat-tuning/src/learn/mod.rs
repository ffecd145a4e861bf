//! `dflat learn`: the flat maps' residual over the parametric model,
//! learned from flight records alone (the commands sent and the poses
//! measured; no state estimate).
//!
//! For each window size r and basis (see [`dflat_control::learned`]):
//!
//! 1. the parametric model's thrust axis and thrust at every tick, from the
//!    commands sent ([`parametric`]);
//! 2. the residual acceleration at every tick k: the measured
//!    `(y_{k+1} − 2y_k + y_{k−1})/δt²` minus the model's, at the velocity
//!    of the window `y_{k−r+1} … y_k`;
//! 3. ridge regression of that residual on the basis ([`fit::ridge`]).
//!
//! The data are cut into blocks of [`fit::BLOCK_S`]: three of every five
//! train, one chooses r, the basis and λ by the held-out horizon error, one
//! tests. The report gives the test blocks' one-step and horizon errors of
//! the learned model against the parametric one.
//!
//! What the flight did not excite is not learned: the velocity terms need
//! the speed to vary ([`MIN_SPEED_STD`]); with a steady speed only the
//! constant is offered. A residual that does not beat the parametric model
//! on held-out data is refused ([`LearnError::NoImprovement`]).

pub mod data;
pub mod fit;
pub mod parametric;

use std::collections::BTreeMap;

use dflat_control::learned::{
    FORMAT, Feature, LearnedResidual, Support, VERSION, Validation, columns,
};
use thiserror::Error;

use data::Run;
use fit::{Errors, Part, Prepared, Sample};
use parametric::Parametric;

/// Window sizes tried (outputs).
pub const WINDOWS: [usize; 5] = [2, 3, 4, 6, 8];
/// Ridge λ tried.
pub const LAMBDAS: [f64; 3] = [1e-6, 1e-3, 1e-1];
/// Horizon of the horizon error \[s\].
pub const HORIZON_S: f64 = 0.5;
/// Least standard deviation of the speed [m/s] for the velocity terms.
pub const MIN_SPEED_STD: f64 = 0.5;
/// Least engaged time \[s\] to learn from.
pub const MIN_SECONDS: f64 = 20.0;
/// Every how many ticks a held-out rollout starts.
const STRIDE: usize = 5;

/// Why nothing was learned.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LearnError {
    /// A record is not usable.
    #[error("{file}: {message}")]
    Record {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// Too little engaged flight.
    #[error(
        "only {seconds:.1} s engaged in the records (need at least {MIN_SECONDS} s): fly longer"
    )]
    TooShort {
        /// Engaged time \[s\].
        seconds: f64,
    },
    /// No basis could be fitted.
    #[error("no fit: the normal equations are singular for every window and basis")]
    NoFit,
    /// The best residual does not beat the parametric model held out.
    #[error(
        "the residual does not improve the held-out prediction ({horizon_s} s ahead: \
         parametric {parametric_m:.4} m, learned {learned_m:.4} m): nothing learned, \
         keep the parametric model"
    )]
    NoImprovement {
        /// Horizon \[s\].
        horizon_s: f64,
        /// Parametric error on the validation blocks \[m\].
        parametric_m: f64,
        /// The best learned error on the validation blocks \[m\].
        learned_m: f64,
    },
}

/// The `[vehicle]` table the residual is learned over.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleTable {
    /// `vehicle.model` (`planar`, `spatial`).
    pub model: String,
    /// Its numeric fields (name, value), stored in the file.
    pub fields: Vec<(String, f64)>,
    /// The parametric model they make.
    pub parametric: Parametric,
}

/// What [`learn`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Learned {
    /// The residual, ready to write.
    pub residual: LearnedResidual,
    /// Basis groups the flight did not excite (with why), not offered.
    pub unexcited: Vec<(Feature, String)>,
    /// Candidates tried (window × basis × λ).
    pub candidates: usize,
}

/// The bases tried, before the excitation check.
fn bases() -> Vec<Vec<Feature>> {
    use Feature::*;
    vec![
        vec![Bias],
        vec![Bias, Velocity],
        vec![Bias, Quadratic],
        vec![Bias, Velocity, Quadratic],
        vec![Bias, Quadratic, RotorPlane],
        vec![Bias, Velocity, Quadratic, RotorPlane],
    ]
}

fn support_of(samples: &[Sample]) -> Support {
    let mut s = Support {
        speed_max: 0.0,
        tilt_max: 0.0,
        thrust_min: f64::INFINITY,
        thrust_max: 0.0,
    };
    for x in samples {
        s.speed_max = s.speed_max.max(x.speed);
        s.tilt_max = s.tilt_max.max(x.tilt);
        s.thrust_min = s.thrust_min.min(x.thrust);
        s.thrust_max = s.thrust_max.max(x.thrust);
    }
    s.thrust_min = s.thrust_min.min(s.thrust_max);
    s
}

fn std_of(v: impl Iterator<Item = f64> + Clone) -> f64 {
    let n = v.clone().count().max(1) as f64;
    let m = v.clone().sum::<f64>() / n;
    (v.map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
}

/// Learns the residual of `vehicle`'s parametric model from the engaged
/// runs of one or more records; `seconds` is their engaged time.
pub fn learn(runs: &[Run], vehicle: &VehicleTable) -> Result<Learned, LearnError> {
    let model = &vehicle.parametric;
    let seconds: f64 = runs.iter().map(|r| r.ticks.len() as f64 * model.dt).sum();
    if seconds < MIN_SECONDS {
        return Err(LearnError::TooShort { seconds });
    }
    let prepared: Vec<Prepared> = runs
        .iter()
        .filter(|r| r.ticks.len() > 2 * WINDOWS[WINDOWS.len() - 1])
        .map(|r| Prepared::new(r, model))
        .collect();
    let horizon = (HORIZON_S / model.dt).round() as usize;
    let base = fit::rollouts(&prepared, model, None, Part::Validate, horizon, STRIDE);
    let probe = fit::samples(&prepared, model, 2, &[Feature::Bias], Part::Train);
    let speed_std = std_of(probe.iter().map(|s| s.speed));
    let mut unexcited = Vec::new();
    if speed_std < MIN_SPEED_STD {
        for f in [Feature::Velocity, Feature::Quadratic, Feature::RotorPlane] {
            unexcited.push((
                f,
                format!("speed std {speed_std:.2} m/s < {MIN_SPEED_STD} m/s"),
            ));
        }
    }
    let offered: Vec<Vec<Feature>> = bases()
        .into_iter()
        .filter(|b| b.iter().all(|f| !unexcited.iter().any(|(u, _)| u == f)))
        .collect();
    let mut best: Option<(f64, LearnedResidual)> = None;
    let mut candidates = 0;
    for r in WINDOWS {
        for features in &offered {
            let train = fit::samples(&prepared, model, r, features, Part::Train);
            let support = support_of(&train);
            for lambda in LAMBDAS {
                candidates += 1;
                let Some(weights) = fit::ridge(&train, columns(features), lambda) else {
                    continue;
                };
                let candidate = residual_file(vehicle, r, features, lambda, weights, support);
                let e = fit::rollouts(
                    &prepared,
                    model,
                    Some(&candidate),
                    Part::Validate,
                    horizon,
                    STRIDE,
                );
                let score = e.horizon_rms();
                if score.is_finite() && best.as_ref().is_none_or(|(b, _)| score < *b) {
                    best = Some((score, candidate));
                }
            }
        }
    }
    let (score, mut residual) = best.ok_or(LearnError::NoFit)?;
    if base.count > 0 && score >= base.horizon_rms() {
        return Err(LearnError::NoImprovement {
            horizon_s: HORIZON_S,
            parametric_m: base.horizon_rms(),
            learned_m: score,
        });
    }
    let test_p = fit::rollouts(&prepared, model, None, Part::Test, horizon, STRIDE);
    let test_l = fit::rollouts(
        &prepared,
        model,
        Some(&residual),
        Part::Test,
        horizon,
        STRIDE,
    );
    residual.validation = validation(&test_p, &test_l);
    residual.seconds = seconds;
    Ok(Learned {
        residual,
        unexcited,
        candidates,
    })
}

fn validation(parametric: &Errors, learned: &Errors) -> Validation {
    Validation {
        one_step_parametric_m: parametric.one_step_rms(),
        one_step_learned_m: learned.one_step_rms(),
        horizon_s: HORIZON_S,
        horizon_parametric_m: parametric.horizon_rms(),
        horizon_learned_m: learned.horizon_rms(),
        samples: learned.count,
    }
}

fn residual_file(
    vehicle: &VehicleTable,
    window: usize,
    features: &[Feature],
    lambda: f64,
    weights: [Vec<f64>; 3],
    support: Support,
) -> LearnedResidual {
    LearnedResidual {
        format: FORMAT.into(),
        version: VERSION,
        vehicle_model: vehicle.model.clone(),
        vehicle: vehicle.fields.iter().cloned().collect::<BTreeMap<_, _>>(),
        dt: vehicle.parametric.dt,
        window,
        features: features.to_vec(),
        lambda,
        weights,
        support,
        validation: Validation {
            one_step_parametric_m: 0.0,
            one_step_learned_m: 0.0,
            horizon_s: HORIZON_S,
            horizon_parametric_m: 0.0,
            horizon_learned_m: 0.0,
            samples: 0,
        },
        seconds: 0.0,
    }
}

#[cfg(test)]
mod tests;
