//! The command stream comes first, end to end: a ground station on the
//! SITL's GCS port floods the daemon with COMMAND_LONG (REQUEST_MESSAGE
//! HEARTBEAT, which the daemon answers with an ACK and a HEARTBEAT) at
//! 2 kHz for 3 s while the daemon holds. The SITL routes the flood to the
//! daemon's link, as an autopilot's MAVLink router does.
//!
//! Judged from the daemon's own summary, flight against flight: a 3 s hold
//! without the flood, then one with it. With the flood the command rate
//! stays 50 Hz (commands sent over the time spent streaming), no command is
//! sent stale, the replies are rate-limited (dropped ones counted), and the
//! pose → command median is within 0.2 ms of the figure without the flood
//! (the p99 is reported: on a shared machine it is scheduling noise). The
//! flood's achieved rate is reported, not asserted. A pair with a stale
//! command in either hold is flown again ([`PAIRS`]).

use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use dflat_daemon::config::{Config, MissionStart};
use dflat_daemon::summary::FlightSummary;
use dflat_daemon::supervisor::FlightState;
use dflat_link::MavMessage;
use dflat_link::dialect::{COMMAND_LONG_DATA, MavCmd};
use dflat_sitl::{self as sitl, SitlOptions, SitlSettings};

mod support;

/// Flood rate asked for \[Hz\] and its duration.
const FLOOD_HZ: f64 = 2000.0;
const HOLD: Duration = Duration::from_secs(3);
/// Pairs of holds (quiet, flood) flown at most: a pair with a stale
/// command is flown again, and the last one judged. The send task drops
/// a command it takes more than a tick after its tick, as it should; on a
/// starved machine (the suite beside two busy loops) it once woke that
/// late in the flood's hold (1 of ~150 commands). A flood that starved
/// the stream would drop commands in every pair.
const PAIRS: usize = 3;

fn config() -> (Config, SitlSettings) {
    let (mut cfg, plant) = support::sitl_flight("flood", dflat_sitl::SitlEngage::Auto);
    cfg.mission.start = MissionStart::Hold;
    (cfg, plant)
}

/// Floods `to` with COMMAND_LONG from the ground station (255/190) until
/// `stop`; counts what it sent.
fn flood(to: std::net::SocketAddr, stop: Arc<AtomicBool>, sent: Arc<AtomicU64>) {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    // A heartbeat makes the ground station known to the SITL's router.
    support::send(
        &socket,
        to,
        255,
        190,
        0,
        &MavMessage::HEARTBEAT(Default::default()),
    );
    let cmd = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system: 1,
        target_component: 191,
        command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
        param1: 0.0,
        ..COMMAND_LONG_DATA::default()
    });
    let start = Instant::now();
    let mut k: u64 = 0;
    while !stop.load(Ordering::Relaxed) {
        // Paced by the schedule, bursts catch up after a late wake.
        let due = start + Duration::from_secs_f64(k as f64 / FLOOD_HZ);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        support::send(&socket, to, 255, 190, k as u8, &cmd);
        k += 1;
        sent.store(k, Ordering::Relaxed);
    }
}

/// One 3 s hold, with or without the flood; the summary and the flood's
/// achieved rate \[Hz\].
async fn hold(with_flood: bool) -> (FlightSummary, f64) {
    let (cfg, plant) = config();
    let sim = sitl::spawn(
        &plant,
        SitlOptions {
            gcs: Some("udpin:127.0.0.1:0".into()),
            ..SitlOptions::default()
        },
    )
    .unwrap();
    let link = format!("udpout:127.0.0.1:{}", sim.local_addr().port());
    let daemon = dflat_daemon::spawn(cfg, Some(link)).await.unwrap();
    let until = Instant::now() + Duration::from_secs(5);
    while daemon.state() != Some(FlightState::Holding) && Instant::now() < until {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(daemon.state(), Some(FlightState::Holding));
    let stop = Arc::new(AtomicBool::new(false));
    let sent = Arc::new(AtomicU64::new(0));
    let started = Instant::now();
    let flooder = with_flood.then(|| {
        let (to, stop, sent) = (sim.gcs_addr().unwrap(), stop.clone(), sent.clone());
        std::thread::spawn(move || flood(to, stop, sent))
    });
    tokio::time::sleep(HOLD).await;
    stop.store(true, Ordering::Relaxed);
    let flood_rate = sent.load(Ordering::Relaxed) as f64 / started.elapsed().as_secs_f64();
    if let Some(f) = flooder {
        f.join().unwrap();
    }
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    sim.stop().unwrap();
    (summary, flood_rate)
}

/// Commands sent per second of streaming (the daemon's own counters).
fn command_rate(s: &FlightSummary) -> f64 {
    let t = &s.time_in_state_s;
    // The stop's brake and level (after the states' times) apart.
    let stop = s.stop.map_or(0, |s| s.commands);
    (s.link_stats.sent.set_attitude_target - stop) as f64 / (t.standby + t.holding + t.tracking)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_command_long_flood_leaves_the_command_stream_alone() {
    let mut pair = 0;
    let (quiet, flooded, flood_rate) = loop {
        pair += 1;
        let (quiet, _) = hold(false).await;
        let (flooded, flood_rate) = hold(true).await;
        let stale = (
            quiet.link_guard.commands_stale,
            flooded.link_guard.commands_stale,
        );
        if stale == (0, 0) || pair == PAIRS {
            break (quiet, flooded, flood_rate);
        }
        eprintln!("pair {pair}: stale commands {stale:?} (quiet, flood): flown again");
    };
    for (name, s) in [("quiet", &quiet), ("flood", &flooded)] {
        eprintln!(
            "{name}: {:.1} commands/s; pose->command p50 {} p99 {} us ({} samples); received COMMAND_LONG {}; link guard {:?}",
            command_rate(s),
            s.latency_us.p50,
            s.latency_us.p99,
            s.latency_us.samples,
            s.link_stats.received.total
                - s.link_stats.received.heartbeat
                - s.link_stats.received.local_position_ned
                - s.link_stats.received.attitude,
            s.link_guard
        );
    }
    eprintln!("flood achieved {flood_rate:.0} COMMAND_LONG/s (asked {FLOOD_HZ})");
    // The flood reached the daemon (it answered some, dropped the rest).
    let g = &flooded.link_guard;
    assert!(g.replies_dropped > 1000, "{g:?}");
    // Replies stay within the budget: 20/s after a burst of 10, over the
    // whole run (the ACK and the HEARTBEAT answer each count).
    assert!(
        (g.replies_sent as f64) <= 10.0 + 20.0 * (flooded.duration_s + 1.0),
        "{g:?}"
    );
    for s in [&quiet, &flooded] {
        let rate = command_rate(s);
        assert!((47.0..=52.0).contains(&rate), "command rate {rate:.1}/s");
        assert_eq!(s.link_guard.commands_stale, 0, "{:?}", s.link_guard);
        assert_eq!(s.final_state, FlightState::Holding);
    }
    // The median pose -> command latency moves by less than 0.2 ms. The
    // p99 of 150 samples is the second-largest one: on a shared, loaded
    // machine it is dominated by scheduling noise in either flight, so it
    // is reported above and in the closing note, not asserted.
    assert!(
        flooded.latency_us.p50 <= quiet.latency_us.p50 + 200,
        "pose->command p50 {} us with the flood, {} us without",
        flooded.latency_us.p50,
        quiet.latency_us.p50
    );
}
