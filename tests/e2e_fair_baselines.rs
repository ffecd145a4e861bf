//! End to end: the daemon's baselines are flyable. The paper's
//! L path (`config/default.toml`'s: 20 m north, then 30 m east, z = −10 m)
//! at 5 m/s against the in-process SITL with its vision stand-in — 15 Hz,
//! 60 ms latency, σ = 2 cm — flown by DF-MPC (as shipped), Flatness MPC and
//! PD (slowing for corners, the default), the baselines fed by their state
//! estimator (the default `[controller.estimator]`), and the paper's PD
//! (`controller.pd.corner_radius = 0`) as the anchor for what slowing buys. The four
//! flights run at once (separate daemons and SITLs, ephemeral ports).
//!
//! Judged from the SITL's truth trace and the commands the daemon sent
//! (no wall-clock figure): cross-track p95 of the true position from the
//! first command until the path end is reached, the mean command step
//! ‖Δ(pitch, roll)‖ per SET_ATTITUDE_TARGET, and the share of commands at
//! the 35° tilt limit.

#[path = "support/mod.rs"]
mod common;

use std::time::Duration;

use common::*;

const PATH: [[f64; 3]; 3] = [
    [-20.0, -30.0, -10.0],
    [0.0, -30.0, -10.0],
    [0.0, 0.0, -10.0],
];
/// The end counts as reached within this distance \[m\].
const ARRIVAL: f64 = 1.0;
/// The issue's bounds: cross-track p95 \[m\], mean command step \[deg per
/// tick\], share of commands at the tilt limit.
const FMPC_P95: f64 = 1.0;
const MEAN_STEP_DEG: f64 = 5.0;
const SATURATED_SHARE: f64 = 0.10;
/// PD's bound \[m\], the issue's. PD has no preview: flown through the
/// corner at 5 m/s it starts to turn there, and with 35° of tilt
/// (g·tan 35° = 6.9 m/s²) the tightest turn has a radius of v²/a = 3.6 m
/// (the paper's PD, `pd_corner_radius = 0`, measured p95 3.0 m, 14 % at
/// the limit). The daemon's PD slows for the corner as PX4's mission mode
/// does (`controller.pd.corner_radius`, default 1 m) and meets it.
const PD_P95: f64 = 2.0;
/// Tilt limit (`vehicle.max_tilt_deg`) and how close counts as at it \[deg\].
const TILT_LIMIT_DEG: f64 = 35.0;
const AT_LIMIT_DEG: f64 = 0.05;

/// The configuration flown by `name`: a controller kind, or `pd-paper`,
/// the paper's PD (no slowing for corners).
fn config(name: &str) -> String {
    let (kind, corner_radius) = match name {
        "pd-paper" => ("pd", 0.0),
        k => (k, 1.0),
    };
    format!(
        r#"
[link]
pose_source = "vision_position_estimate"
pose_min_latency_ms = 60.0
[controller]
kind = "{kind}"
[controller.pd]
corner_radius = {corner_radius:?}
[mission]
start = "path"
path = [[-20.0, -30.0, -10.0], [0.0, -30.0, -10.0], [0.0, 0.0, -10.0]]
speed = 5.0
[logging]
dir = "@DIR@"
tlog = false
[sitl]
plant = "planar"
start = [-20.0, -30.0, -10.0]
vision_rate_hz = 15.0
vision_latency_ms = 60.0
vision_noise_sigma = 0.02
[safety]
pose_timeout_ms = {POSE_TIMEOUT_MS:?}
"#
    )
}

/// `safety.pose_timeout_ms` for these flights \[ms\]: 15 Hz vision leaves
/// ~67 ms between poses against the default 100 ms, and with four flights
/// at once on a starved machine a late pose sent Flatness MPC's daemon to
/// the stale-pose failsafe mid-path (it held and never reached the end).
/// This test is about the controllers, not the failsafe (docs/safety.md,
/// "Losing pose"); [`fly`] asserts none was entered.
const POSE_TIMEOUT_MS: f64 = 300.0;

/// What one flight showed.
#[derive(Debug, Clone, Copy)]
struct Figures {
    mean: f64,
    p95: f64,
    max: f64,
    mean_step_deg: f64,
    saturated: f64,
    commands: usize,
    arrived: bool,
}

