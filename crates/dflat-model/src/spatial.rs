//! The spatial model (ours, beyond the paper): the planar model's first-order
//! attitude loop plus altitude through collective thrust, for autopilots
//! that take a thrust value in attitude mode (PX4 offboard).
//!
//! State `x = [x, ẋ, y, ẏ, z, ż, θ, φ, T]` (m, m/s, rad, m/s²), input
//! `u = [θ_cmd, φ_cmd, T_cmd]` (rad, rad, m/s²), output `y = [x, y, z]` (m),
//! all in the model's [`Frame`]; window R = 3. T is the specific collective
//! thrust [m/s²] (thrust / mass) along the body thrust axis `R·e3`, with
//! `R = Rz(ψ⋆)·Ry(θ)·Rx(φ)` at the fixed yaw ψ⋆. Euler step δt, with
//! `p = [x, y, z]`, `v = [ẋ, ẏ, ż]`:
//!
//! ```text
//! p_{k+1} = p_k + δt·v_k
//! v_{k+1} = v_k + δt·(a_k − D·v_k − d_r·(v_k − n_k·(n_k·v_k))),
//!                           D = diag(drag_h, drag_h, drag_v) [1/s],
//!                           d_r = drag_rotor [1/s], n_k = R_k·e3
//!                           a_k = g·e3 − T_k·R_k·e3   (NED)
//!                           a_k = T_k·R_k·e3 − g·e3   (z-up)
//! θ_{k+1} = θ_k + δt·(k̃·θ_cmd − θ_k)/τ           (φ likewise)
//! T_{k+1} = T_k + δt·(T_cmd − T_k)/τ_T
//! ```
//!
//! ## Why the window is R = 3
//!
//! Follow an input through the step: u_k sets θ, φ, T at k+1, these set the
//! acceleration a_{k+1}, which sets v_{k+2}, which sets the position y_{k+3}.
//! Every input channel reaches the output after exactly three steps, so
//!
//! * Λ(y_k, y_{k+1}, y_{k+2}): `v_k = (y_{k+1} − y_k)/δt`,
//!   `a_k = (y_{k+2} − 2·y_{k+1} + y_k)/δt² + D·v_k` (drag 0: the second
//!   difference); the specific-thrust vector
//!   `t_k = T_k·R_k·e3` follows from a_k and gravity
//!   ([`Frame::thrust_vector`]); its norm is T_k and its direction gives
//!   θ_k, φ_k at ψ⋆ (paper eqs. (pitch), (roll)). A thrust vector that does
//!   not point up through the body (a_k = gravity, free fall, or a tilt of
//!   90° or more) has no attitude: [`FlatError::FreeFall`].
//! * F(y_k, …, y_{k+3}): Λ's attitude and thrust at k and at k+1, then the
//!   exact inverses of the Euler first-order steps,
//!   `θ_cmd = (θ_k + τ·(θ_{k+1} − θ_k)/δt)/k̃` (φ likewise) and
//!   `T_cmd = T_k + τ_T·(T_{k+1} − T_k)/δt`.
//! * F⁻¹(y_k, y_{k+1}, y_{k+2}, u_k): Λ's attitude and thrust at k, one step
//!   of the attitude and thrust loops with u_k, the acceleration a_{k+1}
//!   from them, and `y_{k+3} = 2·y_{k+2} − y_{k+1} + δt²·(a_{k+1} − D·v_{k+1})`,
//!   `v_{k+1} = (y_{k+2} − y_{k+1})/δt`.
//!
//! ## Rotor drag
//!
//! `d_r` is the rotor drag in the body plane, `−d_r·R·diag(1, 1, 0)·Rᵀ·v`
//! (the blades' induced drag, across the thrust axis; Faessler, Franchi
//! and Scaramuzza, RA-L 2018, show it keeps the flatness). It splits into
//! an isotropic linear drag `−d_r·v` and a part along the thrust axis,
//! `+d_r·n·(n·v)`, that acts as a thrust change. So the maps stay closed
//! form: with `c = Δ²y/δt² + (D + d_r)·v` (and the offset), the thrust
//! axis is c's direction (as without rotor drag) and the thrust is
//! `T = T' − s·d_r·(n·v)`, T' what c alone would need and s the frame's
//! sign of the thrust in the acceleration (NED −1, z-up +1). Tilted into
//! its motion, a vehicle needs that much less thrust: the rotor drag lifts
//! it by `d_r·v·sinθ·cosθ`.
//!
//! [`SpatialModel::input_from_outputs_offset`] and
//! [`SpatialModel::next_output_offset`] are F and F⁻¹ with a constant
//! acceleration offset d in the step, `v_{k+1} = v_k + δt·(a_k − D·v_k + d)`.
//!
//! ## What the thrust lag buys
//!
//! With thrust as a direct input (T_k = T_cmd,k, as in the paper's full
//! model, [`crate::full`]), thrust would reach the position after two steps
//! and the attitude commands after three. F would still exist, but no
//! uniform F⁻¹: y_{k+3} would depend on the thrust of u_{k+1}, and y_{k+2}
//! on the thrust of u_k — the very input the controller is computing — so
//! the DF-MPC could not pin y_{k+1}, y_{k+2} from the inputs already sent
//! (paper eq. (input_to_output)). The first-order lag τ_T (physically: motor
//! spin-up and the autopilot's thrust filter, tens of ms) makes the relative
//! degree uniform, three in every channel, so the model plugs into the
//! DF-MPC exactly like the planar model. The full model keeps mixed degrees
//! (thrust two, torques four) and has no F⁻¹.

