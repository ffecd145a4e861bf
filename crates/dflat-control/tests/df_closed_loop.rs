//! Closed-loop tests of [`DfMpc`] on the models' own Euler step (plant =
//! model, 50 Hz, no noise), in NED with yaw ≠ 0.

use dflat_control::dfmpc::{
    DfMpc, DfMpcSettings, InputSaturation, OutputConstraints, PlanTiltBound,
};
use dflat_control::tilt::tilt;
use dflat_control::{
    ControlError, ControlModel, Controller, Frame, Measurement, ReferenceSource, TickOutput,
    TiltLimit,
};
use dflat_model::{FlatModel, PlanarModel, SpatialModel, SpatialParams};
use nalgebra::{SVector, Vector2, Vector3};

mod common;
use common::{DT, G, Setpoint, planar_ned};

/// A polyline flown at constant speed from its first point, timed by the
/// number of `horizon` calls (one per tick); stops at the last point.
struct TimedPath {
    points: Vec<Vector3<f64>>,
    speed: f64,
    tick: usize,
}

impl TimedPath {
    fn at(&self, s: f64) -> Vector3<f64> {
        let mut s = s.max(0.0);
        for w in self.points.windows(2) {
            let len = (w[1] - w[0]).norm();
            if s <= len {
                return w[0] + (w[1] - w[0]) * (s / len);
            }
            s -= len;
        }
        *self.points.last().unwrap()
    }
}

impl ReferenceSource for TimedPath {
    fn horizon(&mut self, _measured: &Vector3<f64>, dt: f64, out: &mut [Vector3<f64>]) {
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.at(self.speed * dt * (self.tick + j) as f64);
        }
        self.tick += 1;
    }
    fn closest(&mut self, _measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        (
            self.at(self.speed * DT * self.tick as f64),
            Vector3::zeros(),
        )
    }
}

/// Runs the planar loop for `ticks`, calling `check(k, position, output)`.
fn run_planar(
    plant: PlanarModel,
    ctrl: &mut DfMpc,
    reference: &mut dyn ReferenceSource,
    ticks: usize,
    mut check: impl FnMut(usize, Vector3<f64>, &TickOutput),
) {
    let mut x = SVector::<f64, 6>::zeros();
    for k in 0..ticks {
        let y = plant.output(&x);
        let position = Vector3::new(y.x, y.y, -2.0);
        let m = Measurement {
            t: k as f64 * DT,
            position,
            yaw: plant.params().psi,
        };
        let out = ctrl
            .update(&m, reference)
            .unwrap_or_else(|e| panic!("tick {k}: {e}"));
        assert!(out.command.is_finite());
        check(k, position, &out);
        x = plant.step(&x, &Vector2::new(out.command.pitch, out.command.roll));
    }
}

#[test]
fn df_planar_setpoint_reached_and_held() {
    let plant = planar_ned(0.6);
    let mut ctrl = DfMpc::new(ControlModel::Planar(plant), DfMpcSettings::default()).unwrap();
    let target = Vector3::new(10.0, 0.0, -2.0); // 10 m north, yawed 34°
    let mut saturated = false;
    let max_tilt = 35f64.to_radians();
    run_planar(
        plant,
        &mut ctrl,
        &mut Setpoint(target),
        1000,
        |k, p, out| {
            saturated |= out.saturated;
            assert!(out.command.pitch.abs() <= max_tilt && out.command.roll.abs() <= max_tilt);
            assert_eq!(out.plan[0], p);
            assert_eq!(out.reference, target);
            let err = (p - target).xy().norm();
            if k >= 300 {
                assert!(err < 0.01, "tick {k} ({} s): error {err} m", k as f64 * DT);
            }
            if k >= 900 {
                assert!(
                    err < 1e-4 && out.command.pitch.abs() < 1e-3,
                    "tick {k}: not settled"
                );
            }
        },
    );
    assert!(saturated, "a 10 m step should hit the 35° saturation");
}

