//! The supervisor's vocabulary: its states, goals, causes, transitions,
//! refusals, and its settings.

use serde::Serialize;

#[cfg(doc)]
use super::Supervisor;

/// The daemon's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FlightState {
    /// No fresh pose (or no autopilot heartbeat) yet; not streaming.
    WaitingForPose,
    /// Streaming, not engaged: the autopilot flies its own mode; the goal
    /// follows the vehicle's stop point.
    Standby,
    /// Holding a fixed position; streaming.
    Holding,
    /// Flying to a setpoint or along the path; streaming.
    Tracking,
    /// Pose stale or autopilot silent; not streaming; controller reset.
    Failsafe,
}

impl FlightState {
    /// All states, in the order of [`FlightState::index`].
    pub const ALL: [FlightState; 5] = [
        FlightState::WaitingForPose,
        FlightState::Holding,
        FlightState::Tracking,
        FlightState::Failsafe,
        FlightState::Standby,
    ];

    /// Position in [`FlightState::ALL`] (0–4).
    pub fn index(self) -> usize {
        match self {
            FlightState::WaitingForPose => 0,
            FlightState::Holding => 1,
            FlightState::Tracking => 2,
            FlightState::Failsafe => 3,
            FlightState::Standby => 4,
        }
    }

    /// Upper-case name for STATUSTEXT and CSV (`WAITING`, `HOLDING`, …).
    pub fn name(self) -> &'static str {
        match self {
            FlightState::WaitingForPose => "WAITING",
            FlightState::Standby => "STANDBY",
            FlightState::Holding => "HOLDING",
            FlightState::Tracking => "TRACKING",
            FlightState::Failsafe => "FAILSAFE",
        }
    }

    /// True in the states that stream SET_ATTITUDE_TARGET.
    pub fn streams(self) -> bool {
        matches!(
            self,
            FlightState::Standby | FlightState::Holding | FlightState::Tracking
        )
    }

    /// True in the states whose commands the autopilot applies.
    pub fn engaged(self) -> bool {
        matches!(self, FlightState::Holding | FlightState::Tracking)
    }
}

/// What the controller is asked to fly. Positions local NED \[m\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Goal {
    /// Nothing yet (WaitingForPose).
    None,
    /// Hold this position.
    Hold([f64; 3]),
    /// Fly to this setpoint and hold it.
    Setpoint([f64; 3]),
    /// Fly the configured path, then hold its end.
    Path,
    /// Fly the mission uploaded over MAVLink (the control core builds its
    /// reference section by section: `crate::mission::MissionRunner`).
    Mission,
    /// Track a streamed trajectory (the samples are the reference's; see
    /// [`Supervisor::on_stream`]).
    Stream,
    /// Brake from `from` (local NED \[m\]) moving at `velocity` (local NED
    /// [m/s]) to a stop at the braking deceleration, then hold there
    /// (standby and engagement; `dflat_control::reference::Reference::braking`).
    Brake {
        /// Where the braking starts \[m\].
        from: [f64; 3],
        /// Velocity there [m/s].
        velocity: [f64; 3],
    },
}

