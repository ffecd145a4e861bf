//! Flatness MPC (FMPC), the paper's first baseline (§VI "Flatness MPC",
//! after its ref. c15): MPC on the continuous-time flat model — per axis a
//! triple integrator `y⃛ = v` — with the flat state taken from finite
//! differences of the measured positions, and the attitude command from
//! feedback linearisation.
//!
//! Per axis, at tick k:
//!
//! * flat state, by [`FmpcSettings::state`]: from the last three
//!   measurements (history padded with the first one),
//!   `z = [y_k, (y_k − y_{k−1})/δt, (y_k − 2y_{k−1} + y_{k−2})/δt²]` — the
//!   paper's simulation (§VI) — or from a [`crate::estimator::StateEstimator`] fed with every
//!   pose at its capture time and predicted to the tick through the sent
//!   commands — the paper's outdoor set-up (§VII, STEAM);
//! * model: the triple integrator discretised exactly at δt (zero-order hold
//!   on the jerk v), `z_{j+1} = A z_j + B v_j`, position `x_j = c·z_j`;
//! * cost `Σ_{j=1..N} q (x_j − ref_j)² + Σ_{i=0..N−1} r v_i²` over the jerks
//!   v_0..v_{N−1}, unconstrained.
//!
//! Condensed, `x = Φ z + Γ v` with Γ lower-triangular Toeplitz and the
//! Hessian `H = q ΓᵀΓ + r I` is constant, so [`FlatnessMpc::new`] factors it
//! once (Cholesky) and keeps only the three rows of the gain
//! `K = H⁻¹ Γᵀ q` that the command and the plan need (v_0, v_1, v_2). A tick
//! is then `v_i = K_i · (ref − Φ z)`: O(N) per axis, no allocation.
//!
//! Command (feedback linearisation with the controller's model): the flat
//! acceleration `a = z[2]` gives the attitude through the model's attitude
//! map (and, for the spatial model, the thrust T = |t|); the rates follow
//! by the chain rule with the jerk `v_0`; then `θ_cmd = (θ + τθ̇)/k̃`,
//! `φ_cmd = (φ + τφ̇)/k̃` and `T_cmd = T + τ_T Ṫ`. In the paper's 1-D z-up
//! case this is `θ = atan(ẍ/g)`, `θ̇ = v_0 cos²θ/g`.

use dflat_model::attitude::{pitch_roll_from_ratios, thrust_pitch_roll};
use dflat_model::{FlatError, Frame};
use nalgebra::{DMatrix, Vector3};

use crate::estimator::differences::PoseDifferences;
use crate::estimator::{BaselineEstimator, StateSource};
use crate::{
    AttitudeCommand, ControlError, ControlModel, Controller, Limit, Measurement, ReferenceSource,
    TickOutput, TiltLimit, limit_tilt,
};

/// Largest accepted horizon N \[steps\] (the Hessian is factored densely in
/// [`FlatnessMpc::new`]).
pub const MAX_HORIZON: usize = 2000;

/// Settings of [`FlatnessMpc`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FmpcSettings {
    /// Prediction horizon N [steps of δt] ([`FmpcSettings::HORIZON`]: 10 ≤ N ≤
    /// [`MAX_HORIZON`]).
    /// Default 75 = 1.5 s at 50 Hz, the paper's FMPC lookahead (§VII-C).
    pub horizon: usize,
    /// Tracking weights q per axis (x, y, z) [1/m²], finite, ≥ 0 (z unused by
    /// the planar model). Default 1.
    pub q: [f64; 3],
    /// Jerk weights r per axis (x, y, z) [s⁶/m²], finite, > 0: r weights the
    /// squared jerk v_i [m/s³]. Default 0.01: with N = 75 (no terminal
    /// cost) and q = 1, r = 0.1 — the paper's simulation weights, which it
    /// pairs with N = 200 — leaves a slowly decaying oscillation and r = 1
    /// is unstable; r = 0.01 settles a 10 m step in ~6 s and tracks the L
    /// path (tests/fmpc_closed_loop.rs).
    pub r: [f64; 3],
    /// Saturation of the pitch and roll commands \[rad\], in (0, π/2);
    /// `None` disables it (replays). Default 35°.
    pub max_tilt: Option<f64>,
    /// How `max_tilt` applies (default [`TiltLimit::PerAxis`], the paper).
    pub tilt_limit: TiltLimit,
    /// Where the flat state comes from. Default
    /// [`StateSource::FiniteDifference`] (the paper's §VI definition); the
    /// daemon and the lab's path study default to the estimator.
    pub state: StateSource,
}

