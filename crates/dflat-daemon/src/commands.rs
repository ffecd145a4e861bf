//! The MAVLink command protocol, the daemon's side (pure).
//!
//! A component must acknowledge the commands addressed to it. The daemon
//! (component `link.component_id`, default 191) answers COMMAND_LONG and
//! COMMAND_INT the way PX4 does:
//!
//! | command | answer |
//! |---|---|
//! | MAV_CMD_REQUEST_MESSAGE (512), param1 = HEARTBEAT (0) | ACCEPTED, then the HEARTBEAT |
//! | MAV_CMD_REQUEST_MESSAGE, param1 = STATUSTEXT (253) | ACCEPTED, then the daemon's state as a STATUSTEXT |
//! | MAV_CMD_REQUEST_MESSAGE, any other message | DENIED, and a STATUSTEXT: the daemon does not send it |
//! | any other command of the common dialect | UNSUPPORTED |
//!
//! Addressing: a command addressed to the daemon's system and component is
//! always answered. A broadcast (target component 0, target system 0 or
//! ours) is answered only when supported — silence is how MAVLink
//! components decline broadcasts, so a ground station's broadcast does not
//! draw an UNSUPPORTED from every component. Commands addressed elsewhere
//! are not the daemon's business. The acknowledgement is addressed to the
//! sender. Command ids outside the common dialect do not decode (the
//! mavlink crate's enum) and are counted as malformed, not answered.

use dflat_link::MavMessage;
pub use dflat_link::command::{Addressing, CommandRequest, command_ack};
use dflat_link::dialect::{MavCmd, MavResult};

/// HEARTBEAT's message id.
const HEARTBEAT_ID: u32 = 0;
/// STATUSTEXT's message id.
const STATUSTEXT_ID: u32 = 253;

/// A message the daemon sends in answer to MAV_CMD_REQUEST_MESSAGE.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RequestedMessage {
    /// Its HEARTBEAT (as the 1 Hz one).
    Heartbeat,
    /// Its state as a STATUSTEXT.
    Status,
}

/// The daemon's answer to one command.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandAnswer {
    /// COMMAND_ACK addressed to the sender.
    pub ack: MavMessage,
    /// Sent after the acknowledgement, when the command asked for it.
    pub then: Option<RequestedMessage>,
    /// Why a command was DENIED, sent as a STATUSTEXT after the ack.
    pub reason: Option<String>,
}

/// The daemon's answer to `req` (`None`: not addressed to it, or a
/// broadcast it does not support). `own` = (system, component).
pub fn answer(req: &CommandRequest, own: (u8, u8)) -> Option<CommandAnswer> {
    let addressing = req.addressing(own);
    if addressing == Addressing::Elsewhere {
        return None;
    }
    let (result, then) = match req.command {
        MavCmd::MAV_CMD_REQUEST_MESSAGE => match req.requested_message_id() {
            Some(HEARTBEAT_ID) => (
                MavResult::MAV_RESULT_ACCEPTED,
                Some(RequestedMessage::Heartbeat),
            ),
            Some(STATUSTEXT_ID) => (
                MavResult::MAV_RESULT_ACCEPTED,
                Some(RequestedMessage::Status),
            ),
            _ => (MavResult::MAV_RESULT_DENIED, None),
        },
        _ => (MavResult::MAV_RESULT_UNSUPPORTED, None),
    };
    if addressing == Addressing::Broadcast && result != MavResult::MAV_RESULT_ACCEPTED {
        return None;
    }
    let reason = (result == MavResult::MAV_RESULT_DENIED)
        .then(|| format!("dflat: message {} not sent by this component", req.param1));
    Some(CommandAnswer {
        ack: command_ack(req, result),
        then,
        reason,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const OWN: (u8, u8) = (1, 191);

    fn req(command: MavCmd, param1: f32, target: (u8, u8)) -> CommandRequest {
        CommandRequest {
            command,
            param1,
            param2: 0.0,
            param3: 0.0,
            target_system: target.0,
            target_component: target.1,
            sender_system: 255,
            sender_component: 190,
        }
    }

    fn result_of(a: &CommandAnswer) -> (MavCmd, MavResult, u8, u8) {
        match &a.ack {
            MavMessage::COMMAND_ACK(d) => {
                (d.command, d.result, d.target_system, d.target_component)
            }
            other => panic!("not an ack: {other:?}"),
        }
    }

    #[test]
    fn request_heartbeat_is_accepted_and_sent() {
        let a = answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, OWN), OWN).unwrap();
        assert_eq!(
            result_of(&a),
            (
                MavCmd::MAV_CMD_REQUEST_MESSAGE,
                MavResult::MAV_RESULT_ACCEPTED,
                255,
                190
            )
        );
        assert_eq!(a.then, Some(RequestedMessage::Heartbeat));
        let a = answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 253.0, OWN), OWN).unwrap();
        assert_eq!(a.then, Some(RequestedMessage::Status));
    }

    #[test]
    fn a_message_the_daemon_does_not_send_is_denied() {
        for id in [30.0, 148.0, 0.5, -1.0, f32::NAN] {
            let a = answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, id, OWN), OWN).unwrap();
            assert_eq!(result_of(&a).1, MavResult::MAV_RESULT_DENIED, "{id}");
            assert_eq!(a.then, None);
            assert!(a.reason.is_some_and(|r| r.contains("not sent")), "{id}");
        }
    }

    #[test]
    fn unsupported_commands_are_said_to_be() {
        let a = answer(&req(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, OWN), OWN).unwrap();
        assert_eq!(
            result_of(&a),
            (
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                MavResult::MAV_RESULT_UNSUPPORTED,
                255,
                190
            )
        );
    }

    #[test]
    fn broadcasts_are_answered_only_when_supported() {
        assert!(answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (0, 0)), OWN).is_some());
        assert!(answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (1, 0)), OWN).is_some());
        assert!(answer(&req(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, (0, 0)), OWN).is_none());
        assert!(answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 30.0, (1, 0)), OWN).is_none());
    }

    #[test]
    fn commands_for_others_are_not_answered() {
        assert!(answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (1, 1)), OWN).is_none());
        assert!(answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (2, 191)), OWN).is_none());
        assert!(answer(&req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (2, 0)), OWN).is_none());
    }

    #[test]
    fn requests_are_read_from_command_long_and_int() {
        use dflat_link::dialect::{COMMAND_INT_DATA, COMMAND_LONG_DATA};
        let long = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
            param1: 0.0,
            target_system: 1,
            target_component: 191,
            ..COMMAND_LONG_DATA::default()
        });
        let r = CommandRequest::from_message(&long, 255, 190).unwrap();
        assert_eq!(
            (r.target_system, r.target_component, r.sender_system),
            (1, 191, 255)
        );
        let int = MavMessage::COMMAND_INT(COMMAND_INT_DATA {
            command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
            param1: 253.0,
            target_system: 1,
            target_component: 191,
            ..COMMAND_INT_DATA::default()
        });
        assert_eq!(
            CommandRequest::from_message(&int, 255, 190).unwrap().param1,
            253.0
        );
        let hb = MavMessage::HEARTBEAT(Default::default());
        assert!(CommandRequest::from_message(&hb, 1, 1).is_none());
    }
}