/// Why the state changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Cause {
    /// Pose fresh and autopilot alive (start, or recovery from failsafe).
    PoseFresh,
    /// `mission.start = "path"`.
    MissionStart,
    /// A position setpoint was accepted.
    Setpoint,
    /// A setpoint near the path's first waypoint started the path.
    PathTrigger,
    /// The path was flown to its end.
    PathFinished,
    /// No pose for longer than the timeout.
    PoseStale,
    /// No autopilot HEARTBEAT for longer than the timeout.
    AutopilotSilent,
    /// The pose jumped (estimator reset): re-anchored, holding there.
    PoseJump,
    /// The model-consistency residual stayed above its threshold.
    ResidualDiverged,
    /// The autopilot applies our commands now (pilot switched to OFFBOARD
    /// / GUIDED_NOGPS): braking to the stop point.
    Engaged,
    /// The autopilot left its offboard mode (pilot override, disarm).
    PilotControl,
    /// Braked after an engagement: the mission resumes.
    Resume,
    /// The controller could not fly: level hover ran out.
    ControlFailed,
    /// MAV_CMD_MISSION_START: the uploaded mission is flown.
    MissionStarted,
    /// The mission's last item was reached.
    MissionFinished,
    /// MAV_CMD_DO_PAUSE_CONTINUE 0: stopping and holding.
    Paused,
    /// MAV_CMD_DO_PAUSE_CONTINUE 1: the goal before the pause goes on.
    Continued,
    /// A streamed trajectory sample was accepted.
    Stream,
    /// The stream went silent: stopping smoothly, then holding.
    StreamTimeout,
    /// The daemon found the autopilot already applying its commands at
    /// start (a restart mid-flight): brake and hold where the vehicle is,
    /// until a goal is given after the start.
    FoundEngaged,
    /// The vehicle is faster than `safety.max_speed_mps`: braking to a stop.
    Overspeed,
    /// The daemon is stopping (SIGTERM / SIGINT): braking to a stop.
    Shutdown,
    /// The daemon is stopping: braked (or out of time), level, then the
    /// stream stops.
    ShutdownLevel,
}

impl Cause {
    fn words(self) -> &'static str {
        match self {
            Cause::PoseFresh => "pose ok",
            Cause::MissionStart => "path start",
            Cause::Setpoint => "setpoint",
            Cause::PathTrigger => "path start",
            Cause::PathFinished => "path done",
            Cause::PoseStale => "pose stale, stream off",
            Cause::AutopilotSilent => "autopilot lost, stream off",
            Cause::PoseJump => "pose jump, re-anchored",
            Cause::ResidualDiverged => "model residual, stream off",
            Cause::Engaged => "engaged, braking",
            Cause::PilotControl => "pilot has control",
            Cause::Resume => "braked, resuming",
            Cause::ControlFailed => "control failed, stream off",
            Cause::MissionStarted => "mission start",
            Cause::MissionFinished => "mission done",
            Cause::Paused => "paused",
            Cause::Continued => "continue",
            Cause::Stream => "trajectory stream",
            Cause::StreamTimeout => "stream lost, stopping",
            Cause::FoundEngaged => "engaged at start, holding",
            Cause::Overspeed => "overspeed, braking",
            Cause::Shutdown => "stopping, braking",
            Cause::ShutdownLevel => "stopping, level, stream off",
        }
    }
}

/// A state change, for STATUSTEXT and the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// State before.
    pub from: FlightState,
    /// State after.
    pub to: FlightState,
    /// Why.
    pub cause: Cause,
    /// When \[s\], the supervisor's clock.
    pub at: f64,
}

impl Transition {
    /// STATUSTEXT text (≤ 50 bytes), e.g. `dflat: FAILSAFE (pose stale, stream off)`.
    pub fn text(&self) -> String {
        format!("dflat: {} ({})", self.to.name(), self.cause.words())
    }

    /// True for transitions into failsafe, and for a brake the envelope
    /// forces (overspeed): sent with a higher severity.
    pub fn is_failsafe(&self) -> bool {
        self.to == FlightState::Failsafe || self.cause == Cause::Overspeed
    }
}

/// Why a setpoint was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refusal {
    /// A coordinate is NaN or infinite.
    NonFinite,
    /// Outside the fence (`mission.geofence`, `mission.geofence_down_m`).
    Geofence {
        /// The refused position \[m\].
        position: [f64; 3],
    },
    /// A stream sample faster than `safety.max_speed_mps`.
    Speed {
        /// The sample's speed [m/s].
        speed: f64,
    },
    /// A stream sample whose horizontal acceleration needs more tilt than
    /// `vehicle.max_tilt_deg`.
    Acceleration {
        /// The sample's horizontal acceleration \[m/s²\].
        acceleration: f64,
    },
    /// The daemon is stopping (SIGTERM / SIGINT): braking, no new goal.
    Stopping,
    /// No control (waiting for pose, or failsafe).
    NotInControl(FlightState),
    /// A stream sample further than `stream.max_jump_m` from where the
    /// reference (or the vehicle) is.
    StreamJump {
        /// The distance \[m\].
        distance: f64,
    },
}

