//! Flatness MPC in closed loop on the models' own dynamics, plus its error
//! handling and settings validation.

use dflat_control::fmpc::{FlatnessMpc, FmpcSettings};
use dflat_control::reference::{Reference, paths};
use dflat_control::{ControlError, ControlModel, Controller, Frame, Measurement, ReferenceSource};
use dflat_model::planar::PlanarState;
use dflat_model::{SpatialModel, SpatialParams};
use nalgebra::Vector3;

mod common;
use common::{DT, SpatialSim, field_of, planar_ned, run_planar};

#[test]
fn fmpc_planar_ned_reaches_and_holds_10_m_setpoint() {
    let model = planar_ned(0.7);
    let mut fmpc = FlatnessMpc::new(ControlModel::Planar(model), FmpcSettings::default()).unwrap();
    let target = Vector3::new(6.0, 8.0, -10.0); // 10 m away
    let mut reference = Reference::setpoint(target).unwrap();
    let traj = run_planar(
        &model,
        &mut fmpc,
        &mut reference,
        PlanarState::zeros(),
        1500,
        |_, _| {},
    );
    let err = |k: usize| (traj[k] - target).norm();
    // Reached within 10 s and held (to 1 cm) for the remaining 20 s.
    for (k, _) in traj.iter().enumerate().skip(500) {
        assert!(err(k) < 0.01, "tick {k}: error {} m", err(k));
    }
    assert!(err(1499) < 1e-4, "final error {} m", err(1499));
    // The unconstrained plan meets the 35° saturation on a 10 m step: some
    // overshoot, bounded.
    let dir = Vector3::new(0.6, 0.8, 0.0);
    let overshoot = traj
        .iter()
        .map(|p| p.dot(&dir) - 10.0)
        .fold(f64::MIN, f64::max);
    assert!(overshoot < 2.0, "overshoot {overshoot} m");
}

#[test]
fn fmpc_planar_ned_follows_the_l_path() {
    let model = planar_ned(0.0);
    let mut fmpc = FlatnessMpc::new(ControlModel::Planar(model), FmpcSettings::default()).unwrap();
    let mut reference = paths::l(-10.0, 3.0).unwrap();
    let x0 = PlanarState::from([-20.0, 0.0, -30.0, 0.0, 0.0, 0.0]);
    let traj = run_planar(&model, &mut fmpc, &mut reference, x0, 1500, |_, _| {});
    let worst = traj
        .iter()
        .map(|p| reference.distance_to_path(p))
        .fold(0.0, f64::max);
    assert!(worst < 1.5, "largest path error {worst} m");
    assert!(
        reference.is_finished(),
        "progress {} of {}",
        reference.progress(),
        reference.path_length()
    );
    assert!((traj[traj.len() - 1] - Vector3::new(0.0, 0.0, -10.0)).norm() < 0.1);
}

#[test]
fn fmpc_nan_measurement_is_an_error_and_nothing_is_recorded() {
    let model = planar_ned(0.3);
    let make = || FlatnessMpc::new(ControlModel::Planar(model), FmpcSettings::default()).unwrap();
    let (mut a, mut b) = (make(), make());
    let mut ra = Reference::setpoint(Vector3::new(5.0, -2.0, 0.0)).unwrap();
    let mut rb = ra.clone();
    let ys = [0.0, 0.01, 0.05, 0.12, 0.2];
    for (k, &p) in ys.iter().enumerate() {
        let m = Measurement {
            t: k as f64 * DT,
            position: Vector3::new(p, -p, 0.0),
            yaw: 0.0,
        };
        if k == 2 {
            for bad in [f64::NAN, f64::INFINITY] {
                let mut nan = m;
                nan.position.y = bad;
                assert_eq!(
                    a.update(&nan, &mut ra),
                    Err(ControlError::NonFiniteMeasurement)
                );
            }
            let mut nan_t = m;
            nan_t.t = f64::NAN;
            assert_eq!(
                a.update(&nan_t, &mut ra),
                Err(ControlError::NonFiniteMeasurement)
            );
        }
        assert_eq!(
            a.update(&m, &mut ra).unwrap(),
            b.update(&m, &mut rb).unwrap(),
            "tick {k}"
        );
    }
    // reset forgets the history: the next tick equals a fresh controller's.
    a.reset();
    let m = Measurement {
        t: 1.0,
        position: Vector3::new(1.0, 1.0, 0.0),
        yaw: 0.0,
    };
    let mut fresh = make();
    assert_eq!(
        a.update(&m, &mut ra).unwrap(),
        fresh.update(&m, &mut rb).unwrap()
    );
}

/// A reference that yields NaN.
struct NanReference;

impl ReferenceSource for NanReference {
    fn horizon(&mut self, _: &Vector3<f64>, _: f64, out: &mut [Vector3<f64>]) {
        out.fill(Vector3::new(f64::NAN, 0.0, 0.0));
    }
    fn closest(&mut self, _: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        (Vector3::new(f64::NAN, 0.0, 0.0), Vector3::zeros())
    }
}

#[test]
fn fmpc_nan_reference_is_an_error() {
    let mut fmpc = FlatnessMpc::new(
        ControlModel::Planar(planar_ned(0.0)),
        FmpcSettings::default(),
    )
    .unwrap();
    let m = Measurement {
        t: 0.0,
        position: Vector3::zeros(),
        yaw: 0.0,
    };
    assert_eq!(
        fmpc.update(&m, &mut NanReference),
        Err(ControlError::NonFiniteReference)
    );
}

