//! The daemon in-process against a tiny fake autopilot on loopback UDP.
//!
//! The fake autopilot listens (`udpin`), sends HEARTBEAT and 50 Hz
//! LOCAL_POSITION_NED + ATTITUDE of a fixed position, and records every
//! message the daemon sends with its arrival time. Rates and the stop are
//! judged from the daemon's own stamps (SET_ATTITUDE_TARGET `time_boot_ms`,
//! the tick's time) and its CSV (`pose_age_ms`), not from the test's
//! clock; the arrival times only split the phases.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use dflat_daemon::config::{Config, MissionStart};
use dflat_daemon::supervisor::FlightState;
use dflat_link::dialect::{
    MavAutopilot, MavFrame, MavState, PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use dflat_link::transport::{Endpoint, RecvEvent, Transport};
use dflat_link::{
    ATTITUDE_TARGET_MASK, MavHeader, MavMessage, attitude, header, heartbeat_autopilot,
    local_position_ned,
};

const HOVER: [f64; 3] = [3.0, -4.0, -10.0];

/// One message the daemon sent, as the fake autopilot received it.
#[derive(Debug, Clone)]
struct Seen {
    at: Instant,
    header: MavHeader,
    message: MavMessage,
}

struct FakeAutopilot {
    link: Transport,
    poses: Arc<AtomicBool>,
    seen: Arc<Mutex<Vec<Seen>>>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

impl FakeAutopilot {
    async fn start() -> Self {
        let link = Transport::open(&Endpoint::parse("udpin:127.0.0.1:0").unwrap())
            .await
            .unwrap();
        let poses = Arc::new(AtomicBool::new(true));
        let seen = Arc::new(Mutex::new(Vec::new()));
        let rx = {
            let (link, seen) = (link.clone(), seen.clone());
            tokio::spawn(async move {
                while let Ok(ev) = link.recv().await {
                    if let RecvEvent::Frame(f) = ev {
                        seen.lock().unwrap().push(Seen {
                            at: f.arrival,
                            header: f.header,
                            message: f.message,
                        });
                    }
                }
            })
        };
        let tx = {
            let (link, poses) = (link.clone(), poses.clone());
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(Duration::from_millis(20));
                let mut k: u64 = 0;
                let started = Instant::now();
                loop {
                    tick.tick().await;
                    let ms = started.elapsed().as_millis() as u32;
                    let hdr = header(1, 1, k as u8);
                    if k.is_multiple_of(50) {
                        // Armed in OFFBOARD: the commands are applied
                        // (engaged at once; standby is tested elsewhere).
                        let hb = heartbeat_autopilot(
                            MavAutopilot::MAV_AUTOPILOT_PX4,
                            true,
                            6 << 16,
                            MavState::MAV_STATE_ACTIVE,
                        );
                        let _ = link.send(&hdr, &hb).await;
                    }
                    if poses.load(Ordering::SeqCst) {
                        let pos = local_position_ned(ms, HOVER, [0.0; 3]).unwrap();
                        let att = attitude(ms, [0.0; 3], [0.0; 3]).unwrap();
                        let _ = link.send(&hdr, &pos).await;
                        let _ = link.send(&hdr, &att).await;
                    }
                    k += 1;
                }
            })
        };
        Self {
            link,
            poses,
            seen,
            tasks: vec![rx, tx],
        }
    }

    fn url(&self) -> String {
        format!(
            "udpout:127.0.0.1:{}",
            self.link.local_addr().unwrap().port()
        )
    }

    fn attitude_targets(&self, from: Instant, to: Instant) -> Vec<Seen> {
        self.seen
            .lock()
            .unwrap()
            .iter()
            .filter(|s| s.at >= from && s.at < to)
            .filter(|s| matches!(s.message, MavMessage::SET_ATTITUDE_TARGET(_)))
            .cloned()
            .collect()
    }

    fn status_texts(&self) -> Vec<String> {
        self.seen
            .lock()
            .unwrap()
            .iter()
            .filter_map(|s| match &s.message {
                MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
                _ => None,
            })
            .collect()
    }
}

