//! The control tick as one pure step: events and time in; the command,
//! STATUSTEXTs, state changes and the CSV record out.
//!
//! [`ControlCore`] holds everything the control thread decides with — the
//! supervisor, the controller, the pose clock, the guard, the fallback and
//! the residual monitor — and nothing that does I/O. The control thread
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

use dflat_control::reference::Reference;
use dflat_control::{ControlModel, Controller, Measurement};
use dflat_link::dialect::MavSeverity;
use dflat_link::{
    AttitudeCommand, AutopilotMode, MavMessage, Target, ThrustMapping, set_attitude_target,
    statustext,
};
use nalgebra::Vector3;
use tracing::{debug, error, info, warn};

use crate::autopilot_params::AutopilotParams;
use crate::clock::PoseClock;
use crate::config::{Config, PoseSourceKind, PoseTime};
use crate::control::{control_model, reference_for};
use crate::guard::{
    CommandGuard, Fallback, FallbackKind, GuardCounts, ResidualMonitor, is_pose_jump,
};
use crate::motion::MotionEstimator;
use crate::records::{CsvDisturbance, CsvRow};
use crate::summary::{DisturbanceSummary, SolveCounts};
use crate::supervisor::{Cause, FlightState, Goal, Supervisor, Transition};

mod exit;
mod failsafe_level;
mod goals;
mod inputs;
mod mission;
mod standby;
use exit::update_caught;
pub use mission::MissionAction;

pub use inputs::{
    Event, ParamName, brake_acceleration, event_from, pose_source, source_filter, supervisor_config,
};

/// Smallest interval between two "setpoint refused" STATUSTEXTs \[s\].
pub const REFUSAL_TEXT_INTERVAL: f64 = 1.0;
/// How long a residual failsafe lasts before pose may re-engage \[s\].
const RESIDUAL_FAILSAFE_LATCH: f64 = 2.0;
/// After a control failsafe, consecutive successful trial solves (not
/// sent) before the stream may resume.
const TRIAL_TICKS: u32 = 5;
/// A pose clock's lag must exceed its bound this long \[s\] to count.
const POSE_LATENCY_PERSISTENCE: f64 = 1.0;