use nalgebra::{SVector, Vector3};

use crate::attitude::{Frame, thrust_axis, thrust_pitch_roll};
use crate::{
    FlatError, FlatModel, check_drag, check_finite, check_finite_param, check_len, check_positive,
    finite_result,
};

/// State `[x, ẋ, y, ẏ, z, ż, θ, φ, T]` (m, m/s, rad, m/s²).
pub type SpatialState = SVector<f64, 9>;
/// Input `[θ_cmd, φ_cmd, T_cmd]` (rad, rad, m/s²).
pub type SpatialInput = Vector3<f64>;
/// Output `[x, y, z]` (m).
pub type SpatialOutput = Vector3<f64>;

/// Parameters of the spatial model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialParams {
    /// Discretisation step δt \[s\].
    pub dt: f64,
    /// Attitude time constant τ \[s\].
    pub tau: f64,
    /// Attitude gain k̃ [-].
    pub k: f64,
    /// Thrust time constant τ_T \[s\]. The Euler step of a first-order lag
    /// overshoots for δt > τ_T and diverges for δt ≥ 2·τ_T (likewise τ):
    /// configure δt ≤ τ_T.
    pub tau_thrust: f64,
    /// Gravity g [m/s²].
    pub g: f64,
    /// Fixed yaw ψ⋆ \[rad\].
    pub psi: f64,
    /// Frame convention.
    pub frame: Frame,
    /// Linear horizontal drag \[1/s\] in the world frame (x, y; ≥ 0,
    /// drag·δt < 1). 0 is no drag.
    pub drag_h: f64,
    /// Linear vertical drag \[1/s\] in the world frame (z; ≥ 0,
    /// drag·δt < 1). 0 is no drag.
    pub drag_v: f64,
    /// Rotor drag \[1/s\] in the body plane: the step loses
    /// `drag_rotor·(v − n·(n·v))`, n = R·e3 the thrust axis (≥ 0,
    /// (drag_h + drag_rotor)·δt < 1). 0 is none.
    pub drag_rotor: f64,
}

impl Default for SpatialParams {
    /// 50 Hz, τ = 0.2 s, k̃ = 1, τ_T = 0.04 s, g = 9.81, ψ = 0, NED, no drag.
    fn default() -> Self {
        Self {
            dt: 0.02,
            tau: 0.2,
            k: 1.0,
            tau_thrust: 0.04,
            g: 9.81,
            psi: 0.0,
            frame: Frame::Ned,
            drag_h: 0.0,
            drag_v: 0.0,
            drag_rotor: 0.0,
        }
    }
}

/// The spatial model with validated parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialModel {
    p: SpatialParams,
}

