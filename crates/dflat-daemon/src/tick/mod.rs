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
//! What happens after a failure — stale pose, a silent autopilot, the
//! fallback ladder, the residual, letting go, the trial solves, a
//! failsafe's brake and level hover, when the failsafe clears — is one
//! state machine, [`failsafe::Failsafe`], with its transitions in one
//! function (`tick/failsafe.rs`); the supervisor enters and leaves its
//! `FAILSAFE` state only as that machine decides.
//!
//! Rooms: `settings.rs` the core's typed settings, `control.rs` the
//! controller's tick, `exit.rs` the exit path and why a tick failed,
//! `failsafe.rs` the failsafe machine, `act.rs` the one place its actions
//! become behaviour, `ladder.rs` the failsafe part and what the core
//! reports to the machine, `failsafe_level.rs` the brake,
//! `pose.rs` and `pose_clock.rs` poses in, `standby.rs` standby and
//! engagement, `params.rs` the autopilot's parameters, `goals.rs`
//! setpoints, streams and the reference, `mission.rs` missions and the
//! heading, `inputs.rs` the events.

use dflat_control::{ControlModel, Controller};
use dflat_link::dialect::MavSeverity;
use dflat_link::{AttitudeCommand, MavMessage, ThrustMapping, statustext};
use tracing::{info, warn};

use crate::config::Config;
use crate::control::control_model;
use crate::guard::{CommandGuard, Fallback, GuardCounts, ResidualMonitor};
use crate::records::CsvRow;
use crate::summary::{DisturbanceSummary, SolveCounts};
use crate::supervisor::{Cause, FlightState, Supervisor, Transition};

mod act;
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
pub mod settings;
mod standby;
pub use exit::TickError;
pub use goals::reference_for;
pub use mission::MissionAction;
pub use settings::CoreSettings;

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

