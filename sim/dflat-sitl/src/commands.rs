//! The SITL's side of the command protocol and of MAVLink FTP (pure), the
//! way PX4 answers them:
//!
//! | command | answer |
//! |---|---|
//! | MAV_CMD_REQUEST_MESSAGE (512): HEARTBEAT 0, SYS_STATUS 1, ATTITUDE 30, ATTITUDE_QUATERNION 31, LOCAL_POSITION_NED 32, GLOBAL_POSITION_INT 33, BATTERY_STATUS 147, AUTOPILOT_VERSION 148, HOME_POSITION 242, EXTENDED_SYS_STATE 245 | ACCEPTED, then the message (DENIED while the SITL has not sent it yet, e.g. the pose paused) |
//! | MAV_CMD_GET_HOME_POSITION (410) | ACCEPTED, HOME_POSITION |
//! | MAV_CMD_SET_MESSAGE_INTERVAL (511) | the streams of [`super::px4_face::Streams`] and ATTITUDE, LOCAL_POSITION_NED ([`super::px4_face::TelemetryRates`]: from the vehicle link; DENIED from the ground station's and with `sitl.fixed_telemetry_rate`): ACCEPTED; HEARTBEAT, SYS_STATUS and others DENIED, STATUSTEXT (answered in the step, `step/services.rs`) |
//! | MAV_CMD_DO_REPOSITION (192, `goto_location`) | ACCEPTED: AUTO_LOITER at the target (answered in the step, `step/services.rs`) |
//! | MAV_CMD_NAV_RETURN_TO_LAUNCH (20) | ACCEPTED: AUTO_RTL, flies to home (the start point) and holds there |
//! | MAV_CMD_NAV_TAKEOFF (22), MAV_CMD_NAV_LAND (21) | DENIED, STATUSTEXT: the plant starts in the air and cannot land |
//! | MAV_CMD_REQUEST_MESSAGE, any other message | DENIED, STATUSTEXT "not sent" |
//! | MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES (520) | ACCEPTED, AUTOPILOT_VERSION |
//! | MAV_CMD_DO_SET_MODE (176), param2 = PX4 main mode OFFBOARD 6 / POSCTL 3 / AUTO 4 with param3 = LOITER 3 or RTL 5, ArduPilot GUIDED_NOGPS 20 / LOITER 5 | ACCEPTED and switched; offboard without a live setpoint stream (attitude or position) DENIED, STATUSTEXT; other modes DENIED |
//! | MAV_CMD_COMPONENT_ARM_DISARM (400) | ACCEPTED: arm / disarm (disarmed, the plant — which cannot land — keeps hovering on the position hold; commands are not applied) |
//! | anything else | UNSUPPORTED |
//!
//! Addressing as [`dflat_link::command`]: a command to the SITL's own
//! system and component is always acknowledged; a broadcast only when
//! supported; others are not its business.
//!
//! FTP (FILE_TRANSFER_PROTOCOL): the SITL has no file system. Session
//! resets and terminations are ACKed; listing or opening anything is
//! NAKed `FileNotFound`, reading/writing `InvalidSession`, anything else
//! `UnknownCommand` — so a ground station (MAVProxy fetching
//! `@PARAM/param.pck`) falls back at once instead of timing out.

use dflat_link::MavMessage;
use dflat_link::command::{Addressing, CommandRequest, command_ack, whole};
use dflat_link::dialect::{MavCmd, MavResult};
use dflat_link::modes::px4;

use super::px4_face::{PX4_AUTO_LOITER, PX4_AUTO_RTL, PX4_MAIN_AUTO};
use super::{ARDUPILOT_MODE_GUIDED_NOGPS, ARDUPILOT_MODE_LOITER, SitlAutopilot, SitlMode};

