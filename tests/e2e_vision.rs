//! End to end: the daemon on `pose_source = "vision_position_estimate"`
//! with the SITL's vision stand-in — 15 Hz, 60 ms latency (each sample's
//! `time_usec` is its capture time, sent 60 ms later), σ = 2 cm — flies the
//! short L with the shipped controller (multi-rate DF-MPC windows fed by
//! every sample at its capture time on the daemon's clock, smoothness
//! weight, 30° plan-tilt bound). The daemon is told the pipeline's 60 ms
//! (`link.pose_min_latency_ms`), so the clock-offset estimate compensates
//! it. Every SET_ATTITUDE_TARGET must be valid and the true path error
//! within the stated bounds.

#[path = "support/mod.rs"]
mod common;

use std::time::Duration;

use common::*;

const CONFIG: &str = r#"
[link]
pose_source = "vision_position_estimate"
pose_min_latency_ms = 60.0
[mission]
start = "path"
path = [[0.0, 0.0, -10.0], [15.0, 0.0, -10.0], [15.0, 10.0, -10.0]]
speed = 3.0
[logging]
dir = "@DIR@"
tlog = false
[sitl]
plant = "planar"
start = [0.0, 0.0, -10.0]
vision_rate_hz = 15.0
vision_latency_ms = 60.0
vision_noise_sigma = 0.02
"#;

const PATH: [[f64; 3]; 3] = [[0.0, 0.0, -10.0], [15.0, 0.0, -10.0], [15.0, 10.0, -10.0]];
/// Bounds on the true path error \[m\] (median, p95, max) and on the mean
/// tick-to-tick change of the pitch/roll command \[deg\], from the lab's
/// figure for the same controller and sensing: the vision-rate study's
/// `df-mr-smooth` at 15 Hz and 3 m/s on the L has p95 0.124 m and
/// 0.29°/tick (docs/results.md, `dflat experiment vision-rate`). This
/// flight measured median 0.015 m, p95 0.127 m, max 0.386 m, 0.30°/tick
/// (2026-11-26, dev profile); the bounds are 2× the lab's p95 and 3× its
/// step, for a daemon on a shared machine's wall clock.
const MEDIAN_BOUND: f64 = 0.05;
const P95_BOUND: f64 = 0.25;
const MAX_BOUND: f64 = 0.6;
const MEAN_STEP_BOUND_DEG: f64 = 0.9;
/// The end of the path must be reached within this distance \[m\].
const ARRIVAL: f64 = 0.5;

/// Flights at most: a flight whose daemon entered a failsafe is flown
/// again. This test keeps the default 100 ms pose timeout (to assert the
/// daemon's warning about it), under two of 15 Hz vision's intervals: on
/// a starved machine one late pose trips the stale-pose failsafe, which
/// brakes and holds, as it should (docs/safety.md, "Losing pose").
const ATTEMPTS: usize = 3;

/// The flight, flown again (up to [`ATTEMPTS`]) while its daemon spent
/// time in FAILSAFE.
fn fly_without_failsafe() -> Flight {
    let mut attempt = 0;
    loop {
        attempt += 1;
        let flight = fly_in_process(
            &format!("vision-{attempt}"),
            CONFIG,
            Duration::from_secs(11),
        );
        let failsafe_s = flight
            .summary()
            .and_then(|s| s["time_in_state_s"]["failsafe"].as_f64())
            .unwrap_or(0.0);
        if failsafe_s == 0.0 || attempt == ATTEMPTS {
            return flight;
        }
        eprintln!("flight {attempt}: {failsafe_s:.2} s in FAILSAFE (a late pose): flown again");
    }
}

#[test]
fn vision_at_15_hz_flies_the_short_l_with_valid_commands() {
    let flight = fly_without_failsafe();
    assert!(flight.clean_exit, "the daemon did not exit cleanly");
    assert!(
        flight.report.counters.visions_sent > 100,
        "vision samples sent: {}",
        flight.report.counters.visions_sent
    );
    // Every command valid.
    let mut tilts = Vec::new();
    let mut n = 0;
    for (_, d) in flight.attitude_targets() {
        n += 1;
        assert_eq!((d.target_system, d.target_component), (1, 1));
        assert_eq!(d.type_mask.bits(), 7, "type_mask");
        let q = d.q.map(f64::from);
        assert!(q.iter().all(|v| v.is_finite()), "quaternion {q:?}");
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() < 1e-3, "quaternion norm {norm}");
        assert!(
            d.thrust.is_finite() && (0.0..=1.0).contains(&d.thrust),
            "thrust {}",
            d.thrust
        );
        let [roll, pitch, _] = dflat_link::euler_from_quaternion(q);
        // The combined tilt (the cone the guard applies).
        let tilt = dflat_control::tilt::tilt(pitch, roll);
        assert!(
            tilt <= 35.001f64.to_radians(),
            "tilt {:.2}° (roll {roll} pitch {pitch})",
            tilt.to_degrees()
        );
        tilts.push((roll, pitch));
    }
    let expected = flight.streamed_s() * 50.0;
    assert!(
        n as f64 >= 0.9 * expected,
        "{n} attitude targets (≈ {expected:.0} at 50 Hz)"
    );
    let mean_step = tilts
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).abs().max((w[1].1 - w[0].1).abs()))
        .sum::<f64>()
        .to_degrees()
        / (tilts.len().max(2) - 1) as f64;

    // True path error while commanded, until the end is reached.
    let (errors, arrived) = path_errors(&flight.report.trace, &PATH, ARRIVAL);
    assert!(!errors.is_empty(), "no commanded samples");
    let (median, p95, max) = (
        quantile(&errors, 0.5),
        quantile(&errors, 0.95),
        errors.iter().copied().fold(0.0, f64::max),
    );
    eprintln!(
        "vision 15 Hz / 60 ms / 2 cm, short L at 3 m/s: {n} commands, path error median {median:.3} m, \
         p95 {p95:.3} m, max {max:.3} m; mean |Δtilt| {mean_step:.2}°/tick; {} vision samples",
        flight.report.counters.visions_sent
    );
    assert!(arrived, "the end of the path was not reached");
    // The default 100 ms pose timeout is under two of 15 Hz vision's
    // intervals (one lost pose can trip the stale-pose failsafe): the
    // daemon says so, once, when the stream's period has settled.
    let warnings = flight
        .statustexts()
        .filter(|t| t.contains("pose timeout 100ms < 2x period"))
        .count();
    assert_eq!(
        warnings,
        1,
        "the pose timeout's warning: {:?}",
        flight.statustexts().collect::<Vec<_>>()
    );
    assert!(median <= MEDIAN_BOUND, "median {median:.3} m");
    assert!(p95 <= P95_BOUND, "p95 {p95:.3} m");
    assert!(max <= MAX_BOUND, "max {max:.3} m");
    assert!(
        mean_step <= MEAN_STEP_BOUND_DEG,
        "mean |Δtilt| {mean_step:.2}°/tick"
    );
}
