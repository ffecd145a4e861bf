//! The daemon's flight state machine, as a pure struct.
//!
//! ```text
//!                 fresh pose + autopilot alive
//! WaitingForPose ─────────────────────────────► Standby ◄─────────────┐
//!                                                 │  pilot switches     │ pilot takes
//!                                                 │  to OFFBOARD /      │ over (mode
//!                                                 ▼  GUIDED_NOGPS       │ change)
//!                                   Holding (braking to the stop point) ─┤
//!                    braked: resume │  ▲ path finished                   │
//!                  path / setpoint  ▼  │                                 │
//!                                   Tracking ────────────────────────────┘
//!
//!        stale pose / silent autopilot                 fresh pose + autopilot alive
//! Standby, Holding, Tracking ──────────────► Failsafe ─────────────────► Standby / Holding
//! ```
//!
//! **Streaming and engaged.** Standby, Holding and Tracking stream
//! SET_ATTITUDE_TARGET; only Holding and Tracking are *engaged*: the
//! autopilot applies the commands (its HEARTBEAT says armed and PX4
//! OFFBOARD / ArduPilot GUIDED_NOGPS or GUIDED, or `link.engagement =
//! "always"`). In Standby the autopilot flies its own mode (the pilot in
//! POSCTL / LOITER); the stream goes on because the autopilot needs it to
//! allow the switch, and what it carries would be harmless if applied:
//! the goal is the point where the vehicle would stop braking, following
//! the vehicle ([`Supervisor::set_motion`]).
//!
//! **Engagement is bumpless.** At the switch the goal freezes at the stop
//! point of the vehicle's motion then (braking at `brake_acceleration`,
//! never back to an older hold point); once braked (slower than
//! [`BRAKED_SPEED`], or after the braking time plus [`BRAKE_SETTLE`]) the
//! mission resumes (`mission.on_engage`): the goal flown before the
//! override — the path from its closest point, the setpoint — or holding.
//! A setpoint accepted in standby is flown after braking either way.
//!
//! Time enters as arguments: seconds on the daemon's monotonic clock (any
//! origin; only differences matter). Pose and heartbeat times are *arrival*
//! times on the companion computer's clock, so staleness does not depend on
//! the sender's clock (vision timestamps are not used yet).
//!
//! In `Failsafe` and `WaitingForPose` the controller's attitude targets are
//! not streamed: a frozen stream would keep PX4 in offboard mode, while
//! silence lets the autopilot's own failsafe take over. A failsafe entered
//! while engaged first streams level hover for at most
//! `safety.level_hover_max_ms` (the control core's `tick/failsafe_level.rs`),
//! so that the autopilot holds a level command, not the last tilt, until
//! its offboard-loss timeout.

use serde::Serialize;

use crate::motion::Motion;

/// Slower than this \[m/s\] after an engagement counts as braked.
pub const BRAKED_SPEED: f64 = 0.3;
/// Braking is over at the latest this long \[s\] after the time the
/// braking deceleration needs.
pub const BRAKE_SETTLE: f64 = 2.0;

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

    /// True for transitions into failsafe (sent with a higher severity).
    pub fn is_failsafe(&self) -> bool {
        self.to == FlightState::Failsafe
    }
}

/// Why a setpoint was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refusal {
    /// A coordinate is NaN or infinite.
    NonFinite,
    /// Outside the geofence half-widths around the origin.
    Geofence {
        /// The refused position \[m\].
        position: [f64; 3],
    },
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
    /// Reset the controller before anything else (entering failsafe).
    pub reset_controller: bool,
    /// The state change at this tick, if any.
    pub transition: Option<Transition>,
}

/// Parameters of the [`Supervisor`].
#[derive(Debug, Clone, PartialEq)]
pub struct SupervisorConfig {
    /// Pose older than this \[s\] is stale.
    pub pose_timeout: f64,
    /// No autopilot HEARTBEAT for this long \[s\] means it is silent.
    pub autopilot_timeout: f64,
    /// Geofence half-widths around the origin \[m\] (x, y, z).
    pub geofence: [f64; 3],
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

/// Braking after an engagement.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Braking {
    /// Over at the latest at this time \[s\].
    until: f64,
}

