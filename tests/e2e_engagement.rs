//! Engagement, standby and pilot override, end to end: the real daemon
//! (in process) against the SITL autopilot playing a pilot.
//!
//! * The pilot flies north at 2 m/s in position mode and switches to
//!   OFFBOARD while moving: the daemon, in standby until then, brakes where
//!   it was engaged — it never flies back to the point where it first saw
//!   a pose, stops within the braking distance of the tilt limit plus
//!   0.5 m, and its commands stay within the tilt limit.
//! * A 3 s pilot override in the middle of the L path, then a hand-back:
//!   the path completes, and from the first command of the hand-back the
//!   command moves by at most 5° per tick for 1 s (no kick from a stale
//!   window). Judged on the daemon's own records: the hand-back is the
//!   CSV's tick where STANDBY becomes engaged again, and the second after
//!   it is counted in the CSV's tick times, not on the test's clock. A
//!   flight the machine starved (a tick over 5 ms late in the daemon's
//!   records) is flown again, as `support::fly_unstarved` does.
//! * A dead stream: the SITL refuses OFFBOARD.
//! * The ArduPilot flavour (LOITER → GUIDED_NOGPS, mode numbers as
//!   ArduPilot reports them) end to end.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use dflat_daemon::config::{Config, MissionStart};
use dflat_daemon::supervisor::FlightState;
use dflat_link::MavMessage;
use dflat_sitl::{
    self as sitl, SitlAutopilot, SitlEngage, SitlHandle, SitlMode, SitlOptions, SitlSettings,
    TapFrame,
};

/// The contract's tilt limit \[deg\] (`vehicle.max_tilt_deg` of the shipped
/// configuration) and the f32 quaternion's rounding.
const MAX_TILT_DEG: f64 = 35.0 + 1e-3;
/// Largest command change per tick after a hand-back \[deg\] (the issue's
/// bound; 0.14°/tick is typical in normal flight).
const HANDBACK_STEP_DEG: f64 = 5.0;

/// The shipped SITL configuration (multi-rate DF-MPC, 30° plan tilt, 1 cm
/// noise off here unless set) with the SITL's pilot in charge of
/// engagement.
fn setup(name: &str, start: MissionStart, autopilot: SitlAutopilot) -> (Config, SitlSettings) {
    let (mut cfg, mut plant) = support::sitl_flight(name, SitlEngage::Pilot);
    cfg.mission.start = start;
    plant.sitl.autopilot = autopilot;
    plant.sitl.noise_sigma = 0.01;
    (cfg, plant)
}

fn tap_sitl(plant: &SitlSettings) -> (SitlHandle, mpsc::Receiver<TapFrame>) {
    let (tx, rx) = mpsc::channel();
    let sitl = sitl::spawn(
        plant,
        SitlOptions {
            record_trace: true,
            tap: Some(tx),
            ..SitlOptions::default()
        },
    )
    .unwrap();
    (sitl, rx)
}

/// Starts the daemon with `cfg` on `sitl` and waits (5 s at most) for
/// standby; `what` the message should it not come.
async fn daemon_in_standby(
    cfg: &Config,
    sitl: &SitlHandle,
    what: &str,
) -> dflat_daemon::DaemonHandle {
    let link = format!("udpout:127.0.0.1:{}", sitl.local_addr().port());
    let daemon = dflat_daemon::spawn(cfg.clone(), Some(link)).await.unwrap();
    wait_for(&daemon, FlightState::Standby, Duration::from_secs(5))
        .await
        .expect(what);
    daemon
}