/// A diagonal 10 m step saturates both channels at once: per channel
/// (the paper) the vehicle tilts by up to 47.9° at a 35° limit; with the
/// cone the tilt stays within 35° and the step is still reached.
#[test]
fn df_cone_tilt_limit_bounds_the_combined_tilt() {
    let plant = planar_ned(0.0);
    let max_tilt = 35f64.to_radians();
    let target = Vector3::new(10.0, -10.0, -2.0);
    let fly = |tilt_limit| {
        let settings = DfMpcSettings {
            saturation: Some(InputSaturation {
                tilt_limit,
                ..InputSaturation::default()
            }),
            ..DfMpcSettings::default()
        };
        let mut ctrl = DfMpc::new(ControlModel::Planar(plant), settings).unwrap();
        let mut largest = 0.0f64;
        let mut final_error = f64::INFINITY;
        run_planar(plant, &mut ctrl, &mut Setpoint(target), 600, |_, p, out| {
            largest = largest.max(tilt(out.command.pitch, out.command.roll));
            final_error = (p - target).xy().norm();
        });
        (largest, final_error)
    };
    let (per_axis, e_per_axis) = fly(TiltLimit::PerAxis);
    let (cone, e_cone) = fly(TiltLimit::Cone);
    assert!(per_axis.to_degrees() > 45.0, "{}", per_axis.to_degrees());
    assert!(cone <= max_tilt, "{}", cone.to_degrees());
    assert!(cone > max_tilt - 1e-6, "the cone is reached");
    assert!(e_per_axis < 0.01 && e_cone < 0.01, "{e_per_axis} {e_cone}");
}

#[test]
fn df_spatial_setpoint_reached_and_held() {
    let plant = SpatialModel::new(SpatialParams {
        psi: -0.4,
        frame: Frame::Ned,
        ..Default::default()
    })
    .unwrap();
    let settings = DfMpcSettings {
        constraints: OutputConstraints {
            max_tilt: Some(30f64.to_radians()),
            vertical_acceleration: Some([-3.0, 3.0]),
            ..Default::default()
        },
        // Tests never depend on timing.
        solver_time_limit: f64::INFINITY,
        ..Default::default()
    };
    let mut ctrl = DfMpc::new(ControlModel::Spatial(plant), settings).unwrap();
    let target = Vector3::new(8.0, -6.0, -3.0); // 10 m across, 3 m up
    let mut reference = Setpoint(target);
    let mut x = SVector::<f64, 9>::zeros();
    x[8] = G; // hovering
    let mut constrained = false;
    for k in 0..1000 {
        let p = plant.output(&x);
        let m = Measurement {
            t: k as f64 * DT,
            position: p,
            yaw: -0.4,
        };
        let out = ctrl
            .update(&m, &mut reference)
            .unwrap_or_else(|e| panic!("tick {k}: {e}"));
        constrained |= out.constrained;
        assert!((2.0..=20.0).contains(&out.command.thrust));
        let err = (p - target).norm();
        if k >= 400 {
            assert!(err < 0.01, "tick {k} ({} s): error {err} m", k as f64 * DT);
        }
        if k >= 900 {
            assert!(
                (out.command.thrust - G).abs() < 1e-3,
                "tick {k}: not hovering"
            );
        }
        x = plant.step(
            &x,
            &Vector3::new(out.command.pitch, out.command.roll, out.command.thrust),
        );
    }
    assert!(constrained);
}

