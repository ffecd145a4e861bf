//! Typed inbound messages and their validating decoder.

use mavlink::MavHeader;
use mavlink::MessageData;
use mavlink::dialects::common::{
    ATTITUDE_DATA, AttitudeTargetTypemask, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot,
    MavCmd, MavFrame, MavMessage, MavModeFlag, MavResult, MavState, MavType, ODOMETRY_DATA,
    PositionTargetTypemask, SET_ATTITUDE_TARGET_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA,
    VISION_POSITION_ESTIMATE_DATA,
};

use crate::math::{normalize_quaternion, quaternion_norm, yaw_from_quaternion};
use crate::{LinkError, SetpointRejection};

/// A decoded, validated message the contract acts on. All numbers are finite.
#[derive(Debug, Clone, PartialEq)]
pub enum Inbound {
    /// HEARTBEAT (0): liveness, mode and arming state of the sender.
    Heartbeat(Heartbeat),
    /// A pose estimate from LOCAL_POSITION_NED (32), ODOMETRY (331) or
    /// VISION_POSITION_ESTIMATE (102).
    Pose(Pose),
    /// ATTITUDE (30): the autopilot's attitude estimate.
    Attitude(Attitude),
    /// SET_POSITION_TARGET_LOCAL_NED (84) in LOCAL_NED with the position used.
    PositionSetpoint(PositionSetpoint),
    /// SET_ATTITUDE_TARGET (82): the command the SITL autopilot receives.
    AttitudeTarget(AttitudeTarget),
    /// PARAM_VALUE (22): one of the autopilot's parameters.
    ParamValue(ParamValue),
    /// COMMAND_ACK (77): the answer to a command.
    CommandAck(CommandAck),
    /// Any other message of the common dialect, by message id.
    Other(u32),
}

/// PARAM_VALUE (22) contents: a parameter's name and value (as a float;
/// PX4 and ArduPilot send the parameters dflat reads as REAL32 or as
/// float-cast integers).
#[derive(Debug, Clone, PartialEq)]
pub struct ParamValue {
    /// The parameter's name (at most 16 characters).
    pub name: String,
    /// Its value (finite).
    pub value: f64,
    /// Its index, and the number of parameters the sender has.
    pub index: u16,
    /// Number of parameters the sender has.
    pub count: u16,
}

/// COMMAND_ACK (77) contents: which command was answered, how, and to
/// whom (target 0/0: an autopilot that does not fill the extension
/// fields; the answer is then for every requester).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandAck {
    /// The command answered.
    pub command: MavCmd,
    /// The result (ACCEPTED, DENIED, UNSUPPORTED, IN_PROGRESS, …).
    pub result: MavResult,
    /// The requester's system id (0: not given).
    pub target_system: u8,
    /// The requester's component id (0: not given).
    pub target_component: u8,
}

impl CommandAck {
    /// Whether the answer is for the component `own` = (system,
    /// component): addressed to it, or to nobody in particular.
    pub fn is_for(&self, own: (u8, u8)) -> bool {
        (self.target_system == 0 || self.target_system == own.0)
            && (self.target_component == 0 || self.target_component == own.1)
    }
}

/// HEARTBEAT (0) contents.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Heartbeat {
    /// Autopilot type of the sender.
    pub autopilot: MavAutopilot,
    /// Vehicle / component type of the sender.
    pub mav_type: MavType,
    /// Base mode flags.
    pub base_mode: MavModeFlag,
    /// Autopilot-specific mode (PX4: main/sub mode packed; ArduPilot: mode number).
    pub custom_mode: u32,
    /// System status.
    pub system_status: MavState,
    /// `base_mode` has MAV_MODE_FLAG_SAFETY_ARMED.
    pub armed: bool,
}

/// Which message a [`Pose`] came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PoseSource {
    /// LOCAL_POSITION_NED (32): position only, no yaw, no reset counter.
    LocalPositionNed,
    /// ODOMETRY (331): position and quaternion (yaw), reset counter.
    Odometry,
    /// VISION_POSITION_ESTIMATE (102): position and Euler angles, reset counter.
    VisionPositionEstimate,
}

