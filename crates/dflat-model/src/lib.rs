//! # dflat-model — multirotor models and their discrete-flatness maps
//!
//! Pure math: no I/O, no clock, no allocation, `f64` throughout. Each model is
//! the forward-Euler discretisation (step δt) of a multirotor model from
//! *Fly Out The Window* (Greeff, Zhou, Schoellig), §IV, and implements
//! [`FlatModel`]: the forward step and the three flatness maps
//!
//! * Λ — [`FlatModel::state_from_outputs`]: `x_k = Λ(y_k, …, y_{k+R−1})`,
//! * F — [`FlatModel::input_from_outputs`] (the *output-to-input map*):
//!   `u_k = F(y_k, …, y_{k+R})`,
//! * F⁻¹ — [`FlatModel::next_output`] (the *input-to-output map*):
//!   `y_{k+R} = F⁻¹(y_k, …, y_{k+R−1}, u_k)`, where the model has one.
//!
//! The models:
//!
//! * [`planar`] — paper §IV-B: x, y at constant altitude, first-order
//!   pitch/roll loop, R = 3;
//! * [`spatial`] — ours: the planar model plus altitude through a
//!   first-order collective-thrust loop, R = 3 in every channel;
//! * [`full`] — paper §IV-A: the 12-state rigid body with thrust and
//!   torques, R = 4, no uniform F⁻¹ ([`FullModel::predict_outputs`]).
//!
//! Both the planar and the spatial model carry an optional linear drag in
//! the world frame, `v_{k+1} = v_k + δt·(a_thrust − D·v_k)` with
//! `D = diag(drag_h, drag_h[, drag_v])` \[1/s\] (0 by default: the paper's
//! models). The maps stay exact: Λ recovers the thrust acceleration as
//! `Δ²y_k/δt² + D·(y_{k+1} − y_k)/δt`, and F⁻¹ subtracts `D·v_{k+1}` with
//! `v_{k+1} = (y_{k+2} − y_{k+1})/δt` (docs/controllers.md, *Drag*).
//!
//! Frames: [`Frame::Ned`] (MAVLink local NED, body FRD, thrust along −z body)
//! or [`Frame::Zup`] (the paper's convention, thrust along +z body). Euler
//! angles are ZYX: body→world rotation `R = Rz(ψ)·Ry(θ)·Rx(φ)`.
//!
//! Singular or invalid data (non-finite numbers, wrong window length, free
//! fall, tilt at or beyond 90°) is returned as a [`FlatError`], never as NaN
//! and never as a panic.

pub mod attitude;
mod error;
pub mod full;
pub mod planar;
pub mod spatial;

pub use attitude::Frame;
pub use error::FlatError;
pub use full::{FullModel, FullParams};
pub use planar::{PlanarModel, PlanarParams};
pub use spatial::{SpatialModel, SpatialParams};

/// A discrete-time model that is difference flat in its output.
///
/// `R` is the window of the paper's Definition 2: the state needs `R`
/// consecutive outputs and the input `R + 1`.
pub trait FlatModel {
    /// Window r: `u_k = F(y_k, …, y_{k+R})`, `x_k = Λ(y_k, …, y_{k+R−1})`.
    const R: usize;
    /// State vector `x_k`.
    type State: Copy;
    /// Input vector `u_k`.
    type Input: Copy;
    /// Flat output `y_k`.
    type Output: Copy;

    /// Discretisation step δt \[s\].
    fn dt(&self) -> f64;
    /// Forward-Euler step `x_{k+1} = x_k + δt·f(x_k, u_k)`.
    fn step(&self, x: &Self::State, u: &Self::Input) -> Self::State;
    /// Flat output `y_k = h(x_k)`.
    fn output(&self, x: &Self::State) -> Self::Output;
    /// Λ: the state at the first of `R` consecutive outputs.
    fn state_from_outputs(&self, y: &[Self::Output]) -> Result<Self::State, FlatError>;
    /// F, the output-to-input map: the input at the first of `R + 1` outputs.
    fn input_from_outputs(&self, y: &[Self::Output]) -> Result<Self::Input, FlatError>;
    /// F⁻¹, the input-to-output map: the output following `R` consecutive
    /// outputs when `u` is applied at the first of them.
    fn next_output(&self, y: &[Self::Output], u: &Self::Input) -> Result<Self::Output, FlatError>;
}

/// Checks that a window holds exactly `expected` samples.
pub(crate) fn check_len(got: usize, expected: usize) -> Result<(), FlatError> {
    if got == expected {
        Ok(())
    } else {
        Err(FlatError::WindowLength { expected, got })
    }
}

/// Checks that a parameter is finite and strictly positive.
pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<(), FlatError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(FlatError::InvalidParameter {
            name,
            value,
            allowed: "finite and > 0",
        })
    }
}

/// Checks a linear drag coefficient D \[1/s\]: finite, ≥ 0 and `D·δt < 1`
/// (beyond that one Euler step reverses the velocity).
pub(crate) fn check_drag(name: &'static str, value: f64, dt: f64) -> Result<(), FlatError> {
    if value.is_finite() && value >= 0.0 && value * dt < 1.0 {
        Ok(())
    } else {
        Err(FlatError::InvalidParameter {
            name,
            value,
            allowed: "finite, >= 0 and < 1/dt",
        })
    }
}

/// Checks that a parameter is finite.
pub(crate) fn check_finite_param(name: &'static str, value: f64) -> Result<(), FlatError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(FlatError::InvalidParameter {
            name,
            value,
            allowed: "finite",
        })
    }
}

/// Returns `v` if all its components are finite, else
/// [`FlatError::NonFinite`]: finite but huge inputs can overflow inside a
/// map (differences of ±1e308), and a map never returns NaN or ±∞.
pub(crate) fn finite_result<const N: usize>(
    v: nalgebra::SVector<f64, N>,
    what: &'static str,
) -> Result<nalgebra::SVector<f64, N>, FlatError> {
    check_finite(v.iter(), what)?;
    Ok(v)
}

/// Checks that every component of every sample is finite.
pub(crate) fn check_finite<'a>(
    values: impl IntoIterator<Item = &'a f64>,
    what: &'static str,
) -> Result<(), FlatError> {
    if values.into_iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(FlatError::NonFinite(what))
    }
}
