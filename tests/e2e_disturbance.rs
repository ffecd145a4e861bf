//! End to end (issue 5): the SITL vehicle is not the configured one — its
//! hover thrust is 0.4 where `[vehicle]` says 0.5 (25 % more thrust per
//! command) and it is 10 % lighter, so it hovers at 0.36, 28 % below the
//! configured 0.5 (without the estimator the altitude settles ~1 m off;
//! a heavier vehicle would partly cancel the thrust error, hiding the
//! mismatch) — and the daemon runs DF-MPC with the
//! disturbance estimator (`controller.disturbance.enabled = true`), spatial model
//! against the spatial plant. A 10 m step north (a two-waypoint path flown
//! at 20 m/s: the reference reaches the end within 0.5 s) must settle
//! within 0.3 m of the setpoint in all three axes, and the per-flight CSV
//! must carry the estimate.

#[path = "support/mod.rs"]
mod common;

use std::time::Duration;

use common::*;

/// A 10 m straight at 20 m/s on the spatial model with the disturbance
/// estimator, against a spatial plant 10 % lighter whose hover thrust is
/// 0.4 (the model's 0.5).
fn config() -> String {
    let sitl = "[sitl]\nplant = \"spatial\"\nhover_thrust = 0.4\nmass_factor = 0.9\nstart = [0.0, 0.0, -10.0]";
    format!(
        r#"
{realtime}
[mission]
start = "path"
path = [[0.0, 0.0, -10.0], [10.0, 0.0, -10.0]]
speed = 20.0
[safety]
# The path's speed is within the envelope's limit.
max_speed_mps = 20.0
[logging]
dir = "@DIR@"
tlog = false
[controller.disturbance]
enabled = true
{SPATIAL_VEHICLE}{sitl}
"#,
        realtime = realtime_if_granted(),
    )
}

const SETPOINT: [f64; 3] = [10.0, 0.0, -10.0];
/// Largest error per axis over the last [`WINDOW`] of the flight \[m\].
const BOUND: f64 = 0.3;
/// The settled window at the end of the flight \[s\].
const WINDOW: f64 = 2.0;

fn fly_and_check(name: &str, config: &str) -> [f64; 3] {
    let flight = fly_in_process(name, config, Duration::from_secs(14));
    assert!(flight.clean_exit, "{name}: the daemon did not exit cleanly");
    let trace = &flight.report.trace;
    let t_end = trace.last().expect("trace").t;
    let mut worst = [0.0f64; 3];
    for s in trace.iter().filter(|s| s.t >= t_end - WINDOW) {
        assert!(s.command.is_some(), "{name}: not commanded at t = {}", s.t);
        for (i, w) in worst.iter_mut().enumerate() {
            *w = w.max((s.position[i] - SETPOINT[i]).abs());
        }
    }
    eprintln!(
        "{name}: error over the last {WINDOW} s: x {:.3} m, y {:.3} m, z {:.3} m",
        worst[0], worst[1], worst[2]
    );
    worst
}

#[test]
fn ten_metre_step_settles_within_0_3_m_despite_wrong_hover_thrust_and_mass() {
    let worst = fly_and_check("disturbance", &config());
    assert!(
        worst.iter().all(|e| *e <= BOUND),
        "not settled within {BOUND} m: {worst:?}"
    );
    // The estimate is in the per-flight CSV.
    let dir = scratch_dir("disturbance");
    let csv = std::fs::read_dir(&dir)
        .expect("records dir")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "csv"))
        .expect("flight CSV");
    let text = std::fs::read_to_string(&csv).expect("read CSV");
    let header: Vec<&str> = text.lines().next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (scale, hover, status) = (col("thrust_scale"), col("hover_thrust"), col("est_status"));
    let last = text
        .lines()
        .rev()
        .map(|l| l.split(',').collect::<Vec<_>>())
        .find(|f| f.get(status).is_some_and(|s| !s.is_empty()))
        .expect("a row with an estimate");
    let kappa: f64 = last[scale].parse().expect("thrust scale");
    let hover_n: f64 = last[hover].parse().expect("hover thrust");
    eprintln!(
        "estimate at the end: thrust scale {kappa:.3}, hover thrust {hover_n:.3}, status {}",
        last[status]
    );
    // Thrust per command 1.25×, mass 0.9×: κ = 1.25/0.9 ≈ 1.39, hover ≈ 0.36.
    assert!((kappa - 1.25 / 0.9).abs() < 0.05, "thrust scale {kappa}");
    assert!(
        (hover_n - 0.5 * 0.9 / 1.25).abs() < 0.03,
        "hover thrust {hover_n}"
    );
}
