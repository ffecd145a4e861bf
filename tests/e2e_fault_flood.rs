//! Fault injection, end to end: a flood of 10,000 messages/s for 3 s into
//! the SITL's ground-station port, which routes it to the daemon's link (the
//! daemon's own socket is connected to the autopilot: datagrams sent to it
//! from elsewhere are dropped by the kernel, see `e2e_intruder`) — a third
//! valid LOCAL_POSITION_NED from a wrong system id (42), a third
//! valid-from-the-GCS setpoints outside the geofence, a third garbage bytes
//! (counted by the router, not forwarded) — while it holds against the SITL.
//!
//! The 50 Hz tick keeps going: the daemon stays HOLDING for the whole
//! flight (the flood neither fakes nor starves the pose), no tick gap
//! longer than [`MAX_TICK_GAP`] (jitter reported, not asserted),
//! every command finite, within the tilt limit and the thrust range; the
//! wrong-source poses are ignored and the garbage counted as malformed in
//! the summary.
//!
//! The real `dflat daemon` binary against the in-process SITL.

#[path = "support/mod.rs"]
mod common;

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use common::*;
use dflat_link::MavMessage;
use dflat_link::dialect::LOCAL_POSITION_NED_DATA;

/// Messages per second of the flood.
const RATE: u64 = 10_000;
/// Flood duration (as paced; a loaded machine may take longer, and sends
/// the same datagrams).
const FLOOD: Duration = Duration::from_secs(3);
/// Bursts of `RATE / 100` datagrams, one every 10 ms.
const BURSTS: u32 = 300;
/// Largest step between consecutive CSV tick indices (1 = none missed;
/// 3 = at most two ticks, 40 ms, missed in a row — well within the 100 ms
/// pose timeout and the autopilot's offboard-loss timeouts).
const MAX_TICK_GAP: u64 = 3;

