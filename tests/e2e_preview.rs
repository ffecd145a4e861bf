//! End to end, preview (issue 39): a planner's trajectory streamed as
//! 20 Hz p/v/a samples, flown by the real daemon against the SITL, and the
//! same stream flown by the SITL's own position loop (PD with velocity and
//! acceleration feed-forward, `sitl.planner.anchor`) on the same plant in
//! the same test: the anchor the issue measures dflat against.
//!
//! What is asserted here is what holds today: the circle within its
//! budget (0.098 m, issue 22) and below the anchor, every flight's command
//! step ≤ 5°/tick. The figure eight's figures are printed next to the
//! anchor's (`-- --nocapture`); the eight's budget of issue 39 (p95 ≤ 0.3×
//! the anchor's) is not met yet and is not asserted (docs/results.md).

#[path = "support/mod.rs"]
mod common;

use std::time::{Duration, Instant};

use common::*;
use dflat_sim::trajectory::{Shape, Trajectory};
use dflat_sitl::{self as sitl, SitlMode, SitlOptions, SitlReport};
use nalgebra::Vector3;

const START: [f64; 3] = [0.0, 0.0, -10.0];
const DURATION_S: f64 = 16.0;
const RAMP_S: f64 = 3.0;

fn config(shape: &str, size: f64, speed: f64, anchor: bool) -> String {
    config_jerk(shape, size, speed, anchor, 0.5)
}

/// As [`config`], with `stream.jerk_horizon_s = jerk`.
fn config_jerk(shape: &str, size: f64, speed: f64, anchor: bool, jerk: f64) -> String {
    format!(
        r#"
[stream]
jerk_horizon_s = {jerk}
[logging]
dir = "@DIR@"
tlog = false
[mission]
start = "hold"
[sitl]
start = [0.0, 0.0, -10.0]
[sitl.planner]
shape = "{shape}"
size = {size}
speed = {speed}
ramp_s = {RAMP_S}
rate_hz = 20.0
start_after_s = 1.0
duration_s = {DURATION_S}
yaw = false
anchor = {anchor}
"#
    )
}

/// Horizontal error p95 at full speed against the planner's trajectory
/// \[m\], and the largest commanded tilt step \[deg/tick\].
fn judge(report: &SitlReport, trajectory: &Trajectory) -> (f64, f64, usize) {
    let t0 = report.planner_start.expect("the planner never streamed");
    let mut errors: Vec<f64> = report
        .trace
        .iter()
        .filter(|s| s.mode == SitlMode::Offboard)
        .filter(|s| s.t >= t0 + RAMP_S + 2.0 && s.t <= t0 + DURATION_S)
        .map(|s| {
            let want = trajectory.at(s.t - t0).position;
            (Vector3::from(s.position) - want).xy().norm()
        })
        .collect();
    let n = errors.len();
    assert!(n > 300, "{n} samples judged");
    errors.sort_by(f64::total_cmp);
    let p95 = errors[((n - 1) as f64 * 0.95).round() as usize];
    // The command the autopilot flew, tick to tick (50 Hz commands).
    let commands: Vec<(f64, f64)> = report
        .trace
        .iter()
        .filter(|s| s.t >= t0 && s.t <= t0 + DURATION_S)
        .filter_map(|s| s.command.map(|c| (c.pitch, c.roll)))
        .collect();
    let step = commands
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).abs().max((w[1].1 - w[0].1).abs()))
        .fold(0.0, f64::max)
        .to_degrees();
    (p95, step, n)
}

/// The daemon flies the stream: p95 and its largest command step.
fn daemon_flight(name: &str, text: &str) -> (SitlReport, f64) {
    let flight = fly_in_process(name, text, Duration::from_secs_f64(DURATION_S + 3.0));
    // The stream's flight: from the first command to the stream's end
    // (the planner starts 1 s after offboard); the stop after it apart.
    let first = flight.attitude_targets().next().map(|(f, _)| f.at).unwrap();
    let stream_end = first + Duration::from_secs_f64(DURATION_S + 1.0);
    let tilts: Vec<(f64, f64)> = flight
        .attitude_targets()
        .filter(|(f, _)| f.at <= stream_end)
        .map(|(_, d)| {
            let [w, x, y, z] = d.q.map(f64::from);
            let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
            let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
            (roll, pitch)
        })
        .collect();
    let all: Vec<(f64, f64, f64)> = flight
        .attitude_targets()
        .map(|(f, d)| {
            let [w, x, y, z] = d.q.map(f64::from);
            let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
            let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
            (f.at.duration_since(first).as_secs_f64(), roll, pitch)
        })
        .collect();
    if let Some(w) = all.windows(2).max_by(|a, b| {
        let s = |w: &[(f64, f64, f64)]| (w[1].1 - w[0].1).abs().max((w[1].2 - w[0].2).abs());
        s(a).total_cmp(&s(b))
    }) {
        println!(
            "largest step of the whole flight at {:.2} s: {:?} -> {:?} (of {:.2} s)",
            w[1].0,
            (w[0].1.to_degrees(), w[0].2.to_degrees()),
            (w[1].1.to_degrees(), w[1].2.to_degrees()),
            all.last().unwrap().0
        );
    }
    let step = tilts
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).abs().max((w[1].1 - w[0].1).abs()))
        .fold(0.0, f64::max)
        .to_degrees();
    (flight.report, step)
}

