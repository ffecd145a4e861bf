//! The autopilot's telemetry at the daemon's rate: at start-up the daemon
//! asks the autopilot, by MAV_CMD_SET_MESSAGE_INTERVAL, to stream the
//! messages it flies on at the tick rate (`controller.rate_hz`), with
//! `link.request_streams` (default on):
//!
//! | `link.pose_source` | asked for |
//! |---|---|
//! | `local_position_ned` | LOCAL_POSITION_NED (32), ATTITUDE (30) |
//! | `odometry`, no `link.pose_components` | ODOMETRY (331), ATTITUDE |
//! | `odometry` from another component, `vision_position_estimate` | ATTITUDE |
//!
//! (A pose that comes from another component is not the autopilot's to
//! send; asking the autopilot for ODOMETRY then would add a second pose
//! stream.) ArduPilot streams its telemetry port's messages at its `SRn_`
//! rates (a few Hz by default) and PX4's `Onboard` link sends
//! LOCAL_POSITION_NED slower than 50 Hz; without this request the ticks
//! run at the stream's rate, and a pose timeout shorter than two of its
//! intervals trips the stale-pose failsafe (`crate::schedule`).
//!
//! One request at a time (COMMAND_ACK does not say which message it
//! answers), each retried every [`RETRY_S`] up to [`TRIES`] times. The
//! answers: ACCEPTED is logged; IN_PROGRESS waits on; TEMPORARILY_REJECTED
//! asks again; DENIED, UNSUPPORTED, FAILED and CANCELLED are refusals, said
//! in words (the autopilot's own settings then set the rate), as is a
//! request never answered. After the autopilot was silent for
//! [`SILENCE_S`] (a reboot forgets the intervals) the requests start
//! again. Pure: time enters as arguments.

use dflat_link::dialect::MavResult;

use crate::config::PoseSourceKind;

/// Seconds between two requests not answered yet.
pub const RETRY_S: f64 = 1.0;
/// Requests per message before giving up.
pub const TRIES: u32 = 3;
/// A HEARTBEAT after this long a silence \[s\] starts the requests again.
pub const SILENCE_S: f64 = 3.0;

/// One message the daemon asks the autopilot for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamRequest {
    /// Its MAVLink message id.
    pub id: u32,
    /// Its name.
    pub name: &'static str,
    /// The interval asked \[µs\].
    pub interval_us: f32,
}

impl StreamRequest {
    /// The rate asked \[Hz\].
    pub fn rate_hz(&self) -> f64 {
        1e6 / f64::from(self.interval_us)
    }
}

/// The messages to ask for (module docs) at `rate_hz`: none when
/// `rate_hz` is not positive and finite.
pub fn requests_for(
    source: PoseSourceKind,
    pose_components: bool,
    rate_hz: f64,
) -> Vec<StreamRequest> {
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Vec::new();
    }
    let interval_us = (1e6 / rate_hz).round() as f32;
    let pose = match source {
        PoseSourceKind::LocalPositionNed => Some((32, "LOCAL_POSITION_NED")),
        PoseSourceKind::Odometry if !pose_components => Some((331, "ODOMETRY")),
        PoseSourceKind::Odometry | PoseSourceKind::VisionPositionEstimate => None,
    };
    pose.into_iter()
        .chain([(30, "ATTITUDE")])
        .map(|(id, name)| StreamRequest {
            id,
            name,
            interval_us,
        })
        .collect()
}

/// What became of one stream-rate request, for the shutdown summary.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StreamOutcome {
    /// The message asked for (`LOCAL_POSITION_NED`, `ODOMETRY`, `ATTITUDE`).
    pub message: String,
    /// The rate asked \[Hz\].
    pub rate_hz: f64,
    /// `accepted`, the autopilot's refusal (`DENIED`, `UNSUPPORTED`, …),
    /// `not answered`, `pending` or `not asked`.
    pub answer: String,
}

/// What an answer did to a request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Answer {
    /// The autopilot streams the message at the rate asked.
    Accepted(StreamRequest),
    /// The autopilot refused (its result).
    Refused(StreamRequest, MavResult),
    /// The autopilot works on it, or asks to be asked again: nothing yet.
    Pending,
}

#[derive(Debug, Clone, Copy)]
struct InFlight {
    request: StreamRequest,
    tries: u32,
    next_at: f64,
}

/// The requests (module docs).
#[derive(Debug, Clone, Default)]
pub struct StreamRates {
    wanted: Vec<StreamRequest>,
    queue: Vec<StreamRequest>,
    current: Option<InFlight>,
    last_heard: Option<f64>,
    accepted: Vec<StreamRequest>,
    refused: Vec<(StreamRequest, MavResult)>,
    unanswered: Vec<StreamRequest>,
}

impl StreamRates {
    /// The requests `wanted`, asked once the autopilot is heard.
    pub fn new(wanted: Vec<StreamRequest>) -> Self {
        Self {
            wanted,
            ..Self::default()
        }
    }

