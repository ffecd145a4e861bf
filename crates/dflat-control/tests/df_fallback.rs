//! [`Controller::plan_fallback`] of DF-MPC: on ticks whose update fails,
//! the last good plan shifted one step per tick is flown, recorded in the
//! window, and the controller resumes from a consistent window (plant =
//! model, planar, 50 Hz, NED, yaw ≠ 0).

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::window::MultiRateSettings;
use dflat_control::{ControlModel, Controller, Frame, Measurement, ReferenceSource};
use dflat_model::{FlatModel, PlanarModel, PlanarParams};
use nalgebra::{SVector, Vector2, Vector3};

const DT: f64 = 0.02;
const Z: f64 = -2.0;

/// A setpoint whose horizon is NaN on the ticks in `broken` (so `update`
/// fails with a non-finite reference there); one `horizon` call per tick.
struct FlakySetpoint {
    target: Vector3<f64>,
    broken: Vec<usize>,
    tick: usize,
}

impl ReferenceSource for FlakySetpoint {
    fn horizon(&mut self, _measured: &Vector3<f64>, _dt: f64, out: &mut [Vector3<f64>]) {
        let value = if self.broken.contains(&self.tick) {
            Vector3::repeat(f64::NAN)
        } else {
            self.target
        };
        out.iter_mut().for_each(|o| *o = value);
        self.tick += 1;
    }
    fn closest(&mut self, _measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        (self.target, Vector3::zeros())
    }
}

fn plant() -> PlanarModel {
    PlanarModel::new(PlanarParams {
        psi: 0.3,
        frame: Frame::Ned,
        ..Default::default()
    })
    .unwrap()
}

fn controller(settings: DfMpcSettings) -> DfMpc {
    DfMpc::new(ControlModel::Planar(plant()), settings).unwrap()
}

/// How the shell answers a failed tick.
#[derive(Clone, Copy, PartialEq)]
enum Shell {
    /// `plan_fallback` (the daemon).
    PlanFallback,
    /// Re-sends the last command without telling the controller.
    HoldUntold,
}

/// Flies 5 m north-east with `update` failing on ticks 60–63 (tick 62:
/// also a NaN pose). Returns the largest error of the controller's
/// one-step prediction `plan[1]` against the plant on the 10 good ticks
/// after the failures \[m\], and checks every fallback command against the
/// last good plan.
fn fly(shell: Shell) -> f64 {
    let plant = plant();
    let model = ControlModel::Planar(plant);
    let mut ctrl = controller(DfMpcSettings::default());
    let broken = vec![60, 61, 62, 63];
    let mut reference = FlakySetpoint {
        target: Vector3::new(5.0, 5.0, Z),
        broken: broken.clone(),
        tick: 0,
    };
    let max_tilt = 35f64.to_radians();
    let mut x = SVector::<f64, 6>::zeros();
    let mut last_good_plan: Vec<Vector3<f64>> = Vec::new();
    let mut steps_flown = 0;
    let mut last_command = Vector2::zeros();
    let mut predicted: Option<Vector3<f64>> = None;
    let mut worst_after = 0.0f64;
    for k in 0..80 {
        let y = plant.output(&x);
        let position = Vector3::new(y.x, y.y, Z);
        if let Some(p) = predicted.take()
            && (65..75).contains(&k)
        {
            worst_after = worst_after.max((p - position).xy().norm());
        }
        let measured = if k == 62 {
            Vector3::new(f64::NAN, y.y, Z)
        } else {
            position
        };
        let m = Measurement {
            t: k as f64 * DT,
            position: measured,
            yaw: 0.3,
        };
        // (A NaN pose fails before the reference is asked.)
        reference.tick = k;
        let command = match ctrl.update(&m, &mut reference) {
            Ok(out) => {
                assert!(!broken.contains(&k), "tick {k} should fail");
                let (px, py) = (ctrl.plan(0).unwrap(), ctrl.plan(1).unwrap());
                last_good_plan = (0..px.len())
                    .map(|j| Vector3::new(px[j], py[j], Z))
                    .collect();
                steps_flown = 0;
                predicted = Some(out.plan[1]);
                Vector2::new(out.command.pitch, out.command.roll)
            }
            Err(_) => {
                assert!(broken.contains(&k), "tick {k} failed");
                match shell {
                    Shell::HoldUntold => last_command,
                    Shell::PlanFallback => {
                        let out = ctrl.plan_fallback(&m, 10).expect("a plan to fly");
                        steps_flown += 1;
                        let s = steps_flown;
                        // The last good plan, shifted s steps, through F.
                        let window: [Vector3<f64>; 4] =
                            std::array::from_fn(|j| last_good_plan[s + j]);
                        let u = model.input_from_outputs(&window).unwrap();
                        let expected = u.xy().map(|v| v.clamp(-max_tilt, max_tilt));
                        let got = Vector2::new(out.command.pitch, out.command.roll);
                        assert!(
                            (got - expected).norm() < 1e-12,
                            "tick {k}, step {s}: {got:?} vs {expected:?}"
                        );
                        assert_eq!(out.plan, window);
                        assert!(!out.constrained);
                        got
                    }
                }
            }
        };
        assert!(command.iter().all(|v| v.is_finite() && v.abs() <= max_tilt));
        last_command = command;
        x = plant.step(&x, &command);
    }
    // Still flying to the target afterwards.
    let y = plant.output(&x);
    assert!((y - Vector2::new(5.0, 5.0)).norm() < 5.0);
    worst_after
}