/// The flight state machine. Feed it events with their times; ask it at
/// each tick whether to stream.
#[derive(Debug, Clone)]
pub struct Supervisor {
    cfg: SupervisorConfig,
    state: FlightState,
    goal: Goal,
    generation: u64,
    last_pose: Option<(f64, [f64; 3])>,
    last_heartbeat: Option<f64>,
    last_setpoint: Option<[f64; 3]>,
    entered_at: Option<f64>,
    time_in: [f64; 5],
    transitions: u64,
    /// No recovery from a forced failsafe before this time.
    latched_until: Option<f64>,
    /// The autopilot applies our commands (its last HEARTBEAT).
    autopilot_engaged: bool,
    /// The vehicle's motion (for the stop point).
    motion: Option<Motion>,
    /// Braking after an engagement.
    braking: Option<Braking>,
    /// What to fly once braked (the mission goal across an override).
    pending: Goal,
    /// The path goal is a resumption: fly it from the vehicle's closest
    /// point of the whole path, not from its start.
    path_resumed: bool,
    /// Engagements and disengagements so far.
    engagements: u64,
    disengagements: u64,
    /// Paused (MAV_CMD_DO_PAUSE_CONTINUE): `pending` goes on at a continue.
    paused: bool,
}

impl Supervisor {
    /// A supervisor in `WaitingForPose`.
    pub fn new(cfg: SupervisorConfig) -> Self {
        Self {
            cfg,
            state: FlightState::WaitingForPose,
            goal: Goal::None,
            generation: 0,
            last_pose: None,
            last_heartbeat: None,
            last_setpoint: None,
            entered_at: None,
            time_in: [0.0; 5],
            transitions: 0,
            latched_until: None,
            autopilot_engaged: false,
            motion: None,
            braking: None,
            pending: Goal::None,
            path_resumed: false,
            engagements: 0,
            disengagements: 0,
            paused: false,
        }
    }

    /// The autopilot's mode at `t`: `applies` when it applies our commands
    /// (armed, offboard mode). The state follows at the next tick.
    pub fn on_mode(&mut self, applies: bool) {
        self.autopilot_engaged = applies;
    }

    /// True when the autopilot applies our commands (as last reported, or
    /// always with `always_engaged`).
    pub fn autopilot_engaged(&self) -> bool {
        self.cfg.always_engaged || self.autopilot_engaged
    }

    /// The vehicle's motion now (from the pose stream), for the standby
    /// goal and the stop point at engagement; `None` forgets it.
    pub fn set_motion(&mut self, motion: Option<Motion>) {
        self.motion = motion;
    }

    /// Engagements (standby → engaged) and disengagements so far.
    pub fn engagement_counts(&self) -> (u64, u64) {
        (self.engagements, self.disengagements)
    }

    /// True while braking after an engagement.
    pub fn braking(&self) -> bool {
        self.braking.is_some()
    }

    /// The goal flown once braked, or after the next engagement.
    pub fn pending_goal(&self) -> Goal {
        self.pending
    }

    /// A stop from the vehicle's motion now; holding where it is when at
    /// rest (or the newest pose without a motion estimate).
    fn stop_goal(&self) -> Option<Goal> {
        match self.motion {
            Some(m) if m.speed() > 0.0 => Some(Goal::Brake {
                from: m.position,
                velocity: m.velocity,
            }),
            Some(m) => Some(Goal::Hold(m.position)),
            None => self.last_pose.map(|(_, p)| Goal::Hold(p)),
        }
    }

    /// Standby: the goal is a stop from wherever the vehicle is.
    fn follow(&mut self) {
        if let Some(g) = self.stop_goal() {
            self.set_goal(g);
        }
    }

    /// Engaged at `t`: brake from the motion now, and hold the stop point.
    fn engage(&mut self, t: f64, cause: Cause) -> Transition {
        if let Some(g) = self.stop_goal() {
            self.set_goal(g);
        }
        let speed = self.motion.map_or(0.0, |m| m.speed());
        self.braking = Some(Braking {
            until: t + speed / self.cfg.brake_acceleration + BRAKE_SETTLE,
        });
        self.engagements += 1;
        self.enter(FlightState::Holding, cause, t)
    }

    /// Braking is over: slow enough, or out of time.
    fn braked(&self, t: f64) -> bool {
        self.braking
            .is_some_and(|b| t >= b.until || self.motion.is_some_and(|m| m.speed() < BRAKED_SPEED))
    }

    /// The pose jumped to `position` at `t`: while streaming, the goal
    /// becomes holding there (a path or setpoint is abandoned; a new
    /// setpoint is needed). Returns the state change, if any; `None` when
    /// not streaming (recovery holds the fresh pose anyway).
    pub fn re_anchor(&mut self, t: f64, position: [f64; 3]) -> Option<Transition> {
        if !self.state.engaged() {
            // Standby: the goal follows the vehicle anyway.
            return None;
        }
        self.set_goal(Goal::Hold(position));
        self.braking = None;
        self.pending = Goal::None;
        // The same setpoint again is a new request after a re-anchor.
        self.last_setpoint = None;
        Some(self.enter(FlightState::Holding, Cause::PoseJump, t))
    }