impl Refusal {
    /// The kind of refusal, for rate-limiting each kind on its own (a fence
    /// refusal said does not hide a speed refusal after it).
    pub fn kind(&self) -> usize {
        match self {
            Refusal::NonFinite => 0,
            Refusal::Geofence { .. } => 1,
            Refusal::NotInControl(_) => 2,
            Refusal::StreamJump { .. } => 3,
            Refusal::Speed { .. } => 4,
            Refusal::Acceleration { .. } => 5,
            Refusal::Stopping => 6,
        }
    }

    /// Number of [`Refusal::kind`]s.
    pub const KINDS: usize = 7;

    /// STATUSTEXT text (≤ 50 bytes).
    pub fn text(&self) -> String {
        match self {
            Refusal::NonFinite => "dflat: setpoint refused: not finite".into(),
            Refusal::Geofence { position: p } => {
                format!(
                    "dflat: setpoint refused: fence {:.0},{:.0},{:.0}",
                    p[0], p[1], p[2]
                )
            }
            Refusal::NotInControl(s) => format!("dflat: setpoint refused: {}", s.name()),
            Refusal::Speed { speed } => {
                format!("dflat: stream refused: speed {speed:.0} m/s > limit")
            }
            Refusal::Acceleration { acceleration } => {
                format!("dflat: stream refused: accel {acceleration:.0} > tilt")
            }
            Refusal::Stopping => "dflat: setpoint refused: stopping".into(),
            Refusal::StreamJump { distance } => {
                format!("dflat: stream refused: jumps {distance:.1} m")
            }
        }
    }
}

/// Result of [`Supervisor::on_setpoint`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SetpointOutcome {
    /// Accepted; the goal changed. `transition` when the state changed too.
    Accepted {
        /// The new goal.
        goal: Goal,
        /// State change (Holding → Tracking), if any.
        transition: Option<Transition>,
    },
    /// The same setpoint as the last accepted one (a streaming ground
    /// station): nothing changes.
    Unchanged,
    /// Refused: say so with STATUSTEXT.
    Refused(Refusal),
}

/// What the shell does at a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickDecision {
    /// Run the controller and send SET_ATTITUDE_TARGET.
    pub stream: bool,
    /// The state change at this tick, if any.
    pub transition: Option<Transition>,
}

/// What the pose and heartbeat arrivals say at a tick
/// ([`Supervisor::links`]): the failsafe machine's stale-pose and
/// silent-autopilot causes, and the start's condition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Links {
    /// A pose arrived within the pose timeout.
    pub pose_fresh: bool,
    /// An autopilot HEARTBEAT arrived within its timeout.
    pub autopilot_alive: bool,
}

/// Parameters of the [`Supervisor`].
#[derive(Debug, Clone, PartialEq)]
pub struct SupervisorConfig {
    /// Pose older than this \[s\] is stale.
    pub pose_timeout: f64,
    /// No autopilot HEARTBEAT for this long \[s\] means it is silent.
    pub autopilot_timeout: f64,
    /// The flight envelope: the fence every goal must lie in
    /// ([`crate::envelope`]).
    pub envelope: crate::envelope::Envelope,
    /// The configured path's first and last waypoints, if a path is configured.
    pub path_ends: Option<([f64; 3], [f64; 3])>,
    /// A setpoint within this distance \[m\] of the path's first waypoint
    /// starts the path (0 = never).
    pub path_trigger_radius: f64,
    /// Start the path as soon as pose is fresh (`mission.start = "path"`).
    pub start_path: bool,
    /// Fly the (closed) path again when it finishes (`mission.repeat`).
    pub repeat_path: bool,
    /// Every streamed command counts as applied (`link.engagement =
    /// "always"`): no standby.
    pub always_engaged: bool,
    /// After braking, resume the goal flown before (`mission.on_engage =
    /// "resume"`); else hold.
    pub resume_on_engage: bool,
    /// Braking deceleration at engagement \[m/s²\] (> 0).
    pub brake_acceleration: f64,
}
