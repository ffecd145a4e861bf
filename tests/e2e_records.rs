//! End to end: the flight records survive a crash and disk trouble never
//! grounds the vehicle (issue 23, item 3).
//!
//! The real `dflat daemon` binary against the in-process SITL (which taps
//! every frame the daemon sends):
//! * **SIGKILL** mid-flight: the CSV and the `.tlog` reach ≤ 1.5 s before
//!   the kill — judged on the daemon's own clock: its last command's
//!   `time_boot_ms` as the SITL received it, against the CSV's last
//!   `t_wake` and the `.tlog`'s last command — and `dflat review`,
//!   `dflat identify` and `dflat replay` succeed on them;
//! * **a small file system fills up** during the flight (a 64 KiB tmpfs
//!   in a private mount namespace, `unshare -m`; where that is not
//!   allowed, a file-size limit with SIGXFSZ ignored, which fails writes
//!   with EFBIG the same way): the daemon keeps flying, says so once (log
//!   and STATUSTEXT) and counts the drops;
//! * **the records directory is read-only at start** (a read-only tmpfs;
//!   where mounting is not allowed, a directory under `/proc`, which not
//!   even root can create): the daemon flies without records, says so
//!   once, and its summary says why.

#[path = "support/mod.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use common::*;
use dflat_link::MavMessage;
use dflat_link::tlog::TlogReader;
use dflat_sitl::{self as sitl, SitlHandle, SitlOptions, TapFrame};
use dflat_tuning::flightlog::FlightCsv;

/// The daemon's side: the spatial model (what `dflat identify` fits),
/// the identification manoeuvre as the mission.
fn config_text(records_dir: &Path) -> String {
    format!(
        r#"
[logging]
dir = "{}"
tlog = true
csv = true
[vehicle]
model = "spatial"
thrust_mode = "normalized"
{}
[sitl]
plant = "spatial"
start = [0.0, 0.0, -10.0]
noise_sigma = 0.005
"#,
        records_dir.display(),
        dflat_tuning::identify::manoeuvre_mission([0.0, 0.0, -10.0])
    )
}

fn start_sitl(config: &Path) -> (SitlHandle, Receiver<TapFrame>) {
    let (tx, tap) = channel();
    let sim = sitl::spawn(
        &dflat_sitl::SitlSettings::load(config).expect("sitl config"),
        SitlOptions {
            link: Some("udpin:127.0.0.1:0".into()),
            tap: Some(tx),
            ..SitlOptions::default()
        },
    )
    .expect("sitl");
    (sim, tap)
}

/// The daemon's SET_ATTITUDE_TARGETs (arrival, `time_boot_ms`) and
/// STATUSTEXTs (arrival, text) among the tapped frames.
type Stamped<T> = Vec<(Instant, T)>;

fn daemon_frames(tap: &Receiver<TapFrame>) -> (Stamped<u32>, Stamped<String>) {
    let mut commands = Vec::new();
    let mut texts = Vec::new();
    for f in tap.try_iter() {
        if f.header.component_id != 191 {
            continue;
        }
        match &f.message {
            MavMessage::SET_ATTITUDE_TARGET(d) => commands.push((f.at, d.time_boot_ms)),
            MavMessage::STATUSTEXT(s) => {
                texts.push((f.at, s.text.to_str().unwrap_or("").to_owned()));
            }
            _ => {}
        }
    }
    (commands, texts)
}

