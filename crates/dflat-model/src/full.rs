//! The full rigid-body model (paper §IV-A).
//!
//! State `x = [x, ẋ, y, ẏ, z, ż, θ, φ, ψ, p, q, r]` (m, m/s, rad, rad/s;
//! note pitch θ before roll φ), input `u = [T, τx, τy, τz]` (N, N·m), output
//! `y = [x, y, z, ψ]` (m, rad), window R = 4. Positions and velocities are in
//! the model's [`Frame`]; body rates p, q, r are about the body axes (FRD
//! for NED, FLU-like z-up body for the paper's frame). `R = Rz(ψ)·Ry(θ)·Rx(φ)`
//! (ZYX). Euler step δt on every state:
//!
//! ```text
//! p_{k+1} = p_k + δt·v_k,   v_{k+1} = v_k + δt·a_k
//!     a_k = g·e3 − (T_k/m)·R_k·e3   (NED),   a_k = (T_k/m)·R_k·e3 − g·e3   (z-up)
//! [φ, θ, ψ]_{k+1} = [φ, θ, ψ]_k + δt·W_k⁻¹·R_k·[p, q, r]_k         (Euler kinematics)
//! ṗ = −((Izz − Iyy)/Ixx)·q·r + τx/Ixx                              (paper eq. (dyn_rot))
//! q̇ = −((Ixx − Izz)/Iyy)·p·r + τy/Iyy
//! ṙ = −((Iyy − Ixx)/Izz)·p·q + τz/Izz
//! ```
//!
//! with the ZYX Euler-rate matrix `W = [[cψcθ, −sψ, 0], [sψcθ, cψ, 0],
//! [−sθ, 0, 1]]` on `[φ̇, θ̇, ψ̇]`: world angular velocity
//! `ω = W·[φ̇, θ̇, ψ̇] = R·[p, q, r]`. (The paper prints the ZXY matrix; with
//! its ZYX pitch/roll formulas the ZYX one is correct: erratum 2 of
//! `docs/errata.md`.)
//! `W` is singular at cos θ = 0; see [`crate::attitude::euler_rates`].
//!
//! ## Flatness maps
//!
//! * Λ(y_k, …, y_{k+3}): velocities are first differences of the
//!   positions; for j = k, k+1 the specific-thrust vector
//!   `t_j = (T_j/m)·R_j·e3` follows from the second difference
//!   `a_j = (y_{j+2} − 2·y_{j+1} + y_j)/δt²` and gravity (paper eq. (t)),
//!   and with ψ_j gives θ_j, φ_j (paper eqs. (pitch), (roll)); the body
//!   rates at k are `Rᵀ_k·W_k·[Δφ, Δθ, Δψ]/δt` (paper eq. (ang_vel), ZYX).
//! * F(y_k, …, y_{k+4}): the same at k, k+1, k+2, so body rates at k and
//!   k+1; `T_k = m·|t_k|`, and the torques invert the Euler step of the
//!   rotational dynamics (paper eq. (torq)):
//!   `τx = Ixx·(p_{k+1} − p_k)/δt + (Izz − Iyy)·q_k·r_k`, and cyclically.
//! * F⁻¹: none. Thrust reaches the position two steps later (T_k → a_k →
//!   v_{k+1} → y_{k+2}), torques four steps later (τ_k → ω_{k+1} → attitude
//!   at k+2 → a_{k+2} → v_{k+3} → y_{k+4}), and yaw torque the yaw two steps
//!   later. `y_{k+4}` therefore depends on the thrust of u_{k+2}, not only on
//!   u_k: there is no uniform map `y_{k+4} = F⁻¹(y_k, …, y_{k+3}, u_k)`, and
//!   [`FlatModel::next_output`] returns [`FlatError::NoInputToOutputMap`].
//!   Predict the general way instead, [`FullModel::predict_outputs`]: Λ on
//!   the oldest R outputs, then [`FlatModel::step`] with the inputs sent
//!   since.
//!
//! Yaw differences are wrapped to [−π, π]
//! ([`crate::attitude::wrap_angle_difference`]), so yaw measurements wrapped
//! to (−π, π] are fine while |ψ̇| < π/δt.

use nalgebra::{SVector, Vector3, Vector4};

use crate::attitude::{
    Frame, body_rates, euler_rates, thrust_axis, thrust_pitch_roll, wrap_angle_difference,
};
use crate::{FlatError, FlatModel, check_finite, check_len, check_positive, finite_result};

