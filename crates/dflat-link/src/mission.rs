//! The MAVLink mission protocol's messages, typed (pure): what a component
//! that keeps a mission receives ([`MissionMessage::from_message`]) and the
//! builders of what it sends (MISSION_COUNT, MISSION_REQUEST_INT,
//! MISSION_ITEM_INT, MISSION_ITEM, MISSION_ACK, MISSION_CURRENT,
//! MISSION_ITEM_REACHED).
//!
//! The protocol (mavlink.io, "Mission Protocol"): upload is MISSION_COUNT →
//! MISSION_REQUEST_INT(seq) … → MISSION_ITEM_INT(seq) … → MISSION_ACK from
//! the receiver; download is MISSION_REQUEST_LIST → MISSION_COUNT →
//! MISSION_REQUEST_INT(seq) → MISSION_ITEM_INT(seq) … → MISSION_ACK from the
//! ground station; MISSION_CLEAR_ALL → MISSION_ACK. The state machine that
//! runs it is the daemon's (`dflat_daemon::mission`).

// MISSION_ITEM is deprecated in favour of MISSION_ITEM_INT; it is kept for
// ground stations that still ask with MISSION_REQUEST.
#[allow(deprecated)]
use mavlink::dialects::common::MISSION_ITEM_DATA;
use mavlink::dialects::common::{
    MISSION_ACK_DATA, MISSION_COUNT_DATA, MISSION_CURRENT_DATA, MISSION_ITEM_INT_DATA,
    MISSION_ITEM_REACHED_DATA, MISSION_REQUEST_INT_DATA, MavCmd, MavFrame, MavMessage,
    MavMissionResult, MavMissionType, MissionState,
};

/// The [`ItemFields`] of a MISSION_ITEM_INT (`int`: x and y are scaled
/// integers) or MISSION_ITEM: the two messages share their field names.
macro_rules! item_fields {
    ($d:expr, $int:expr) => {
        ItemFields {
            seq: $d.seq,
            frame: $d.frame,
            command: $d.command,
            params: [$d.param1, $d.param2, $d.param3, $d.param4],
            x: f64::from($d.x),
            y: f64::from($d.y),
            z: $d.z,
            current: $d.current,
            autocontinue: $d.autocontinue,
            int: $int,
        }
    };
}

/// One mission item as both MISSION_ITEM_INT and MISSION_ITEM carry it.
///
/// `x` and `y` are kept as received: for MISSION_ITEM_INT integers
/// (local frames: metres × 1e4 per the specification; global frames:
/// degrees × 1e7), for the legacy MISSION_ITEM floats (metres or degrees).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ItemFields {
    /// Sequence number (0-based).
    pub seq: u16,
    /// The item's frame.
    pub frame: MavFrame,
    /// The command (MAV_CMD_NAV_WAYPOINT, …).
    pub command: MavCmd,
    /// param1 … param4 (the command's parameters, as sent; may be NaN).
    pub params: [f32; 4],
    /// param5 / x, as described above.
    pub x: f64,
    /// param6 / y, as described above.
    pub y: f64,
    /// param7 / z \[m\] (local frames: down).
    pub z: f32,
    /// The `current` flag.
    pub current: u8,
    /// The `autocontinue` flag.
    pub autocontinue: u8,
    /// True when it came as MISSION_ITEM_INT (x, y integers).
    pub int: bool,
}

/// A mission-protocol message, typed, with its addressee.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MissionMessage {
    /// MISSION_COUNT (44): an upload of `count` items begins.
    Count {
        /// Number of items.
        count: u16,
        /// Mission type.
        mission_type: MavMissionType,
    },
    /// MISSION_REQUEST_INT (51), or the legacy MISSION_REQUEST (40) when
    /// `int` is false: the item `seq` is asked for (download).
    Request {
        /// Sequence number asked for.
        seq: u16,
        /// Mission type.
        mission_type: MavMissionType,
        /// True for MISSION_REQUEST_INT.
        int: bool,
    },
    /// MISSION_ITEM_INT (73) or the legacy MISSION_ITEM (39): an item
    /// (upload).
    Item {
        /// The item.
        item: ItemFields,
        /// Mission type.
        mission_type: MavMissionType,
    },
    /// MISSION_ACK (47): the end of a download, or an error from the
    /// other side.
    Ack {
        /// The result.
        result: MavMissionResult,
        /// Mission type.
        mission_type: MavMissionType,
    },
    /// MISSION_REQUEST_LIST (43): a download begins.
    RequestList {
        /// Mission type.
        mission_type: MavMissionType,
    },
    /// MISSION_CLEAR_ALL (45).
    ClearAll {
        /// Mission type.
        mission_type: MavMissionType,
    },
}

