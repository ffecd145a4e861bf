//! What enters the step: events from received messages, and the pieces of
//! the receive path built from the configuration (source filter, pose
//! source, supervisor parameters) — shared by the daemon and the fuzzer.

use dflat_link::dialect::MavCmd;
use dflat_link::{AutopilotFamily, AutopilotMode, Inbound, PoseSource, SourceFilter};

use crate::config::{Config, LinkConfig, PoseSourceKind};
use crate::supervisor::SupervisorConfig;

/// An inbound fact for the control thread, stamped with its arrival time
/// \[s\] since the daemon's epoch (this computer's monotonic clock).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A pose from the configured pose source.
    Pose {
        /// Arrival \[s\].
        arrival: f64,
        /// The source's timestamp \[s\] on its own clock (`None`: 0 / none).
        source_time: Option<f64>,
        /// Position, local NED \[m\].
        position: [f64; 3],
        /// Yaw from the pose message \[rad\], if it has one.
        yaw: Option<f64>,
        /// The estimator reset counter (ODOMETRY, VISION_POSITION_ESTIMATE).
        reset_counter: Option<u8>,
    },
    /// ATTITUDE: the autopilot's attitude estimate (ZYX Euler, FRD body in
    /// NED).
    Attitude {
        /// Arrival \[s\].
        arrival: f64,
        /// Roll φ \[rad\].
        roll: f64,
        /// Pitch θ \[rad\].
        pitch: f64,
        /// Yaw ψ \[rad\].
        yaw: f64,
    },
    /// The autopilot's HEARTBEAT.
    Heartbeat {
        /// Arrival \[s\].
        arrival: f64,
        /// Its mode and arming state, the family read from its `autopilot`
        /// field (`link.autopilot` may override it: [`crate::tick`]).
        mode: AutopilotMode,
    },
    /// PARAM_VALUE from the autopilot.
    Param {
        /// Arrival \[s\].
        arrival: f64,
        /// The parameter's name.
        name: ParamName,
        /// Its value (finite).
        value: f64,
    },
    /// COMMAND_ACK from the autopilot to MAV_CMD_SET_MESSAGE_INTERVAL,
    /// addressed to this daemon (or to nobody).
    IntervalAck {
        /// Arrival \[s\].
        arrival: f64,
        /// The autopilot's answer.
        result: dflat_link::dialect::MavResult,
    },
    /// An accepted position setpoint, or (velocity and/or acceleration
    /// given) a sample of a streamed trajectory.
    Setpoint {
        /// Arrival \[s\].
        arrival: f64,
        /// Position, local NED \[m\].
        position: [f64; 3],
        /// Yaw \[rad\], when the setpoint sets one.
        yaw: Option<f64>,
        /// Yaw rate \[rad/s\], when the setpoint sets one.
        yaw_rate: Option<f64>,
        /// The sender's `time_boot_ms` \[s\] (`None`: 0).
        source_time: Option<f64>,
        /// Velocity, local NED [m/s], when given.
        velocity: Option<[f64; 3]>,
        /// Acceleration, local NED [m/s²], when given.
        acceleration: Option<[f64; 3]>,
    },
    /// A mission command the receive task accepted (COMMAND_ACK sent).
    Mission {
        /// Arrival \[s\].
        arrival: f64,
        /// What to do.
        action: super::MissionAction,
    },
}

impl Event {
    /// Arrival \[s\] since the daemon's epoch.
    pub fn arrival(&self) -> f64 {
        match self {
            Event::Pose { arrival, .. }
            | Event::Attitude { arrival, .. }
            | Event::Heartbeat { arrival, .. }
            | Event::Param { arrival, .. }
            | Event::IntervalAck { arrival, .. }
            | Event::Setpoint { arrival, .. }
            | Event::Mission { arrival, .. } => *arrival,
        }
    }

    /// The same event arriving at `t` \[s since the daemon's epoch\] (a
    /// replay maps a log's stamps to the daemon's clock this way).
    pub fn arriving_at(mut self, t: f64) -> Self {
        match &mut self {
            Event::Pose { arrival, .. }
            | Event::Attitude { arrival, .. }
            | Event::Heartbeat { arrival, .. }
            | Event::Param { arrival, .. }
            | Event::IntervalAck { arrival, .. }
            | Event::Setpoint { arrival, .. }
            | Event::Mission { arrival, .. } => *arrival = t,
        }
        self
    }
}

/// A MAVLink parameter name (at most 16 bytes), kept inline so that
/// [`Event`] stays `Copy`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamName {
    bytes: [u8; 16],
    len: u8,
}

