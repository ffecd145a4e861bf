//! The planar plant (paper §IV-B) with continuous-time dynamics.

use dflat_control::AttitudeCommand;
use nalgebra::{SVector, Vector3};

use super::shell::{Shell, shell_plant_methods};
use super::{Plant, PlantKind, PlantOptions, PlantState, level_flight_acceleration, thrust_axis};
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
    /// State `[x, ẋ, y, ẏ, θ, φ]` and the common bookkeeping.
    shell: Shell<6>,
    z: f64,
}

impl PlanarPlant {
    /// A planar plant at level hover at the origin; `seed` drives the gusts.
    pub fn new(options: PlantOptions, seed: u64) -> Result<Self, SimError> {
        let (shell, state) = Shell::new(options, seed)?;
        let mut plant = Self { shell, z: 0.0 };
        plant.reset(&state);
        Ok(plant)
    }

    fn derivative(s: &Shell<6>, x: &SVector<f64, 6>, w: &Vector3<f64>) -> SVector<f64, 6> {
        let o = &s.options;
        let (ax, ay) = level_flight_acceleration(o.g, x[5], x[4], s.yaw_ref);
        let c = &s.held.command;
        let (cp, cr) = super::yaw::command_tilt(o, c, s.yaw, s.yaw_ref);
        let air = Vector3::new(x[1] - w.x, x[3] - w.y, 0.0);
        let aero = super::aero_acceleration(o, &air, &thrust_axis(x[5], x[4], s.yaw_ref));
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
        self.shell.x = SVector::from([
            state.position.x,
            state.velocity.x,
            state.position.y,
            state.velocity.y,
            state.pitch,
            state.roll,
        ]);
        self.z = state.position.z;
        let mut s = *state;
        s.thrust = self.shell.options.g;
        self.shell.restart(&s);
    }

    fn apply(&mut self, command: &AttitudeCommand) {
        // Altitude is held by the autopilot: the thrust command plays no
        // part (neither in the dynamics nor in the saturation flag).
        let o = &self.shell.options;
        let hover = o.thrust_command_for(o.g);
        self.shell.held.apply(
            o,
            &AttitudeCommand {
                thrust: hover,
                ..*command
            },
        );
    }

    fn advance(&mut self, dt: f64) {
        self.shell.advance(dt, true, Self::derivative);
    }

    fn position(&self) -> Vector3<f64> {
        Vector3::new(self.shell.x[0], self.shell.x[2], self.z)
    }

    fn velocity(&self) -> Vector3<f64> {
        Vector3::new(self.shell.x[1], self.shell.x[3], 0.0)
    }

    fn attitude(&self) -> (f64, f64, f64) {
        let (pitch, roll) = self.shell.body_tilt(4);
        (roll, pitch, self.shell.yaw)
    }

    fn true_state(&self) -> PlantState {
        let sh = &self.shell;
        let thrust = sh.options.g / (sh.x[4].cos() * sh.x[5].cos());
        sh.loop_state(self, 4, thrust, Self::derivative)
    }

    shell_plant_methods!();
}
