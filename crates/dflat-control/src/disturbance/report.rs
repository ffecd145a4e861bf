//! What the disturbance estimator reports (logs, telemetry).

use serde::{Deserialize, Serialize};

/// What the estimator did at the last recorded tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EstimatorStatus {
    /// After a reset: the model's input dynamics are forgetting their start.
    Settling,
    /// The window is filling (fewer than L samples since its last restart).
    Filling,
    /// The estimate was updated.
    Tracking,
    /// The command was saturated: the estimate was held.
    Frozen,
}

/// A snapshot of the estimator for logs and telemetry (serialisable).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DisturbanceReport {
    /// Acceleration offset d̂ \[m/s²\], model frame (local NED for flight).
    pub acceleration: [f64; 3],
    /// Thrust scale κ̂ \[-\] (actual thrust per model thrust).
    pub thrust_scale: f64,
    /// Hover specific thrust g/κ̂ \[m/s²\] in the model's thrust units.
    pub hover_thrust: f64,
    /// What the estimator did at the last recorded tick.
    pub status: EstimatorStatus,
    /// The estimate sits at a clamp.
    pub clamped: bool,
    /// Pose jumps detected since construction.
    pub jumps: u64,
}
