//! The SITL autopilot as one pure step: inputs and time in; the messages
//! to send, the truth sample, counter increments and events out.
//!
//! [`SitlCore`] holds everything the autopilot stand-in decides with — the
//! plant and its sensors (seeded), the pilot's mode machine, the hold
//! target, the loiter / RTL mover and its goal, the latest attitude command
//! and position setpoint with their arrival times, the armed state, the
//! planner, the vision queue, the one-shot pose faults, the parameter
//! table, the message intervals, the refusal limiter and the latest
//! periodic messages — and nothing that does I/O: no sockets, no clock, no
//! threads, no locks. The plant thread (`plant_loop`) is a thin shell
//! around it: it sleeps to the next plant step, reads the clock, drains the
//! input channel (fed by the receive threads and the [`crate::SitlHandle`]
//! hooks), calls [`SitlCore::step`], then publishes the status, the truth
//! and the counters and encodes, signs and sends what the step returns.
//! The unit tests drive the same step on a synthetic clock.
//!
//! Time enters as arguments, in seconds of the SITL clock (since it
//! started, the clock of `time_boot_ms`): the step's clock reading and each
//! input's arrival time.
//!
//! Rooms: `flight.rs` the mode, the command or the hold and the plant;
//! `telemetry.rs` what the SITL sends on its own (HEARTBEAT, the pose,
//! vision, the PX4 streams, the planner); `services.rs` what it answers on
//! either link (commands, parameters, FTP, missions, position setpoints).

use std::collections::VecDeque;

use dflat_link::command::Addressing;
use dflat_link::{MavHeader, MavMessage};
use dflat_sim::plant::{Plant, PlantOptions, PlantState, build_plant};
use dflat_sim::sensing::{GaussianOptions, GaussianSensor, Sensor};
use nalgebra::Vector3;

use crate::autopilot_state::Px4State;
use crate::counters::SentKind;
use crate::latency::PoseFaults;
pub use crate::links::Link;
use crate::params::ParamTable;
use crate::pilot::ModeMachine;
use crate::planner::Planner;
use crate::{
    GRAVITY, ReceivedCommand, SitlAutopilot, SitlCounters, SitlError, SitlMode, SitlSettings,
    TILT_LIMIT_DEG, TruthSample, plant_kind, plant_options,
};

mod flight;
mod services;
mod telemetry;

#[cfg(test)]
pub(crate) use flight::hold_law;
pub use services::{addressing, served};

/// Seed offset of the vision stand-in's noise (independent of the
/// LOCAL_POSITION_NED noise).
const VISION_SEED: u64 = 0x5649_5349_4f4e;
/// Vision samples in flight at most (latency × rate; older ones dropped).
const VISION_QUEUE: usize = 256;

/// Where an outgoing message goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dest {
    /// Both links (the SITL's telemetry).
    Both,
    /// One link (an answer, back where the request came from; the
    /// planner's samples, to the vehicle link).
    Only(Link),
}

/// Who sends an outgoing message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// The SITL itself (its system and component, its sequence), counted
    /// per destination as this kind.
    Own(SentKind),
    /// The planner (`[sitl.planner]`) with this header (its ids and its
    /// own sequence); counted in `planner_samples` when it left.
    Planner(MavHeader),
}

/// A message the step asks the shell to send.
#[derive(Debug, Clone)]
pub struct Outgoing {
    /// The message.
    pub message: MavMessage,
    /// Where it goes.
    pub to: Dest,
    /// Who sends it.
    pub origin: Origin,
    /// A pose of the measured stream departs (VISION_POSITION_ESTIMATE
    /// with vision on, else LOCAL_POSITION_NED): the shell notes its
    /// departure time for the pose → command latency.
    pub measured_pose: bool,
}

