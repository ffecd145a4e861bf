//! End to end: the daemon's systemd notifications, against a fake
//! `NOTIFY_SOCKET` (a Unix datagram socket this test binds) with
//! `WATCHDOG_USEC` set as systemd sets it for `WatchdogSec=`:
//! `READY=1` once the control loop runs, `STATUS=state …` on every state
//! change, `WATCHDOG=1` from the control loop at a quarter of the watchdog
//! timeout, `STOPPING=1` on SIGINT.

#![cfg(unix)]

#[path = "support/mod.rs"]
mod common;

use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;
use dflat_daemon::config::Config;
use dflat_sitl::{self as sitl, SitlOptions};

/// `WATCHDOG_USEC` given to the daemon: 400 ms → one WATCHDOG=1 per 100 ms.
const WATCHDOG_USEC: u64 = 400_000;

#[test]
fn ready_status_watchdog_and_stopping_reach_the_notify_socket() {
    let dir = scratch("sdnotify");
    let text = format!(
        "[mission]\nstart = \"hold\"\n[logging]\ndir = \"{}\"\ntlog = false\n[sitl]\nstart = [0.0, 0.0, -10.0]\n",
        dir.display()
    );
    let config = write_config(&dir, "sdnotify.toml", &text);
    Config::load(&config).expect("daemon config");
    let sim = sitl::spawn(
        &dflat_sitl::SitlSettings::load(&config).expect("sitl config"),
        SitlOptions {
            link: Some("udpin:127.0.0.1:0".into()),
            ..SitlOptions::default()
        },
    )
    .expect("sitl");
    let sock_path = dir.join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).expect("bind notify socket");
    sock.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let stderr = dir.join("daemon.stderr");
    let child = Command::new(bin())
        .arg("daemon")
        .arg("--config")
        .arg(&config)
        .arg("--link")
        .arg(format!("udpout:{}", sim.local_addr()))
        .env("NOTIFY_SOCKET", &sock_path)
        .env("WATCHDOG_USEC", WATCHDOG_USEC.to_string())
        .env_remove("WATCHDOG_PID")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&stderr).unwrap())
        .spawn()
        .expect("spawn daemon");
    let mut daemon = Proc {
        child,
        name: "daemon",
        stderr,
    };

    let mut messages: Vec<(Instant, String)> = Vec::new();
    // Messages after SIGINT are drained at once once the daemon exited (its
    // stop brakes and levels first): their arrival times say nothing.
    let interrupted: Instant;
    let mut buf = [0u8; 4096];
    let start = Instant::now();
    loop {
        if let Ok(n) = sock.recv(&mut buf) {
            let text = String::from_utf8_lossy(&buf[..n]).into_owned();
            for line in text.lines() {
                messages.push((Instant::now(), line.to_owned()));
            }
        }
        if start.elapsed() > Duration::from_secs(3) {
            interrupted = Instant::now();
            assert!(daemon.interrupt_and_wait(Duration::from_secs(5)));
            // Drain what is left.
            while let Ok(n) = sock.recv(&mut buf) {
                let text = String::from_utf8_lossy(&buf[..n]).into_owned();
                for line in text.lines() {
                    messages.push((Instant::now(), line.to_owned()));
                }
            }
            break;
        }
    }
    sim.stop().expect("sitl stop");
    let lines: Vec<&str> = messages.iter().map(|m| m.1.as_str()).collect();
    let first = |needle: &str| lines.iter().position(|l| l.starts_with(needle));
    let ready = first("READY=1").expect("no READY=1");
    let holding = first("STATUS=state HOLDING").expect("no STATUS=state HOLDING");
    let stopping = first("STOPPING=1").expect("no STOPPING=1");
    assert!(first("STATUS=state WAITING").is_some(), "{lines:?}");
    assert!(ready < holding && holding < stopping, "{lines:?}");
    let watchdogs: Vec<Instant> = messages
        .iter()
        .filter(|m| m.1 == "WATCHDOG=1")
        .map(|m| m.0)
        .filter(|t| *t <= interrupted)
        .collect();
    let longest = watchdogs
        .windows(2)
        .map(|w| w[1] - w[0])
        .max()
        .unwrap_or_default();
    eprintln!(
        "{} notifications, {} WATCHDOG=1, longest gap {:.0} ms",
        lines.len(),
        watchdogs.len(),
        longest.as_secs_f64() * 1e3
    );
    // ≈ 3 s at one per 100 ms.
    assert!(watchdogs.len() >= 20, "{} watchdogs", watchdogs.len());
    // Well within the 400 ms timeout.
    assert!(longest < Duration::from_millis(300), "gap {longest:?}");
}
