//! The controllers under test, as plain serialisable specifications.

use std::sync::Arc;

use dflat_control::dfmpc::{DfMpc, DfMpcSettings, InputSaturation, OutputConstraints};
use dflat_control::estimator::{EstimatorSettings, StateSource};
use dflat_control::fmpc::{FlatnessMpc, FmpcSettings};
use dflat_control::pd::{Pd, PdSettings};
use dflat_control::window::MultiRateSettings;
use dflat_control::{
    ControlError, ControlModel, Controller, Measurement, ReferenceSource, TickOutput, TiltLimit,
};
use dflat_model::{PlanarModel, PlanarParams};
use serde::{Deserialize, Serialize};

use super::ExperimentError;
use crate::harness::ControllerFactory;

/// One controller with its settings, on the planar control model (δt =
/// 0.02 s, τ = 0.2 s, k̃ = 1, g = 9.81, ψ = 0, NED — the plant's nominal
/// values). Weights: q tracks position \[1/m²\], r weights the squared jerk
/// \[s⁶/m²\] (DF-MPC: `R = r/δt⁶` on the raw third difference, so the
/// paper's R = 1.25e9 is r = 0.08). Tilts in degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ControllerSpec {
    /// Discrete-flatness MPC ([`DfMpc`]), unconstrained fast path, command
    /// clipped at ±`max_tilt_deg`.
    DfMpc {
        /// Horizon N [steps of δt].
        horizon: usize,
        /// Tracking weight q (x and y).
        q: f64,
        /// Jerk weight r (x and y).
        r: f64,
        /// Command saturation \[deg\].
        max_tilt_deg: f64,
    },
    /// DF-MPC as the daemon ships it (`df-mr-smooth`, name
    /// "df-mr-smooth"): multi-rate windows fed with every pose sample at
    /// its capture time, command-smoothness weight, tilt bound on the plan
    /// per axis (`docs/configuration.md`, `config/default.toml`).
    DfMrSmooth {
        /// Horizon N [steps of δt].
        horizon: usize,
        /// Tracking weight q (x and y).
        q: f64,
        /// Jerk weight r (x and y).
        r: f64,
        /// Command-smoothness weight (x and y) [1/rad²].
        smoothness: f64,
        /// Tilt bound on the plan, per axis \[deg\].
        plan_tilt_deg: f64,
        /// Command saturation \[deg\].
        max_tilt_deg: f64,
    },
    /// Flatness MPC ([`FlatnessMpc`]) on finite-difference flat states, or
    /// on a state estimator's (`estimator`).
    Fmpc {
        /// Horizon N [steps of δt].
        horizon: usize,
        /// Tracking weight q (x and y).
        q: f64,
        /// Jerk weight r (x and y).
        r: f64,
        /// Command saturation \[deg\].
        max_tilt_deg: f64,
        /// The state estimator ([`StateSource::Estimator`]; name
        /// "fmpc-est"); absent: finite differences (the paper's §VI set-up,
        /// name "fmpc").
        #[serde(default, skip_serializing_if = "Option::is_none")]
        estimator: Option<EstimatorSettings>,
    },
    /// PD on the closest path point and the desired velocity ([`Pd`]),
    /// finite-difference velocity or a state estimator's (`estimator`).
    Pd {
        /// Position gain k_p \[1/s²\].
        kp: f64,
        /// Velocity gain k_d \[1/s\].
        kd: f64,
        /// Command saturation (and acceleration limit g·tan) \[deg\].
        max_tilt_deg: f64,
        /// The state estimator (name "pd-est"); absent: finite
        /// differences (name "pd").
        #[serde(default, skip_serializing_if = "Option::is_none")]
        estimator: Option<EstimatorSettings>,
    },
}

impl ControllerSpec {
    /// The shipped DF-MPC (`df-mr-smooth`: N = 100, q = 1, r = 0.003,
    /// smoothness 50, 30° plan tilt) at the tilt limit `max_tilt_deg`
    /// \[deg\].
    pub fn shipped_dfmpc(max_tilt_deg: f64) -> Self {
        Self::DfMrSmooth {
            horizon: 100,
            q: 1.0,
            r: 0.003,
            smoothness: 50.0,
            plan_tilt_deg: 30.0,
            max_tilt_deg,
        }
    }

