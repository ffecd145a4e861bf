//! `[controller.estimator]`: the baselines' state source (Flatness MPC, PD).

use dflat_control::estimator::{EstimatorSettings, StateSource};
use serde::{Deserialize, Serialize};

use super::validate::Validator;
use super::{ConfigError, ControllerConfig, VehicleConfig};

/// Where the baselines (`kind = "fmpc"`, `"pd"`) take their state from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum StateSourceKind {
    /// A Kalman filter over every pose at its capture time, predicted to
    /// the tick through the sent commands (the paper's outdoor set-up).
    #[default]
    Estimator,
    /// Finite differences of the newest positions, one per tick (the
    /// paper's simulation set-up; noisy and bang-bang with slow poses).
    FiniteDifference,
}

/// `[controller.estimator]`: the baselines' state estimator
/// ([`dflat_control::estimator`]). Unused by df-mpc.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimatorConfig {
    /// "estimator" (default) or "finite-difference".
    pub state_source: StateSourceKind,
    /// Pose rate the noise rule assumes \[Hz\] (1–400). Default 15 (the
    /// paper's camera; 50 for a 50 Hz pose stream).
    pub pose_rate_hz: f64,
    /// White-jerk spectral density [m²/s⁵] (0 = derived: bandwidth
    /// ω = 2π·min(pose_rate_hz/10, 1.5 Hz), `q = σ²ω⁶/pose_rate_hz` with σ =
    /// `controller.sample_sigma`; 18.5 at the defaults; else 1e-12–1e6,
    /// [`EstimatorSettings::JERK_PSD`]).
    pub jerk_psd: f64,
    /// Predict with the sent commands (acceleration lag `vehicle.tau`):
    /// compensates the pose latency through the model. Default true; false
    /// is the constant-acceleration prior alone (STEAM's).
    pub use_inputs: bool,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            state_source: StateSourceKind::Estimator,
            pose_rate_hz: dflat_control::estimator::DEFAULT_POSE_RATE_HZ,
            jerk_psd: 0.0,
            use_inputs: true,
        }
    }
}

impl EstimatorConfig {
    /// The baselines' state source for this configuration.
    pub fn state_source(
        &self,
        controller: &ControllerConfig,
        vehicle: &VehicleConfig,
    ) -> StateSource {
        match self.state_source {
            StateSourceKind::FiniteDifference => StateSource::FiniteDifference,
            StateSourceKind::Estimator => {
                let mut s =
                    EstimatorSettings::for_sensor(controller.sample_sigma, self.pose_rate_hz);
                if self.jerk_psd > 0.0 {
                    s.jerk_psd = self.jerk_psd;
                }
                s.input_lag = self.use_inputs.then_some(vehicle.tau);
                StateSource::Estimator(s)
            }
        }
    }

    pub(super) fn validate(&self, v: &mut Validator<'_>) -> Result<(), ConfigError> {
        v.limit(
            "controller.estimator.pose_rate_hz",
            self.pose_rate_hz,
            EstimatorSettings::POSE_RATE_HZ,
        )?;
        v.limit_or_off(
            "controller.estimator.jerk_psd",
            self.jerk_psd,
            EstimatorSettings::JERK_PSD,
        )
    }
}
