//! End to end: an autopilot that streams its pose and attitude slower than
//! the daemon ticks (ArduPilot's `SRn_` defaults, PX4's `Onboard` link).
//! The SITL starts at 5 Hz (`sitl.telemetry_rate_hz`); the daemon asks it,
//! by MAV_CMD_SET_MESSAGE_INTERVAL, for LOCAL_POSITION_NED and ATTITUDE at
//! its 50 Hz (`link.request_streams`, default on) and flies the short L on
//! them, with the SITL's PX4 face and its ArduPilot face. An autopilot that refuses (`sitl.fixed_telemetry_rate`) is said in
//! words, with the pose timeout's warning against the slow stream.

#[path = "support/mod.rs"]
mod common;

use std::time::Duration;

use common::*;
use dflat_link::dialect::MavCmd;

/// The SITL's starting rate \[Hz\], ten times slower than the tick.
const SLOW: &str = "plant = \"planar\"\ntelemetry_rate_hz = 5.0";

/// The daemon's SET_MESSAGE_INTERVAL requests in `flight`: (message id,
/// interval µs), in order.
fn interval_requests(flight: &Flight) -> Vec<(u32, f32)> {
    flight
        .frames
        .iter()
        .filter_map(|f| match &f.message {
            dflat_link::MavMessage::COMMAND_LONG(d)
                if d.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL =>
            {
                Some((d.param1 as u32, d.param2))
            }
            _ => None,
        })
        .collect()
}

/// The daemon's summary's answers to its stream-rate requests: (message,
/// answer), in the order asked.
fn stream_answers(flight: &Flight) -> Vec<[String; 2]> {
    let summary = flight.summary().expect("the daemon's summary");
    summary["autopilot_streams"]
        .as_array()
        .expect("autopilot_streams")
        .iter()
        .map(|s| {
            let field = |k: &str| s[k].as_str().expect("a string").to_owned();
            [field("message"), field("answer")]
        })
        .collect()
}

#[test]
fn a_slow_autopilot_stream_is_raised_to_the_tick_rate() {
    raised("stream-rates-raised", "");
}

/// The same with the SITL's ArduPilot face (GUIDED_NOGPS engages; its
/// `SRn_POSITION` defaults are a few Hz).
#[test]
fn a_slow_ardupilot_stream_is_raised_to_the_tick_rate() {
    raised("stream-rates-raised-ardupilot", "autopilot = \"ardupilot\"");
}

/// Flies the short L against the SITL started at 5 Hz (with the further
/// `[sitl]` keys `sitl`) and judges that the daemon raised the stream.
fn raised(name: &str, sitl: &str) {
    let config = format!("{SHORT_L}\n[sitl]\nstart = [0.0, 0.0, -10.0]\n{SLOW}\n{sitl}\n");
    let flight = fly_in_process(name, &config, Duration::from_secs(6));
    assert!(flight.clean_exit, "the daemon did not exit cleanly");
    let asked = interval_requests(&flight);
    assert_eq!(
        asked,
        [(32, 20_000.0), (30, 20_000.0)],
        "each asked once, in order, and answered"
    );
    let texts: Vec<String> = flight.statustexts().collect();
    assert!(
        !texts
            .iter()
            .any(|t| t.contains(" Hz ") || t.contains("pose timeout")),
        "no refusal, no pose-timeout warning: {texts:?}"
    );
    // The daemon's own records: the pose each commanding tick flew on was
    // at most a 50 Hz interval (and the tick's lateness) old, after the
    // first second of streaming (the request goes out at the first
    // HEARTBEAT; the stream may begin on the slow poses).
    let rows = read_flight_csv(&flight.dir);
    let wakes: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| field(r, "roll").is_some())
        .filter_map(|r| Some((field(r, "t_wake")?, field(r, "pose_age_ms")?)))
        .collect();
    let first = wakes.first().expect("commanded ticks").0;
    let ages: Vec<f64> = wakes
        .iter()
        .filter(|(t, _)| *t > first + 1.0)
        .map(|(_, a)| *a)
        .collect();
    assert!(ages.len() > 150, "{} commanded ticks", ages.len());
    let p95 = quantile(&ages, 0.95);
    eprintln!(
        "{name}: SITL from 5 Hz: {} LOCAL_POSITION_NED, {} ATTITUDE sent; pose age at the ticks \
         p95 {p95:.1} ms over {} commanding ticks",
        flight.report.counters.positions_sent,
        flight.report.counters.attitudes_sent,
        ages.len()
    );
    assert!(
        p95 <= 40.0,
        "pose age p95 {p95:.1} ms: the stream stayed slow"
    );
    flight.assert_no_failsafe("the raised stream");
    // The daemon's summary keeps the answers.
    assert_eq!(
        stream_answers(&flight),
        [["LOCAL_POSITION_NED", "accepted"], ["ATTITUDE", "accepted"]]
    );
    let (errors, arrived) = path_errors(
        &flight.report.trace,
        &[[0.0, 0.0, -10.0], [8.0, 0.0, -10.0], [8.0, 6.0, -10.0]],
        0.5,
    );
    assert!(arrived, "the L was not flown to its end");
    let p95_path = quantile(&errors, 0.95);
    assert!(p95_path < 0.5, "path error p95 {p95_path:.3} m");
}

#[test]
fn an_autopilot_that_refuses_is_said_in_words() {
    let config = format!(
        "{SHORT_L}\n[sitl]\nstart = [0.0, 0.0, -10.0]\n{SLOW}\nfixed_telemetry_rate = true\n"
    );
    let end = FlightEnd {
        fly: Duration::from_secs(6),
        cap: Duration::from_secs(12),
        settle: Duration::ZERO,
    };
    let flight = fly_in_process_until("stream-rates-refused", &config, end, |_| false);
    let texts: Vec<String> = flight.statustexts().collect();
    for want in [
        "dflat: LOCAL_POSITION_NED at 50 Hz DENIED",
        "dflat: ATTITUDE at 50 Hz DENIED",
    ] {
        assert_eq!(
            texts.iter().filter(|t| *t == want).count(),
            1,
            "{want:?} once: {texts:?}"
        );
    }
    // The stream stays at 5 Hz: the default 100 ms pose timeout is under
    // two of its intervals, which the daemon says too.
    assert!(
        texts
            .iter()
            .any(|t| t.contains("pose timeout 100ms < 2x period 200ms")),
        "the pose timeout's warning: {texts:?}"
    );
    assert_eq!(
        interval_requests(&flight).len(),
        2,
        "each asked once: a refusal is not asked again"
    );
    assert_eq!(
        stream_answers(&flight),
        [["LOCAL_POSITION_NED", "DENIED"], ["ATTITUDE", "DENIED"]]
    );
}