fn only_file(dir: &Path, ext: &str) -> PathBuf {
    let v: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("records dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == ext))
        .collect();
    assert_eq!(v.len(), 1, "one .{ext} in {}: {v:?}", dir.display());
    v[0].clone()
}

fn dflat(args: &[&str]) -> String {
    String::from_utf8_lossy(&common::dflat_ok(args).stderr).into_owned()
}

#[test]
fn after_sigkill_the_records_reach_the_kill_and_the_tools_read_them() {
    let dir = scratch("records-kill");
    let records = dir.join("flights");
    let config = write_config(&dir, "kill.toml", &config_text(&records));
    let (sim, tap) = start_sitl(&config);
    let mut daemon = spawn_daemon(&dir, &config, sim.local_addr());
    // 9 s into the flight, as in the issue.
    std::thread::sleep(Duration::from_secs(9));
    daemon.child.kill().expect("SIGKILL"); // SIGKILL on Unix
    let _ = daemon.child.wait();
    std::thread::sleep(Duration::from_millis(100));
    let (commands, _) = daemon_frames(&tap);
    let _ = sim.stop();
    let &(_, last_ms) = commands.last().expect("the daemon flew");
    assert!(commands.len() > 200, "{} commands", commands.len());
    let killed_at = f64::from(last_ms) / 1000.0; // the daemon's clock at the kill

    // The CSV: its last row's tick time (same clock).
    let csv_path = only_file(&records, "csv");
    let csv = FlightCsv::read(&csv_path).expect("CSV readable");
    let t_wake = csv.numbers("t_wake");
    let last_row = t_wake.iter().rev().flatten().next().copied().expect("rows");
    let csv_lag = killed_at - last_row;
    // The tlog: its last command's time_boot_ms.
    let tlog_path = only_file(&records, "tlog");
    let file = std::fs::File::open(&tlog_path).unwrap();
    let mut tlog_last_ms = None;
    let mut frames = 0;
    for record in TlogReader::new(std::io::BufReader::new(file)) {
        let Ok(record) = record else { break };
        frames += 1;
        if let Ok(frame) = record.parse()
            && let MavMessage::SET_ATTITUDE_TARGET(d) = &frame.message
        {
            tlog_last_ms = Some(d.time_boot_ms);
        }
    }
    let tlog_lag = killed_at - f64::from(tlog_last_ms.expect("commands in the tlog")) / 1000.0;
    eprintln!(
        "killed at t = {killed_at:.3} s (daemon clock): CSV {} rows, last at {last_row:.3} s ({:.0} ms before); \
         tlog {frames} frames, last command {:.0} ms before; CSV torn tail: {:?}",
        csv.rows.len(),
        csv_lag * 1e3,
        tlog_lag * 1e3,
        csv.torn_tail
    );
    // The newest row may be one tick ahead of the last command the SITL
    // got (written, its command not yet sent at the kill), and
    // time_boot_ms is whole milliseconds.
    assert!(
        (-0.05..=1.5).contains(&csv_lag),
        "CSV ends {csv_lag:.3} s before the kill"
    );
    assert!(
        (-0.05..=1.5).contains(&tlog_lag),
        "tlog ends {tlog_lag:.3} s before the kill"
    );

    // The tools read them.
    let csv_arg = csv_path.to_str().unwrap();
    let config_arg = config.to_str().unwrap();
    dflat(&["review", csv_arg]);
    dflat(&[
        "identify",
        tlog_path.to_str().unwrap(),
        "--config",
        config_arg,
    ]);
    dflat(&["replay", csv_arg, "--config", config_arg]);
}

/// `sh -c SCRIPT` run as the daemon, with `$DFLAT` the binary and the
/// daemon's arguments after it; stderr to `dir/daemon.stderr`.
fn spawn_daemon_wrapped(dir: &Path, wrapper: &[&str], script: &str, args: &[String]) -> Proc {
    let stderr = dir.join("daemon.stderr");
    let mut cmd = Command::new(wrapper[0]);
    cmd.args(&wrapper[1..])
        .arg("sh")
        .arg("-c")
        .arg(script)
        .arg("sh")
        .args(args)
        .env("DFLAT", bin())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&stderr).expect("stderr file"));
    Proc {
        child: cmd.spawn().expect("spawn the wrapped daemon"),
        name: "daemon",
        stderr,
    }
}

