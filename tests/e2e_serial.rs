//! Serial links, end to end: the daemon flies the SITL through a
//! pseudo-terminal at 921600 baud (`link.url = "serial:PTY:921600"`, the
//! pty bridged to the SITL's UDP port by `support/pty_bridge.rs`, as a
//! MAVLink router bridges a UART; no socat needed).
//!
//! * The "adapter" is pulled mid-flight (the pty closes, its name goes) and
//!   plugged back 0.5 s later (a new pty behind the same name), then again
//!   for 1 s: the daemon says so in one warning per outage, reopens the
//!   port with backoff, and its commands resume within 2 s of the port's
//!   return — judged from the daemon's own `.tlog` (the first
//!   SET_ATTITUDE_TARGET it wrote after the return) and its summary
//!   (`reconnects`). The outages are shorter than the autopilot's command
//!   timeout, so the autopilot never leaves OFFBOARD.
//! * A wrong baud rate (the autopilot's port at 57600, the daemon's at
//!   921600, modelled bit by bit by the bridge): no frame, the bytes counted
//!   as link errors, and one warning that names the baud rate.
//!
//! Real processes: `dflat sitl`, `dflat daemon`.

#[path = "support/mod.rs"]
mod common;
#[path = "support/pty_bridge.rs"]
mod pty_bridge;

use std::path::{Path, PathBuf};
use std::time::Duration;

use common::*;
use dflat_link::MavMessage;
use dflat_link::tlog::TlogReader;
use pty_bridge::{BaudMismatch, PtyBridge};

/// The daemon's and the SITL's configuration: hold at 10 m, records in
/// `dir`, the link a serial port at `link`. The SITL's command timeout
/// (PX4's COM_OF_LOSS_T) is 2 s: longer than the outage.
fn config(dir: &Path, link: &Path) -> PathBuf {
    let text = format!(
        r#"
[link]
url = "serial:{}:921600"
[mission]
start = "hold"
[logging]
dir = "{}"
tlog = true
[sitl]
start = [0.0, 0.0, -10.0]
noise_sigma = 0.01
command_timeout_s = 2.0
"#,
        link.display(),
        dir.display()
    );
    write_config(dir, "serial.toml", &text)
}

/// `dflat daemon --config CONFIG --summary-json SUMMARY` (the link from
/// the configuration: the serial port).
fn spawn_serial_daemon(dir: &Path, config: &Path, summary: &Path) -> Proc {
    let args = [
        "--config".into(),
        config.into(),
        "--summary-json".into(),
        summary.into(),
    ];
    spawn_daemon_args(dir, &args, &[("RUST_LOG", "info")])
}

fn read_summary(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("summary")).expect("summary JSON")
}