#[test]
fn a_10k_per_second_flood_does_not_disturb_the_50_hz_tick() {
    let dir = scratch("flood");
    let text = hold_config(
        &dir,
        "geofence = [100.0, 100.0, 50.0]",
        "noise_sigma = 0.01",
    );
    let (config, _) = write_daemon_config(&dir, "flood.toml", &text);
    let summary_path = dir.join("summary.json");
    let (sim, tap) = tapped_sitl(
        &config,
        TapOptions {
            gcs: true,
            ..TapOptions::default()
        },
    );
    let mut daemon = spawn_daemon_with(
        &dir,
        &config,
        sim.local_addr(),
        &["--summary-json", summary_path.to_str().unwrap()],
    );
    daemon_local_addr(&daemon, Duration::from_secs(10))
        .expect("the daemon did not log its local address");
    let target = sim.gcs_addr().expect("the SITL's GCS port");

    // Holding for 1 s.
    assert!(
        wait_streaming(&tap, Duration::from_secs(1)),
        "the daemon never streamed"
    );

    // The flood: 100 datagrams every 10 ms.
    let wrong_pose = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        time_boot_ms: 1,
        x: 50.0,
        y: 50.0,
        z: -10.0,
        ..LOCAL_POSITION_NED_DATA::default()
    });
    let outside = position_setpoint([1000.0, 0.0, -10.0]);
    let socket = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut rand = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let (mut sent, mut garbage, mut wrong, mut fenced) = (0u64, 0u64, 0u64, 0u64);
    let start = Instant::now();
    let burst = RATE / 100;
    assert_eq!(Duration::from_millis(10) * BURSTS, FLOOD);
    for k in 1..=BURSTS {
        for i in 0..burst {
            let seq = (sent & 0xff) as u8;
            let ok = match i % 3 {
                0 => {
                    wrong += 1;
                    let f = dflat_link::serialize_v2(&dflat_link::header(42, 1, seq), &wrong_pose)
                        .expect("encode");
                    socket.send_to(f.as_bytes(), target)
                }
                1 => {
                    fenced += 1;
                    let f = dflat_link::serialize_v2(&dflat_link::header(255, 190, seq), &outside)
                        .expect("encode");
                    socket.send_to(f.as_bytes(), target)
                }
                _ => {
                    garbage += 1;
                    let len = 8 + (rand() % 60) as usize;
                    let mut bytes: Vec<u8> = (0..len).map(|_| rand() as u8).collect();
                    // Half of them look like MAVLink 2 frames.
                    if rand() % 2 == 0 {
                        bytes[0] = 0xFD;
                    }
                    socket.send_to(&bytes, target)
                }
            };
            if ok.is_ok() {
                sent += 1;
            }
        }
        let next = start + Duration::from_millis(10) * k;
        if let Some(d) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
    }
    let flood_took = start.elapsed();
    let during = tap
        .try_iter()
        .filter(|f| matches!(f.message, MavMessage::SET_ATTITUDE_TARGET(_)))
        .count();
    std::thread::sleep(Duration::from_secs(1));
    assert!(
        daemon.interrupt_and_wait(Duration::from_secs(5)),
        "the daemon did not exit cleanly"
    );
    let report = sim.stop().expect("sitl stop");
    assert!(!report.diverged);

    let rate = sent as f64 / flood_took.as_secs_f64();
    eprintln!(
        "flood: {sent} datagrams in {:.2} s ({rate:.0}/s): {wrong} wrong-source poses, {fenced} fenced setpoints, {garbage} garbage; {} attitude targets during it",
        flood_took.as_secs_f64(),
        during
    );
    // Every datagram left (the rate is reported, not asserted: the
    // machine is shared); that no tick was lost under it is judged from
    // the CSV's tick indices below.
    assert!(
        sent >= 99 * u64::from(BURSTS) * burst / 100,
        "only {sent} datagrams sent"
    );

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary_path).expect("summary"))
            .expect("summary JSON");
    let jitter = &summary["jitter_us"];
    let link = &summary["link_stats"];
    eprintln!(
        "jitter p50 {} µs, p99 {} µs, max {} µs; missed ticks {}; malformed {}, crc errors {}, wrong source {}, events dropped {}; guards {}",
        jitter["p50"],
        jitter["p99"],
        jitter["max"],
        summary["missed_ticks"],
        link["malformed"],
        link["crc_errors"],
        link["ignored_wrong_source"],
        summary["events_dropped"],
        summary["guards"]
    );
    assert_eq!(summary["final_state"], "holding", "{summary:#}");
    assert_eq!(summary["time_in_state_s"]["failsafe"].as_f64(), Some(0.0));
    // Jitter is reported above, not asserted (timing is shown by the
    // reported figures, not by tests on a shared machine); that the flood
    // costs no tick is asserted below from the CSV's tick indices.
    assert!(jitter["p99"].as_u64().is_some(), "no jitter in the summary");
    // Garbage is counted by the router that received it.
    eprintln!("router frame errors {}", report.counters.frame_errors);
    assert!(
        report.counters.frame_errors > 0,
        "no malformed frame counted"
    );
    assert!(
        link["ignored_wrong_source"].as_u64().unwrap() > wrong / 2,
        "wrong-source poses not counted"
    );

    let rows = read_flight_csv(&dir);
    let (n, worst) = check_csv_commands(&rows, MAX_TILT_DEG);
    let ticks: Vec<u64> = rows.iter().filter_map(|r| r["tick"].parse().ok()).collect();
    // Holding for the whole flight at 50 Hz: a CSV of a few hundred ticks.
    assert!(ticks.len() >= 100, "only {} ticks in the CSV", ticks.len());
    let gap = ticks.windows(2).map(|w| w[1] - w[0]).max().unwrap();
    eprintln!("{n} commands, largest tilt {worst:.2}°, largest tick gap {gap}");
    // Holding under the flood: a command on every tick from the first one.
    let first = rows
        .iter()
        .position(|r| r.get("roll").is_some_and(|v| !v.is_empty()))
        .expect("no command recorded");
    assert_eq!(
        n,
        rows.len() - first,
        "{n} commands in {} ticks from the first",
        rows.len() - first
    );
    assert!(gap <= MAX_TICK_GAP, "tick gap {gap}");
    // Streaming continuously once holding: no FAILSAFE row before the stop
    // (whose level phase is one, `guard` = "stop" marks where it began).
    let stop = rows
        .iter()
        .position(|r| r.get("guard").is_some_and(|g| g == "stop"))
        .unwrap_or(rows.len());
    assert!(rows[..stop].iter().all(|r| r["state"] != "FAILSAFE"));
}