/// True when this process may mount in a private mount namespace.
fn can_mount() -> bool {
    let probe = std::env::temp_dir().join(format!("dflat-mount-probe-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&probe);
    let ok = Command::new("unshare")
        .args(["-m", "sh", "-c"])
        .arg(format!(
            "mount -t tmpfs -o size=16k tmpfs '{}'",
            probe.display()
        ))
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let _ = std::fs::remove_dir(&probe);
    ok
}

/// Flies `seconds` with the daemon spawned by `spawn`, stops it with
/// SIGINT; returns its JSON summary, the commands and texts the SITL got,
/// and the daemon's stderr.
/// What a wrapped flight left.
struct Flown {
    /// The daemon's JSON summary.
    json: serde_json::Value,
    /// Its SET_ATTITUDE_TARGETs as the SITL got them.
    commands: Vec<(Instant, u32)>,
    /// Its STATUSTEXTs as the SITL got them.
    texts: Vec<(Instant, String)>,
    /// Its stderr.
    stderr: String,
    /// When SIGINT was sent.
    stopped: Instant,
}

fn fly_wrapped(
    name: &str,
    seconds: u64,
    records: &Path,
    spawn: impl FnOnce(&Path, &Path, std::net::SocketAddr, &Path) -> Proc,
) -> Flown {
    let dir = scratch(name);
    let config = write_config(&dir, "disk.toml", &config_text(records));
    let (sim, tap) = start_sitl(&config);
    let summary = dir.join("summary.json");
    let mut daemon = spawn(&dir, &config, sim.local_addr(), &summary);
    std::thread::sleep(Duration::from_secs(seconds));
    let stopped = Instant::now();
    assert!(
        daemon.interrupt_and_wait(Duration::from_secs(10)),
        "the daemon did not exit cleanly: {}",
        daemon.stderr_text()
    );
    let (commands, texts) = daemon_frames(&tap);
    let _ = sim.stop();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).expect("summary JSON"))
            .expect("summary parses");
    Flown {
        json,
        commands,
        texts,
        stderr: daemon.stderr_text(),
        stopped,
    }
}

fn daemon_args(config: &Path, sitl: std::net::SocketAddr, summary: &Path) -> Vec<String> {
    vec![
        "daemon".into(),
        "--config".into(),
        config.display().to_string(),
        "--link".into(),
        format!("udpout:{sitl}"),
        "--summary-json".into(),
        summary.display().to_string(),
    ]
}

impl Flown {
    /// The daemon [`kept_flying`] past its trouble and [`said_once`] `what`.
    fn kept_flying_and_said_once(&self, what: &str) {
        kept_flying(&self.commands, self.stopped);
        said_once(&self.texts, &self.stderr, what);
    }
}

/// The daemon kept streaming to the end: commands in each of the last 2 s.
fn kept_flying(commands: &[(Instant, u32)], stopped: Instant) {
    for (from, to) in [(2.0, 1.0), (1.0, 0.1)] {
        let n = commands
            .iter()
            .filter(|(at, _)| {
                let before = stopped.saturating_duration_since(*at).as_secs_f64();
                *at <= stopped && before <= from && before > to
            })
            .count();
        assert!(
            n as f64 >= 0.8 * 50.0 * (from - to),
            "{n} commands between {from} s and {to} s before the stop"
        );
    }
}

fn said_once(texts: &[(Instant, String)], stderr: &str, what: &str) {
    let n = texts.iter().filter(|(_, t)| t.contains(what)).count();
    assert_eq!(n, 1, "STATUSTEXT `{what}` {n} times: {texts:?}");
    let logged =
        stderr.matches("disk trouble").count() + stderr.matches("flying without records").count();
    assert!(logged >= 1, "not logged:\n{stderr}");
    assert_eq!(
        stderr
            .lines()
            .filter(|l| l.contains("WARN")
                && (l.contains("disk trouble") || l.contains("flying without records")))
            .count(),
        1,
        "said once in the log:\n{stderr}"
    );
}