impl SpatialModel {
    /// Builds the model; errors name the invalid parameter (dt, tau, k,
    /// tau_thrust, g must be finite and > 0; psi finite).
    pub fn new(p: SpatialParams) -> Result<Self, FlatError> {
        check_positive("dt", p.dt)?;
        check_positive("tau", p.tau)?;
        check_positive("k", p.k)?;
        check_positive("tau_thrust", p.tau_thrust)?;
        check_positive("g", p.g)?;
        check_finite_param("psi", p.psi)?;
        check_drag("drag_h", p.drag_h, p.dt)?;
        check_drag("drag_v", p.drag_v, p.dt)?;
        check_drag("drag_rotor", p.drag_rotor, p.dt)?;
        // The isotropic part of the rotor drag adds to the linear drag.
        if (p.drag_rotor + p.drag_h.max(p.drag_v)) * p.dt >= 1.0 {
            return Err(FlatError::InvalidParameter {
                name: "drag_rotor",
                value: p.drag_rotor,
                allowed: "max(drag_h, drag_v) + drag_rotor < 1/dt",
            });
        }
        Ok(Self { p })
    }

    /// The parameters.
    pub fn params(&self) -> &SpatialParams {
        &self.p
    }

    /// Specific thrust [m/s²] that holds hover: g.
    pub fn hover_thrust(&self) -> f64 {
        self.p.g
    }

    /// World-frame acceleration [m/s²] (model frame) at pitch θ, roll φ
    /// \[rad\], yaw ψ⋆ and specific thrust `thrust` [m/s²]. Defined for every
    /// attitude.
    pub fn acceleration(&self, theta: f64, phi: f64, thrust: f64) -> Vector3<f64> {
        let t = thrust_axis(theta, phi, self.p.psi).map(|c| thrust * c);
        Vector3::from(self.p.frame.acceleration(t, self.p.g))
    }

    /// Specific thrust T [m/s²], pitch θ and roll φ \[rad\] (at yaw ψ⋆) that
    /// produce the world-frame acceleration `a` [m/s²] (model frame): the
    /// inverse of [`Self::acceleration`] for T > 0 and |θ|, |φ| < 90°.
    ///
    /// Errors: [`FlatError::NonFinite`] for non-finite `a`,
    /// [`FlatError::FreeFall`] when the required thrust does not point up
    /// through the body (`a` equal to gravity, or beyond 90° of tilt).
    pub fn attitude_thrust(&self, a: &Vector3<f64>) -> Result<(f64, f64, f64), FlatError> {
        check_finite(a.iter(), "acceleration")?;
        let t = self.p.frame.thrust_vector([a.x, a.y, a.z], self.p.g);
        let (thrust, theta, phi) = thrust_pitch_roll(t, self.p.psi)?;
        Ok((thrust, theta, phi))
    }

    /// The linear drag's deceleration \[m/s²\] at velocity `v` \[m/s\]:
    /// `D·v`.
    fn drag(&self, v: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(
            self.p.drag_h * v.x,
            self.p.drag_h * v.y,
            self.p.drag_v * v.z,
        )
    }

    /// The drag's acceleration \[m/s²\] (model frame) at velocity `v`
    /// \[m/s\] and pitch θ, roll φ \[rad\] (yaw ψ⋆): the linear drag's
    /// and the rotor drag's, `−D·v − d_r·(v − n·(n·v))`, n = R·e3.
    pub fn drag_acceleration(&self, theta: f64, phi: f64, v: &Vector3<f64>) -> Vector3<f64> {
        if self.p.drag_rotor == 0.0 {
            return -self.drag(v);
        }
        self.drag_acceleration_at_axis(&Vector3::from(thrust_axis(theta, phi, self.p.psi)), v)
    }

    /// [`Self::drag_acceleration`] at the unit thrust axis `n` (model
    /// frame; its sign does not matter): `−D·v − d_r·(v − n·(n·v))`.
    pub fn drag_acceleration_at_axis(&self, n: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
        -self.drag(v) - self.p.drag_rotor * (v - n * n.dot(v))
    }

