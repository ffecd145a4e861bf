//! What the SITL answers on either link (the shell around the pure
//! [`super::commands`] and [`super::params`]): COMMAND_LONG / COMMAND_INT,
//! the parameter protocol, MAVLink FTP, SETUP_SIGNING. Answers go back on
//! the link the request came from, addressed to its sender; refusals say
//! why in a STATUSTEXT and are counted.

use std::sync::atomic::Ordering;
use std::time::Duration;

use dflat_link::command::{Addressing, CommandRequest};
use dflat_link::dialect::{
    FILE_TRANSFER_PROTOCOL_DATA, MavProtocolCapability, MavResult, MavSeverity,
};
use dflat_link::params::{AutopilotParam, param_name};
use dflat_link::{MavHeader, MavMessage, statustext};

use super::SitlMode;
use super::commands::{CommandContext, SitlMessage, answer, ftp_reply};
use super::counters::{Kind, bump};
use super::params::ParamError;
use super::position_control::position_target;
use super::px4_face;
use super::routing::{Dest, Link};
use super::{Shared, lock};
use dflat_link::command::{command_ack, whole};
use dflat_link::dialect::{MavCmd, MavFrame};
use dflat_link::refusal::Say;
use std::time::Instant;

/// The latest of the SITL's periodic messages, for MAV_CMD_REQUEST_MESSAGE.
#[derive(Debug, Default)]
pub(super) struct Latest {
    pub(super) heartbeat: Option<MavMessage>,
    pub(super) sys_status: Option<MavMessage>,
    pub(super) attitude: Option<MavMessage>,
    pub(super) position: Option<MavMessage>,
}

/// AUTOPILOT_VERSION ([`px4_face::autopilot_version`]) with the
/// flavour's parameter encoding (PX4 bytewise, ArduPilot cast).
fn autopilot_version(shared: &Shared) -> MavMessage {
    let encoding = match shared.params_family() {
        dflat_link::AutopilotFamily::Px4 => {
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
        }
        _ => MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
    };
    px4_face::autopilot_version(shared.system_id, encoding)
}

impl Shared {
    fn params_family(&self) -> dflat_link::AutopilotFamily {
        lock(&self.params).family()
    }

    /// The offboard-loss timeout in force (`COM_OF_LOSS_T` / `GUID_TIMEOUT`).
    pub(super) fn command_timeout(&self) -> Duration {
        Duration::from_micros(self.command_timeout_us.load(Ordering::Relaxed))
    }

    fn reply(&self, link: Link, msg: &MavMessage) {
        self.send_own(msg, Dest::Only(link), Kind::Reply);
    }

    /// Says a refusal on `link`: the first of its reason at once (INFO),
    /// repeats at most once per 10 s with their count (DEBUG).
    fn refuse(&self, link: Link, text: &str) {
        let say = lock(&self.px4.refusals).refuse(link, text, self.elapsed());
        match say {
            Say::First => tracing::info!(text, "sitl: refused"),
            Say::Again { held_back } => tracing::debug!(text, held_back, "sitl: refused again"),
            Say::Quiet => {
                tracing::debug!(text, "sitl: refused (repeat not said)");
                return;
            }
        }
        self.reply(
            link,
            &statustext(MavSeverity::MAV_SEVERITY_WARNING, &say.text(text)),
        );
    }
}

/// A message of the PX4 face built now for MAV_CMD_REQUEST_MESSAGE, from
/// the latest truth sample.
fn on_request(shared: &Shared, m: SitlMessage) -> MavMessage {
    let truth = *lock(&shared.truth);
    let px4 = &shared.px4;
    let time_boot_ms = (truth.t * 1000.0).round() as u32;
    match m {
        SitlMessage::Home => px4_face::home_position(&px4.origin, px4.home, (truth.t * 1e6) as u64),
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
        _ => px4_face::extended_sys_state(
            dflat_link::dialect::MavLandedState::MAV_LANDED_STATE_IN_AIR,
        ),
    }
}

