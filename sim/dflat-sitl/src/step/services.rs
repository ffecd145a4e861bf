//! What the step answers on either link (around the pure
//! [`crate::commands`] and [`crate::params`]): COMMAND_LONG / COMMAND_INT,
//! the parameter protocol, MAVLink FTP, missions, position setpoints to
//! the autopilot, SETUP_SIGNING. Answers go back on the link the request
//! came from, addressed to its sender; refusals say why in a STATUSTEXT
//! and are counted.

use dflat_link::command::{Addressing, CommandRequest, command_ack, whole};
use dflat_link::dialect::{
    FILE_TRANSFER_PROTOCOL_DATA, MavCmd, MavFrame, MavLandedState, MavProtocolCapability,
    MavResult, MavSeverity,
};
use dflat_link::params::{AutopilotParam, param_name};
use dflat_link::refusal::Say;
use dflat_link::{MavHeader, MavMessage, statustext};

use super::{Dest, Link, SitlCore, SitlEvent, SitlOutput};
use crate::SitlMode;
use crate::commands::{CommandContext, SitlMessage, answer, ftp_reply};
use crate::counters::SentKind;
use crate::params::ParamError;
use crate::position_control::position_target;
use crate::px4_face;

/// Whom `msg` addresses, seen from `own` (system, component); `None`: no
/// target.
pub fn addressing(own: (u8, u8), msg: &MavMessage) -> Option<Addressing> {
    use dflat_link::mavlink::Message as _;
    let system = msg.target_system_id()?;
    let component = msg.target_component_id().unwrap_or(0);
    Some(Addressing::of(system, component, own))
}

/// Whether a frame from `header` is for the services of the SITL `own`
/// (a [`super::SitlInput::Frame`]): addressed to it or broadcast, not sent
/// by itself, and not a SET_ATTITUDE_TARGET (decoded by the receive side).
pub fn served(own: (u8, u8), header: &MavHeader, msg: &MavMessage) -> bool {
    let from_self = header.system_id == u32::from(own.0) && header.component_id == own.1;
    !from_self
        && !matches!(msg, MavMessage::SET_ATTITUDE_TARGET(_))
        && addressing(own, msg).is_some_and(|a| a != Addressing::Elsewhere)
}

impl SitlCore {
    /// Answers `reply` on `link`.
    fn reply(out: &mut SitlOutput, link: Link, msg: MavMessage) {
        out.send(msg, Dest::Only(link), SentKind::Reply);
    }

    /// Says a refusal on `link`: the first of its reason at once (INFO),
    /// repeats at most once per 10 s with their count (DEBUG).
    fn refuse(&mut self, out: &mut SitlOutput, link: Link, text: &str) {
        let say = self.px4.refusals.refuse(link, text, self.clock);
        match say {
            Say::First => tracing::info!(text, "sitl: refused"),
            Say::Again { held_back } => tracing::debug!(text, held_back, "sitl: refused again"),
            Say::Quiet => {
                tracing::debug!(text, "sitl: refused (repeat not said)");
                return;
            }
        }
        let text = statustext(MavSeverity::MAV_SEVERITY_WARNING, &say.text(text));
        Self::reply(out, link, text);
    }

