//! Builders for every message dflat (daemon or SITL) sends.
//!
//! Each builder sets every field explicitly: the mavlink crate's bitflag
//! `Default` is the *first flag* (e.g. `MavModeFlag::default()` is
//! SAFETY_ARMED), never "empty". Builders that take numbers refuse
//! non-finite input with [`LinkError::NonFinite`], so no NaN leaves through
//! them (the only exception is the MAVLink-specified "unknown" marker, NaN
//! in the first covariance element, see [`vision_position_estimate`]).

use mavlink::dialects::common::{
    ATTITUDE_DATA, AttitudeTargetTypemask, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot,
    MavEstimatorType, MavFrame, MavMessage, MavModeFlag, MavSeverity, MavState, MavType,
    ODOMETRY_DATA, SET_ATTITUDE_TARGET_DATA, STATUSTEXT_DATA, VISION_POSITION_ESTIMATE_DATA,
};
use mavlink::types::CharArray;

use crate::LinkError;
use crate::math::quaternion_from_euler;

/// MAVLink protocol version byte carried in HEARTBEAT (`mavlink_version`).
pub const HEARTBEAT_MAVLINK_VERSION: u8 = 3;

/// Longest STATUSTEXT text in bytes (one chunk).
pub const STATUSTEXT_MAX_LEN: usize = 50;

/// Addressee of a command: `target_system` / `target_component`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Target {
    /// Target system id (the vehicle; default 1).
    pub system: u8,
    /// Target component id (the autopilot; default 1).
    pub component: u8,
}

impl Default for Target {
    fn default() -> Self {
        Self {
            system: 1,
            component: 1,
        }
    }
}

/// The daemon's health, reported as HEARTBEAT `system_status`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DaemonStatus {
    /// Starting up (MAV_STATE_BOOT).
    Boot,
    /// Ready, not commanding (MAV_STATE_STANDBY).
    Standby,
    /// Sending attitude commands (MAV_STATE_ACTIVE).
    Active,
    /// Failsafe engaged, still in control (MAV_STATE_CRITICAL).
    Critical,
    /// Lost control authority or input (MAV_STATE_EMERGENCY).
    Emergency,
    /// Shutting down (MAV_STATE_POWEROFF).
    Poweroff,
}

impl DaemonStatus {
    /// The MAV_STATE value sent for this status.
    pub fn mav_state(self) -> MavState {
        match self {
            DaemonStatus::Boot => MavState::MAV_STATE_BOOT,
            DaemonStatus::Standby => MavState::MAV_STATE_STANDBY,
            DaemonStatus::Active => MavState::MAV_STATE_ACTIVE,
            DaemonStatus::Critical => MavState::MAV_STATE_CRITICAL,
            DaemonStatus::Emergency => MavState::MAV_STATE_EMERGENCY,
            DaemonStatus::Poweroff => MavState::MAV_STATE_POWEROFF,
        }
    }
}

/// An attitude command: ZYX Euler angles of body FRD w.r.t. local NED, and thrust.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeCommand {
    /// Roll φ \[rad\].
    pub roll: f64,
    /// Pitch θ \[rad\] (θ < 0 is nose down: accelerates north at ψ = 0).
    pub pitch: f64,
    /// Yaw ψ \[rad\].
    pub yaw: f64,
    /// Normalized collective thrust in [0, 1] (see [`crate::ThrustMapping`]).
    pub thrust: f64,
}

