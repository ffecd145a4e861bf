//! The stream-rate requests in the pure step (`link.request_streams`,
//! [`crate::stream_rates`]): asked once the autopilot is heard, one at a
//! time, answered or said; none with the key off.

use dflat_link::MavMessage;

use super::tests::{Script, core, core_with, step_at};
use super::*;

/// The stream-rate requests of `out`: (message id, interval µs).
fn interval_requests(out: &StepOutput) -> Vec<(u32, f32)> {
    out.texts
        .iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_LONG(d)
                if d.command == dflat_link::dialect::MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL =>
            {
                assert_eq!((d.target_system, d.target_component), (1, 1));
                Some((d.param1 as u32, d.param2))
            }
            _ => None,
        })
        .collect()
}

/// `link.request_streams` (default): once the autopilot is heard, the
/// pose message and then ATTITUDE are asked at the tick rate, one at a
/// time; an acceptance moves on, a refusal is said in words; with the key
/// off nothing is asked.
#[test]
fn asks_the_autopilot_for_its_streams_at_the_tick_rate_one_at_a_time() {
    use dflat_link::dialect::MavResult;
    let (mut core, _) = core(vec![Script::Command(0.0, 0.0)]);
    let step = |core: &mut ControlCore, k: u64, extra: Vec<Event>| step_at(core, k, None, extra);
    let out = step(&mut core, 0, vec![]);
    assert_eq!(interval_requests(&out), [(32, 20_000.0)]);
    assert!(
        interval_requests(&step(&mut core, 1, vec![])).is_empty(),
        "waits"
    );
    let ack = |result| Event::IntervalAck {
        arrival: 0.03,
        result,
    };
    let out = step(&mut core, 2, vec![ack(MavResult::MAV_RESULT_ACCEPTED)]);
    assert_eq!(interval_requests(&out), [(30, 20_000.0)]);
    let out = step(&mut core, 3, vec![ack(MavResult::MAV_RESULT_DENIED)]);
    assert!(interval_requests(&out).is_empty());
    let said: Vec<String> = out
        .texts
        .iter()
        .filter_map(|m| match m {
            MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
            _ => None,
        })
        .collect();
    assert!(
        said.iter().any(|t| t == "dflat: ATTITUDE at 50 Hz DENIED"),
        "{said:?}"
    );
    for k in 4..200 {
        assert!(
            interval_requests(&step(&mut core, k, vec![])).is_empty(),
            "tick {k}"
        );
    }

    let cfg = Config {
        link: crate::config::LinkConfig {
            request_streams: false,
            ..Default::default()
        },
        ..Config::default()
    };
    let (mut quiet, _, _) = core_with(&cfg, vec![Script::Command(0.0, 0.0)]);
    for k in 0..100 {
        assert!(
            interval_requests(&step(&mut quiet, k, vec![])).is_empty(),
            "tick {k}"
        );
    }
}
