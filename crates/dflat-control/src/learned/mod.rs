//! The learned residual of the flat maps: the acceleration the parametric
//! model does not explain, as a function of the output window and the
//! inputs sent (pure maths; the file is read and written by the shells).
//!
//! The parametric model predicts the specific force of the thrust and the
//! linear drag; the airframe adds what no parametric term has (parasitic
//! drag quadratic in speed, rotor drag in the body plane, …). The residual
//!
//! ```text
//! ρ(v, n) = W·φ(v, n)        [m/s², local NED]
//! ```
//!
//! is linear in its weights `W` (3 × m) over a basis `φ` of [`Feature`]
//! groups of the velocity `v` (local NED [m/s], from the window of the last
//! [`LearnedResidual::window`] measured outputs) and the thrust axis `n`
//! (unit `R·e3`, NED, from the inputs sent): a constant, `v`, `|v|·v`, and
//! `v − n·(n·v)` (the velocity across the thrust axis, `R·diag(1,1,0)·Rᵀ·v`).
//! It is learned by regularised least squares from flight records alone
//! (`dflat learn`: commands sent and poses measured, no state estimate).
//!
//! A residual acts only inside the [`Support`] of its data: the speed, the
//! tilt and the specific thrust it was learned over. Beyond [`FULL_MARGIN`]
//! of an edge its weight [`LearnedResidual::support_weight`] fades
//! linearly, to 0 at [`FADE_MARGIN`], so the prediction falls back to the
//! parametric model.
//!
//! A residual is learned against one `[vehicle]` table (its parametric
//! model): [`LearnedResidual::check_vehicle`] refuses another one.

mod term;

pub use term::{
    ERROR_FLOOR, ERROR_RATIO_FULL, ERROR_RATIO_OFF, ERROR_TICKS, LearnedStatus, LearnedTerm,
    RunningError,
};

use std::collections::BTreeMap;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The `format` every learned-residual file carries.
pub const FORMAT: &str = "dflat-learned-residual";
/// The file version this build writes (2: the window counts poses
/// centred on the sample, the held-out acceleration reported; 3: the
/// held-out predictions' start windows, [`Validation::start_parametric_s`]
/// and [`Validation::start_learned_s`]).
pub const VERSION: u32 = 3;
/// The oldest file version this build reads: a version-2 file's held-out
/// predictions started from 0.4 s of poses ([`LEGACY_START_S`]).
pub const MIN_VERSION: u32 = 2;
/// The start window of a version-2 file's held-out predictions \[s\].
pub const LEGACY_START_S: f64 = 0.4;

fn legacy_start_s() -> f64 {
    LEGACY_START_S
}
/// Relative reach beyond each edge of the support where the residual still
/// acts in full (0.1: a speed 10 % above the fastest flown, a thrust 10 %
/// below the least): a smooth basis extrapolates that far, and a flight
/// that tracks better than the ones learned from flies a little faster.
pub const FULL_MARGIN: f64 = 0.1;
/// Relative reach beyond each edge where it has faded to 0 (linearly from
/// [`FULL_MARGIN`]).
pub const FADE_MARGIN: f64 = 0.3;
/// Relative difference of a `[vehicle]` value from the one the residual
/// was learned with that still counts as the same table.
pub const VEHICLE_TOLERANCE: f64 = 1e-6;

/// `[vehicle]` fields added after model files were first written, with the
/// value every earlier file was learned at: `drag_rotor` (none).
pub const FIELDS_ADDED_LATER: &[(&str, f64)] = &[("drag_rotor", 0.0)];

/// A group of basis functions; each adds its columns to `φ` in this order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Feature {
    /// 1 (one column): a constant acceleration (wind, bias). Model files
    /// may carry it and fly it; `dflat learn` no longer fits it (a constant
    /// is the day's wind or a trim, which the disturbance estimator
    /// estimates in flight: `dflat_tuning::learn`'s module docs).
    Bias,
    /// `v` (three columns, NED [m/s]): linear drag beyond the model's.
    Velocity,
    /// `|v|·v` (three columns, [m²/s²]): parasitic drag.
    Quadratic,
    /// `v − n·(n·v)` (three columns, [m/s]): rotor drag in the body plane.
    RotorPlane,
}

impl Feature {
    /// Number of columns the group adds to `φ`.
    pub const fn columns(self) -> usize {
        match self {
            Self::Bias => 1,
            _ => 3,
        }
    }