impl Default for FmpcSettings {
    fn default() -> Self {
        Self {
            horizon: 75,
            q: [1.0; 3],
            r: [0.01; 3],
            max_tilt: Some(35f64.to_radians()),
            tilt_limit: TiltLimit::PerAxis,
            state: StateSource::FiniteDifference,
        }
    }
}

fn invalid(field: &'static str, reason: impl Into<String>) -> ControlError {
    ControlError::InvalidSetting {
        field,
        reason: reason.into(),
    }
}

impl FmpcSettings {
    /// `horizon` \[steps\]: at least 10, at most [`MAX_HORIZON`].
    pub const HORIZON: Limit = Limit::closed(10.0, MAX_HORIZON as f64, "ticks");
    /// Each of `q` \[1/m²\].
    pub const Q: Limit = Limit::positive("1/m²");
    /// Each of `r` \[s⁶/m²\].
    pub const R: Limit = Limit::positive("s⁶/m²");

    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ControlError> {
        Self::HORIZON.check("horizon", self.horizon as f64)?;
        Self::Q.check_all("q", &self.q)?;
        Self::R.check_all("r", &self.r)?;
        if let Some(t) = self.max_tilt
            && !(t.is_finite() && t > 0.0 && t < std::f64::consts::FRAC_PI_2)
        {
            return Err(invalid(
                "max_tilt",
                format!("must be in (0, π/2) rad, got {t}"),
            ));
        }
        Ok(())
    }
}

/// Rows 0..3 of the gain `K = H⁻¹ Γᵀ q` of one axis: `v_i = K_i · e` with
/// `e_j = ref_{j+1} − (Φ z)_{j+1}`.
#[derive(Debug, Clone)]
struct AxisGains {
    k: [Vec<f64>; 3],
}

/// Flatness MPC, the paper's baseline (§VI): see the module docs.
#[derive(Debug, Clone)]
pub struct FlatnessMpc {
    model: ControlModel,
    settings: FmpcSettings,
    /// Control step δt \[s\] (the model's).
    dt: f64,
    /// Controlled axes: 2 (planar: x, y) or 3 (spatial: x, y, z).
    axes: usize,
    gains: Vec<AxisGains>,
    /// Reference over the horizon, j = 0..=N (pre-allocated).
    refs: Vec<Vector3<f64>>,
    /// Measurements y_{k−2}, y_{k−1}, y_k (NED \[m\]).
    /// The finite-difference state's poses at their capture times
    /// ([`StateSource::FiniteDifference`]).
    differences: PoseDifferences,
    /// The state estimator ([`StateSource::Estimator`]), else None.
    estimator: Option<BaselineEstimator>,
}

/// Impulse response of the exactly discretised triple integrator:
/// position m+1 steps after a unit jerk held for one step,
/// `c Aᵐ B = δt³ (3m² + 3m + 1)/6`.
fn impulse(m: usize, dt: f64) -> f64 {
    let m = m as f64;
    dt * dt * dt * (3.0 * m * m + 3.0 * m + 1.0) / 6.0
}

/// Free response `c Aʲ z` of the triple integrator after `j` steps.
fn free(z: &[f64; 3], j: usize, dt: f64) -> f64 {
    let t = j as f64 * dt;
    z[0] + t * z[1] + 0.5 * t * t * z[2]
}

/// Attitude (θ, φ) and rates (θ̇, φ̇) from the ratios `A = R13/R33`,
/// `B = R23/R33`, their time derivatives and yaw ψ: the chain rule through
/// [`pitch_roll_from_ratios`] (`θ = atan(A cψ + B sψ)`,
/// `φ = atan((A sψ − B cψ) cθ)`).
pub(crate) fn attitude_with_rates(a: f64, b: f64, a_dot: f64, b_dot: f64, psi: f64) -> [f64; 4] {
    let (theta, phi) = pitch_roll_from_ratios(a, b, psi);
    let (s, c) = psi.sin_cos();
    let u = a * c + b * s;
    let theta_dot = (a_dot * c + b_dot * s) / (1.0 + u * u);
    let w = a * s - b * c;
    let w_dot = a_dot * s - b_dot * c;
    let (st, ct) = theta.sin_cos();
    let p = w * ct;
    let p_dot = w_dot * ct - w * st * theta_dot;
    let phi_dot = p_dot / (1.0 + p * p);
    [theta, phi, theta_dot, phi_dot]
}

