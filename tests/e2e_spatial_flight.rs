//! End to end: the spatial model (PX4-style normalised thrust) against a
//! spatial plant streams at 50 Hz and holds altitude while flying a short L.
//!
//! Pose and tick phases are independent (with ~1 ms between them a little
//! jitter is enough for a tick to find no new pose): this flight once ran
//! away when such a tick entered the repeated pose into the window as new.
//! Flown with the shipped defaults (multi-rate windows) and, as
//! `..._classic_window`, with the paper's one-pose-per-tick window, where
//! the controller predicts y_k for a tick without a new pose.

#[path = "support/mod.rs"]
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

/// Largest altitude error allowed while flying \[m\].
const ALTITUDE_BOUND: f64 = 0.5;

#[test]
fn spatial_model_streams_at_50_hz_and_holds_altitude() {
    check("spatial-flight", CONFIG);
}

#[test]
fn spatial_model_streams_at_50_hz_and_holds_altitude_classic_window() {
    let config = format!("{CONFIG}[controller.dfmpc]\nmulti_rate = false\n");
    check("spatial-flight-classic", &config);
}

fn check(name: &str, config: &str) {
    let flight = fly_in_process(name, config, Duration::from_secs(6));
    let n = flight.attitude_targets().count();
    let expected = flight.streamed_for.as_secs_f64() * 50.0;
    let altitude_error = flight
        .report
        .trace
        .iter()
        .map(|s| (s.position[2] + 10.0).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "{name}: {n} attitude targets in {:?}, max altitude error {altitude_error:.3} m",
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
