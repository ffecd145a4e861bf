//! When the daemon cannot fly, it lets go: a controller that fails on
//! every tick from some point on. The daemon flies its plan fallback, then
//! level hover for at most `safety.level_hover_max_ms`, then stops the
//! stream — the SITL's own position hold takes over — and says why
//! (STATUSTEXT). No level hover beyond the configured period. How long it
//! streamed after the failure is read from the daemon's CSV (tick times
//! from the first failed tick to the last command), not the test's clock.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use dflat_daemon::config::MissionStart;
use dflat_daemon::control::build_controller;
use dflat_daemon::supervisor::FlightState;
use dflat_link::MavMessage;
use dflat_sitl::{self as sitl, SitlEngage, SitlMode, SitlOptions};

mod support;
use support::{Fault, Faulty};

/// The configured level-hover period \[ms\] (shorter than the default 1 s
/// to keep the test short).
const LEVEL_HOVER_MAX_MS: f64 = 600.0;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_controller_that_fails_every_tick_stops_the_stream_in_time() {
    let (mut cfg, plant) = support::sitl_flight("let-go", SitlEngage::Auto);
    cfg.mission.start = MissionStart::Hold;
    cfg.safety.level_hover_max_ms = LEVEL_HOVER_MAX_MS;
    let records = std::env::temp_dir().join(format!("dflat-let-go-{}", std::process::id()));
    cfg.logging.dir = records.to_string_lossy().into_owned();
    cfg.logging.tlog = false;
    let (tx, taps) = mpsc::channel();
    let sitl = sitl::spawn(
        &plant,
        SitlOptions {
            record_trace: true,
            tap: Some(tx),
            ..SitlOptions::default()
        },
    )
    .unwrap();
    let broken = Arc::new(AtomicBool::new(false));
    let breaks = broken.clone();
    // Fails every update once `broken` is set.
    let controller = Faulty {
        inner: build_controller(&cfg).unwrap(),
        tick: 0,
        fault: Box::new(move |_| breaks.load(Ordering::Relaxed).then_some(Fault::Fail)),
    };
    let link = format!("udpout:127.0.0.1:{}", sitl.local_addr().port());
    let daemon = dflat_daemon::spawn_with_controller(cfg.clone(), Some(link), Box::new(controller))
        .await
        .unwrap();
    let until = Instant::now() + Duration::from_secs(5);
    while daemon.state() != Some(FlightState::Holding) {
        assert!(Instant::now() < until, "not engaged: {:?}", daemon.state());
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    broken.store(true, Ordering::Relaxed);
    tokio::time::sleep(Duration::from_secs(3)).await;
    let state = daemon.state();
    let mode = sitl.mode();
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    sitl.stop().unwrap();

    assert_eq!(state, Some(FlightState::Failsafe), "{summary}");
    assert_eq!(mode, SitlMode::Hold, "the autopilot's own hold took over");
    let g = summary.guards;
    assert_eq!(g.control_failsafes, 1, "{g:?}");
    let level_ticks_max = (LEVEL_HOVER_MAX_MS / 20.0).round() as u64;
    assert!(
        g.level_hover <= level_ticks_max,
        "{} level-hover ticks",
        g.level_hover
    );
    assert!(g.level_hover > 0, "{g:?}");
    // In the daemon's CSV: the first tick the controller failed (the plan
    // fallback flown, guard `plan`) and the last command sent.
    let csv_path = summary.csv.as_ref().expect("the flight's CSV").path.clone();
    let csv = dflat_tuning::flightlog::FlightCsv::read(&csv_path).unwrap();
    let _ = std::fs::remove_dir_all(&records);
    let guard = csv.index("guard").expect("guard column");
    let (t, roll) = (csv.numbers("t"), csv.numbers("roll"));
    let failed = (0..csv.rows.len())
        .find(|&i| csv.rows[i][guard] == "plan")
        .expect("a plan-fallback tick in the CSV");
    let last_command = (0..csv.rows.len())
        .rev()
        .find(|&i| roll[i].is_some())
        .expect("a command in the CSV");
    let guards: Vec<&str> = csv.rows[failed..=last_command]
        .iter()
        .map(|r| r[guard].as_str())
        .collect();
    let streamed_after = t[last_command].unwrap() - t[failed].unwrap();
    let frames: Vec<_> = taps.try_iter().collect();
    let plan = f64::from(cfg.safety.hold_last_ticks) * 0.02;
    eprintln!(
        "stream stopped {streamed_after:.2} s after the controller broke (plan {plan:.2} s + level hover ≤ {:.2} s), {} level-hover ticks",
        LEVEL_HOVER_MAX_MS / 1000.0,
        g.level_hover
    );
    assert!(
        streamed_after <= plan + LEVEL_HOVER_MAX_MS / 1000.0 + 0.1,
        "streamed {streamed_after:.2} s: {guards:?}"
    );
    let said = frames.iter().any(|f| match &f.message {
        MavMessage::STATUSTEXT(d) => d.text.to_str().unwrap_or("").contains("control failed"),
        _ => false,
    });
    assert!(said, "no STATUSTEXT naming the cause");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pose_clock_at_0_6_of_real_time_is_found_and_replaced() {
    let (mut cfg, mut plant) = support::sitl_flight("clock", SitlEngage::Auto);
    cfg.mission.start = MissionStart::Hold;
    plant.sitl.pose_clock_rate = 0.6;
    plant.sitl.noise_sigma = 0.01;
    let (tx, taps) = mpsc::channel();
    let sitl = sitl::spawn(
        &plant,
        SitlOptions {
            tap: Some(tx),
            ..SitlOptions::default()
        },
    )
    .unwrap();
    let start = plant.sitl.start;
    let link = format!("udpout:127.0.0.1:{}", sitl.local_addr().port());
    let daemon = dflat_daemon::spawn(cfg.clone(), Some(link)).await.unwrap();
    tokio::time::sleep(Duration::from_secs(6)).await;
    let state = daemon.state();
    let truth = sitl.truth();
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    sitl.stop().unwrap();
    let g = summary.guards;
    eprintln!(
        "0.6x pose clock: {g:?}; final state {state:?}; at {:?}",
        truth.position
    );
    assert_eq!(g.pose_clock_faults, 1, "{summary}");
    let level_ticks_max = (cfg.safety.level_hover_max_ms / 20.0).round() as u64;
    assert!(g.level_hover <= level_ticks_max, "{g:?}");
    let said = taps.try_iter().any(|f| match &f.message {
        MavMessage::STATUSTEXT(d) => d.text.to_str().unwrap_or("").contains("pose clock lags"),
        _ => false,
    });
    assert!(said, "no STATUSTEXT naming the cause");
    // Re-stamped with arrival times, the daemon flies on: holding, near
    // where it started.
    assert_eq!(state, Some(FlightState::Holding), "{summary}");
    let d =
        ((truth.position[0] - start[0]).powi(2) + (truth.position[1] - start[1]).powi(2)).sqrt();
    assert!(d < 0.5, "drifted {d:.2} m");
}
