//! The control tick as one pure step: events and time in; the command,
//! STATUSTEXTs, state changes and the CSV record out.
//!
//! [`ControlCore`] holds everything the control thread decides with — the
//! supervisor, the controller, the pose clock, the guard, the failsafe
//! state machine and the residual monitor — and nothing that does I/O. The control thread
//! ([`crate::daemon`]) is a thin shell around it: it sleeps to the tick's
//! deadline, drains the event queue, calls [`ControlCore::step`], sends
//! what the step returns and hands the record to the CSV thread. The fuzz
//! target and the tests drive the same step on a synthetic clock.
//!
//! Time enters as arguments: event arrival and tick times in seconds since
//! the daemon's epoch, and a stopwatch (monotonic seconds) the step reads
//! around the controller's solve to detect a deadline overrun.
//!
//! The exit path is written once (`tick/exit.rs`): controller
//! output → thrust mapping → [`CommandGuard`] → command. A good tick's
//! command, a plan-fallback step and the held / level-hover fallback all
//! pass through it exactly once, so each guard counter counts a command at
//! most once.
//!
//! What happens after a failure — the fallback ladder, letting go, the
//! trial solves, a failsafe's brake and level hover, recovery latches — is
//! one state machine, [`failsafe::Failsafe`], with its transitions in one
//! function (`tick/failsafe.rs`).
//!
//! Rooms: `control.rs` the controller's tick, `exit.rs` the exit path and
//! why a tick failed, `failsafe.rs` the failsafe machine, `ladder.rs` the
//! core carrying out its actions, `failsafe_level.rs` the brake,
//! `pose.rs` and `pose_clock.rs` poses in, `standby.rs` standby and
//! engagement, `params.rs` the autopilot's parameters, `goals.rs`
//! setpoints, streams and the reference, `mission.rs` missions and the
//! heading, `inputs.rs` the events.

use dflat_control::reference::Reference;
use dflat_control::{ControlModel, Controller};
use dflat_link::dialect::MavSeverity;
use dflat_link::{AttitudeCommand, AutopilotMode, MavMessage, Target, ThrustMapping, statustext};
use tracing::{info, warn};

use crate::autopilot_params::AutopilotParams;
use crate::clock::PoseClock;
use crate::config::Config;
use crate::control::control_model;
use crate::guard::{CommandGuard, Fallback, GuardCounts, ResidualMonitor};
use crate::motion::MotionEstimator;
use crate::records::CsvRow;
use crate::summary::{DisturbanceSummary, SolveCounts};
use crate::supervisor::{Cause, FlightState, Refusal, Supervisor, Transition};

mod control;
mod envelope;
pub use envelope::STOP_GUARD;
mod exit;
pub mod failsafe;
mod failsafe_level;
mod goals;
mod inputs;
mod ladder;
mod mission;
mod params;
mod pose;
mod pose_clock;
mod standby;
pub use exit::TickError;
pub use mission::MissionAction;
use pose::PoseSample;

pub use inputs::{
    Event, ParamName, brake_acceleration, event_from, pose_source, source_filter, supervisor_config,
};

/// Smallest interval between two "setpoint refused" STATUSTEXTs \[s\].
pub const REFUSAL_TEXT_INTERVAL: f64 = 1.0;

/// A pose-locked tick's time is its pose's arrival plus this \[s\]: the
/// tick takes the events that arrived up to it (the ATTITUDE sent just
/// before the pose among them).
pub const BATCH_MARGIN: f64 = 20e-6;

/// An event's arrival \[s since the daemon's epoch\] from its arrival in
/// whole microseconds since the epoch. The daemon stamps every received
/// frame in whole µs and its `.tlog` records the same µs (plus the epoch's
/// UNIX time), so `dflat replay` recovers each arrival bit for bit through
/// this one function.
pub fn arrival_secs(us: u64) -> f64 {
    us as f64 / 1e6
}

/// The time of one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickTime {
    /// Tick number since start.
    pub tick: u64,
    /// Wake time \[s\] since the epoch (the tick's time for the controller
    /// and the supervisor).
    pub t: f64,
    /// The scheduled time \[s\] (wake − jitter), for the record.
    pub scheduled: f64,
    /// Wake-up lateness \[µs\].
    pub jitter_us: u32,
}