#[test]
fn plan_fallback_flies_the_last_plan_shifted_and_keeps_the_window_consistent() {
    // With the fallback recorded, the window after the failures still
    // matches the plant exactly: the one-step prediction is exact.
    let with_fallback = fly(Shell::PlanFallback);
    assert!(with_fallback < 1e-9, "prediction error {with_fallback} m");
    // A shell that sends something the controller never hears of: the
    // window restarts from rest and the prediction is off while it refills.
    let untold = fly(Shell::HoldUntold);
    assert!(untold > 1e-4, "prediction error {untold} m");
}

#[test]
fn plan_fallback_ends_at_max_steps_and_at_the_end_of_the_plan() {
    let target = Vector3::new(3.0, -1.0, Z);
    let m = |k: usize| Measurement {
        t: k as f64 * DT,
        position: Vector3::new(0.0, 0.0, Z),
        yaw: 0.3,
    };
    let mut reference = FlakySetpoint {
        target,
        broken: vec![],
        tick: 0,
    };

    // No good tick yet: nothing to fly.
    let mut ctrl = controller(DfMpcSettings::default());
    assert!(ctrl.plan_fallback(&m(0), 10).is_none());

    // max_steps = 2.
    ctrl.update(&m(0), &mut reference).unwrap();
    assert!(ctrl.plan_fallback(&m(1), 2).is_some());
    assert!(ctrl.plan_fallback(&m(2), 2).is_some());
    assert!(ctrl.plan_fallback(&m(3), 2).is_none());
    assert!(ctrl.plan_fallback(&m(4), 2).is_none(), "stays used up");
    // The shell sent its own fallback at tick 3: the window restarts, so
    // the next tick is a fresh controller's first.
    let mut fresh = controller(DfMpcSettings::default());
    assert_eq!(
        ctrl.update(&m(5), &mut reference).unwrap(),
        fresh.update(&m(5), &mut reference).unwrap()
    );

    // Horizon 10 (the shortest allowed) keeps y*_0..y*_10: steps 1..=7
    // use y*_s..y*_{s+3}.
    let mut short = controller(DfMpcSettings {
        horizon: 10,
        ..DfMpcSettings::default()
    });
    short.update(&m(0), &mut reference).unwrap();
    for k in 1..=7 {
        assert!(short.plan_fallback(&m(k), 50).is_some(), "step {k}");
    }
    assert!(short.plan_fallback(&m(8), 50).is_none());

    // A reset forgets the plan.
    ctrl.reset();
    assert!(ctrl.plan_fallback(&m(6), 10).is_none());
}

#[test]
fn plan_fallback_in_multi_rate_mode() {
    let mut ctrl = controller(DfMpcSettings {
        multi_rate: Some(MultiRateSettings::default()),
        ..DfMpcSettings::default()
    });
    let mut reference = FlakySetpoint {
        target: Vector3::new(2.0, 0.0, Z),
        broken: vec![],
        tick: 0,
    };
    let sample = |t: f64| Measurement {
        t,
        position: Vector3::new(0.0, 0.0, Z),
        yaw: 0.3,
    };
    for k in 0..5 {
        let t = k as f64 * DT;
        ctrl.observe(&sample(t));
        ctrl.update(&sample(t), &mut reference).unwrap();
    }
    let first = ctrl.plan_fallback(&sample(5.0 * DT), 10).unwrap();
    let second = ctrl.plan_fallback(&sample(6.0 * DT), 10).unwrap();
    assert!(first.command.is_finite() && second.command.is_finite());
    assert_ne!(first.plan, second.plan, "one plan step per tick");
    let last = |c: &DfMpc| c.multi_rate_window().unwrap().last_tick().unwrap();
    assert!((last(&ctrl) - 6.0 * DT).abs() < 1e-12);
    // Back to normal ticks.
    ctrl.observe(&sample(7.0 * DT));
    assert!(ctrl.update(&sample(7.0 * DT), &mut reference).is_ok());
    // A late update (the shell flies its plan instead, at the same tick
    // time): the fallback is the step after it, on the window's clock too.
    assert!(ctrl.plan_fallback(&sample(7.0 * DT), 10).is_some());
    assert!((last(&ctrl) - 8.0 * DT).abs() < 1e-12, "{}", last(&ctrl));
    ctrl.observe(&sample(9.0 * DT));
    assert!(ctrl.update(&sample(9.0 * DT), &mut reference).is_ok());
    assert!((last(&ctrl) - 9.0 * DT).abs() < 1e-12);
}
