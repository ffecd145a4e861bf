//! The MAVLink command protocol, the part every component shares (pure):
//! a COMMAND_LONG / COMMAND_INT read as a [`CommandRequest`], whom it
//! addresses ([`Addressing`]), and the COMMAND_ACK addressed to its sender.
//!
//! A component acknowledges every command addressed to it (ACCEPTED,
//! UNSUPPORTED, DENIED, …) and answers a broadcast only when it supports
//! the command — silence is how MAVLink components decline broadcasts, so
//! a ground station's broadcast does not draw an UNSUPPORTED from every
//! component. What each component supports is its own business (the
//! daemon's `commands` module, the SITL's `sitl::commands`).

use mavlink::dialects::common::{
    COMMAND_ACK_DATA, COMMAND_LONG_DATA, MavCmd, MavMessage, MavResult,
};

/// A command received as COMMAND_LONG or COMMAND_INT, with its sender.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandRequest {
    /// The command.
    pub command: MavCmd,
    /// param1 (MAV_CMD_REQUEST_MESSAGE: the message id; MAV_CMD_DO_SET_MODE:
    /// the base mode flags).
    pub param1: f32,
    /// param2 (MAV_CMD_DO_SET_MODE: the custom mode — PX4 main mode,
    /// ArduPilot mode number).
    pub param2: f32,
    /// param3 (MAV_CMD_DO_SET_MODE: PX4's sub mode).
    pub param3: f32,
    /// Addressed system (0 = broadcast).
    pub target_system: u8,
    /// Addressed component (0 = broadcast).
    pub target_component: u8,
    /// Sender's system id.
    pub sender_system: u8,
    /// Sender's component id.
    pub sender_component: u8,
}

/// Whom a command (or any targeted message) addresses, seen from one
/// component.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Addressing {
    /// Our system and our component.
    ToUs,
    /// Target component 0, target system 0 or ours.
    Broadcast,
    /// Another system or another component.
    Elsewhere,
}

impl Addressing {
    /// Whom `(target_system, target_component)` addresses, seen from `own`
    /// = (system, component).
    pub fn of(target_system: u8, target_component: u8, own: (u8, u8)) -> Self {
        if target_system == own.0 && target_component == own.1 {
            Self::ToUs
        } else if target_component == 0 && (target_system == 0 || target_system == own.0) {
            Self::Broadcast
        } else {
            Self::Elsewhere
        }
    }
}

impl CommandRequest {
    /// The request in `msg` from `(sender_system, sender_component)`, if it
    /// is a COMMAND_LONG or COMMAND_INT.
    pub fn from_message(msg: &MavMessage, sender_system: u8, sender_component: u8) -> Option<Self> {
        let (command, [param1, param2, param3], target_system, target_component) = match msg {
            MavMessage::COMMAND_LONG(c) => (
                c.command,
                [c.param1, c.param2, c.param3],
                c.target_system,
                c.target_component,
            ),
            MavMessage::COMMAND_INT(c) => (
                c.command,
                [c.param1, c.param2, c.param3],
                c.target_system,
                c.target_component,
            ),
            _ => return None,
        };
        Some(Self {
            command,
            param1,
            param2,
            param3,
            target_system,
            target_component,
            sender_system,
            sender_component,
        })
    }

    /// Whom the request addresses, seen from `own` = (system, component).
    pub fn addressing(&self, own: (u8, u8)) -> Addressing {
        Addressing::of(self.target_system, self.target_component, own)
    }

    /// param1 as a message id (MAV_CMD_REQUEST_MESSAGE): a finite,
    /// non-negative whole number, else `None`.
    pub fn requested_message_id(&self) -> Option<u32> {
        whole(self.param1)
    }
}

/// `v` as a whole number ≥ 0 that fits a `u32`, else `None`.
pub fn whole(v: f32) -> Option<u32> {
    (v.is_finite() && v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f32).then_some(v as u32)
}

/// COMMAND_ACK for `req` with `result`, addressed to its sender.
pub fn command_ack(req: &CommandRequest, result: MavResult) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command: req.command,
        result,
        progress: 0,
        result_param2: 0,
        target_system: req.sender_system,
        target_component: req.sender_component,
    })
}

/// MAV_CMD_SET_MESSAGE_INTERVAL (511) to `target` = (system, component):
/// message `message_id` every `interval_us` µs (−1 stops it, 0 restores
/// the sender's default), on the link the command arrives by;
/// `confirmation` 0 the first time, counting up on each retransmission
/// (the command protocol's rule).
pub fn set_message_interval(
    target: (u8, u8),
    message_id: u32,
    interval_us: f32,
    confirmation: u8,
) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: message_id as f32,
        param2: interval_us,
        command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        target_system: target.0,
        target_component: target.1,
        confirmation,
        ..Default::default()
    })
}

/// A result's name without its `MAV_RESULT_` prefix (`DENIED`,
/// `UNSUPPORTED`, …), for words a person reads.
pub fn result_name(result: MavResult) -> String {
    let name = format!("{result:?}");
    name.strip_prefix("MAV_RESULT_").unwrap_or(&name).to_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addressing_of_targets() {
        let own = (1, 191);
        assert_eq!(Addressing::of(1, 191, own), Addressing::ToUs);
        assert_eq!(Addressing::of(0, 0, own), Addressing::Broadcast);
        assert_eq!(Addressing::of(1, 0, own), Addressing::Broadcast);
        assert_eq!(Addressing::of(1, 1, own), Addressing::Elsewhere);
        assert_eq!(Addressing::of(2, 0, own), Addressing::Elsewhere);
        assert_eq!(Addressing::of(0, 191, own), Addressing::Elsewhere);
    }

    #[test]
    fn message_ids_are_whole_numbers() {
        assert_eq!(whole(30.0), Some(30));
        for bad in [0.5, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(whole(bad), None, "{bad}");
        }
    }

    /// The request reads back as what it asks (param1 the message id,
    /// param2 the interval), addressed to the autopilot; an answer to it
    /// is for the daemon when addressed to it or to nobody.
    #[test]
    fn a_message_interval_request_reads_back() {
        let msg = set_message_interval((1, 1), 32, 20_000.0, 0);
        let req = CommandRequest::from_message(&msg, 1, 191).unwrap();
        assert_eq!(req.command, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
        assert_eq!(req.requested_message_id(), Some(32));
        assert_eq!(req.param2, 20_000.0);
        assert_eq!(req.addressing((1, 1)), Addressing::ToUs);
        assert_eq!(result_name(MavResult::MAV_RESULT_DENIED), "DENIED");
        assert_eq!(
            result_name(MavResult::MAV_RESULT_UNSUPPORTED),
            "UNSUPPORTED"
        );
    }
}
