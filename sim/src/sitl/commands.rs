//! The SITL's side of the command protocol and of MAVLink FTP (pure), the
//! way PX4 answers them:
//!
//! | command | answer |
//! |---|---|
//! | MAV_CMD_REQUEST_MESSAGE (512): HEARTBEAT 0, SYS_STATUS 1, ATTITUDE 30, LOCAL_POSITION_NED 32, AUTOPILOT_VERSION 148 | ACCEPTED, then the message (DENIED while the SITL has not sent it yet, e.g. the pose paused) |
//! | MAV_CMD_REQUEST_MESSAGE, any other message | DENIED, STATUSTEXT "not sent" |
//! | MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES (520) | ACCEPTED, AUTOPILOT_VERSION |
//! | MAV_CMD_DO_SET_MODE (176), param2 = PX4 main mode OFFBOARD 6 / POSCTL 3, ArduPilot GUIDED_NOGPS 20 / LOITER 5 | ACCEPTED and switched; offboard without a live setpoint stream DENIED, STATUSTEXT; other modes DENIED |
//! | MAV_CMD_COMPONENT_ARM_DISARM (400) | arm: ACCEPTED (always armed); disarm: DENIED, STATUSTEXT |
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
    /// A SET_ATTITUDE_TARGET arrived within the offboard-loss timeout.
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
        MavCmd::MAV_CMD_DO_SET_MODE => out = set_mode(req.param2, ctx),
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
            out = if req.param1 == 1.0 {
                Outcome::new(MavResult::MAV_RESULT_ACCEPTED)
            } else {
                Outcome::denied("SITL: disarm refused, the SITL stays armed".into())
            };
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
    })
}

struct Outcome {
    result: MavResult,
    reason: Option<String>,
    then: Option<SitlMessage>,
    mode: Option<SitlMode>,
}

impl Outcome {
    fn new(result: MavResult) -> Self {
        Self {
            result,
            reason: None,
            then: None,
            mode: None,
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
    let pose = matches!(message, SitlMessage::Attitude | SitlMessage::LocalPosition);
    if pose && !ctx.pose_available {
        return Outcome::denied(format!("SITL: {message:?} not available (pose paused)"));
    }
    let mut out = Outcome::new(MavResult::MAV_RESULT_ACCEPTED);
    out.then = Some(message);
    out
}

fn set_mode(custom: f32, ctx: &CommandContext) -> Outcome {
    let mode = whole(custom).and_then(|m| match ctx.autopilot {
        SitlAutopilot::Px4 if m == u32::from(px4::OFFBOARD) => Some(SitlMode::Offboard),
        SitlAutopilot::Px4 if m == u32::from(px4::POSCTL) => Some(SitlMode::Hold),
        SitlAutopilot::Ardupilot if m == ARDUPILOT_MODE_GUIDED_NOGPS => Some(SitlMode::Offboard),
        SitlAutopilot::Ardupilot if m == ARDUPILOT_MODE_LOITER => Some(SitlMode::Hold),
        _ => None,
    });
    match mode {
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
            &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 245.0, 0.0, (1, 1)),
            &CTX,
        )
        .unwrap();
        assert_eq!(a.result, MavResult::MAV_RESULT_DENIED);
        assert!(a.reason.unwrap().contains("245"));
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
    fn unknown_commands_unsupported_broadcasts_quiet_others_ignored() {
        let takeoff = req(MavCmd::MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, (1, 1));
        let a = answer(&takeoff, &CTX).unwrap();
        assert_eq!(a.result, MavResult::MAV_RESULT_UNSUPPORTED);
        match a.ack {
            MavMessage::COMMAND_ACK(d) => {
                assert_eq!((d.target_system, d.target_component), (255, 190))
            }
            other => panic!("{other:?}"),
        }
        assert!(answer(&req(MavCmd::MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, (0, 0)), &CTX).is_none());
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
        let disarm = answer(
            &req(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0.0, 0.0, (1, 1)),
            &CTX,
        )
        .unwrap();
        assert_eq!(disarm.result, MavResult::MAV_RESULT_DENIED);
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
