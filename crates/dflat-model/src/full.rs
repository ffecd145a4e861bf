//! The full rigid-body model (paper §IV-A).
//!
//! TODO(model helper): implementation and derivation.

use nalgebra::{SVector, Vector4};

use crate::attitude::Frame;
use crate::{FlatError, FlatModel};

/// State `[x, ẋ, y, ẏ, z, ż, θ, φ, ψ, p, q, r]` (m, m/s, rad, rad/s body FRD).
pub type FullState = SVector<f64, 12>;
/// Input `[T, τx, τy, τz]` (N, N·m).
pub type FullInput = Vector4<f64>;
/// Output `[x, y, z, ψ]` (m, rad).
pub type FullOutput = Vector4<f64>;

/// Parameters of the full rigid-body model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FullParams {
    /// Discretisation step δt [s].
    pub dt: f64,
    /// Mass m [kg].
    pub m: f64,
    /// Gravity g [m/s²].
    pub g: f64,
    /// Principal moments of inertia [kg·m²].
    pub ixx: f64,
    /// See `ixx`.
    pub iyy: f64,
    /// See `ixx`.
    pub izz: f64,
    /// Frame convention.
    pub frame: Frame,
}

/// The full model with validated parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FullModel {
    p: FullParams,
}

impl FullModel {
    /// Builds the model; errors name the invalid parameter.
    pub fn new(p: FullParams) -> Result<Self, FlatError> {
        Ok(Self { p })
    }
}

impl FlatModel for FullModel {
    const R: usize = 4;
    type State = FullState;
    type Input = FullInput;
    type Output = FullOutput;
    fn dt(&self) -> f64 {
        self.p.dt
    }
    fn step(&self, x: &FullState, _u: &FullInput) -> FullState {
        *x
    }
    fn output(&self, x: &FullState) -> FullOutput {
        FullOutput::new(x[0], x[2], x[4], x[8])
    }
    fn state_from_outputs(&self, _y: &[FullOutput]) -> Result<FullState, FlatError> {
        Err(FlatError::Singular)
    }
    fn input_from_outputs(&self, _y: &[FullOutput]) -> Result<FullInput, FlatError> {
        Err(FlatError::Singular)
    }
    fn next_output(&self, _y: &[FullOutput], _u: &FullInput) -> Result<FullOutput, FlatError> {
        Err(FlatError::NoInputToOutputMap)
    }
}
