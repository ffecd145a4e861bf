//! End to end: the spatial model (PX4-style normalised thrust) against a
//! spatial plant streams at 50 Hz and holds altitude while flying a short L.
//!
//! Ignored for now: when a tick finds no pose newer than the previous one
//! (pose and tick phases are independent; with ~1 ms between them a little
//! jitter is enough), the daemon enters the repeated pose into the window
//! as a new sample; the planar model answers with one saturated (±35°)
//! command, the spatial model with a growing thrust / "free fall"
//! oscillation that fails every other tick. Run with `--ignored` once fixed.

mod common;

use std::time::Duration;

use common::*;

const CONFIG: &str = r#"
[mission]
start = "path"
path = [[0.0, 0.0, -10.0], [8.0, 0.0, -10.0], [8.0, 6.0, -10.0]]
speed = 4.0
[logging]
dir = "@DIR@"
tlog = false
[vehicle]
model = "spatial"
thrust_mode = "normalized"
hover_thrust = 0.5
[sitl]
plant = "spatial"
hover_thrust = 0.5
start = [0.0, 0.0, -10.0]
"#;

/// Largest altitude error allowed while flying [m].
const ALTITUDE_BOUND: f64 = 0.5;

#[test]
#[ignore = "daemon: a tick without a new pose feeds the repeated pose into the window (see module docs)"]
fn spatial_model_streams_at_50_hz_and_holds_altitude() {
    let flight = fly_in_process("spatial-flight", CONFIG, Duration::from_secs(6));
    let n = flight.attitude_targets().count();
    let expected = flight.streamed_for.as_secs_f64() * 50.0;
    let altitude_error = flight
        .report
        .trace
        .iter()
        .map(|s| (s.position[2] + 10.0).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "spatial: {n} attitude targets in {:?}, max altitude error {altitude_error:.3} m",
        flight.streamed_for
    );
    assert!(
        n as f64 >= 0.9 * expected,
        "{n} attitude targets (≈ {expected:.0} at 50 Hz)"
    );
    assert!(
        altitude_error < ALTITUDE_BOUND,
        "altitude error {altitude_error:.2} m"
    );
}