/// The UNIX µs timestamps of the SET_ATTITUDE_TARGET frames in the
/// daemon's `.tlog` in `dir` (what it wrote to the port, when).
fn commands_written(dir: &Path) -> Vec<u64> {
    let tlog = std::fs::read_dir(dir)
        .expect("records dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "tlog"))
        .expect("a .tlog");
    let file = std::fs::File::open(&tlog).expect("open tlog");
    TlogReader::new(std::io::BufReader::new(file))
        .map_while(Result::ok)
        .filter(|r| {
            r.parse()
                .is_ok_and(|f| matches!(f.message, MavMessage::SET_ATTITUDE_TARGET(_)))
        })
        .map(|r| r.timestamp_us)
        .collect()
}

#[test]
fn a_replugged_serial_port_is_reopened_and_the_commands_resume() {
    if !pty_bridge::ptys_available() {
        eprintln!("skipped: no pseudo-terminals here (openpty failed)");
        return;
    }
    let dir = scratch("serial-replug");
    let link = dir.join("ttyACM-dflat");
    let config = config(&dir, &link);
    let summary_path = dir.join("summary.json");
    let sitl = spawn_sitl(&dir, &config, false, &dir.join("truth.csv"));
    let bridge = PtyBridge::start(&link, sitl.link);
    let mut daemon = spawn_serial_daemon(&dir, &config, &summary_path);
    assert!(
        sitl.wait_for_line("sitl mode offboard", Duration::from_secs(15))
            .is_some(),
        "the daemon never took control over the serial link"
    );
    // Pull the adapter twice, for 0.5 s and for 1 s, 2 s of flight around
    // each outage: (when it was pulled, when it was back) in UNIX µs.
    let mut outages = Vec::new();
    for gone in [500, 1000] {
        std::thread::sleep(Duration::from_secs(2));
        bridge.unplug();
        let unplugged_us = pty_bridge::unix_us();
        std::thread::sleep(Duration::from_millis(gone));
        outages.push((unplugged_us, bridge.replug()));
    }
    std::thread::sleep(Duration::from_secs(2));
    let mode_changes: Vec<String> = sitl.lines.try_iter().collect();
    assert!(
        daemon.interrupt_and_wait(Duration::from_secs(5)),
        "the daemon did not exit cleanly"
    );
    drop(bridge);
    drop(sitl);

    let summary = read_summary(&summary_path);
    let reconnects = summary["link_guard"]["reconnects"].as_u64().unwrap();
    assert_eq!(reconnects, 2, "two outages, two reopens: {summary:#}");

    let stderr = daemon.stderr_text();
    let lost = stderr.matches("serial port lost").count();
    let reopened = stderr.matches("serial link reopened").count();
    let broken = stderr.matches("Broken pipe").count();
    let write_failed = stderr.matches("serial write failed").count();
    eprintln!(
        "stderr: {lost} 'serial port lost', {reopened} 'reopened', {broken} 'Broken pipe', {} lines",
        stderr.lines().count()
    );
    assert_eq!(lost, 2, "one warning per outage:\n{stderr}");
    assert_eq!(reopened, 2, "each reopen said once:\n{stderr}");
    assert!(
        broken <= 2 && write_failed == 0,
        "per-frame errors:\n{stderr}"
    );

    // The daemon's own record of what it wrote to the port.
    let written = commands_written(&dir);
    let before = written.iter().filter(|&&t| t < outages[0].0).count();
    assert!(
        before > 50,
        "only {before} commands before the first outage"
    );
    for (i, &(unplugged_us, back_us)) in outages.iter().enumerate() {
        let next = outages.get(i + 1).map_or(u64::MAX, |o| o.0);
        let during = written
            .iter()
            .filter(|&&t| t > unplugged_us + 50_000 && t < back_us)
            .count();
        let first_after = written
            .iter()
            .copied()
            .find(|&t| t >= back_us)
            .expect("no command after the port came back");
        let last_before = written
            .iter()
            .copied()
            .filter(|&t| t < back_us)
            .max()
            .unwrap_or(0);
        let after = written
            .iter()
            .filter(|&&t| t >= back_us && t < next)
            .count();
        let resume_s = (first_after - back_us) as f64 / 1e6;
        eprintln!(
            "outage {}: port gone {:.3} s; {during} commands written meanwhile; the first \
             {resume_s:.3} s after the port came back, the autopilot {:.3} s without one; \
             {after} commands until the next outage or the end",
            i + 1,
            (back_us - unplugged_us) as f64 / 1e6,
            (first_after - last_before) as f64 / 1e6,
        );
        assert_eq!(
            during, 0,
            "commands recorded as written while the port was gone"
        );
        assert!(
            resume_s <= 2.0,
            "commands resumed {resume_s:.3} s after the port came back (budget 2 s)"
        );
        assert!(after > 50, "only {after} commands after outage {}", i + 1);
    }

    // The autopilot never fell into its failsafe: no mode change after the
    // daemon took control.
    assert!(
        mode_changes.iter().all(|l| !l.starts_with("sitl mode")),
        "the autopilot changed mode: {mode_changes:?}"
    );
}

#[test]
fn a_wrong_baud_rate_is_counted_as_garbage_and_named_once() {
    if !pty_bridge::ptys_available() {
        eprintln!("skipped: no pseudo-terminals here (openpty failed)");
        return;
    }
    let dir = scratch("serial-baud");
    let link = dir.join("ttyACM-dflat");
    let config = config(&dir, &link);
    let summary_path = dir.join("summary.json");
    let sitl = spawn_sitl(&dir, &config, false, &dir.join("truth.csv"));
    let mismatch = BaudMismatch {
        autopilot: 57_600,
        daemon: 921_600,
    };
    let bridge = PtyBridge::wrong_baud(&link, sitl.link, mismatch);
    let mut daemon = spawn_serial_daemon(&dir, &config, &summary_path);
    // Until the daemon has had 8 KiB of the autopilot's stream (at most 15 s).
    for _ in 0..150 {
        if bridge.bytes_to_daemon() > 8192 {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(300));
    let garbled = bridge.bytes_to_daemon();
    assert!(
        daemon.interrupt_and_wait(Duration::from_secs(5)),
        "the daemon did not exit cleanly"
    );
    drop(bridge);
    drop(sitl);
    assert!(garbled > 8192, "the SITL's stream never reached the daemon");

    let summary = read_summary(&summary_path);
    let l = &summary["link_stats"];
    let frames = l["received"]["total"].as_u64().unwrap();
    let garbage = l["malformed"].as_u64().unwrap() + l["crc_errors"].as_u64().unwrap();
    eprintln!("{garbled} bytes at the wrong rate: {frames} frames, {garbage} framing errors");
    assert_eq!(frames, 0, "frames decoded at the wrong baud rate: {l:#}");
    assert!(garbage > 0, "the garbage was not counted: {l:#}");
    assert_eq!(summary["commands"].as_u64(), Some(0));

    let stderr = daemon.stderr_text();
    let warnings: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("wrong baud rate"))
        .collect();
    assert_eq!(warnings.len(), 1, "one baud-rate warning:\n{stderr}");
    assert!(
        warnings[0].contains("921600"),
        "the warning names the baud rate: {}",
        warnings[0]
    );
}