/// Serves `msg` from `header` received on `link` if it is a request to the
/// SITL; returns whom it addresses (`None`: no target), which decides the
/// routing.
pub(super) fn serve(
    shared: &Shared,
    link: Link,
    header: &MavHeader,
    msg: &MavMessage,
) -> Option<Addressing> {
    let addressing = shared.addressing(msg)?;
    let own = (shared.system_id, shared.component_id);
    let from_self = header.system_id == u32::from(own.0) && header.component_id == own.1;
    if addressing == Addressing::Elsewhere || from_self {
        return Some(addressing);
    }
    match msg {
        MavMessage::COMMAND_LONG(_) | MavMessage::COMMAND_INT(_) => {
            if let Some(req) =
                CommandRequest::from_message(msg, header.system_id as u8, header.component_id)
                && !px4_command(shared, link, &req, msg)
            {
                command(shared, link, &req);
            }
        }
        MavMessage::PARAM_REQUEST_LIST(_) => {
            let params = lock(&shared.params).clone();
            for i in 0..params.len() {
                if let Some(m) = params.value_message(i) {
                    shared.reply(link, &m);
                }
            }
        }
        MavMessage::PARAM_REQUEST_READ(d) => {
            let params = lock(&shared.params).clone();
            let name = param_name(&d.param_id).unwrap_or("?");
            match params.lookup(d.param_index, name) {
                Ok(i) => {
                    if let Some(m) = params.value_message(i) {
                        shared.reply(link, &m);
                    }
                }
                Err(e) => {
                    bump(&shared.counters.params_refused);
                    shared.refuse(link, &e.to_string());
                }
            }
        }
        MavMessage::PARAM_SET(d) => {
            let name = param_name(&d.param_id).unwrap_or("?");
            let mut params = lock(&shared.params);
            let result = params.set(name, d.param_value);
            if result.is_ok()
                && let Some(t) = params.si(AutopilotParam::OffboardLossTimeout)
            {
                shared
                    .command_timeout_us
                    .store((t * 1e6).round() as u64, Ordering::Relaxed);
            }
            let params = params.clone();
            match result {
                Ok(i) => {
                    bump(&shared.counters.params_set);
                    tracing::info!(name, value = d.param_value, "sitl: parameter set");
                    if let Some(m) = params.value_message(i) {
                        shared.reply(link, &m);
                    }
                }
                Err(e) => {
                    bump(&shared.counters.params_refused);
                    shared.refuse(link, &e.to_string());
                    // The unchanged value, so a ground station sees it stayed.
                    if matches!(e, ParamError::ReadOnly(_))
                        && let Some((i, _)) = params.find(name)
                        && let Some(m) = params.value_message(i)
                    {
                        shared.reply(link, &m);
                    }
                }
            }
        }
        MavMessage::FILE_TRANSFER_PROTOCOL(d) => {
            if let Some(payload) = ftp_reply(&d.payload) {
                bump(&shared.counters.ftp_answered);
                shared.reply(
                    link,
                    &MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
                        target_network: 0,
                        target_system: header.system_id as u8,
                        target_component: header.component_id,
                        payload,
                    }),
                );
            }
        }
        // Position setpoints to the autopilot: flown in OFFBOARD by its
        // own position loop (PX4 does the same).
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(_) if addressing == Addressing::ToUs => {
            match position_target(msg) {
                Some(Ok(t)) => shared.px4.set_setpoint(Instant::now(), t),
                Some(Err(text)) => shared.refuse(link, text),
                None => {}
            }
        }
        MavMessage::MISSION_COUNT(_)
        | MavMessage::MISSION_ITEM_INT(_)
        | MavMessage::MISSION_CLEAR_ALL(_)
        | MavMessage::MISSION_REQUEST_LIST(_)
            if addressing == Addressing::ToUs =>
        {
            let sender = (header.system_id as u8, header.component_id);
            if let Some(answer) = px4_face::mission_answer(msg, sender) {
                if matches!(msg, MavMessage::MISSION_COUNT(_)) {
                    shared.refuse(link, "SITL: missions unsupported, hold/goto/offboard");
                }
                shared.reply(link, &answer);
            }
        }
        MavMessage::SETUP_SIGNING(_) => {
            bump(&shared.counters.signing_setups_refused);
            shared.refuse(link, "SITL: SETUP_SIGNING refused, key from config");
        }
        _ => {}
    }
    Some(addressing)
}

/// The commands that need the SITL's state to answer (pure parts in
/// [`px4_face`]): MAV_CMD_SET_MESSAGE_INTERVAL and MAV_CMD_DO_REPOSITION
/// (`goto_location`: AUTO_LOITER at the target). True when answered.
fn px4_command(shared: &Shared, link: Link, req: &CommandRequest, msg: &MavMessage) -> bool {
    if req.addressing((shared.system_id, shared.component_id)) != Addressing::ToUs {
        return false;
    }
    let (result, reason) = match req.command {
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
            let id = whole(req.param1).unwrap_or(u32::MAX);
            let set = lock(&shared.px4.streams).set(id, req.param2, shared.elapsed());
            match set {
                Ok(()) => {
                    tracing::info!(id, interval_us = req.param2, "sitl: message interval set");
                    (MavResult::MAV_RESULT_ACCEPTED, None)
                }
                Err(text) => (MavResult::MAV_RESULT_DENIED, Some(text)),
            }
        }
        MavCmd::MAV_CMD_DO_REPOSITION => match reposition_target(shared, msg) {
            Some(goal) => {
                tracing::info!(?goal, "sitl: goto");
                *lock(&shared.px4.goal) = Some(goal);
                *lock(&shared.mode_request) = Some(SitlMode::Loiter);
                (MavResult::MAV_RESULT_ACCEPTED, None)
            }
            None => (
                MavResult::MAV_RESULT_DENIED,
                Some("SITL: goto refused: no valid position".to_owned()),
            ),
        },
        _ => return false,
    };
    bump(&shared.counters.commands_acked);
    if result == MavResult::MAV_RESULT_DENIED {
        bump(&shared.counters.commands_denied);
    }
    shared.reply(link, &command_ack(req, result));
    if let Some(text) = reason {
        shared.refuse(link, &text);
    }
    true
}

