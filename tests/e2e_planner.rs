//! End to end against the SITL: `[sitl.planner]` streams a 6 m circle at
//! 4 m/s (p, v, a, with or without yaw, 20 Hz, from 255/190 to 1/191, as
//! a planner does) once the autopilot is in offboard; the real daemon
//! binary flies it on the planar SITL with the shipped defaults. Judged on
//! the SITL's truth against the planner's own trajectory at the same SITL
//! time: horizontal error p95 ≤ 0.098 m (issue 22), commands smooth, the
//! heading following the stream's yaw; then the stream ends and the
//! vehicle stops smoothly and holds.
//!
//! `cargo test --workspace --test e2e_planner -- --nocapture` prints the
//! figures.

#[path = "support/circle.rs"]
mod circle;
#[path = "support/mod.rs"]
mod common;

use std::time::Duration;

use common::*;
use dflat_sitl::SitlMode;
use nalgebra::Vector3;

/// The budget of issue 22 \[m\].
const CIRCLE_BUDGET_M: f64 = 0.098;
/// The planner's circle (as `[sitl.planner]` below): starts 1 s after
/// offboard, full speed after 3 s, ends after 12 s.
const START: [f64; 3] = [0.0, 0.0, -10.0];

/// The flight: `@YAW@` is `true` or `false` (`sitl.planner.yaw`).
const CONFIG: &str = r#"
[logging]
dir = "@DIR@"
[mission]
start = "hold"
[sitl]
start = [0.0, 0.0, -10.0]
[sitl.planner]
shape = "circle"
size = 6.0
speed = 4.0
ramp_s = 3.0
rate_hz = 20.0
start_after_s = 1.0
duration_s = 12.0
yaw = @YAW@
"#;

fn p95(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * 0.95).round() as usize]
}

/// What a flight gave.
struct Figures {
    /// Horizontal error p95 at full speed \[m\].
    p95: f64,
    /// Largest command step \[deg/tick\].
    step: f64,
    /// Heading error against the stream's yaw at its end \[rad\].
    yaw_err: f64,
    /// Drift over the last second, after the stream ended \[m\].
    drift: f64,
}

fn fly(yaw: bool) -> Figures {
    let name = if yaw { "planner-yaw" } else { "planner" };
    let config = CONFIG.replace("@YAW@", if yaw { "true" } else { "false" });
    let flight = fly_in_process(name, &config, Duration::from_secs(19));
    let report = &flight.report;
    let t0 = report.planner_start.expect("the planner never streamed");
    assert!(
        report.counters.planner_samples > 230,
        "{} samples",
        report.counters.planner_samples
    );
    let circle = circle::circle(4.0, 3.0, START);
    // Position at the sample's start (the planner starts where the vehicle
    // is; the SITL holds START before offboard).
    let offboard: Vec<_> = report
        .trace
        .iter()
        .filter(|s| s.mode == SitlMode::Offboard)
        .collect();
    assert!(offboard.len() > 500, "{} offboard samples", offboard.len());
    // Full speed (2 s after the ramp) until the stream ends.
    let errors: Vec<f64> = offboard
        .iter()
        .filter(|s| s.t >= t0 + 5.0 && s.t <= t0 + 12.0)
        .map(|s| {
            let want = circle.at(s.t - t0).position;
            (Vector3::from(s.position) - want).xy().norm()
        })
        .collect();
    assert!(errors.len() > 300, "{} samples judged", errors.len());
    let e95 = p95(errors);
    // The commands the daemon sent: largest step per tick of the tilt.
    let step = largest_tilt_step_deg(flight.attitude_targets().map(|(_, d)| d));
    // The heading follows the stream's yaw (along the velocity).
    let last_streamed = offboard
        .iter()
        .rfind(|s| s.t <= t0 + 12.0)
        .expect("offboard at the stream's end");
    let want_yaw = circle.at(last_streamed.t - t0).yaw;
    let yaw_err = dflat_link::math::wrap_pi(last_streamed.euler[2] - want_yaw).abs();
    // The stream ended at t0 + 14 s: a smooth stop, then a hold.
    let end = report.trace.last().expect("trace");
    let before_end = report
        .trace
        .iter()
        .rev()
        .find(|s| s.t <= end.t - 1.0)
        .expect("a second before the end");
    let drift = (Vector3::from(end.position) - Vector3::from(before_end.position)).norm();
    eprintln!(
        "planner circle r 6 m, 4 m/s, 20 Hz p/v/a (yaw {yaw}) from the SITL: horizontal error \
         p95 {e95:.4} m; largest command step {step:.2}°/tick; heading error at the stream's \
         end {:.1}°; drift over the last 1 s after the stream ended {drift:.4} m",
        yaw_err.to_degrees()
    );
    assert!(end.t > t0 + 17.0, "flown only to {:.1} s", end.t - t0);
    Figures {
        p95: e95,
        step,
        yaw_err,
        drift,
    }
}

/// Position, velocity and acceleration streamed: within the budget of
/// issue 22 (measured 0.0145 m), smooth, and a smooth stop and hold when
/// the stream ends.
#[test]
fn a_planner_stream_from_the_sitl_is_flown_within_the_budget() {
    let f = fly(false);
    assert!(f.p95 <= CIRCLE_BUDGET_M, "p95 {:.4} m", f.p95);
    assert!(f.step <= 5.0, "command step {:.2}°/tick", f.step);
    assert!(
        f.drift < 0.05,
        "not holding after the stream: {:.3} m in 1 s",
        f.drift
    );
}

/// With the stream's yaw flown (the heading turns with the velocity,
/// 0.67 rad/s): the heading follows, the command stays smooth. The SITL's
/// yaw loop lags the commanded heading (τ 0.1 s) and applies pitch and
/// roll at the *actual* heading, so the thrust axis is off by the lag
/// (PX4 and ArduPilot control the thrust axis of the whole quaternion
/// first): the error is larger than without yaw (measured 0.091 m; bound
/// 0.15 m here).
#[test]
fn a_planner_stream_with_yaw_turns_the_heading_with_it() {
    let f = fly(true);
    assert!(
        f.yaw_err < 10f64.to_radians(),
        "heading {:.1}° off",
        f.yaw_err.to_degrees()
    );
    assert!(f.p95 <= 0.15, "p95 {:.4} m", f.p95);
    assert!(f.step <= 5.0, "command step {:.2}°/tick", f.step);
}