/// A message to send, as a value (e.g. for a channel to the link task).
/// [`Outbound::to_message`] runs the matching builder.
#[derive(Debug, Clone, PartialEq)]
pub enum Outbound {
    /// Daemon HEARTBEAT, see [`heartbeat_onboard`].
    OnboardHeartbeat(DaemonStatus),
    /// Autopilot (SITL) HEARTBEAT, see [`heartbeat_autopilot`].
    AutopilotHeartbeat {
        /// MAV_AUTOPILOT_PX4 or MAV_AUTOPILOT_GENERIC, typically.
        autopilot: MavAutopilot,
        /// Armed state.
        armed: bool,
        /// Autopilot-specific mode.
        custom_mode: u32,
        /// System status.
        system_status: MavState,
    },
    /// SET_ATTITUDE_TARGET, see [`set_attitude_target`].
    AttitudeTarget {
        /// Addressee.
        target: Target,
        /// Sender time since boot \[ms\].
        time_boot_ms: u32,
        /// The command.
        command: AttitudeCommand,
    },
    /// STATUSTEXT, see [`statustext`].
    StatusText {
        /// Severity.
        severity: MavSeverity,
        /// Text (truncated to 50 bytes on a char boundary when built).
        text: String,
    },
    /// LOCAL_POSITION_NED, see [`local_position_ned`].
    LocalPositionNed {
        /// Time since boot \[ms\].
        time_boot_ms: u32,
        /// Position NED \[m\].
        position: [f64; 3],
        /// Velocity NED \[m/s\].
        velocity: [f64; 3],
    },
    /// ATTITUDE, see [`attitude`].
    Attitude {
        /// Time since boot \[ms\].
        time_boot_ms: u32,
        /// [roll, pitch, yaw] ZYX \[rad\].
        euler: [f64; 3],
        /// Body rates [p, q, r] \[rad/s\].
        rates: [f64; 3],
    },
    /// VISION_POSITION_ESTIMATE, see [`vision_position_estimate`].
    VisionPositionEstimate {
        /// Timestamp \[µs\].
        time_usec: u64,
        /// Position NED \[m\].
        position: [f64; 3],
        /// [roll, pitch, yaw] ZYX \[rad\].
        euler: [f64; 3],
        /// Estimator reset counter.
        reset_counter: u8,
    },
}

impl Outbound {
    /// Builds the MAVLink message.
    pub fn to_message(&self) -> Result<MavMessage, LinkError> {
        match self {
            Outbound::OnboardHeartbeat(status) => Ok(heartbeat_onboard(*status)),
            Outbound::AutopilotHeartbeat {
                autopilot,
                armed,
                custom_mode,
                system_status,
            } => Ok(heartbeat_autopilot(
                *autopilot,
                *armed,
                *custom_mode,
                *system_status,
            )),
            Outbound::AttitudeTarget {
                target,
                time_boot_ms,
                command,
            } => set_attitude_target(*target, *time_boot_ms, command),
            Outbound::StatusText { severity, text } => Ok(statustext(*severity, text)),
            Outbound::LocalPositionNed {
                time_boot_ms,
                position,
                velocity,
            } => local_position_ned(*time_boot_ms, *position, *velocity),
            Outbound::Attitude {
                time_boot_ms,
                euler,
                rates,
            } => attitude(*time_boot_ms, *euler, *rates),
            Outbound::VisionPositionEstimate {
                time_usec,
                position,
                euler,
                reset_counter,
            } => vision_position_estimate(*time_usec, *position, *euler, *reset_counter, None),
        }
    }
}

fn check(message: &'static str, field: &'static str, values: &[f64]) -> Result<(), LinkError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(LinkError::NonFinite { message, field })
    }
}

/// f64 → f32 for a value already checked finite; saturates beyond f32 range
/// instead of producing ±inf.
fn f32_of(v: f64) -> f32 {
    v.clamp(f64::from(f32::MIN), f64::from(f32::MAX)) as f32
}

fn f32x3(v: [f64; 3]) -> [f32; 3] {
    [f32_of(v[0]), f32_of(v[1]), f32_of(v[2])]
}

/// The daemon's HEARTBEAT: MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID,
/// `base_mode` empty, `custom_mode` 0, `system_status` from `status`.
pub fn heartbeat_onboard(status: DaemonStatus) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: status.mav_state(),
        mavlink_version: HEARTBEAT_MAVLINK_VERSION,
    })
}