/// The spatial model plans thrust, so its tilt cone follows the vertical
/// plan: ‖a_h‖ ≤ tan(max_tilt)·(g − a_z) per stage (NED). A move 10 m
/// across and 3 m down from hover (the descent takes thrust away, so the
/// cone narrows below g·tan(max_tilt) there): every stage's planned tilt
/// atan(‖a_h‖ / (g − a_z)) stays within the bound, the radius the
/// controller reports is the vertical plan's, and the setpoint is reached.
#[test]
fn df_spatial_cone_follows_the_vertical_plan() {
    let plant = SpatialModel::new(SpatialParams {
        psi: 0.3,
        frame: Frame::Ned,
        ..Default::default()
    })
    .unwrap();
    let max_tilt = 25f64.to_radians();
    let settings = DfMpcSettings {
        constraints: OutputConstraints {
            max_tilt: Some(max_tilt),
            vertical_acceleration: Some([-3.0, 3.0]),
            ..Default::default()
        },
        plan_tilt_bound: PlanTiltBound::Cone,
        solver_time_limit: f64::INFINITY,
        ..Default::default()
    };
    let mut ctrl = DfMpc::new(ControlModel::Spatial(plant), settings).unwrap();
    let target = Vector3::new(8.0, -6.0, 3.0); // 10 m across, 3 m down
    let mut reference = Setpoint(target);
    let mut x = SVector::<f64, 9>::zeros();
    x[8] = G; // hovering
    let (mut constrained, mut narrowest, mut widest) = (0, f64::INFINITY, 0.0f64);
    let dt2 = DT * DT;
    for k in 0..600 {
        let p = plant.output(&x);
        let m = Measurement {
            t: k as f64 * DT,
            position: p,
            yaw: 0.3,
        };
        let out = ctrl
            .update(&m, &mut reference)
            .unwrap_or_else(|e| panic!("tick {k}: {e}"));
        constrained += usize::from(out.constrained);
        let (px, py, pz) = (
            ctrl.plan(0).unwrap(),
            ctrl.plan(1).unwrap(),
            ctrl.plan(2).unwrap(),
        );
        let radius = ctrl.cone_radius().unwrap();
        for j in 1..px.len() - 2 {
            let acc = |v: &[f64]| (v[j + 2] - 2.0 * v[j + 1] + v[j]) / dt2;
            let (ah, az) = (acc(px).hypot(acc(py)), acc(pz));
            let vertical = G - az;
            assert!(
                (radius[j - 1] - max_tilt.tan() * vertical.max(0.2 * G)).abs() < 1e-9,
                "tick {k} row {j}: radius {} for a_z {az}",
                radius[j - 1]
            );
            assert!(
                ah <= radius[j - 1] * (1.0 + 1e-6) + 1e-9,
                "tick {k} row {j}: |a_h| {ah} > {}",
                radius[j - 1]
            );
            if vertical >= 0.2 * G {
                assert!(ah.atan2(vertical) <= max_tilt + 1e-6);
            }
            narrowest = narrowest.min(radius[j - 1]);
            widest = widest.max(radius[j - 1]);
        }
        if k >= 500 {
            let err = (p - target).norm();
            assert!(err < 0.01, "tick {k}: error {err} m");
        }
        x = plant.step(
            &x,
            &Vector3::new(out.command.pitch, out.command.roll, out.command.thrust),
        );
    }
    assert!(constrained > 10, "{constrained}");
    // The descent narrows the cone, the braking at its end widens it.
    let nominal = G * max_tilt.tan();
    assert!(
        narrowest < 0.9 * nominal && widest > 1.1 * nominal,
        "{narrowest} {widest}"
    );
}

#[test]
fn df_planar_follows_straight_path() {
    let plant = planar_ned(-1.0);
    let mut ctrl = DfMpc::new(ControlModel::Planar(plant), DfMpcSettings::default()).unwrap();
    let dir = Vector3::new(0.6, 0.8, 0.0);
    let mut path = TimedPath {
        points: vec![
            Vector3::new(0.0, 0.0, -2.0),
            Vector3::new(0.0, 0.0, -2.0) + 40.0 * dir,
        ],
        speed: 2.0,
        tick: 0,
    };
    let (mut worst, mut steady): (f64, f64) = (0.0, 0.0);
    run_planar(plant, &mut ctrl, &mut path, 750, |k, p, out| {
        let err = (p - out.reference).xy().norm();
        worst = worst.max(err);
        if k >= 250 {
            steady = steady.max(err);
        }
    });
    println!("straight path: worst {worst} m, after 5 s {steady} m");
    // Starting from rest behind a reference already moving at 2 m/s.
    assert!(worst < 0.8, "largest error {worst} m");
    assert!(steady < 0.005, "steady tracking error {steady} m");
}

