//! The spatial plant: planar attitude plus altitude through collective thrust.

use dflat_control::AttitudeCommand;
use nalgebra::{SVector, Vector3};

use super::{
    HeldCommand, Plant, PlantKind, PlantOptions, PlantState, Wind, integrate, thrust_axis,
};
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
    options: PlantOptions,
    x: SVector<f64, 9>,
    yaw: f64,
    /// The heading θ and φ are kept at (the reset heading) \[rad\].
    yaw_ref: f64,
    t: f64,
    held: HeldCommand,
    wind: Wind,
}

impl SpatialPlant {
    /// A spatial plant at level hover at the origin; `seed` drives the gusts.
    pub fn new(options: PlantOptions, seed: u64) -> Result<Self, SimError> {
        options.validate()?;
        let wind = Wind::new(options.wind, options.gust_std, options.gust_tau, seed);
        let state = PlantState::hover(Vector3::zeros(), options.g);
        let mut plant = Self {
            held: HeldCommand::steady(&options, &state),
            options,
            x: SVector::zeros(),
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
        super::yaw::tilt_between(self.x[6], self.x[7], self.yaw_ref, self.yaw)
    }

    fn derivative(&self, x: &SVector<f64, 9>, w: &Vector3<f64>) -> SVector<f64, 9> {
        let o = &self.options;
        let c = &self.held.command;
        let axis = thrust_axis(x[7], x[6], self.yaw_ref);
        let (cp, cr) = super::yaw::command_tilt(o, c, self.yaw, self.yaw_ref);
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
        self.x = SVector::from([
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
        self.yaw = s.yaw;
        self.yaw_ref = s.yaw;
        self.t = 0.0;
        self.held = HeldCommand::steady(&self.options, s);
        self.wind.restart();
    }

    fn apply(&mut self, command: &AttitudeCommand) {
        self.held.apply(&self.options, command);
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
        Vector3::new(self.x[0], self.x[2], self.x[4])
    }

    fn velocity(&self) -> Vector3<f64> {
        Vector3::new(self.x[1], self.x[3], self.x[5])
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
                    self.x[7],
                    self.x[6],
                    d[7],
                    d[6],
                    super::yaw::yaw_rate(&self.options, self.yaw, self.held.command.yaw),
                )
            },
            thrust: self.x[8],
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