impl MissionMessage {
    /// The mission-protocol message in `msg` and its `(target_system,
    /// target_component)`, if it is one.
    pub fn from_message(msg: &MavMessage) -> Option<(Self, (u8, u8))> {
        Some(match msg {
            MavMessage::MISSION_COUNT(d) => (
                Self::Count {
                    count: d.count,
                    mission_type: d.mission_type,
                },
                (d.target_system, d.target_component),
            ),
            MavMessage::MISSION_REQUEST_INT(d) => (
                Self::Request {
                    seq: d.seq,
                    mission_type: d.mission_type,
                    int: true,
                },
                (d.target_system, d.target_component),
            ),
            #[allow(deprecated)]
            MavMessage::MISSION_REQUEST(d) => (
                Self::Request {
                    seq: d.seq,
                    mission_type: d.mission_type,
                    int: false,
                },
                (d.target_system, d.target_component),
            ),
            MavMessage::MISSION_ITEM_INT(d) => (
                Self::Item {
                    item: item_fields!(d, true),
                    mission_type: d.mission_type,
                },
                (d.target_system, d.target_component),
            ),
            #[allow(deprecated)]
            MavMessage::MISSION_ITEM(d) => (
                Self::Item {
                    item: item_fields!(d, false),
                    mission_type: d.mission_type,
                },
                (d.target_system, d.target_component),
            ),
            MavMessage::MISSION_ACK(d) => (
                Self::Ack {
                    result: d.mavtype,
                    mission_type: d.mission_type,
                },
                (d.target_system, d.target_component),
            ),
            MavMessage::MISSION_REQUEST_LIST(d) => (
                Self::RequestList {
                    mission_type: d.mission_type,
                },
                (d.target_system, d.target_component),
            ),
            MavMessage::MISSION_CLEAR_ALL(d) => (
                Self::ClearAll {
                    mission_type: d.mission_type,
                },
                (d.target_system, d.target_component),
            ),
            _ => return None,
        })
    }
}

/// MISSION_COUNT (44) to `to` = (system, component).
pub fn mission_count(to: (u8, u8), count: u16, mission_type: MavMissionType) -> MavMessage {
    MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
        count,
        target_system: to.0,
        target_component: to.1,
        mission_type,
        opaque_id: 0,
    })
}

/// MISSION_REQUEST_INT (51) for item `seq`, to `to`.
pub fn mission_request_int(to: (u8, u8), seq: u16, mission_type: MavMissionType) -> MavMessage {
    MavMessage::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
        seq,
        target_system: to.0,
        target_component: to.1,
        mission_type,
    })
}

/// MISSION_ACK (47) with `result`, to `to`.
pub fn mission_ack(
    to: (u8, u8),
    result: MavMissionResult,
    mission_type: MavMissionType,
) -> MavMessage {
    MavMessage::MISSION_ACK(MISSION_ACK_DATA {
        target_system: to.0,
        target_component: to.1,
        mavtype: result,
        mission_type,
        opaque_id: 0,
    })
}

/// MISSION_ITEM_INT (73) with `item` (x, y as integers, rounded and
/// saturated), to `to`, mission type MISSION.
pub fn mission_item_int(to: (u8, u8), item: &ItemFields) -> MavMessage {
    let int = |v: f64| v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
    MavMessage::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
        param1: item.params[0],
        param2: item.params[1],
        param3: item.params[2],
        param4: item.params[3],
        x: int(item.x),
        y: int(item.y),
        z: item.z,
        seq: item.seq,
        command: item.command,
        target_system: to.0,
        target_component: to.1,
        frame: item.frame,
        current: item.current,
        autocontinue: item.autocontinue,
        mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
    })
}

