//! Standby: the autopilot flies its own commands (a pilot in position
//! mode) while DF-MPC runs and streams commands nobody applies. With
//! [`Controller::correct_last_input`] fed the input that explains the
//! measured attitude ([`ControlModel::input_from_attitude`]) the window
//! stays true — the one-step prediction matches the plant exactly, classic
//! and multi-rate — and at engagement the first command continues from the
//! vehicle's attitude. Without it the window holds commands that were never
//! flown (negative control). Plant = model, planar, 50 Hz, NED, yaw 0.3.

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::window::MultiRateSettings;
use dflat_control::{ControlModel, Controller, Frame, Measurement, ReferenceSource};
use dflat_model::{FlatModel, PlanarModel, PlanarParams};
use nalgebra::SVector;
use nalgebra::{Vector2, Vector3};
use proptest::prelude::*;

const DT: f64 = 0.02;
const Z: f64 = -2.0;
const PSI: f64 = 0.3;

/// Hold wherever the vehicle is (the standby reference follows it).
struct FollowVehicle;

impl ReferenceSource for FollowVehicle {
    fn horizon(&mut self, measured: &Vector3<f64>, _dt: f64, out: &mut [Vector3<f64>]) {
        out.iter_mut().for_each(|o| *o = *measured);
    }
    fn closest(&mut self, measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        (*measured, Vector3::zeros())
    }
}

fn plant() -> PlanarModel {
    PlanarModel::new(PlanarParams {
        psi: PSI,
        frame: Frame::Ned,
        ..Default::default()
    })
    .unwrap()
}

/// The pilot's attitude commands (pitch, roll) \[rad\] at tick k: a push
/// north-east, then a brake — nothing the controller would command.
fn pilot(k: usize) -> Vector2<f64> {
    let t = k as f64 * DT;
    if t < 1.0 {
        Vector2::new(-0.15 * (3.0 * t).sin(), 0.1)
    } else {
        Vector2::new(0.08, -0.05 * (2.0 * t).cos())
    }
}

struct Flight {
    /// Largest error of the two-step prediction `plan[2]` (F⁻¹ through the
    /// input of the tick before) on standby ticks after the window has
    /// filled \[m\].
    standby_prediction: f64,
    /// Largest change between the vehicle's attitude and the commanded
    /// one at the first engaged tick \[rad\].
    first_step: f64,
}

/// Standby for 90 ticks (the pilot flies), then engaged for 10.
fn fly(multi_rate: bool, correct: bool) -> Flight {
    let plant = plant();
    let model = ControlModel::Planar(plant);
    let settings = DfMpcSettings {
        smoothness_weight: [50.0, 50.0, 0.0],
        multi_rate: multi_rate.then(MultiRateSettings::default),
        ..DfMpcSettings::default()
    };
    let mut ctrl = DfMpc::new(model, settings).unwrap();
    let mut x = SVector::<f64, 6>::zeros();
    // plan[2] of the tick before and of this tick.
    let mut predicted: [Option<Vector3<f64>>; 2] = [None, None];
    let mut standby_prediction = 0.0f64;
    let mut first_step = 0.0;
    let mut attitude_before: Option<[f64; 2]> = None;
    for k in 0..100 {
        let engaged = k >= 90;
        let y = plant.output(&x);
        let position = Vector3::new(y.x, y.y, Z);
        let attitude = [x[4], x[5]];
        if let Some(p) = predicted[0]
            && (40..90).contains(&k)
        {
            standby_prediction = standby_prediction.max((p - position).xy().norm());
        }
        // The tick before was standby: its input was the pilot's.
        if correct && let Some(before) = attitude_before.take() {
            let u = model.input_from_attitude(before, attitude);
            ctrl.correct_last_input(&Vector3::new(u[0], u[1], 0.0));
        }
        let m = Measurement {
            t: k as f64 * DT,
            position,
            yaw: PSI,
        };
        if multi_rate {
            ctrl.observe(&m);
        }
        let out = ctrl.update(&m, &mut FollowVehicle).unwrap();
        predicted = [predicted[1], Some(out.plan[2])];
        let command = Vector2::new(out.command.pitch, out.command.roll);
        let applied = if engaged {
            if k == 90 {
                first_step = (command - Vector2::new(attitude[0], attitude[1])).norm();
            }
            command
        } else {
            attitude_before = Some(attitude);
            pilot(k)
        };
        x = plant.step(&x, &applied);
    }
    Flight {
        standby_prediction,
        first_step,
    }
}

#[test]
fn corrected_inputs_keep_the_classic_window_true_in_standby() {
    let corrected = fly(false, true);
    assert!(
        corrected.standby_prediction < 1e-9,
        "prediction error {} m",
        corrected.standby_prediction
    );
    let untold = fly(false, false);
    // The classic window's prediction reaches only two ticks ahead, so an
    // input that was never flown moves it by less than a millimetre per
    // tick — still ten orders of magnitude above rounding.
    assert!(
        untold.standby_prediction > 1e-4,
        "negative control: prediction error {} m",
        untold.standby_prediction
    );
    eprintln!(
        "classic: prediction {:.2e} vs {:.2e} m; first engaged step {:.2}° vs {:.2}°",
        corrected.standby_prediction,
        untold.standby_prediction,
        corrected.first_step.to_degrees(),
        untold.first_step.to_degrees()
    );
}

#[test]
fn corrected_inputs_keep_the_multi_rate_window_true_in_standby() {
    let corrected = fly(true, true);
    let untold = fly(true, false);
    eprintln!(
        "multi-rate: prediction {:.2e} vs {:.2e} m; first engaged step {:.2}° vs {:.2}°",
        corrected.standby_prediction,
        untold.standby_prediction,
        corrected.first_step.to_degrees(),
        untold.first_step.to_degrees()
    );
    // The multi-rate window fits noisy samples: exact to the fit's
    // tolerance, not to rounding.
    assert!(
        corrected.standby_prediction < 1e-6,
        "prediction error {} m",
        corrected.standby_prediction
    );
    assert!(
        untold.standby_prediction > 100.0 * corrected.standby_prediction.max(1e-6),
        "negative control: prediction error {} m",
        untold.standby_prediction
    );
}

proptest! {
    /// `input_from_attitude` inverts the model's attitude step.
    #[test]
    fn input_from_attitude_inverts_the_attitude_step(
        theta in -0.6f64..0.6, phi in -0.6f64..0.6,
        ut in -0.6f64..0.6, up in -0.6f64..0.6,
        tau in 0.05f64..0.5, k in 0.5f64..1.5,
    ) {
        let model = ControlModel::Planar(PlanarModel::new(PlanarParams {
            tau, k, psi: PSI, frame: Frame::Ned, ..Default::default()
        }).unwrap());
        let s = Vector3::new(theta, phi, 0.0);
        let u = Vector3::new(ut, up, 0.0);
        let next = model.input_state_step(&s, &u);
        let back = model.input_from_attitude([theta, phi], [next.x, next.y]);
        prop_assert!((back[0] - ut).abs() < 1e-9 && (back[1] - up).abs() < 1e-9);
    }
}