/// One pose as the control core keeps it.
#[derive(Debug, Clone, Copy)]
struct PoseSample {
    /// Arrival on this computer \[s\].
    arrival: f64,
    /// Capture time on this computer's clock \[s\].
    capture: f64,
    /// The source's own timestamp \[s\], if it has one.
    source_time: Option<f64>,
    /// Position, local NED \[m\].
    position: [f64; 3],
    /// Yaw from the pose message \[rad\], if it has one.
    yaw: Option<f64>,
    /// Estimator reset counter, if the message has one.
    reset_counter: Option<u8>,
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
    /// Since when level hover has been streamed \[s\].
    level_hover_since: Option<f64>,
    /// A failsafe's level hover, while it streams (`tick/failsafe_level.rs`).
    failsafe_level: Option<failsafe_level::FailsafeLevel>,
    /// The autopilot's tilt integrated since the newest pose (the brake).
    tilt_since_pose: failsafe_level::TiltSincePose,
    /// In a control failsafe: the controller is tried each tick.
    control_failsafe: bool,
    /// Consecutive successful trial solves in a control failsafe.
    trial_streak: u32,
    /// Since when poses have arrived later than `safety.pose_max_latency_ms`
    /// after their mapped capture time \[s\].
    pose_late_since: Option<f64>,
    /// The pose source's clock was found unusable: poses are stamped with
    /// their arrival time.
    pose_time_arrival: bool,
    last_used_arrival: Option<f64>,
    reference: Option<Reference>,
    reference_generation: u64,
    last_refusal_text: Option<f64>,
    error_streak: u64,
    guard_note: Option<&'static str>,
    fallback_kind: Option<FallbackKind>,
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
    /// The newest accepted stream sample (a stream is built from it).
    newest_sample: Option<dflat_control::reference::StreamSample>,
    /// The position-only setpoint before the stream's first sample
    /// (implied velocity): (time \[s\], position \[m\]).
    stream_seed: Option<(f64, [f64; 3])>,
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
            level_hover_since: None,
            failsafe_level: None,
            tilt_since_pose: Default::default(),
            control_failsafe: false,
            trial_streak: 0,
            pose_late_since: None,
            pose_time_arrival: false,
            last_used_arrival: None,
            reference: None,
            reference_generation,
            last_refusal_text: None,
            error_streak: 0,
            guard_note: None,
            fallback_kind: None,
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
            newest_sample: None,
            stream_seed: None,
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
        for name in self.params.due(t) {
            debug!(name, "requesting the autopilot's parameter");
            self.pending_texts
                .push(dflat_link::params::param_request_read(
                    (self.target.system, self.target.component),
                    name,
                ));
        }
        // 2. Decide. (The level command a failsafe would leave is taken
        // before a failsafe resets the controller.)
        let level = self.failsafe_level_command();
        self.check_stream_timeout(t);
        self.supervisor.set_motion(self.motion.estimate());
        let decision = self.supervisor.tick(t);
        if decision.reset_controller {
            self.reset_controller();
            self.last_used_arrival = None;
        }
        if let Some(tr) = decision.transition {
            self.announce(tr);
        }
        self.refresh_reference();
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
            if trip
                && let Some(tr) = self.supervisor.force_failsafe(
                    t,
                    Cause::ResidualDiverged,
                    RESIDUAL_FAILSAFE_LATCH,
                )
            {
                self.counts.guards.residual_failsafes += 1;
                warn!(residual = ?r, "model residual above the threshold: failsafe");
                self.reset_controller();
                self.last_used_arrival = None;
                self.announce(tr);
                row.guard = Some("residual");
            }
        }
        self.maybe_start_failsafe_level(t, level);
        if self.control_failsafe && self.supervisor.state() == FlightState::Failsafe {
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
            self.failsafe_level_tick(t, &mut row)
        };
        self.mission_tick(t);
        row.state = self.supervisor.state();
        StepOutput {
            command,
            texts: std::mem::take(&mut self.pending_texts),
            transitions: std::mem::take(&mut self.pending_transitions),
            row,
            solve_us,
        }
    }

    /// Runs the controller on `pose` and produces the tick's command (or
    /// none when it cannot be encoded); returns it and the solve time.
    fn control(
        &mut self,
        t: f64,
        pose: PoseSample,
        stopwatch: &mut dyn FnMut() -> f64,
        row: &mut CsvRow,
    ) -> (Option<SentCommand>, u32) {
        let multi_rate = self.multi_rate;
        let measurement = self.tick_measurement(t, &pose);
        // Standby: the tick before sent a command the autopilot did not
        // apply; record the input its attitude shows instead, before this
        // tick's update uses the window.
        self.correct_standby_input();
        let t0 = stopwatch();
        let Some(reference) = self.reference.as_mut() else {
            unreachable!("control() runs with a reference")
        };
        // Routes and streams are trajectories in time: at the measurement's.
        reference.set_time(measurement.t);
        let result = update_caught(self.controller.as_mut(), &measurement, reference);
        if result.is_err() && multi_rate {
            // After a reset (panic) the window needs a sample again (a
            // repeated sample replaces the one held).
            self.observe(&pose);
        }
        let solve = (stopwatch() - t0).max(0.0);
        let solve_us = (solve * 1e6).min(f64::from(u32::MAX)) as u32;
        row.solve_us = Some(solve_us);
        let path_done = matches!(self.supervisor.goal(), Goal::Path)
            && self.reference.as_ref().is_some_and(|r| r.is_finished());
        let produced = result
            .map_err(|e| e.to_string())
            .and_then(|out| self.guarded(&out.command).map(|c| (out, c)));
        // The one exit point: a guarded controller command, or the fallback
        // (the previous plan, the held command, then level hover).
        let (command, out) = match produced {
            Ok((out, command)) if solve <= self.period => {
                if self.error_streak > 0 {
                    info!(ticks = self.error_streak, "controller recovered");
                }
                self.error_streak = 0;
                self.fallback_kind = None;
                self.level_hover_since = None;
                self.counts.solves.record(&out);
                self.fallback.good(command);
                self.residual
                    .predict([out.plan[1].x, out.plan[1].y, out.plan[1].z]);
                (command, Some(out))
            }
            failed => match self.fallback_command(t, &measurement, failed, solve_us, row) {
                Some(command) => (command, None),
                None => return (None, solve_us),
            },
        };
        // This tick's command is not applied in standby: correct it at the
        // next tick from the attitude then.
        self.standby_attitude = if self.supervisor.state() == FlightState::Standby {
            self.attitude
        } else {
            None
        };
        let time_boot_ms = (t * 1000.0) as u64 as u32;
        // Every path above is guarded (or is the fallback's own finite
        // hover); the encoder refuses a non-finite field all the same.
        let sent = match set_attitude_target(self.target, time_boot_ms, &command) {
            Ok(message) => {
                let fresh = self.last_used_arrival != Some(pose.arrival);
                self.last_used_arrival = Some(pose.arrival);
                self.counts.commands += 1;
                row.command = Some([command.roll, command.pitch, command.yaw, command.thrust]);
                Some(SentCommand {
                    message,
                    command,
                    pose_arrival: fresh.then_some(pose.arrival),
                })
            }
            Err(e) => {
                error!(error = %e, "guarded command not encodable: nothing sent");
                None
            }
        };
        if let Some(out) = out {
            row.plan = Some(out.plan.map(|p| [p.x, p.y, p.z]));
            row.reference = Some([out.reference.x, out.reference.y, out.reference.z]);
            if let Some(report) = self.controller.disturbance() {
                let hover = self.mapping.normalized(report.hover_thrust).ok();
                row.disturbance = Some(CsvDisturbance {
                    acceleration: report.acceleration,
                    thrust_scale: report.thrust_scale,
                    hover_thrust: hover,
                    status: report.status,
                });
                self.counts.disturbance = Some(DisturbanceSummary {
                    report,
                    hover_thrust_normalized: hover,
                });
            }
        }
        if path_done {
            if let Some(tr) = self.supervisor.on_path_finished(t) {
                self.announce(tr);
            }
            // Holding the end, or the path again (`mission.repeat`).
            self.refresh_reference();
        }
        (sent, solve_us)
    }

    /// The measurement a tick at `t` hands the controller: multi-rate, the
    /// tick's own time (the samples were observed as they arrived);
    /// otherwise the newest pose at its capture time (not newer than the
    /// last: no new pose).
    fn tick_measurement(&self, t: f64, pose: &PoseSample) -> Measurement {
        Measurement {
            t: if self.multi_rate { t } else { pose.capture },
            position: Vector3::from(pose.position),
            yaw: self.yaw_of(pose.yaw, self.attitude_yaw),
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

    /// Re-anchors after a pose jump to `pose`: controller window reset (a
    /// multi-rate one gets this pose), held / predicted state forgotten,
    /// the reference holds the new position.
    fn re_anchor(&mut self, t: f64, pose: &PoseSample) {
        self.counts.guards.pose_jumps += 1;
        self.controller.reset();
        if self.multi_rate {
            self.observe(pose);
        }
        self.fallback.forget();
        self.residual.forget();
        self.guard_note = Some("jump");
        warn!(position = ?pose.position, "pose jump: re-anchored");
        match self.supervisor.re_anchor(t, pose.position) {
            Some(tr) => self.announce(tr),
            None => self.text(
                MavSeverity::MAV_SEVERITY_WARNING,
                "dflat: pose jump, re-anchored",
            ),
        }
        self.refresh_reference();
    }

    /// The yaw a measurement carries: the pose message's (ODOMETRY,
    /// VISION_POSITION_ESTIMATE), ATTITUDE's (LOCAL_POSITION_NED), else the
    /// configured fixed yaw.
    fn yaw_of(&self, pose_yaw: Option<f64>, attitude_yaw: Option<f64>) -> f64 {
        let yaw = if self.config.link.pose_source == PoseSourceKind::LocalPositionNed {
            attitude_yaw
        } else {
            pose_yaw
        };
        yaw.unwrap_or_else(|| self.config.vehicle.yaw_deg.to_radians())
    }

    /// Hands a pose to a multi-rate controller at its capture time.
    fn observe(&mut self, pose: &PoseSample) {
        let sample = Measurement {
            t: pose.capture,
            position: Vector3::from(pose.position),
            yaw: self.yaw_of(pose.yaw, self.attitude_yaw),
        };
        self.controller.observe(&sample);
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
                source_time,
                velocity,
                acceleration,
            } => self.apply_setpoint(arrival, position, yaw, source_time, velocity, acceleration),
        }
    }

    fn apply_pose(
        &mut self,
        arrival: f64,
        source_time: Option<f64>,
        position: [f64; 3],
        yaw: Option<f64>,
        reset_counter: Option<u8>,
    ) {
        self.supervisor.on_pose(arrival, position);
        let capture = match self.config.link.pose_time {
            PoseTime::Source if !self.pose_time_arrival => {
                let capture = self.clock.capture_time(arrival, source_time);
                self.check_pose_clock(arrival, capture);
                if self.pose_time_arrival {
                    arrival
                } else {
                    capture
                }
            }
            PoseTime::Source | PoseTime::Arrival => arrival,
        };
        let mut pose = PoseSample {
            arrival,
            capture,
            source_time,
            position,
            yaw,
            reset_counter,
        };
        // A jump from the newest pose (further than the vehicle can fly in
        // between, or an estimator reset): re-anchor below.
        let s = &self.config.safety;
        let jump = self.pose.is_some_and(|p| {
            capture >= p.capture
                && is_pose_jump(
                    p.position,
                    position,
                    capture - p.capture,
                    s.max_speed_mps,
                    self.period,
                    s.pose_jump_margin_m,
                    (p.reset_counter, reset_counter),
                )
        });
        // Every sample to a multi-rate controller (late ones too).
        // The motion estimate restarts at a jump (the old poses are
        // another frame).
        if jump {
            self.motion.reset();
        } else {
            self.observe(&pose);
        }
        self.motion.push(capture, position);
        // The newest for the others, by the source's own clock when both
        // have one (a falling offset estimate may map a newer pose before
        // the previous capture), else by capture time; its time must then
        // be newer than the previous one's, or the controller takes the
        // tick as one without a new pose.
        let newer = |p: &PoseSample| match (source_time, p.source_time) {
            (Some(a), Some(b)) if (a - b).abs() < crate::clock::SOURCE_RESET => a > b,
            _ => capture > p.capture,
        };
        match self.pose {
            None => self.pose = Some(pose),
            Some(p) if newer(&p) => {
                pose.capture = pose.capture.max(p.capture + 1e-6);
                self.pose = Some(pose);
            }
            Some(_) => {}
        }
        if jump {
            // The jumped pose is the newest one now.
            self.pose = Some(pose);
            self.re_anchor(arrival, &pose);
        }
    }

    /// Rebuilds the reference when the supervisor's goal changed.
    fn refresh_reference(&mut self) {
        let generation = self.supervisor.goal_generation();
        if generation == self.reference_generation {
            return;
        }
        self.reference_generation = generation;
        if self.supervisor.goal() == Goal::Mission {
            self.reference = match self.mission_reference() {
                Some(Ok(r)) => Some(r),
                Some(Err(e)) => {
                    error!(error = %e, "cannot build the mission's reference; keeping the previous one");
                    self.reference.take()
                }
                None => self.reference.take(),
            };
            return;
        }
        let goal = self.supervisor.goal();
        // A lost stream holds where its extrapolation stops: keep flying
        // the stream's own smooth stop there.
        if let Goal::Hold(p) = goal
            && self
                .reference
                .as_ref()
                .is_some_and(|r| r.is_stream() && (r.rest_point() - Vector3::from(p)).norm() < 1e-9)
        {
            return;
        }
        if goal == Goal::Stream {
            if let Some(r) = self.stream_reference() {
                self.reference = Some(r);
            }
            return;
        }
        // Setpoints are routes from the vehicle's position and velocity.
        let from = match self.motion.estimate() {
            Some(m) => Some((m.position, m.velocity)),
            None => self.pose.map(|p| (p.position, [0.0; 3])),
        };
        self.reference = match reference_for(&self.config, goal, from) {
            Some(Ok(mut r)) => {
                if self.supervisor.path_resumed()
                    && let Some(p) = self.pose
                {
                    r.seek(&Vector3::from(p.position));
                }
                Some(r)
            }
            Some(Err(e)) => {
                // Validated at start; a setpoint is checked finite. Keep
                // flying the previous reference rather than none.
                error!(error = %e, "cannot build the reference; keeping the previous one");
                self.reference.take()
            }
            None => None,
        };
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
