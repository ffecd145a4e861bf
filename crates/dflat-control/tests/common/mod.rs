//! Fixtures shared by the closed-loop tests: the control step, a constant
//! setpoint, deterministic noise, the planar model in NED, the planar
//! closed loop on the model's own Euler step and an Euler simulation of the
//! spatial model written from its equations.

#![allow(dead_code)] // each test binary uses a subset

use dflat_control::{ControlError, Controller, Measurement, ReferenceSource, TickOutput};
use dflat_model::attitude::thrust_axis;
use dflat_model::planar::{PlanarInput, PlanarState};
use dflat_model::{FlatModel, Frame, PlanarModel, PlanarParams, SpatialParams};
use nalgebra::Vector3;

/// Control step \[s\] (50 Hz).
pub const DT: f64 = 0.02;
/// Gravity \[m/s²\].
pub const G: f64 = 9.81;

/// A constant setpoint (local frame \[m\]), held over the whole horizon.
pub struct Setpoint(pub Vector3<f64>);

impl ReferenceSource for Setpoint {
    fn horizon(&mut self, _measured: &Vector3<f64>, _dt: f64, out: &mut [Vector3<f64>]) {
        out.fill(self.0);
    }
    fn closest(&mut self, _measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        (self.0, Vector3::zeros())
    }
}

/// Deterministic noise from a 64-bit LCG, no dependency; the seed is the
/// state.
pub struct Noise(pub u64);

impl Noise {
    /// Uniform on \[0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard-normal-ish: the sum of twelve uniforms less six.
    pub fn normal(&mut self) -> f64 {
        (0..12).map(|_| self.uniform()).sum::<f64>() - 6.0
    }
}

/// The planar model in NED at yaw `psi` \[rad\], default parameters.
pub fn planar_ned(psi: f64) -> PlanarModel {
    PlanarModel::new(PlanarParams {
        psi,
        frame: Frame::Ned,
        ..Default::default()
    })
    .unwrap()
}

/// The largest command angle the default controllers send \[rad\] (35°),
/// with rounding.
fn within_default_tilt(angle: f64) -> bool {
    angle.abs() <= 35f64.to_radians() + 1e-12
}

/// Runs `ticks` ticks of `ctrl` on the planar model's own Euler step from
/// `x0` at z = −10 m, measured at the model's yaw; checks every command is
/// finite and within 35° per axis and hands each tick to `check`; returns
/// the positions after each step.
pub fn run_planar(
    model: &PlanarModel,
    ctrl: &mut dyn Controller,
    reference: &mut dyn ReferenceSource,
    x0: PlanarState,
    ticks: usize,
    mut check: impl FnMut(&Measurement, &TickOutput),
) -> Vec<Vector3<f64>> {
    let mut x = x0;
    let mut out = Vec::with_capacity(ticks);
    for k in 0..ticks {
        let m = Measurement {
            t: k as f64 * DT,
            position: Vector3::new(x[0], x[2], -10.0),
            yaw: model.params().psi,
        };
        let tick = ctrl.update(&m, reference).unwrap();
        assert!(tick.command.is_finite());
        assert!(within_default_tilt(tick.command.pitch));
        assert!(within_default_tilt(tick.command.roll));
        check(&m, &tick);
        x = model.step(&x, &PlanarInput::new(tick.command.pitch, tick.command.roll));
        out.push(Vector3::new(x[0], x[2], -10.0));
    }
    out
}

/// The field an `InvalidSetting` names; panics on any other error.
pub fn field_of(e: ControlError) -> &'static str {
    match e {
        ControlError::InvalidSetting { field, .. } => field,
        other => panic!("expected InvalidSetting, got {other:?}"),
    }
}

/// Euler simulation of the spatial model's dynamics (state p, v, θ, φ, T),
/// written from its documented equations so a test does not depend on
/// `SpatialModel::step`.
pub struct SpatialSim {
    /// The model's parameters.
    pub p: SpatialParams,
    /// Position \[m\], in the parameters' frame.
    pub pos: Vector3<f64>,
    /// Velocity \[m/s\].
    pub vel: Vector3<f64>,
    /// Pitch \[rad\].
    pub theta: f64,
    /// Roll \[rad\].
    pub phi: f64,
    /// Thrust \[m/s²\].
    pub thrust: f64,
}

impl SpatialSim {
    /// At rest at `pos` with hover thrust, level.
    pub fn at_rest(p: SpatialParams, pos: Vector3<f64>) -> Self {
        Self {
            p,
            pos,
            vel: Vector3::zeros(),
            theta: 0.0,
            phi: 0.0,
            thrust: p.g,
        }
    }

    /// One Euler step under the commands (pitch, roll \[rad\], thrust \[m/s²\]).
    pub fn step(&mut self, theta_cmd: f64, phi_cmd: f64, thrust_cmd: f64) {
        let p = &self.p;
        let axis = thrust_axis(self.theta, self.phi, p.psi);
        let a = p.frame.acceleration(axis.map(|c| c * self.thrust), p.g);
        self.pos += self.vel * p.dt;
        self.vel += Vector3::from(a) * p.dt;
        self.theta += p.dt * (p.k * theta_cmd - self.theta) / p.tau;
        self.phi += p.dt * (p.k * phi_cmd - self.phi) / p.tau;
        self.thrust += p.dt * (thrust_cmd - self.thrust) / p.tau_thrust;
    }
}
pub mod timing;
