//! MAVLink 2 signing end to end: the daemon and the built-in SITL, in
//! process on loopback, with key files as an installation has them (64 hex
//! digits, mode 0600). The shipped SITL configuration (multi-rate DF-MPC)
//! flies the demo's L path at 5 m/s.
//!
//! * Same key on both sides: the flight completes, nothing is refused on
//!   either side, and a ground station on the SITL's GCS port gets the
//!   daemon's frames with their signatures intact.
//! * SITL signed, daemon without a key: the daemon flies "blind" (it takes
//!   the signed telemetry as ordinary frames), the SITL ignores its unsigned
//!   commands and holds.
//! * Different keys: each side refuses the other's frames.
//!
//! The tests fly in real time, so they run one at a time ([`SERIAL`]).

use std::net::{SocketAddr, UdpSocket};
use std::os::unix::fs::PermissionsExt as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use dflat_daemon::config::Config;
use dflat_daemon::supervisor::FlightState;
use dflat_link::{
    SignatureCheck, Signing, SigningKey, TIMESTAMP_UNITS_PER_S, frames, header, heartbeat_onboard,
    timestamp_from_system_time,
};
use dflat_sitl::{self as sitl, SitlOptions, SitlReport, SitlSettings};
use nalgebra::Vector3;

mod support;

/// One flight at a time: each runs a real-time plant and a 50 Hz control
/// loop (a 2-core machine has no room for three at once).
static SERIAL: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The SITL's key in every test; the daemon's unless said otherwise.
const KEY: u8 = 0x5a;
/// Another key.
const OTHER_KEY: u8 = 0xc3;
/// Signing link id of the test's ground station (daemon 0, SITL 1).
const GCS_LINK_ID: u8 = 2;

fn now() -> u64 {
    timestamp_from_system_time(SystemTime::now())
}

/// A scratch directory for one test (removed on drop).
struct Scratch {
    dir: PathBuf,
}

