//! End to end: a short L path flown by the real daemon against the real
//! SITL stays within a stated true path error.
//!
//! `dflat sitl` + `dflat daemon` (mission "path") over loopback UDP; the
//! path error is the distance of the SITL's *true* position (truth CSV) to
//! the polyline, from the first command until the vehicle reaches the end.

#[path = "support/mod.rs"]
mod common;

use std::time::{Duration, Instant};

use common::*;
use dflat_sitl::read_truth_csv;

/// The short L: 15 m north, then 10 m east, at z = −10 m.
const PATH: [[f64; 3]; 3] = [[0.0, 0.0, -10.0], [15.0, 0.0, -10.0], [15.0, 10.0, -10.0]];
/// Speed along it [m/s].
const SPEED: f64 = 3.0;
/// Bounds on the true path error \[m\], with 1 cm position noise (the
/// shipped tuning: multi-rate DF-MPC, q = 1, r = 0.003, s = 50, 30° plan
/// tilt). Measured (dev profile, 2-core shared VM, 3 runs, 2026-11-24):
/// median 0.007 m, p95 0.134 m, max 0.379 m — the corner dominates the
/// tail; at σ = 0 the figures are the same to the millimetre, at σ = 5 cm
/// the median is 0.019 m. Bounds: 3× the median, 2× the p95, 1.6× the max
/// (a loaded CI machine delays ticks; the corner error grows with it).
const MEDIAN_BOUND: f64 = 0.02;
const P95_BOUND: f64 = 0.27;
const MAX_BOUND: f64 = 0.6;
/// The end counts as reached within this distance \[m\].
const ARRIVAL: f64 = 0.5;

#[test]
fn short_l_path_stays_within_the_stated_path_error() {
    let dir = scratch("lpath");
    let text = path_config(&dir, &PATH, SPEED, "", PLANAR_NOISY);
    let (mut sitl, mut daemon, truth) = start_flight(&dir, "lpath.toml", &text, false);
    // Path time 25 m / 3 m/s ≈ 8.3 s; stop at arrival + 1 s or after 20 s.
    let started = Instant::now();
    let mut arrived: Option<Instant> = None;
    while started.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(200));
        let rows = read_truth_csv(&truth).unwrap_or_default();
        if arrived.is_none()
            && rows
                .last()
                .is_some_and(|r| r.commanded && dist(r.position, PATH[2]) < ARRIVAL)
        {
            arrived = Some(Instant::now());
        }
        if arrived.is_some_and(|a| a.elapsed() > Duration::from_secs(1)) {
            break;
        }
    }
    assert!(
        daemon.interrupt_and_wait(Duration::from_secs(5)),
        "daemon did not exit cleanly"
    );
    assert!(
        sitl.proc.interrupt_and_wait(Duration::from_secs(5)),
        "SITL did not exit cleanly"
    );
    assert!(
        arrived.is_some(),
        "the vehicle did not reach the end of the path in 20 s"
    );

    let rows = read_truth_csv(&truth).expect("truth CSV");
    let first = rows
        .iter()
        .position(|r| r.commanded)
        .expect("commanded rows");
    let errors: Vec<f64> = rows[first..]
        .iter()
        .map(|r| path_distance(&PATH, r.position))
        .collect();
    let (median, p95, max) = (
        quantile(&errors, 0.5),
        quantile(&errors, 0.95),
        errors.iter().copied().fold(0.0, f64::max),
    );
    eprintln!(
        "short L at {SPEED} m/s: true path error median {median:.3} m, p95 {p95:.3} m, max {max:.3} m ({} samples)",
        errors.len()
    );
    assert!(
        median <= MEDIAN_BOUND,
        "median path error {median:.3} m > {MEDIAN_BOUND} m"
    );
    assert!(
        p95 <= P95_BOUND,
        "p95 path error {p95:.3} m > {P95_BOUND} m"
    );
    assert!(
        max <= MAX_BOUND,
        "max path error {max:.3} m > {MAX_BOUND} m"
    );
}
