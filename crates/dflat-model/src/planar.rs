//! The planar model (paper §IV-B): 2-D motion at constant altitude with a
//! first-order attitude loop (the autopilot's), fixed yaw ψ⋆.
//!
//! State `x = [x, ẋ, y, ẏ, θ, φ]` (m, m/s, rad), input `u = [θ_cmd, φ_cmd]`
//! (rad), output `y = [x, y]` (m), window R = 3. Euler step δt:
//!
//! ```text
//! ẍ = s·g·R13/R33 − D·ẋ,  ÿ = s·g·R23/R33 − D·ẏ    (s = −1 NED, +1 z-up)
//! θ̇ = (k̃·θ_cmd − θ)/τ,  φ̇ = (k̃·φ_cmd − φ)/τ
//! ```
//!
//! with the linear drag D = `drag_h` \[1/s\] (0: the paper's model).
//!
//! Λ: velocities are first differences, the ratios R13/R33, R23/R33 are
//! `s·(Δ²y/δt² + D·Δy/δt)/g` (the thrust's acceleration: the second
//! difference plus what drag took), and pitch/roll follow from them and ψ⋆
//! ([`crate::attitude::pitch_roll_from_ratios`]).
//!
//! F: the attitude at k and k+1 from `y_k..y_{k+3}`, then the exact inverse
//! of the Euler attitude step, `θ_cmd = (θ_k + τ·(θ_{k+1} − θ_k)/δt)/k̃`.
//! (The paper prints `(τ·θ_{k+1} − θ_k)/k̃`, which drops δt.)
//!
//! F⁻¹: the attitude at k from `y_k..y_{k+2}`, one attitude step with u_k,
//! then `y_{k+3} = 2·y_{k+2} − y_{k+1} + δt²·(a(θ_{k+1}, φ_{k+1}) − D·v_{k+1})`
//! with `v_{k+1} = (y_{k+2} − y_{k+1})/δt`.
//!
//! [`PlanarModel::input_from_outputs_offset`] and
//! [`PlanarModel::next_output_offset`] are F and F⁻¹ of the same step with a
//! constant acceleration offset d added (`ẍ = … − D·ẋ + d_x`): the
//! disturbance-aware maps of the controllers.

use nalgebra::{SVector, Vector2};

use crate::attitude::{Frame, pitch_roll_from_ratios, ratios_from_pitch_roll};
use crate::{
    FlatError, FlatModel, check_drag, check_finite, check_finite_param, check_len, check_positive,
    finite_result,
};

/// State `[x, ẋ, y, ẏ, θ, φ]` (m, m/s, m, m/s, rad, rad).
pub type PlanarState = SVector<f64, 6>;
/// Input `[θ_cmd, φ_cmd]` (rad).
pub type PlanarInput = Vector2<f64>;
/// Output `[x, y]` (m).
pub type PlanarOutput = Vector2<f64>;

/// Parameters of the planar model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarParams {
    /// Discretisation step δt \[s\].
    pub dt: f64,
    /// Attitude time constant τ \[s\].
    pub tau: f64,
    /// Attitude gain k̃ [-].
    pub k: f64,
    /// Gravity g [m/s²].
    pub g: f64,
    /// Fixed yaw ψ⋆ \[rad\].
    pub psi: f64,
    /// Frame convention.
    pub frame: Frame,
    /// Linear horizontal drag D \[1/s\] in the world frame (≥ 0, D·δt < 1):
    /// `v_{k+1} = v_k + δt·(a − D·v_k)`. 0 is the paper's model.
    pub drag_h: f64,
}

impl Default for PlanarParams {
    /// 50 Hz, τ = 0.2 s, k̃ = 1, g = 9.81, ψ = 0, NED, no drag.
    fn default() -> Self {
        Self {
            dt: 0.02,
            tau: 0.2,
            k: 1.0,
            g: 9.81,
            psi: 0.0,
            frame: Frame::Ned,
            drag_h: 0.0,
        }
    }
}

/// The planar model with validated parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarModel {
    p: PlanarParams,
}

impl PlanarModel {
    /// Builds the model; errors name the invalid parameter.
    pub fn new(p: PlanarParams) -> Result<Self, FlatError> {
        check_positive("dt", p.dt)?;
        check_positive("tau", p.tau)?;
        check_positive("k", p.k)?;
        check_positive("g", p.g)?;
        check_finite_param("psi", p.psi)?;
        check_drag("drag_h", p.drag_h, p.dt)?;
        Ok(Self { p })
    }

