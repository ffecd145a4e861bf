//! The spatial model (ours, beyond the paper): the planar model's first-order
//! attitude loop plus altitude through collective thrust, for autopilots
//! that take a thrust value in attitude mode (PX4 offboard).
//!
//! State `[x, ẋ, y, ẏ, z, ż, θ, φ, T]`, input `[θ_cmd, φ_cmd, T_cmd]`,
//! output `[x, y, z]`, window R = 3. T is the specific collective thrust
//! [m/s²] (thrust / mass), with a first-order response of time constant τ_T.
//!
//! TODO(model helper): implementation and derivation.

use nalgebra::{SVector, Vector3};

use crate::attitude::Frame;
use crate::{FlatError, FlatModel};

/// State `[x, ẋ, y, ẏ, z, ż, θ, φ, T]` (m, m/s, rad, m/s²).
pub type SpatialState = SVector<f64, 9>;
/// Input `[θ_cmd, φ_cmd, T_cmd]` (rad, rad, m/s²).
pub type SpatialInput = Vector3<f64>;
/// Output `[x, y, z]` (m).
pub type SpatialOutput = Vector3<f64>;

/// Parameters of the spatial model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialParams {
    /// Discretisation step δt [s].
    pub dt: f64,
    /// Attitude time constant τ [s].
    pub tau: f64,
    /// Attitude gain k̃ [-].
    pub k: f64,
    /// Thrust time constant τ_T [s].
    pub tau_thrust: f64,
    /// Gravity g [m/s²].
    pub g: f64,
    /// Fixed yaw ψ⋆ [rad].
    pub psi: f64,
    /// Frame convention.
    pub frame: Frame,
}

impl Default for SpatialParams {
    /// 50 Hz, τ = 0.2 s, k̃ = 1, τ_T = 0.04 s, g = 9.81, ψ = 0, NED.
    fn default() -> Self {
        Self {
            dt: 0.02,
            tau: 0.2,
            k: 1.0,
            tau_thrust: 0.04,
            g: 9.81,
            psi: 0.0,
            frame: Frame::Ned,
        }
    }
}

/// The spatial model with validated parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialModel {
    p: SpatialParams,
}

impl SpatialModel {
    /// Builds the model; errors name the invalid parameter.
    pub fn new(p: SpatialParams) -> Result<Self, FlatError> {
        Ok(Self { p })
    }
    /// The parameters.
    pub fn params(&self) -> &SpatialParams {
        &self.p
    }
}

impl FlatModel for SpatialModel {
    const R: usize = 3;
    type State = SpatialState;
    type Input = SpatialInput;
    type Output = SpatialOutput;
    fn dt(&self) -> f64 {
        self.p.dt
    }
    fn step(&self, x: &SpatialState, _u: &SpatialInput) -> SpatialState {
        *x
    }
    fn output(&self, x: &SpatialState) -> SpatialOutput {
        SpatialOutput::new(x[0], x[2], x[4])
    }
    fn state_from_outputs(&self, _y: &[SpatialOutput]) -> Result<SpatialState, FlatError> {
        Err(FlatError::Singular)
    }
    fn input_from_outputs(&self, _y: &[SpatialOutput]) -> Result<SpatialInput, FlatError> {
        Err(FlatError::Singular)
    }
    fn next_output(&self, _y: &[SpatialOutput], _u: &SpatialInput) -> Result<SpatialOutput, FlatError> {
        Err(FlatError::Singular)
    }
}