fn fly(kind: &str) -> Figures {
    // L at 5 m/s: 50 m / 5 m/s + the 3 m/s² start ramp ≈ 11 s; the flight
    // ends 3 s after the end is reached (as the fixed 15 s did), or at 40 s
    // after the first command should it never be (under the full suite's
    // load, a fixed 15 s once ended DF-MPC's flight on its first leg).
    let until = FlightEnd {
        fly: Duration::from_secs(40),
        cap: Duration::from_secs(50),
        settle: Duration::from_secs(3),
    };
    let flight = fly_in_process_until(&format!("fair-{kind}"), &config(kind), until, |p| {
        dist(p, PATH[2]) < ARRIVAL
    });
    assert!(flight.clean_exit, "{kind}: the daemon did not exit cleanly");
    flight.assert_no_failsafe(kind);
    // 300 ms is over two of the stream's intervals: no warning.
    assert!(
        !flight.statustexts().any(|t| t.contains("pose timeout")),
        "{kind}: {:?}",
        flight.statustexts().collect::<Vec<_>>()
    );
    let mut tilts = Vec::new();
    for (_, d) in flight.attitude_targets() {
        let q = d.q.map(f64::from);
        assert!(q.iter().all(|v| v.is_finite()), "{kind}: quaternion {q:?}");
        let [roll, pitch, _] = dflat_link::euler_from_quaternion(q);
        tilts.push((roll, pitch));
    }
    let commands = tilts.len();
    let steps: Vec<f64> = tilts
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1).to_degrees())
        .collect();
    let mean_step_deg = steps.iter().sum::<f64>() / steps.len().max(1) as f64;
    let at_limit = tilts
        .iter()
        .filter(|(r, p)| {
            dflat_control::tilt::tilt(*p, *r).to_degrees() >= TILT_LIMIT_DEG - AT_LIMIT_DEG
        })
        .count();
    let saturated = at_limit as f64 / commands.max(1) as f64;

    let trace = &flight.report.trace;
    let (errors, arrived) = path_errors(trace, &PATH, ARRIVAL);
    if !arrived {
        // What the daemon said (state changes, failsafes): the diagnosis of
        // a flight that did not get to the end in 40 s.
        let texts: Vec<String> = flight.statustexts().collect();
        let last = trace.last().map(|s| s.position);
        eprintln!("{kind}: not at the end; last position {last:?}; the daemon said {texts:?}");
    }
    Figures {
        mean: errors.iter().sum::<f64>() / errors.len().max(1) as f64,
        p95: quantile(&errors, 0.95),
        max: errors.iter().copied().fold(0.0, f64::max),
        mean_step_deg,
        saturated,
        commands,
        arrived,
    }
}

#[test]
fn estimator_fed_baselines_fly_the_l_at_5_mps_and_df_mpc_stays_lowest() {
    let kinds = ["df-mpc", "fmpc", "pd", "pd-paper"];
    let figures: Vec<Figures> = std::thread::scope(|s| {
        let handles: Vec<_> = kinds.iter().map(|k| s.spawn(move || fly(k))).collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("flight thread"))
            .collect()
    });
    for (k, f) in kinds.iter().zip(&figures) {
        eprintln!(
            "{k:>6}: L at 5 m/s, vision 15 Hz / 60 ms / 2 cm: cross-track mean {:.3} m, p95 {:.3} m, \
             max {:.3} m; mean command step {:.2}°/tick; {:.1} % of {} commands at the {TILT_LIMIT_DEG}° limit; \
             arrived {}",
            f.mean,
            f.p95,
            f.max,
            f.mean_step_deg,
            100.0 * f.saturated,
            f.commands,
            f.arrived
        );
    }
    for (k, f) in kinds.iter().zip(&figures).take(3) {
        assert!(f.commands > 300, "{k}: {} commands", f.commands);
        assert!(f.arrived, "{k}: the end of the path was not reached");
        assert!(
            f.mean_step_deg <= MEAN_STEP_DEG,
            "{k}: mean command step {:.2}°/tick",
            f.mean_step_deg
        );
        assert!(
            f.saturated <= SATURATED_SHARE,
            "{k}: {:.1} % of commands at the tilt limit",
            100.0 * f.saturated
        );
    }
    let (df, fmpc, pd, paper) = (figures[0], figures[1], figures[2], figures[3]);
    assert!(fmpc.p95 <= FMPC_P95, "fmpc p95 {:.3} m", fmpc.p95);
    assert!(pd.p95 <= PD_P95, "pd p95 {:.3} m", pd.p95);
    // The paper's PD, in the same run: slowing for the corner is what
    // brings PD under the bound (its turn radius, not its gains).
    assert!(
        paper.p95 > PD_P95 && paper.p95 > 2.0 * pd.p95,
        "the paper's PD p95 {:.3} m against {:.3} m slowing for corners",
        paper.p95,
        pd.p95
    );
    assert!(
        df.p95 < fmpc.p95 && df.p95 < pd.p95,
        "df-mpc p95 {:.3} m is not the lowest (fmpc {:.3}, pd {:.3})",
        df.p95,
        fmpc.p95,
        pd.p95
    );
}
