//! End to end: every SET_ATTITUDE_TARGET the daemon emits obeys the
//! contract — sender (1, 191), target (1, 1), type_mask 7 (body rates
//! ignored), unit quaternion, finite fields, body rates 0, thrust_body 0,
//! thrust in [0, 1], tilt within 35° — for the planar model (fixed thrust
//! 0.5, ArduPilot-style) and the spatial model (normalised thrust,
//! PX4-style, against a spatial plant), while flying a short L. The daemon's
//! HEARTBEAT and STATUSTEXT are checked too.
//!
//! The real `dflat daemon` binary against the SITL run in-process
//! (`dflat_sitl`), whose tap sees every frame the daemon sends.

#[path = "support/mod.rs"]
mod common;

use std::time::Duration;

use common::*;
use dflat_link::MavMessage;
use dflat_link::dialect::{MavAutopilot, MavType};

/// Flight time observed per model after the first command \[s\].
const FLY: Duration = Duration::from_secs(6);

/// Checks every frame of `flight`; returns the thrust values.
fn check_contract(name: &str, flight: &Flight) -> Vec<f64> {
    assert!(
        flight.clean_exit,
        "{name}: the daemon did not exit cleanly on SIGINT"
    );
    let mut thrusts = Vec::new();
    let mut heartbeats = 0;
    for f in &flight.frames {
        assert_eq!(
            (f.header.system_id, f.header.component_id),
            (1, 191),
            "{name}: frame from an unexpected sender: {:?}",
            f.message
        );
        match &f.message {
            MavMessage::SET_ATTITUDE_TARGET(d) => {
                assert_eq!(
                    (d.target_system, d.target_component),
                    (1, 1),
                    "{name}: target ids"
                );
                assert_eq!(
                    d.type_mask.bits(),
                    7,
                    "{name}: type_mask must ignore exactly the body rates"
                );
                let q = d.q.map(f64::from);
                assert!(q.iter().all(|v| v.is_finite()), "{name}: q {q:?}");
                let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                assert!((norm - 1.0).abs() < 1e-5, "{name}: |q| = {norm}");
                for v in [d.body_roll_rate, d.body_pitch_rate, d.body_yaw_rate] {
                    assert!(v == 0.0, "{name}: body rate {v}");
                }
                assert!(
                    d.thrust_body.iter().all(|v| *v == 0.0),
                    "{name}: thrust_body"
                );
                let thrust = f64::from(d.thrust);
                assert!((0.0..=1.0).contains(&thrust), "{name}: thrust {thrust}");
                thrusts.push(thrust);
                let [roll, pitch, _] = dflat_link::euler_from_quaternion(q);
                let limit = 35.01f64.to_radians();
                // The contract bounds the combined tilt (the cone), not
                // roll and pitch separately (that would let 48° pass).
                let tilt = dflat_control::tilt::tilt(pitch, roll);
                assert!(
                    tilt <= limit,
                    "{name}: tilt {:.2}° (roll {roll} pitch {pitch})",
                    tilt.to_degrees()
                );
            }
            MavMessage::HEARTBEAT(d) => {
                heartbeats += 1;
                assert_eq!(d.mavtype, MavType::MAV_TYPE_ONBOARD_CONTROLLER);
                assert_eq!(d.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
            }
            MavMessage::STATUSTEXT(d) => {
                let text = d.text.to_str().unwrap_or("");
                assert!(!text.is_empty(), "{name}: empty STATUSTEXT");
            }
            _ => {}
        }
    }
    assert!(!thrusts.is_empty(), "{name}: no SET_ATTITUDE_TARGET at all");
    assert!(
        heartbeats >= 3,
        "{name}: only {heartbeats} daemon heartbeats"
    );
    let c = &flight.report.counters;
    assert_eq!(c.commands_rejected, 0, "{name}: the SITL rejected commands");
    assert_eq!(c.commands_ignored, 0, "{name}: the SITL ignored commands");
    thrusts
}

#[test]
fn every_attitude_target_obeys_the_contract() {
    // Planar model, fixed thrust (ArduPilot GUIDED_NOGPS style).
    let planar = fly_in_process(
        "contract-planar",
        &format!("{SHORT_L}[sitl]\nstart = [0.0, 0.0, -10.0]\n"),
        FLY,
    );
    let thrusts = check_contract("planar", &planar);
    assert!(
        thrusts.iter().all(|t| (*t - 0.5).abs() < 1e-6),
        "fixed thrust must be 0.5"
    );
    // ... streamed at 50 Hz throughout.
    let streamed_s = planar.streamed_s();
    let expected = streamed_s * 50.0;
    assert!(
        thrusts.len() as f64 >= 0.9 * expected,
        "planar: {} attitude targets in {streamed_s:.2} s of the daemon's stream (≈ {expected:.0} at 50 Hz)",
        thrusts.len(),
    );
    eprintln!("planar: {} attitude targets checked", thrusts.len());

    // Spatial model, normalised thrust, against a spatial plant (PX4 style).
    let spatial = fly_in_process(
        "contract-spatial",
        &format!("{SHORT_L}{SPATIAL_VEHICLE}{SPATIAL_PLANT}"),
        FLY,
    );
    let thrusts = check_contract("spatial", &spatial);
    let (lo, hi) = thrusts
        .iter()
        .fold((1.0f64, 0.0f64), |(lo, hi), t| (lo.min(*t), hi.max(*t)));
    eprintln!(
        "spatial: {} attitude targets checked, thrust {lo:.3}–{hi:.3}",
        thrusts.len()
    );
    assert!(hi > lo, "normalised thrust never varied");
}

/// The spatial plant (PX4 style) at hover thrust 0.5, at rest at NED
/// (0, 0, −10) m.
const SPATIAL_PLANT: &str = r#"[sitl]
plant = "spatial"
hover_thrust = 0.5
start = [0.0, 0.0, -10.0]
"#;
