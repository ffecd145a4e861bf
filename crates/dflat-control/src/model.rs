//! The models the controllers run on, behind one enum chosen by config.
//!
//! [`ControlModel`] gives the controllers one representation for both
//! models, so the window, the prediction and the optimisation do not care
//! which one flies:
//!
//! * outputs are `Vector3` positions `[x, y, z]` \[m\] in the model's frame
//!   (local NED for flight; the planar model ignores z and carries it along),
//! * inputs are `Vector3` `[θ_cmd, φ_cmd, T_cmd]` (rad, rad, m/s² specific
//!   thrust); the planar model's thrust is always hover, `T_cmd = g`.
//!
//! Both models have window r = [`WINDOW`] = 3: `u_k = F(y_k..y_{k+3})` and
//! `y_{k+3} = F⁻¹(y_k..y_{k+2}, u_k)`. Everything here is pure and does not
//! allocate.
//!
//! # Disturbance-aware maps
//!
//! [`ControlModel::next_output_disturbed`] and
//! [`ControlModel::input_from_outputs_disturbed`] are F⁻¹ and F of the
//! model with an estimated constant acceleration offset d \[m/s²\] (model
//! frame) and, for the spatial model, a thrust scale κ (actual specific
//! thrust = κ · model thrust) added to its Euler step:
//!
//! ```text
//! v_{k+1} = v_k + δt·(a(θ_k, φ_k, κ·T_k) + d)
//! ```
//!
//! The offset goes straight into the models' maps (Λ's thrust acceleration
//! is `Δ²y/δt² + D·Δy/δt − d`, F⁻¹ adds `δt²·d`:
//! [`dflat_model::PlanarModel::next_output_offset`] and its siblings), exact
//! with and without the model's linear drag D; the thrust scale by working
//! in effective thrust κ·T (a linear first-order lag commutes with the
//! scale):
//!
//! ```text
//! F⁻¹_d(y_0..y_2, u) = F⁻¹ with offset d of (y_0..y_2, [θ_cmd, φ_cmd, κ·T_cmd])
//! F_d(y_0..y_3)      = F with offset d of (y_0..y_3), T_cmd divided by κ
//! ```
//!
//! With the nominal estimate (d = 0, κ = 1) they call the plain maps, so
//! results are bit-identical to them.

use dflat_model::{FlatError, FlatModel, Frame, PlanarModel, SpatialModel};
use nalgebra::{Vector2, Vector3};

use crate::AttitudeCommand;

/// Window r of both control models: the input needs r + 1 = 4 consecutive
/// outputs, the prediction r = 3 outputs and one input.
pub const WINDOW: usize = 3;

/// The controller's model of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControlModel {
    /// Planar model: x, y controlled, altitude held by the autopilot.
    Planar(PlanarModel),
    /// Spatial model: x, y, z with collective thrust.
    Spatial(SpatialModel),
}

fn xy(v: &Vector3<f64>) -> Vector2<f64> {
    Vector2::new(v.x, v.y)
}

impl ControlModel {
    /// Number of controlled position axes: 2 (planar: x, y) or 3 (spatial).
    pub fn axes(&self) -> usize {
        match self {
            ControlModel::Planar(_) => 2,
            ControlModel::Spatial(_) => 3,
        }
    }

    /// Control step δt \[s\].
    pub fn dt(&self) -> f64 {
        match self {
            ControlModel::Planar(m) => m.dt(),
            ControlModel::Spatial(m) => m.dt(),
        }
    }

    /// The model's fixed yaw ψ⋆ \[rad\].
    pub fn yaw(&self) -> f64 {
        match self {
            ControlModel::Planar(m) => m.params().psi,
            ControlModel::Spatial(m) => m.params().psi,
        }
    }

    /// Gravity g [m/s²].
    pub fn gravity(&self) -> f64 {
        match self {
            ControlModel::Planar(m) => m.params().g,
            ControlModel::Spatial(m) => m.params().g,
        }
    }

    /// Frame convention of the outputs and attitude.
    pub fn frame(&self) -> Frame {
        match self {
            ControlModel::Planar(m) => m.params().frame,
            ControlModel::Spatial(m) => m.params().frame,
        }
    }

