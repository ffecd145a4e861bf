//! Test fixtures: a PD controller on the measured position and a fixed
//! reference, standing in for dflat-control's controllers.

#![allow(dead_code)]

use std::sync::Arc;

use dflat_control::{
    AttitudeCommand, ControlError, Controller, Measurement, ReferenceSource, TickOutput,
};
use dflat_lab::harness::{ControllerFactory, ReferenceFactory};
use nalgebra::Vector3;

/// Gravity [m/s²].
pub const G: f64 = 9.81;

/// A fixed reference point (local NED \[m\]).
#[derive(Debug, Clone, Copy)]
pub struct FixedRef(pub Vector3<f64>);

impl ReferenceSource for FixedRef {
    fn horizon(&mut self, _measured: &Vector3<f64>, _dt: f64, out: &mut [Vector3<f64>]) {
        out.fill(self.0);
    }
    fn closest(&mut self, _measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        (self.0, Vector3::zeros())
    }
}

/// PD on the measured position, velocity from the first difference of
/// measurements, mapped to NED pitch/roll/thrust at ψ = 0.
#[derive(Debug, Clone)]
pub struct TestPd {
    pub kp: f64,
    pub kd: f64,
    pub max_tilt: f64,
    prev: Option<Measurement>,
}

impl TestPd {
    pub fn new(kp: f64, kd: f64) -> Self {
        Self {
            kp,
            kd,
            max_tilt: 0.5,
            prev: None,
        }
    }
}

impl Controller for TestPd {
    fn name(&self) -> &'static str {
        "pd"
    }

    fn update(
        &mut self,
        m: &Measurement,
        reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        if !m.position.iter().all(|v| v.is_finite()) {
            return Err(ControlError::NonFiniteMeasurement);
        }
        let mut r = [Vector3::zeros(); 1];
        reference.horizon(&m.position, 0.02, &mut r);
        let v = match self.prev {
            Some(p) if m.t > p.t => (m.position - p.position) / (m.t - p.t),
            _ => Vector3::zeros(),
        };
        self.prev = Some(*m);
        let a = (r[0] - m.position) * self.kp - v * self.kd;
        let pitch_raw = -(a.x / G).atan();
        let pitch = pitch_raw.clamp(-self.max_tilt, self.max_tilt);
        let roll_raw = (a.y * pitch.cos() / G).atan();
        let roll = roll_raw.clamp(-self.max_tilt, self.max_tilt);
        let thrust = (G - a.z) / (pitch.cos() * roll.cos());
        Ok(TickOutput {
            command: AttitudeCommand {
                pitch,
                roll,
                yaw: 0.0,
                thrust,
            },
            plan: [m.position; 4],
            reference: r[0],
            saturated: pitch != pitch_raw || roll != roll_raw,
            constrained: false,
            qp_fallback: false,
            cone_interior_point: false,
        })
    }

    fn reset(&mut self) {
        self.prev = None;
    }
}

/// Fails every `every`-th update (k = every−1, 2·every−1, …), else delegates.
pub struct Flaky {
    pub inner: TestPd,
    pub every: usize,
    pub count: usize,
}

impl Controller for Flaky {
    fn name(&self) -> &'static str {
        "flaky"
    }
    fn update(
        &mut self,
        m: &Measurement,
        reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        self.count += 1;
        if self.count.is_multiple_of(self.every) {
            return Err(ControlError::NotPositiveDefinite);
        }
        self.inner.update(m, reference)
    }
    fn reset(&mut self) {
        self.count = 0;
        self.inner.reset();
    }
}

/// Always commands a fixed attitude (for divergence and saturation tests).
pub struct Constant(pub AttitudeCommand);

impl Controller for Constant {
    fn name(&self) -> &'static str {
        "constant"
    }
    fn update(
        &mut self,
        m: &Measurement,
        _reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        Ok(TickOutput {
            command: self.0,
            plan: [m.position; 4],
            reference: m.position,
            saturated: false,
            constrained: false,
            qp_fallback: false,
            cone_interior_point: false,
        })
    }
    fn reset(&mut self) {}
}

pub fn pd_factory(kp: f64, kd: f64) -> ControllerFactory {
    Arc::new(move || Box::new(TestPd::new(kp, kd)))
}

pub fn fixed_ref(p: Vector3<f64>) -> ReferenceFactory {
    Arc::new(move || Box::new(FixedRef(p)))
}

/// Asserts |a − b| ≤ tol with a message.
#[track_caller]
pub fn close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b} (tol {tol})");
}