/// A position (and maybe yaw) estimate in the local NED frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Timestamp on the *source's* clock \[µs\] (LOCAL_POSITION_NED:
    /// `time_boot_ms·1000`; the others: their `time_usec` / `usec`).
    pub time_usec: u64,
    /// Position [x north, y east, z down] \[m\] in local NED (or LOCAL_FRD, see
    /// [`decode`]).
    pub position: [f64; 3],
    /// Yaw ψ \[rad\] (heading of body x from the frame's x axis), if the message has one.
    pub yaw: Option<f64>,
    /// Message the pose came from.
    pub source: PoseSource,
    /// Estimator reset counter (increments on a discontinuity), if the message has one.
    pub reset_counter: Option<u8>,
}

/// ATTITUDE (30) contents.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attitude {
    /// Timestamp since the autopilot booted \[ms\].
    pub time_boot_ms: u32,
    /// Roll φ \[rad\], ZYX.
    pub roll: f64,
    /// Pitch θ \[rad\], ZYX.
    pub pitch: f64,
    /// Yaw ψ \[rad\], ZYX.
    pub yaw: f64,
    /// Body rates [p, q, r] \[rad/s\] about body FRD axes.
    pub rates: [f64; 3],
}

/// A position setpoint in local NED, from SET_POSITION_TARGET_LOCAL_NED (84).
///
/// Velocity and acceleration are read when their three type_mask ignore
/// bits are all clear (then the message is a sample of a streamed
/// trajectory); fields whose bits are set are not read (they may
/// legitimately be NaN).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionSetpoint {
    /// Sender's timestamp since boot \[ms\].
    pub time_boot_ms: u32,
    /// Target position [x north, y east, z down] \[m\].
    pub position: [f64; 3],
    /// Target yaw \[rad\], `None` when the yaw-ignore bit (1024) is set.
    pub yaw: Option<f64>,
    /// Target yaw rate \[rad/s\], `None` when the yaw-rate-ignore bit
    /// (2048) is set.
    pub yaw_rate: Option<f64>,
    /// Velocity, local NED [m/s], when bits 8–32 (vx, vy, vz ignore) are clear.
    pub velocity: Option<[f64; 3]>,
    /// Acceleration, local NED [m/s²], when bits 64–256 (ax, ay, az ignore)
    /// are clear and bit 512 (force) is not set.
    pub acceleration: Option<[f64; 3]>,
    /// Addressed system id (0 = broadcast).
    pub target_system: u8,
    /// Addressed component id (0 = broadcast).
    pub target_component: u8,
}

/// SET_ATTITUDE_TARGET (82) contents, honouring its type_mask.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeTarget {
    /// Sender's timestamp since boot \[ms\].
    pub time_boot_ms: u32,
    /// Addressed system id.
    pub target_system: u8,
    /// Addressed component id.
    pub target_component: u8,
    /// Attitude `[w, x, y, z]` (body FRD → NED), normalized; `None` if ignored (bit 128).
    pub q: Option<[f64; 4]>,
    /// Body rates [p, q, r] \[rad/s\], each `None` if its ignore bit (1, 2, 4) is set.
    pub body_rates: [Option<f64>; 3],
    /// Normalized thrust (nominally [0, 1], not clamped here); `None` if ignored (bit 64).
    pub thrust: Option<f64>,
    /// The raw type_mask bits.
    pub type_mask: u8,
}