/// What arrived since the last step, with arrival times on the SITL clock.
#[derive(Debug, Clone)]
pub enum SitlInput {
    /// A SET_ATTITUDE_TARGET from the vehicle link, accepted (source,
    /// target and signature checked) and decoded by the receive side,
    /// arrived at `at` \[s\].
    Command {
        /// Arrival \[s\], SITL clock.
        at: f64,
        /// The command (angles ZYX \[rad\], normalised thrust).
        command: ReceivedCommand,
    },
    /// A frame for the autopilot's services (see [`served`]): a command,
    /// a parameter request, FTP, a mission message, a position setpoint,
    /// SETUP_SIGNING — addressed to the SITL or broadcast — received on
    /// `link` at `at` \[s\] (authenticated if it came on the vehicle link).
    Frame {
        /// Arrival \[s\], SITL clock.
        at: f64,
        /// The link it came on (answers go back there).
        link: Link,
        /// Its header (the sender).
        header: MavHeader,
        /// The message (boxed: a MAVLink message is large, the other
        /// inputs small).
        message: Box<MavMessage>,
    },
    /// The pilot switches to this mode ([`crate::SitlHandle::request_mode`]).
    ModeRequest(SitlMode),
    /// The pilot's stick: a velocity, local NED \[m/s\].
    PilotVelocity([f64; 3]),
    /// Stop (`true`) or resume (`false`) the pose stream.
    PausePose(bool),
    /// Added to every reported position from now on, NED \[m\].
    PoseOffset([f64; 3]),
    /// Drop the next `n` LOCAL_POSITION_NED (one-shot).
    DropNextPoses(u32),
    /// Send the next LOCAL_POSITION_NED this late \[s\] (one-shot).
    DelayNextPose(f64),
}

/// What the handle reads of the autopilot, after a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SitlStatus {
    /// The mode.
    pub mode: SitlMode,
    /// Armed (HEARTBEAT).
    pub armed: bool,
    /// The pose stream is paused.
    pub pose_paused: bool,
    /// Position setpoints addressed to the autopilot accepted so far.
    pub setpoints_accepted: u64,
    /// SITL time \[s\] the planner's trajectory started (its t = 0).
    pub planner_start: Option<f64>,
    /// The plant's state became non-finite at some point.
    pub diverged: bool,
}

/// Something that happened at a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SitlEvent {
    /// The mode changed.
    ModeChanged {
        /// Before.
        from: SitlMode,
        /// After.
        to: SitlMode,
    },
    /// The armed state changed (MAV_CMD_COMPONENT_ARM_DISARM).
    ArmedChanged(bool),
    /// The plant's state became non-finite (the first time); it was reset
    /// to hover at the hold target.
    Diverged,
}

/// What one step returns.
#[derive(Debug, Clone)]
pub struct SitlOutput {
    /// The messages to send, in order.
    pub messages: Vec<Outgoing>,
    /// The true state, on telemetry steps (for the handle, the trace and
    /// the truth CSV).
    pub truth: Option<TruthSample>,
    /// Counter increments: only the counters the step keeps are set
    /// (plant and late steps, mode changes, hold entries, offboard
    /// refusals, the answers' counts, the pose faults'); the shell counts
    /// what it receives and sends.
    pub counts: SitlCounters,
    /// What happened.
    pub events: Vec<SitlEvent>,
    /// The status after the step.
    pub status: SitlStatus,
}

impl SitlOutput {
    /// The SITL's own `message` to `to`, counted as `kind`.
    fn send(&mut self, message: MavMessage, to: Dest, kind: SentKind) {
        self.messages.push(Outgoing {
            message,
            to,
            origin: Origin::Own(kind),
            measured_pose: false,
        });
    }
}

/// The vision stand-in: captures at its rate, sends after its latency.
struct VisionStream {
    sensor: GaussianSensor,
    /// Capture period \[s\].
    period: f64,
    /// Capture → send delay \[s\].
    latency: f64,
    /// SITL time of the next capture \[s\].
    next_capture: f64,
    /// Captured, not yet sent: (capture time \[s\], position, ZYX euler).
    pending: VecDeque<(f64, [f64; 3], [f64; 3])>,
}

/// The latest of the SITL's periodic messages, for MAV_CMD_REQUEST_MESSAGE.
#[derive(Debug, Default)]
struct Latest {
    heartbeat: Option<MavMessage>,
    sys_status: Option<MavMessage>,
    attitude: Option<MavMessage>,
    position: Option<MavMessage>,
}