/// The command a tick sends.
#[derive(Debug, Clone, PartialEq)]
pub struct SentCommand {
    /// SET_ATTITUDE_TARGET, ready to send.
    pub message: MavMessage,
    /// The guarded command in it.
    pub command: AttitudeCommand,
    /// Arrival \[s\] of the pose it used, when that pose is new since the
    /// previous command (for the pose → command latency).
    pub pose_arrival: Option<f64>,
}

/// What one step produced.
#[derive(Debug, Clone)]
pub struct StepOutput {
    /// SET_ATTITUDE_TARGET to send (`None`: not streaming).
    pub command: Option<SentCommand>,
    /// STATUSTEXTs to send, in order.
    pub texts: Vec<MavMessage>,
    /// State changes, in order (for the published state and systemd).
    pub transitions: Vec<Transition>,
    /// The tick's CSV row.
    pub row: CsvRow,
    /// Controller solve time \[µs\] (when it ran).
    pub solve_us: Option<u32>,
}

/// Counters of the core over the run.
#[derive(Debug, Clone, Default)]
pub struct CoreCounts {
    /// Commands produced.
    pub commands: u64,
    /// Ticks the controller failed (error or panic).
    pub control_errors: u64,
    /// The disturbance estimate at the last tick the controller ran.
    pub disturbance: Option<DisturbanceSummary>,
    /// Flags of the controller's successful ticks.
    pub solves: SolveCounts,
    /// What the guards did.
    pub guards: GuardCounts,
    /// Setpoints and stream samples refused (fence, not finite, not in
    /// control, stream jump).
    pub setpoints_refused: u64,
    /// Streams lost (no sample for `stream.timeout_s`).
    pub stream_timeouts: u64,
}

/// Everything the control thread decides with (see the module docs).
pub struct ControlCore {
    /// Link events applied so far, mission commands excluded (the CSV's
    /// `events`: the tick's cutoff in the tlog's received frames, for an
    /// exact replay).
    events_applied: u64,
    supervisor: Supervisor,
    controller: Box<dyn Controller>,
    mapping: ThrustMapping,
    target: Target,
    config: Config,
    period: f64,
    multi_rate: bool,
    clock: PoseClock,
    guard: CommandGuard,
    fallback: Fallback,
    residual: ResidualMonitor,
    /// The controller's model, for the input that explains a measured
    /// attitude in standby (`None`: the configuration's model is invalid;
    /// validated configurations always have one).
    model: Option<ControlModel>,
    // Per-run state.
    pose: Option<PoseSample>,
    attitude_yaw: Option<f64>,
    /// Newest ATTITUDE (pitch, roll) \[rad\].
    attitude: Option<[f64; 2]>,
    /// The attitude at the previous tick, when that tick's command was
    /// sent in standby (corrected from the attitude at this tick).
    standby_attitude: Option<[f64; 2]>,
    /// The autopilot's mode as last reported.
    mode: Option<AutopilotMode>,
    /// The vehicle's motion from the poses (engagement's stop point).
    motion: MotionEstimator,
    /// The autopilot's own hover thrust and tilt limit, read at start-up.
    params: AutopilotParams,
    /// Engagement is refused (the autopilot's tilt limit is below ours);
    /// said once.
    tilt_refusal_said: bool,
    /// What happens after a failure: the failsafe state machine
    /// (`tick/failsafe.rs`).
    failsafe: failsafe::Failsafe,
    /// The autopilot's tilt integrated since the newest pose (the brake).
    tilt_since_pose: failsafe_level::TiltSincePose,
    /// The pose clock's lateness check (`tick/pose_clock.rs`).
    pose_latency: pose_clock::PoseLatency,
    last_used_arrival: Option<f64>,
    reference: Option<Reference>,
    reference_generation: u64,
    /// When each kind of refusal was last said \[s\] ([`Refusal::kind`]).
    last_refusal_text: [Option<f64>; Refusal::KINDS],
    /// The flight envelope (fence, speed limit).
    envelope: crate::envelope::Envelope,
    /// Braking for overspeed (said once per excursion).
    overspeed: bool,
    /// The stop sequence, once asked for (`tick/envelope.rs`).
    stop: Option<envelope::Stop>,
    /// The next step's CSV row carries [`STOP_GUARD`] (the stop began).
    stop_marked: bool,
    /// The last command sent (the stop's level ramps from it).
    last_sent: Option<dflat_link::AttitudeCommand>,
    guard_note: Option<&'static str>,
    /// The learned residual's state last said (`tick/control.rs`).
    learned_said: Option<dflat_control::learned::LearnedStatus>,
    counts: CoreCounts,
    /// Outputs produced between steps (by [`ControlCore::apply`]).
    pending_texts: Vec<MavMessage>,
    pending_transitions: Vec<Transition>,
    /// The mission uploaded over MAVLink, if any.
    mission: Option<crate::mission::Mission>,
    /// The mission being flown (started), if any.
    runner: Option<crate::mission::MissionRunner>,
    /// The last MISSION_CURRENT sent: when, and (seq, total, state).
    mission_current_sent: Option<(f64, (u16, u16, dflat_link::dialect::MissionState))>,
    /// The yaw of the setpoint being flown \[rad\], if it set one.
    setpoint_yaw: Option<f64>,
    /// The commanded heading, rate-limited.
    yaw_command: crate::yaw::YawCommand,
    /// The heading this tick's command carries \[rad\].
    commanded_yaw: f64,
    /// Maps stream senders' `time_boot_ms` onto this computer's clock.
    stream_clock: PoseClock,
    /// The stream's samples so far (the flown stream is built from them;
    /// kept while a stream is flown or pending).
    stream_buffer: Option<Reference>,
    /// Arrival of the newest stream sample \[s\].
    last_sample_arrival: Option<f64>,
    /// The newest position-only setpoint: arrival \[s\], (time \[s\], position \[m\]).
    last_position_setpoint: Option<(f64, (f64, [f64; 3]))>,
}

