//! End to end: when the pose stream stops, the daemon stops streaming
//! attitude targets once its failsafe level hover is over
//! (`safety.level_hover_max_ms`, 1 s by default, plus the pose timeout and
//! 200 ms of margin), and resumes when pose returns. (What it streams in
//! that second is `e2e_pose_loss_level`'s subject.)
//!
//! The real `dflat daemon` binary against the SITL run in-process
//! (`dflat_sitl`), whose hooks pause / resume the pose stream and
//! tap every frame the daemon sends, with its arrival time.

#[path = "support/mod.rs"]
mod common;

use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use common::*;
use dflat_daemon::config::Config;
use dflat_link::MavMessage;
use dflat_sitl::{self as sitl, SitlOptions, TapFrame};

/// The daemon must fall silent within this time after the pose stops:
/// the pose timeout (100 ms) and the level hover (1 s) of the defaults,
/// plus 200 ms.
const STOP_WITHIN: Duration = Duration::from_millis(1300);
/// ... and stream again within this time after the pose returns.
const RESUME_WITHIN: Duration = Duration::from_millis(500);

fn attitude_targets(tap: &Receiver<TapFrame>) -> Vec<Instant> {
    tap.try_iter()
        .filter(|f| matches!(f.message, MavMessage::SET_ATTITUDE_TARGET(_)))
        .map(|f| f.at)
        .collect()
}

#[test]
fn pose_loss_stops_the_stream_after_the_level_hover_and_pose_return_resumes_it() {
    let dir = scratch("poseloss");
    let text = format!(
        r#"
[mission]
start = "hold"
[logging]
dir = "{}"
tlog = false
[sitl]
start = [0.0, 0.0, -10.0]
"#,
        dir.display()
    );
    let config = write_config(&dir, "poseloss.toml", &text);
    Config::load(&config).expect("daemon config");
    let (tx, tap) = channel();
    let sim = sitl::spawn(
        &dflat_sitl::SitlSettings::load(&config).expect("sitl config"),
        SitlOptions {
            link: Some("udpin:127.0.0.1:0".into()),
            tap: Some(tx),
            ..SitlOptions::default()
        },
    )
    .expect("sitl");
    let _daemon = spawn_daemon(&dir, &config, sim.local_addr());

    // Streaming steadily for 1 s.
    let until = Instant::now() + Duration::from_secs(15);
    let mut streaming_since = None;
    while Instant::now() < until {
        std::thread::sleep(Duration::from_millis(50));
        if !attitude_targets(&tap).is_empty() {
            let since = *streaming_since.get_or_insert_with(Instant::now);
            if since.elapsed() > Duration::from_secs(1) {
                break;
            }
        }
    }
    assert!(streaming_since.is_some(), "the daemon never streamed");

    for round in 0..2 {
        // Pose stops.
        let _ = attitude_targets(&tap);
        let paused = Instant::now();
        sim.pause_pose();
        std::thread::sleep(Duration::from_millis(1800));
        let during = attitude_targets(&tap);
        let last = during.iter().filter(|t| **t >= paused).max().copied();
        let silent_after = last.map_or(Duration::ZERO, |t| t - paused);
        eprintln!(
            "round {round}: last attitude target {:.0} ms after the pose stopped",
            silent_after.as_secs_f64() * 1e3
        );
        assert!(
            silent_after <= STOP_WITHIN,
            "still streaming {silent_after:?} after the pose stopped"
        );
        // Pose returns.
        let resumed = Instant::now();
        sim.resume_pose();
        let mut first = None;
        while resumed.elapsed() < Duration::from_secs(3) && first.is_none() {
            std::thread::sleep(Duration::from_millis(10));
            first = attitude_targets(&tap).into_iter().find(|t| *t >= resumed);
        }
        let first = first.expect("the daemon did not resume streaming within 3 s");
        eprintln!(
            "round {round}: streaming again {:.0} ms after the pose returned",
            (first - resumed).as_secs_f64() * 1e3
        );
        assert!(
            first - resumed <= RESUME_WITHIN,
            "resumed only after {:?}",
            first - resumed
        );
        // And it keeps streaming at ~50 Hz.
        std::thread::sleep(Duration::from_millis(1000));
        let n = attitude_targets(&tap).len();
        assert!(
            n >= 40,
            "only {n} attitude targets in the second after resuming"
        );
    }
    let report = sim.stop().expect("sitl stop");
    assert!(!report.diverged);
}