impl ParamName {
    /// The name, cut to 16 bytes (at a character boundary).
    pub fn new(name: &str) -> Self {
        let mut end = name.len().min(16);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0u8; 16];
        bytes[..end].copy_from_slice(&name.as_bytes()[..end]);
        Self {
            bytes,
            len: end as u8,
        }
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        std::str::from_utf8(&self.bytes[..usize::from(self.len)]).unwrap_or("")
    }
}

/// The event a decoded, accepted message is for the control thread (`None`:
/// not one it acts on). `arrival` \[s\] since the daemon's epoch.
pub fn event_from(inbound: &Inbound, pose_source: PoseSource, arrival: f64) -> Option<Event> {
    match inbound {
        Inbound::Pose(p) if p.source == pose_source => Some(Event::Pose {
            arrival,
            source_time: (p.time_usec > 0).then_some(p.time_usec as f64 * 1e-6),
            position: p.position,
            yaw: p.yaw,
            reset_counter: p.reset_counter,
        }),
        Inbound::Attitude(a) => Some(Event::Attitude {
            arrival,
            roll: a.roll,
            pitch: a.pitch,
            yaw: a.yaw,
        }),
        Inbound::Heartbeat(h) => Some(Event::Heartbeat {
            arrival,
            mode: AutopilotMode {
                family: AutopilotFamily::from_mav_autopilot(h.autopilot),
                custom_mode: h.custom_mode,
                armed: h.armed,
            },
        }),
        Inbound::ParamValue(p) => Some(Event::Param {
            arrival,
            name: ParamName::new(&p.name),
            value: p.value,
        }),
        Inbound::CommandAck(a) if a.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
            Some(Event::IntervalAck {
                arrival,
                result: a.result,
            })
        }
        Inbound::PositionSetpoint(s) => Some(Event::Setpoint {
            arrival,
            position: s.position,
            yaw: s.yaw,
            yaw_rate: s.yaw_rate,
            source_time: (s.time_boot_ms > 0).then(|| f64::from(s.time_boot_ms) * 1e-3),
            velocity: s.velocity,
            acceleration: s.acceleration,
        }),
        _ => None,
    }
}

/// The receive path's source filter from `[link]`: the autopilot and the
/// ground stations by id, setpoints from every other component of the
/// vehicle with `link.vehicle_setpoints`, pose from `link.pose_components`.
pub fn source_filter(link: &LinkConfig) -> SourceFilter {
    let mut filter = SourceFilter {
        vehicle_system_id: link.system_id,
        autopilot_component_id: link.autopilot_component,
        own_component_id: link.component_id,
        gcs_system_ids: link.ground_station_ids(),
        setpoint_components: Vec::new(),
        pose_components: link.pose_components.clone(),
    };
    if link.vehicle_setpoints {
        filter.setpoint_components = (1..=255u8).filter(|c| *c != link.component_id).collect();
    }
    filter
}

/// The pose message `link.pose_source` names.
pub fn pose_source(kind: PoseSourceKind) -> PoseSource {
    match kind {
        PoseSourceKind::LocalPositionNed => PoseSource::LocalPositionNed,
        PoseSourceKind::Odometry => PoseSource::Odometry,
        PoseSourceKind::VisionPositionEstimate => PoseSource::VisionPositionEstimate,
    }
}

/// The supervisor's parameters from the configuration.
pub fn supervisor_config(cfg: &Config) -> SupervisorConfig {
    let m = &cfg.mission;
    let path_ends = match (m.path.first(), m.path.last()) {
        (Some(a), Some(b)) if m.path.len() >= 2 => Some((*a, *b)),
        _ => None,
    };
    SupervisorConfig {
        pose_timeout: cfg.safety.pose_timeout_ms / 1000.0,
        autopilot_timeout: cfg.safety.autopilot_timeout_ms / 1000.0,
        envelope: crate::envelope::Envelope::from_config(cfg),
        path_ends,
        path_trigger_radius: m.path_trigger_radius,
        start_path: m.start == crate::config::MissionStart::Path,
        repeat_path: m.repeat,
        always_engaged: cfg.link.engagement == crate::config::Engagement::Always,
        resume_on_engage: m.on_engage == crate::config::OnEngage::Resume,
        brake_acceleration: brake_acceleration(cfg),
    }
}

/// Braking deceleration at engagement \[m/s²\]: `mission.brake_fraction`
/// of the acceleration at the plan's tilt bound
/// (`controller.constraint_tilt_deg`, else `vehicle.max_tilt_deg`).
pub fn brake_acceleration(cfg: &Config) -> f64 {
    let tilt = if cfg.controller.constraint_tilt_deg > 0.0 {
        cfg.controller
            .constraint_tilt_deg
            .min(cfg.vehicle.max_tilt_deg)
    } else {
        cfg.vehicle.max_tilt_deg
    };
    cfg.mission.brake_fraction * cfg.vehicle.gravity * tilt.to_radians().tan()
}
