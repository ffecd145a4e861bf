//! Fault injection, end to end: the SITL (the autopilot) is killed in
//! flight and restarted on the same port. The daemon stops streaming
//! (FAILSAFE: pose stale), survives the dead peer (ICMP port unreachable
//! on its UDP socket), and recovers to HOLDING once the new SITL's pose and
//! heartbeat arrive. Every command it emitted is finite, within the tilt
//! limit and the thrust range.
//!
//! Real processes over loopback: `dflat sitl` twice, `dflat daemon`.

#[path = "support/mod.rs"]
mod common;

use std::time::{Duration, Instant};

use common::*;

#[test]
fn killed_and_restarted_sitl_failsafe_then_recover_to_holding() {
    let dir = scratch("sitlrestart");
    let text = hold_config(
        &dir,
        r#"
[safety]
# Silent at once in failsafe (the brake and level hover before it are
# e2e_pose_loss_level's): this test is about the restart.
level_hover_max_ms = 0.0
"#,
        "noise_sigma = 0.01",
    );
    let config = write_config(&dir, "sitlrestart.toml", &text);
    let summary_path = dir.join("summary.json");
    let mut sitl = spawn_sitl(&dir, &config, false, &dir.join("truth1.csv"));
    let port = sitl.link;
    let mut daemon = spawn_daemon_with(
        &dir,
        &config,
        port,
        &["--summary-json", summary_path.to_str().unwrap()],
    );
    assert!(
        sitl.wait_for_line("sitl mode offboard", Duration::from_secs(10))
            .is_some(),
        "the daemon never took control"
    );
    std::thread::sleep(Duration::from_secs(1));

    // Kill the autopilot mid-flight.
    let _ = sitl.proc.child.kill();
    let _ = sitl.proc.child.wait();
    let killed = Instant::now();
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        matches!(daemon.child.try_wait(), Ok(None)),
        "the daemon exited when its autopilot died"
    );
    assert!(
        daemon.stderr_text().contains("FAILSAFE"),
        "no failsafe after the autopilot died"
    );

    // Restart it on the same port: the daemon's heartbeat (1 Hz) finds it.
    let restarted = Instant::now();
    let sitl2 = spawn_sitl_on(
        &dir,
        &config,
        &format!("udpin:{port}"),
        false,
        &dir.join("truth2.csv"),
        "sitl2.stderr",
    );
    let line = sitl2.wait_for_line("sitl mode offboard", Duration::from_secs(8));
    assert!(line.is_some(), "the daemon did not re-engage the new SITL");
    eprintln!(
        "killed → restarted {:.1} s; restarted → streaming again {:.1} s",
        (restarted - killed).as_secs_f64(),
        restarted.elapsed().as_secs_f64()
    );
    std::thread::sleep(Duration::from_secs(1));
    assert!(
        daemon.interrupt_and_wait(Duration::from_secs(5)),
        "the daemon did not exit cleanly"
    );
    drop(sitl2);

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary_path).expect("summary"))
            .expect("summary JSON");
    assert_eq!(summary["final_state"], "holding", "{summary:#}");
    let failsafe_s = summary["time_in_state_s"]["failsafe"].as_f64().unwrap();
    assert!(failsafe_s > 1.0, "failsafe only {failsafe_s} s");
    let rows = read_flight_csv(&dir);
    let (n, worst) = check_csv_commands(&rows, MAX_TILT_DEG);
    eprintln!("{n} commands, largest tilt {worst:.2}°, failsafe {failsafe_s:.2} s");
    assert!(n > 100, "only {n} commands");
    // No command while in failsafe (before the stop, whose level phase is
    // one: `guard` = "stop" marks where it began).
    let stop = rows
        .iter()
        .position(|r| r.get("guard").is_some_and(|g| g == "stop"))
        .unwrap_or(rows.len());
    assert!(
        rows[..stop]
            .iter()
            .filter(|r| r["state"] == "FAILSAFE")
            .all(|r| field(r, "roll").is_none()),
        "a command was sent in FAILSAFE"
    );
}