#[test]
fn fmpc_settings_validation_names_the_field() {
    let ok = FmpcSettings::default();
    assert_eq!(ok.validate(), Ok(()));
    assert_eq!(ok.horizon, 75);
    let cases: [(FmpcSettings, &str); 7] = [
        (FmpcSettings { horizon: 2, ..ok }, "horizon"),
        (
            FmpcSettings {
                horizon: 100_000,
                ..ok
            },
            "horizon",
        ),
        (
            FmpcSettings {
                q: [1.0, -1.0, 1.0],
                ..ok
            },
            "q",
        ),
        (
            FmpcSettings {
                q: [f64::NAN, 1.0, 1.0],
                ..ok
            },
            "q",
        ),
        (
            FmpcSettings {
                r: [0.1, 0.1, 0.0],
                ..ok
            },
            "r",
        ),
        (
            FmpcSettings {
                max_tilt: Some(2.0),
                ..ok
            },
            "max_tilt",
        ),
        (
            FmpcSettings {
                max_tilt: Some(0.0),
                ..ok
            },
            "max_tilt",
        ),
    ];
    for (s, field) in cases {
        assert_eq!(field_of(s.validate().unwrap_err()), field);
        let e = FlatnessMpc::new(ControlModel::Planar(planar_ned(0.0)), s).unwrap_err();
        assert_eq!(field_of(e), field);
    }
    let no_limit = FmpcSettings {
        max_tilt: None,
        ..ok
    };
    assert_eq!(no_limit.validate(), Ok(()));
}

#[test]
fn fmpc_planar_plan_starts_at_the_measurement_and_saturates() {
    let model = planar_ned(0.0);
    let mut fmpc = FlatnessMpc::new(ControlModel::Planar(model), FmpcSettings::default()).unwrap();
    // A far setpoint demands more than 35° of tilt.
    let mut reference = Reference::setpoint(Vector3::new(500.0, 0.0, 0.0)).unwrap();
    let m = Measurement {
        t: 0.0,
        position: Vector3::new(1.0, 2.0, -3.0),
        yaw: 0.0,
    };
    let out = fmpc.update(&m, &mut reference).unwrap();
    assert_eq!(out.plan[0], m.position);
    assert!(out.saturated);
    // NED: accelerating north is nose down.
    assert!((out.command.pitch + 35f64.to_radians()).abs() < 1e-12);
    assert_eq!(out.reference, Vector3::new(500.0, 0.0, 0.0));
    assert_eq!(out.command.thrust, 9.81);
    // The plan moves toward the setpoint and keeps the measured altitude.
    assert!(out.plan[3].x > out.plan[2].x && out.plan[2].x > out.plan[1].x && out.plan[1].x > 1.0);
    assert_eq!(out.plan[3].z, -3.0);
    assert!(!out.constrained);
}

fn spatial(psi: f64, frame: Frame) -> (SpatialParams, SpatialModel) {
    let p = SpatialParams {
        psi,
        frame,
        ..Default::default()
    };
    (p, SpatialModel::new(p).unwrap())
}

#[test]
fn fmpc_spatial_hover_and_ned_signs() {
    let (p, model) = spatial(0.0, Frame::Ned);
    let mut fmpc = FlatnessMpc::new(ControlModel::Spatial(model), FmpcSettings::default()).unwrap();
    let here = Vector3::new(1.0, 2.0, -10.0);
    let m = Measurement {
        t: 0.0,
        position: here,
        yaw: 0.0,
    };
    let out = fmpc
        .update(&m, &mut Reference::setpoint(here).unwrap())
        .unwrap();
    assert_eq!((out.command.pitch, out.command.roll), (0.0, 0.0));
    assert!((out.command.thrust - p.g).abs() < 1e-12);

    // North and up (NED z negative): nose down, more thrust. East: right roll.
    for (target, check) in [
        (Vector3::new(5.0, 2.0, -10.0), 0),
        (Vector3::new(1.0, 6.0, -10.0), 1),
        (Vector3::new(1.0, 2.0, -15.0), 2),
    ] {
        fmpc.reset();
        let out = fmpc
            .update(&m, &mut Reference::setpoint(target).unwrap())
            .unwrap();
        match check {
            0 => assert!(out.command.pitch < -1e-3 && out.command.roll.abs() < 1e-12),
            1 => assert!(out.command.roll > 1e-3 && out.command.pitch.abs() < 1e-12),
            _ => assert!(out.command.thrust > p.g + 1e-3 && out.command.pitch == 0.0),
        }
    }
}

#[test]
fn fmpc_spatial_reaches_and_holds_setpoint_in_both_frames() {
    // The vertical loop rings: FMPC's lead τ_T·Ṫ acts on an acceleration
    // estimated from a second difference (two steps old), and τ_T = 0.04 s
    // is only two control steps. It decays (about ×0.5 every 2.5 s); hold
    // is checked from 30 s on.
    for frame in [Frame::Ned, Frame::Zup] {
        let up = if frame == Frame::Ned { -1.0 } else { 1.0 };
        let (p, model) = spatial(-0.6, frame);
        let mut fmpc =
            FlatnessMpc::new(ControlModel::Spatial(model), FmpcSettings::default()).unwrap();
        let target = Vector3::new(6.0, -6.0, 12.0 * up);
        let mut reference = Reference::setpoint(target).unwrap();
        let mut sim = SpatialSim::at_rest(p, Vector3::new(0.0, 0.0, 10.0 * up));
        for k in 0..2000 {
            let m = Measurement {
                t: k as f64 * DT,
                position: sim.pos,
                yaw: p.psi,
            };
            let c = fmpc.update(&m, &mut reference).unwrap().command;
            assert!(c.is_finite() && c.thrust >= 0.0);
            sim.step(c.pitch, c.roll, c.thrust);
            if k >= 1500 {
                assert!(
                    (sim.pos - target).norm() < 0.02,
                    "{frame:?} tick {k}: {}",
                    sim.pos
                );
            }
        }
    }
}