    /// The parameters.
    pub fn params(&self) -> &PlanarParams {
        &self.p
    }

    /// Horizontal acceleration [m/s²] at attitude (θ, φ).
    pub fn acceleration(&self, theta: f64, phi: f64) -> Result<Vector2<f64>, FlatError> {
        let (a, b) = ratios_from_pitch_roll(theta, phi, self.p.psi)?;
        let sg = self.p.frame.horizontal_sign() * self.p.g;
        Ok(Vector2::new(sg * a, sg * b))
    }

    /// Attitude (θ, φ) \[rad\] that produces the horizontal acceleration `a` [m/s²].
    pub fn attitude(&self, a: &Vector2<f64>) -> (f64, f64) {
        let s = self.p.frame.horizontal_sign() / self.p.g;
        pitch_roll_from_ratios(s * a.x, s * a.y, self.p.psi)
    }

    /// Attitude at the first of three outputs: from the thrust's
    /// acceleration, their second difference plus the drag at the first
    /// velocity minus the acceleration offset `d` [m/s²].
    fn attitude_at(
        &self,
        y0: &PlanarOutput,
        y1: &PlanarOutput,
        y2: &PlanarOutput,
        d: &Vector2<f64>,
    ) -> (f64, f64) {
        let dt = self.p.dt;
        let a = (y2 - 2.0 * y1 + y0) / (dt * dt) + self.p.drag_h * (y1 - y0) / dt - d;
        self.attitude(&a)
    }

    /// F with a constant acceleration offset `d` [m/s²] in the step
    /// (`ẍ = … − D·ẋ + d_x`): the input at the first of four outputs.
    /// `d = 0` is [`FlatModel::input_from_outputs`].
    pub fn input_from_outputs_offset(
        &self,
        y: &[PlanarOutput],
        d: &Vector2<f64>,
    ) -> Result<PlanarInput, FlatError> {
        self.input_from_outputs_offsets(y, &[*d, *d])
    }

    /// F with an acceleration offset per step [m/s²]: `d[0]` in the step
    /// from the first output, `d[1]` in the step from the second (an offset
    /// that depends on the outputs, such as a learned residual, evaluated
    /// at each step's velocity). `[d, d]` is
    /// [`PlanarModel::input_from_outputs_offset`].
    pub fn input_from_outputs_offsets(
        &self,
        y: &[PlanarOutput],
        d: &[Vector2<f64>; 2],
    ) -> Result<PlanarInput, FlatError> {
        check_len(y.len(), 4)?;
        check_finite(
            y.iter().flat_map(|v| v.iter()).chain(d.iter().flatten()),
            "outputs",
        )?;
        let (t0, p0) = self.attitude_at(&y[0], &y[1], &y[2], &d[0]);
        let (t1, p1) = self.attitude_at(&y[1], &y[2], &y[3], &d[1]);
        finite_result(
            PlanarInput::new(self.attitude_command(t0, t1), self.attitude_command(p0, p1)),
            "input",
        )
    }

    /// F⁻¹ with a constant acceleration offset `d` [m/s²] in the step: the
    /// output after three when `u` is applied at the first.
    /// `d = 0` is [`FlatModel::next_output`].
    pub fn next_output_offset(
        &self,
        y: &[PlanarOutput],
        u: &PlanarInput,
        d: &Vector2<f64>,
    ) -> Result<PlanarOutput, FlatError> {
        self.next_output_offsets(y, u, &[*d, *d])
    }

    /// F⁻¹ with an acceleration offset per step [m/s²]: `d[0]` in the step
    /// from the first output (the attitude there), `d[1]` in the step from
    /// the second (the one `u` drives). `[d, d]` is
    /// [`PlanarModel::next_output_offset`].
    pub fn next_output_offsets(
        &self,
        y: &[PlanarOutput],
        u: &PlanarInput,
        d: &[Vector2<f64>; 2],
    ) -> Result<PlanarOutput, FlatError> {
        check_len(y.len(), 3)?;
        check_finite(
            y.iter()
                .flat_map(|v| v.iter())
                .chain(u.iter())
                .chain(d.iter().flatten()),
            "outputs and input",
        )?;
        let (t0, p0) = self.attitude_at(&y[0], &y[1], &y[2], &d[0]);
        let acc = self.acceleration(self.attitude_step(t0, u.x), self.attitude_step(p0, u.y))?;
        let dt = self.p.dt;
        let v1 = (y[2] - y[1]) / dt;
        finite_result(
            2.0 * y[2] - y[1] + dt * dt * (acc - self.p.drag_h * v1 + d[1]),
            "next output",
        )
    }