#[test]
fn df_planar_follows_l_path() {
    let plant = planar_ned(0.3);
    let mut ctrl = DfMpc::new(ControlModel::Planar(plant), DfMpcSettings::default()).unwrap();
    let corner = Vector3::new(10.0, 0.0, -2.0);
    let end = Vector3::new(10.0, 10.0, -2.0);
    let mut path = TimedPath {
        points: vec![Vector3::new(0.0, 0.0, -2.0), corner, end],
        speed: 2.0,
        tick: 0,
    };
    let (mut worst, mut corner): (f64, f64) = (0.0, 0.0);
    let mut last = Vector3::zeros();
    run_planar(plant, &mut ctrl, &mut path, 800, |k, p, out| {
        let err = (p - out.reference).xy().norm();
        worst = worst.max(err);
        if k >= 150 {
            corner = corner.max(err);
        }
        last = p;
    });
    println!("L path: worst {worst} m, after 3 s (the corner at 5 s) {corner} m");
    assert!(worst < 0.8, "largest path error {worst} m");
    // The plan previews the corner and cuts it.
    assert!(corner < 0.5, "largest error around the corner {corner} m");
    assert!((last - end).xy().norm() < 0.01, "ended at {last}");
}

#[test]
fn df_tilt_constraint_engages_and_bounds_the_plan() {
    let plant = planar_ned(0.6);
    let tilt = 15f64.to_radians();
    let a_max = G * tilt.tan();
    let settings = DfMpcSettings {
        constraints: OutputConstraints {
            max_tilt: Some(tilt),
            ..Default::default()
        },
        // Tests never depend on timing.
        solver_time_limit: f64::INFINITY,
        ..Default::default()
    };
    let mut ctrl = DfMpc::new(ControlModel::Planar(plant), settings).unwrap();
    let target = Vector3::new(8.0, -6.0, -2.0);
    let mut engaged = 0;
    let mut x = SVector::<f64, 6>::zeros();
    let mut reference = Setpoint(target);
    for k in 0..600 {
        let y = plant.output(&x);
        let m = Measurement {
            t: k as f64 * DT,
            position: Vector3::new(y.x, y.y, -2.0),
            yaw: 0.6,
        };
        let out = ctrl
            .update(&m, &mut reference)
            .unwrap_or_else(|e| panic!("tick {k}: {e}"));
        if k == 0 {
            assert!(
                out.constrained,
                "the first tick needs more than 15° of tilt"
            );
        }
        if out.constrained {
            engaged += 1;
            for axis in 0..2 {
                let plan = ctrl.plan(axis).unwrap();
                // Accelerations j = 1..N−2 are decision-dependent (j = 0 is fixed).
                for j in 1..plan.len() - 2 {
                    let a = (plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / (DT * DT);
                    assert!(
                        a.abs() <= a_max * (1.0 + 1e-5),
                        "tick {k} axis {axis} j {j}: {a} > {a_max}"
                    );
                }
            }
        }
        x = plant.step(&x, &Vector2::new(out.command.pitch, out.command.roll));
    }
    assert!(engaged > 10, "constraint engaged on {engaged} ticks");
    let err = (plant.output(&x) - Vector2::new(8.0, -6.0)).norm();
    assert!(err < 0.05, "final error {err} m");
}

#[test]
fn df_nan_measurement_is_an_error_and_nothing_is_recorded_then_the_window_restarts() {
    let plant = planar_ned(0.2);
    let target = Vector3::new(3.0, 1.0, 0.0);
    let mut a = DfMpc::new(ControlModel::Planar(plant), DfMpcSettings::default()).unwrap();
    let mut b = DfMpc::new(ControlModel::Planar(plant), DfMpcSettings::default()).unwrap();
    let m = |x: f64| Measurement {
        t: 0.0,
        position: Vector3::new(x, 0.0, 0.0),
        yaw: 0.2,
    };
    for k in 0..5 {
        let x = 0.001 * (k * k) as f64;
        a.update(&m(x), &mut Setpoint(target)).unwrap();
        b.update(&m(x), &mut Setpoint(target)).unwrap();
    }
    let window = *a.window();
    assert_eq!(
        a.update(&m(f64::NAN), &mut Setpoint(target)),
        Err(ControlError::NonFiniteMeasurement)
    );
    let bad_yaw = Measurement {
        yaw: f64::INFINITY,
        ..m(0.1)
    };
    assert_eq!(
        a.update(&bad_yaw, &mut Setpoint(target)),
        Err(ControlError::NonFiniteMeasurement)
    );
    assert_eq!(
        a.update(&m(0.03), &mut Setpoint(Vector3::new(f64::NAN, 0.0, 0.0))),
        Err(ControlError::NonFiniteReference)
    );
    assert_eq!(
        a.window(),
        &window,
        "a failed update must not touch the window"
    );
    assert!(a.plan(0).is_none());
    // The shell sent something on those ticks that the controller never
    // saw (no `plan_fallback`): the next good tick restarts the window, so
    // it equals a fresh controller's first tick, not `b`'s next one.
    let next = m(0.03);
    let mut fresh = DfMpc::new(ControlModel::Planar(plant), DfMpcSettings::default()).unwrap();
    let after_gap = a.update(&next, &mut Setpoint(target)).unwrap();
    assert_eq!(
        after_gap,
        fresh.update(&next, &mut Setpoint(target)).unwrap()
    );
    assert_ne!(after_gap, b.update(&next, &mut Setpoint(target)).unwrap());
}

#[test]
fn df_reset_starts_over() {
    let plant = planar_ned(0.0);
    let target = Vector3::new(1.0, 0.0, 0.0);
    let m = |x: f64| Measurement {
        t: 0.0,
        position: Vector3::new(x, 0.5, 0.0),
        yaw: 0.0,
    };
    let mut a = DfMpc::new(ControlModel::Planar(plant), DfMpcSettings::default()).unwrap();
    let first = a.update(&m(0.0), &mut Setpoint(target)).unwrap();
    a.update(&m(0.01), &mut Setpoint(target)).unwrap();
    a.reset();
    assert!(a.window().is_empty());
    assert_eq!(a.update(&m(0.0), &mut Setpoint(target)).unwrap(), first);
    // At rest at the first tick the prediction is the measurement.
    assert_eq!(first.plan[1], first.plan[0]);
    assert_eq!(first.plan[2], first.plan[0]);
}

#[test]
fn df_settings_validation_names_the_field() {
    let model = ControlModel::Planar(planar_ned(0.0));
    let field = |s: DfMpcSettings| match DfMpc::new(model, s) {
        Err(ControlError::InvalidSetting { field, .. }) => field,
        other => panic!("expected an invalid setting, got {other:?}"),
    };
    let d = DfMpcSettings::default();
    assert_eq!(field(DfMpcSettings { horizon: 0, ..d }), "horizon");
    assert_eq!(
        field(DfMpcSettings {
            jerk_weight: [0.0; 3],
            ..d
        }),
        "jerk_weight"
    );
    assert_eq!(
        field(DfMpcSettings {
            tracking_weight: [-1.0; 3],
            ..d
        }),
        "tracking_weight"
    );
    let nan_tilt = OutputConstraints {
        max_tilt: Some(f64::NAN),
        ..Default::default()
    };
    let both_signs = OutputConstraints {
        vertical_acceleration: Some([-3.0, 3.0]),
        ..Default::default()
    };
    for (constraints, name) in [
        (nan_tilt, "constraints.max_tilt"),
        (both_signs, "constraints.vertical_acceleration"),
    ] {
        assert_eq!(field(DfMpcSettings { constraints, ..d }), name);
    }
    let e = DfMpc::new(model, DfMpcSettings { horizon: 0, ..d }).unwrap_err();
    assert!(e.to_string().contains("horizon"), "{e}");
}