    /// Thrust and attitude (T, θ, φ) at the first of three outputs, from the
    /// thrust's acceleration: their second difference plus the drag at the
    /// first velocity minus the acceleration offset `d` \[m/s²\].
    fn attitude_thrust_at(
        &self,
        y0: &SpatialOutput,
        y1: &SpatialOutput,
        y2: &SpatialOutput,
        d: &Vector3<f64>,
    ) -> Result<(f64, f64, f64), FlatError> {
        let dt = self.p.dt;
        let v = (y1 - y0) / dt;
        let dr = self.p.drag_rotor;
        let a = (y2 - 2.0 * y1 + y0) / (dt * dt) + self.drag(&v) + dr * v - d;
        let (thrust, theta, phi) = self.attitude_thrust(&a)?;
        if dr == 0.0 {
            return Ok((thrust, theta, phi));
        }
        // The rotor drag's part along the thrust axis, d_r·n·(n·v), is a
        // thrust change (module docs, Rotor drag).
        let n = Vector3::from(thrust_axis(theta, phi, self.p.psi));
        // s, the thrust's sign in `a = g_vec + s·T·n`, is the frame's
        // horizontal sign (NED −1, z-up +1).
        let thrust = thrust - self.p.frame.horizontal_sign() * dr * n.dot(&v);
        if thrust > 0.0 {
            Ok((thrust, theta, phi))
        } else {
            Err(FlatError::FreeFall)
        }
    }

    /// F with a constant acceleration offset `d` \[m/s²\] in the step: the
    /// input at the first of four outputs. `d = 0` is
    /// [`FlatModel::input_from_outputs`].
    pub fn input_from_outputs_offset(
        &self,
        y: &[SpatialOutput],
        d: &Vector3<f64>,
    ) -> Result<SpatialInput, FlatError> {
        self.input_from_outputs_offsets(y, &[*d, *d])
    }

    /// F with an acceleration offset per step \[m/s²\]: `d[0]` in the step
    /// from the first output, `d[1]` in the step from the second (an offset
    /// that depends on the outputs, such as a learned residual, evaluated
    /// at each step's velocity). `[d, d]` is
    /// [`SpatialModel::input_from_outputs_offset`].
    pub fn input_from_outputs_offsets(
        &self,
        y: &[SpatialOutput],
        d: &[Vector3<f64>; 2],
    ) -> Result<SpatialInput, FlatError> {
        check_len(y.len(), 4)?;
        check_finite(
            y.iter().flat_map(|v| v.iter()).chain(d.iter().flatten()),
            "outputs",
        )?;
        let (f0, t0, p0) = self.attitude_thrust_at(&y[0], &y[1], &y[2], &d[0])?;
        let (f1, t1, p1) = self.attitude_thrust_at(&y[1], &y[2], &y[3], &d[1])?;
        finite_result(
            SpatialInput::new(
                self.attitude_command(t0, t1),
                self.attitude_command(p0, p1),
                self.thrust_command(f0, f1),
            ),
            "input",
        )
    }

    /// F⁻¹ with a constant acceleration offset `d` \[m/s²\] in the step:
    /// the output after three when `u` is applied at the first. `d = 0` is
    /// [`FlatModel::next_output`].
    pub fn next_output_offset(
        &self,
        y: &[SpatialOutput],
        u: &SpatialInput,
        d: &Vector3<f64>,
    ) -> Result<SpatialOutput, FlatError> {
        self.next_output_offsets(y, u, &[*d, *d])
    }

