//! The rigid-body plant: 12 states plus an inner attitude autopilot.

use std::f64::consts::PI;

use dflat_control::AttitudeCommand;
use nalgebra::{SVector, Vector3};

use super::shell::{Shell, shell_plant_methods};
use super::{Plant, PlantKind, PlantOptions, PlantState, thrust_axis};
use crate::SimError;

/// Length of the state vector: 12 rigid-body states + thrust + 3 rate
/// integrators + 3 derivative-filter states.
const N: usize = 19;

/// A multirotor rigid body (paper §IV-A, continuous time) with the
/// autopilot of [`super::RigidBodyOptions`] closing attitude and rate loops.
///
/// State vector (length 19):
/// `[x, ẋ, y, ẏ, z, ż, θ, φ, ψ, p, q, r]` (NED m, m/s, ZYX rad, FRD rad/s —
/// the paper's order), then the actual specific thrust T [m/s²], the three
/// rate integrators \[rad\], the three rate-filter states [rad/s].
///
/// ```text
/// v̇ = g·e3 − T·R·e3 + a_aero(v − w)              (super::aero_acceleration)
/// [φ̇, θ̇, ψ̇] = W(φ, θ)⁻¹·[p, q, r]                   (ZYX kinematics)
/// J_true·ω̇ = J_nom·α − ω × J_true·ω                  (α from the rate PID)
/// Ṫ = (k_T·T_cmd − T)/τ_T,  k_T = thrust_gain / mass_factor
/// ```
///
/// Pitch and roll setpoints are `k̃ ·` the (saturated) commands; yaw tracks
/// the yaw command (error wrapped to (−π, π]).
#[derive(Debug, Clone)]
pub struct RigidBodyPlant {
    /// The state vector and the common bookkeeping (the heading is `x[8]`:
    /// the shell's yaw and reference yaw play no part).
    shell: Shell<N>,
}

/// Wraps an angle to (−π, π].
fn wrap(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI { w + 2.0 * PI } else { w }
}

impl RigidBodyPlant {
    /// A rigid-body plant at level hover at the origin; `seed` drives the gusts.
    pub fn new(options: PlantOptions, seed: u64) -> Result<Self, SimError> {
        let (shell, state) = Shell::new(options, seed)?;
        let mut plant = Self { shell };
        plant.reset(&state);
        Ok(plant)
    }

    fn derivative(s: &Shell<N>, x: &SVector<f64, N>, w: &Vector3<f64>) -> SVector<f64, N> {
        let o = &s.options;
        let rb = &o.rigid;
        let c = &s.held.command;
        let (theta, phi, psi) = (x[6], x[7], x[8]);
        let omega = Vector3::new(x[9], x[10], x[11]);
        let thrust = x[12];
        let integ = Vector3::new(x[13], x[14], x[15]);
        let filt = Vector3::new(x[16], x[17], x[18]);

        // Translation.
        let v = Vector3::new(x[1], x[3], x[5]);
        let axis = thrust_axis(phi, theta, psi);
        let a = Vector3::new(0.0, 0.0, o.g) - axis * thrust
            + super::aero_acceleration(o, &(v - w), &axis);

        // ZYX kinematics: Euler rates from body rates.
        let (sp, cp) = phi.sin_cos();
        let (st, ct) = theta.sin_cos();
        let tt = st / ct;
        let phi_dot = omega.x + (omega.y * sp + omega.z * cp) * tt;
        let theta_dot = omega.y * cp - omega.z * sp;
        let psi_dot = (omega.y * sp + omega.z * cp) / ct;

        // Autopilot: attitude P on Euler errors, mapped to body-rate setpoints.
        let e = Vector3::new(
            o.attitude_gain * c.roll - phi,
            o.attitude_gain * c.pitch - theta,
            wrap(c.yaw - psi),
        );
        let eta_dot_sp = Vector3::from(rb.att_p).component_mul(&e);
        let omega_sp = Vector3::new(
            eta_dot_sp.x - st * eta_dot_sp.z,
            cp * eta_dot_sp.y + sp * ct * eta_dot_sp.z,
            -sp * eta_dot_sp.y + cp * ct * eta_dot_sp.z,
        );
        // The autopilot's rate limits (0: none).
        let omega_sp = Vector3::from_fn(|i, _| {
            let m = rb.max_rate[i];
            if m > 0.0 {
                omega_sp[i].clamp(-m, m)
            } else {
                omega_sp[i]
            }
        });
        // Rate PID (derivative on the filtered measured rate).
        let e_omega = omega_sp - omega;
        let omega_dot_f = (omega - filt) * rb.d_filter;
        let i_term_raw = Vector3::from(rb.rate_i).component_mul(&integ);
        let i_term = i_term_raw.map(|v| v.clamp(-rb.i_limit, rb.i_limit));
        let alpha = Vector3::from(rb.rate_p).component_mul(&e_omega) + i_term
            - Vector3::from(rb.rate_d).component_mul(&omega_dot_f);
        // Conditional integration: stop integrating further into the clamp.
        let integ_dot = Vector3::from_fn(|i, _| {
            let at_limit = i_term_raw[i].abs() >= rb.i_limit && i_term_raw[i] * e_omega[i] > 0.0;
            if at_limit { 0.0 } else { e_omega[i] }
        });

        // Rigid-body rotation with the true inertia.
        let j_nom = Vector3::from(rb.inertia);
        let j_true = j_nom * rb.inertia_factor;
        let torque = j_nom.component_mul(&alpha);
        let gyro = omega.cross(&j_true.component_mul(&omega));
        let omega_dot = (torque - gyro).component_div(&j_true);

        let k_t = o.thrust_gain / o.mass_factor;
        let mut d = SVector::<f64, N>::zeros();
        d[0] = x[1];
        d[1] = a.x;
        d[2] = x[3];
        d[3] = a.y;
        d[4] = x[5];
        d[5] = a.z;
        d[6] = theta_dot;
        d[7] = phi_dot;
        d[8] = psi_dot;
        d[9] = omega_dot.x;
        d[10] = omega_dot.y;
        d[11] = omega_dot.z;
        d[12] = (k_t * c.thrust - thrust) / o.thrust_tau;
        d[13] = integ_dot.x;
        d[14] = integ_dot.y;
        d[15] = integ_dot.z;
        d[16] = omega_dot_f.x;
        d[17] = omega_dot_f.y;
        d[18] = omega_dot_f.z;
        d
    }

