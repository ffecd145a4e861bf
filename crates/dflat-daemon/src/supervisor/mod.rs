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
//!        the failsafe machine enters              the failsafe machine clears
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
//! `safety.level_hover_max_ms`, so that the autopilot holds a level
//! command, not the last tilt, until its offboard-loss timeout. What
//! happens in a failsafe, and when it is entered and left, is the failsafe
//! state machine's (`tick/failsafe.rs`), the one owner of every failure
//! cause: stale pose and a silent autopilot among them. This machine
//! records the pose and heartbeat arrivals it judges them by
//! ([`Supervisor::links`]) and follows its decisions
//! ([`Supervisor::enter_failsafe`], [`Supervisor::recover`]).
//!
//! Rooms: this file the state, engagement and the tick; `state.rs` the
//! vocabulary (states, goals, causes, transitions); `goals.rs` the goals
//! accepted (setpoints, streams, missions, pause).

use crate::motion::Motion;

mod goals;
mod state;
pub use state::{
    Cause, FlightState, Goal, Links, Refusal, SetpointOutcome, SupervisorConfig, TickDecision,
    Transition,
};

/// Slower than this \[m/s\] after an engagement counts as braked.
pub const BRAKED_SPEED: f64 = 0.3;
/// Braking is over at the latest this long \[s\] after the time the
/// braking deceleration needs.
pub const BRAKE_SETTLE: f64 = 2.0;

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
    /// The configured path was started (`mission.start = "path"` starts it
    /// once, at an engagement the daemon saw happen).
    path_started: bool,
    /// Stopping (SIGTERM / SIGINT): no goal is accepted.
    stopping: bool,
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
            autopilot_engaged: false,
            motion: None,
            braking: None,
            pending: Goal::None,
            path_resumed: false,
            engagements: 0,
            disengagements: 0,
            paused: false,
            path_started: false,
            stopping: false,
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

    /// The vehicle is faster than the speed limit at `t`: while engaged,
    /// brake from its motion now and hold the stop point (the goal flown
    /// is abandoned; a new goal is needed). `None` when not engaged.
    pub fn overspeed(&mut self, t: f64) -> Option<Transition> {
        if !self.state.engaged() {
            return None;
        }
        self.paused = false;
        self.last_setpoint = None;
        Some(self.brake_to_a_stop(t, Cause::Overspeed))
    }

    /// The daemon is stopping at `t` (SIGTERM / SIGINT): from now on no
    /// goal is accepted; while engaged the goal becomes a stop from the
    /// vehicle's motion (the control core then levels and stops the
    /// stream). `None` when not engaged (nothing to brake).
    pub fn begin_stop(&mut self, t: f64) -> Option<Transition> {
        self.stopping = true;
        if !self.state.engaged() {
            return None;
        }
        Some(self.brake_to_a_stop(t, Cause::Shutdown))
    }

    /// Holding at `t` for `cause`: a stop from the vehicle's motion, the
    /// goal flown before abandoned.
    fn brake_to_a_stop(&mut self, t: f64, cause: Cause) -> Transition {
        if let Some(g) = self.stop_goal() {
            self.set_goal(g);
        }
        self.braking = None;
        self.pending = Goal::None;
        self.enter(FlightState::Holding, cause, t)
    }

    /// True once [`Supervisor::begin_stop`] was called.
    pub fn stopping(&self) -> bool {
        self.stopping
    }

    /// The vehicle's speed now [m/s], from the pose stream's motion
    /// estimate (`None` without one).
    pub fn speed(&self) -> Option<f64> {
        self.motion.map(|m| m.speed())
    }

    /// `Failsafe` at `t` for `cause`, as the failsafe machine decided
    /// (`tick/failsafe.rs`): braking and the setpoint last accepted are
    /// forgotten. `None` when not streaming.
    pub fn enter_failsafe(&mut self, t: f64, cause: Cause) -> Option<Transition> {
        if !self.state.streams() {
            return None;
        }
        self.braking = None;
        Some(self.enter(FlightState::Failsafe, cause, t))
    }

    /// Out of `Failsafe` at `t`, as the failsafe machine decided (its
    /// cause cleared): the mission is abandoned; engaged, brake and hold,
    /// else stand by. `None` when not in `Failsafe`.
    pub fn recover(&mut self, t: f64) -> Option<Transition> {
        if self.state != FlightState::Failsafe {
            return None;
        }
        self.pending = Goal::None;
        let engaged = self.autopilot_engaged();
        Some(self.start_streaming(t, engaged))
    }

    /// What the pose and heartbeat arrivals say at `t` \[s\]: a pose
    /// within `pose_timeout`, a HEARTBEAT within `autopilot_timeout`.
    pub fn links(&self, t: f64) -> Links {
        Links {
            pose_fresh: self
                .last_pose
                .is_some_and(|(arrival, _)| t - arrival <= self.cfg.pose_timeout),
            autopilot_alive: self
                .last_heartbeat
                .is_some_and(|h| t - h <= self.cfg.autopilot_timeout),
        }
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

    /// The control tick at `t` \[s\]: the start, engagement, the pilot's
    /// override and the end of braking. Entering and leaving `Failsafe` are
    /// the failsafe machine's ([`Supervisor::enter_failsafe`],
    /// [`Supervisor::recover`]).
    pub fn tick(&mut self, t: f64) -> TickDecision {
        if self.entered_at.is_none() {
            self.entered_at = Some(t);
        }
        let links = self.links(t);
        let engaged = self.autopilot_engaged();
        let transition = match self.state {
            FlightState::WaitingForPose if links.pose_fresh && links.autopilot_alive => {
                if engaged {
                    // Applied from the first command: a restart mid-flight
                    // (or `link.engagement = "always"`). Never take the
                    // vehicle anywhere by ourselves: brake and hold until a
                    // goal is given after this start.
                    Some(self.engage(t, Cause::FoundEngaged))
                } else {
                    // The path waits for the engagement the daemon will see.
                    if self.cfg.start_path && self.cfg.path_ends.is_some() {
                        self.pending = Goal::Path;
                    }
                    self.follow();
                    Some(self.enter(FlightState::Standby, Cause::PoseFresh, t))
                }
            }
            FlightState::Standby if engaged => {
                // An engagement the daemon saw happen: the explicit start
                // `mission.start = "path"` waits for.
                if self.cfg.start_path
                    && self.cfg.path_ends.is_some()
                    && !self.path_started
                    && self.pending == Goal::None
                {
                    self.pending = Goal::Path;
                }
                Some(self.engage(t, Cause::Engaged))
            }
            FlightState::Standby => {
                self.follow();
                None
            }
            FlightState::Holding | FlightState::Tracking if !engaged => {
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
            FlightState::Holding if self.braked(t) => {
                self.braking = None;
                match self.pending {
                    g @ (Goal::Path | Goal::Setpoint(_) | Goal::Mission | Goal::Stream) => {
                        self.set_goal(g);
                        let cause = if g == Goal::Path && self.cfg.start_path && !self.path_started
                        {
                            Cause::MissionStart
                        } else {
                            Cause::Resume
                        };
                        if g == Goal::Path {
                            self.path_started = true;
                        }
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

#[cfg(test)]
mod tests;
