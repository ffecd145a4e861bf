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
//! | MAV_CMD_MISSION_START (300), param1 = first item | ACCEPTED with a mission uploaded and the stream on (flown at once, or after the engagement in standby); DENIED without a mission, TEMPORARILY_REJECTED without the stream |
//! | MAV_CMD_DO_PAUSE_CONTINUE (193), param1 0 / 1 | ACCEPTED while engaged: pause = brake to a stop and hold, continue = the goal before, from where the vehicle is; TEMPORARILY_REJECTED in standby; DENIED for another param1 |
//! | MAV_CMD_DO_CHANGE_SPEED (178), param2 = speed \[m/s\] | ACCEPTED for 0.1–20 m/s (the mission's speed from now on); DENIED otherwise |
//! | any other command of the common dialect | UNSUPPORTED |
//!
//! The three mission commands are acted on only when addressed to the
//! daemon itself (a broadcast MISSION_START is the autopilot's).
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

use crate::mission::items::MAX_SPEED;
use crate::tick::MissionAction;

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
    /// Why a command was not accepted, sent as a STATUSTEXT after the ack.
    pub reason: Option<String>,
    /// The mission command for the control thread, when accepted.
    pub action: Option<MissionAction>,
}

/// What the mission commands' answers depend on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CommandContext {
    /// A mission with a navigation item is uploaded.
    pub has_mission: bool,
    /// The daemon streams commands (standby, holding, tracking).
    pub streaming: bool,
    /// The autopilot applies them (holding, tracking).
    pub engaged: bool,
}

impl CommandContext {
    /// The context of a command answered in flight state `state` (`None`:
    /// before the first tick) with or without a navigable mission.
    pub fn new(has_mission: bool, state: Option<crate::supervisor::FlightState>) -> Self {
        Self {
            has_mission,
            streaming: state.is_some_and(crate::supervisor::FlightState::streams),
            engaged: state.is_some_and(crate::supervisor::FlightState::engaged),
        }
    }
}

/// The daemon's answer to `req` (`None`: not addressed to it, or a
/// broadcast it does not support). `own` = (system, component).
pub fn answer(req: &CommandRequest, own: (u8, u8), ctx: &CommandContext) -> Option<CommandAnswer> {
    let addressing = req.addressing(own);
    if addressing == Addressing::Elsewhere {
        return None;
    }
    if let Some((result, action, reason)) = mission_command(req, ctx) {
        if addressing == Addressing::Broadcast {
            return None;
        }
        return Some(CommandAnswer {
            ack: command_ack(req, result),
            then: None,
            reason: reason.map(str::to_owned),
            action,
        });
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
        action: None,
    })
}