/// The legacy MISSION_ITEM (39) with `item` (x, y as floats), to `to`, for
/// a ground station that asked with MISSION_REQUEST.
#[allow(deprecated)]
pub fn mission_item(to: (u8, u8), item: &ItemFields) -> MavMessage {
    MavMessage::MISSION_ITEM(MISSION_ITEM_DATA {
        param1: item.params[0],
        param2: item.params[1],
        param3: item.params[2],
        param4: item.params[3],
        x: item.x as f32,
        y: item.y as f32,
        z: item.z,
        seq: item.seq,
        command: item.command,
        target_system: to.0,
        target_component: to.1,
        frame: item.frame,
        current: item.current,
        autocontinue: item.autocontinue,
        mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
    })
}

/// MISSION_CURRENT (42): item `seq` of `total` is current; `state` as
/// PX4 reports it.
pub fn mission_current(seq: u16, total: u16, state: MissionState) -> MavMessage {
    MavMessage::MISSION_CURRENT(MISSION_CURRENT_DATA {
        seq,
        total,
        mission_state: state,
        mission_mode: 0,
        mission_id: 0,
        fence_id: 0,
        rally_points_id: 0,
    })
}

/// MISSION_ITEM_REACHED (46): item `seq` was reached.
pub fn mission_item_reached(seq: u16) -> MavMessage {
    MavMessage::MISSION_ITEM_REACHED(MISSION_ITEM_REACHED_DATA { seq })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn items_round_trip_through_the_int_and_legacy_messages() {
        let item = ItemFields {
            seq: 3,
            frame: MavFrame::MAV_FRAME_LOCAL_NED,
            command: MavCmd::MAV_CMD_NAV_WAYPOINT,
            params: [0.0, 0.5, 0.0, 1.5],
            x: 40_000.0,
            y: -12_345.0,
            z: -10.0,
            current: 0,
            autocontinue: 1,
            int: true,
        };
        let (m, to) = MissionMessage::from_message(&mission_item_int((1, 191), &item)).unwrap();
        assert_eq!(to, (1, 191));
        assert_eq!(
            m,
            MissionMessage::Item {
                item,
                mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION
            }
        );
        let (m, _) = MissionMessage::from_message(&mission_item((1, 191), &item)).unwrap();
        let MissionMessage::Item { item: legacy, .. } = m else {
            panic!("{m:?}")
        };
        assert!(!legacy.int);
        assert_eq!((legacy.x, legacy.y, legacy.seq), (40_000.0, -12_345.0, 3));
        let hb = MavMessage::HEARTBEAT(Default::default());
        assert!(MissionMessage::from_message(&hb).is_none());
    }

    #[test]
    fn requests_counts_and_acks_are_typed() {
        let t = MavMissionType::MAV_MISSION_TYPE_FENCE;
        let (m, to) = MissionMessage::from_message(&mission_count((1, 191), 4, t)).unwrap();
        assert_eq!(
            (m, to),
            (
                MissionMessage::Count {
                    count: 4,
                    mission_type: t
                },
                (1, 191)
            )
        );
        let (m, _) = MissionMessage::from_message(&mission_request_int((255, 190), 2, t)).unwrap();
        assert_eq!(
            m,
            MissionMessage::Request {
                seq: 2,
                mission_type: t,
                int: true
            }
        );
        let ack = mission_ack((255, 190), MavMissionResult::MAV_MISSION_UNSUPPORTED, t);
        let (m, to) = MissionMessage::from_message(&ack).unwrap();
        assert_eq!(to, (255, 190));
        assert_eq!(
            m,
            MissionMessage::Ack {
                result: MavMissionResult::MAV_MISSION_UNSUPPORTED,
                mission_type: t
            }
        );
    }
}