    /// The autopilot's HEARTBEAT at `t` \[s\]: the first one, and the first
    /// after a silence of [`SILENCE_S`], (re)starts the requests.
    pub fn on_heartbeat(&mut self, t: f64) {
        let restart = self.last_heard.is_none_or(|h| t - h >= SILENCE_S);
        self.last_heard = Some(self.last_heard.map_or(t, |h| h.max(t)));
        if restart && !self.wanted.is_empty() {
            self.queue = self.wanted.iter().rev().copied().collect();
            self.current = None;
            self.accepted.clear();
            self.refused.clear();
            self.unanswered.clear();
        }
    }

    /// The request to send at `t` \[s\], if one is due (a new one, or the
    /// current one again after [`RETRY_S`]), with its confirmation number
    /// (0 the first time, then 1, 2: the command protocol's count of
    /// retransmissions); a request sent [`TRIES`] times without an answer
    /// is given up ([`StreamRates::unanswered`]).
    pub fn due(&mut self, t: f64) -> Option<(StreamRequest, u8)> {
        loop {
            match &mut self.current {
                Some(c) if t < c.next_at => return None,
                Some(c) if c.tries < TRIES => {
                    let confirmation = c.tries as u8;
                    c.tries += 1;
                    c.next_at = t + RETRY_S;
                    return Some((c.request, confirmation));
                }
                Some(c) => {
                    self.unanswered.push(c.request);
                    self.current = None;
                }
                None => {
                    let request = self.queue.pop()?;
                    self.current = Some(InFlight {
                        request,
                        tries: 0,
                        next_at: t,
                    });
                }
            }
        }
    }

    /// A COMMAND_ACK to MAV_CMD_SET_MESSAGE_INTERVAL with `result` at `t`
    /// \[s\]: what it did to the request in flight (`None`: none was).
    pub fn on_ack(&mut self, result: MavResult, t: f64) -> Option<Answer> {
        let current = self.current.as_mut()?;
        let request = current.request;
        Some(match result {
            MavResult::MAV_RESULT_ACCEPTED => {
                self.current = None;
                self.accepted.push(request);
                Answer::Accepted(request)
            }
            MavResult::MAV_RESULT_IN_PROGRESS => {
                current.next_at = t + RETRY_S;
                Answer::Pending
            }
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED => {
                current.next_at = t;
                Answer::Pending
            }
            other => {
                self.current = None;
                self.refused.push((request, other));
                Answer::Refused(request, other)
            }
        })
    }

    /// Every wanted message with what became of its request since the
    /// requests (re)started: `accepted`, the refusal's result (`DENIED`,
    /// `UNSUPPORTED`, …), `not answered`, `pending` (in flight or queued)
    /// or `not asked` (the autopilot not heard yet).
    pub fn outcomes(&self) -> Vec<StreamOutcome> {
        self.wanted
            .iter()
            .map(|w| {
                let answer = if self.accepted.iter().any(|r| r.id == w.id) {
                    "accepted".to_owned()
                } else if let Some((_, result)) = self.refused.iter().find(|(r, _)| r.id == w.id) {
                    dflat_link::command::result_name(*result)
                } else if self.unanswered.iter().any(|r| r.id == w.id) {
                    "not answered".to_owned()
                } else if self.last_heard.is_none() {
                    "not asked".to_owned()
                } else {
                    "pending".to_owned()
                };
                StreamOutcome {
                    message: w.name.to_owned(),
                    rate_hz: w.rate_hz(),
                    answer,
                }
            })
            .collect()
    }

    /// The messages the autopilot accepted since the requests (re)started.
    pub fn accepted(&self) -> &[StreamRequest] {
        &self.accepted
    }

    /// The messages it refused, with its result.
    pub fn refused(&self) -> &[(StreamRequest, MavResult)] {
        &self.refused
    }

    /// The messages asked [`TRIES`] times without an answer.
    pub fn unanswered(&self) -> &[StreamRequest] {
        &self.unanswered
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(r: &[StreamRequest]) -> Vec<&'static str> {
        r.iter().map(|r| r.name).collect()
    }

    #[test]
    fn the_pose_message_is_asked_only_from_the_autopilot() {
        let at = |s, c| names(&requests_for(s, c, 50.0));
        assert_eq!(
            at(PoseSourceKind::LocalPositionNed, false),
            ["LOCAL_POSITION_NED", "ATTITUDE"]
        );
        assert_eq!(
            at(PoseSourceKind::Odometry, false),
            ["ODOMETRY", "ATTITUDE"]
        );
        assert_eq!(at(PoseSourceKind::Odometry, true), ["ATTITUDE"]);
        assert_eq!(
            at(PoseSourceKind::VisionPositionEstimate, false),
            ["ATTITUDE"]
        );
        let r = requests_for(PoseSourceKind::LocalPositionNed, false, 50.0);
        assert_eq!(r[0].interval_us, 20_000.0);
        assert!((r[0].rate_hz() - 50.0).abs() < 1e-9);
        assert!(requests_for(PoseSourceKind::LocalPositionNed, false, 0.0).is_empty());
        assert!(requests_for(PoseSourceKind::LocalPositionNed, false, f64::NAN).is_empty());
    }