    /// Forces failsafe at `t` (residual failsafe); no recovery before
    /// `t + latch` \[s\]. `None` when not streaming.
    pub fn force_failsafe(&mut self, t: f64, cause: Cause, latch: f64) -> Option<Transition> {
        if !self.state.streams() {
            return None;
        }
        self.latched_until = Some(t + latch);
        Some(self.enter(FlightState::Failsafe, cause, t))
    }

    /// Lifts a failsafe's latch (the controller can fly again): recovery
    /// follows at the next tick with fresh pose and a live autopilot.
    pub fn release_latch(&mut self) {
        self.latched_until = None;
    }

    /// The current state.
    pub fn state(&self) -> FlightState {
        self.state
    }

    /// The current goal.
    pub fn goal(&self) -> Goal {
        self.goal
    }

    /// Increments whenever the goal changes (rebuild the reference then).
    pub fn goal_generation(&self) -> u64 {
        self.generation
    }

    /// Number of state changes so far.
    pub fn transitions(&self) -> u64 {
        self.transitions
    }

    /// Seconds spent in each state up to `now`, indexed by [`FlightState::index`].
    pub fn time_in_states(&self, now: f64) -> [f64; 5] {
        let mut t = self.time_in;
        if let Some(since) = self.entered_at {
            t[self.state.index()] += (now - since).max(0.0);
        }
        t
    }

    /// A pose arrived at `arrival` \[s\] with `position` (local NED \[m\]).
    /// Older arrivals than the newest are ignored.
    pub fn on_pose(&mut self, arrival: f64, position: [f64; 3]) {
        if self.last_pose.is_none_or(|(t, _)| arrival >= t) {
            self.last_pose = Some((arrival, position));
        }
    }

    /// An autopilot HEARTBEAT arrived at `arrival` \[s\].
    pub fn on_heartbeat(&mut self, arrival: f64) {
        if self.last_heartbeat.is_none_or(|t| arrival >= t) {
            self.last_heartbeat = Some(arrival);
        }
    }

    /// A position setpoint (local NED \[m\]) arrived at `t` \[s\].
    pub fn on_setpoint(&mut self, t: f64, position: [f64; 3]) -> SetpointOutcome {
        if !position.iter().all(|v| v.is_finite()) {
            return SetpointOutcome::Refused(Refusal::NonFinite);
        }
        if position
            .iter()
            .zip(&self.cfg.geofence)
            .any(|(p, fence)| p.abs() > *fence)
        {
            return SetpointOutcome::Refused(Refusal::Geofence { position });
        }
        if !self.state.streams() {
            return SetpointOutcome::Refused(Refusal::NotInControl(self.state));
        }
        if self.last_setpoint == Some(position) {
            return SetpointOutcome::Unchanged;
        }
        self.last_setpoint = Some(position);
        let triggers_path = self.cfg.path_trigger_radius > 0.0
            && self.cfg.path_ends.is_some_and(|(first, _)| {
                distance(&first, &position) <= self.cfg.path_trigger_radius
            });
        let (goal, cause) = if triggers_path {
            (Goal::Path, Cause::PathTrigger)
        } else {
            (Goal::Setpoint(position), Cause::Setpoint)
        };
        if self.state == FlightState::Standby {
            // Flown after the next engagement (once braked).
            self.pending = goal;
            return SetpointOutcome::Accepted {
                goal,
                transition: None,
            };
        }
        self.braking = None;
        self.pending = goal;
        self.set_goal(goal);
        let transition = if self.state == FlightState::Tracking {
            None
        } else {
            Some(self.enter(FlightState::Tracking, cause, t))
        };
        SetpointOutcome::Accepted { goal, transition }
    }