    /// Serves `msg` from `header`, received on `link` at `at` \[s\], if it
    /// is a request to the SITL.
    pub(super) fn serve(
        &mut self,
        at: f64,
        link: Link,
        header: &MavHeader,
        msg: &MavMessage,
        out: &mut SitlOutput,
    ) {
        if !served(self.own, header, msg) {
            return;
        }
        let Some(addressing) = self.addressing(msg) else {
            return;
        };
        let sender = (header.system_id as u8, header.component_id);
        match msg {
            MavMessage::COMMAND_LONG(_) | MavMessage::COMMAND_INT(_) => {
                if let Some(req) = CommandRequest::from_message(msg, sender.0, sender.1)
                    && !self.px4_command(link, &req, msg, out)
                {
                    self.command(link, &req, out);
                }
            }
            MavMessage::PARAM_REQUEST_LIST(_) => {
                for i in 0..self.params.len() {
                    if let Some(m) = self.params.value_message(i) {
                        Self::reply(out, link, m);
                    }
                }
            }
            MavMessage::PARAM_REQUEST_READ(d) => {
                let name = param_name(&d.param_id).unwrap_or("?");
                match self.params.lookup(d.param_index, name) {
                    Ok(i) => {
                        if let Some(m) = self.params.value_message(i) {
                            Self::reply(out, link, m);
                        }
                    }
                    Err(e) => {
                        out.counts.params_refused += 1;
                        self.refuse(out, link, &e.to_string());
                    }
                }
            }
            MavMessage::PARAM_SET(d) => self.param_set(link, d, out),
            MavMessage::FILE_TRANSFER_PROTOCOL(d) => {
                if let Some(payload) = ftp_reply(&d.payload) {
                    out.counts.ftp_answered += 1;
                    let msg = MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
                        target_network: 0,
                        target_system: sender.0,
                        target_component: sender.1,
                        payload,
                    });
                    Self::reply(out, link, msg);
                }
            }
            // Position setpoints to the autopilot: flown in OFFBOARD by its
            // own position loop (PX4 does the same).
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(_) if addressing == Addressing::ToUs => {
                match position_target(msg) {
                    Some(Ok(t)) => self.px4.set_setpoint(at, t),
                    Some(Err(text)) => self.refuse(out, link, text),
                    None => {}
                }
            }
            MavMessage::MISSION_COUNT(_)
            | MavMessage::MISSION_ITEM_INT(_)
            | MavMessage::MISSION_CLEAR_ALL(_)
            | MavMessage::MISSION_REQUEST_LIST(_)
                if addressing == Addressing::ToUs =>
            {
                if let Some(answer) = px4_face::mission_answer(msg, sender) {
                    if matches!(msg, MavMessage::MISSION_COUNT(_)) {
                        self.refuse(out, link, "SITL: missions unsupported, hold/goto/offboard");
                    }
                    Self::reply(out, link, answer);
                }
            }
            MavMessage::SETUP_SIGNING(_) => {
                out.counts.signing_setups_refused += 1;
                self.refuse(out, link, "SITL: SETUP_SIGNING refused, key from config");
            }
            _ => {}
        }
    }

    /// PARAM_SET: applied (the offboard-loss timeout at once) and echoed,
    /// or refused in words (a read-only one echoed unchanged).
    fn param_set(
        &mut self,
        link: Link,
        d: &dflat_link::dialect::PARAM_SET_DATA,
        out: &mut SitlOutput,
    ) {
        let name = param_name(&d.param_id).unwrap_or("?");
        let result = self.params.set(name, d.param_value);
        if result.is_ok()
            && let Some(t) = self.params.si(AutopilotParam::OffboardLossTimeout)
        {
            self.command_timeout = t;
        }
        match result {
            Ok(i) => {
                out.counts.params_set += 1;
                tracing::info!(name, value = d.param_value, "sitl: parameter set");
                if let Some(m) = self.params.value_message(i) {
                    Self::reply(out, link, m);
                }
            }
            Err(e) => {
                out.counts.params_refused += 1;
                self.refuse(out, link, &e.to_string());
                // The unchanged value, so a ground station sees it stayed.
                if matches!(e, ParamError::ReadOnly(_))
                    && let Some((i, _)) = self.params.find(name)
                    && let Some(m) = self.params.value_message(i)
                {
                    Self::reply(out, link, m);
                }
            }
        }
    }

    /// AUTOPILOT_VERSION ([`px4_face::autopilot_version`]) with the
    /// flavour's parameter encoding (PX4 bytewise, ArduPilot cast).
    fn autopilot_version(&self) -> MavMessage {
        let encoding = match self.params.family() {
            dflat_link::AutopilotFamily::Px4 => {
                MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            }
            _ => MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
        };
        px4_face::autopilot_version(self.own.0, encoding)
    }

    /// A message of the PX4 face built now for MAV_CMD_REQUEST_MESSAGE,
    /// from the latest truth sample.
    fn on_request(&self, m: SitlMessage) -> MavMessage {
        let truth = self.truth;
        let px4 = &self.px4;
        let time_boot_ms = (truth.t * 1000.0).round() as u32;
        match m {
            SitlMessage::Home => {
                px4_face::home_position(&px4.origin, px4.home, (truth.t * 1e6) as u64)
            }
            SitlMessage::AttitudeQuaternion => {
                px4_face::attitude_quaternion(time_boot_ms, truth.euler, [0.0; 3])
            }
            SitlMessage::GlobalPosition => px4_face::global_position_int(
                &px4.origin,
                px4.home,
                time_boot_ms,
                truth.position,
                truth.velocity,
                truth.euler[2],
            ),
            SitlMessage::Battery => px4_face::battery_status(),
            _ => px4_face::extended_sys_state(MavLandedState::MAV_LANDED_STATE_IN_AIR),
        }
    }

    /// The commands that need the SITL's state to answer (pure parts in
    /// [`px4_face`]): MAV_CMD_SET_MESSAGE_INTERVAL and MAV_CMD_DO_REPOSITION
    /// (`goto_location`: AUTO_LOITER at the target). True when answered.
    fn px4_command(
        &mut self,
        link: Link,
        req: &CommandRequest,
        msg: &MavMessage,
        out: &mut SitlOutput,
    ) -> bool {
        if req.addressing(self.own) != Addressing::ToUs {
            return false;
        }
        let (result, reason) = match req.command {
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                let id = whole(req.param1).unwrap_or(u32::MAX);
                // ATTITUDE and LOCAL_POSITION_NED go out on both links at
                // one rate: only the vehicle link's requests set it (PX4
                // keeps one rate per link; the ground station's stays).
                let telemetry = match link {
                    Link::Vehicle => self.telemetry_rates.set(id, req.param2, self.dt),
                    Link::Gcs => self.telemetry_rates.refuse_on_gcs(id),
                };
                let set = match telemetry {
                    Some(set) => set,
                    None => self.px4.streams.set(id, req.param2, self.clock),
                };
                match set {
                    Ok(()) => {
                        tracing::info!(id, interval_us = req.param2, "sitl: message interval set");
                        (MavResult::MAV_RESULT_ACCEPTED, None)
                    }
                    Err(text) => (MavResult::MAV_RESULT_DENIED, Some(text)),
                }
            }
            MavCmd::MAV_CMD_DO_REPOSITION => match self.reposition_target(msg) {
                Some(goal) => {
                    tracing::info!(?goal, "sitl: goto");
                    self.pending_goal = Some(goal);
                    self.request = Some(SitlMode::Loiter);
                    (MavResult::MAV_RESULT_ACCEPTED, None)
                }
                None => (
                    MavResult::MAV_RESULT_DENIED,
                    Some("SITL: goto refused: no valid position".to_owned()),
                ),
            },
            _ => return false,
        };
        out.counts.commands_acked += 1;
        if result == MavResult::MAV_RESULT_DENIED {
            out.counts.commands_denied += 1;
        }
        Self::reply(out, link, command_ack(req, result));
        if let Some(text) = reason {
            self.refuse(out, link, &text);
        }
        true
    }

    /// The local NED goal of a MAV_CMD_DO_REPOSITION: lat/lon (degE7 in
    /// COMMAND_INT x/y, degrees in COMMAND_LONG param5/6) and altitude AMSL
    /// (z / param7) through the SITL's geodetic origin; NaN keeps the
    /// current altitude, lat/lon 0 the current position (as PX4).
    // MAV_FRAME_GLOBAL_RELATIVE_ALT_INT is deprecated but still sent.
    #[allow(deprecated)]
    fn reposition_target(&self, msg: &MavMessage) -> Option<[f64; 3]> {
        let now = self.truth.position;
        let origin = &self.px4.origin;
        let (lat, lon, alt) = match msg {
            MavMessage::COMMAND_INT(d) if d.x != 0 || d.y != 0 => {
                (f64::from(d.x) * 1e-7, f64::from(d.y) * 1e-7, f64::from(d.z))
            }
            MavMessage::COMMAND_LONG(d) if d.param5 != 0.0 || d.param6 != 0.0 => (
                f64::from(d.param5),
                f64::from(d.param6),
                f64::from(d.param7),
            ),
            MavMessage::COMMAND_INT(_) | MavMessage::COMMAND_LONG(_) => {
                let (lat, lon, _) = origin.global(now);
                let alt = match msg {
                    MavMessage::COMMAND_INT(d) => f64::from(d.z),
                    MavMessage::COMMAND_LONG(d) => f64::from(d.param7),
                    _ => f64::NAN,
                };
                (lat, lon, alt)
            }
            _ => return None,
        };
        // COMMAND_INT in a relative-altitude frame: above home.
        let relative = matches!(
            msg,
            MavMessage::COMMAND_INT(d) if matches!(
                d.frame,
                MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT | MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
            )
        );
        let alt = if !alt.is_finite() {
            origin.global(now).2
        } else if relative {
            origin.global(self.px4.home).2 + alt
        } else {
            alt
        };
        let goal = origin.local(lat, lon, alt)?;
        // Farther than 10 km from the origin is a wrong origin, not a goto.
        goal.iter().all(|x| x.abs() < 10_000.0).then_some(goal)
    }

    /// The commands answered by [`answer`]: the ack, the reason, the mode
    /// or armed state it switches, the message it asks for.
    fn command(&mut self, link: Link, req: &CommandRequest, out: &mut SitlOutput) {
        let (clock, timeout) = (self.clock, self.command_timeout);
        let stream_alive = self.command.is_some_and(|(at, _)| clock - at < timeout)
            || self.px4.fresh_setpoint(clock, timeout).is_some();
        let ctx = CommandContext {
            own: self.own,
            autopilot: self.autopilot,
            stream_alive,
            pose_available: !self.pose_paused && self.latest.attitude.is_some(),
        };
        let Some(a) = answer(req, &ctx) else {
            return;
        };
        out.counts.commands_acked += 1;
        match a.result {
            MavResult::MAV_RESULT_UNSUPPORTED => out.counts.commands_unsupported += 1,
            MavResult::MAV_RESULT_DENIED => out.counts.commands_denied += 1,
            _ => {}
        }
        tracing::debug!(command = ?req.command, result = ?a.result, "sitl: command answered");
        Self::reply(out, link, a.ack.clone());
        if let Some(reason) = &a.reason {
            self.refuse(out, link, reason);
        }
        if let Some(mode) = a.mode {
            self.request = Some(mode);
        }
        if let Some(armed) = a.armed
            && self.px4.armed != armed
        {
            self.px4.armed = armed;
            out.events.push(SitlEvent::ArmedChanged(armed));
            tracing::info!(armed, "sitl: armed state changed");
            if !armed {
                self.refuse(out, link, "SITL: disarmed; no ground, position hold on");
            }
        }
        let then = match a.then {
            Some(SitlMessage::AutopilotVersion) => Some(self.autopilot_version()),
            Some(SitlMessage::Heartbeat) => self.latest.heartbeat.clone(),
            Some(SitlMessage::SysStatus) => self
                .latest
                .sys_status
                .clone()
                .or_else(|| Some(px4_face::sys_status())),
            Some(SitlMessage::Attitude) => self.latest.attitude.clone(),
            Some(SitlMessage::LocalPosition) => self.latest.position.clone(),
            Some(other) => Some(self.on_request(other)),
            None => None,
        };
        if let Some(m) = then {
            let kind = match a.then {
                Some(SitlMessage::Heartbeat) => SentKind::Heartbeat,
                Some(SitlMessage::SysStatus) => SentKind::SysStatus,
                Some(SitlMessage::Attitude) => SentKind::Attitude,
                Some(SitlMessage::LocalPosition) => SentKind::Position,
                _ => SentKind::Reply,
            };
            out.send(m, Dest::Only(link), kind);
        }
    }
}
