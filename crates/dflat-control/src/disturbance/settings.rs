//! The disturbance estimator's settings and their one range each.

use serde::{Deserialize, Serialize};

use crate::{ControlError, Limit};

/// Largest accepted fit window [control steps].
pub const MAX_WINDOW: usize = 2000;
/// Smallest accepted fit window [control steps].
pub const MIN_WINDOW: usize = 10;
/// Multi-rate mode: pose samples kept per tick of the fit window (the ring
/// holds this many times L; beyond that the oldest are dropped).
pub const SAMPLES_PER_TICK: usize = 4;

/// Settings of [`DisturbanceEstimator`](super::DisturbanceEstimator), checked by
/// [`DisturbanceSettings::validate`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DisturbanceSettings {
    /// Bandwidth f_c of the first-order low-pass on the window fit \[Hz\]:
    /// the estimate follows a step in the disturbance with time constant
    /// 1/(2π·f_c) after about half the window. Default 0.1 Hz (1.6 s): at
    /// 0.2 Hz the estimate reacts more to the phantom disturbance of an
    /// attitude-gain or time-constant mismatch during a manoeuvre, which
    /// slows the settling of slow DF tunings (`dflat experiment mismatch`).
    pub bandwidth_hz: f64,
    /// Fit span L [control steps]. Longer: less noise (∝ L^−2.5 for the
    /// fit), more delay. Default 50 (1 s at 50 Hz). Serialized as `window`
    /// (the lab's JSON).
    #[serde(rename = "window")]
    pub fit_span: usize,
    /// Clamp on each component of the acceleration offset |d| \[m/s²\].
    /// Default 3 (≈ 17° of tilt).
    pub max_acceleration: f64,
    /// Bounds \[κ_min, κ_max\] on the thrust scale (spatial model), with
    /// κ_min ≤ 1 ≤ κ_max. Default \[0.5, 2\] (hover thrust between half and
    /// twice the model's).
    pub thrust_scale_range: [f64; 2],
    /// Pose-jump threshold \[m\]: a measured step between consecutive ticks
    /// larger than this resets the estimate. Default 1 m (50 m/s at 50 Hz).
    pub max_step: f64,
}

impl Default for DisturbanceSettings {
    fn default() -> Self {
        Self {
            bandwidth_hz: 0.1,
            fit_span: 50,
            max_acceleration: 3.0,
            thrust_scale_range: [0.5, 2.0],
            max_step: 1.0,
        }
    }
}

pub(super) fn invalid(field: &'static str, reason: &str) -> ControlError {
    ControlError::InvalidSetting {
        field,
        reason: reason.to_string(),
    }
}

impl DisturbanceSettings {
    /// `bandwidth_hz`: 0.001 Hz to a tenth of the control rate (`0.1/δt`;
    /// 5 Hz at 50 Hz), well below the Nyquist rate 1/(2δt).
    pub fn bandwidth_limit(dt: f64) -> Limit {
        Limit::closed(0.001, 0.1 / dt, "Hz")
    }
    /// `fit_span` (`window` in files) [control steps].
    pub const WINDOW: Limit = Limit::closed(MIN_WINDOW as f64, MAX_WINDOW as f64, "ticks");
    /// `max_acceleration` \[m/s²\].
    pub const MAX_ACCELERATION: Limit = Limit::closed(0.0, 10.0, "m/s²");
    /// `thrust_scale_range[0]` (κ_min) \[-\].
    pub const THRUST_SCALE_MIN: Limit = Limit::closed(0.1, 1.0, "");
    /// `thrust_scale_range[1]` (κ_max) \[-\].
    pub const THRUST_SCALE_MAX: Limit = Limit::closed(1.0, 10.0, "");
    /// `max_step` \[m\].
    pub const MAX_STEP: Limit = Limit::closed(0.01, 100.0, "m");

    /// Checks every field; the error names the first invalid one (as
    /// `disturbance.<field>`). The bandwidth is checked against the control
    /// step ([`DisturbanceSettings::bandwidth_limit`]) in
    /// [`DisturbanceEstimator::new`](super::DisturbanceEstimator::new); here only that it is positive.
    pub fn validate(&self) -> Result<(), ControlError> {
        Limit::positive("Hz").check("disturbance.bandwidth_hz", self.bandwidth_hz)?;
        Self::WINDOW.check("disturbance.fit_span", self.fit_span as f64)?;
        Self::MAX_ACCELERATION.check("disturbance.max_acceleration", self.max_acceleration)?;
        let [lo, hi] = self.thrust_scale_range;
        Self::THRUST_SCALE_MIN.check("disturbance.thrust_scale_range", lo)?;
        Self::THRUST_SCALE_MAX.check("disturbance.thrust_scale_range", hi)?;
        Self::MAX_STEP.check("disturbance.max_step", self.max_step)
    }
}