/// An autopilot's HEARTBEAT (for the SITL): MAV_TYPE_QUADROTOR, the given
/// autopilot (MAV_AUTOPILOT_PX4 / MAV_AUTOPILOT_GENERIC), `base_mode` =
/// CUSTOM_MODE_ENABLED plus SAFETY_ARMED when `armed`.
pub fn heartbeat_autopilot(
    autopilot: MavAutopilot,
    armed: bool,
    custom_mode: u32,
    system_status: MavState,
) -> MavMessage {
    let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
    if armed {
        base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot,
        base_mode,
        system_status,
        mavlink_version: HEARTBEAT_MAVLINK_VERSION,
    })
}

/// The type_mask of every SET_ATTITUDE_TARGET dflat sends: ignore body roll,
/// pitch and yaw rates (1|2|4 = 7); attitude and thrust are used.
pub const ATTITUDE_TARGET_MASK: AttitudeTargetTypemask =
    AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
        .union(AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE)
        .union(AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE);

/// SET_ATTITUDE_TARGET (82): quaternion from the ZYX angles (body FRD → NED),
/// `type_mask` = [`ATTITUDE_TARGET_MASK`], body rates 0, `thrust_body` 0.
///
/// Refuses non-finite angles or thrust ([`LinkError::NonFinite`]) and thrust
/// outside [0, 1] ([`LinkError::OutOfRange`]).
pub fn set_attitude_target(
    target: Target,
    time_boot_ms: u32,
    command: &AttitudeCommand,
) -> Result<MavMessage, LinkError> {
    const M: &str = "SET_ATTITUDE_TARGET";
    check(M, "attitude", &[command.roll, command.pitch, command.yaw])?;
    check(M, "thrust", &[command.thrust])?;
    if !(0.0..=1.0).contains(&command.thrust) {
        return Err(LinkError::OutOfRange {
            name: "thrust",
            value: command.thrust,
            allowed: "[0, 1]",
        });
    }
    let q = quaternion_from_euler(command.roll, command.pitch, command.yaw);
    Ok(MavMessage::SET_ATTITUDE_TARGET(SET_ATTITUDE_TARGET_DATA {
        time_boot_ms,
        q: [q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32],
        body_roll_rate: 0.0,
        body_pitch_rate: 0.0,
        body_yaw_rate: 0.0,
        thrust: command.thrust as f32,
        target_system: target.system,
        target_component: target.component,
        type_mask: ATTITUDE_TARGET_MASK,
        thrust_body: [0.0; 3],
    }))
}

/// `text` cut to at most `max_bytes` bytes on a char boundary, and at the
/// first NUL (which would end the string for receivers).
pub fn truncate_text(text: &str, max_bytes: usize) -> &str {
    let text = text.split('\0').next().unwrap_or("");
    if text.len() <= max_bytes {
        return text;
    }
    let mut end = max_bytes;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// STATUSTEXT (253), one chunk (`id` 0): `text` truncated to 50 bytes on a
/// UTF-8 char boundary (see [`truncate_text`]).
pub fn statustext(severity: MavSeverity, text: &str) -> MavMessage {
    let text = truncate_text(text, STATUSTEXT_MAX_LEN);
    MavMessage::STATUSTEXT(STATUSTEXT_DATA {
        severity,
        text: CharArray::from(text),
        id: 0,
        chunk_seq: 0,
    })
}

/// LOCAL_POSITION_NED (32) for the SITL: position \[m\] and velocity \[m/s\] in
/// local NED. Refuses non-finite input.
pub fn local_position_ned(
    time_boot_ms: u32,
    position: [f64; 3],
    velocity: [f64; 3],
) -> Result<MavMessage, LinkError> {
    const M: &str = "LOCAL_POSITION_NED";
    check(M, "position", &position)?;
    check(M, "velocity", &velocity)?;
    let [x, y, z] = f32x3(position);
    let [vx, vy, vz] = f32x3(velocity);
    Ok(MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        time_boot_ms,
        x,
        y,
        z,
        vx,
        vy,
        vz,
    }))
}

