//! The shipped `config/px4.toml`, flown as shipped (spatial model,
//! normalised thrust, the disturbance estimator on) against the SITL's
//! spatial plant whose hover thrust is 0.4 where the file says 0.5: the
//! daemon must hold its altitude within 0.1 m after settling — 95 % of the
//! last 3 s within the band, no sample beyond twice it (without the
//! estimator it settles about 1.3 m low). The band is judged on the 95th
//! percentile because the SITL runs in real time on a shared machine: one
//! full-suite run, its tick jitter at p99 1.0 ms and max 8.2 ms, had a
//! single excursion to 0.109 m (mean 0.047 m); alone the worst is
//! 0.02–0.05 m.

#[path = "support/mod.rs"]
mod common;

use std::path::Path;
use std::time::{Duration, Instant};

use dflat_daemon::config::Config;
use dflat_daemon::supervisor::FlightState;
use dflat_sitl::SitlSettings;

/// Altitude band after settling \[m\]: the 95th percentile of the error
/// within it, the worst within twice it.
const ALTITUDE_BAND: f64 = 0.1;
/// Flight time after engagement \[s\]; the last [`CHECK_S`] are checked.
/// The altitude sags about 1 m while the estimator learns the hover
/// thrust and recovers within some 10 s. Under load the daemon ticks on
/// its deadline for late poses; until 2026-11-29 the estimator restarted
/// its fit window on each such tick, and beside eight busy loops (load average ~10) the sag
/// was still 0.2–1.2 m 13–16 s into a 16 s hover (the full suite failed
/// this test twice); with the window kept, 0.001 m there and 0.011–0.016 m
/// over the last 3 s of 12 s (`DisturbanceEstimator::record_input`).
const FLY_S: f64 = 12.0;
const CHECK_S: f64 = 3.0;

fn px4_toml() -> (String, &'static Path) {
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/px4.toml"));
    (std::fs::read_to_string(path).unwrap(), path)
}

/// The altitude error over the last [`CHECK_S`] s: mean, 95th percentile
/// and worst \[m\].
#[derive(Debug, Clone, Copy)]
struct AltitudeError {
    mean: f64,
    p95: f64,
    worst: f64,
}

impl AltitudeError {
    /// Asserts the band: the 95th percentile within it, the worst within
    /// twice it.
    fn assert_within_band(&self) {
        assert!(
            self.p95 <= ALTITUDE_BAND && self.worst <= 2.0 * ALTITUDE_BAND,
            "altitude off: {self:?} against the band {ALTITUDE_BAND} m"
        );
    }
}

async fn hold_altitude(disturbance: bool) -> AltitudeError {
    hold_altitude_with(disturbance, false).await
}

/// As [`hold_altitude`], with `vehicle.hover_thrust_from_autopilot`.
async fn hold_altitude_with(disturbance: bool, autopilot_hover: bool) -> AltitudeError {
    let (text, path) = px4_toml();
    let mut cfg = Config::parse(&text, path).unwrap();
    cfg.logging.dir = String::new();
    cfg.controller.disturbance.enabled = disturbance;
    cfg.vehicle.hover_thrust_from_autopilot = autopilot_hover;
    let mut plant = SitlSettings::parse(&text, path).unwrap();
    plant.sitl.url = "udpin:127.0.0.1:0".into();
    plant.sitl.hover_thrust = 0.4;
    let sitl = common::traced_sitl(&plant);
    let z0 = plant.sitl.start[2];
    let link = format!("udpout:127.0.0.1:{}", sitl.local_addr().port());
    let daemon = dflat_daemon::spawn(cfg, Some(link)).await.unwrap();
    let until = Instant::now() + Duration::from_secs(5);
    while daemon.state() != Some(FlightState::Holding) {
        assert!(Instant::now() < until, "not engaged: {:?}", daemon.state());
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let engaged = sitl.truth().t;
    tokio::time::sleep(Duration::from_secs_f64(FLY_S)).await;
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let report = sitl.stop().unwrap();
    // The daemon's counters in the log, for a failure's diagnosis (one
    // failure seen at load ~5: mean 0.334 m; alone 0.021 m).
    eprintln!("{summary}");
    assert_eq!(summary.final_state, FlightState::Holding, "{summary}");
    let end = engaged + FLY_S;
    let errs: Vec<f64> = report
        .trace
        .iter()
        .filter(|s| s.t >= end - CHECK_S && s.t <= end)
        .map(|s| (s.position[2] - z0).abs())
        .collect();
    assert!(errs.len() > 100, "{} samples", errs.len());
    AltitudeError {
        mean: errs.iter().sum::<f64>() / errs.len() as f64,
        p95: common::quantile(&errs, 0.95),
        worst: errs.iter().copied().fold(0.0, f64::max),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_px4_config_holds_altitude_on_a_vehicle_hovering_at_0_4() {
    let e = hold_altitude(true).await;
    eprintln!(
        "px4.toml, hover 0.4: altitude error mean {:.3} m, p95 {:.3} m, worst {:.3} m over the last {CHECK_S} s",
        e.mean, e.p95, e.worst
    );
    e.assert_within_band();
    // Negative control: the estimator is what holds it.
    let mean_off = hold_altitude(false).await.mean;
    eprintln!("without the estimator: mean {mean_off:.3} m");
    assert!(mean_off > 5.0 * ALTITUDE_BAND, "{mean_off:.3} m");
}

/// `vehicle.hover_thrust_from_autopilot = true`: the SITL answers
/// MPC_THR_HOVER 0.4 before the engagement and the daemon flies it, so
/// even without the disturbance estimator the altitude holds (without the
/// option the same flight settles about 1.3 m low).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_autopilots_hover_thrust_holds_altitude_without_the_estimator() {
    let e = hold_altitude_with(false, true).await;
    eprintln!(
        "px4.toml, hover 0.4 read from MPC_THR_HOVER, no estimator: altitude error mean {:.3} m, p95 {:.3} m, worst {:.3} m",
        e.mean, e.p95, e.worst
    );
    e.assert_within_band();
}
