//! Missions uploaded over MAVLink to the daemon's own component (1/191):
//! the items ([`items`]), the mission protocol as a pure state machine
//! ([`protocol`]) and the flight of a mission ([`runner`]).
//!
//! Supported items, in MAV_FRAME_LOCAL_NED: MAV_CMD_NAV_WAYPOINT (param1
//! hold time, param2 acceptance radius, param4 yaw in degrees, NaN = keep),
//! MAV_CMD_NAV_LOITER_TIME (param1 hold time) and MAV_CMD_DO_CHANGE_SPEED
//! (param2 speed). MISSION_ITEM_INT's x and y are metres × 1e4 in local
//! frames (the specification), or × `mission.local_xy_scale` when a ground
//! station scales them otherwise (MAVProxy and pymavlink's `mavwp` send
//! × 1e7); the legacy MISSION_ITEM's floats are metres.

pub mod items;
pub mod protocol;
pub mod runner;

pub use items::{ItemError, ItemRules, Mission, MissionItem, parse_item};
pub use protocol::{MissionChange, MissionProtocol, ProtocolCounts, Reply};
pub use runner::{MissionRunner, MissionStatus, RunnerUpdate};
