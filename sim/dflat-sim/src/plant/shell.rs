//! What the plants share around their own dynamics: options, the heading
//! loop's state, time, the held command, the wind and the integration loop.

use nalgebra::{SVector, Vector3};

use super::{HeldCommand, Plant, PlantOptions, PlantState, Wind, integrate};
use crate::SimError;

/// A plant's state vector `x` and the bookkeeping every plant keeps with it.
#[derive(Debug, Clone)]
pub(super) struct Shell<const D: usize> {
    pub(super) options: PlantOptions,
    pub(super) x: SVector<f64, D>,
    /// Heading \[rad\] (the first-order plants' yaw loop).
    pub(super) yaw: f64,
    /// The heading θ and φ are kept at (the reset heading) \[rad\].
    pub(super) yaw_ref: f64,
    pub(super) t: f64,
    pub(super) held: HeldCommand,
    pub(super) wind: Wind,
}

impl<const D: usize> Shell<D> {
    /// Validated options, zero state, the gusts seeded by `seed`; and the
    /// level hover at the origin the plant is to be reset to.
    pub(super) fn new(options: PlantOptions, seed: u64) -> Result<(Self, PlantState), SimError> {
        options.validate()?;
        let wind = Wind::new(options.wind, options.gust_std, options.gust_tau, seed);
        let state = PlantState::hover(Vector3::zeros(), options.g);
        let shell = Self {
            held: HeldCommand::steady(&options, &state),
            options,
            x: SVector::zeros(),
            yaw: 0.0,
            yaw_ref: 0.0,
            t: 0.0,
            wind,
        };
        Ok((shell, state))
    }

    /// Resets all but `x`: heading (and reference heading) from `s`, time,
    /// the command steady at `s`, the gusts.
    pub(super) fn restart(&mut self, s: &PlantState) {
        self.yaw = s.yaw;
        self.yaw_ref = s.yaw;
        self.t = 0.0;
        self.held = HeldCommand::steady(&self.options, s);
        self.wind.restart();
    }

    /// Integrates `derivative` over `dt` in the options' substeps, the wind
    /// held over each; `yaw_loop`: the heading follows the yaw command.
    pub(super) fn advance(
        &mut self,
        dt: f64,
        yaw_loop: bool,
        derivative: impl Fn(&Self, &SVector<f64, D>, &Vector3<f64>) -> SVector<f64, D>,
    ) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let (n, h) = self.options.substeps(dt);
        for _ in 0..n {
            let w = self.wind.velocity();
            self.x = integrate(self.options.integrator, &self.x, h, |x| {
                derivative(self, x, &w)
            });
            if yaw_loop {
                self.yaw = super::yaw::step_yaw(&self.options, self.yaw, self.held.command.yaw, h);
            }
            self.wind.step(h);
            self.t += h;
        }
    }
}

impl<const D: usize> Shell<D> {
    /// Pitch and roll \[rad\] at the actual heading of a first-order plant
    /// keeping θ at `x[pitch]` and φ at `x[pitch + 1]` (at the reset heading).
    pub(super) fn body_tilt(&self, pitch: usize) -> (f64, f64) {
        super::yaw::tilt_between(self.x[pitch], self.x[pitch + 1], self.yaw_ref, self.yaw)
    }

    /// A first-order `plant`'s true state at its position and velocity and
    /// actual `thrust`: θ at `x[pitch]`, φ at `x[pitch + 1]`, the body rates
    /// those of its attitude and yaw loops (`derivative` the dynamics).
    pub(super) fn loop_state(
        &self,
        plant: &impl Plant,
        pitch: usize,
        thrust: f64,
        derivative: impl Fn(&Self, &SVector<f64, D>, &Vector3<f64>) -> SVector<f64, D>,
    ) -> PlantState {
        let (pitch_angle, roll) = self.body_tilt(pitch);
        let d = derivative(self, &self.x, &self.wind.velocity());
        PlantState {
            position: plant.position(),
            velocity: plant.velocity(),
            roll,
            pitch: pitch_angle,
            yaw: self.yaw,
            body_rates: super::body_rates_from_euler_rates(
                self.x[pitch + 1],
                self.x[pitch],
                d[pitch + 1],
                d[pitch],
                super::yaw::yaw_rate(&self.options, self.yaw, self.held.command.yaw),
            ),
            thrust,
        }
    }
}

impl<const D: usize> Shell<D> {
    /// Position, local NED \[m\], of a plant whose state starts
    /// `[x, ẋ, y, ẏ, z, ż, …]`.
    pub(super) fn position(&self) -> Vector3<f64> {
        Vector3::new(self.x[0], self.x[2], self.x[4])
    }

    /// Velocity, local NED [m/s], of a plant whose state starts
    /// `[x, ẋ, y, ẏ, z, ż, …]`.
    pub(super) fn velocity(&self) -> Vector3<f64> {
        Vector3::new(self.x[1], self.x[3], self.x[5])
    }
}

/// The [`super::Plant`] methods a plant with a `shell: Shell<_>` field
/// answers from it alone.
macro_rules! shell_plant_methods {
    () => {
        fn state_vector(&self) -> Vec<f64> {
            self.shell.x.iter().copied().collect()
        }

        fn time(&self) -> f64 {
            self.shell.t
        }

        fn applied_command(&self) -> AttitudeCommand {
            self.shell.held.command
        }

        fn saturated(&self) -> bool {
            self.shell.held.saturated
        }

        fn wind(&self) -> Vector3<f64> {
            self.shell.wind.velocity()
        }
    };
}
pub(super) use shell_plant_methods;