/// A message the SITL sends on request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SitlMessage {
    /// HEARTBEAT (0).
    Heartbeat,
    /// SYS_STATUS (1).
    SysStatus,
    /// ATTITUDE (30).
    Attitude,
    /// LOCAL_POSITION_NED (32).
    LocalPosition,
    /// AUTOPILOT_VERSION (148).
    AutopilotVersion,
    /// ATTITUDE_QUATERNION (31).
    AttitudeQuaternion,
    /// GLOBAL_POSITION_INT (33).
    GlobalPosition,
    /// BATTERY_STATUS (147).
    Battery,
    /// HOME_POSITION (242).
    Home,
    /// EXTENDED_SYS_STATE (245).
    ExtendedSysState,
}

impl SitlMessage {
    /// The message of MAVLink id `id`, if the SITL sends it.
    pub fn from_id(id: u32) -> Option<Self> {
        Some(match id {
            0 => Self::Heartbeat,
            1 => Self::SysStatus,
            30 => Self::Attitude,
            32 => Self::LocalPosition,
            148 => Self::AutopilotVersion,
            31 => Self::AttitudeQuaternion,
            33 => Self::GlobalPosition,
            147 => Self::Battery,
            242 => Self::Home,
            245 => Self::ExtendedSysState,
            _ => return None,
        })
    }
}

/// What the SITL knows when it answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CommandContext {
    /// The SITL's (system, component).
    pub own: (u8, u8),
    /// Its flavour (mode numbers).
    pub autopilot: SitlAutopilot,
    /// A setpoint (SET_ATTITUDE_TARGET, or a position setpoint to the
    /// autopilot) arrived within the offboard-loss timeout.
    pub stream_alive: bool,
    /// The pose stream has started and is not paused (ATTITUDE and
    /// LOCAL_POSITION_NED can be sent).
    pub pose_available: bool,
}

/// The SITL's answer to one command.
#[derive(Debug, Clone, PartialEq)]
pub struct SitlAnswer {
    /// COMMAND_ACK, addressed to the sender.
    pub ack: MavMessage,
    /// The result in the ack.
    pub result: MavResult,
    /// Why (DENIED), sent as a STATUSTEXT after the ack.
    pub reason: Option<String>,
    /// The message to send after the ack.
    pub then: Option<SitlMessage>,
    /// The mode to switch to.
    pub mode: Option<SitlMode>,
    /// Arm (`true`) or disarm.
    pub armed: Option<bool>,
}

/// The SITL's answer to `req` (`None`: not addressed to it, or a
/// broadcast it does not support).
pub fn answer(req: &CommandRequest, ctx: &CommandContext) -> Option<SitlAnswer> {
    let addressing = req.addressing(ctx.own);
    if addressing == Addressing::Elsewhere {
        return None;
    }
    let mut out = Outcome::new(MavResult::MAV_RESULT_UNSUPPORTED);
    match req.command {
        MavCmd::MAV_CMD_REQUEST_MESSAGE => {
            out = request_message(req.requested_message_id(), ctx);
        }
        // Superseded by REQUEST_MESSAGE, but ground stations still send it.
        #[allow(deprecated)]
        MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
            out = Outcome::new(MavResult::MAV_RESULT_ACCEPTED);
            out.then = Some(SitlMessage::AutopilotVersion);
        }
        #[allow(deprecated)]
        MavCmd::MAV_CMD_GET_HOME_POSITION => {
            out = Outcome::new(MavResult::MAV_RESULT_ACCEPTED);
            out.then = Some(SitlMessage::Home);
        }
        MavCmd::MAV_CMD_DO_SET_MODE => out = set_mode(req.param2, req.param3, ctx),
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
            out = Outcome::new(MavResult::MAV_RESULT_ACCEPTED);
            out.armed = Some(req.param1 == 1.0);
        }
        MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH => {
            out = Outcome::new(MavResult::MAV_RESULT_ACCEPTED);
            out.mode = Some(SitlMode::Rtl);
        }
        MavCmd::MAV_CMD_NAV_TAKEOFF => {
            out = Outcome::denied("SITL: takeoff refused: plant starts in the air".into());
        }
        MavCmd::MAV_CMD_NAV_LAND => {
            out = Outcome::denied("SITL: land refused: the plant cannot land".into());
        }
        _ => {}
    }
    if addressing == Addressing::Broadcast && out.result == MavResult::MAV_RESULT_UNSUPPORTED {
        return None;
    }
    Some(SitlAnswer {
        ack: command_ack(req, out.result),
        result: out.result,
        reason: out.reason,
        then: out.then,
        mode: out.mode,
        armed: out.armed,
    })
}