    /// Nominal mass \[kg\] (the autopilot's); the true mass is this times
    /// [`PlantOptions::mass_factor`].
    pub fn nominal_mass(&self) -> f64 {
        self.shell.options.rigid.mass
    }
}

impl Plant for RigidBodyPlant {
    fn kind(&self) -> PlantKind {
        PlantKind::RigidBody
    }

    fn reset(&mut self, s: &PlantState) {
        let mut x = SVector::<f64, N>::zeros();
        x[0] = s.position.x;
        x[1] = s.velocity.x;
        x[2] = s.position.y;
        x[3] = s.velocity.y;
        x[4] = s.position.z;
        x[5] = s.velocity.z;
        x[6] = s.pitch;
        x[7] = s.roll;
        x[8] = s.yaw;
        x[9] = s.body_rates.x;
        x[10] = s.body_rates.y;
        x[11] = s.body_rates.z;
        x[12] = s.thrust;
        x[16] = s.body_rates.x;
        x[17] = s.body_rates.y;
        x[18] = s.body_rates.z;
        self.shell.x = x;
        self.shell.restart(s);
    }

    fn apply(&mut self, command: &AttitudeCommand) {
        self.shell.held.apply(&self.shell.options, command);
    }

    fn advance(&mut self, dt: f64) {
        self.shell.advance(dt, false, Self::derivative);
    }

    fn position(&self) -> Vector3<f64> {
        self.shell.position()
    }

    fn velocity(&self) -> Vector3<f64> {
        self.shell.velocity()
    }

    fn attitude(&self) -> (f64, f64, f64) {
        let x = &self.shell.x;
        (x[7], x[6], x[8])
    }

    fn true_state(&self) -> PlantState {
        let x = &self.shell.x;
        PlantState {
            position: self.position(),
            velocity: self.velocity(),
            roll: x[7],
            pitch: x[6],
            yaw: x[8],
            body_rates: Vector3::new(x[9], x[10], x[11]),
            thrust: x[12],
        }
    }

    shell_plant_methods!();
}

#[cfg(test)]
mod tests {
    use super::wrap;
    use std::f64::consts::PI;

    #[test]
    fn wrap_is_half_open() {
        assert!((wrap(PI) - PI).abs() < 1e-15);
        assert!((wrap(-PI) - PI).abs() < 1e-15);
        assert!((wrap(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap(0.3) - 0.3).abs() < 1e-15);
    }
}