    /// A sample of a streamed trajectory at `position` (local NED \[m\])
    /// arrived at `t` \[s\]; the shell checked its jump
    /// ([`Refusal::StreamJump`]). Refused like a setpoint (non-finite,
    /// outside the fence, not in control). Standby: the stream is flown
    /// after the next engagement, once braked. Engaged: the goal becomes
    /// [`Goal::Stream`] (a new generation only when it was not already).
    pub fn on_stream(&mut self, t: f64, position: [f64; 3]) -> SetpointOutcome {
        if !position.iter().all(|v| v.is_finite()) {
            return SetpointOutcome::Refused(Refusal::NonFinite);
        }
        if position
            .iter()
            .zip(&self.cfg.geofence)
            .any(|(p, fence)| p.abs() > *fence)
        {
            return SetpointOutcome::Refused(Refusal::Geofence { position });
        }
        if !self.state.streams() {
            return SetpointOutcome::Refused(Refusal::NotInControl(self.state));
        }
        // A position setpoint after the stream is a new request.
        self.last_setpoint = None;
        let goal = Goal::Stream;
        if self.state == FlightState::Standby {
            self.pending = goal;
            return SetpointOutcome::Accepted {
                goal,
                transition: None,
            };
        }
        if self.goal == goal && self.braking.is_none() {
            return SetpointOutcome::Unchanged;
        }
        self.braking = None;
        self.pending = goal;
        self.set_goal(goal);
        let transition = (self.state != FlightState::Tracking)
            .then(|| self.enter(FlightState::Tracking, Cause::Stream, t));
        SetpointOutcome::Accepted { goal, transition }
    }

    /// The stream went silent at `t`: hold `rest` (local NED \[m\], where
    /// the stream's extrapolation stops). `None` unless a stream is flown.
    pub fn on_stream_timeout(&mut self, t: f64, rest: [f64; 3]) -> Option<Transition> {
        if self.goal != Goal::Stream || !self.state.engaged() {
            return None;
        }
        self.set_goal(Goal::Hold(rest));
        self.pending = Goal::None;
        Some(self.enter(FlightState::Holding, Cause::StreamTimeout, t))
    }

    /// The path reached its end at `t`: hold the last waypoint.
    pub fn on_path_finished(&mut self, t: f64) -> Option<Transition> {
        if self.state != FlightState::Tracking || self.goal != Goal::Path {
            return None;
        }
        let (_, end) = self.cfg.path_ends?;
        if self.cfg.repeat_path {
            // The same goal again: a new generation rebuilds the reference.
            self.generation += 1;
            return None;
        }
        self.set_goal(Goal::Hold(end));
        self.pending = Goal::None;
        Some(self.enter(FlightState::Holding, Cause::PathFinished, t))
    }

    /// The control tick at `t` \[s\].
    pub fn tick(&mut self, t: f64) -> TickDecision {
        if self.entered_at.is_none() {
            self.entered_at = Some(t);
        }
        let pose = self
            .last_pose
            .filter(|(arrival, _)| t - arrival <= self.cfg.pose_timeout);
        let autopilot_alive = self
            .last_heartbeat
            .is_some_and(|h| t - h <= self.cfg.autopilot_timeout);
        let mut reset_controller = false;
        let latched = self.latched_until.is_some_and(|u| t < u);
        let engaged = self.autopilot_engaged();
        let transition = match (self.state, pose) {
            (FlightState::WaitingForPose, Some(_)) if autopilot_alive => {
                if self.cfg.start_path && self.cfg.path_ends.is_some() {
                    self.pending = Goal::Path;
                }
                Some(self.start_streaming(t, engaged))
            }
            (FlightState::Failsafe, Some(_)) if autopilot_alive && !latched => {
                // A failsafe abandons the mission: hold (or stand by).
                self.pending = Goal::None;
                Some(self.start_streaming(t, engaged))
            }
            (FlightState::Standby | FlightState::Holding | FlightState::Tracking, _)
                if pose.is_none() || !autopilot_alive =>
            {
                reset_controller = true;
                self.braking = None;
                let cause = if pose.is_none() {
                    Cause::PoseStale
                } else {
                    Cause::AutopilotSilent
                };
                Some(self.enter(FlightState::Failsafe, cause, t))
            }
            (FlightState::Standby, _) if engaged => Some(self.engage(t, Cause::Engaged)),
            (FlightState::Standby, _) => {
                self.follow();
                None
            }
            (FlightState::Holding | FlightState::Tracking, _) if !engaged => {
                // Pilot override: the mission goal is kept for the hand-back.
                self.pending = match self.goal {
                    g @ (Goal::Path | Goal::Setpoint(_) | Goal::Mission | Goal::Stream)
                        if self.cfg.resume_on_engage =>
                    {
                        g
                    }
                    _ if self.braking.is_some() && self.cfg.resume_on_engage => self.pending,
                    _ => Goal::None,
                };
                self.braking = None;
                self.disengagements += 1;
                self.follow();
                Some(self.enter(FlightState::Standby, Cause::PilotControl, t))
            }
            (FlightState::Holding, _) if self.braked(t) => {
                self.braking = None;
                match self.pending {
                    g @ (Goal::Path | Goal::Setpoint(_) | Goal::Mission | Goal::Stream) => {
                        self.set_goal(g);
                        let cause =
                            if g == Goal::Path && self.cfg.start_path && self.engagements == 1 {
                                Cause::MissionStart
                            } else {
                                Cause::Resume
                            };
                        self.path_resumed = cause == Cause::Resume;
                        Some(self.enter(FlightState::Tracking, cause, t))
                    }
                    _ => None,
                }
            }
            _ => None,
        };
        TickDecision {
            stream: self.state.streams(),
            reset_controller,
            transition,
        }
    }

