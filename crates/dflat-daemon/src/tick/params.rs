//! The autopilot's parameters as the tick uses them: the requests due
//! (`crate::autopilot_params`), and the values read back — the hover
//! thrust (flown with `vehicle.hover_thrust_from_autopilot`, else compared)
//! and the tilt limit (which refuses engagement: `tick/standby.rs`); and
//! the telemetry rates asked of it (`crate::stream_rates`) with their
//! answers.

use dflat_link::ThrustMapping;
use dflat_link::command::{result_name, set_message_interval};
use dflat_link::dialect::{MavResult, MavSeverity};
use tracing::{debug, info, warn};

use super::ControlCore;
use crate::autopilot_params::ParamKind;
use crate::config::ThrustMode;
use crate::stream_rates::{Answer, StreamRequest};

impl ControlCore {
    /// Queues the parameter requests due at `t` (sent with the texts).
    pub(super) fn request_params(&mut self, t: f64) {
        for name in self.engagement.params.due(t) {
            debug!(name, "requesting the autopilot's parameter");
            self.pending_texts
                .push(dflat_link::params::param_request_read(
                    (self.settings.target.system, self.settings.target.component),
                    name,
                ));
        }
    }

    /// Queues the stream-rate request due at `t` (sent with the texts); a
    /// request given up unanswered is said.
    pub(super) fn request_streams(&mut self, t: f64) {
        let given_up = self.engagement.streams.unanswered().len();
        let due = self.engagement.streams.due(t);
        if let Some(&r) = self.engagement.streams.unanswered().get(given_up) {
            self.say_stream_not_granted(r, "not answered");
        }
        if let Some((r, confirmation)) = due {
            debug!(
                message = r.name,
                interval_us = r.interval_us,
                confirmation,
                "asking the autopilot's stream rate"
            );
            let target = (self.settings.target.system, self.settings.target.component);
            self.pending_texts.push(set_message_interval(
                target,
                r.id,
                r.interval_us,
                confirmation,
            ));
        }
    }

    /// The autopilot's COMMAND_ACK to a stream-rate request at `t`: an
    /// acceptance is logged, a refusal said in words (its own rate stands).
    pub(super) fn apply_interval_ack(&mut self, result: MavResult, t: f64) {
        match self.engagement.streams.on_ack(result, t) {
            Some(Answer::Accepted(r)) => {
                info!(
                    message = r.name,
                    rate_hz = r.rate_hz(),
                    "the autopilot streams at the tick rate"
                );
            }
            Some(Answer::Refused(r, result)) => {
                self.say_stream_not_granted(r, &result_name(result));
            }
            Some(Answer::Pending) | None => {}
        }
    }

    /// Says that the autopilot did not grant the rate of `r` (`answer`: its
    /// refusal's result, or `not answered`): a log warning naming the
    /// parameters to set, and the STATUSTEXT `dflat: NAME at R Hz ANSWER`.
    fn say_stream_not_granted(&mut self, r: StreamRequest, answer: &str) {
        warn!(
            message = r.name,
            rate_hz = r.rate_hz(),
            answer,
            "the autopilot did not grant the stream rate: its own rate stands \
             (docs/deployment.md: PX4 `mavlink stream`, ArduPilot SRn_ parameters)"
        );
        let text = format!("dflat: {} at {:.0} Hz {answer}", r.name, r.rate_hz());
        self.text(MavSeverity::MAV_SEVERITY_WARNING, &text);
    }

    /// A PARAM_VALUE from the autopilot: a value dflat reads is logged next
    /// to the configuration's, and said when they differ.
    pub(super) fn apply_param(&mut self, name: &str, value: f64) {
        let Some(known) = self.engagement.params.on_value(name, value) else {
            return;
        };
        let v = self.settings.vehicle;
        match known.spec.kind {
            ParamKind::HoverThrust if v.hover_thrust_from_autopilot => {
                self.fly_autopilot_hover(name, known.value);
            }
            ParamKind::HoverThrust => {
                info!(
                    param = name,
                    autopilot = known.value,
                    config = v.hover_thrust,
                    "hover thrust: the configuration's vehicle.hover_thrust is flown; \
                     the disturbance estimator takes up a difference"
                );
                if v.thrust_mode == ThrustMode::Normalized
                    && (known.value - v.hover_thrust).abs() > 0.05
                {
                    let text = format!(
                        "dflat: {name} {:.2}, config hover {:.2}",
                        known.value, v.hover_thrust
                    );
                    self.text(MavSeverity::MAV_SEVERITY_WARNING, &text);
                }
            }
            ParamKind::TiltLimitDeg => {
                info!(
                    param = name,
                    autopilot_deg = known.value,
                    config_deg = v.max_tilt.to_degrees(),
                    "tilt limit"
                );
            }
        }
    }

    /// `vehicle.hover_thrust_from_autopilot`: the autopilot's hover thrust
    /// `value` (parameter `name`) becomes the one flown — the thrust
    /// mapping and the level hover's thrust — if it is in 0.05–0.95 and
    /// the daemon has not engaged yet (a change in flight would step the
    /// thrust). Said either way.
    fn fly_autopilot_hover(&mut self, name: &str, value: f64) {
        let v = self.settings.vehicle;
        if v.thrust_mode != ThrustMode::Normalized {
            return;
        }
        let (engagements, _) = self.supervisor.engagement_counts();
        let (lo, hi) = crate::config::HOVER_THRUST_RANGE;
        let text = if !(lo..=hi).contains(&value) {
            warn!(
                param = name,
                value, "autopilot hover thrust outside 0.05–0.95: vehicle.hover_thrust flown"
            );
            format!(
                "dflat: {name} {value:.2} refused, hover {:.2} flown",
                v.hover_thrust
            )
        } else if engagements > 0 {
            warn!(
                param = name,
                value, "autopilot hover thrust arrived after engagement: not flown"
            );
            format!(
                "dflat: {name} {value:.2} late, hover {:.2} flown",
                v.hover_thrust
            )
        } else {
            self.mapping = ThrustMapping::Normalized {
                hover_thrust: value,
                gravity: v.gravity,
            };
            self.failsafe.fallback.hover_thrust = value;
            info!(
                param = name,
                value,
                config = v.hover_thrust,
                "flying the autopilot's hover thrust"
            );
            format!("dflat: flying {name} {value:.2} as hover thrust")
        };
        self.text(MavSeverity::MAV_SEVERITY_INFO, &text);
    }
}