/// Decodes and validates one message of the common dialect.
///
/// `header` is the sender's header: a system id above 255 (the mavlink
/// crate's non-standard 32-bit ids) is refused. Source filtering is *not*
/// done here (see [`crate::SourceFilter`]).
///
/// Accepted forms:
/// * LOCAL_POSITION_NED: x, y, z finite.
/// * ODOMETRY: `frame_id` MAV_FRAME_LOCAL_NED (1) or MAV_FRAME_LOCAL_FRD (20)
///   — both are fixed, z-down, right-handed local frames, which is all the
///   controller needs (setpoints must then be in the same frame; with FRD,
///   "north" means the frame's x axis). ENU/FLU and global frames are
///   refused ([`LinkError::UnsupportedFrame`]). `child_frame_id` only
///   concerns the velocity, which is not read. Position and quaternion
///   finite, quaternion norm within 10 % of 1; yaw from the quaternion.
/// * VISION_POSITION_ESTIMATE: x, y, z, yaw finite (covariance not read).
/// * ATTITUDE: angles and rates finite.
/// * SET_POSITION_TARGET_LOCAL_NED: `coordinate_frame` MAV_FRAME_LOCAL_NED
///   only and x/y/z ignore bits clear, else [`LinkError::SetpointRejected`];
///   position finite, yaw finite if used.
/// * SET_ATTITUDE_TARGET: fields not ignored by type_mask finite; the 3-D
///   `thrust_body` mode (bit 32) is refused.
/// * Everything else: [`Inbound::Other`] with the message id.
pub fn decode(header: &MavHeader, msg: &MavMessage) -> Result<Inbound, LinkError> {
    if header.system_id > u32::from(u8::MAX) {
        return Err(LinkError::SystemIdOutOfRange(header.system_id));
    }
    Ok(match msg {
        MavMessage::HEARTBEAT(d) => Inbound::Heartbeat(decode_heartbeat(d)),
        MavMessage::LOCAL_POSITION_NED(d) => Inbound::Pose(decode_local_position(d)?),
        MavMessage::ODOMETRY(d) => Inbound::Pose(decode_odometry(d)?),
        MavMessage::VISION_POSITION_ESTIMATE(d) => Inbound::Pose(decode_vision(d)?),
        MavMessage::ATTITUDE(d) => Inbound::Attitude(decode_attitude(d)?),
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) => {
            Inbound::PositionSetpoint(decode_setpoint(d)?)
        }
        MavMessage::SET_ATTITUDE_TARGET(d) => Inbound::AttitudeTarget(decode_attitude_target(d)?),
        MavMessage::PARAM_VALUE(d) => Inbound::ParamValue(ParamValue {
            name: d.param_id.to_str().unwrap_or("").to_owned(),
            value: finite("PARAM_VALUE", "param_value", d.param_value)?,
            index: d.param_index,
            count: d.param_count,
        }),
        MavMessage::COMMAND_ACK(d) => Inbound::CommandAck(CommandAck {
            command: d.command,
            result: d.result,
            target_system: d.target_system,
            target_component: d.target_component,
        }),
        other => Inbound::Other(mavlink::Message::message_id(other)),
    })
}

fn finite(message: &'static str, field: &'static str, v: f32) -> Result<f64, LinkError> {
    if v.is_finite() {
        Ok(f64::from(v))
    } else {
        Err(LinkError::NonFinite { message, field })
    }
}

/// Three finite components; the error names the component (`z`, `vx`,
/// `afy`, `yawspeed`: the message's own field names).
fn finite3(message: &'static str, field: &'static str, v: [f32; 3]) -> Result<[f64; 3], LinkError> {
    let names: [&'static str; 3] = match field {
        "position" => ["x", "y", "z"],
        "velocity" => ["vx", "vy", "vz"],
        "acceleration" => ["afx", "afy", "afz"],
        "rates" => ["rollspeed", "pitchspeed", "yawspeed"],
        other => [other; 3],
    };
    Ok([
        finite(message, names[0], v[0])?,
        finite(message, names[1], v[1])?,
        finite(message, names[2], v[2])?,
    ])
}

/// Checks a received quaternion and returns it normalized.
fn quaternion(message: &'static str, q: [f32; 4]) -> Result<[f64; 4], LinkError> {
    let q = [
        finite(message, "q", q[0])?,
        finite(message, "q", q[1])?,
        finite(message, "q", q[2])?,
        finite(message, "q", q[3])?,
    ];
    let norm = quaternion_norm(q);
    if (norm - 1.0).abs() > 0.1 {
        return Err(LinkError::BadQuaternion { message, norm });
    }
    normalize_quaternion(q).ok_or(LinkError::BadQuaternion { message, norm })
}

fn decode_heartbeat(d: &HEARTBEAT_DATA) -> Heartbeat {
    Heartbeat {
        autopilot: d.autopilot,
        mav_type: d.mavtype,
        base_mode: d.base_mode,
        custom_mode: d.custom_mode,
        system_status: d.system_status,
        armed: d
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
    }
}