struct Outcome {
    result: MavResult,
    reason: Option<String>,
    then: Option<SitlMessage>,
    mode: Option<SitlMode>,
    armed: Option<bool>,
}

impl Outcome {
    fn new(result: MavResult) -> Self {
        Self {
            result,
            reason: None,
            then: None,
            mode: None,
            armed: None,
        }
    }

    fn denied(reason: String) -> Self {
        Self {
            reason: Some(reason),
            ..Self::new(MavResult::MAV_RESULT_DENIED)
        }
    }
}

fn request_message(id: Option<u32>, ctx: &CommandContext) -> Outcome {
    let Some(message) = id.and_then(SitlMessage::from_id) else {
        let id = id.map_or("?".to_owned(), |i| i.to_string());
        return Outcome::denied(format!("SITL: message {id} not sent"));
    };
    let pose = matches!(
        message,
        SitlMessage::Attitude
            | SitlMessage::LocalPosition
            | SitlMessage::AttitudeQuaternion
            | SitlMessage::GlobalPosition
    );
    if pose && !ctx.pose_available {
        return Outcome::denied(format!("SITL: {message:?} not available (pose paused)"));
    }
    let mut out = Outcome::new(MavResult::MAV_RESULT_ACCEPTED);
    out.then = Some(message);
    out
}

fn set_mode(custom: f32, sub: f32, ctx: &CommandContext) -> Outcome {
    let sub = whole(sub).unwrap_or(0);
    let mode = whole(custom).and_then(|m| match ctx.autopilot {
        SitlAutopilot::Px4 if m == u32::from(px4::OFFBOARD) => Some(SitlMode::Offboard),
        SitlAutopilot::Px4 if m == u32::from(px4::POSCTL) => Some(SitlMode::Hold),
        SitlAutopilot::Px4 if m == PX4_MAIN_AUTO && sub == PX4_AUTO_LOITER => {
            Some(SitlMode::Loiter)
        }
        SitlAutopilot::Px4 if m == PX4_MAIN_AUTO && sub == PX4_AUTO_RTL => Some(SitlMode::Rtl),
        SitlAutopilot::Ardupilot if m == ARDUPILOT_MODE_GUIDED_NOGPS => Some(SitlMode::Offboard),
        SitlAutopilot::Ardupilot if m == ARDUPILOT_MODE_LOITER => Some(SitlMode::Hold),
        _ => None,
    });
    match mode {
        None if sub != 0 => Outcome::denied(format!("SITL: mode {custom}/{sub} not modelled")),
        None => Outcome::denied(format!("SITL: mode {custom} not modelled")),
        Some(SitlMode::Offboard) if !ctx.stream_alive => {
            Outcome::denied("SITL: offboard refused, no setpoint stream".into())
        }
        Some(m) => {
            let mut out = Outcome::new(MavResult::MAV_RESULT_ACCEPTED);
            out.mode = Some(m);
            out
        }
    }
}

/// FTP opcode ACK.
pub const FTP_ACK: u8 = 128;
/// FTP opcode NAK.
pub const FTP_NAK: u8 = 129;
/// FTP error: unknown command.
pub const FTP_ERR_UNKNOWN_COMMAND: u8 = 7;
/// FTP error: no such file.
pub const FTP_ERR_FILE_NOT_FOUND: u8 = 10;
/// FTP error: no such session.
pub const FTP_ERR_INVALID_SESSION: u8 = 4;