    /// The group's name in files and reports.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Bias => "bias",
            Self::Velocity => "velocity",
            Self::Quadratic => "quadratic",
            Self::RotorPlane => "rotor_plane",
        }
    }
}

/// Writes the columns of `features` at velocity `v` (NED [m/s]) and thrust
/// axis `n` (unit, NED) into `out` (at least [`columns`] long); returns how
/// many were written.
pub fn basis(features: &[Feature], v: &Vector3<f64>, n: &Vector3<f64>, out: &mut [f64]) -> usize {
    let mut i = 0;
    for f in features {
        let cols: [f64; 3] = match f {
            Feature::Bias => [1.0, 0.0, 0.0],
            Feature::Velocity => [v.x, v.y, v.z],
            Feature::Quadratic => {
                let s = v.norm();
                [s * v.x, s * v.y, s * v.z]
            }
            Feature::RotorPlane => {
                let a = v - n * n.dot(v);
                [a.x, a.y, a.z]
            }
        };
        let m = f.columns();
        out[i..i + m].copy_from_slice(&cols[..m]);
        i += m;
    }
    i
}

/// Unit thrust axis `R·e3` (NED) of ZYX angles \[rad\] (thrust acts along
/// its negative).
pub fn thrust_axis(roll: f64, pitch: f64, yaw: f64) -> Vector3<f64> {
    let (sp, cp) = roll.sin_cos();
    let (st, ct) = pitch.sin_cos();
    let (ss, cs) = yaw.sin_cos();
    Vector3::new(cs * st * cp + ss * sp, ss * st * cp - cs * sp, ct * cp)
}

/// Number of columns of `φ` for `features`.
pub fn columns(features: &[Feature]) -> usize {
    features.iter().map(|f| f.columns()).sum()
}

/// The ranges the residual's data covered.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Support {
    /// Largest speed [m/s] (the smallest is 0).
    pub speed_max: f64,
    /// Largest tilt of the thrust axis from vertical \[rad\].
    pub tilt_max: f64,
    /// Smallest specific thrust [m/s²].
    pub thrust_min: f64,
    /// Largest specific thrust [m/s²].
    pub thrust_max: f64,
}

/// Held-out prediction errors, the learned model against the parametric
/// one (RMS over the held-out samples, metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Validation {
    /// One-step prediction error of the parametric model \[m\].
    pub one_step_parametric_m: f64,
    /// One-step prediction error with the residual \[m\].
    pub one_step_learned_m: f64,
    /// Horizon over which the horizon errors are taken \[s\].
    pub horizon_s: f64,
    /// Error at the horizon of the parametric model \[m\].
    pub horizon_parametric_m: f64,
    /// Error at the horizon with the residual \[m\].
    pub horizon_learned_m: f64,
    /// Held-out samples.
    pub samples: usize,
    /// The span of poses the parametric model's held-out predictions
    /// start from \[s\] (chosen on the validation blocks: the
    /// input-to-output map's window from data).
    #[serde(default = "legacy_start_s")]
    pub start_parametric_s: f64,
    /// The same for the model with the residual \[s\].
    #[serde(default = "legacy_start_s")]
    pub start_learned_s: f64,
    /// RMS acceleration the parametric model leaves on the test blocks
    /// [m/s²].
    pub acceleration_parametric: f64,
    /// RMS acceleration the residual leaves there [m/s²].
    pub acceleration_learned: f64,
}

impl Validation {
    /// Nothing measured yet (every error and count zero) over a horizon of
    /// `horizon_s` \[s\]: what a model carries before its held-out check.
    pub fn unmeasured(horizon_s: f64) -> Self {
        Self {
            one_step_parametric_m: 0.0,
            one_step_learned_m: 0.0,
            horizon_s,
            horizon_parametric_m: 0.0,
            horizon_learned_m: 0.0,
            samples: 0,
            start_parametric_s: 0.0,
            start_learned_s: 0.0,
            acceleration_parametric: 0.0,
            acceleration_learned: 0.0,
        }
    }
}

