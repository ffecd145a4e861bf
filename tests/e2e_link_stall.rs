//! Liveness of the link tasks, end to end: the real `dflat daemon` binary
//! with a fake `NOTIFY_SOCKET` and `WATCHDOG_USEC` (as systemd sets them
//! for `WatchdogSec=`), holding against the in-process SITL. The test-only
//! hook `DFLAT_TEST_STALL_TASK=receive` stalls the receive task 1.5 s after
//! start.
//!
//! Before the stall the control loop sends `WATCHDOG=1` every quarter of
//! the timeout; after it, `WATCHDOG=trigger` once and no `WATCHDOG=1`
//! any more, so systemd's watchdog fires. The HEARTBEATs the SITL receives
//! turn MAV_STATE_CRITICAL and a STATUSTEXT names the task. Then the test
//! does what systemd does (SIGABRT, start again) and the restarted daemon
//! is READY and feeds the watchdog again.

#![cfg(unix)]

#[path = "support/mod.rs"]
mod common;

use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;
use dflat_link::MavMessage;
use dflat_link::dialect::MavState;

/// `WATCHDOG_USEC` given to the daemon: 400 ms → one WATCHDOG=1 per 100 ms.
const WATCHDOG_USEC: u64 = 400_000;
/// When the receive task stalls, after start \[s\].
const STALL_AFTER_S: f64 = 1.5;

fn start_daemon(
    dir: &std::path::Path,
    config: &std::path::Path,
    sitl: std::net::SocketAddr,
    sock: &std::path::Path,
    stall: bool,
    n: u32,
) -> Proc {
    let stderr = dir.join(format!("daemon{n}.stderr"));
    let mut cmd = Command::new(bin());
    cmd.arg("daemon")
        .arg("--config")
        .arg(config)
        .arg("--link")
        .arg(format!("udpout:{sitl}"))
        .env("NOTIFY_SOCKET", sock)
        .env("WATCHDOG_USEC", WATCHDOG_USEC.to_string())
        .env_remove("WATCHDOG_PID")
        .env_remove("DFLAT_TEST_STALL_TASK")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&stderr).unwrap());
    if stall {
        cmd.env("DFLAT_TEST_STALL_TASK", "receive")
            .env("DFLAT_TEST_STALL_AFTER_S", STALL_AFTER_S.to_string());
    }
    Proc {
        child: cmd.spawn().expect("spawn daemon"),
        name: "daemon",
        stderr,
    }
}

/// Notifications received for `window`, with their arrival.
fn collect(sock: &UnixDatagram, window: Duration) -> Vec<(Instant, String)> {
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    let start = Instant::now();
    while start.elapsed() < window {
        if let Ok(n) = sock.recv(&mut buf) {
            for line in String::from_utf8_lossy(&buf[..n]).lines() {
                out.push((Instant::now(), line.to_owned()));
            }
        }
    }
    out
}

#[test]
fn a_stalled_link_task_stops_the_watchdog_and_reports_critical() {
    let dir = scratch("link-stall");
    let text = hold_config(&dir, "", "");
    let (config, _) = write_daemon_config(&dir, "stall.toml", &text);
    let (sim, tap) = tapped_sitl(&config, TapOptions::default());
    let sock_path = dir.join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).expect("bind notify socket");
    sock.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();

    let mut daemon = start_daemon(&dir, &config, sim.local_addr(), &sock_path, true, 1);
    let messages = collect(&sock, Duration::from_millis(3500));
    let lines: Vec<&str> = messages.iter().map(|m| m.1.as_str()).collect();
    let pings: Vec<usize> = (0..lines.len())
        .filter(|&i| lines[i] == "WATCHDOG=1")
        .collect();
    let trigger = lines.iter().position(|l| *l == "WATCHDOG=trigger");
    let silent_for = pings
        .last()
        .map_or(Duration::ZERO, |&i| messages[i].0.elapsed());
    eprintln!(
        "{} WATCHDOG=1 before the stall, trigger at line {trigger:?}, then silent for {:.0} ms (watchdog timeout {} ms)",
        pings.len(),
        silent_for.as_secs_f64() * 1e3,
        WATCHDOG_USEC / 1000
    );
    // The daemon ran and fed the watchdog until the stall ...
    assert!(lines.contains(&"READY=1"), "{lines:?}");
    assert!(pings.len() >= 5, "{lines:?}");
    // ... then asked systemd to act, and fed it no more.
    let trigger = trigger.expect("no WATCHDOG=trigger");
    assert!(pings.iter().all(|&i| i < trigger), "{lines:?}");
    assert!(
        silent_for > Duration::from_micros(WATCHDOG_USEC),
        "last WATCHDOG=1 only {silent_for:?} ago"
    );
    let log = daemon.stderr_text();
    assert!(log.contains("link task stalled"), "{log}");

    // What the autopilot saw: CRITICAL heartbeats and the STATUSTEXT.
    let frames: Vec<_> = tap.try_iter().collect();
    let critical = frames.iter().any(|f| {
        f.header.component_id == 191
            && matches!(&f.message, MavMessage::HEARTBEAT(h) if h.system_status == MavState::MAV_STATE_CRITICAL)
    });
    let text = frames.iter().any(|f| {
        matches!(&f.message, MavMessage::STATUSTEXT(t)
            if t.text.to_str().unwrap_or("").contains("link task receive stalled"))
    });
    eprintln!("autopilot saw CRITICAL heartbeat: {critical}, STATUSTEXT: {text}");
    assert!(critical, "no MAV_STATE_CRITICAL heartbeat");
    assert!(text, "no STATUSTEXT naming the stalled task");

    // systemd's watchdog action: SIGABRT, then Restart=on-failure.
    daemon.signal("ABRT");
    let _ = daemon.child.wait();
    let mut again = start_daemon(&dir, &config, sim.local_addr(), &sock_path, false, 2);
    let after = collect(&sock, Duration::from_millis(1500));
    let lines: Vec<&str> = after.iter().map(|m| m.1.as_str()).collect();
    assert!(lines.contains(&"READY=1"), "{lines:?}");
    assert!(
        lines.iter().filter(|l| **l == "WATCHDOG=1").count() >= 5,
        "{lines:?}"
    );
    assert!(!lines.contains(&"WATCHDOG=trigger"), "{lines:?}");
    assert!(again.interrupt_and_wait(Duration::from_secs(5)));
    sim.stop().expect("sitl stop");
}