    /// The controller's short name: "df-mpc", "fmpc" or "pd" (as its
    /// [`Controller::name`]), "fmpc-est" or "pd-est" for the baselines fed
    /// by the state estimator.
    pub fn name(&self) -> &'static str {
        match self {
            Self::DfMpc { .. } => "df-mpc",
            Self::DfMrSmooth { .. } => "df-mr-smooth",
            Self::Fmpc {
                estimator: None, ..
            } => "fmpc",
            Self::Fmpc { .. } => "fmpc-est",
            Self::Pd {
                estimator: None, ..
            } => "pd",
            Self::Pd { .. } => "pd-est",
        }
    }

    /// The paper's label: "Discrete-Flatness", "Flatness MPC", "PD"; the
    /// estimator-fed baselines add "(estimator)".
    pub fn label(&self) -> &'static str {
        match self {
            Self::DfMpc { .. } => "Discrete-Flatness",
            Self::DfMrSmooth { .. } => "Discrete-Flatness (as shipped)",
            Self::Fmpc {
                estimator: None, ..
            } => "Flatness MPC",
            Self::Fmpc { .. } => "Flatness MPC (estimator)",
            Self::Pd {
                estimator: None, ..
            } => "PD",
            Self::Pd { .. } => "PD (estimator)",
        }
    }

    /// The same spec with its state estimator's settings replaced by `e`,
    /// if it is an estimator-fed baseline (else unchanged).
    pub fn with_estimator(mut self, e: EstimatorSettings) -> Self {
        if let Self::Fmpc {
            estimator: Some(old),
            ..
        }
        | Self::Pd {
            estimator: Some(old),
            ..
        } = &mut self
        {
            *old = e;
        }
        self
    }

    /// The baseline's state source (finite differences for DF-MPC, which
    /// has none).
    fn state_source(&self) -> StateSource {
        match self {
            Self::Fmpc {
                estimator: Some(e), ..
            }
            | Self::Pd {
                estimator: Some(e), ..
            } => StateSource::Estimator(*e),
            _ => StateSource::FiniteDifference,
        }
    }

    /// The tuned parameter in words, e.g. "r = 0.08" or "kp = 2, kd = 2.5".
    pub fn describe(&self) -> String {
        match self {
            Self::DfMpc { horizon, q, r, .. } | Self::Fmpc { horizon, q, r, .. } => {
                format!("N = {horizon}, q = {q}, r = {r}")
            }
            Self::DfMrSmooth {
                horizon,
                q,
                r,
                smoothness,
                plan_tilt_deg,
                ..
            } => format!(
                "N = {horizon}, q = {q}, r = {r}, s = {smoothness}, plan ≤ {plan_tilt_deg}°"
            ),
            Self::Pd { kp, kd, .. } => format!("kp = {kp}, kd = {kd}"),
        }
    }

    /// DF-MPC's settings for the DF variants, as [`ControllerSpec::build`]
    /// flies them on the planar model; `None` for the baselines.
    pub fn df_settings(&self) -> Option<DfMpcSettings> {
        match *self {
            Self::DfMpc {
                horizon,
                q,
                r,
                max_tilt_deg,
            } => Some(DfMpcSettings {
                horizon,
                tracking_weight: [q; 3],
                jerk_weight: [r; 3],
                saturation: Some(InputSaturation {
                    max_tilt: max_tilt_deg.to_radians(),
                    ..InputSaturation::default()
                }),
                ..DfMpcSettings::default()
            }),
            Self::DfMrSmooth {
                horizon,
                q,
                r,
                smoothness,
                plan_tilt_deg,
                max_tilt_deg,
            } => Some(smooth_dfmpc_settings(
                (horizon, q, r, smoothness),
                Some(MultiRateSettings::default()),
                Some(plan_tilt_deg),
                max_tilt_deg,
            )),
            Self::Fmpc { .. } | Self::Pd { .. } => None,
        }
    }

    /// Builds the controller.
    pub fn build(&self) -> Result<Box<dyn Controller>, ExperimentError> {
        let model = planar_model().map_err(|e| ExperimentError::Controller {
            controller: self.name(),
            source: e,
        })?;
        let wrap = |source| ExperimentError::Controller {
            controller: self.name(),
            source,
        };
        let state = self.state_source();
        if let Some(settings) = self.df_settings() {
            return Ok(Box::new(DfMpc::new(model, settings).map_err(wrap)?));
        }
        Ok(match *self {
            Self::DfMpc { .. } | Self::DfMrSmooth { .. } => {
                unreachable!("DF variants have settings")
            }
            Self::Fmpc {
                horizon,
                q,
                r,
                max_tilt_deg,
                ..
            } => Box::new(
                FlatnessMpc::new(
                    model,
                    FmpcSettings {
                        horizon,
                        q: [q; 3],
                        r: [r; 3],
                        max_tilt: Some(max_tilt_deg.to_radians()),
                        // The lab's plants clip each channel the same way.
                        tilt_limit: TiltLimit::PerAxis,
                        state,
                    },
                )
                .map_err(wrap)?,
            ),
            Self::Pd {
                kp,
                kd,
                max_tilt_deg,
                ..
            } => {
                let tilt = max_tilt_deg.to_radians();
                Box::new(
                    Pd::new(
                        model,
                        PdSettings {
                            kp: [kp; 3],
                            kd: [kd; 3],
                            max_horizontal_acceleration: 9.81 * tilt.tan(),
                            max_tilt: tilt,
                            state,
                            ..PdSettings::default()
                        },
                    )
                    .map_err(wrap)?,
                )
            }
        })
    }

    /// A factory for the harness. The controller is built once here to
    /// check the settings; should a later build fail anyway, the trial gets
    /// a controller that reports the error at every tick (recorded by the
    /// harness), never a panic.
    pub fn factory(&self) -> Result<ControllerFactory, ExperimentError> {
        self.build()?;
        let spec = *self;
        Ok(Arc::new(move || match spec.build() {
            Ok(c) => c,
            Err(e) => Box::new(Unbuildable::new(spec.name(), &e)),
        }))
    }
}