impl Scratch {
    fn new(test: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("dflat-signed-flight-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self { dir }
    }

    /// Writes a key file of 32 bytes `byte` (64 hex digits and a newline,
    /// mode 0600) and returns its path.
    fn key_file(&self, byte: u8) -> String {
        let path = self.dir.join(format!("key-{byte:02x}"));
        std::fs::write(&path, format!("{}\n", format!("{byte:02x}").repeat(32))).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        path.display().to_string()
    }

    fn timestamp_file(&self) -> PathBuf {
        self.dir.join("signing_timestamp")
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The demo's configuration (L path at 5 m/s, SITL on a free port, no
/// records) with the SITL's key and, if given, the daemon's.
fn config(scratch: &Scratch, daemon_key: Option<u8>, sitl_key: u8) -> (Config, SitlSettings) {
    // Engaged as soon as the stream runs (the demo plays a pilot instead).
    let (mut cfg, mut plant) = support::sitl_flight("signed", dflat_sitl::SitlEngage::Auto);
    plant.sitl.signing_key_file = scratch.key_file(sitl_key);
    if let Some(k) = daemon_key {
        cfg.link.signing_key_file = scratch.key_file(k);
        cfg.link.signing_timestamp_file = scratch.timestamp_file().display().to_string();
    }
    (cfg, plant)
}

fn spawn_sitl(cfg: &SitlSettings, gcs: bool) -> sitl::SitlHandle {
    sitl::spawn(
        cfg,
        SitlOptions {
            gcs: gcs.then(|| "udpin:127.0.0.1:0".to_owned()),
            record_trace: true,
            ..SitlOptions::default()
        },
    )
    .unwrap()
}

fn link_to(sitl: &sitl::SitlHandle) -> String {
    format!("udpout:127.0.0.1:{}", sitl.local_addr().port())
}

/// Largest distance of the true position from the start over the run \[m\].
fn max_displacement(cfg: &SitlSettings, report: &SitlReport) -> f64 {
    let start = Vector3::from(cfg.sitl.start);
    report
        .trace
        .iter()
        .map(|s| (Vector3::from(s.position) - start).norm())
        .fold(0.0, f64::max)
}

/// What the ground station received, by sender, verified with its key.
#[derive(Debug, Default)]
struct GcsSeen {
    /// From the autopilot (1/1): [valid, not valid].
    autopilot: [u64; 2],
    /// From the daemon (1/191): [valid, not valid].
    daemon: [u64; 2],
}

/// A ground station on the SITL's GCS port: a signed HEARTBEAT once a
/// second (which makes it the SITL's GCS peer), and every frame routed to
/// it verified with `key`.
struct Gcs {
    stop: Arc<AtomicBool>,
    thread: JoinHandle<GcsSeen>,
}

impl Gcs {
    fn spawn(port: SocketAddr, key: u8) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let thread = std::thread::spawn(move || {
            let mut signing = Signing::new(SigningKey::from_bytes([key; 32]), GCS_LINK_ID, now());
            let hb = heartbeat_onboard(dflat_link::DaemonStatus::Active);
            let mut seen = GcsSeen::default();
            let mut buf = [0u8; 65_536];
            let mut next_hb = Instant::now();
            let mut seq = 0u8;
            while !flag.load(Ordering::Relaxed) {
                if Instant::now() >= next_hb {
                    let f = signing.sign(&header(255, 190, seq), &hb, now()).unwrap();
                    socket.send_to(f.as_bytes(), port).unwrap();
                    seq = seq.wrapping_add(1);
                    next_hb += Duration::from_secs(1);
                }
                let Ok((n, _)) = socket.recv_from(&mut buf) else {
                    continue;
                };
                for f in frames(&buf[..n]).flatten() {
                    let check = signing.verify(&f.header, f.signed.as_ref(), now());
                    let slot = usize::from(!matches!(check, SignatureCheck::Valid { .. }));
                    match (f.header.system_id, f.header.component_id) {
                        (1, 1) => seen.autopilot[slot] += 1,
                        (1, 191) => seen.daemon[slot] += 1,
                        _ => {}
                    }
                }
            }
            seen
        });
        Self { stop, thread }
    }

    fn finish(self) -> GcsSeen {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn signed_flight_completes() {
    let _serial = SERIAL.lock().await;
    let scratch = Scratch::new("completes");
    let (cfg, plant) = config(&scratch, Some(KEY), KEY);
    let sitl = spawn_sitl(&plant, true);
    let gcs = Gcs::spawn(sitl.gcs_addr().unwrap(), KEY);
    let start_timestamp = now();
    let started = Instant::now();
    let daemon = dflat_daemon::spawn(cfg.clone(), Some(link_to(&sitl)))
        .await
        .unwrap();

    // The L path is 50 m: 10 s at 5 m/s. Wait for arrival and 1 s more.
    let end = Vector3::from(*cfg.mission.path.last().unwrap());
    let mut arrived: Option<Instant> = None;
    while started.elapsed() < Duration::from_secs(25) {
        tokio::time::sleep(Duration::from_millis(20)).await;
        if arrived.is_none() && (Vector3::from(sitl.truth().position) - end).norm() < 0.3 {
            arrived = Some(Instant::now());
        }
        if arrived.is_some_and(|t| t.elapsed() > Duration::from_secs(1)) {
            break;
        }
    }
    let flown = started.elapsed();
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let report = sitl.stop().unwrap();
    let seen = gcs.finish();
    let persisted: u64 = std::fs::read_to_string(scratch.timestamp_file())
        .expect("the signing timestamp file exists after shutdown")
        .trim()
        .parse()
        .unwrap();

    let c = report.counters;
    let l = summary.link_stats;
    eprintln!(
        "signed flight: arrival after {:?}; sitl commands {} accepted, {} unauthenticated, {} rejected; \
         daemon rx {} (pose {}), tx attitude targets {}, unsigned {} badsig {} replayed {}; \
         gcs saw autopilot {:?} daemon {:?} [valid, invalid]; persisted timestamp start + {:.2} s",
        arrived.map(|t| t - started),
        c.commands_accepted,
        c.commands_unauthenticated,
        c.commands_rejected,
        l.received.total,
        l.received.local_position_ned,
        l.sent.set_attitude_target,
        l.unsigned,
        l.bad_signature,
        l.replayed,
        seen.autopilot,
        seen.daemon,
        persisted.saturating_sub(start_timestamp) as f64 / TIMESTAMP_UNITS_PER_S as f64,
    );
    assert!(
        arrived.is_some(),
        "did not reach the path end; last {:?}",
        report.last.position
    );
    assert!(!report.diverged);
    // The SITL applied the daemon's signed commands and refused none.
    assert!(c.commands_accepted > 100, "{c:?}");
    assert_eq!(c.commands_unauthenticated, 0, "{c:?}");
    assert_eq!(c.commands_rejected, 0, "{c:?}");
    // The daemon verified every frame of the signed SITL telemetry.
    assert_eq!(
        (l.unsigned, l.bad_signature, l.replayed),
        (0, 0, 0),
        "{l:?}"
    );
    assert!(l.received.local_position_ned > 500, "{l:?}");
    // Routed through the SITL, the daemon's frames keep valid signatures
    // (HEARTBEAT 1 Hz, STATUSTEXT; its commands are addressed to the
    // autopilot and not routed), and so does the SITL's own telemetry.
    assert!(seen.daemon[0] >= 5 && seen.daemon[1] == 0, "{seen:?}");
    assert!(
        seen.autopilot[0] > 500 && seen.autopilot[1] == 0,
        "{seen:?}"
    );
    // Persisted at shutdown: about the wall clock of the last signed frame,
    // not just the start value written when the daemon started (the 20 s
    // periodic save does not come in a flight this short).
    let at_least = start_timestamp
        + (flown.saturating_sub(Duration::from_secs(1)).as_secs_f64()
            * TIMESTAMP_UNITS_PER_S as f64) as u64;
    assert!(
        persisted > at_least,
        "persisted {persisted}, start {start_timestamp}, flown {flown:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unsigned_daemon_cannot_fly_a_signed_sitl() {
    let _serial = SERIAL.lock().await;
    let scratch = Scratch::new("unsigned-daemon");
    let (cfg, plant) = config(&scratch, None, KEY);
    let sitl = spawn_sitl(&plant, false);
    let daemon = dflat_daemon::spawn(cfg.clone(), Some(link_to(&sitl)))
        .await
        .unwrap();
    // Without a key the daemon does not check signatures: the parser frames
    // signed MAVLink 2 and the receive path authenticates only when its own
    // signing is on. So it gets pose, engages and streams commands.
    let engage_by = Instant::now() + Duration::from_secs(5);
    while !daemon.state().is_some_and(FlightState::streams) && Instant::now() < engage_by {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let engaged = daemon.state();
    tokio::time::sleep(Duration::from_secs(3)).await;
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let report = sitl.stop().unwrap();

    let c = report.counters;
    let l = summary.link_stats;
    let moved = max_displacement(&plant, &report);
    eprintln!(
        "unsigned daemon: state {engaged:?}, sent {} attitude targets; sitl {} accepted, {} unauthenticated; \
         largest displacement {moved:.4} m",
        l.sent.set_attitude_target, c.commands_accepted, c.commands_unauthenticated,
    );
    assert!(
        engaged.is_some_and(FlightState::streams),
        "the daemon did not engage on signed telemetry: {engaged:?}"
    );
    assert!(l.sent.set_attitude_target > 100, "{l:?}");
    // The SITL applied none of the unsigned commands and held its start.
    assert_eq!(c.commands_accepted, 0, "{c:?}");
    assert!(c.commands_unauthenticated > 50, "{c:?}");
    assert!(c.commands_unauthenticated <= l.sent.set_attitude_target);
    assert_eq!(c.hold_entries, 0, "never in offboard: {c:?}");
    assert!(moved < 0.2, "moved {moved} m from the start");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_key_is_refused_both_ways() {
    let _serial = SERIAL.lock().await;
    let scratch = Scratch::new("wrong-key");
    let (cfg, plant) = config(&scratch, Some(OTHER_KEY), KEY);
    let sitl = spawn_sitl(&plant, true);
    let gcs = Gcs::spawn(sitl.gcs_addr().unwrap(), KEY);
    let daemon = dflat_daemon::spawn(cfg.clone(), Some(link_to(&sitl)))
        .await
        .unwrap();
    let mut states = Vec::new();
    let until = Instant::now() + Duration::from_secs(3);
    while Instant::now() < until {
        // `None` only before the control loop's first tick.
        if let Some(s) = daemon.state()
            && states.last() != Some(&s)
        {
            states.push(s);
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let report = sitl.stop().unwrap();
    let seen = gcs.finish();

    let c = report.counters;
    let l = summary.link_stats;
    eprintln!(
        "wrong key: daemon states {states:?}, badsig {}, sent attitude targets {}; sitl received {}, \
         {} accepted, {} unauthenticated; gcs saw autopilot {:?} daemon {:?} [valid, invalid]",
        l.bad_signature,
        l.sent.set_attitude_target,
        c.frames_received,
        c.commands_accepted,
        c.commands_unauthenticated,
        seen.autopilot,
        seen.daemon,
    );
    // Daemon side: every SITL frame (pose 50 Hz, attitude 50 Hz, heartbeat)
    // fails the signature check, so no pose ever arrives and the daemon
    // stays in WaitingForPose.
    assert!(l.bad_signature > 50, "{l:?}");
    assert_eq!(l.replayed, 0, "{l:?}");
    assert_eq!(states, [FlightState::WaitingForPose]);
    assert_eq!(summary.final_state, FlightState::WaitingForPose);
    // Hence it never sends a SET_ATTITUDE_TARGET (commands stream only in
    // Holding / Tracking), and the SITL has no command to refuse:
    // commands_unauthenticated stays 0 here — the refusal of wrongly
    // signed commands is covered by the SITL's unit tests.
    assert_eq!(l.sent.set_attitude_target, 0, "{l:?}");
    assert_eq!(summary.commands, 0);
    assert_eq!(c.commands_accepted, 0, "{c:?}");
    assert_eq!(c.commands_unauthenticated, 0, "{c:?}");
    // SITL side: the daemon's HEARTBEATs (1 Hz, signed with the other key)
    // arrive but are dropped, so they are not routed to the ground station,
    // which does get the SITL's own signed telemetry.
    assert!(c.frames_received >= 2, "{c:?}");
    assert_eq!(seen.daemon, [0, 0], "{seen:?}");
    assert!(seen.autopilot[0] > 50 && seen.autopilot[1] == 0, "{seen:?}");
    assert!(max_displacement(&plant, &report) < 0.2);
}
