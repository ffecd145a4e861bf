//! What the benches share: the planar plant they fly and the recording of
//! a closed-loop flight (`#[path]`-included by each bench that uses it).

#![allow(dead_code)]

use dflat_control::reference::Reference;
use dflat_control::{Controller, Frame, Measurement};
use dflat_model::{FlatModel, PlanarModel, PlanarParams};
use nalgebra::{SVector, Vector2, Vector3};

/// The controller's period \[s\].
pub const DT: f64 = 0.02;

/// The planar vehicle every bench flies (ψ = 0, NED).
pub fn plant() -> PlanarModel {
    PlanarModel::new(PlanarParams {
        psi: 0.0,
        frame: Frame::Ned,
        ..Default::default()
    })
    .unwrap()
}

/// `ticks` ticks of `ctrl` flying [`plant`] from rest along `reference`
/// at 2 m up (noise-free poses): the measurements it was given, for a
/// replay.
pub fn record(
    ctrl: &mut impl Controller,
    reference: &mut Reference,
    ticks: usize,
) -> Vec<Measurement> {
    let plant = plant();
    let mut x = SVector::<f64, 6>::zeros();
    let mut out = Vec::with_capacity(ticks);
    for k in 0..ticks {
        let y = plant.output(&x);
        let m = Measurement {
            t: k as f64 * DT,
            position: Vector3::new(y.x, y.y, -2.0),
            yaw: 0.0,
        };
        let c = ctrl.update(&m, reference).unwrap();
        x = plant.step(&x, &Vector2::new(c.command.pitch, c.command.roll));
        out.push(m);
    }
    out
}