/// The SITL's own position loop flies the same stream (no daemon).
fn anchor_flight(name: &str, shape: &str, size: f64, speed: f64) -> SitlReport {
    let dir = scratch(name);
    let text = config(shape, size, speed, true).replace("@DIR@", &dir.display().to_string());
    let path = write_config(&dir, &format!("{name}.toml"), &text);
    let sim = sitl::spawn(
        &dflat_sitl::SitlSettings::load(&path).expect("sitl config"),
        SitlOptions {
            link: Some("udpin:127.0.0.1:0".into()),
            record_trace: true,
            ..SitlOptions::default()
        },
    )
    .expect("sitl");
    let until = Instant::now() + Duration::from_secs_f64(DURATION_S + 3.0);
    while Instant::now() < until {
        std::thread::sleep(Duration::from_millis(100));
    }
    sim.stop().expect("sitl stop")
}

fn compare(name: &str, shape: &str, kind: Shape, size: f64, speed: f64) -> (f64, f64, f64) {
    compare_jerk(name, shape, kind, size, speed, 0.5)
}

fn compare_jerk(
    name: &str,
    shape: &str,
    kind: Shape,
    size: f64,
    speed: f64,
    jerk: f64,
) -> (f64, f64, f64) {
    let trajectory = Trajectory {
        shape: kind,
        size,
        speed,
        ramp_s: RAMP_S,
        start: Vector3::from(START),
    };
    let anchor = anchor_flight(&format!("{name}-anchor"), shape, size, speed);
    let (a95, a_step, _) = judge(&anchor, &trajectory);
    let text = config_jerk(shape, size, speed, false, jerk);
    let (report, d_step) = daemon_flight(&format!("{name}-dflat"), &text);
    let (d95, _, n) = judge(&report, &trajectory);
    println!(
        "{name} ({shape}, size {size} m, speed {speed} m/s, 20 Hz p/v/a, jerk horizon {jerk} s): dflat p95 {d95:.4} m \
         (largest command step {d_step:.2}°/tick), anchor PD+FF p95 {a95:.4} m (step {a_step:.2}°/tick); \
         ratio {:.2}; {n} samples",
        d95 / a95
    );
    (d95, a95, d_step)
}

#[test]
fn the_circle_is_flown_within_budget_and_better_than_the_anchor() {
    let (d95, a95, step) = compare("preview-circle", "circle", Shape::Circle, 6.0, 4.0);
    assert!(d95 <= 0.098, "circle p95 {d95} m");
    assert!(
        d95 < a95,
        "dflat {d95} m not better than the anchor's {a95} m"
    );
    assert!(step <= 5.0, "command step {step}°/tick");
}

#[test]
fn the_figure_eight_is_flown_smoothly_beside_its_anchor() {
    let (d95, a95, step) = compare(
        "preview-eight",
        "figure_eight",
        Shape::FigureEight,
        8.0,
        4.0,
    );
    assert!(a95.is_finite() && d95.is_finite());
    assert!(step <= 5.0, "command step {step}°/tick");
    // Not yet the issue's budget (0.3× the anchor): reported, not asserted.
}

/// The same eight with the stream's jerk not used (`stream.jerk_horizon_s
/// = 0`: a coordinated turn at each sample's curvature, the prediction
/// before issue 39): `cargo test -p dflat-e2e --test e2e_preview --
/// --ignored --nocapture` prints it beside its anchor.
#[test]
#[ignore = "a comparison for docs/results.md, 40 s"]
fn the_figure_eight_without_the_jerk() {
    let (d95, a95, _) = compare_jerk(
        "preview-eight-nojerk",
        "figure_eight",
        Shape::FigureEight,
        8.0,
        4.0,
        0.0,
    );
    assert!(d95.is_finite() && a95.is_finite());
}