    /// The hover input `[0, 0, g]`: level attitude, specific thrust g [m/s²].
    pub fn hover_input(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, self.gravity())
    }

    /// F⁻¹, the input-to-output map: `y_{k+3}` from `y_k, y_{k+1}, y_{k+2}`
    /// (oldest first) and `u_k`. The planar model carries z of `y_{k+2}`.
    pub fn next_output(
        &self,
        y: &[Vector3<f64>; 3],
        u: &Vector3<f64>,
    ) -> Result<Vector3<f64>, FlatError> {
        match self {
            ControlModel::Planar(m) => {
                let w = [xy(&y[0]), xy(&y[1]), xy(&y[2])];
                let n = m.next_output(&w, &Vector2::new(u.x, u.y))?;
                Ok(Vector3::new(n.x, n.y, y[2].z))
            }
            ControlModel::Spatial(m) => m.next_output(y, u),
        }
    }

    /// F, the output-to-input map: `u_k = [θ_cmd, φ_cmd, T_cmd]` from
    /// `y_k..y_{k+3}` (oldest first). The planar model returns `T_cmd = g`.
    pub fn input_from_outputs(&self, y: &[Vector3<f64>; 4]) -> Result<Vector3<f64>, FlatError> {
        match self {
            ControlModel::Planar(m) => {
                let w = [xy(&y[0]), xy(&y[1]), xy(&y[2]), xy(&y[3])];
                let u = m.input_from_outputs(&w)?;
                Ok(Vector3::new(u.x, u.y, m.params().g))
            }
            ControlModel::Spatial(m) => m.input_from_outputs(y),
        }
    }

    /// The offset d \[m/s²\] the maps add to the step (z dropped for the
    /// planar model).
    fn offset(&self, d: &DisturbanceEstimate) -> Vector3<f64> {
        let mut q = d.acceleration;
        if let ControlModel::Planar(_) = self {
            q.z = 0.0;
        }
        q
    }

    /// F⁻¹ with a disturbance estimate (see the module docs): `y_{k+3}` \[m\]
    /// from `y_k, y_{k+1}, y_{k+2}` (oldest first) and `u_k` when the model's
    /// acceleration is offset by `d.acceleration` \[m/s²\] (model frame) and,
    /// for the spatial model, its thrust scaled by `d.thrust_scale`.
    /// Identical to [`ControlModel::next_output`] for the nominal estimate.
    pub fn next_output_disturbed(
        &self,
        y: &[Vector3<f64>; 3],
        u: &Vector3<f64>,
        d: &DisturbanceEstimate,
    ) -> Result<Vector3<f64>, FlatError> {
        if d.is_nominal() {
            return self.next_output(y, u);
        }
        let q = self.offset(d);
        match self {
            ControlModel::Planar(m) => {
                let w = [xy(&y[0]), xy(&y[1]), xy(&y[2])];
                let n = m.next_output_offset(&w, &Vector2::new(u.x, u.y), &xy(&q))?;
                Ok(Vector3::new(n.x, n.y, y[2].z))
            }
            ControlModel::Spatial(m) => {
                let u_eff = Vector3::new(u.x, u.y, u.z * d.thrust_scale);
                m.next_output_offset(y, &u_eff, &q)
            }
        }
    }

    /// F with a disturbance estimate (see the module docs): the input
    /// `[θ_cmd, φ_cmd, T_cmd]` that makes the disturbed model fly
    /// `y_k..y_{k+3}` \[m\] (oldest first). Identical to
    /// [`ControlModel::input_from_outputs`] for the nominal estimate.
    pub fn input_from_outputs_disturbed(
        &self,
        y: &[Vector3<f64>; 4],
        d: &DisturbanceEstimate,
    ) -> Result<Vector3<f64>, FlatError> {
        if d.is_nominal() {
            return self.input_from_outputs(y);
        }
        let q = self.offset(d);
        let u = match self {
            ControlModel::Planar(m) => {
                let w = [xy(&y[0]), xy(&y[1]), xy(&y[2]), xy(&y[3])];
                let u = m.input_from_outputs_offset(&w, &xy(&q))?;
                Vector3::new(u.x, u.y, m.params().g)
            }
            ControlModel::Spatial(m) => {
                let mut u = m.input_from_outputs_offset(y, &q)?;
                u.z /= d.thrust_scale;
                u
            }
        };
        if u.iter().all(|v| v.is_finite()) {
            Ok(u)
        } else {
            Err(FlatError::NonFinite("input"))
        }
    }

    /// F⁻¹ with a disturbance estimate and, on top of its offset, an
    /// acceleration offset per step `steps` \[m/s²\] (model frame): `steps[0]`
    /// in the step from `y_k` (the attitude there), `steps[1]` in the step
    /// from `y_{k+1}` (the one `u_k` drives). The learned residual enters
    /// here, evaluated at each step's velocity. Zero `steps` is
    /// [`ControlModel::next_output_disturbed`], bit for bit.
    pub fn next_output_stepped(
        &self,
        y: &[Vector3<f64>; 3],
        u: &Vector3<f64>,
        d: &DisturbanceEstimate,
        steps: &[Vector3<f64>; 2],
    ) -> Result<Vector3<f64>, FlatError> {
        if steps.iter().all(|s| *s == Vector3::zeros()) {
            return self.next_output_disturbed(y, u, d);
        }
        let q = self.offset(d);
        match self {
            ControlModel::Planar(m) => {
                let w = [xy(&y[0]), xy(&y[1]), xy(&y[2])];
                let qs = [xy(&(q + steps[0])), xy(&(q + steps[1]))];
                let n = m.next_output_offsets(&w, &Vector2::new(u.x, u.y), &qs)?;
                Ok(Vector3::new(n.x, n.y, y[2].z))
            }
            ControlModel::Spatial(m) => {
                let u_eff = Vector3::new(u.x, u.y, u.z * d.thrust_scale);
                m.next_output_offsets(y, &u_eff, &[q + steps[0], q + steps[1]])
            }
        }
    }

    /// F with a disturbance estimate and an acceleration offset per step
    /// `steps` \[m/s²\] (model frame): `steps[0]` in the step from `y_k`,
    /// `steps[1]` in the step from `y_{k+1}`. Zero `steps` is
    /// [`ControlModel::input_from_outputs_disturbed`], bit for bit.
    pub fn input_from_outputs_stepped(
        &self,
        y: &[Vector3<f64>; 4],
        d: &DisturbanceEstimate,
        steps: &[Vector3<f64>; 2],
    ) -> Result<Vector3<f64>, FlatError> {
        if steps.iter().all(|s| *s == Vector3::zeros()) {
            return self.input_from_outputs_disturbed(y, d);
        }
        let q = self.offset(d);
        let u = match self {
            ControlModel::Planar(m) => {
                let w = [xy(&y[0]), xy(&y[1]), xy(&y[2]), xy(&y[3])];
                let qs = [xy(&(q + steps[0])), xy(&(q + steps[1]))];
                let u = m.input_from_outputs_offsets(&w, &qs)?;
                Vector3::new(u.x, u.y, m.params().g)
            }
            ControlModel::Spatial(m) => {
                let mut u = m.input_from_outputs_offsets(y, &[q + steps[0], q + steps[1]])?;
                u.z /= d.thrust_scale;
                u
            }
        };
        if u.iter().all(|v| v.is_finite()) {
            Ok(u)
        } else {
            Err(FlatError::NonFinite("input"))
        }
    }

    /// The model's drag as a linear drag \[1/s\] per axis at level
    /// attitude, `[D_h + d_r, D_h + d_r, D_v]` (planar: `[D_h, D_h, 0]`):
    /// the step subtracts `D·v` from the acceleration. The rotor drag d_r
    /// (spatial) is `−d_r·(v − n·(n·v))`, which with the thrust axis n
    /// vertical is `−d_r·v` horizontally and nothing vertically; the tilt
    /// bound, the sent command's anchor, the disturbance estimator's basis
    /// and the residual's features take it so. The maps and
    /// [`Self::drag_acceleration`] take it exactly.
    pub fn drag(&self) -> Vector3<f64> {
        match self {
            ControlModel::Planar(m) => Vector3::new(m.params().drag_h, m.params().drag_h, 0.0),
            ControlModel::Spatial(m) => {
                let p = m.params();
                Vector3::new(p.drag_h + p.drag_rotor, p.drag_h + p.drag_rotor, p.drag_v)
            }
        }
    }

    /// The drag's acceleration \[m/s²\] (model frame) at velocity `v`
    /// \[m/s\] when the thrust and gravity give `thrust_acc` \[m/s²\]:
    /// `−D·v`, and for the spatial model with rotor drag
    /// `−D·v − d_r·(v − n·(n·v))`, n the thrust axis (the direction of
    /// `thrust_acc` less gravity; vertical when that is 0).
    pub fn drag_acceleration(&self, v: &Vector3<f64>, thrust_acc: &Vector3<f64>) -> Vector3<f64> {
        match self {
            ControlModel::Spatial(m) if m.params().drag_rotor != 0.0 => {
                let p = m.params();
                let t = Vector3::from(
                    p.frame
                        .thrust_vector([thrust_acc.x, thrust_acc.y, thrust_acc.z], p.g),
                );
                let n = if t.norm() > 0.0 {
                    t.normalize()
                } else {
                    Vector3::z()
                };
                m.drag_acceleration_at_axis(&n, v)
            }
            _ => -self.drag().component_mul(v),
        }
    }

    /// One Euler step of the model's input dynamics: the first-order
    /// attitude loop `θ_{k+1} = θ_k + δt·(k̃·θ_cmd − θ_k)/τ` (φ likewise)
    /// and, for the spatial model, the thrust lag
    /// `T_{k+1} = T_k + δt·(T_cmd − T_k)/τ_T`. `s = [θ, φ, T]`, `u` the sent
    /// input; the planar model keeps T.
    pub fn input_state_step(&self, s: &Vector3<f64>, u: &Vector3<f64>) -> Vector3<f64> {
        let dt = self.dt();
        let (tau, k, thrust) = match self {
            ControlModel::Planar(m) => (m.params().tau, m.params().k, s.z),
            ControlModel::Spatial(m) => {
                let p = m.params();
                (p.tau, p.k, s.z + dt * (u.z - s.z) / p.tau_thrust)
            }
        };
        Vector3::new(
            s.x + dt * (k * u.x - s.x) / tau,
            s.y + dt * (k * u.y - s.y) / tau,
            thrust,
        )
    }

    /// The attitude gain k̃ [-]: the attitude settles to k̃·θ_cmd.
    pub fn attitude_gain(&self) -> f64 {
        match self {
            ControlModel::Planar(m) => m.params().k,
            ControlModel::Spatial(m) => m.params().k,
        }
    }

    /// The inverse of [`ControlModel::input_state_step`]'s attitude part:
    /// the commanded `(θ_cmd, φ_cmd)` \[rad\] that takes the measured
    /// attitude `before = (θ, φ)` to `after` in one step δt,
    /// `θ_cmd = (θ_k + τ·(θ_{k+1} − θ_k)/δt) / k̃` (φ likewise). This is what
    /// F does for the pitch command from the outputs, here from a measured
    /// attitude (ATTITUDE): the input that explains what the vehicle did
    /// when the autopilot flew its own commands (standby).
    pub fn input_from_attitude(&self, before: [f64; 2], after: [f64; 2]) -> [f64; 2] {
        let (tau, k) = match self {
            ControlModel::Planar(m) => (m.params().tau, m.params().k),
            ControlModel::Spatial(m) => (m.params().tau, m.params().k),
        };
        let r = tau / self.dt();
        [
            (before[0] + r * (after[0] - before[0])) / k,
            (before[1] + r * (after[1] - before[1])) / k,
        ]
    }

    /// The model's acceleration \[m/s²\] (model frame) at the input-driven
    /// state `s = [θ, φ, T]`, split as `a = a_g + κ·a_T` for a thrust scale
    /// κ: returns `(a_g, a_T)`. Planar: `a_g` is the level-flight
    /// acceleration (z = 0) and `a_T = 0` (the autopilot holds altitude);
    /// spatial: `a_g` is gravity alone and `a_T` the thrust's share.
    /// Errors at 90° of tilt (planar).
    pub fn acceleration_parts(
        &self,
        s: &Vector3<f64>,
    ) -> Result<(Vector3<f64>, Vector3<f64>), FlatError> {
        match self {
            ControlModel::Planar(m) => {
                let a = m.acceleration(s.x, s.y)?;
                Ok((Vector3::new(a.x, a.y, 0.0), Vector3::zeros()))
            }
            ControlModel::Spatial(m) => {
                let a_g = m.acceleration(s.x, s.y, 0.0);
                let a = m.acceleration(s.x, s.y, s.z);
                Ok((a_g, a - a_g))
            }
        }
    }

    /// The autopilot command for input `u = [θ_cmd, φ_cmd, T_cmd]` at the
    /// model's yaw ψ⋆.
    pub fn command(&self, u: &Vector3<f64>) -> AttitudeCommand {
        AttitudeCommand {
            pitch: u.x,
            roll: u.y,
            yaw: self.yaw(),
            thrust: u.z,
        }
    }
}