#[test]
fn a_full_disk_does_not_stop_the_flight() {
    let dir = scratch("records-full");
    let records = dir.join("small");
    std::fs::create_dir_all(&records).unwrap();
    let mount = can_mount();
    let flown = fly_wrapped(
        "records-full-fly",
        7,
        &records,
        |d, config, sitl, summary| {
            let args = daemon_args(config, sitl, summary);
            if mount {
                // A 64 KiB tmpfs over the records directory, in a private
                // mount namespace: it fills up after ~2 s of records.
                let script = format!(
                    "mount -t tmpfs -o size=64k tmpfs '{}' && exec \"$DFLAT\" \"$@\"",
                    records.display()
                );
                spawn_daemon_wrapped(d, &["unshare", "-m"], &script, &args)
            } else {
                // No mounts allowed: a 64 KiB file-size limit (SIGXFSZ ignored,
                // so writes past it fail with EFBIG, as on a full disk).
                spawn_daemon_wrapped(
                    d,
                    &["prlimit", "--fsize=65536"],
                    "trap '' XFSZ; exec \"$DFLAT\" \"$@\"",
                    &args,
                )
            }
        },
    );
    eprintln!("mounted a tmpfs: {mount}");
    let json = &flown.json;
    let r = &json["records"];
    eprintln!("records: {r}\ncsv: {}\ntlog: {}", json["csv"], json["tlog"]);
    assert_eq!(
        r["disk_trouble"], true,
        "the disk-full path was not taken: {r}"
    );
    assert!(r["off_at_start"].is_null());
    let dropped = json["csv"]["error_dropped"].as_u64().unwrap_or(0)
        + json["tlog"]["error_dropped"].as_u64().unwrap_or(0);
    assert!(dropped > 0, "nothing counted as dropped");
    let written = r["written_bytes"].as_u64().unwrap();
    // A 64 KiB tmpfs holds both files; the fallback's file-size limit
    // bounds each of the two files.
    let limit = if mount { 65_536 } else { 2 * 65_536 };
    assert!(written > 0 && written <= limit, "{written} bytes written");
    flown.kept_flying_and_said_once("disk trouble");
    assert!(json["commands"].as_u64().unwrap() > 250);
}

#[test]
fn a_read_only_records_directory_at_start_does_not_ground_the_vehicle() {
    let dir = scratch("records-ro");
    let mount = can_mount();
    let records = if mount {
        let r = dir.join("ro");
        std::fs::create_dir_all(&r).unwrap();
        r
    } else {
        // Not even root can create a directory here.
        PathBuf::from(format!("/proc/dflat-records-{}", std::process::id()))
    };
    let flown = fly_wrapped("records-ro-fly", 4, &records, |d, config, sitl, summary| {
        let args = daemon_args(config, sitl, summary);
        if mount {
            let script = format!(
                "mount -t tmpfs -o ro,size=64k tmpfs '{}' && exec \"$DFLAT\" \"$@\"",
                records.display()
            );
            spawn_daemon_wrapped(d, &["unshare", "-m"], &script, &args)
        } else {
            spawn_daemon_wrapped(d, &["env"], "exec \"$DFLAT\" \"$@\"", &args)
        }
    });
    eprintln!("mounted a read-only tmpfs: {mount}");
    let json = &flown.json;
    let r = &json["records"];
    eprintln!("records: {r}");
    assert!(
        r["off_at_start"].is_string(),
        "the daemon did not take the no-records path: {r}"
    );
    assert!(json["csv"].is_null() && json["tlog"].is_null());
    assert_eq!(r["written_bytes"], 0);
    flown.kept_flying_and_said_once("disk trouble");
}

/// A start that fails at the link (its `udpin` port taken) exits with the
/// link's error and leaves the records directory as it found it: no empty
/// flight of its own, and the old flight that `records.keep_mb` would have
/// pruned for it still there.
#[test]
fn a_start_whose_link_does_not_open_leaves_the_records_as_they_were() {
    let dir = std::env::temp_dir().join(format!("dflat-failed-start-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let old = dir.join("flight-20260101-000000.csv");
    std::fs::write(&old, vec![b'x'; 3 * 1024 * 1024]).unwrap();
    let config = dir.join("daemon.toml");
    std::fs::write(
        &config,
        format!(
            "[logging]\ndir = \"{}\"\ntlog = true\ncsv = true\n[records]\nmax_mb = 1.0\nkeep_mb = 2.0\n",
            dir.display()
        ),
    )
    .unwrap();
    let taken = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let link = format!("udpin:{}", taken.local_addr().unwrap());
    let out = Command::new(bin())
        .args(["daemon", "--config"])
        .arg(&config)
        .args(["--link", &link])
        .output()
        .expect("run dflat daemon");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the daemon started: {stderr}");
    assert!(stderr.contains("link"), "{stderr}");
    let mut left: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        ["daemon.toml", "flight-20260101-000000.csv"],
        "{stderr}"
    );
    assert_eq!(std::fs::metadata(&old).unwrap().len(), 3 * 1024 * 1024);
    drop(taken);
    let _ = std::fs::remove_dir_all(&dir);
}
