//! A stream is a trajectory in time, and the controller's state is at the
//! tick's time as the controller takes it (`Controller::tick_time`). With
//! the paper's classic window (or the baselines on finite differences) a
//! tick without a new pose carries the state a step past the pose; the
//! stream's reference must be there too, not at the pose's time. Set to
//! the pose's time, the reference stood still on every tick without a
//! pose and jumped two steps on the next.

use super::tests::step_events;
use super::*;
use crate::config::{ControllerKind, StateSourceKind};
use crate::control::{build_controller, thrust_mapping};

const DT: f64 = 0.02;

/// PX4 armed in OFFBOARD.
const OFFBOARD: dflat_link::AutopilotMode = dflat_link::AutopilotMode {
    family: dflat_link::AutopilotFamily::Px4,
    custom_mode: 6 << 16,
    armed: true,
};

/// The reference of each tick (x, m) flying a stream along x at 1 m/s
/// with `cfg`; the pose of every third tick from tick 40 is missing.
fn references(cfg: &Config) -> Vec<Option<f64>> {
    let controller = build_controller(cfg).unwrap();
    let mut core = ControlCore::new(cfg, controller, thrust_mapping(cfg));
    (0..120u64)
        .map(|k| {
            let t = k as f64 * DT;
            let mut events = vec![Event::Heartbeat {
                arrival: t - 0.002,
                mode: OFFBOARD,
            }];
            if k < 40 || k % 3 != 0 {
                events.push(Event::Pose {
                    arrival: t - 0.001,
                    source_time: None,
                    position: [t, 0.0, -10.0],
                    yaw: Some(0.0),
                    reset_counter: None,
                });
            }
            if k >= 10 {
                events.push(Event::Setpoint {
                    arrival: t - 0.0005,
                    position: [t, 0.0, -10.0],
                    yaw: None,
                    yaw_rate: None,
                    source_time: None,
                    velocity: Some([1.0, 0.0, 0.0]),
                    acceleration: None,
                });
            }
            step_events(&mut core, k, events)
                .row
                .reference
                .map(|r| r[0])
        })
        .collect()
}

/// The reference moves a step's worth (2 cm) on every tick, with and
/// without a pose, for each controller that takes its clock from the
/// poses.
#[test]
fn a_streams_reference_moves_on_ticks_without_a_pose() {
    for (name, kind, multi_rate) in [
        ("classic window", ControllerKind::DfMpc, false),
        ("flatness mpc on differences", ControllerKind::Fmpc, false),
        ("multi-rate window", ControllerKind::DfMpc, true),
    ] {
        let mut cfg = Config::default();
        cfg.controller.kind = kind;
        cfg.controller.dfmpc.multi_rate = multi_rate;
        cfg.controller.estimator.state_source = StateSourceKind::FiniteDifference;
        let refs = references(&cfg);
        let mut compared = 0;
        for k in 60..120 {
            let (Some(a), Some(b)) = (refs[k - 1], refs[k]) else {
                panic!("{name}: tick {k} has no reference");
            };
            let step = b - a;
            assert!(
                (step - DT).abs() < 2e-3,
                "{name}: tick {k} (pose {}): the reference moved {step:.4} m",
                if k % 3 == 0 { "missing" } else { "new" }
            );
            compared += 1;
        }
        assert_eq!(compared, 60);
    }
}