fn decode_local_position(d: &LOCAL_POSITION_NED_DATA) -> Result<Pose, LinkError> {
    const M: &str = "LOCAL_POSITION_NED";
    Ok(Pose {
        time_usec: u64::from(d.time_boot_ms) * 1000,
        position: finite3(M, "position", [d.x, d.y, d.z])?,
        yaw: None,
        source: PoseSource::LocalPositionNed,
        reset_counter: None,
    })
}

fn decode_odometry(d: &ODOMETRY_DATA) -> Result<Pose, LinkError> {
    const M: &str = "ODOMETRY";
    match d.frame_id {
        MavFrame::MAV_FRAME_LOCAL_NED | MavFrame::MAV_FRAME_LOCAL_FRD => {}
        frame => {
            return Err(LinkError::UnsupportedFrame {
                message: M,
                frame,
                accepted: "MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_FRD",
            });
        }
    }
    let position = finite3(M, "position", [d.x, d.y, d.z])?;
    let q = quaternion(M, d.q)?;
    Ok(Pose {
        time_usec: d.time_usec,
        position,
        yaw: Some(yaw_from_quaternion(q)),
        source: PoseSource::Odometry,
        reset_counter: Some(d.reset_counter),
    })
}

fn decode_vision(d: &VISION_POSITION_ESTIMATE_DATA) -> Result<Pose, LinkError> {
    const M: &str = "VISION_POSITION_ESTIMATE";
    Ok(Pose {
        time_usec: d.usec,
        position: finite3(M, "position", [d.x, d.y, d.z])?,
        yaw: Some(finite(M, "yaw", d.yaw)?),
        source: PoseSource::VisionPositionEstimate,
        reset_counter: Some(d.reset_counter),
    })
}

fn decode_attitude(d: &ATTITUDE_DATA) -> Result<Attitude, LinkError> {
    const M: &str = "ATTITUDE";
    Ok(Attitude {
        time_boot_ms: d.time_boot_ms,
        roll: finite(M, "roll", d.roll)?,
        pitch: finite(M, "pitch", d.pitch)?,
        yaw: finite(M, "yaw", d.yaw)?,
        rates: finite3(M, "rates", [d.rollspeed, d.pitchspeed, d.yawspeed])?,
    })
}

fn decode_setpoint(d: &SET_POSITION_TARGET_LOCAL_NED_DATA) -> Result<PositionSetpoint, LinkError> {
    const M: &str = "SET_POSITION_TARGET_LOCAL_NED";
    if d.coordinate_frame != MavFrame::MAV_FRAME_LOCAL_NED {
        return Err(LinkError::SetpointRejected(SetpointRejection::Frame(
            d.coordinate_frame,
        )));
    }
    let position_ignore = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE;
    if d.type_mask.intersects(position_ignore) {
        return Err(LinkError::SetpointRejected(
            SetpointRejection::PositionIgnored {
                type_mask: d.type_mask.bits(),
            },
        ));
    }
    let yaw = if d
        .type_mask
        .contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE)
    {
        None
    } else {
        Some(finite(M, "yaw", d.yaw)?)
    };
    let yaw_rate = if d
        .type_mask
        .contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE)
    {
        None
    } else {
        Some(finite(M, "yaw_rate", d.yaw_rate)?)
    };
    let velocity_ignore = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE;
    let velocity = if d.type_mask.intersects(velocity_ignore) {
        None
    } else {
        Some(finite3(M, "velocity", [d.vx, d.vy, d.vz])?)
    };
    let acceleration_ignore = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_FORCE_SET;
    let acceleration = if d.type_mask.intersects(acceleration_ignore) {
        None
    } else {
        Some(finite3(M, "acceleration", [d.afx, d.afy, d.afz])?)
    };
    Ok(PositionSetpoint {
        time_boot_ms: d.time_boot_ms,
        position: finite3(M, "position", [d.x, d.y, d.z])?,
        yaw,
        yaw_rate,
        velocity,
        acceleration,
        target_system: d.target_system,
        target_component: d.target_component,
    })
}