    /// Pose fresh and the autopilot alive at `t`: engaged (brake, then the
    /// pending goal) or standby.
    fn start_streaming(&mut self, t: f64, engaged: bool) -> Transition {
        if engaged {
            self.engage(t, Cause::PoseFresh)
        } else {
            self.follow();
            self.enter(FlightState::Standby, Cause::PoseFresh, t)
        }
    }

    /// True when the current path goal resumes the path after an override
    /// (the reference then starts from the vehicle's closest point of the
    /// whole path).
    pub fn path_resumed(&self) -> bool {
        self.path_resumed && self.goal == Goal::Path
    }

    /// MAV_CMD_MISSION_START at `t`: fly the mission (from its start). In
    /// standby it is flown after the next engagement, once braked. Refused
    /// when not streaming.
    pub fn on_mission_start(&mut self, t: f64) -> Result<Option<Transition>, Refusal> {
        if !self.state.streams() {
            return Err(Refusal::NotInControl(self.state));
        }
        self.paused = false;
        self.last_setpoint = None;
        self.pending = Goal::Mission;
        if self.state == FlightState::Standby {
            return Ok(None);
        }
        self.braking = None;
        // A restart of the mission being flown is a new goal too.
        self.goal = Goal::None;
        self.set_goal(Goal::Mission);
        Ok(Some(self.enter(
            FlightState::Tracking,
            Cause::MissionStarted,
            t,
        )))
    }

    /// The mission's last item was reached (and held) at `t`: hold `end`.
    pub fn on_mission_finished(&mut self, t: f64, end: [f64; 3]) -> Option<Transition> {
        if self.goal != Goal::Mission || self.state != FlightState::Tracking {
            return None;
        }
        self.set_goal(Goal::Hold(end));
        self.pending = Goal::None;
        Some(self.enter(FlightState::Holding, Cause::MissionFinished, t))
    }

    /// MAV_CMD_DO_PAUSE_CONTINUE 0 at `t`: while tracking a path, a
    /// setpoint or a mission, stop from the vehicle's motion (the braking
    /// reference) and hold; the goal is kept for [`Supervisor::resume`].
    /// `None` when there is nothing to pause (holding already).
    pub fn pause(&mut self, t: f64) -> Option<Transition> {
        if self.state != FlightState::Tracking {
            return None;
        }
        let goal = self.goal;
        let stop = self.stop_goal()?;
        self.set_goal(stop);
        self.pending = goal;
        self.paused = true;
        Some(self.enter(FlightState::Holding, Cause::Paused, t))
    }

    /// MAV_CMD_DO_PAUSE_CONTINUE 1 at `t`: the paused goal goes on (a path
    /// from its closest point). `None` when not paused.
    pub fn resume(&mut self, t: f64) -> Option<Transition> {
        if !(self.paused && self.state == FlightState::Holding) {
            return None;
        }
        self.paused = false;
        let goal = self.pending;
        if !matches!(goal, Goal::Path | Goal::Setpoint(_) | Goal::Mission) {
            return None;
        }
        self.set_goal(goal);
        self.path_resumed = goal == Goal::Path;
        Some(self.enter(FlightState::Tracking, Cause::Continued, t))
    }

    /// True while paused (MAV_CMD_DO_PAUSE_CONTINUE 0).
    pub fn paused(&self) -> bool {
        self.paused
    }

    fn set_goal(&mut self, goal: Goal) {
        if goal != self.goal {
            self.path_resumed = false;
            self.goal = goal;
            self.generation += 1;
        }
    }

    fn enter(&mut self, to: FlightState, cause: Cause, t: f64) -> Transition {
        let from = self.state;
        if let Some(since) = self.entered_at {
            self.time_in[from.index()] += (t - since).max(0.0);
        }
        self.entered_at = Some(t);
        self.state = to;
        self.transitions += 1;
        if to == FlightState::Failsafe {
            self.last_setpoint = None;
        }
        if !matches!(cause, Cause::Paused) {
            self.paused = false;
        }
        Transition {
            from,
            to,
            cause,
            at: t,
        }
    }
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests;
