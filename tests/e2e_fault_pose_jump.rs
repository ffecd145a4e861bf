//! Fault injection, end to end: the reported pose jumps by 5 m (as an
//! estimator reset would make it) while the daemon holds. The daemon sees a
//! jump larger than the vehicle can fly in one tick, re-anchors (controller
//! window reset, reference = hold at the new reported position) and holds:
//! no tilt spike, no command beyond the tilt limit, and the true vehicle
//! does not fly 5 m to undo the jump.
//!
//! The real `dflat daemon` binary against the in-process SITL, whose
//! `set_pose_offset` hook shifts every reported position. The stream's
//! steadiness after the jump is judged on the daemon's records (the CSV's
//! tick times from its `jump` row), not on the test's clock.

#[path = "support/mod.rs"]
mod common;

use std::time::Duration;

use common::*;
use dflat_link::MavMessage;

/// The jump \[m\] (north).
const JUMP: f64 = 5.0;
/// The true vehicle stays within this of where it was at the jump \[m\].
const HOLD_WITHIN: f64 = 1.0;
/// Largest tilt commanded after the jump \[deg\] (a spike would hit 35°).
const TILT_AFTER_JUMP: f64 = 10.0;

#[test]
fn pose_jump_re_anchors_without_a_tilt_spike() {
    let dir = scratch("posejump");
    let text = hold_config(&dir, "", "noise_sigma = 0.01");
    let (config, _) = write_daemon_config(&dir, "posejump.toml", &text);
    let (sim, tap) = tapped_sitl(&config, TapOptions::default());
    let mut daemon = spawn_daemon(&dir, &config, sim.local_addr());

    // Holding steadily for 2 s.
    assert!(
        wait_streaming(&tap, Duration::from_secs(2)),
        "the daemon never streamed"
    );
    let before = sim.truth().position;
    sim.set_pose_offset([JUMP, 0.0, 0.0]);
    std::thread::sleep(Duration::from_secs(3));
    let after = sim.truth().position;
    // The tilt of every command on the wire after the jump.
    let targets: Vec<f64> = tap
        .try_iter()
        .filter_map(|f| match &f.message {
            MavMessage::SET_ATTITUDE_TARGET(d) => Some(quaternion_tilt_deg(d.q)),
            _ => None,
        })
        .collect();
    let worst = targets.iter().copied().fold(0.0, f64::max);
    let moved = dist(before, after);
    assert!(targets.iter().all(|t| t.is_finite()), "non-finite target");
    assert!(worst <= TILT_AFTER_JUMP, "tilt spike {worst:.1}°");
    assert!(
        moved <= HOLD_WITHIN,
        "the vehicle flew {moved:.2} m after the jump"
    );

    assert!(daemon.interrupt_and_wait(Duration::from_secs(5)));
    let report = sim.stop().expect("sitl stop");
    assert!(!report.diverged);
    let rows = read_flight_csv(&dir);
    let (n, _) = check_csv_commands(&rows, MAX_TILT_DEG);
    // Every command the SITL received after the jump is in the record.
    assert!(
        n >= targets.len(),
        "{n} commands recorded, {} received",
        targets.len()
    );
    let jump_rows: Vec<_> = rows
        .iter()
        .filter(|r| r.get("guard").is_some_and(|g| g == "jump"))
        .collect();
    assert_eq!(jump_rows.len(), 1, "expected exactly one re-anchor");
    // A steady stream after it: the commands of the second second after
    // the re-anchor, by the CSV's tick times.
    let t_jump = field(jump_rows[0], "t").expect("the jump row's time");
    let second_second = rows
        .iter()
        .filter(|r| {
            field(r, "t").is_some_and(|t| t > t_jump + 1.0 && t <= t_jump + 2.0)
                && field(r, "roll").is_some()
        })
        .count();
    eprintln!(
        "after the {JUMP} m jump: largest tilt {worst:.2}°, vehicle moved {moved:.3} m, {second_second} commands in the second second (CSV, from t = {t_jump:.3} s)"
    );
    assert!(second_second >= 40, "stream not steady: {second_second}");
    assert!(
        daemon.stderr_text().contains("pose jump"),
        "no pose-jump log line"
    );
    // After the re-anchor the reference is the new reported position.
    let last = rows
        .iter()
        .rev()
        .find(|r| field(r, "ref_x").is_some())
        .unwrap();
    let (rx, x) = (field(last, "ref_x").unwrap(), field(last, "x").unwrap());
    assert!((rx - x).abs() < 0.5, "reference {rx} vs measured {x}");
    assert!(
        (rx - (before[0] + JUMP)).abs() < 0.5,
        "reference {rx} not re-anchored near {}",
        before[0] + JUMP
    );
}