/// State `[x, ẋ, y, ẏ, z, ż, θ, φ, ψ, p, q, r]` (m, m/s, rad, rad/s body FRD).
pub type FullState = SVector<f64, 12>;
/// Input `[T, τx, τy, τz]` (N, N·m).
pub type FullInput = Vector4<f64>;
/// Output `[x, y, z, ψ]` (m, rad).
pub type FullOutput = Vector4<f64>;

/// Parameters of the full rigid-body model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FullParams {
    /// Discretisation step δt \[s\].
    pub dt: f64,
    /// Mass m \[kg\].
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

impl Default for FullParams {
    /// 50 Hz, a 1.5 kg quadrotor (Ixx = Iyy = 0.029, Izz = 0.055 kg·m²),
    /// g = 9.81, NED.
    fn default() -> Self {
        Self {
            dt: 0.02,
            m: 1.5,
            g: 9.81,
            ixx: 0.029,
            iyy: 0.029,
            izz: 0.055,
            frame: Frame::Ned,
        }
    }
}

/// The full model with validated parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FullModel {
    p: FullParams,
}

/// Thrust and attitude at one step: specific thrust |t| [m/s²], θ, φ, ψ \[rad\].
#[derive(Debug, Clone, Copy)]
struct Attitude {
    thrust: f64,
    theta: f64,
    phi: f64,
    psi: f64,
}

impl FullModel {
    /// Builds the model; errors name the invalid parameter (dt, m, g, ixx,
    /// iyy, izz must be finite and > 0).
    pub fn new(p: FullParams) -> Result<Self, FlatError> {
        check_positive("dt", p.dt)?;
        check_positive("m", p.m)?;
        check_positive("g", p.g)?;
        check_positive("ixx", p.ixx)?;
        check_positive("iyy", p.iyy)?;
        check_positive("izz", p.izz)?;
        Ok(Self { p })
    }

    /// The parameters.
    pub fn params(&self) -> &FullParams {
        &self.p
    }

    /// Thrust \[N\] that holds hover: m·g.
    pub fn hover_thrust(&self) -> f64 {
        self.p.m * self.p.g
    }

    /// World-frame acceleration [m/s²] (model frame) from thrust \[N\] at the
    /// ZYX attitude θ, φ, ψ \[rad\] (paper eq. (dyn_trans)).
    pub fn acceleration(&self, thrust: f64, theta: f64, phi: f64, psi: f64) -> Vector3<f64> {
        let s = thrust / self.p.m;
        let t = thrust_axis(theta, phi, psi).map(|c| s * c);
        Vector3::from(self.p.frame.acceleration(t, self.p.g))
    }

    /// Thrust T \[N\], pitch θ and roll φ \[rad\] that produce the world-frame
    /// acceleration `a` [m/s²] (model frame) at yaw ψ \[rad\]: the inverse of
    /// [`Self::acceleration`] for T > 0 and |θ|, |φ| < 90°.
    ///
    /// Errors: [`FlatError::NonFinite`], or [`FlatError::FreeFall`] when the
    /// required thrust does not point up through the body.
    pub fn attitude_thrust(
        &self,
        a: &Vector3<f64>,
        psi: f64,
    ) -> Result<(f64, f64, f64), FlatError> {
        check_finite(a.iter().chain([psi].iter()), "acceleration and yaw")?;
        let t = self.p.frame.thrust_vector([a.x, a.y, a.z], self.p.g);
        let (s, theta, phi) = thrust_pitch_roll(t, psi)?;
        Ok((self.p.m * s, theta, phi))
    }

    /// Angular acceleration [rad/s²] of the body rates `w = [p, q, r]`
    /// [rad/s] under torques `tau` [N·m] (paper eq. (dyn_rot)).
    pub fn angular_acceleration(&self, w: &Vector3<f64>, tau: &Vector3<f64>) -> Vector3<f64> {
        let (ixx, iyy, izz) = (self.p.ixx, self.p.iyy, self.p.izz);
        Vector3::new(
            -((izz - iyy) / ixx) * w.y * w.z + tau.x / ixx,
            -((ixx - izz) / iyy) * w.x * w.z + tau.y / iyy,
            -((iyy - ixx) / izz) * w.x * w.y + tau.z / izz,
        )
    }