fn decode_attitude_target(d: &SET_ATTITUDE_TARGET_DATA) -> Result<AttitudeTarget, LinkError> {
    const M: &str = "SET_ATTITUDE_TARGET";
    let mask = d.type_mask;
    if mask.contains(AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_THRUST_BODY_SET) {
        return Err(LinkError::UnsupportedTypeMask {
            message: M,
            type_mask: u16::from(mask.bits()),
            reason: "3-D thrust_body is not supported",
        });
    }
    let q = if mask.contains(AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE) {
        None
    } else {
        Some(quaternion(M, d.q)?)
    };
    let rate = |bit: AttitudeTargetTypemask, v: f32| -> Result<Option<f64>, LinkError> {
        if mask.contains(bit) {
            Ok(None)
        } else {
            finite(M, "body rate", v).map(Some)
        }
    };
    let body_rates = [
        rate(
            AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE,
            d.body_roll_rate,
        )?,
        rate(
            AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE,
            d.body_pitch_rate,
        )?,
        rate(
            AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE,
            d.body_yaw_rate,
        )?,
    ];
    let thrust = if mask.contains(AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE)
    {
        None
    } else {
        Some(finite(M, "thrust", d.thrust)?)
    };
    Ok(AttitudeTarget {
        time_boot_ms: d.time_boot_ms,
        target_system: d.target_system,
        target_component: d.target_component,
        q,
        body_rates,
        thrust,
        type_mask: mask.bits(),
    })
}

/// Message id constants of the contract, for matching on [`Inbound::Other`]
/// and on raw frames.
pub mod ids {
    use super::*;
    /// HEARTBEAT.
    pub const HEARTBEAT: u32 = HEARTBEAT_DATA::ID;
    /// ATTITUDE.
    pub const ATTITUDE: u32 = ATTITUDE_DATA::ID;
    /// LOCAL_POSITION_NED.
    pub const LOCAL_POSITION_NED: u32 = LOCAL_POSITION_NED_DATA::ID;
    /// SET_ATTITUDE_TARGET.
    pub const SET_ATTITUDE_TARGET: u32 = SET_ATTITUDE_TARGET_DATA::ID;
    /// SET_POSITION_TARGET_LOCAL_NED.
    pub const SET_POSITION_TARGET_LOCAL_NED: u32 = SET_POSITION_TARGET_LOCAL_NED_DATA::ID;
    /// VISION_POSITION_ESTIMATE.
    pub const VISION_POSITION_ESTIMATE: u32 = VISION_POSITION_ESTIMATE_DATA::ID;
    /// ODOMETRY.
    pub const ODOMETRY: u32 = ODOMETRY_DATA::ID;
    /// STATUSTEXT.
    pub const STATUSTEXT: u32 = mavlink::dialects::common::STATUSTEXT_DATA::ID;
}

#[cfg(test)]
mod command_ack_tests {
    use super::*;
    use mavlink::dialects::common::COMMAND_ACK_DATA;

    /// COMMAND_ACK decodes with its command, result and requester; it is
    /// for us when addressed to us or to nobody (an autopilot that leaves
    /// the extension fields 0), not when addressed to another component.
    #[test]
    fn a_command_ack_decodes_and_names_its_requester() {
        let header = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        };
        let ack = |target_system, target_component| {
            MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                result: MavResult::MAV_RESULT_DENIED,
                progress: 0,
                result_param2: 0,
                target_system,
                target_component,
            })
        };
        let Ok(Inbound::CommandAck(a)) = decode(&header, &ack(1, 191)) else {
            panic!("not a COMMAND_ACK");
        };
        assert_eq!(a.command, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
        assert_eq!(a.result, MavResult::MAV_RESULT_DENIED);
        assert!(a.is_for((1, 191)));
        let Ok(Inbound::CommandAck(anyone)) = decode(&header, &ack(0, 0)) else {
            panic!("not a COMMAND_ACK");
        };
        assert!(anyone.is_for((1, 191)));
        let Ok(Inbound::CommandAck(other)) = decode(&header, &ack(255, 190)) else {
            panic!("not a COMMAND_ACK");
        };
        assert!(!other.is_for((1, 191)));
    }
}