/// Everything the control thread decides with (see the module docs): the
/// supervisor and the controller, and the core's parts, each owning its
/// state in its own file — the pose clock and window (`pose.rs`), the goals
/// and the reference (`goals.rs`), engagement (`standby.rs`) and the
/// failsafe (`ladder.rs`).
pub struct ControlCore {
    /// The settings, built once from the configuration.
    settings: CoreSettings,
    /// Link events applied so far, mission commands excluded (the CSV's
    /// `events`: the tick's cutoff in the tlog's received frames, for an
    /// exact replay).
    events_applied: u64,
    supervisor: Supervisor,
    controller: Box<dyn Controller>,
    /// The controller's model, for the input that explains a measured
    /// attitude in standby (`None`: the configuration's model is invalid;
    /// validated configurations always have one).
    model: Option<ControlModel>,
    mapping: ThrustMapping,
    guard: CommandGuard,
    /// The pose clock and window.
    poses: pose::Poses,
    /// The goals and the reference.
    goals: goals::Goals,
    /// Engagement and the stop.
    engagement: standby::Engagement,
    /// The failsafe.
    failsafe: ladder::FailsafePart,
    /// The last command sent (the stop's level ramps from it).
    last_sent: Option<dflat_link::AttitudeCommand>,
    guard_note: Option<&'static str>,
    /// The learned residual's state last said (`tick/control.rs`).
    learned_said: Option<dflat_control::learned::LearnedStatus>,
    /// The tick of the controller's last update (`tick/control.rs`): the
    /// ticks after it without one are told to it as skipped.
    last_update_tick: Option<u64>,
    counts: CoreCounts,
    /// Outputs produced between steps (by [`ControlCore::apply`]).
    pending_texts: Vec<MavMessage>,
    pending_transitions: Vec<Transition>,
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
        let settings = CoreSettings::new(config, controller.as_ref());
        let supervisor = Supervisor::new(supervisor_config(config));
        let generation = supervisor.goal_generation();
        let v = &settings.vehicle;
        let failsafe = ladder::FailsafePart {
            state: failsafe::Failsafe::Nominal,
            fallback: Fallback::new(
                settings.failsafe.hold_ticks,
                mapping.normalized(v.gravity).unwrap_or(v.hover_thrust),
                v.yaw,
            ),
            residual: ResidualMonitor::new(settings.failsafe.residual_failsafe),
            tilt_since_pose: Default::default(),
        };
        Self {
            supervisor,
            controller,
            mapping,
            guard: CommandGuard {
                max_tilt: v.max_tilt,
            },
            model: control_model(config).ok(),
            poses: pose::Poses::new(&settings.pose),
            goals: goals::Goals::new(
                &settings,
                crate::envelope::Envelope::from_config(config),
                generation,
            ),
            engagement: standby::Engagement::new(settings.streams.clone()),
            failsafe,
            last_sent: None,
            guard_note: None,
            learned_said: None,
            last_update_tick: None,
            counts: CoreCounts::default(),
            pending_texts: Vec::new(),
            events_applied: 0,
            pending_transitions: Vec::new(),
            settings,
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

    /// What DF-MPC's window did with the poses (`None` for the baselines).
    pub fn window_stats(&self) -> Option<dflat_control::window::PoseWindowStats> {
        self.controller.window_stats()
    }

    /// What became of the stream-rate requests (`link.request_streams`).
    pub fn stream_outcomes(&self) -> Vec<crate::stream_rates::StreamOutcome> {
        self.engagement.streams.outcomes()
    }

    /// The counters so far.
    pub fn counts(&self) -> &CoreCounts {
        &self.counts
    }

    /// The failsafe state (what happens after a failure).
    pub fn failsafe(&self) -> failsafe::Failsafe {
        self.failsafe.state
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
        // Parameter and stream-rate requests due (sent with the texts).
        self.request_params(t);
        self.request_streams(t);
        // 2. Decide. (The level command a failsafe would leave is taken
        // before a failsafe resets the controller.)
        let level = self.failsafe_level_command();
        self.check_stream_timeout(t);
        self.supervisor.set_motion(self.poses.motion.estimate());
        self.check_overspeed(t);
        // The failsafe machine first (stale pose, a silent autopilot, its
        // clearing); the flight state moves on when it changed nothing.
        let transitions = self.supervisor.transitions();
        self.report_health(t, level);
        if self.supervisor.transitions() == transitions
            && let Some(tr) = self.supervisor.tick(t).transition
        {
            self.announce(tr);
        }
        self.stop_tick(t, level);
        self.refresh_reference();
        self.bound_reference();
        self.goals.commanded_yaw = self.heading(t);

        // 3. Control.
        let mut row = CsvRow {
            tick: time.tick,
            t: time.scheduled,
            state: self.supervisor.state(),
            measured: self.poses.newest.map(|p| p.position),
            plan: None,
            reference: None,
            command: None,
            solve_us: None,
            jitter_us: time.jitter_us,
            disturbance: None,
            residual: None,
            guard: self.guard_note.take(),
            pose_age_ms: self.poses.newest.map(|p| (t - p.capture) * 1e3),
            wake: t,
            events: self.events_applied,
        };
        // The model-consistency residual: this tick's measurement against
        // the previous plan's prediction for it.
        if !self.supervisor.state().engaged() {
            // Standby: the plan is not flown, so it predicts nothing.
            self.failsafe.residual.forget();
        } else if let Some(pose) = self.poses.newest {
            let (r, trip) = self.failsafe.residual.measure(pose.position);
            row.residual = r;
            if trip {
                warn!(residual = ?r, "model residual above the threshold: failsafe");
                let tripped = failsafe::Event::Tripped {
                    t,
                    cause: Cause::ResidualDiverged,
                    engaged: true,
                    level: self.level_plan(t, level),
                };
                self.failsafe_on(t, tripped, None, &mut row.guard);
            }
        }
        if matches!(self.failsafe.state, failsafe::Failsafe::Trial { .. })
            && self.supervisor.state() == FlightState::Failsafe
        {
            self.trial(t);
        }
        let controlled = match self.poses.newest {
            Some(pose) if self.supervisor.state().streams() => {
                self.control(time, pose, stopwatch, &mut row)
            }
            _ => None,
        };
        let (command, solve_us) = match controlled {
            Some((sent, us)) => (sent, Some(us)),
            // A failsafe's brake and level hover, while due.
            None => (self.idle_tick(t, &mut row), None),
        };
        self.mission_tick(t);
        self.last_sent = command.as_ref().map(|c| c.command);
        if command.is_some()
            && let Some(stop) = self.engagement.stop.as_mut()
        {
            stop.commands += 1;
            stop.last_command = Some(t);
        }
        row.state = self.supervisor.state();
        if std::mem::take(&mut self.engagement.stop_marked) {
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
        self.last_update_tick = None;
        self.failsafe.fallback.forget();
        self.failsafe.residual.forget();
        if self.settings.multi_rate
            && let Some(pose) = self.poses.newest
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
                self.failsafe.tilt_since_pose.on_pose(arrival);
                self.apply_pose(arrival, source_time, position, yaw, reset_counter);
            }
            Event::Attitude {
                arrival,
                roll,
                pitch,
                yaw,
            } => {
                self.failsafe
                    .tilt_since_pose
                    .on_attitude(arrival, [pitch, roll]);
                self.poses.attitude_yaw = Some(yaw);
                if roll.is_finite() && pitch.is_finite() {
                    // As the window records inputs: a world-frame tilt.
                    self.poses.attitude = Some(self.tilt_from_measured(pitch, roll, yaw));
                }
            }
            Event::Mission { arrival, action } => self.apply_mission(arrival, action),
            Event::Heartbeat { arrival, mode } => {
                self.supervisor.on_heartbeat(arrival);
                self.engagement.streams.on_heartbeat(arrival);
                self.apply_mode(mode, arrival);
            }
            Event::Param { name, value, .. } => self.apply_param(name.as_str(), value),
            Event::IntervalAck { arrival, result } => self.apply_interval_ack(result, arrival),
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
mod recovery_tests;
#[cfg(test)]
mod stream_rate_tests;
#[cfg(test)]
mod stream_time_tests;
#[cfg(test)]
mod tests;