/// ATTITUDE (30) for the SITL: ZYX `[roll, pitch, yaw]` \[rad\], body rates
/// `[p, q, r]` \[rad/s\]. Refuses non-finite input.
pub fn attitude(
    time_boot_ms: u32,
    euler: [f64; 3],
    rates: [f64; 3],
) -> Result<MavMessage, LinkError> {
    const M: &str = "ATTITUDE";
    check(M, "attitude", &euler)?;
    check(M, "rates", &rates)?;
    let [roll, pitch, yaw] = f32x3(euler);
    let [rollspeed, pitchspeed, yawspeed] = f32x3(rates);
    Ok(MavMessage::ATTITUDE(ATTITUDE_DATA {
        time_boot_ms,
        roll,
        pitch,
        yaw,
        rollspeed,
        pitchspeed,
        yawspeed,
    }))
}

/// The MAVLink "covariance unknown" marker: NaN in the first element.
fn unknown_covariance() -> [f32; 21] {
    let mut c = [0.0; 21];
    c[0] = f32::NAN;
    c
}

/// VISION_POSITION_ESTIMATE (102): timestamp \[µs\], position NED \[m\], ZYX
/// `[roll, pitch, yaw]` \[rad\], reset counter. `covariance` is the upper
/// triangle of the 6×6 pose covariance; `None` sends MAVLink's "unknown"
/// marker (NaN first element), the one NaN these builders ever emit.
pub fn vision_position_estimate(
    time_usec: u64,
    position: [f64; 3],
    euler: [f64; 3],
    reset_counter: u8,
    covariance: Option<[f32; 21]>,
) -> Result<MavMessage, LinkError> {
    const M: &str = "VISION_POSITION_ESTIMATE";
    check(M, "position", &position)?;
    check(M, "attitude", &euler)?;
    let [x, y, z] = f32x3(position);
    let [roll, pitch, yaw] = f32x3(euler);
    Ok(MavMessage::VISION_POSITION_ESTIMATE(
        VISION_POSITION_ESTIMATE_DATA {
            usec: time_usec,
            x,
            y,
            z,
            roll,
            pitch,
            yaw,
            covariance: covariance.unwrap_or_else(unknown_covariance),
            reset_counter,
        },
    ))
}

/// ODOMETRY (331) for the SITL: `frame_id` MAV_FRAME_LOCAL_NED, `child_frame_id`
/// MAV_FRAME_BODY_FRD; position NED \[m\], ZYX angles \[rad\], velocity in body
/// FRD \[m/s\], body rates \[rad/s\], reset counter, estimator VISION.
/// Covariances are sent as "unknown" (NaN first element). Refuses
/// non-finite input.
pub fn odometry(
    time_usec: u64,
    position: [f64; 3],
    euler: [f64; 3],
    velocity_body: [f64; 3],
    rates: [f64; 3],
    reset_counter: u8,
) -> Result<MavMessage, LinkError> {
    const M: &str = "ODOMETRY";
    check(M, "position", &position)?;
    check(M, "attitude", &euler)?;
    check(M, "velocity", &velocity_body)?;
    check(M, "rates", &rates)?;
    let q = quaternion_from_euler(euler[0], euler[1], euler[2]);
    let [x, y, z] = f32x3(position);
    let [vx, vy, vz] = f32x3(velocity_body);
    let [rollspeed, pitchspeed, yawspeed] = f32x3(rates);
    Ok(MavMessage::ODOMETRY(ODOMETRY_DATA {
        time_usec,
        x,
        y,
        z,
        q: [q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32],
        vx,
        vy,
        vz,
        rollspeed,
        pitchspeed,
        yawspeed,
        pose_covariance: unknown_covariance(),
        velocity_covariance: unknown_covariance(),
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: MavFrame::MAV_FRAME_BODY_FRD,
        reset_counter,
        estimator_type: MavEstimatorType::MAV_ESTIMATOR_TYPE_VISION,
        quality: 0,
    }))
}