    /// Predicts the outputs following a window of measured outputs, given
    /// the inputs sent since — the general input-to-output prediction for
    /// models without a uniform F⁻¹.
    ///
    /// `past` = `[y_j, …, y_{j+3}]` (R = 4 consecutive outputs),
    /// `inputs` = `[u_j, u_{j+1}, …]` (the inputs applied from step j on),
    /// and `out[i]` receives `y_{j+4+i}`. The state `x_j = Λ(past)` is
    /// stepped with the inputs; since an output never depends on the input
    /// of the step that produced it, n inputs reach `y_{j+n+1}`, so `inputs`
    /// must hold exactly `out.len() + R − 2` = `out.len() + 2` inputs. At
    /// tick k with `past = [y_{k−3}, …, y_k]` and the three inputs
    /// `u_{k−3}, u_{k−2}, u_{k−1}` this predicts `y_{k+1}` only: `y_{k+2}`
    /// already depends on the thrust of u_k.
    ///
    /// Errors: those of Λ, [`FlatError::WindowLength`] for the wrong number
    /// of inputs, [`FlatError::NonFinite`] for non-finite inputs or an
    /// overflowing prediction. `out` is unspecified on error.
    pub fn predict_outputs(
        &self,
        past: &[FullOutput],
        inputs: &[FullInput],
        out: &mut [FullOutput],
    ) -> Result<(), FlatError> {
        let r = <Self as FlatModel>::R;
        check_len(inputs.len(), out.len() + r - 2)?;
        check_finite(inputs.iter().flat_map(|u| u.iter()), "inputs")?;
        let mut x = self.state_from_outputs(past)?;
        for (n, u) in inputs.iter().enumerate() {
            x = self.step(&x, u);
            // x is now x_{j+n+1}; y_{j+4+i} with i = n + 1 − 4.
            if n + 1 >= r {
                out[n + 1 - r] = finite_result(self.output(&x), "prediction")?;
            }
        }
        if let Some(last) = out.last_mut() {
            *last = finite_result(
                self.output(&self.step(&x, &FullInput::zeros())),
                "prediction",
            )?;
        }
        Ok(())
    }

    /// Thrust and attitude at the first of three outputs.
    fn attitude_at(
        &self,
        y0: &FullOutput,
        y1: &FullOutput,
        y2: &FullOutput,
    ) -> Result<Attitude, FlatError> {
        let dt2 = self.p.dt * self.p.dt;
        let a = (y2.xyz() - 2.0 * y1.xyz() + y0.xyz()) / dt2;
        let t = self.p.frame.thrust_vector([a.x, a.y, a.z], self.p.g);
        let (thrust, theta, phi) = thrust_pitch_roll(t, y0.w)?;
        Ok(Attitude {
            thrust,
            theta,
            phi,
            psi: y0.w,
        })
    }