/// Attitude, thrust and their rates from the flat acceleration `acc`
/// [m/s²] and jerk `jerk` [m/s³] (world frame) for the spatial model:
/// `[θ, φ, T, θ̇, φ̇, Ṫ]`.
pub(crate) fn spatial_attitude_with_rates(
    frame: Frame,
    g: f64,
    psi: f64,
    acc: [f64; 3],
    jerk: [f64; 3],
) -> Result<[f64; 6], FlatError> {
    let t = frame.thrust_vector(acc, g);
    // thrust_vector is affine in acc with slope ±I (the frame's sign).
    let sign = frame.horizontal_sign();
    let td = jerk.map(|j| sign * j);
    let (thrust, _, _) = thrust_pitch_roll(t, psi)?;
    let thrust_dot = (t[0] * td[0] + t[1] * td[1] + t[2] * td[2]) / thrust;
    let (a, b) = (t[0] / t[2], t[1] / t[2]);
    let t22 = t[2] * t[2];
    let a_dot = (td[0] * t[2] - t[0] * td[2]) / t22;
    let b_dot = (td[1] * t[2] - t[1] * td[2]) / t22;
    let [theta, phi, theta_dot, phi_dot] = attitude_with_rates(a, b, a_dot, b_dot, psi);
    Ok([theta, phi, thrust, theta_dot, phi_dot, thrust_dot])
}

/// Rate of the vertical thrust-vector component `ṫ_z` [m/s³] from the
/// vertical jerk (see [`Frame::thrust_vector`]: slope −1 NED, +1 z-up).
fn frame_vertical_rate(frame: Frame, jerk_z: f64) -> f64 {
    frame.horizontal_sign() * jerk_z
}

/// `(pitch, roll)` \[rad\] under the tilt limit (none: unchanged);
/// sets `saturated` when it changed them.
pub(crate) fn limit_pair(
    pitch: f64,
    roll: f64,
    limit: Option<f64>,
    mode: TiltLimit,
    saturated: &mut bool,
) -> (f64, f64) {
    match limit {
        Some(l) => {
            let (p, r, hit) = limit_tilt(pitch, roll, l, mode);
            *saturated |= hit;
            (p, r)
        }
        None => (pitch, roll),
    }
}