async fn wait_for(
    daemon: &dflat_daemon::DaemonHandle,
    want: FlightState,
    within: Duration,
) -> Option<Instant> {
    let until = Instant::now() + within;
    while Instant::now() < until {
        if daemon.state() == Some(want) {
            return Some(Instant::now());
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    None
}

/// (arrival, roll, pitch) of every SET_ATTITUDE_TARGET the SITL received.
fn commands(rx: &mpsc::Receiver<TapFrame>) -> Vec<(Instant, f64, f64)> {
    rx.try_iter()
        .filter_map(|f| match f.message {
            MavMessage::SET_ATTITUDE_TARGET(d) => {
                let [roll, pitch, _] = dflat_link::euler_from_quaternion(d.q.map(f64::from));
                Some((f.at, roll, pitch))
            }
            _ => None,
        })
        .collect()
}

/// Braking distance \[m\] from `v` [m/s] at the tilt limit `tilt_deg`,
/// commanded at once, through the plant's first-order attitude loop of
/// time constant `tau` \[s\] (a vehicle cannot decelerate before it tilts:
/// at 2 m/s, τ = 0.2 s and 35°, 0.61 m against 0.29 m for an instant tilt).
fn braking_distance(v: f64, tau: f64, tilt_deg: f64) -> f64 {
    let dt = 1e-4;
    let (mut speed, mut x, mut tilt) = (v, 0.0, 0.0f64);
    while speed > 0.0 {
        tilt += dt / tau * (tilt_deg.to_radians() - tilt);
        speed -= 9.81 * tilt.tan() * dt;
        x += speed.max(0.0) * dt;
    }
    x
}

fn tilt_deg(roll: f64, pitch: f64) -> f64 {
    dflat_control::tilt::tilt(pitch, roll).to_degrees()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn engaging_while_the_pilot_flies_brakes_where_it_was_engaged() {
    let (cfg, mut plant) = setup("engage-moving", MissionStart::Hold, SitlAutopilot::Px4);
    plant.sitl.start = [0.0, 0.0, -10.0];
    let (sitl, taps) = tap_sitl(&plant);
    // Standby: streaming, the autopilot in position mode.
    let daemon = daemon_in_standby(&cfg, &sitl, "standby").await;
    let first_seen = sitl.truth().position;
    // The pilot flies north at 2 m/s for 2.5 s (5 m), then engages.
    sitl.set_pilot_velocity([2.0, 0.0, 0.0]);
    tokio::time::sleep(Duration::from_millis(2500)).await;
    assert_eq!(daemon.state(), Some(FlightState::Standby));
    assert_eq!(sitl.mode(), SitlMode::Hold);
    sitl.request_mode(SitlMode::Offboard);
    let engaged_at = Instant::now();
    tokio::time::sleep(Duration::from_millis(30)).await;
    assert_eq!(sitl.mode(), SitlMode::Offboard, "the stream is alive");
    let at_switch = sitl.truth();
    assert!(
        at_switch.velocity[0] > 1.5,
        "moving at the switch: {:?}",
        at_switch.velocity
    );
    // The daemon learns it from the next HEARTBEAT (1 Hz).
    wait_for(&daemon, FlightState::Holding, Duration::from_secs(3))
        .await
        .expect("engaged");
    tokio::time::sleep(Duration::from_secs(4)).await;
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let report = sitl.stop().unwrap();

    let after: Vec<_> = report.trace.iter().filter(|s| s.t >= at_switch.t).collect();
    let x0 = at_switch.position[0];
    let x_max = after.iter().map(|s| s.position[0]).fold(f64::MIN, f64::max);
    let x_end = after.last().unwrap().position[0];
    let v = at_switch.velocity[0];
    let braking = braking_distance(v, plant.sitl.tau, 35.0);
    eprintln!(
        "engaged at x = {x0:.2} m, {v:.2} m/s (first pose at x = {:.2}); stopped at {x_max:.2} m \
         ({:.2} m past, braking distance at 35° {braking:.2} m), back-move {:.3} m, end {x_end:.2} m",
        first_seen[0],
        x_max - x0,
        x_max - x_end
    );
    assert!(
        x_max - x_end <= 0.3,
        "moved back {:.2} m against its motion",
        x_max - x_end
    );
    assert!(
        x_max - x0 <= braking + 0.5,
        "stopped {:.2} m past the switch (braking {braking:.2} m + 0.5)",
        x_max - x0
    );
    assert!(x_end > x0 - 0.3, "flew back towards the first pose");
    let cmds = commands(&taps);
    let worst = cmds
        .iter()
        .filter(|(at, _, _)| *at >= engaged_at)
        .map(|(_, r, p)| tilt_deg(*r, *p))
        .fold(0.0, f64::max);
    eprintln!("largest tilt after the switch {worst:.1}°");
    assert!(worst <= MAX_TILT_DEG, "tilt {worst:.2}°");
    assert_eq!(summary.engagements, 1, "{summary}");
    assert_eq!(summary.disengagements, 0);
    assert!(summary.time_in_state_s.standby > 2.0);
    assert_eq!(summary.final_state, FlightState::Holding);
}

/// One override flight (the test below): what the daemon and the SITL
/// said, whether the path completed, the daemon's CSV and the commands
/// the SITL received.
struct OverrideFlight {
    summary: dflat_daemon::summary::FlightSummary,
    diverged: bool,
    arrived: bool,
    csv: dflat_tuning::flightlog::FlightCsv,
    cmds: Vec<(Instant, f64, f64)>,
}

impl OverrideFlight {
    /// The latest engaged or standby tick in the daemon's records \[µs\]
    /// (`jitter_us` of the rows that carry a command).
    fn latest_tick_us(&self) -> f64 {
        let (roll, jitter) = (self.csv.numbers("roll"), self.csv.numbers("jitter_us"));
        roll.iter()
            .zip(&jitter)
            .filter_map(|(r, j)| r.and(*j))
            .fold(0.0, f64::max)
    }
}

/// Flies the L path with a 3 s pilot override 4 s in and the hand-back
/// (the test below), as flight `attempt`.
async fn fly_override(attempt: usize) -> OverrideFlight {
    let (mut cfg, plant) = setup("override", MissionStart::Path, SitlAutopilot::Px4);
    // The daemon's records: the hand-back is judged from them.
    let records =
        std::env::temp_dir().join(format!("dflat-override-{}-{attempt}", std::process::id()));
    cfg.logging.dir = records.to_string_lossy().into_owned();
    cfg.logging.tlog = false;
    let (sitl, taps) = tap_sitl(&plant);
    let daemon = daemon_in_standby(&cfg, &sitl, "standby").await;
    sitl.request_mode(SitlMode::Offboard);
    wait_for(&daemon, FlightState::Tracking, Duration::from_secs(5))
        .await
        .expect("tracking the path");
    // 4 s into the path (on the first leg at 5 m/s): the pilot takes over
    // for 3 s, sticks centred, then hands back.
    tokio::time::sleep(Duration::from_secs(4)).await;
    sitl.request_mode(SitlMode::Hold);
    wait_for(&daemon, FlightState::Standby, Duration::from_secs(3))
        .await
        .expect("standby after the override");
    tokio::time::sleep(Duration::from_secs(2)).await;
    sitl.request_mode(SitlMode::Offboard);
    // The rest of the path (≤ 50 m at 5 m/s) and 1 s more.
    let end = *cfg.mission.path.last().unwrap();
    let arrived = support::arrive_and_linger(&sitl, end, 0.5, Duration::from_secs(25)).await;
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let report = sitl.stop().unwrap();
    let csv_path = summary.csv.as_ref().expect("the flight's CSV").path.clone();
    let csv = dflat_tuning::flightlog::FlightCsv::read(&csv_path).unwrap();
    let _ = std::fs::remove_dir_all(&records);
    OverrideFlight {
        summary,
        diverged: report.diverged,
        arrived,
        csv,
        cmds: commands(&taps),
    }
}

/// The override flight, flown again while the daemon's own records show
/// a tick later than [`support::STARVED_US`] (the machine starved it:
/// its pose failsafe then holds, as designed, and the path does not
/// complete in time), up to [`support::STARVED_ATTEMPTS`] flights; when
/// every one was starved, the least late is judged (said).
async fn fly_override_unstarved() -> OverrideFlight {
    let mut flights = support::LeastLate::new("override");
    for attempt in 1..=support::STARVED_ATTEMPTS {
        let flight = fly_override(attempt).await;
        let late = flight.latest_tick_us();
        if flights.offer(attempt, late, flight) {
            break;
        }
    }
    flights.judged().1
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn override_and_hand_back_on_the_l_path_without_a_kick() {
    let OverrideFlight {
        summary,
        diverged,
        arrived,
        csv,
        cmds,
    } = fly_override_unstarved().await;
    assert!(!diverged);
    assert!(arrived, "path not completed: {summary}");
    assert_eq!(summary.engagements, 2, "{summary}");
    assert_eq!(summary.disengagements, 1, "{summary}");

    // The hand-back in the daemon's CSV: the last tick where STANDBY
    // becomes engaged (TRACKING or HOLDING); its second by the CSV's tick
    // times, from the last standby command (the step into the engagement
    // counts too).
    let state = csv.index("state").expect("state column");
    let engaged = |i: usize| matches!(csv.rows[i][state].as_str(), "TRACKING" | "HOLDING");
    let handback = (1..csv.rows.len())
        .rev()
        .find(|&i| csv.rows[i - 1][state] == "STANDBY" && engaged(i))
        .expect("a hand-back in the CSV");
    let t = csv.numbers("t");
    let (roll, pitch) = (csv.numbers("roll"), csv.numbers("pitch"));
    let t0 = t[handback].expect("tick time");
    let after: Vec<(f64, f64)> = (handback - 1..csv.rows.len())
        .take_while(|&i| t[i].is_some_and(|ti| ti <= t0 + 1.0))
        .filter_map(|i| Some((roll[i]?, pitch[i]?)))
        .collect();
    let in_second = (handback..csv.rows.len())
        .take_while(|&i| t[i].is_some_and(|ti| ti <= t0 + 1.0))
        .filter(|&i| roll[i].is_some())
        .count();
    assert!(
        in_second >= 40,
        "{in_second} commands in the second after the hand-back (CSV tick times from {t0:.3} s)"
    );
    let steps: Vec<f64> = after
        .windows(2)
        .map(|w| {
            let d = ((w[1].0 - w[0].0).powi(2) + (w[1].1 - w[0].1).powi(2)).sqrt();
            d.to_degrees()
        })
        .collect();
    let worst = steps.iter().copied().fold(0.0, f64::max);
    let normal: Vec<f64> = cmds
        .windows(2)
        .map(|w| (((w[1].1 - w[0].1).powi(2) + (w[1].2 - w[0].2).powi(2)).sqrt()).to_degrees())
        .collect();
    eprintln!(
        "hand-back: largest command step {worst:.2}°/tick in the first second (median over the flight {:.3}°/tick)",
        support::quantile(&normal, 0.5)
    );
    assert!(
        worst <= HANDBACK_STEP_DEG,
        "command jumped {worst:.2}° in one tick after the hand-back"
    );
    let worst_tilt = cmds
        .iter()
        .map(|(_, r, p)| tilt_deg(*r, *p))
        .fold(0.0, f64::max);
    // The wire never carries more than the limit (the guard's cut), and
    // the guard never had to cut: the controller kept within it itself.
    assert!(worst_tilt <= MAX_TILT_DEG, "tilt {worst_tilt:.2}°");
    assert_eq!(summary.guards.tilt_saturated, 0, "{:?}", summary.guards);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn offboard_is_refused_without_a_stream_and_the_ardupilot_flavour_flies() {
    let (mut cfg, plant) = setup("ardupilot", MissionStart::Hold, SitlAutopilot::Ardupilot);
    // A short leg from the start, triggered by the mission start.
    cfg.mission.start = MissionStart::Path;
    cfg.mission.path = vec![[-20.0, -30.0, -10.0], [-12.0, -30.0, -10.0]];
    let (sitl, _taps) = tap_sitl(&plant);
    // No daemon yet: no stream, OFFBOARD (GUIDED_NOGPS) refused.
    tokio::time::sleep(Duration::from_millis(200)).await;
    sitl.request_mode(SitlMode::Offboard);
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert_eq!(sitl.mode(), SitlMode::Hold);
    assert_eq!(sitl.counters().offboard_refused, 1);

    let daemon = daemon_in_standby(&cfg, &sitl, "standby: LOITER is not GUIDED_NOGPS").await;
    sitl.request_mode(SitlMode::Offboard);
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(sitl.mode(), SitlMode::Offboard);
    wait_for(&daemon, FlightState::Tracking, Duration::from_secs(5))
        .await
        .expect("engaged in GUIDED_NOGPS, flying the path");
    let end = *cfg.mission.path.last().unwrap();
    let until = Instant::now() + Duration::from_secs(10);
    let mut arrived = false;
    while Instant::now() < until && !arrived {
        tokio::time::sleep(Duration::from_millis(20)).await;
        arrived = support::dist(sitl.truth().position, end) < 0.3;
    }
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let report = sitl.stop().unwrap();
    assert!(arrived, "did not reach {end:?}: {:?}", report.last.position);
    assert_eq!(summary.engagements, 1, "{summary}");
    assert_eq!(report.counters.offboard_refused, 1);
}

mod support;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn engagement_is_refused_above_the_autopilots_tilt_limit() {
    // The SITL's MPC_TILTMAX_AIR is its own 35° limit; ask for 40°.
    let (mut cfg, plant) = setup("tilt-refused", MissionStart::Hold, SitlAutopilot::Px4);
    cfg.vehicle.max_tilt_deg = 40.0;
    let (sitl, taps) = tap_sitl(&plant);
    let daemon = daemon_in_standby(&cfg, &sitl, "standby").await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    sitl.request_mode(SitlMode::Offboard);
    tokio::time::sleep(Duration::from_secs(3)).await;
    let state = daemon.state();
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    sitl.stop().unwrap();
    let frames: Vec<_> = taps.try_iter().collect();
    let requested: Vec<String> = frames
        .iter()
        .filter_map(|f| match &f.message {
            MavMessage::PARAM_REQUEST_READ(d) => Some(d.param_id.to_str().unwrap_or("").to_owned()),
            _ => None,
        })
        .collect();
    assert!(
        requested.iter().any(|n| n == "MPC_THR_HOVER"),
        "{requested:?}"
    );
    assert!(
        requested.iter().any(|n| n == "MPC_TILTMAX_AIR"),
        "{requested:?}"
    );
    let said: Vec<String> = frames
        .iter()
        .filter_map(|f| match &f.message {
            MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
            _ => None,
        })
        .filter(|t| t.contains("not engaging"))
        .collect();
    eprintln!("{said:?}");
    assert_eq!(said, ["dflat: not engaging, tilt 40 > MPC_TILTMAX_AIR 35"]);
    assert_eq!(state, Some(FlightState::Standby), "{summary}");
    assert_eq!(summary.engagements, 0);
}