    /// Body rates [rad/s] at `a0` from the Euler-angle differences to `a1`
    /// (paper eq. (ang_vel), ZYX).
    fn rates(&self, a0: &Attitude, a1: &Attitude) -> Vector3<f64> {
        let dt = self.p.dt;
        Vector3::from(body_rates(
            a0.theta,
            a0.phi,
            [
                (a1.phi - a0.phi) / dt,
                (a1.theta - a0.theta) / dt,
                wrap_angle_difference(a1.psi - a0.psi) / dt,
            ],
        ))
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

    /// Forward Euler on all twelve states. At gimbal lock (cos θ = 0) the
    /// Euler rates are undefined; the step then holds the Euler angles
    /// (callers validate states with [`FlatModel::state_from_outputs`] or
    /// their own limits).
    fn step(&self, x: &FullState, u: &FullInput) -> FullState {
        let dt = self.p.dt;
        let (theta, phi, psi) = (x[6], x[7], x[8]);
        let w = Vector3::new(x[9], x[10], x[11]);
        let a = self.acceleration(u[0], theta, phi, psi);
        let [dphi, dtheta, dpsi] = euler_rates(theta, phi, [w.x, w.y, w.z]).unwrap_or([0.0; 3]);
        let dw = self.angular_acceleration(&w, &Vector3::new(u[1], u[2], u[3]));
        FullState::from([
            x[0] + dt * x[1],
            x[1] + dt * a.x,
            x[2] + dt * x[3],
            x[3] + dt * a.y,
            x[4] + dt * x[5],
            x[5] + dt * a.z,
            theta + dt * dtheta,
            phi + dt * dphi,
            psi + dt * dpsi,
            w.x + dt * dw.x,
            w.y + dt * dw.y,
            w.z + dt * dw.z,
        ])
    }

    fn output(&self, x: &FullState) -> FullOutput {
        FullOutput::new(x[0], x[2], x[4], x[8])
    }

    fn state_from_outputs(&self, y: &[FullOutput]) -> Result<FullState, FlatError> {
        check_len(y.len(), 4)?;
        check_finite(y.iter().flat_map(|v| v.iter()), "outputs")?;
        let v = (y[1].xyz() - y[0].xyz()) / self.p.dt;
        let a0 = self.attitude_at(&y[0], &y[1], &y[2])?;
        let a1 = self.attitude_at(&y[1], &y[2], &y[3])?;
        let w = self.rates(&a0, &a1);
        finite_result(
            FullState::from([
                y[0].x, v.x, y[0].y, v.y, y[0].z, v.z, a0.theta, a0.phi, a0.psi, w.x, w.y, w.z,
            ]),
            "state",
        )
    }

    fn input_from_outputs(&self, y: &[FullOutput]) -> Result<FullInput, FlatError> {
        check_len(y.len(), 5)?;
        check_finite(y.iter().flat_map(|v| v.iter()), "outputs")?;
        let a0 = self.attitude_at(&y[0], &y[1], &y[2])?;
        let a1 = self.attitude_at(&y[1], &y[2], &y[3])?;
        let a2 = self.attitude_at(&y[2], &y[3], &y[4])?;
        let w0 = self.rates(&a0, &a1);
        let w1 = self.rates(&a1, &a2);
        let (ixx, iyy, izz, dt) = (self.p.ixx, self.p.iyy, self.p.izz, self.p.dt);
        finite_result(
            FullInput::new(
                self.p.m * a0.thrust,
                ixx * (w1.x - w0.x) / dt + (izz - iyy) * w0.y * w0.z,
                iyy * (w1.y - w0.y) / dt + (ixx - izz) * w0.x * w0.z,
                izz * (w1.z - w0.z) / dt + (iyy - ixx) * w0.x * w0.y,
            ),
            "input",
        )
    }

    /// Always [`FlatError::NoInputToOutputMap`]: thrust reaches the position
    /// two steps later, torques four, so no uniform F⁻¹ exists. Use
    /// [`FullModel::predict_outputs`].
    fn next_output(&self, _y: &[FullOutput], _u: &FullInput) -> Result<FullOutput, FlatError> {
        Err(FlatError::NoInputToOutputMap)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parameter's name and what makes it invalid.
    type Spoiler = (&'static str, fn(&mut FullParams));

    #[test]
    fn rejects_bad_parameters() {
        let spoilers: [Spoiler; 6] = [
            ("dt", |p| p.dt = 0.0),
            ("m", |p| p.m = -1.0),
            ("g", |p| p.g = f64::NAN),
            ("ixx", |p| p.ixx = 0.0),
            ("iyy", |p| p.iyy = f64::INFINITY),
            ("izz", |p| p.izz = -0.1),
        ];
        for (name, spoil) in spoilers {
            let mut p = FullParams::default();
            spoil(&mut p);
            match FullModel::new(p) {
                Err(FlatError::InvalidParameter { name: got, .. }) => assert_eq!(got, name),
                other => panic!("{name}: {other:?}"),
            }
        }
    }

    #[test]
    fn hover_is_a_fixed_point() {
        for frame in [Frame::Ned, Frame::Zup] {
            let m = FullModel::new(FullParams {
                frame,
                ..Default::default()
            })
            .unwrap();
            let mut x = FullState::zeros();
            x[8] = 1.0;
            let u = FullInput::new(m.hover_thrust(), 0.0, 0.0, 0.0);
            assert_eq!(m.step(&x, &u), x);
        }
    }

    #[test]
    fn no_input_to_output_map() {
        let m = FullModel::new(FullParams::default()).unwrap();
        let y = [FullOutput::zeros(); 4];
        assert_eq!(
            m.next_output(&y, &FullInput::zeros()),
            Err(FlatError::NoInputToOutputMap)
        );
    }

    #[test]
    fn gimbal_lock_step_stays_finite() {
        let m = FullModel::new(FullParams::default()).unwrap();
        let mut x = FullState::zeros();
        x[6] = std::f64::consts::FRAC_PI_2;
        x[10] = 1.0;
        let next = m.step(&x, &FullInput::new(10.0, 0.1, 0.1, 0.1));
        assert!(next.iter().all(|v| v.is_finite()));
        assert_eq!(next[6], x[6]);
    }
}