type MissionAnswer = (MavResult, Option<MissionAction>, Option<&'static str>);

/// The answer to a mission command (`None`: not one).
fn mission_command(req: &CommandRequest, ctx: &CommandContext) -> Option<MissionAnswer> {
    let rejected = |why| Some((MavResult::MAV_RESULT_TEMPORARILY_REJECTED, None, Some(why)));
    let denied = |why| Some((MavResult::MAV_RESULT_DENIED, None, Some(why)));
    let accepted = |action| Some((MavResult::MAV_RESULT_ACCEPTED, Some(action), None));
    match req.command {
        MavCmd::MAV_CMD_MISSION_START => {
            if !ctx.has_mission {
                denied("dflat: no mission uploaded to 191")
            } else if !ctx.streaming {
                rejected("dflat: mission start: not in control")
            } else {
                let first = dflat_link::command::whole(req.param1).unwrap_or(0);
                accepted(MissionAction::Start {
                    first: first.min(u32::from(u16::MAX)) as u16,
                })
            }
        }
        MavCmd::MAV_CMD_DO_PAUSE_CONTINUE => {
            let action = match dflat_link::command::whole(req.param1) {
                Some(0) => MissionAction::Pause,
                Some(1) => MissionAction::Continue,
                _ => return denied("dflat: pause/continue: param1 not 0 or 1"),
            };
            if ctx.engaged {
                accepted(action)
            } else {
                rejected("dflat: pause/continue: not engaged")
            }
        }
        MavCmd::MAV_CMD_DO_CHANGE_SPEED => {
            let speed = f64::from(req.param2);
            if speed.is_finite() && (0.1..=MAX_SPEED).contains(&speed) {
                accepted(MissionAction::Speed(speed))
            } else {
                denied("dflat: speed not 0.1-20 m/s")
            }
        }
        _ => None,
    }
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
        let a = answer(
            &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, OWN),
            OWN,
            &CommandContext::default(),
        )
        .unwrap();
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
        let a = answer(
            &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 253.0, OWN),
            OWN,
            &CommandContext::default(),
        )
        .unwrap();
        assert_eq!(a.then, Some(RequestedMessage::Status));
    }

    #[test]
    fn a_message_the_daemon_does_not_send_is_denied() {
        for id in [30.0, 148.0, 0.5, -1.0, f32::NAN] {
            let a = answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, id, OWN),
                OWN,
                &CommandContext::default(),
            )
            .unwrap();
            assert_eq!(result_of(&a).1, MavResult::MAV_RESULT_DENIED, "{id}");
            assert_eq!(a.then, None);
            assert!(a.reason.is_some_and(|r| r.contains("not sent")), "{id}");
        }
    }

    #[test]
    fn unsupported_commands_are_said_to_be() {
        let a = answer(
            &req(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, OWN),
            OWN,
            &CommandContext::default(),
        )
        .unwrap();
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
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (0, 0)),
                OWN,
                &CommandContext::default()
            )
            .is_some()
        );
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (1, 0)),
                OWN,
                &CommandContext::default()
            )
            .is_some()
        );
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, (0, 0)),
                OWN,
                &CommandContext::default()
            )
            .is_none()
        );
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 30.0, (1, 0)),
                OWN,
                &CommandContext::default()
            )
            .is_none()
        );
    }

    #[test]
    fn commands_for_others_are_not_answered() {
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (1, 1)),
                OWN,
                &CommandContext::default()
            )
            .is_none()
        );
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (2, 191)),
                OWN,
                &CommandContext::default()
            )
            .is_none()
        );
        assert!(
            answer(
                &req(MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0, (2, 0)),
                OWN,
                &CommandContext::default()
            )
            .is_none()
        );
    }

    #[test]
    fn mission_commands_depend_on_the_mission_and_the_state() {
        use MavResult::*;
        let flying = CommandContext {
            has_mission: true,
            streaming: true,
            engaged: true,
        };
        let standby = CommandContext {
            engaged: false,
            ..flying
        };
        let none = CommandContext::default();
        let mut speed = req(MavCmd::MAV_CMD_DO_CHANGE_SPEED, 1.0, OWN);
        speed.param2 = 3.0;
        let mut too_fast = speed;
        too_fast.param2 = 40.0;
        let table = [
            (
                req(MavCmd::MAV_CMD_MISSION_START, 2.0, OWN),
                flying,
                MAV_RESULT_ACCEPTED,
                Some(MissionAction::Start { first: 2 }),
            ),
            (
                req(MavCmd::MAV_CMD_MISSION_START, 0.0, OWN),
                standby,
                MAV_RESULT_ACCEPTED,
                Some(MissionAction::Start { first: 0 }),
            ),
            (
                req(MavCmd::MAV_CMD_MISSION_START, 0.0, OWN),
                none,
                MAV_RESULT_DENIED,
                None,
            ),
            (
                req(MavCmd::MAV_CMD_MISSION_START, 0.0, OWN),
                CommandContext {
                    has_mission: true,
                    ..none
                },
                MAV_RESULT_TEMPORARILY_REJECTED,
                None,
            ),
            (
                req(MavCmd::MAV_CMD_DO_PAUSE_CONTINUE, 0.0, OWN),
                flying,
                MAV_RESULT_ACCEPTED,
                Some(MissionAction::Pause),
            ),
            (
                req(MavCmd::MAV_CMD_DO_PAUSE_CONTINUE, 1.0, OWN),
                flying,
                MAV_RESULT_ACCEPTED,
                Some(MissionAction::Continue),
            ),
            (
                req(MavCmd::MAV_CMD_DO_PAUSE_CONTINUE, 0.0, OWN),
                standby,
                MAV_RESULT_TEMPORARILY_REJECTED,
                None,
            ),
            (
                req(MavCmd::MAV_CMD_DO_PAUSE_CONTINUE, 2.0, OWN),
                flying,
                MAV_RESULT_DENIED,
                None,
            ),
            (
                speed,
                none,
                MAV_RESULT_ACCEPTED,
                Some(MissionAction::Speed(3.0)),
            ),
            (too_fast, flying, MAV_RESULT_DENIED, None),
        ];
        for (r, ctx, result, action) in table {
            let a = answer(&r, OWN, &ctx).unwrap();
            assert_eq!(
                (result_of(&a).1, a.action),
                (result, action),
                "{r:?} {ctx:?}"
            );
            assert_eq!(a.reason.is_some(), result != MAV_RESULT_ACCEPTED);
        }
        // Broadcasts are the autopilot's.
        let b = req(MavCmd::MAV_CMD_MISSION_START, 0.0, (1, 0));
        assert!(answer(&b, OWN, &flying).is_none());
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