/// The FTP reply payload to request `payload` (`None`: a reply itself, or
/// too short to be a request): same session, sequence + 1, `req_opcode`
/// the request's; ACK for session resets and terminations, else NAK with
/// one error byte.
pub fn ftp_reply(payload: &[u8]) -> Option<[u8; 251]> {
    if payload.len() < 12 {
        return None;
    }
    let seq = u16::from_le_bytes([payload[0], payload[1]]);
    let (session, opcode) = (payload[2], payload[3]);
    if opcode >= FTP_ACK {
        return None;
    }
    let mut out = [0u8; 251];
    out[..2].copy_from_slice(&seq.wrapping_add(1).to_le_bytes());
    out[2] = session;
    out[5] = opcode;
    let error = match opcode {
        1 | 2 => None,
        3 | 4 => Some(FTP_ERR_FILE_NOT_FOUND),
        5 | 7 | 15 => Some(FTP_ERR_INVALID_SESSION),
        _ => Some(FTP_ERR_UNKNOWN_COMMAND),
    };
    match error {
        None => out[3] = FTP_ACK,
        Some(e) => {
            out[3] = FTP_NAK;
            out[4] = 1;
            out[12] = e;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CTX: CommandContext = CommandContext {
        own: (1, 1),
        autopilot: SitlAutopilot::Px4,
        stream_alive: false,
        pose_available: true,
    };

    fn req(command: MavCmd, p1: f32, p2: f32, target: (u8, u8)) -> CommandRequest {
        CommandRequest {
            command,
            param1: p1,
            param2: p2,
            param3: 0.0,
            target_system: target.0,
            target_component: target.1,
            sender_system: 255,
            sender_component: 190,
        }
    }

    #[test]
    fn requested_messages_are_sent_unknown_ones_denied() {
        for (id, m) in [
            (0.0, SitlMessage::Heartbeat),
            (1.0, SitlMessage::SysStatus),
            (30.0, SitlMessage::Attitude),
            (32.0, SitlMessage::LocalPosition),
            (148.0, SitlMessage::AutopilotVersion),
        ] {
            let a = answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, id, 0.0, (1, 1)), &CTX).unwrap();
            assert_eq!(
                (a.result, a.then),
                (MavResult::MAV_RESULT_ACCEPTED, Some(m))
            );
        }
        let a = answer(
            &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 77.0, 0.0, (1, 1)),
            &CTX,
        )
        .unwrap();
        assert_eq!(a.result, MavResult::MAV_RESULT_DENIED);
        assert!(a.reason.unwrap().contains("77"));
        let paused = CommandContext {
            pose_available: false,
            ..CTX
        };
        let a = answer(
            &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 30.0, 0.0, (1, 1)),
            &paused,
        )
        .unwrap();
        assert_eq!(a.result, MavResult::MAV_RESULT_DENIED);
    }

    #[test]
    fn set_mode_offboard_needs_a_stream() {
        let offboard = req(MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 6.0, (1, 1));
        let a = answer(&offboard, &CTX).unwrap();
        assert_eq!((a.result, a.mode), (MavResult::MAV_RESULT_DENIED, None));
        assert!(a.reason.unwrap().contains("no setpoint stream"));
        let live = CommandContext {
            stream_alive: true,
            ..CTX
        };
        let a = answer(&offboard, &live).unwrap();
        assert_eq!(
            (a.result, a.mode),
            (MavResult::MAV_RESULT_ACCEPTED, Some(SitlMode::Offboard))
        );
        let pos = answer(&req(MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 3.0, (1, 1)), &CTX).unwrap();
        assert_eq!(pos.mode, Some(SitlMode::Hold));
        let ap = CommandContext {
            autopilot: SitlAutopilot::Ardupilot,
            stream_alive: true,
            ..CTX
        };
        let a = answer(&req(MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 20.0, (1, 1)), &ap).unwrap();
        assert_eq!(a.mode, Some(SitlMode::Offboard));
        let a = answer(&req(MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 9.0, (1, 1)), &ap).unwrap();
        assert_eq!(a.result, MavResult::MAV_RESULT_DENIED);
    }

    #[test]
    fn px4_hold_rtl_disarm_and_refused_takeoff() {
        let mut hold = req(MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 4.0, (1, 1));
        hold.param3 = 3.0;
        let a = answer(&hold, &CTX).unwrap();
        assert_eq!(
            (a.result, a.mode),
            (MavResult::MAV_RESULT_ACCEPTED, Some(SitlMode::Loiter))
        );
        hold.param3 = 5.0;
        assert_eq!(answer(&hold, &CTX).unwrap().mode, Some(SitlMode::Rtl));
        hold.param3 = 4.0; // AUTO_MISSION: no missions
        let a = answer(&hold, &CTX).unwrap();
        assert_eq!(a.result, MavResult::MAV_RESULT_DENIED);
        assert!(a.reason.unwrap().contains("4/4"));
        let rtl = answer(
            &req(MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH, 0.0, 0.0, (1, 1)),
            &CTX,
        )
        .unwrap();
        assert_eq!(
            (rtl.result, rtl.mode),
            (MavResult::MAV_RESULT_ACCEPTED, Some(SitlMode::Rtl))
        );
        let disarm = answer(
            &req(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0.0, 0.0, (1, 1)),
            &CTX,
        )
        .unwrap();
        assert_eq!(
            (disarm.result, disarm.armed),
            (MavResult::MAV_RESULT_ACCEPTED, Some(false))
        );
        for c in [MavCmd::MAV_CMD_NAV_TAKEOFF, MavCmd::MAV_CMD_NAV_LAND] {
            let a = answer(&req(c, 0.0, 0.0, (1, 1)), &CTX).unwrap();
            assert_eq!(a.result, MavResult::MAV_RESULT_DENIED);
            assert!(a.reason.unwrap().contains("refused"));
        }
        for (id, m) in [
            (242.0, SitlMessage::Home),
            (245.0, SitlMessage::ExtendedSysState),
        ] {
            let a = answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, id, 0.0, (1, 1)), &CTX).unwrap();
            assert_eq!(
                (a.result, a.then),
                (MavResult::MAV_RESULT_ACCEPTED, Some(m))
            );
        }
    }

    #[test]
    fn unknown_commands_unsupported_broadcasts_quiet_others_ignored() {
        let takeoff = req(MavCmd::MAV_CMD_DO_FLIGHTTERMINATION, 0.0, 0.0, (1, 1));
        let a = answer(&takeoff, &CTX).unwrap();
        assert_eq!(a.result, MavResult::MAV_RESULT_UNSUPPORTED);
        match a.ack {
            MavMessage::COMMAND_ACK(d) => {
                assert_eq!((d.target_system, d.target_component), (255, 190))
            }
            other => panic!("{other:?}"),
        }
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_DO_FLIGHTTERMINATION, 0.0, 0.0, (0, 0)),
                &CTX
            )
            .is_none()
        );
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, 0.0, (0, 0)),
                &CTX
            )
            .is_some()
        );
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, 0.0, (1, 191)),
                &CTX
            )
            .is_none()
        );
    }

    #[test]
    fn ftp_requests_are_nacked_or_acked() {
        let mut open = [0u8; 251];
        open[..2].copy_from_slice(&7u16.to_le_bytes());
        open[2] = 0;
        open[3] = 4; // OpenFileRO
        let r = ftp_reply(&open).unwrap();
        assert_eq!(u16::from_le_bytes([r[0], r[1]]), 8);
        assert_eq!(
            (r[3], r[4], r[5], r[12]),
            (FTP_NAK, 1, 4, FTP_ERR_FILE_NOT_FOUND)
        );
        open[3] = 2; // ResetSessions
        assert_eq!(ftp_reply(&open).unwrap()[3], FTP_ACK);
        open[3] = 99;
        assert_eq!(ftp_reply(&open).unwrap()[12], FTP_ERR_UNKNOWN_COMMAND);
        open[3] = FTP_NAK;
        assert!(ftp_reply(&open).is_none());
        assert!(ftp_reply(&[0; 5]).is_none());
    }
}
