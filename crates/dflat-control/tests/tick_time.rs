//! The time a controller takes its tick to be (`Controller::tick_time`),
//! told before its update so the shell sets a trajectory reference (a
//! route, a stream) to the time its state is at. With poses on time it is
//! the pose's time; on a tick without a new pose, a step after the last
//! tick (plus the ticks the shell skipped), where a controller that takes
//! its clock from the poses carries its state — the pose's own time would
//! put the reference a step behind the state. Multi-rate controllers are
//! handed the tick time and tell it back.

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::estimator::{EstimatorSettings, StateSource};
use dflat_control::fmpc::{FlatnessMpc, FmpcSettings};
use dflat_control::pd::{Pd, PdSettings};
use dflat_control::window::MultiRateSettings;
use dflat_control::{ControlModel, Controller, Measurement};
use dflat_model::{SpatialModel, SpatialParams};
use nalgebra::Vector3;

mod common;
use common::{DT, Setpoint};

fn model() -> ControlModel {
    ControlModel::Spatial(SpatialModel::new(SpatialParams::default()).unwrap())
}

/// A pose at `t` on a line at 2 m/s.
fn pose(t: f64) -> Measurement {
    Measurement {
        t,
        position: Vector3::new(2.0 * t, 0.0, -10.0),
        yaw: 0.0,
    }
}

/// One tick: the time told, then the update.
fn tick(c: &mut dyn Controller, m: &Measurement) -> f64 {
    c.observe(m);
    let told = c.tick_time(m);
    let mut reference = Setpoint(Vector3::new(5.0, 0.0, -10.0));
    c.update(m, &mut reference)
        .unwrap_or_else(|e| panic!("{}: {e}", c.name()));
    told
}

/// Ticks 0–9 on time, tick 10 without a new pose, ticks 11–12 skipped
/// (said), tick 13 without a new pose, tick 14 with tick 12's pose (late),
/// tick 15 on time: the times told, per tick.
fn told(c: &mut dyn Controller) -> Vec<(u32, f64)> {
    let mut out = Vec::new();
    for k in 0..10 {
        out.push((k, tick(c, &pose(f64::from(k) * DT))));
    }
    let last = pose(9.0 * DT);
    out.push((10, tick(c, &last)));
    c.skipped(2);
    out.push((13, tick(c, &last)));
    out.push((14, tick(c, &pose(12.0 * DT))));
    out.push((15, tick(c, &pose(15.0 * DT))));
    out
}

#[test]
fn controllers_on_the_poses_clock_tell_the_ticks_own_time() {
    let controllers: Vec<Box<dyn Controller>> = vec![
        Box::new(DfMpc::new(model(), DfMpcSettings::default()).unwrap()),
        Box::new(FlatnessMpc::new(model(), FmpcSettings::default()).unwrap()),
        Box::new(Pd::new(model(), PdSettings::default()).unwrap()),
    ];
    for mut c in controllers {
        assert!(!c.multi_rate());
        for (k, t) in told(c.as_mut()) {
            assert!(
                (t - f64::from(k) * DT).abs() < 1e-12,
                "{}: tick {k} told {t} s",
                c.name()
            );
        }
    }
}

#[test]
fn multi_rate_controllers_tell_the_tick_time_they_are_handed() {
    let estimator = StateSource::Estimator(EstimatorSettings::for_sensor(0.002, 50.0));
    let controllers: Vec<Box<dyn Controller>> = vec![
        Box::new(
            DfMpc::new(
                model(),
                DfMpcSettings {
                    multi_rate: Some(MultiRateSettings::default()),
                    ..DfMpcSettings::default()
                },
            )
            .unwrap(),
        ),
        Box::new(
            FlatnessMpc::new(
                model(),
                FmpcSettings {
                    state: estimator,
                    ..FmpcSettings::default()
                },
            )
            .unwrap(),
        ),
        Box::new(
            Pd::new(
                model(),
                PdSettings {
                    state: estimator,
                    ..PdSettings::default()
                },
            )
            .unwrap(),
        ),
    ];
    for mut c in controllers {
        assert!(c.multi_rate());
        for k in 0..5 {
            let m = pose(f64::from(k) * DT);
            assert_eq!(tick(c.as_mut(), &m), m.t, "{}", c.name());
        }
        c.skipped(3);
        let m = Measurement {
            t: 9.0 * DT,
            ..pose(4.0 * DT)
        };
        assert_eq!(tick(c.as_mut(), &m), m.t, "{}", c.name());
    }
}
