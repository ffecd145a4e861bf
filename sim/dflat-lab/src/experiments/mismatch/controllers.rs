//! The mismatch study's controllers: the six compared and the multi-rate
//! DF-MPC set-up.

use dflat_control::dfmpc::{
    DfMpcSettings, InputSaturation, OutputConstraints, PlanTiltBound, QpSolver,
};
use dflat_control::disturbance::DisturbanceSettings;
use dflat_control::window::MultiRateSettings;
use serde::{Deserialize, Serialize};

use super::{DF_EST_DARK_RED, DF_MR_EST_DARK_PURPLE, DF_MR_PURPLE};
use crate::plot::{DF_RED, FMPC_BLUE, PD_GREEN, RGBColor};

/// The multi-rate DF-MPC of the study: the vision-rate study's
/// recommended `df-mr-smooth` (multi-rate window, command smoothness, jerk
/// weight, plan-tilt bound) on the spatial model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MultiRateDf {
    /// Horizon N \[ticks\].
    pub horizon: usize,
    /// Tracking weight q \[1/m²\] (every axis).
    pub q: f64,
    /// Jerk weight r \[s⁶/m²\] (every axis).
    pub r: f64,
    /// Command-smoothness weight s \[1/rad²\] per axis `[x, y, z]`.
    pub smoothness: [f64; 3],
    /// Tilt bound on the plan \[deg\] (clarabel when it binds).
    pub plan_tilt_deg: f64,
    /// The multi-rate window (M = 25 by default).
    pub window: MultiRateSettings,
}

impl Default for MultiRateDf {
    /// N = 100, q = 1, r = 0.003, s = 50 on x, y, 30° plan tilt, the
    /// [`MultiRateSettings`] defaults (M = 25).
    fn default() -> Self {
        Self {
            horizon: 100,
            q: 1.0,
            r: 0.003,
            smoothness: [50.0, 50.0, 0.0],
            plan_tilt_deg: 30.0,
            window: MultiRateSettings::default(),
        }
    }
}

impl MultiRateDf {
    /// The DF-MPC settings, command clipped at `max_tilt` \[rad\] and
    /// `thrust_max` \[m/s²\] (spatial), with `disturbance`.
    pub fn settings(
        &self,
        max_tilt: f64,
        thrust_max: f64,
        disturbance: Option<DisturbanceSettings>,
    ) -> DfMpcSettings {
        DfMpcSettings {
            horizon: self.horizon,
            tracking_weight: [self.q; 3],
            jerk_weight: [self.r; 3],
            smoothness_weight: self.smoothness,
            multi_rate: Some(self.window),
            constraints: OutputConstraints {
                max_tilt: Some(self.plan_tilt_deg.to_radians()),
                ..OutputConstraints::default()
            },
            saturation: Some(InputSaturation {
                max_tilt,
                thrust_max,
                ..InputSaturation::default()
            }),
            qp_solver: QpSolver::default(),
            // The box per axis, as this study was run (the cone
            // came later; stated here so the study's JSON stays as it is).
            plan_tilt_bound: PlanTiltBound::Box,
            warm_start: true,
            // The lab is deterministic: no wall-clock limit.
            solver_time_limit: f64::INFINITY,
            disturbance,
            delay_ticks: 0,
        }
    }
}

/// The controllers compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MismatchController {
    /// DF-MPC, library defaults.
    Df,
    /// DF-MPC with the disturbance estimator.
    DfEstimator,
    /// DF-MPC on multi-rate windows with the command-smoothness weight
    /// (the recommended set-up of the vision-rate study, [`MultiRateDf`]).
    DfMultiRate,
    /// The same with the disturbance estimator (fed the raw samples).
    DfMultiRateEstimator,
    /// Flatness MPC, library defaults.
    Fmpc,
    /// PD, library defaults.
    Pd,
}

impl MismatchController {
    /// All six, in table order.
    pub const ALL: [Self; 6] = [
        Self::Df,
        Self::DfEstimator,
        Self::DfMultiRate,
        Self::DfMultiRateEstimator,
        Self::Fmpc,
        Self::Pd,
    ];

    /// The variants with the estimator (the steady-state budget's rows).
    pub const WITH_ESTIMATOR: [Self; 2] = [Self::DfEstimator, Self::DfMultiRateEstimator];

    /// Short name: "df-mpc", "df-mpc+est", "df-mr-smooth",
    /// "df-mr-smooth+est", "fmpc", "pd".
    pub fn name(self) -> &'static str {
        match self {
            Self::Df => "df-mpc",
            Self::DfEstimator => "df-mpc+est",
            Self::DfMultiRate => "df-mr-smooth",
            Self::DfMultiRateEstimator => "df-mr-smooth+est",
            Self::Fmpc => "fmpc",
            Self::Pd => "pd",
        }
    }

    /// Label for tables and legends.
    pub fn label(self) -> &'static str {
        match self {
            Self::Df => "DF",
            Self::DfEstimator => "DF + estimator",
            Self::DfMultiRate => "DF multi-rate",
            Self::DfMultiRateEstimator => "DF multi-rate + estimator",
            Self::Fmpc => "Flatness MPC",
            Self::Pd => "PD",
        }
    }

    /// Plot colour: DF red, DF + estimator dark red, FMPC blue, PD green.
    pub fn color(self) -> RGBColor {
        match self {
            Self::Df => DF_RED,
            Self::DfEstimator => DF_EST_DARK_RED,
            Self::DfMultiRate => DF_MR_PURPLE,
            Self::DfMultiRateEstimator => DF_MR_EST_DARK_PURPLE,
            Self::Fmpc => FMPC_BLUE,
            Self::Pd => PD_GREEN,
        }
    }
}