/// A learned residual as stored in its file (TOML): versioned, with the
/// `[vehicle]` table it was learned with and the support of its data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearnedResidual {
    /// Always [`FORMAT`].
    pub format: String,
    /// File version ([`VERSION`]).
    pub version: u32,
    /// `vehicle.model` it was learned with (`planar`, `spatial`, `full`).
    pub vehicle_model: String,
    /// The numeric `[vehicle]` fields it was learned with (name → value).
    pub vehicle: BTreeMap<String, f64>,
    /// Control step δt \[s\] of the records.
    pub dt: f64,
    /// Poses in the window (centred on each sample) the velocity and the
    /// acceleration were taken through when learning (odd, 3 ..= 51).
    pub window: usize,
    /// The basis, in column order.
    pub features: Vec<Feature>,
    /// Ridge regularisation λ (on standardised columns).
    pub lambda: f64,
    /// Weights, one row of [`columns`] values per NED axis [m/s² per unit].
    pub weights: [Vec<f64>; 3],
    /// The data's ranges.
    pub support: Support,
    /// Held-out errors at learning time.
    pub validation: Validation,
    /// Seconds of flight it was learned from.
    pub seconds: f64,
}

/// Why a learned residual cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LearnedError {
    /// Not a learned-residual file.
    #[error("format = {found:?}: not a learned residual (expected {FORMAT:?})")]
    Format {
        /// The `format` found.
        found: String,
    },
    /// A version this build does not read.
    #[error(
        "version = {found}: this build reads versions {MIN_VERSION} ..= {VERSION}; learn it again"
    )]
    Version {
        /// The version found.
        found: u32,
    },
    /// A field out of range.
    #[error("{field} = {value}: allowed {allowed}")]
    Field {
        /// The field.
        field: String,
        /// The offending value, as text.
        value: String,
        /// What is allowed.
        allowed: String,
    },
    /// Learned against another `[vehicle]` table.
    #[error(
        "learned with vehicle.{field} = {learned}, but this configuration has {configured}: \
         a residual is learned over one parametric model; learn it again with this [vehicle] table"
    )]
    Vehicle {
        /// The `[vehicle]` field that differs.
        field: String,
        /// The value the residual was learned with (as text).
        learned: String,
        /// The configured value (as text).
        configured: String,
    },
}

fn field_err(field: &str, value: impl ToString, allowed: &str) -> LearnedError {
    LearnedError::Field {
        field: field.to_owned(),
        value: value.to_string(),
        allowed: allowed.to_owned(),
    }
}

fn finite_in(field: &str, v: f64, lo: f64, hi: f64) -> Result<(), LearnedError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(field_err(field, v, &format!("finite, {lo} ..= {hi}")))
    }
}

impl LearnedResidual {
    /// Checks the format, the version and every field; the error names the
    /// field and what is allowed.
    pub fn validate(&self) -> Result<(), LearnedError> {
        if self.format != FORMAT {
            return Err(LearnedError::Format {
                found: self.format.clone(),
            });
        }
        if !(MIN_VERSION..=VERSION).contains(&self.version) {
            return Err(LearnedError::Version {
                found: self.version,
            });
        }
        finite_in("dt", self.dt, 1e-4, 1.0)?;
        if !(3..=51).contains(&self.window) || self.window.is_multiple_of(2) {
            return Err(field_err("window", self.window, "odd, 3 ..= 51"));
        }
        let mut sorted = self.features.clone();
        sorted.sort();
        sorted.dedup();
        if self.features.is_empty() || sorted.len() != self.features.len() {
            return Err(field_err(
                "features",
                format!("{:?}", self.features),
                "one or more distinct groups",
            ));
        }
        finite_in("lambda", self.lambda, 0.0, 1e12)?;
        let m = columns(&self.features);
        for (axis, row) in ["weights[0]", "weights[1]", "weights[2]"]
            .iter()
            .zip(&self.weights)
        {
            if row.len() != m {
                return Err(field_err(axis, row.len(), &format!("{m} values")));
            }
            for w in row {
                finite_in(axis, *w, -1e3, 1e3)?;
            }
        }
        let s = &self.support;
        finite_in("support.speed_max", s.speed_max, 0.0, 200.0)?;
        finite_in("support.tilt_max", s.tilt_max, 0.0, 1.6)?;
        finite_in("support.thrust_min", s.thrust_min, 0.0, 200.0)?;
        finite_in("support.thrust_max", s.thrust_max, s.thrust_min, 200.0)?;
        for (k, v) in &self.vehicle {
            if !v.is_finite() {
                return Err(field_err(&format!("vehicle.{k}"), v, "finite"));
            }
        }
        finite_in("seconds", self.seconds, 0.0, 1e7)
    }

