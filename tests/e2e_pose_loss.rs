//! End to end: when the pose stream stops, the daemon stops streaming
//! attitude targets once its failsafe level hover is over
//! (`safety.level_hover_max_ms`, 1 s by default, plus the pose timeout and
//! 200 ms of margin), and resumes when pose returns. (What it streams in
//! that second is `e2e_pose_loss_level`'s subject.)
//!
//! The real `dflat daemon` binary against the SITL run in-process
//! (`dflat_sitl`), whose hooks pause / resume the pose stream. Judged on
//! the daemon's records: each tick's time and the age of its newest pose.

#[path = "support/mod.rs"]
mod common;

use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use common::*;
use dflat_link::MavMessage;
use dflat_sitl::TapFrame;

/// The daemon must fall silent within this time after the pose stops
/// \[ms\]: the pose timeout (100 ms) and the level hover (1 s) of the
/// defaults, plus 200 ms.
const STOP_WITHIN_MS: f64 = 1300.0;
/// ... and stream again within this time after the pose returns \[ms\].
const RESUME_WITHIN_MS: f64 = 500.0;
/// A tick whose newest pose is older than this has lost the pose \[ms\]
/// (the daemon's default pose timeout).
const POSE_TIMEOUT_MS: f64 = 100.0;

fn attitude_targets(tap: &Receiver<TapFrame>) -> usize {
    tap.try_iter()
        .filter(|f| matches!(f.message, MavMessage::SET_ATTITUDE_TARGET(_)))
        .count()
}

/// One pose outage in the daemon's records, on its clock: how long after
/// the newest pose it still commanded \[ms\], how long after the pose's
/// return it commanded again \[ms\], and its commands in the second from
/// that one.
#[derive(Debug)]
struct Outage {
    silent_after_ms: f64,
    resumed_after_ms: f64,
    commands_in_second: usize,
}

/// The pose outages of the flight CSV's rows (ticks whose newest pose is
/// older than [`POSE_TIMEOUT_MS`], or missing, after the first fresh one);
/// an outage the pose never came back from is not one.
fn outages(rows: &[std::collections::HashMap<String, String>]) -> Vec<Outage> {
    let age = |i: usize| field(&rows[i], "pose_age_ms");
    let wake = |i: usize| field(&rows[i], "t_wake").expect("t_wake");
    let commanded = |i: usize| field(&rows[i], "roll").is_some();
    let fresh = |i: usize| age(i).is_some_and(|a| a <= POSE_TIMEOUT_MS);
    let mut found = Vec::new();
    let mut i = (0..rows.len()).find(|&i| fresh(i)).unwrap_or(rows.len());
    while i < rows.len() {
        if fresh(i) {
            i += 1;
            continue;
        }
        let start = i;
        while i < rows.len() && !fresh(i) {
            i += 1;
        }
        if i == rows.len() {
            break;
        }
        // The newest pose before the outage and the pose's return: the
        // captures of the last and the next fresh tick's poses.
        let capture = |j: usize| pose_capture(&rows[j]).expect("fresh");
        let (lost, back) = (capture(start - 1), capture(i));
        let silent_after_ms = (start..i)
            .filter(|&j| commanded(j))
            .map(|j| (wake(j) - lost) * 1e3)
            .fold(0.0, f64::max);
        let Some(first) = (i..rows.len()).find(|&j| commanded(j)) else {
            break;
        };
        let t0 = wake(first);
        let commands_in_second = (first..rows.len())
            .take_while(|&j| wake(j) <= t0 + 1.0)
            .filter(|&j| commanded(j))
            .count();
        found.push(Outage {
            silent_after_ms,
            resumed_after_ms: (t0 - back) * 1e3,
            commands_in_second,
        });
    }
    found
}

#[test]
fn pose_loss_stops_the_stream_after_the_level_hover_and_pose_return_resumes_it() {
    let dir = scratch("poseloss");
    let text = hold_config(&dir, "", "");
    let (config, _) = write_daemon_config(&dir, "poseloss.toml", &text);
    let (sim, tap) = tapped_sitl(&config, TapOptions::default());
    let mut daemon = spawn_daemon(&dir, &config, sim.local_addr());

    // Streaming steadily for 1 s.
    assert!(
        wait_streaming(&tap, Duration::from_secs(1)),
        "the daemon never streamed"
    );

    // Two outages: the pose stops for 1.8 s, returns, and the stream runs
    // on for a second from its return (at most 3 s to return).
    for _ in 0..2 {
        sim.pause_pose();
        std::thread::sleep(Duration::from_millis(1800));
        attitude_targets(&tap);
        sim.resume_pose();
        let resumed = Instant::now();
        while resumed.elapsed() < Duration::from_secs(3) && attitude_targets(&tap) == 0 {
            std::thread::sleep(Duration::from_millis(10));
        }
        std::thread::sleep(Duration::from_millis(1000));
    }
    assert!(daemon.interrupt_and_wait(Duration::from_secs(5)));
    let report = sim.stop().expect("sitl stop");
    assert!(!report.diverged);

    // Judged on the daemon's records: its tick times and pose ages.
    let found = outages(&read_flight_csv(&dir));
    assert_eq!(found.len(), 2, "pose outages in the records: {found:?}");
    for (round, o) in found.iter().enumerate() {
        eprintln!(
            "round {round}: last command {:.0} ms after the newest pose, streaming again {:.0} ms after its return, {} commands in that second",
            o.silent_after_ms, o.resumed_after_ms, o.commands_in_second
        );
        assert!(
            o.silent_after_ms <= STOP_WITHIN_MS,
            "still streaming {:.0} ms after the pose stopped",
            o.silent_after_ms
        );
        assert!(
            o.resumed_after_ms <= RESUME_WITHIN_MS,
            "resumed only after {:.0} ms",
            o.resumed_after_ms
        );
        assert!(
            o.commands_in_second >= 40,
            "only {} commands in the second after resuming",
            o.commands_in_second
        );
    }
}