/// The local NED goal of a MAV_CMD_DO_REPOSITION: lat/lon (degE7 in
/// COMMAND_INT x/y, degrees in COMMAND_LONG param5/6) and altitude AMSL
/// (z / param7) through the SITL's geodetic origin; NaN keeps the current
/// altitude, lat/lon 0 the current position (as PX4).
// MAV_FRAME_GLOBAL_RELATIVE_ALT_INT is deprecated but still sent.
#[allow(deprecated)]
fn reposition_target(shared: &Shared, msg: &MavMessage) -> Option<[f64; 3]> {
    let now = lock(&shared.truth).position;
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
            let (lat, lon, _) = shared.px4.origin.global(now);
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
        shared.px4.origin.global(now).2
    } else if relative {
        shared.px4.origin.global(shared.px4.home).2 + alt
    } else {
        alt
    };
    let goal = shared.px4.origin.local(lat, lon, alt)?;
    // Farther than 10 km from the origin is a wrong origin, not a goto.
    goal.iter().all(|x| x.abs() < 10_000.0).then_some(goal)
}

fn command(shared: &Shared, link: Link, req: &CommandRequest) {
    let stream_alive = lock(&shared.command)
        .is_some_and(|(at, _)| at.elapsed() < shared.command_timeout())
        || shared
            .px4
            .fresh_setpoint(shared.command_timeout())
            .is_some();
    let pose_available =
        !shared.pose_paused.load(Ordering::Relaxed) && lock(&shared.latest).attitude.is_some();
    let ctx = CommandContext {
        own: (shared.system_id, shared.component_id),
        autopilot: shared.autopilot,
        stream_alive,
        pose_available,
    };
    let Some(a) = answer(req, &ctx) else {
        return;
    };
    bump(&shared.counters.commands_acked);
    match a.result {
        MavResult::MAV_RESULT_UNSUPPORTED => bump(&shared.counters.commands_unsupported),
        MavResult::MAV_RESULT_DENIED => bump(&shared.counters.commands_denied),
        _ => {}
    }
    tracing::debug!(command = ?req.command, result = ?a.result, "sitl: command answered");
    shared.reply(link, &a.ack);
    if let Some(reason) = &a.reason {
        shared.refuse(link, reason);
    }
    if let Some(mode) = a.mode {
        *lock(&shared.mode_request) = Some(mode);
    }
    if let Some(armed) = a.armed
        && shared.px4.armed.swap(armed, Ordering::Relaxed) != armed
    {
        tracing::info!(armed, "sitl: armed state changed");
        if !armed {
            shared.refuse(link, "SITL: disarmed; no ground, position hold on");
        }
    }
    let then = match a.then {
        Some(SitlMessage::AutopilotVersion) => Some(autopilot_version(shared)),
        Some(m) => {
            let latest = lock(&shared.latest);
            match m {
                SitlMessage::Heartbeat => latest.heartbeat.clone(),
                SitlMessage::SysStatus => latest
                    .sys_status
                    .clone()
                    .or_else(|| Some(px4_face::sys_status())),
                SitlMessage::Attitude => latest.attitude.clone(),
                SitlMessage::LocalPosition => latest.position.clone(),
                SitlMessage::AutopilotVersion => None,
                other => Some(on_request(shared, other)),
            }
        }
        None => None,
    };
    if let Some(m) = then {
        let kind = match a.then {
            Some(SitlMessage::Heartbeat) => Kind::Heartbeat,
            Some(SitlMessage::SysStatus) => Kind::SysStatus,
            Some(SitlMessage::Attitude) => Kind::Attitude,
            Some(SitlMessage::LocalPosition) => Kind::Position,
            _ => Kind::Reply,
        };
        shared.send_own(&m, Dest::Only(link), kind);
    }
}