    /// Refuses a `[vehicle]` table other than the one the residual was
    /// learned with: `model` is `vehicle.model`, `vehicle` its numeric fields
    /// (name, value). Every field of the file must be present and equal
    /// within [`VEHICLE_TOLERANCE`] (relative); a field of
    /// [`FIELDS_ADDED_LATER`] the file does not hold was learned at its
    /// value there (a file written before the field existed).
    pub fn check_vehicle(&self, model: &str, vehicle: &[(&str, f64)]) -> Result<(), LearnedError> {
        for (field, before) in FIELDS_ADDED_LATER {
            let configured = vehicle.iter().find(|(k, _)| k == field).map(|(_, v)| *v);
            if let Some(c) = configured
                && !self.vehicle.contains_key(*field)
                && c != *before
            {
                return Err(LearnedError::Vehicle {
                    field: (*field).into(),
                    learned: format!("{before} (not in the file: written before the field)"),
                    configured: c.to_string(),
                });
            }
        }
        if model != self.vehicle_model {
            return Err(LearnedError::Vehicle {
                field: "model".into(),
                learned: self.vehicle_model.clone(),
                configured: model.to_owned(),
            });
        }
        for (field, learned) in &self.vehicle {
            let configured = vehicle.iter().find(|(k, _)| k == field).map(|(_, v)| *v);
            let same = configured.is_some_and(|c| {
                (c - learned).abs() <= VEHICLE_TOLERANCE * learned.abs().max(c.abs()).max(1e-9)
            });
            if !same {
                return Err(LearnedError::Vehicle {
                    field: field.clone(),
                    learned: learned.to_string(),
                    configured: configured.map_or("nothing".into(), |c| c.to_string()),
                });
            }
        }
        Ok(())
    }

    /// The raw residual [m/s², NED] at velocity `v` (NED [m/s]) and thrust
    /// axis `n` (unit, NED), without the support's fade.
    pub fn residual(&self, v: &Vector3<f64>, n: &Vector3<f64>) -> Vector3<f64> {
        let mut phi = [0.0; 16];
        let m = basis(&self.features, v, n, &mut phi);
        Vector3::from_fn(|axis, _| {
            self.weights[axis]
                .iter()
                .zip(&phi[..m])
                .map(|(w, p)| w * p)
                .sum()
        })
    }

    /// The weight in [0, 1] of the residual at `speed` [m/s], `tilt` \[rad\]
    /// and specific thrust `thrust` [m/s²]: 1 inside the support and up to
    /// [`FULL_MARGIN`] beyond an edge (relative to the edge's value: the
    /// fastest speed, the largest tilt, the least and the largest thrust),
    /// falling linearly to 0 at [`FADE_MARGIN`] beyond it (the product over
    /// the three); 0 for non-finite arguments.
    pub fn support_weight(&self, speed: f64, tilt: f64, thrust: f64) -> f64 {
        let s = &self.support;
        let fade = |out: f64, edge: f64| {
            let scale = edge.abs().max(1e-3);
            let full = FULL_MARGIN * scale;
            let zero = FADE_MARGIN * scale;
            (1.0 - (out - full).max(0.0) / (zero - full)).clamp(0.0, 1.0)
        };
        if !(speed.is_finite() && tilt.is_finite() && thrust.is_finite()) {
            return 0.0;
        }
        fade((speed - s.speed_max).max(0.0), s.speed_max)
            * fade((tilt - s.tilt_max).max(0.0), s.tilt_max)
            * fade((s.thrust_min - thrust).max(0.0), s.thrust_min)
            * fade((thrust - s.thrust_max).max(0.0), s.thrust_max)
    }

    /// The residual [m/s², NED] faded by [`Self::support_weight`]: the
    /// acceleration to add to the parametric model's at velocity `v`, thrust
    /// axis `n` and specific thrust `thrust` [m/s²]. Never non-finite: a
    /// non-finite result is 0 (the parametric model).
    pub fn acceleration(&self, v: &Vector3<f64>, n: &Vector3<f64>, thrust: f64) -> Vector3<f64> {
        let tilt = n.z.clamp(-1.0, 1.0).acos();
        let w = self.support_weight(v.norm(), tilt, thrust);
        if w == 0.0 {
            return Vector3::zeros();
        }
        let a = self.residual(v, n) * w;
        if a.iter().all(|x| x.is_finite()) {
            a
        } else {
            Vector3::zeros()
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