/// The SITL autopilot and its plant as a pure step (see the module docs).
pub struct SitlCore {
    // What the configuration fixes.
    options: PlantOptions,
    /// Plant step \[s\].
    dt: f64,
    /// ATTITUDE's and LOCAL_POSITION_NED's intervals (SET_MESSAGE_INTERVAL),
    /// and the plant steps per sample at `sitl.telemetry_rate_hz` (the
    /// truth's samples: `default_every`).
    telemetry_rates: crate::px4_face::TelemetryRates,
    /// Plant steps per heartbeat.
    heartbeat_every: u64,
    /// `sitl.hover_thrust` (normalised).
    hover_thrust: f64,
    autopilot: SitlAutopilot,
    /// The SITL's (system, component).
    own: (u8, u8),
    /// `sitl.pose_clock_rate`.
    pose_clock_rate: f64,
    // The plant and its sensors.
    plant: Box<dyn Plant>,
    sensor: GaussianSensor,
    vision: Option<VisionStream>,
    /// Plant steps taken.
    steps: u64,
    // The autopilot.
    modes: ModeMachine,
    mode: SitlMode,
    /// Where position mode holds, NED \[m\].
    hold_target: Vector3<f64>,
    /// The moving target of loiter / RTL: (position, velocity), NED.
    mover: ([f64; 3], [f64; 3]),
    /// The goal of loiter / RTL, NED \[m\].
    goal: [f64; 3],
    /// When the two-streams warning was last said \[s\].
    told_both: Option<f64>,
    /// A HEARTBEAT is due at this step.
    heartbeat_due: bool,
    /// The latest attitude command and its arrival \[s\].
    command: Option<(f64, ReceivedCommand)>,
    /// The offboard-loss timeout \[s\] (`sitl.command_timeout_s`, or
    /// `COM_OF_LOSS_T` / `GUID_TIMEOUT` set over MAVLink).
    command_timeout: f64,
    /// The gust still to come: when \[s\] and its velocity [m/s].
    gust: Option<(f64, Vector3<f64>)>,
    /// A mode request of this step (the latest wins).
    request: Option<SitlMode>,
    /// A goal of this step (goto).
    pending_goal: Option<[f64; 3]>,
    pose_paused: bool,
    pose_offset: [f64; 3],
    faults: PoseFaults,
    params: ParamTable,
    px4: Px4State,
    latest: Latest,
    /// The latest truth sample (telemetry rate).
    truth: TruthSample,
    planner: Option<Planner>,
    diverged: bool,
    /// The clock of the step being taken \[s\].
    clock: f64,
}

impl std::fmt::Debug for SitlCore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SitlCore")
            .field("steps", &self.steps)
            .field("mode", &self.mode)
            .field("truth", &self.truth)
            .finish_non_exhaustive()
    }
}

impl SitlCore {
    /// The autopilot of `[sitl]` at rest: the plant hovering at
    /// `sitl.start`, in position mode, armed, sensors seeded with
    /// `sitl.seed`.
    pub fn new(cfg: &SitlSettings) -> Result<Self, SitlError> {
        let s = &cfg.sitl;
        let options = plant_options(cfg);
        let mut plant = build_plant(plant_kind(s.plant), &options, s.seed)?;
        plant.reset(&PlantState::hover(Vector3::from(s.start), GRAVITY));
        let mut sensor = GaussianSensor::new(GaussianOptions::isotropic(s.noise_sigma), s.seed)?;
        sensor.reset(0.0, &plant.true_state());
        let vision = if s.vision_rate_hz > 0.0 {
            Some(VisionStream {
                sensor: GaussianSensor::new(
                    GaussianOptions::isotropic(s.vision_noise_sigma),
                    s.seed ^ VISION_SEED,
                )?,
                period: 1.0 / s.vision_rate_hz,
                latency: s.vision_latency_ms / 1000.0,
                next_capture: 1.0 / s.vision_rate_hz,
                pending: VecDeque::with_capacity(VISION_QUEUE),
            })
        } else {
            None
        };
        let hold_target = plant.position();
        Ok(Self {
            options,
            dt: 1.0 / s.plant_rate_hz,
            telemetry_rates: crate::px4_face::TelemetryRates::new(
                (s.plant_rate_hz / s.telemetry_rate_hz).round().max(1.0) as u64,
                s.fixed_telemetry_rate,
            ),
            heartbeat_every: s.plant_rate_hz.round().max(1.0) as u64,
            hover_thrust: s.hover_thrust,
            autopilot: s.autopilot,
            own: (cfg.ids.system_id, cfg.ids.autopilot_component),
            pose_clock_rate: s.pose_clock_rate,
            plant,
            sensor,
            vision,
            steps: 0,
            modes: ModeMachine::new(s.engage, s.pilot.clone())
                .with_stays_offboard(s.stays_offboard),
            gust: (s.gust_at_s > 0.0).then_some((s.gust_at_s, Vector3::from(s.gust_velocity))),
            mode: SitlMode::Hold,
            hold_target,
            mover: (hold_target.into(), [0.0; 3]),
            goal: hold_target.into(),
            told_both: None,
            // First heartbeat right away (sent once a peer is known).
            heartbeat_due: true,
            command: None,
            command_timeout: s.command_timeout_s,
            request: None,
            pending_goal: None,
            pose_paused: false,
            pose_offset: [0.0; 3],
            faults: PoseFaults::default(),
            params: ParamTable::new(
                s.autopilot,
                s.hover_thrust,
                TILT_LIMIT_DEG,
                s.command_timeout_s,
                cfg.ids.system_id,
            ),
            px4: Px4State::new(s.start),
            latest: Latest::default(),
            truth: TruthSample {
                t: 0.0,
                position: s.start,
                velocity: [0.0; 3],
                euler: [0.0; 3],
                command: None,
                mode: SitlMode::Hold,
            },
            planner: s.planner.clone().map(Planner::new),
            diverged: false,
            clock: 0.0,
        })
    }