impl Drop for FakeAutopilot {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

fn config(dir: &std::path::Path) -> Config {
    let mut cfg = Config::default();
    cfg.logging.dir = dir.display().to_string();
    cfg.mission.start = MissionStart::Hold;
    // Silent at once when pose goes stale: the brake and level hover that
    // come first by default are tests/e2e_pose_loss_level.rs's.
    cfg.safety.level_hover_max_ms = 0.0;
    cfg
}

/// Polls the daemon's state until `want` (or panics after `within`).
async fn wait_for_state(daemon: &dflat_daemon::DaemonHandle, want: FlightState, within: Duration) {
    let until = Instant::now() + within;
    while daemon.state() != Some(want) {
        assert!(
            Instant::now() < until,
            "state {:?}, wanted {want:?}",
            daemon.state()
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("dflat-it-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every SET_ATTITUDE_TARGET obeys the contract.
fn check_contract(commands: &[Seen]) {
    for s in commands {
        let MavMessage::SET_ATTITUDE_TARGET(d) = &s.message else {
            unreachable!()
        };
        assert_eq!((s.header.system_id, s.header.component_id), (1, 191));
        assert_eq!((d.target_system, d.target_component), (1, 1));
        assert_eq!(d.type_mask, ATTITUDE_TARGET_MASK);
        let q: Vec<f64> = d.q.iter().map(|v| f64::from(*v)).collect();
        assert!(q.iter().all(|v| v.is_finite()), "{d:?}");
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() <= 1e-6, "|q| = {norm}");
        assert!(
            d.thrust.is_finite() && (0.0..=1.0).contains(&d.thrust),
            "{d:?}"
        );
        for v in [d.body_roll_rate, d.body_pitch_rate, d.body_yaw_rate] {
            assert!(v.is_finite());
        }
        assert!(d.thrust_body.iter().all(|v| v.is_finite()));
    }
}

/// Commands per second by the daemon's stamps: the commands between the
/// first and the last over the time between their `time_boot_ms`.
fn rate(commands: &[Seen]) -> f64 {
    let stamps: Vec<u32> = commands
        .iter()
        .filter_map(|s| match &s.message {
            MavMessage::SET_ATTITUDE_TARGET(d) => Some(d.time_boot_ms),
            _ => None,
        })
        .collect();
    match (stamps.first(), stamps.last()) {
        (Some(a), Some(b)) if b > a => (stamps.len() - 1) as f64 / (f64::from(b - a) * 1e-3),
        _ => 0.0,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn streams_at_50_hz_stops_on_stale_pose_and_resumes() {
    let dir = temp_dir("stream");
    let fake = FakeAutopilot::start().await;
    let daemon = dflat_daemon::spawn(config(&dir), Some(fake.url()))
        .await
        .unwrap();

    // Phase 1: poses flowing. Holding once the first autopilot HEARTBEAT
    // (1 Hz, only sent once the daemon spoke) arrived; then count 1.5 s.
    wait_for_state(&daemon, FlightState::Holding, Duration::from_secs(3)).await;
    tokio::time::sleep(Duration::from_millis(100)).await;
    let t0 = Instant::now();
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let t1 = Instant::now();
    assert_eq!(daemon.state(), Some(FlightState::Holding));
    let phase1 = fake.attitude_targets(t0, t1);
    let hz = rate(&phase1);
    assert!((45.0..=55.0).contains(&hz), "command rate {hz} Hz");
    check_contract(&phase1);

    // Phase 2: poses stop; the stream must stop within 200 ms of the last
    // pose (judged from the CSV's pose age of every command, below).
    fake.poses.store(false, Ordering::SeqCst);
    tokio::time::sleep(Duration::from_millis(830)).await;
    assert_eq!(daemon.state(), Some(FlightState::Failsafe));

    // Phase 3: poses resume; so does the stream, at 50 Hz.
    fake.poses.store(true, Ordering::SeqCst);
    tokio::time::sleep(Duration::from_millis(300)).await;
    let t3 = Instant::now();
    tokio::time::sleep(Duration::from_millis(1000)).await;
    let t4 = Instant::now();
    assert_eq!(daemon.state(), Some(FlightState::Holding));
    let phase3 = fake.attitude_targets(t3, t4);
    let hz = rate(&phase3);
    assert!((45.0..=55.0).contains(&hz), "resumed command rate {hz} Hz");
    check_contract(&phase3);
    // Holding a fixed, measured position: level attitude.
    for s in &phase3 {
        if let MavMessage::SET_ATTITUDE_TARGET(d) = &s.message {
            assert!((f64::from(d.q[0]) - 1.0).abs() < 1e-3, "{d:?}");
        }
    }

    let summary = daemon.join().await.unwrap();
    let texts = fake.status_texts();
    assert!(texts.iter().any(|t| t.contains("HOLDING")), "{texts:?}");
    assert!(texts.iter().any(|t| t.contains("FAILSAFE")), "{texts:?}");
    assert!(summary.ticks >= 150, "{summary:#?}");
    assert!(summary.commands >= 100);
    // Holding, failsafe, holding (the stop's brake and level apart).
    assert_eq!(summary.state_changes, 3, "{summary:#?}");
    let stop = summary.stop.expect("the stop sequence ran");
    assert!(stop.commands > 0 && stop.duration_s <= 2.0, "{stop:?}");
    assert!(summary.time_in_state_s.failsafe > 0.3);
    assert_eq!(summary.final_state, FlightState::Holding);
    assert_eq!(summary.link_stats.inbound_errors(), 0);
    // Every command the ticks produced was sent, or replaced in the send
    // task's slot by a newer one before it went out (a late link task
    // under load), or dropped there as stale; one may still sit in the
    // slot at shutdown.
    let lg = &summary.link_guard;
    let sent = summary.link_stats.sent.set_attitude_target;
    let accounted = sent + lg.commands_replaced + lg.commands_stale;
    assert!(
        accounted + 1 >= summary.commands && sent <= summary.commands,
        "commands {}: sent {sent}, replaced {}, stale {}",
        summary.commands,
        lg.commands_replaced,
        lg.commands_stale
    );
    assert!(summary.latency_us.samples > 0);
    let csv = summary.csv.as_ref().unwrap();
    assert_eq!((csv.rows, csv.dropped), (summary.ticks, 0));
    let tlog = summary.tlog.as_ref().unwrap();
    assert!(tlog.records > summary.commands, "{tlog:?}");
    assert_eq!(tlog.dropped, 0);
    // The records are complete on disk.
    let text = std::fs::read_to_string(&csv.path).unwrap();
    assert_eq!(text.lines().count() as u64, csv.rows + 1);
    // No command on a pose older than 200 ms: the stream stopped in time.
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (roll, age) = (col("roll"), col("pose_age_ms"));
    let (mut commands, mut oldest) = (0, 0.0f64);
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        if f[roll].is_empty() {
            continue;
        }
        commands += 1;
        if let Ok(a) = f[age].parse::<f64>() {
            oldest = oldest.max(a);
        }
    }
    assert!(commands >= 100, "{commands} commands in the CSV");
    assert!(oldest <= 200.0, "a command on a pose {oldest} ms old");
    let json = serde_json::to_string(&summary).unwrap();
    assert!(json.contains("\"latency_us\""));
    let _ = std::fs::remove_dir_all(&dir);
}

fn setpoint(p: [f32; 3]) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms: 0,
        x: p[0],
        y: p[1],
        z: p[2],
        vx: 0.0,
        vy: 0.0,
        vz: 0.0,
        afx: 0.0,
        afy: 0.0,
        afz: 0.0,
        yaw: 0.0,
        yaw_rate: 0.0,
        type_mask: PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE,
        target_system: 1,
        target_component: 0,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ground_station_setpoints_are_tracked_or_refused() {
    let dir = temp_dir("setpoint");
    let fake = FakeAutopilot::start().await;
    let daemon = dflat_daemon::spawn(config(&dir), Some(fake.url()))
        .await
        .unwrap();
    wait_for_state(&daemon, FlightState::Holding, Duration::from_secs(3)).await;
    let gcs = header(255, 190, 0);

    // Outside the geofence: refused with STATUSTEXT, still holding.
    fake.link
        .send(&gcs, &setpoint([900.0, 0.0, -10.0]))
        .await
        .unwrap();
    // From an untrusted system: ignored.
    fake.link
        .send(&header(42, 1, 0), &setpoint([10.0, 0.0, -10.0]))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(daemon.state(), Some(FlightState::Holding));
    assert!(
        fake.status_texts().iter().any(|t| t.contains("refused")),
        "{:?}",
        fake.status_texts()
    );

    // 10 m north of the (fixed) measured position: tracking, nose down.
    fake.link
        .send(&gcs, &setpoint([13.0, -4.0, -10.0]))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(daemon.state(), Some(FlightState::Tracking));
    let t = Instant::now();
    tokio::time::sleep(Duration::from_millis(200)).await;
    let commands = fake.attitude_targets(t, Instant::now());
    check_contract(&commands);
    let pitch = commands
        .iter()
        .map(|s| match &s.message {
            MavMessage::SET_ATTITUDE_TARGET(d) => {
                let q: [f64; 4] = d.q.map(f64::from);
                dflat_link::euler_from_quaternion(q)[1]
            }
            _ => unreachable!(),
        })
        .next_back()
        .unwrap();
    assert!(
        pitch < -0.05,
        "pitch {pitch} rad: should be nose down toward north"
    );

    let summary = daemon.join().await.unwrap();
    assert_eq!(
        summary.link_stats.ignored_wrong_source, 1,
        "{:?}",
        summary.link_stats
    );
    assert!(fake.status_texts().iter().any(|t| t.contains("TRACKING")));
    let _ = std::fs::remove_dir_all(&dir);
}