impl std::fmt::Debug for ControlCore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControlCore")
            .field("state", &self.supervisor.state())
            .field("controller", &self.controller.name())
            .finish_non_exhaustive()
    }
}

impl ControlCore {
    /// The core for `config` around `controller` (reset here), commands
    /// mapped with `mapping`.
    pub fn new(
        config: &Config,
        mut controller: Box<dyn Controller>,
        mapping: ThrustMapping,
    ) -> Self {
        controller.reset();
        let supervisor = Supervisor::new(supervisor_config(config));
        let reference_generation = supervisor.goal_generation();
        Self {
            multi_rate: controller.multi_rate(),
            supervisor,
            controller,
            mapping,
            target: Target {
                system: config.link.system_id,
                component: config.link.autopilot_component,
            },
            period: 1.0 / config.controller.rate_hz,
            clock: PoseClock::new(
                config.link.pose_clock_window_s,
                config.link.pose_min_latency_ms / 1000.0,
            ),
            guard: CommandGuard {
                max_tilt: config.vehicle.max_tilt_deg.to_radians(),
            },
            fallback: Fallback::new(
                config.safety.hold_last_ticks,
                mapping
                    .normalized(config.vehicle.gravity)
                    .unwrap_or(config.vehicle.hover_thrust),
                config.vehicle.yaw_deg.to_radians(),
            ),
            residual: ResidualMonitor::new(config.safety.residual_failsafe_m),
            model: control_model(config).ok(),
            config: config.clone(),
            pose: None,
            attitude_yaw: None,
            attitude: None,
            standby_attitude: None,
            mode: None,
            motion: MotionEstimator::new(),
            params: AutopilotParams::new(),
            tilt_refusal_said: false,
            failsafe: failsafe::Failsafe::Nominal,
            tilt_since_pose: Default::default(),
            pose_latency: Default::default(),
            last_used_arrival: None,
            reference: None,
            reference_generation,
            last_refusal_text: [None; Refusal::KINDS],
            envelope: crate::envelope::Envelope::from_config(config),
            overspeed: false,
            stop: None,
            stop_marked: false,
            last_sent: None,
            guard_note: None,
            learned_said: None,
            counts: CoreCounts::default(),
            pending_texts: Vec::new(),
            events_applied: 0,
            pending_transitions: Vec::new(),
            mission: None,
            runner: None,
            mission_current_sent: None,
            setpoint_yaw: None,
            yaw_command: crate::yaw::YawCommand::new(
                config.vehicle.max_yaw_rate_deg_s.to_radians(),
            ),
            commanded_yaw: config.vehicle.yaw_deg.to_radians(),
            stream_clock: PoseClock::new(config.link.pose_clock_window_s, 0.0),
            stream_buffer: None,
            last_sample_arrival: None,
            last_position_setpoint: None,
        }
    }