    /// One request in flight at a time, in order; ACCEPTED moves on, a
    /// refusal is kept with its result, a request never answered is given
    /// up after three tries.
    #[test]
    fn requests_go_one_at_a_time_and_are_answered_or_given_up() {
        let wanted = requests_for(PoseSourceKind::LocalPositionNed, false, 50.0);
        let mut s = StreamRates::new(wanted);
        assert_eq!(s.due(0.0), None, "nothing before the autopilot is heard");
        assert_eq!(s.outcomes()[0].answer, "not asked");
        assert_eq!(s.on_ack(MavResult::MAV_RESULT_ACCEPTED, 0.0), None);
        s.on_heartbeat(1.0);
        assert_eq!(s.due(1.0).unwrap().0.name, "LOCAL_POSITION_NED");
        assert_eq!(s.due(1.5), None, "waits for the answer");
        let a = s.on_ack(MavResult::MAV_RESULT_ACCEPTED, 1.6).unwrap();
        assert!(matches!(a, Answer::Accepted(r) if r.id == 32));
        assert_eq!(s.due(1.6).unwrap().0.name, "ATTITUDE");
        let a = s.on_ack(MavResult::MAV_RESULT_DENIED, 1.7).unwrap();
        assert!(matches!(a, Answer::Refused(r, MavResult::MAV_RESULT_DENIED) if r.id == 30));
        assert_eq!(s.due(5.0), None, "all answered");
        assert_eq!(names(s.accepted()), ["LOCAL_POSITION_NED"]);
        assert_eq!(s.refused().len(), 1);
        let answers: Vec<String> = s.outcomes().into_iter().map(|o| o.answer).collect();
        assert_eq!(answers, ["accepted", "DENIED"]);
        // A late or stray answer changes nothing.
        assert_eq!(s.on_ack(MavResult::MAV_RESULT_ACCEPTED, 5.0), None);
        assert_eq!(names(s.accepted()), ["LOCAL_POSITION_NED"]);
    }

    #[test]
    fn an_unanswered_request_is_retried_then_given_up() {
        let wanted = requests_for(PoseSourceKind::VisionPositionEstimate, false, 50.0);
        let mut s = StreamRates::new(wanted);
        s.on_heartbeat(0.0);
        assert_eq!(s.due(0.0).unwrap().1, 0, "first sent");
        assert!(s.due(0.5).is_none());
        assert_eq!(s.due(1.0).unwrap().1, 1, "second try");
        assert_eq!(s.due(2.0).unwrap().1, 2, "third try");
        assert!(s.due(3.0).is_none(), "given up");
        assert_eq!(names(s.unanswered()), ["ATTITUDE"]);
        assert!(s.accepted().is_empty() && s.refused().is_empty());
        assert_eq!(s.outcomes()[0].answer, "not answered");
    }

    /// IN_PROGRESS waits a retry interval on; TEMPORARILY_REJECTED asks
    /// again at once (within the tries).
    #[test]
    fn in_progress_waits_and_temporarily_rejected_asks_again() {
        let wanted = requests_for(PoseSourceKind::VisionPositionEstimate, false, 50.0);
        let mut s = StreamRates::new(wanted);
        s.on_heartbeat(0.0);
        assert!(s.due(0.0).is_some());
        assert_eq!(
            s.on_ack(MavResult::MAV_RESULT_IN_PROGRESS, 0.9),
            Some(Answer::Pending)
        );
        assert!(s.due(1.5).is_none(), "in progress: waits on");
        assert!(s.due(1.9).is_some());
        assert_eq!(
            s.on_ack(MavResult::MAV_RESULT_TEMPORARILY_REJECTED, 2.0),
            Some(Answer::Pending)
        );
        assert!(s.due(2.0).is_some(), "asked again at once");
        assert!(s.on_ack(MavResult::MAV_RESULT_ACCEPTED, 2.1).is_some());
        assert_eq!(names(s.accepted()), ["ATTITUDE"]);
    }

    /// A heartbeat after a silence (a rebooted autopilot forgot the
    /// intervals) asks again; heartbeats in a row do not.
    #[test]
    fn a_silence_restarts_the_requests() {
        let wanted = requests_for(PoseSourceKind::VisionPositionEstimate, false, 50.0);
        let mut s = StreamRates::new(wanted);
        s.on_heartbeat(0.0);
        assert!(s.due(0.0).is_some());
        s.on_ack(MavResult::MAV_RESULT_ACCEPTED, 0.1);
        for k in 1..10 {
            s.on_heartbeat(f64::from(k));
            assert!(s.due(f64::from(k)).is_none(), "heartbeat {k}");
        }
        s.on_heartbeat(9.0 + SILENCE_S);
        assert_eq!(s.due(9.0 + SILENCE_S).unwrap().0.name, "ATTITUDE");
        assert!(s.accepted().is_empty(), "the old answers are forgotten");
        // Nothing wanted: nothing asked, ever.
        let mut none = StreamRates::new(Vec::new());
        none.on_heartbeat(0.0);
        assert!(none.due(0.0).is_none());
    }
}