/// The planar control model with the lab's nominal parameters.
pub(crate) fn planar_model() -> Result<ControlModel, ControlError> {
    Ok(ControlModel::Planar(PlanarModel::new(
        PlanarParams::default(),
    )?))
}

/// Stand-in for a controller whose construction failed: every tick errors.
pub(crate) struct Unbuildable {
    name: &'static str,
    message: String,
}

impl Unbuildable {
    /// The stand-in for controller `name` that failed with `error`.
    pub(crate) fn new(name: &'static str, error: &dyn std::fmt::Display) -> Self {
        Self {
            name,
            message: error.to_string(),
        }
    }
}

impl Controller for Unbuildable {
    fn name(&self) -> &'static str {
        self.name
    }

    fn update(
        &mut self,
        _m: &Measurement,
        _r: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        Err(ControlError::InvalidSetting {
            field: "controller",
            reason: self.message.clone(),
        })
    }

    fn reset(&mut self) {}
}

/// The lab's DF-MPC with a smoothness weight: `(horizon, q, r, smoothness)`
/// on x and y, the pose window `multi_rate`, the plan's tilt bound
/// `plan_tilt_deg` and the command's tilt limit `max_tilt_deg` \[deg\], no
/// wall-clock limit (the lab is deterministic).
pub(crate) fn smooth_dfmpc_settings(
    (horizon, q, r, smoothness): (usize, f64, f64, f64),
    multi_rate: Option<MultiRateSettings>,
    plan_tilt_deg: Option<f64>,
    max_tilt_deg: f64,
) -> DfMpcSettings {
    DfMpcSettings {
        horizon,
        tracking_weight: [q; 3],
        jerk_weight: [r; 3],
        smoothness_weight: [smoothness, smoothness, 0.0],
        multi_rate,
        constraints: OutputConstraints {
            max_tilt: plan_tilt_deg.map(f64::to_radians),
            ..OutputConstraints::default()
        },
        saturation: Some(InputSaturation {
            max_tilt: max_tilt_deg.to_radians(),
            ..InputSaturation::default()
        }),
        solver_time_limit: f64::INFINITY,
        ..DfMpcSettings::default()
    }
}