    /// The flight state.
    pub fn state(&self) -> FlightState {
        self.supervisor.state()
    }

    /// The supervisor (time in states, transitions).
    pub fn supervisor(&self) -> &Supervisor {
        &self.supervisor
    }

    /// The controller's name.
    pub fn controller_name(&self) -> &'static str {
        self.controller.name()
    }

    /// The counters so far.
    pub fn counts(&self) -> &CoreCounts {
        &self.counts
    }

    /// The failsafe state (what happens after a failure).
    pub fn failsafe(&self) -> failsafe::Failsafe {
        self.failsafe
    }

    /// One control tick at `time`: the events since the previous tick are
    /// applied in order, the supervisor decides, the controller runs when
    /// the state streams, and the command goes through the guard once.
    /// `stopwatch` returns monotonic seconds; it is read around the solve
    /// (an overrun of the tick period sends the fallback instead).
    pub fn step(
        &mut self,
        time: &TickTime,
        events: impl IntoIterator<Item = Event>,
        stopwatch: &mut dyn FnMut() -> f64,
    ) -> StepOutput {
        let t = time.t;
        // 1. Inbound facts up to now.
        for event in events {
            if !matches!(event, Event::Mission { .. }) {
                self.events_applied += 1;
            }
            self.apply(event);
        }
        // Parameter requests due (sent with the texts).
        self.request_params(t);
        // 2. Decide. (The level command a failsafe would leave is taken
        // before a failsafe resets the controller.)
        let level = self.failsafe_level_command();
        self.check_stream_timeout(t);
        self.supervisor.set_motion(self.motion.estimate());
        self.check_overspeed(t);
        let decision = self.supervisor.tick(t, !self.failsafe.latched(t));
        if decision.reset_controller {
            self.reset_controller();
            self.last_used_arrival = None;
        }
        if let Some(tr) = decision.transition {
            self.on_transition(t, tr, level);
        }
        self.stop_tick(t, level);
        self.refresh_reference();
        self.bound_reference();
        self.commanded_yaw = self.heading(t);

        // 3. Control.
        let mut row = CsvRow {
            tick: time.tick,
            t: time.scheduled,
            state: self.supervisor.state(),
            measured: self.pose.map(|p| p.position),
            plan: None,
            reference: None,
            command: None,
            solve_us: None,
            jitter_us: time.jitter_us,
            disturbance: None,
            residual: None,
            guard: self.guard_note.take(),
            pose_age_ms: self.pose.map(|p| (t - p.capture) * 1e3),
            wake: t,
            events: self.events_applied,
        };
        // The model-consistency residual: this tick's measurement against
        // the previous plan's prediction for it.
        if !self.supervisor.state().engaged() {
            // Standby: the plan is not flown, so it predicts nothing.
            self.residual.forget();
        } else if decision.stream
            && let Some(pose) = self.pose
        {
            let (r, trip) = self.residual.measure(pose.position);
            row.residual = r;
            if trip && let Some(tr) = self.supervisor.force_failsafe(t, Cause::ResidualDiverged) {
                self.counts.guards.residual_failsafes += 1;
                warn!(residual = ?r, "model residual above the threshold: failsafe");
                self.reset_controller();
                self.last_used_arrival = None;
                self.on_transition(t, tr, level);
                row.guard = Some("residual");
            }
        }
        if matches!(self.failsafe, failsafe::Failsafe::Trial { .. })
            && self.supervisor.state() == FlightState::Failsafe
        {
            self.trial(t);
        }
        let mut solve_us = None;
        let command = if self.supervisor.state().streams()
            && let Some(pose) = self.pose
            && self.reference.is_some()
        {
            let (sent, us) = self.control(t, pose, stopwatch, &mut row);
            solve_us = Some(us);
            sent
        } else {
            // A failsafe's brake and level hover, while due.
            self.idle_tick(t, &mut row)
        };
        self.mission_tick(t);
        self.last_sent = command.as_ref().map(|c| c.command);
        if command.is_some()
            && let Some(stop) = self.stop.as_mut()
        {
            stop.commands += 1;
            stop.last_command = Some(t);
        }
        row.state = self.supervisor.state();
        if std::mem::take(&mut self.stop_marked) {
            row.guard = Some(STOP_GUARD);
        }
        StepOutput {
            command,
            texts: std::mem::take(&mut self.pending_texts),
            transitions: std::mem::take(&mut self.pending_transitions),
            row,
            solve_us,
        }
    }

    fn text(&mut self, severity: MavSeverity, text: &str) {
        self.pending_texts.push(statustext(severity, text));
    }

    fn announce(&mut self, tr: Transition) {
        info!(
            from = tr.from.name(),
            to = tr.to.name(),
            cause = ?tr.cause,
            t = tr.at,
            "state change"
        );
        let severity = if tr.is_failsafe() {
            MavSeverity::MAV_SEVERITY_CRITICAL
        } else {
            MavSeverity::MAV_SEVERITY_INFO
        };
        self.text(severity, &tr.text());
        self.pending_transitions.push(tr);
    }

    /// Resets the controller (failsafe: window and disturbance estimate
    /// forgotten); a multi-rate controller gets the newest pose again so
    /// that it can run at the next tick.
    fn reset_controller(&mut self) {
        self.controller.reset();
        self.fallback.forget();
        self.residual.forget();
        if self.multi_rate
            && let Some(pose) = self.pose
        {
            self.observe(&pose);
        }
    }

    /// Applies one inbound fact (pose clock, jump check, supervisor).
    pub fn apply(&mut self, event: Event) {
        match event {
            Event::Pose {
                arrival,
                source_time,
                position,
                yaw,
                reset_counter,
            } => {
                self.tilt_since_pose.on_pose(arrival);
                self.apply_pose(arrival, source_time, position, yaw, reset_counter);
            }
            Event::Attitude {
                arrival,
                roll,
                pitch,
                yaw,
            } => {
                self.tilt_since_pose.on_attitude(arrival, [pitch, roll]);
                self.attitude_yaw = Some(yaw);
                if roll.is_finite() && pitch.is_finite() {
                    // As the window records inputs: a world-frame tilt.
                    self.attitude = Some(self.tilt_from_measured(pitch, roll, yaw));
                }
            }
            Event::Mission { arrival, action } => self.apply_mission(arrival, action),
            Event::Heartbeat { arrival, mode } => {
                self.supervisor.on_heartbeat(arrival);
                self.apply_mode(mode, arrival);
            }
            Event::Param { name, value, .. } => self.apply_param(name.as_str(), value),
            Event::Setpoint {
                arrival,
                position,
                yaw,
                yaw_rate,
                source_time,
                velocity,
                acceleration,
            } => self.apply_setpoint(
                arrival,
                position,
                (yaw, yaw_rate),
                source_time,
                velocity,
                acceleration,
            ),
        }
    }

    /// The shutdown text and whatever the last events left to say.
    pub fn shutdown_texts(&mut self) -> Vec<MavMessage> {
        self.text(
            MavSeverity::MAV_SEVERITY_NOTICE,
            "dflat: shutdown, attitude stream off",
        );
        std::mem::take(&mut self.pending_texts)
    }
}

#[cfg(test)]
mod heading_tests;
#[cfg(test)]
mod tests;