/// The current disturbance estimate, as the disturbance-aware maps use it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisturbanceEstimate {
    /// Acceleration offset d \[m/s²\] in the model frame (local NED for
    /// flight): what the vehicle accelerates beyond the model. z is 0 for
    /// both models (the spatial model's vertical channel is κ).
    pub acceleration: Vector3<f64>,
    /// Thrust scale κ \[-\]: actual specific thrust per model thrust (1 for
    /// the planar model).
    pub thrust_scale: f64,
}

impl DisturbanceEstimate {
    /// No disturbance: d = 0, κ = 1.
    pub const NOMINAL: Self = Self {
        acceleration: Vector3::new(0.0, 0.0, 0.0),
        thrust_scale: 1.0,
    };

    /// True for exactly d = 0 and κ = 1 (the maps then run unchanged).
    pub fn is_nominal(&self) -> bool {
        *self == Self::NOMINAL
    }

    /// Specific thrust that holds hover \[m/s²\] in the model's thrust units:
    /// `g/κ` for gravity `g` \[m/s²\]. Divide by the autopilot's full-scale
    /// specific thrust for the normalised hover thrust.
    pub fn hover_thrust(&self, g: f64) -> f64 {
        g / self.thrust_scale
    }
}

impl Default for DisturbanceEstimate {
    fn default() -> Self {
        Self::NOMINAL
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_model::PlanarParams;

    fn planar() -> ControlModel {
        ControlModel::Planar(PlanarModel::new(PlanarParams::default()).unwrap())
    }

    #[test]
    fn planar_maps_are_inverse() {
        let m = planar();
        let y = [
            Vector3::new(0.0, 0.0, -2.0),
            Vector3::new(0.01, -0.02, -2.0),
            Vector3::new(0.021, -0.041, -2.0),
        ];
        let u = Vector3::new(-0.1, 0.05, 9.81);
        let y3 = m.next_output(&y, &u).unwrap();
        assert_eq!(y3.z, -2.0);
        let u2 = m.input_from_outputs(&[y[0], y[1], y[2], y3]).unwrap();
        assert!((u2 - u).norm() < 1e-9, "{u2} vs {u}");
        assert_eq!(m.axes(), 2);
        assert_eq!(m.hover_input(), Vector3::new(0.0, 0.0, 9.81));
        let c = m.command(&u);
        assert_eq!((c.pitch, c.roll, c.thrust), (-0.1, 0.05, 9.81));
    }

    #[test]
    fn disturbed_maps_invert_the_disturbed_step() {
        use dflat_model::{FlatModel, SpatialParams};
        let sm = SpatialModel::new(SpatialParams {
            psi: 0.4,
            ..Default::default()
        })
        .unwrap();
        let m = ControlModel::Spatial(sm);
        let d = DisturbanceEstimate {
            acceleration: Vector3::new(0.7, -0.3, 0.0),
            thrust_scale: 1.25,
        };
        // The disturbed Euler step: thrust scaled by κ, offset d on v.
        let step = |x: &dflat_model::spatial::SpatialState, u: &Vector3<f64>| {
            let mut n = sm.step(x, &Vector3::new(u.x, u.y, d.thrust_scale * u.z));
            for (i, a) in [
                (1, d.acceleration.x),
                (3, d.acceleration.y),
                (5, d.acceleration.z),
            ] {
                n[i] += sm.dt() * a;
            }
            n
        };
        let mut x = dflat_model::spatial::SpatialState::from([
            1.0, 0.5, -2.0, 0.2, -3.0, -0.1, 0.05, -0.03, 9.81,
        ]);
        let us = [
            Vector3::new(0.1, -0.05, 8.0),
            Vector3::new(0.12, -0.02, 8.3),
            Vector3::new(0.08, 0.01, 7.9),
            Vector3::new(0.05, 0.03, 8.1),
        ];
        let mut y = Vec::new();
        for u in &us {
            y.push(sm.output(&x));
            x = step(&x, u);
        }
        y.push(sm.output(&x));
        let y3 = m
            .next_output_disturbed(&[y[0], y[1], y[2]], &us[0], &d)
            .unwrap();
        assert!((y3 - y[3]).norm() < 1e-12, "{y3} vs {}", y[3]);
        let u = m
            .input_from_outputs_disturbed(&[y[1], y[2], y[3], y[4]], &d)
            .unwrap();
        assert!((u - us[1]).norm() < 1e-7, "{u} vs {}", us[1]);
        // The nominal estimate is the plain map, bit for bit.
        let n = DisturbanceEstimate::NOMINAL;
        assert_eq!(
            m.next_output_disturbed(&[y[0], y[1], y[2]], &us[0], &n),
            m.next_output(&[y[0], y[1], y[2]], &us[0])
        );
    }

    #[test]
    fn nan_is_an_error() {
        let m = planar();
        let y = [Vector3::new(f64::NAN, 0.0, 0.0); 3];
        assert!(m.next_output(&y, &Vector3::zeros()).is_err());
    }
}