    /// F⁻¹ with an acceleration offset per step \[m/s²\]: `d[0]` in the step
    /// from the first output (the attitude and thrust there), `d[1]` in the
    /// step from the second (the one `u` drives). `[d, d]` is
    /// [`SpatialModel::next_output_offset`].
    pub fn next_output_offsets(
        &self,
        y: &[SpatialOutput],
        u: &SpatialInput,
        d: &[Vector3<f64>; 2],
    ) -> Result<SpatialOutput, FlatError> {
        check_len(y.len(), 3)?;
        check_finite(
            y.iter()
                .flat_map(|v| v.iter())
                .chain(u.iter())
                .chain(d.iter().flatten()),
            "outputs and input",
        )?;
        let (f0, t0, p0) = self.attitude_thrust_at(&y[0], &y[1], &y[2], &d[0])?;
        let acc = self.acceleration(
            self.attitude_step(t0, u.x),
            self.attitude_step(p0, u.y),
            self.thrust_step(f0, u.z),
        );
        let (theta1, phi1) = (self.attitude_step(t0, u.x), self.attitude_step(p0, u.y));
        let dt = self.p.dt;
        let v1 = (y[2] - y[1]) / dt;
        finite_result(
            2.0 * y[2] - y[1] + dt * dt * (acc + self.drag_acceleration(theta1, phi1, &v1) + d[1]),
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

    /// One Euler step of the first-order thrust loop.
    fn thrust_step(&self, thrust: f64, cmd: f64) -> f64 {
        thrust + self.p.dt * (cmd - thrust) / self.p.tau_thrust
    }

    /// Exact inverse of [`Self::thrust_step`]: the command taking `t0` to `t1`.
    fn thrust_command(&self, t0: f64, t1: f64) -> f64 {
        t0 + self.p.tau_thrust * (t1 - t0) / self.p.dt
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

    /// Forward Euler; defined for every state (the thrust axis exists at any
    /// attitude).
    fn step(&self, x: &SpatialState, u: &SpatialInput) -> SpatialState {
        let dt = self.p.dt;
        let v = Vector3::new(x[1], x[3], x[5]);
        let a = self.acceleration(x[6], x[7], x[8]) + self.drag_acceleration(x[6], x[7], &v);
        SpatialState::from([
            x[0] + dt * x[1],
            x[1] + dt * a.x,
            x[2] + dt * x[3],
            x[3] + dt * a.y,
            x[4] + dt * x[5],
            x[5] + dt * a.z,
            self.attitude_step(x[6], u.x),
            self.attitude_step(x[7], u.y),
            self.thrust_step(x[8], u.z),
        ])
    }

    fn output(&self, x: &SpatialState) -> SpatialOutput {
        SpatialOutput::new(x[0], x[2], x[4])
    }

    fn state_from_outputs(&self, y: &[SpatialOutput]) -> Result<SpatialState, FlatError> {
        check_len(y.len(), 3)?;
        check_finite(y.iter().flat_map(|v| v.iter()), "outputs")?;
        let v = (y[1] - y[0]) / self.p.dt;
        let (thrust, theta, phi) =
            self.attitude_thrust_at(&y[0], &y[1], &y[2], &Vector3::zeros())?;
        finite_result(
            SpatialState::from([y[0].x, v.x, y[0].y, v.y, y[0].z, v.z, theta, phi, thrust]),
            "state",
        )
    }

    fn input_from_outputs(&self, y: &[SpatialOutput]) -> Result<SpatialInput, FlatError> {
        self.input_from_outputs_offset(y, &Vector3::zeros())
    }

    fn next_output(
        &self,
        y: &[SpatialOutput],
        u: &SpatialInput,
    ) -> Result<SpatialOutput, FlatError> {
        self.next_output_offset(y, u, &Vector3::zeros())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parameter's name and what makes it invalid.
    type Spoiler = (&'static str, fn(&mut SpatialParams));

    #[test]
    fn rejects_bad_parameters() {
        let spoilers: [Spoiler; 6] = [
            ("dt", |p| p.dt = 0.0),
            ("tau", |p| p.tau = -1.0),
            ("k", |p| p.k = f64::NAN),
            ("tau_thrust", |p| p.tau_thrust = 0.0),
            ("g", |p| p.g = f64::INFINITY),
            ("psi", |p| p.psi = f64::NAN),
        ];
        for (name, spoil) in spoilers {
            let mut p = SpatialParams::default();
            spoil(&mut p);
            match SpatialModel::new(p) {
                Err(FlatError::InvalidParameter { name: got, .. }) => assert_eq!(got, name),
                other => panic!("{name}: {other:?}"),
            }
        }
    }

    /// The rotor drag's isotropic part adds to the linear drag: their sum
    /// must keep one Euler step from reversing the velocity.
    #[test]
    fn rotor_drag_and_linear_drag_together_are_bounded() {
        let p = SpatialParams {
            dt: 0.1,
            drag_h: 6.0,
            drag_rotor: 5.0,
            ..Default::default()
        };
        match SpatialModel::new(p) {
            Err(FlatError::InvalidParameter { name, allowed, .. }) => {
                assert_eq!(name, "drag_rotor");
                assert!(allowed.contains("drag_h"), "{allowed}");
            }
            other => panic!("{other:?}"),
        }
        SpatialModel::new(SpatialParams {
            drag_rotor: 4.0,
            ..p
        })
        .unwrap_err();
        SpatialModel::new(SpatialParams {
            drag_h: 4.0,
            drag_rotor: 5.0,
            ..p
        })
        .unwrap();
    }

    #[test]
    fn hover_is_a_fixed_point() {
        for frame in [Frame::Ned, Frame::Zup] {
            let m = SpatialModel::new(SpatialParams {
                frame,
                ..Default::default()
            })
            .unwrap();
            let x = SpatialState::from([1.0, 0.0, 2.0, 0.0, -3.0, 0.0, 0.0, 0.0, 9.81]);
            assert_eq!(m.step(&x, &SpatialInput::new(0.0, 0.0, 9.81)), x);
        }
    }

    /// Level flight at constant velocity against rotor drag alone: along
    /// the thrust axis, `0 = g·n_z − T + d_r·(n·v) − d_r·(n·v)`, so the
    /// thrust is `g·n_z` — less than hover, where without the rotor
    /// drag's lift a tilted vehicle needs `g/n_z`. Λ finds it from the
    /// outputs, in both frames and on any heading.
    #[test]
    fn rotor_drag_lifts_a_vehicle_tilted_into_its_motion() {
        for (frame, psi, v) in [
            (Frame::Ned, 0.0, Vector3::new(9.0, 0.0, 0.0)),
            (Frame::Ned, 0.7, Vector3::new(-3.0, 6.0, 0.0)),
            (Frame::Zup, -1.2, Vector3::new(4.0, -5.0, 0.0)),
        ] {
            let m = SpatialModel::new(SpatialParams {
                frame,
                psi,
                drag_rotor: 0.3,
                ..Default::default()
            })
            .unwrap();
            let y: Vec<SpatialOutput> = (0..3).map(|k| v * (0.02 * k as f64)).collect();
            let x = m.state_from_outputs(&y).unwrap();
            let n = Vector3::from(thrust_axis(x[6], x[7], psi));
            let tilt = n.z.abs().acos();
            assert!(tilt > 0.05, "tilted into the motion: {tilt}");
            assert!(
                (x[8] - 9.81 * n.z.abs()).abs() < 1e-9,
                "{frame:?}: T = {}",
                x[8]
            );
            // One step of the model from that state keeps the velocity.
            let u = SpatialInput::new(x[6] / m.params().k, x[7] / m.params().k, x[8]);
            let next = m.step(&x, &u);
            assert!((next[1] - v.x).abs() < 1e-12 && (next[3] - v.y).abs() < 1e-12);
            assert!(next[5].abs() < 1e-12, "{frame:?}: vz {}", next[5]);
        }
    }

    #[test]
    fn ned_nose_down_accelerates_north_and_thrust_lifts() {
        let m = SpatialModel::new(SpatialParams::default()).unwrap();
        let a = m.acceleration(-0.2, 0.0, 9.81 / 0.2_f64.cos());
        assert!((a.x - 9.81 * 0.2_f64.tan()).abs() < 1e-12 && a.z.abs() < 1e-12);
        // More thrust than hover: up, i.e. −z in NED.
        assert!(m.acceleration(0.0, 0.0, 12.0).z < 0.0);
        let (t, th, ph) = m.attitude_thrust(&a).unwrap();
        assert!(
            (t - 9.81 / 0.2_f64.cos()).abs() < 1e-12
                && (th + 0.2).abs() < 1e-14
                && ph.abs() < 1e-14
        );
    }
}
