//! # dflat-link — the MAVLink contract
//!
//! Pure conversions between dflat's typed messages and the `mavlink` crate
//! (0.21, `common` dialect, MAVLink 2), plus small stateful helpers. No
//! clock in the message code: the daemon owns time. [`transport`] is the one
//! piece of I/O here (UDP, TCP, serial, the .tlog tap), shared by the daemon
//! and the SITL.
//!
//! | direction | message | here |
//! |---|---|---|
//! | out 1 Hz | HEARTBEAT (0) | [`heartbeat_onboard`]: ONBOARD_CONTROLLER, autopilot INVALID, status from [`DaemonStatus`] |
//! | in | HEARTBEAT | [`Inbound::Heartbeat`]: autopilot liveness, mode, armed |
//! | in | LOCAL_POSITION_NED (32) / ODOMETRY (331) / VISION_POSITION_ESTIMATE (102) | [`Inbound::Pose`] |
//! | in | ATTITUDE (30) | [`Inbound::Attitude`] |
//! | in | SET_POSITION_TARGET_LOCAL_NED (84) | [`Inbound::PositionSetpoint`], LOCAL_NED only |
//! | out 50 Hz | SET_ATTITUDE_TARGET (82) | [`set_attitude_target`]: q from ZYX angles, body rates ignored, thrust ∈ [0, 1] |
//! | out | STATUSTEXT (253) | [`statustext`], ≤ 50 bytes |
//!
//! The SITL autopilot reuses the crate the other way round:
//! [`heartbeat_autopilot`], [`local_position_ned`], [`attitude`],
//! [`vision_position_estimate`], [`odometry`] out and
//! [`Inbound::AttitudeTarget`] in.
//!
//! Frames: local NED (x north, y east, z down), body FRD; ZYX Euler angles;
//! quaternions `[w, x, y, z]` rotating body into NED. SI units, radians.
//!
//! Receiving: [`LinkRx::handle`] = [`SourceFilter::check`] → [`decode`] →
//! [`LinkStats`]; with MAVLink 2 signing, [`LinkRx::authenticate`] first
//! ([`Signing`]). Bytes: [`FrameParser`] / [`frames`] report CRC failures
//! (the mavlink crate's own readers skip them silently). Logging:
//! [`tlog::TlogWriter`].

pub mod backoff;
pub mod command;
mod error;
mod filter;
mod frame;
mod inbound;
pub mod math;
pub mod mission;
pub mod modes;
mod outbound;
pub mod params;
pub mod records;
pub mod refusal;
mod signing;
mod stats;
pub mod tlog;
#[cfg(feature = "transport")]
pub mod transport;

/// The mavlink crate this contract is built on (same version for all users).
pub use mavlink;
/// The `common` dialect: message structs and enums.
pub use mavlink::dialects::common as dialect;
pub use mavlink::dialects::common::MavMessage;
pub use mavlink::{MavHeader, MavlinkVersion};

pub use command::{Addressing, CommandRequest, command_ack};
pub use error::{ErrorCategory, FrameError, LinkError, PayloadFault, SetpointRejection};
pub use filter::{DEFAULT_GCS_SYSTEM_IDS, LinkRx, RxOutcome, SourceFilter, Verdict};
pub use frame::{
    EncodedFrame, Frame, FrameIter, FrameParser, MAX_FRAME_LEN, SignedFrame, frames, header,
    parse_frame, serialize_v2, write_v2,
};
pub use inbound::{
    Attitude, AttitudeTarget, CommandAck, Heartbeat, Inbound, ParamValue, Pose, PoseSource,
    PositionSetpoint, decode, ids,
};
pub use math::{ThrustMapping, euler_from_quaternion, quaternion_from_euler};
pub use modes::{AutopilotFamily, AutopilotMode};
pub use outbound::{
    ATTITUDE_TARGET_MASK, AttitudeCommand, DaemonStatus, HEARTBEAT_MAVLINK_VERSION, Outbound,
    STATUSTEXT_MAX_LEN, Target, attitude, heartbeat_autopilot, heartbeat_onboard,
    local_position_ned, odometry, set_attitude_target, statustext, truncate_text,
    vision_position_estimate,
};
pub use signing::{
    KEY_FILE_MAX, KeyFileError, KeyFormatError, MUST_BE_SIGNED, ONE_MINUTE, SIGNING_EPOCH_UNIX_S,
    SignatureCheck, Signing, SigningKey, TIMESTAMP_MAX, TIMESTAMP_UNITS_PER_S, check_key_metadata,
    constant_time_eq, load_key_file, must_be_signed_id, parse_timestamp_file, restart_timestamp,
    timestamp_from_system_time, unsigned_message_id,
};
pub use stats::{LinkStats, MessageCounts};

/// Default MAVLink ids of the contract.
pub mod defaults {
    /// Vehicle system id.
    pub const VEHICLE_SYSTEM_ID: u8 = 1;
    /// Autopilot component id (MAV_COMP_ID_AUTOPILOT1).
    pub const AUTOPILOT_COMPONENT_ID: u8 = 1;
    /// Daemon component id (MAV_COMP_ID_ONBOARD_COMPUTER).
    pub const DAEMON_COMPONENT_ID: u8 = 191;
    /// Ground station system id.
    pub const GCS_SYSTEM_ID: u8 = 255;
}