    /// One Euler step of the first-order attitude loop.
    fn attitude_step(&self, angle: f64, cmd: f64) -> f64 {
        angle + self.p.dt * (self.p.k * cmd - angle) / self.p.tau
    }

    /// Exact inverse of [`Self::attitude_step`]: the command taking `a0` to `a1`.
    fn attitude_command(&self, a0: f64, a1: f64) -> f64 {
        (a0 + self.p.tau * (a1 - a0) / self.p.dt) / self.p.k
    }
}

impl FlatModel for PlanarModel {
    const R: usize = 3;
    type State = PlanarState;
    type Input = PlanarInput;
    type Output = PlanarOutput;

    fn dt(&self) -> f64 {
        self.p.dt
    }

    /// Forward Euler. A state at or beyond 90° tilt has no defined
    /// acceleration; the step then keeps the velocity (callers validate
    /// states with [`FlatModel::state_from_outputs`] or their own limits).
    fn step(&self, x: &PlanarState, u: &PlanarInput) -> PlanarState {
        let dt = self.p.dt;
        let acc = self
            .acceleration(x[4], x[5])
            .unwrap_or_else(|_| Vector2::zeros());
        let drag = self.p.drag_h;
        PlanarState::from([
            x[0] + dt * x[1],
            x[1] + dt * (acc.x - drag * x[1]),
            x[2] + dt * x[3],
            x[3] + dt * (acc.y - drag * x[3]),
            self.attitude_step(x[4], u.x),
            self.attitude_step(x[5], u.y),
        ])
    }

    fn output(&self, x: &PlanarState) -> PlanarOutput {
        PlanarOutput::new(x[0], x[2])
    }

    fn state_from_outputs(&self, y: &[PlanarOutput]) -> Result<PlanarState, FlatError> {
        check_len(y.len(), 3)?;
        check_finite(y.iter().flat_map(|v| v.iter()), "outputs")?;
        let v = (y[1] - y[0]) / self.p.dt;
        let (theta, phi) = self.attitude_at(&y[0], &y[1], &y[2], &Vector2::zeros());
        finite_result(
            PlanarState::from([y[0].x, v.x, y[0].y, v.y, theta, phi]),
            "state",
        )
    }

    fn input_from_outputs(&self, y: &[PlanarOutput]) -> Result<PlanarInput, FlatError> {
        self.input_from_outputs_offset(y, &Vector2::zeros())
    }

    fn next_output(&self, y: &[PlanarOutput], u: &PlanarInput) -> Result<PlanarOutput, FlatError> {
        self.next_output_offset(y, u, &Vector2::zeros())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_parameters() {
        let p = PlanarParams {
            tau: 0.0,
            ..Default::default()
        };
        assert!(matches!(
            PlanarModel::new(p),
            Err(FlatError::InvalidParameter { name: "tau", .. })
        ));
    }

    #[test]
    fn window_length_and_nan_are_errors() {
        let m = PlanarModel::new(PlanarParams::default()).unwrap();
        let y = [PlanarOutput::zeros(); 3];
        assert_eq!(
            m.input_from_outputs(&y),
            Err(FlatError::WindowLength {
                expected: 4,
                got: 3
            })
        );
        let bad = [PlanarOutput::new(f64::NAN, 0.0), y[1], y[2]];
        assert!(matches!(
            m.state_from_outputs(&bad),
            Err(FlatError::NonFinite(_))
        ));
    }

    #[test]
    fn hover_is_a_fixed_point() {
        let m = PlanarModel::new(PlanarParams::default()).unwrap();
        let x = PlanarState::from([1.0, 0.0, 2.0, 0.0, 0.0, 0.0]);
        assert_eq!(m.step(&x, &PlanarInput::zeros()), x);
    }
}