impl FlatnessMpc {
    /// Builds the controller for `model` (its δt is the control step) and
    /// factors the constant Hessian of every axis. Errors name an invalid
    /// setting, or report a Hessian that is not positive definite.
    pub fn new(model: ControlModel, settings: FmpcSettings) -> Result<Self, ControlError> {
        settings.validate()?;
        let (dt, axes) = match &model {
            ControlModel::Planar(m) => (m.params().dt, 2),
            ControlModel::Spatial(m) => (m.params().dt, 3),
        };
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid(
                "dt",
                format!("model step must be finite and > 0 s, got {dt}"),
            ));
        }
        let n = settings.horizon;
        // Γ[j][i] = impulse(j − i) for i ≤ j: position j+1 from jerk i.
        let gamma = DMatrix::from_fn(n, n, |j, i| if i <= j { impulse(j - i, dt) } else { 0.0 });
        let gtg = gamma.tr_mul(&gamma);
        let mut gains = Vec::with_capacity(axes);
        for axis in 0..axes {
            let (q, r) = (settings.q[axis], settings.r[axis]);
            let mut h = &gtg * q;
            for d in 0..n {
                h[(d, d)] += r;
            }
            let chol = h.cholesky().ok_or(ControlError::NotPositiveDefinite)?;
            // Columns of H⁻¹ for e_0, e_1, e_2 (H symmetric: rows of H⁻¹).
            let w = chol.solve(&DMatrix::from_fn(
                n,
                3,
                |m, i| if m == i { 1.0 } else { 0.0 },
            ));
            let k = &gamma * w * q; // N×3: column i is row i of H⁻¹Γᵀq
            gains.push(AxisGains {
                k: [0, 1, 2].map(|i| k.column(i).iter().copied().collect()),
            });
        }
        Ok(Self {
            model,
            settings,
            dt,
            axes,
            gains,
            refs: vec![Vector3::zeros(); n + 1],
            differences: PoseDifferences::new(dt),
            estimator: BaselineEstimator::from_source(settings.state, &model)?,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &FmpcSettings {
        &self.settings
    }

    /// The controller's model.
    pub fn model(&self) -> &ControlModel {
        &self.model
    }

    /// Control step δt \[s\].
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The attitude command from the flat state `z` and the planned jerks
    /// `v` per axis (feedback linearisation with the attitude's lead, then
    /// the tilt limit), and whether it saturated.
    fn command(
        &self,
        z: &[[f64; 3]; 3],
        v: &[[f64; 3]; 3],
    ) -> Result<(AttitudeCommand, bool), ControlError> {
        let limit = self.settings.max_tilt;
        let mode = self.settings.tilt_limit;
        let mut saturated = false;
        let command = match &self.model {
            ControlModel::Planar(m) => {
                let p = m.params();
                let s = p.frame.horizontal_sign() / p.g;
                let [theta, phi, theta_dot, phi_dot] =
                    attitude_with_rates(s * z[0][2], s * z[1][2], s * v[0][0], s * v[1][0], p.psi);
                let (pitch, roll) = limit_pair(
                    (theta + p.tau * theta_dot) / p.k,
                    (phi + p.tau * phi_dot) / p.k,
                    limit,
                    mode,
                    &mut saturated,
                );
                AttitudeCommand {
                    pitch,
                    roll,
                    yaw: p.psi,
                    thrust: p.g,
                }
            }
            ControlModel::Spatial(m) => {
                let p = m.params();
                let acc = [z[0][2], z[1][2], z[2][2]];
                let jerk = [v[0][0], v[1][0], v[2][0]];
                let [theta, phi, thrust, theta_dot, phi_dot, thrust_dot] =
                    spatial_attitude_with_rates(p.frame, p.g, p.psi, acc, jerk)?;
                let mut tilt_saturated = false;
                let (pitch, roll) = limit_pair(
                    (theta + p.tau * theta_dot) / p.k,
                    (phi + p.tau * phi_dot) / p.k,
                    limit,
                    mode,
                    &mut tilt_saturated,
                );
                let mut flat_tilt_beyond = false;
                let (theta_l, phi_l) = limit_pair(theta, phi, limit, mode, &mut flat_tilt_beyond);
                let mut thrust_cmd = if flat_tilt_beyond {
                    // The flat attitude itself is beyond the limit: vertical
                    // priority, keep the vertical thrust t_z + τ_T ṫ_z at the
                    // limited attitude (so saturation does not climb or sink).
                    let t_z = thrust * theta.cos() * phi.cos();
                    let t_z_dot = frame_vertical_rate(p.frame, jerk[2]);
                    (t_z + p.tau_thrust * t_z_dot) / (theta_l.cos() * phi_l.cos())
                } else {
                    thrust + p.tau_thrust * thrust_dot
                };
                saturated |= tilt_saturated;
                if thrust_cmd.is_nan() || thrust_cmd < 0.0 {
                    thrust_cmd = 0.0;
                    saturated = true;
                }
                AttitudeCommand {
                    pitch,
                    roll,
                    yaw: p.psi,
                    thrust: thrust_cmd,
                }
            }
        };
        Ok((command, saturated))
    }
}

impl Controller for FlatnessMpc {
    fn name(&self) -> &'static str {
        "fmpc"
    }

    fn multi_rate(&self) -> bool {
        self.estimator.is_some()
    }

    fn observe(&mut self, sample: &Measurement) {
        BaselineEstimator::observe(self.estimator.as_mut(), sample);
    }

    fn skipped(&mut self, ticks: u32) {
        // The estimator takes the tick time from the update.
        self.differences.skip(ticks);
    }

    fn tick_time(&self, measurement: &Measurement) -> f64 {
        BaselineEstimator::tick_time(self.estimator.as_ref(), &self.differences, measurement)
    }

    fn correct_last_input(&mut self, applied: &Vector3<f64>) {
        if let Some(e) = &mut self.estimator {
            e.correct(&self.model, applied);
        }
    }

    fn update(
        &mut self,
        measurement: &Measurement,
        reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        let estimate = BaselineEstimator::checked_state(self.estimator.as_ref(), measurement)?;
        let mut differences = self.differences.clone();
        let differenced = match &estimate {
            Some(_) => None,
            None => {
                differences.tick(measurement.t, &measurement.position);
                differences.state()
            }
        };
        let y = match (&estimate, &differenced) {
            (Some(s), _) => Vector3::new(s[0][0], s[1][0], s[2][0]),
            (None, Some(d)) => d.position,
            (None, None) => measurement.position,
        };
        reference.horizon(&y, self.dt, &mut self.refs);
        if !self.refs.iter().all(|r| r.iter().all(|c| c.is_finite())) {
            return Err(ControlError::NonFiniteReference);
        }

        let dt = self.dt;
        let mut z = [[0.0; 3]; 3]; // per axis: flat state
        let mut v = [[0.0; 3]; 3]; // per axis: jerks v_0, v_1, v_2
        for axis in 0..self.axes {
            let za = match (&estimate, &differenced) {
                (Some(s), _) => [s[axis][0], s[axis][1], s[axis][2]],
                (None, Some(d)) => [d.position[axis], d.velocity[axis], d.acceleration[axis]],
                (None, None) => [y[axis], 0.0, 0.0],
            };
            let gains = &self.gains[axis];
            let mut acc = [0.0; 3];
            for (j, r) in self.refs[1..].iter().enumerate() {
                let e = r[axis] - free(&za, j + 1, dt);
                for (a, k) in acc.iter_mut().zip(&gains.k) {
                    *a += k[j] * e;
                }
            }
            z[axis] = za;
            v[axis] = acc;
        }

        // Plan: predicted positions j = 0..3 from the triple integrator.
        let mut plan = [y; 4];
        for (j, p) in plan.iter_mut().enumerate().skip(1) {
            for axis in 0..self.axes {
                let forced: f64 = (0..j).map(|i| impulse(j - 1 - i, dt) * v[axis][i]).sum();
                p[axis] = free(&z[axis], j, dt) + forced;
            }
        }

        let (command, saturated) = self.command(&z, &v)?;
        if !command.is_finite() || !plan.iter().all(|p| p.iter().all(|c| c.is_finite())) {
            return Err(ControlError::Flat(FlatError::NonFinite("FMPC command")));
        }

        self.differences = differences;
        if let Some(e) = &mut self.estimator {
            e.sent(&self.model, measurement.t, &command);
        }
        Ok(TickOutput {
            command,
            plan,
            reference: self.refs[0],
            saturated,
            constrained: false,
            qp_fallback: false,
            cone_interior_point: false,
        })
    }

    fn reset(&mut self) {
        self.differences.reset();
        if let Some(e) = &mut self.estimator {
            e.estimator.reset();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The analytic rates equal central differences of the attitude map
    /// along a path a(t) = a0 + t·ȧ.
    #[test]
    fn chain_rule_rates_match_finite_differences() {
        let h = 1e-6;
        for &(a, b, ad, bd, psi) in &[
            (0.3, -0.2, 1.1, -0.7, 0.7),
            (-0.5, 0.4, -0.3, 2.0, -2.0),
            (0.0, 0.0, 1.0, 1.0, 0.0),
        ] {
            let [th, ph, thd, phd] = attitude_with_rates(a, b, ad, bd, psi);
            let (t1, p1) = pitch_roll_from_ratios(a + h * ad, b + h * bd, psi);
            let (t0, p0) = pitch_roll_from_ratios(a - h * ad, b - h * bd, psi);
            assert_eq!((th, ph), pitch_roll_from_ratios(a, b, psi));
            assert!((thd - (t1 - t0) / (2.0 * h)).abs() < 1e-7, "θ̇ {thd}");
            assert!((phd - (p1 - p0) / (2.0 * h)).abs() < 1e-7, "φ̇ {phd}");
        }
    }

    #[test]
    fn spatial_rates_match_finite_differences() {
        let h = 1e-6;
        let g = 9.81;
        for frame in [Frame::Ned, Frame::Zup] {
            let acc = [1.5, -2.0, 0.8];
            let jerk = [3.0, 1.0, -2.5];
            let r = spatial_attitude_with_rates(frame, g, 0.4, acc, jerk).unwrap();
            let at = |s: f64| {
                let a = [0, 1, 2].map(|i| acc[i] + s * jerk[i]);
                let (t, th, ph) = thrust_pitch_roll(frame.thrust_vector(a, g), 0.4).unwrap();
                [th, ph, t]
            };
            let (p, m) = (at(h), at(-h));
            for i in 0..3 {
                let fd = (p[i] - m[i]) / (2.0 * h);
                assert!(
                    (r[3 + i] - fd).abs() < 1e-6,
                    "{frame:?} rate {i}: {} vs {fd}",
                    r[3 + i]
                );
            }
            assert_eq!([r[0], r[1], r[2]], at(0.0));
        }
    }

    #[test]
    fn impulse_response_matches_the_exact_discretisation() {
        // c·Aᵐ·B with A = [[1, δt, δt²/2], [0, 1, δt], [0, 0, 1]], B = [δt³/6, δt²/2, δt].
        let dt = 0.02;
        let mut x = [dt * dt * dt / 6.0, dt * dt / 2.0, dt];
        for m in 0..50 {
            assert!((impulse(m, dt) - x[0]).abs() <= 1e-12 * x[0]);
            x = [
                x[0] + dt * x[1] + dt * dt / 2.0 * x[2],
                x[1] + dt * x[2],
                x[2],
            ];
        }
    }
}
