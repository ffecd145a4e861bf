//! The planar plant (paper §IV-B) with continuous-time dynamics.

use dflat_control::AttitudeCommand;
use nalgebra::{SVector, Vector3};

use super::{
    HeldCommand, Plant, PlantKind, PlantOptions, PlantState, Wind, integrate,
    level_flight_acceleration, thrust_axis,
};
use crate::SimError;

/// 2-D motion at constant altitude and yaw with first-order pitch and roll.
///
/// State vector `[x, ẋ, y, ẏ, θ, φ]` (NED m, m/s, rad):
///
/// ```text
/// ẍ = −g·R13/R33 + a_x,  ÿ = −g·R23/R33 + a_y
/// θ̇ = (k̃·θ_cmd − θ)/τ,            φ̇ = (k̃·φ_cmd − φ)/τ
/// ```
///
/// with `a` the horizontal part of [`super::aero_acceleration`] on the
/// horizontal air-relative velocity `(ẋ − w_x, ẏ − w_y, 0)` (linear,
/// quadratic and rotor drag).
/// Altitude stays at its reset value and the thrust command is ignored (the
/// autopilot holds altitude). The heading follows the yaw command through
/// the yaw loop of [`PlantOptions::max_yaw_rate`] (`plant/yaw.rs`; off by
/// default: the heading stays at its reset value); θ and φ are the tilt at
/// the reset heading (a world frame), tracking the command's thrust axis,
/// and are reported at the actual heading.
#[derive(Debug, Clone)]
pub struct PlanarPlant {
    options: PlantOptions,
    x: SVector<f64, 6>,
    z: f64,
    yaw: f64,
    /// The heading θ and φ are kept at (the reset heading) \[rad\].
    yaw_ref: f64,
    t: f64,
    held: HeldCommand,
    wind: Wind,
}

impl PlanarPlant {
    /// A planar plant at level hover at the origin; `seed` drives the gusts.
    pub fn new(options: PlantOptions, seed: u64) -> Result<Self, SimError> {
        options.validate()?;
        let wind = Wind::new(options.wind, options.gust_std, options.gust_tau, seed);
        let state = PlantState::hover(Vector3::zeros(), options.g);
        let mut plant = Self {
            held: HeldCommand::steady(&options, &state),
            options,
            x: SVector::zeros(),
            z: 0.0,
            yaw: 0.0,
            yaw_ref: 0.0,
            t: 0.0,
            wind,
        };
        plant.reset(&state);
        Ok(plant)
    }

    /// Pitch and roll \[rad\] at the actual heading.
    fn body_tilt(&self) -> (f64, f64) {
        super::yaw::tilt_between(self.x[4], self.x[5], self.yaw_ref, self.yaw)
    }

    fn derivative(&self, x: &SVector<f64, 6>, w: &Vector3<f64>) -> SVector<f64, 6> {
        let o = &self.options;
        let (ax, ay) = level_flight_acceleration(o.g, x[5], x[4], self.yaw_ref);
        let c = &self.held.command;
        let (cp, cr) = super::yaw::command_tilt(o, c, self.yaw, self.yaw_ref);
        let air = Vector3::new(x[1] - w.x, x[3] - w.y, 0.0);
        let aero = super::aero_acceleration(o, &air, &thrust_axis(x[5], x[4], self.yaw_ref));
        SVector::from([
            x[1],
            ax + aero.x,
            x[3],
            ay + aero.y,
            (o.attitude_gain * cp - x[4]) / o.attitude_tau,
            (o.attitude_gain * cr - x[5]) / o.attitude_tau,
        ])
    }
}

impl Plant for PlanarPlant {
    fn kind(&self) -> PlantKind {
        PlantKind::Planar
    }

    fn reset(&mut self, state: &PlantState) {
        self.x = SVector::from([
            state.position.x,
            state.velocity.x,
            state.position.y,
            state.velocity.y,
            state.pitch,
            state.roll,
        ]);
        self.z = state.position.z;
        self.yaw = state.yaw;
        self.yaw_ref = state.yaw;
        self.t = 0.0;
        let mut s = *state;
        s.thrust = self.options.g;
        self.held = HeldCommand::steady(&self.options, &s);
        self.wind.restart();
    }

    fn apply(&mut self, command: &AttitudeCommand) {
        // Altitude is held by the autopilot: the thrust command plays no
        // part (neither in the dynamics nor in the saturation flag).
        let hover = self.options.thrust_command_for(self.options.g);
        self.held.apply(
            &self.options,
            &AttitudeCommand {
                thrust: hover,
                ..*command
            },
        );
    }

    fn advance(&mut self, dt: f64) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let (n, h) = self.options.substeps(dt);
        for _ in 0..n {
            let w = self.wind.velocity();
            self.x = integrate(self.options.integrator, &self.x, h, |x| {
                self.derivative(x, &w)
            });
            self.yaw = super::yaw::step_yaw(&self.options, self.yaw, self.held.command.yaw, h);
            self.wind.step(h);
            self.t += h;
        }
    }

    fn position(&self) -> Vector3<f64> {
        Vector3::new(self.x[0], self.x[2], self.z)
    }

    fn velocity(&self) -> Vector3<f64> {
        Vector3::new(self.x[1], self.x[3], 0.0)
    }

    fn attitude(&self) -> (f64, f64, f64) {
        let (pitch, roll) = self.body_tilt();
        (roll, pitch, self.yaw)
    }

    fn true_state(&self) -> PlantState {
        let (pitch, roll) = self.body_tilt();
        PlantState {
            position: self.position(),
            velocity: self.velocity(),
            roll,
            pitch,
            yaw: self.yaw,
            body_rates: {
                // The first-order attitude and yaw loops' rates.
                let d = self.derivative(&self.x, &self.wind.velocity());
                super::body_rates_from_euler_rates(
                    self.x[5],
                    self.x[4],
                    d[5],
                    d[4],
                    super::yaw::yaw_rate(&self.options, self.yaw, self.held.command.yaw),
                )
            },
            thrust: self.options.g / (self.x[4].cos() * self.x[5].cos()),
        }
    }

    fn state_vector(&self) -> Vec<f64> {
        self.x.iter().copied().collect()
    }

    fn time(&self) -> f64 {
        self.t
    }

    fn applied_command(&self) -> AttitudeCommand {
        self.held.command
    }

    fn saturated(&self) -> bool {
        self.held.saturated
    }

    fn wind(&self) -> Vector3<f64> {
        self.wind.velocity()
    }
}
