//! The spatial plant: planar attitude plus altitude through collective thrust.

use dflat_control::AttitudeCommand;
use nalgebra::{SVector, Vector3};

use super::shell::{Shell, shell_plant_methods};
use super::{Plant, PlantKind, PlantOptions, PlantState, thrust_axis};
use crate::SimError;

/// 3-D motion with first-order pitch/roll and first-order collective thrust,
/// fixed yaw.
///
/// State vector `[x, ẋ, y, ẏ, z, ż, θ, φ, T]` (NED m, m/s, rad, m/s²):
///
/// ```text
/// v̇ = g·e3 − T·R·e3 + a_aero(v − w)       (super::aero_acceleration)
/// θ̇ = (k̃·θ_cmd − θ)/τ,  φ̇ = (k̃·φ_cmd − φ)/τ
/// Ṫ = (k_T·T_cmd − T)/τ_T,  k_T = thrust_gain / mass_factor
/// ```
///
/// The heading follows the yaw command through the yaw loop of
/// [`PlantOptions::max_yaw_rate`] (`plant/yaw.rs`; off by default: the
/// heading stays at its reset value); θ and φ are the tilt at the reset
/// heading (a world frame), tracking the command's thrust axis, and are
/// reported at the actual heading.
#[derive(Debug, Clone)]
pub struct SpatialPlant {
    /// State `[x, ẋ, y, ẏ, z, ż, θ, φ, T]` and the common bookkeeping.
    shell: Shell<9>,
}

impl SpatialPlant {
    /// A spatial plant at level hover at the origin; `seed` drives the gusts.
    pub fn new(options: PlantOptions, seed: u64) -> Result<Self, SimError> {
        let (shell, state) = Shell::new(options, seed)?;
        let mut plant = Self { shell };
        plant.reset(&state);
        Ok(plant)
    }

    fn derivative(s: &Shell<9>, x: &SVector<f64, 9>, w: &Vector3<f64>) -> SVector<f64, 9> {
        let o = &s.options;
        let c = &s.held.command;
        let axis = thrust_axis(x[7], x[6], s.yaw_ref);
        let (cp, cr) = super::yaw::command_tilt(o, c, s.yaw, s.yaw_ref);
        let v = Vector3::new(x[1], x[3], x[5]);
        let a = Vector3::new(0.0, 0.0, o.g) - axis * x[8]
            + super::aero_acceleration(o, &(v - w), &axis);
        let k_t = o.thrust_gain / o.mass_factor;
        SVector::from([
            x[1],
            a.x,
            x[3],
            a.y,
            x[5],
            a.z,
            (o.attitude_gain * cp - x[6]) / o.attitude_tau,
            (o.attitude_gain * cr - x[7]) / o.attitude_tau,
            (k_t * c.thrust - x[8]) / o.thrust_tau,
        ])
    }
}

impl Plant for SpatialPlant {
    fn kind(&self) -> PlantKind {
        PlantKind::Spatial
    }

    fn reset(&mut self, s: &PlantState) {
        self.shell.x = SVector::from([
            s.position.x,
            s.velocity.x,
            s.position.y,
            s.velocity.y,
            s.position.z,
            s.velocity.z,
            s.pitch,
            s.roll,
            s.thrust,
        ]);
        self.shell.restart(s);
    }

    fn apply(&mut self, command: &AttitudeCommand) {
        self.shell.held.apply(&self.shell.options, command);
    }

    fn advance(&mut self, dt: f64) {
        self.shell.advance(dt, true, Self::derivative);
    }

    fn position(&self) -> Vector3<f64> {
        self.shell.position()
    }

    fn velocity(&self) -> Vector3<f64> {
        self.shell.velocity()
    }

    fn attitude(&self) -> (f64, f64, f64) {
        let (pitch, roll) = self.shell.body_tilt(6);
        (roll, pitch, self.shell.yaw)
    }

    fn true_state(&self) -> PlantState {
        let sh = &self.shell;
        let thrust = sh.x[8];
        sh.loop_state(self, 6, thrust, Self::derivative)
    }

    shell_plant_methods!();
}