    /// The plant step \[s\] (1 / `sitl.plant_rate_hz`).
    pub fn step_period(&self) -> f64 {
        self.dt
    }

    /// SITL time \[s\] of the next plant step: when the shell should call
    /// [`step`](Self::step) next.
    pub fn next_step_time(&self) -> f64 {
        (self.steps + 1) as f64 * self.dt
    }

    /// SITL time \[s\] the plant has been integrated to.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.dt
    }

    /// The latest truth sample (telemetry rate; the start at first).
    pub fn truth(&self) -> TruthSample {
        self.truth
    }

    /// The status now.
    pub fn status(&self) -> SitlStatus {
        SitlStatus {
            mode: self.mode,
            armed: self.px4.armed,
            pose_paused: self.pose_paused,
            setpoints_accepted: self.px4.setpoints_accepted,
            planner_start: self.planner.as_ref().and_then(Planner::started_at),
            diverged: self.diverged,
        }
    }

    /// One step at clock reading `clock` \[s\]: take `inputs` (in their
    /// order), then switch modes, fly the command or the hold, integrate
    /// the plant to the last plant step due at `clock` (at least one step;
    /// the steps the clock skipped count as late) and send what is due.
    pub fn step(&mut self, clock: f64, inputs: impl IntoIterator<Item = SitlInput>) -> SitlOutput {
        self.clock = clock;
        let mut out = SitlOutput {
            messages: Vec::new(),
            truth: None,
            counts: SitlCounters::default(),
            events: Vec::new(),
            status: self.status(),
        };
        for input in inputs {
            self.input(input, &mut out);
        }
        let due = (clock / self.dt).floor().max(0.0) as u64;
        let n = due.saturating_sub(self.steps).max(1);
        out.counts.late_steps = n - 1;
        let before = self.steps;
        let fresh = self.fly(n, &mut out);
        self.send_due(before, fresh, &mut out);
        out.status = self.status();
        out
    }

    /// Takes one input.
    fn input(&mut self, input: SitlInput, out: &mut SitlOutput) {
        match input {
            SitlInput::Command { at, command } => self.command = Some((at, command)),
            SitlInput::Frame {
                at,
                link,
                header,
                message,
            } => self.serve(at, link, &header, &message, out),
            SitlInput::ModeRequest(m) => self.request = Some(m),
            SitlInput::PilotVelocity(v) => self.modes.set_velocity(v),
            SitlInput::PausePose(p) => self.pose_paused = p,
            SitlInput::PoseOffset(o) => self.pose_offset = o,
            SitlInput::DropNextPoses(n) => self.faults.drop_next(n),
            SitlInput::DelayNextPose(d) => self.faults.delay_next(d),
        }
    }

    /// Whom `msg` addresses, seen from the SITL (`None`: no target).
    fn addressing(&self, msg: &MavMessage) -> Option<Addressing> {
        addressing(self.own, msg)
    }
}

#[cfg(test)]
mod tests;
