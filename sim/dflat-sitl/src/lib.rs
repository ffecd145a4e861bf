//! The SITL autopilot stand-in: a real-time plant behind a MAVLink link.
//!
//! What a flight controller (PX4 in offboard, ArduPilot in GUIDED_NOGPS)
//! looks like to the daemon, built from the lab's plants and sensing:
//!
//! * a plant thread integrates one of `dflat-sim`'s plants
//!   ([`PlanarPlant`](dflat_sim::plant::PlanarPlant),
//!   [`SpatialPlant`](dflat_sim::plant::SpatialPlant),
//!   [`RigidBodyPlant`](dflat_sim::plant::RigidBodyPlant), chosen by
//!   `sitl.plant`) in real time at `sitl.plant_rate_hz`, with the plant
//!   parameters of `[sitl]` (τ, k̃, hover thrust, mass factor — they may
//!   differ from the controller's `[vehicle]` model) and the autopilot's
//!   ±35° pitch/roll saturation;
//! * it sends HEARTBEAT (1 Hz; MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_PX4, armed,
//!   PX4 custom mode OFFBOARD while commanded, POSCTL while holding),
//!   LOCAL_POSITION_NED (true position plus Gaussian noise of σ =
//!   `sitl.noise_sigma`, true velocity) and ATTITUDE at
//!   `sitl.telemetry_rate_hz`;
//! * optionally (`sitl.vision_rate_hz` > 0) VISION_POSITION_ESTIMATE, a
//!   vision pipeline stand-in: at that rate the true position plus Gaussian
//!   noise (σ = `sitl.vision_noise_sigma`) is captured, stamped with its
//!   capture time (`time_usec`, the SITL's clock) and sent
//!   `sitl.vision_latency_ms` later (to the plant step's resolution);
//! * it accepts SET_ATTITUDE_TARGET (82) from another component of its own
//!   vehicle addressed to its system/component (or broadcast, 0): the
//!   quaternion becomes roll/pitch/yaw, the normalised thrust the specific
//!   thrust `T = thrust / sitl.hover_thrust · g` (ignored by the planar
//!   plant, whose altitude the autopilot holds);
//! * it answers like a PX4 an SDK can script ([`px4_face`]): HOME_POSITION,
//!   EXTENDED_SYS_STATE, ATTITUDE_QUATERNION, GLOBAL_POSITION_INT,
//!   BATTERY_STATUS (unknown) with SET_MESSAGE_INTERVAL, AUTOPILOT_VERSION,
//!   the mission protocol (unsupported, answered), AUTO_LOITER (hold, goto)
//!   and AUTO_RTL flown by its own position loop ([`position_control`]),
//!   disarm; and in OFFBOARD it flies SET_POSITION_TARGET_LOCAL_NED
//!   addressed to it with that loop (the latest setpoint type wins against
//!   SET_ATTITUDE_TARGET, said every 10 s);
//! * when no valid command arrived for `sitl.command_timeout_s` it holds
//!   position on its own: an internal PD position loop on its true state,
//!   like an autopilot's position-mode failsafe. It starts in that mode;
//! * optionally (`sitl.signing_key_file`, or [`SitlOptions::signing`])
//!   MAVLink 2 signing: every frame it sends is signed (link id
//!   [`SIGNING_LINK_ID`], timestamps from the wall clock; nothing is
//!   persisted). On the vehicle link a SET_ATTITUDE_TARGET without a valid
//!   signature (unsigned, another key, or a replayed timestamp) is not
//!   applied and is counted in [`SitlCounters::commands_unauthenticated`];
//!   unsigned SET_POSITION_TARGET_LOCAL_NED and every frame with a wrong
//!   signature or a replayed timestamp are dropped too. Other *unsigned*
//!   messages outside [`dflat_link::MUST_BE_SIGNED`] are still accepted
//!   (the daemon accepts only those listed in
//!   `link.signing_accept_unsigned`) — looser than ArduPilot, which with
//!   signing on accepts unsigned frames only of RADIO_STATUS or on its USB
//!   channel. A dropped frame is not routed to
//!   the ground station either.
//!
//! Link: `udpin:HOST:PORT` (port 0 picks a free one, see
//! [`SitlHandle::local_addr`]); like the mavlink crate's `udpin`, it replies
//! to the last sender and sends nothing before a peer spoke. An optional
//! second `udpin` port for a ground station ([`SitlOptions::gcs`]) routes
//! MAVLink like a real autopilot: frames from the GCS go to the vehicle link
//! (the daemon), frames from the vehicle link that are not addressed to the
//! autopilot itself go to the GCS, and the SITL's own telemetry goes to both.
//! Signed frames are routed as received (their bytes, signature included);
//! the SITL does not check frames from the GCS, the daemon does.
//!
//! Shape: the autopilot and its plant are one pure step,
//! [`SitlCore::step`] (module [`step`]): the SITL clock and what arrived
//! since the last step ([`SitlInput`]: decoded commands and requests with
//! their arrival times, the hooks' switches) in; the messages to send with
//! their destination, the truth sample, counter increments and events out
//! ([`SitlOutput`]). No socket, clock, thread or lock inside. Three
//! threads are its thin I/O: the plant thread (sleeps to the next plant
//! step, reads the clock, drains the input channel, steps, publishes the
//! status and truth for the handle, encodes, signs and sends), and the
//! receive threads of the vehicle link (frames parsed, signatures checked,
//! SET_ATTITUDE_TARGET decoded, requests passed to the step, routing to the
//! GCS) and of the GCS port. Answers to requests therefore leave at the next
//! plant step (within 1/`sitl.plant_rate_hz`).
//!
//! In-process hooks ([`SitlHandle`]): the true state and an optional trace,
//! counters, the current mode, a tap of every received frame, a pose pause
//! switch (the pose stream stops, HEARTBEAT goes on) and a pose offset (an
//! estimator jump as the daemon sees it); the switches act from the next
//! plant step, the state is the latest step's. `dflat sitl` (the binary crate's shell) maps
//! SIGUSR1 / SIGUSR2 to pause / resume and prints its bound addresses and
//! mode changes on stdout.

use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use dflat_link::{
    LinkRx, MavHeader, MavMessage, Signing, SourceFilter, timestamp_from_system_time,
};
use dflat_sim::plant::{PlantKind, PlantOptions, RigidBodyOptions};

use dflat_link::transport::Endpoint;

mod autopilot_state;
pub mod commands;
mod config;
mod counters;
mod error;
mod latency;
mod links;
mod mode;
pub mod params;
pub mod pilot;
pub mod planner;
mod plant_loop;
pub mod position_control;
pub mod px4_face;
mod routing;
pub mod step;
mod truth;
pub use config::{SitlAutopilot, SitlConfig, SitlConfigError, SitlIds, SitlPlant, SitlSettings};
pub use counters::{SentCounts, SentKind, SitlCounters};
pub use error::SitlError;
pub use latency::PoseLatency;
pub use mode::SitlMode;
pub use params::{ParamError, ParamTable, SitlParam};
pub use pilot::{ModeMachine, PilotAction, PilotMode, SitlEngage};
use plant_loop::PlantLoop;
pub use step::{SitlCore, SitlInput, SitlOutput, SitlStatus};
pub use truth::{TruthRow, read_truth_csv};
use truth::{create_truth_csv, write_truth_row};

use counters::Counters;
use routing::{GcsRx, Links, Outbox, Peers, VehicleRx};

/// Gravity of the simulated world [m/s²].
pub const GRAVITY: f64 = 9.81;
/// The autopilot's pitch/roll command saturation \[deg\].
pub const TILT_LIMIT_DEG: f64 = 35.0;
/// PX4 custom mode of main mode OFFBOARD (6 << 16), reported while commanded.
pub const PX4_MODE_OFFBOARD: u32 = 6 << 16;
/// PX4 custom mode of main mode POSCTL (3 << 16), reported while holding.
pub const PX4_MODE_POSCTL: u32 = 3 << 16;
/// ArduPilot Copter LOITER, reported in position mode.
pub const ARDUPILOT_MODE_LOITER: u32 = 5;
/// ArduPilot Copter RTL, reported in return-to-launch.
pub const ARDUPILOT_MODE_RTL: u32 = 6;
/// ArduPilot Copter GUIDED_NOGPS, reported in offboard mode.
pub const ARDUPILOT_MODE_GUIDED_NOGPS: u32 = 20;
/// Read timeout of the receive threads: how fast they notice a stop.
const RX_POLL: Duration = Duration::from_millis(50);
/// Truth rows buffered between flushes of the truth CSV.
const CSV_FLUSH_ROWS: u64 = 25;

/// The SITL's signing link id (the daemon's default is 0).
pub const SIGNING_LINK_ID: u8 = 1;

/// A received attitude command as the autopilot reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReceivedCommand {
    /// Roll φ \[rad\], ZYX.
    pub roll: f64,
    /// Pitch θ \[rad\], ZYX.
    pub pitch: f64,
    /// Yaw ψ \[rad\], ZYX.
    pub yaw: f64,
    /// Normalised thrust as received (the hover value when ignored).
    pub thrust: f64,
}

/// The true state at one telemetry instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSample {
    /// SITL time since start \[s\] (the clock of `time_boot_ms`).
    pub t: f64,
    /// True position, local NED \[m\].
    pub position: [f64; 3],
    /// True velocity, local NED \[m/s\].
    pub velocity: [f64; 3],
    /// True attitude `[roll, pitch, yaw]` \[rad\], ZYX.
    pub euler: [f64; 3],
    /// The command in force (`None` while holding).
    pub command: Option<ReceivedCommand>,
    /// The mode.
    pub mode: SitlMode,
}

/// One frame received on the vehicle link, for [`SitlOptions::tap`].
#[derive(Debug, Clone)]
pub struct TapFrame {
    /// When it was received.
    pub at: Instant,
    /// Sender header.
    pub header: MavHeader,
    /// The message.
    pub message: MavMessage,
}

/// How to run the SITL beyond its `[sitl]` configuration.
#[derive(Debug, Clone, Default)]
pub struct SitlOptions {
    /// Vehicle link, overriding `sitl.url` (`udpin:HOST:PORT`, port 0 = any free).
    pub link: Option<String>,
    /// Optional ground-station port (`udpin:HOST:PORT`), routed to the vehicle link.
    pub gcs: Option<String>,
    /// Write the truth CSV here (created with its parent directory).
    pub truth_csv: Option<PathBuf>,
    /// Keep every telemetry-rate truth sample in memory ([`SitlHandle::trace`]).
    pub record_trace: bool,
    /// Receives a copy of every frame that arrives on the vehicle link
    /// (before the signature check).
    pub tap: Option<Sender<TapFrame>>,
    /// MAVLink 2 signing, overriding `sitl.signing_key_file`: outgoing
    /// frames are signed with it (its link id, timestamps ≥ its start) and
    /// the vehicle link is verified with a copy. Its
    /// [`accept_unsigned_telemetry`](Signing::accept_unsigned_telemetry) is
    /// honoured (`Signing::new` leaves it off: then every unsigned frame is
    /// dropped; from the config file it is on).
    pub signing: Option<Signing>,
}

/// What a finished SITL run leaves.
#[derive(Debug, Clone)]
pub struct SitlReport {
    /// Final counters.
    pub counters: SitlCounters,
    /// The recorded truth trace (empty unless [`SitlOptions::record_trace`]).
    pub trace: Vec<TruthSample>,
    /// The last true state.
    pub last: TruthSample,
    /// The plant's state became non-finite at some point.
    pub diverged: bool,
    /// SITL time \[s\] the planner's trajectory started (its t = 0; the
    /// first sample), when `[sitl.planner]` streamed.
    pub planner_start: Option<f64>,
}

/// What the plant thread publishes after each step for the handle.
struct Published {
    /// The status after the latest step.
    status: SitlStatus,
    /// The latest true state (telemetry rate).
    truth: TruthSample,
    /// The recorded trace (with [`SitlOptions::record_trace`]).
    trace: Vec<TruthSample>,
}

/// What the SITL's threads and its handle share.
struct Shared {
    /// The SITL clock's origin.
    start: Instant,
    stop: AtomicBool,
    links: Links,
    counters: Counters,
    /// Pose → command latency, measured at the sockets.
    latency: latency::LatencyProbe,
    published: Mutex<Published>,
}

/// Locks a mutex, recovering the data if a thread panicked while holding it.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The SITL's signing: [`SitlOptions::signing`], else a key from
/// `sitl.signing_key_file` (link id [`SIGNING_LINK_ID`], starting at the
/// wall clock, unsigned non-commands accepted), else off.
fn sitl_signing(cfg: &SitlSettings, options: &SitlOptions) -> Result<Option<Signing>, SitlError> {
    if let Some(s) = &options.signing {
        return Ok(Some(s.clone()));
    }
    let file = cfg.sitl.signing_key_file.trim();
    if file.is_empty() {
        return Ok(None);
    }
    let key = dflat_link::load_key_file(Path::new(file)).map_err(|e| SitlError::SigningKey {
        file: PathBuf::from(file),
        reason: e.reason,
    })?;
    let now = timestamp_from_system_time(SystemTime::now());
    let mut signing = Signing::new(key, SIGNING_LINK_ID, now);
    signing.accept_unsigned_telemetry = true;
    Ok(Some(signing))
}

/// A running SITL: the in-process hooks. Dropping it stops the SITL.
pub struct SitlHandle {
    shared: Arc<Shared>,
    /// The hooks' way into the step.
    inputs: Sender<SitlInput>,
    /// Outgoing frames are signed.
    #[cfg(test)]
    signed: bool,
    local_addr: SocketAddr,
    gcs_addr: Option<SocketAddr>,
    threads: Vec<(&'static str, JoinHandle<Result<(), SitlError>>)>,
}

impl std::fmt::Debug for SitlHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SitlHandle")
            .field("local_addr", &self.local_addr)
            .field("gcs_addr", &self.gcs_addr)
            .finish_non_exhaustive()
    }
}

/// Parses `udpin:HOST:PORT` (see [`Endpoint`]) into a socket address.
pub fn parse_udpin(what: &'static str, url: &str) -> Result<SocketAddr, SitlError> {
    let err = || SitlError::Endpoint {
        what,
        url: url.to_owned(),
    };
    match Endpoint::parse(url) {
        Ok(Endpoint::UdpIn { host, port }) => (host.as_str(), port)
            .to_socket_addrs()
            .map_err(|_| err())?
            .next()
            .ok_or_else(err),
        _ => Err(err()),
    }
}

fn bind(what: &'static str, addr: SocketAddr) -> Result<UdpSocket, SitlError> {
    let bind_err = |source| SitlError::Bind { what, addr, source };
    let socket = UdpSocket::bind(addr).map_err(bind_err)?;
    socket.set_read_timeout(Some(RX_POLL)).map_err(bind_err)?;
    Ok(socket)
}

/// The plant options of `[sitl]`: 1/`plant_rate_hz` step, τ, k̃, τ_T, the
/// command delay, mass factor, the drags (linear, quadratic, rotor), ±35° saturation, g = 9.81 m/s².
pub fn plant_options(cfg: &SitlSettings) -> PlantOptions {
    let s = &cfg.sitl;
    PlantOptions {
        plant_dt: 1.0 / s.plant_rate_hz,
        g: GRAVITY,
        tilt_limit: TILT_LIMIT_DEG.to_radians(),
        attitude_tau: s.tau,
        attitude_gain: s.k,
        thrust_tau: s.tau_thrust,
        command_delay: s.command_delay_ms / 1000.0,
        mass_factor: s.mass_factor,
        max_yaw_rate: s.max_yaw_rate_deg_s.to_radians(),
        drag: s.drag,
        quadratic_drag: s.quadratic_drag,
        rotor_drag: s.rotor_drag,
        rigid: RigidBodyOptions {
            max_rate: [
                s.max_tilt_rate_deg_s.to_radians(),
                s.max_tilt_rate_deg_s.to_radians(),
                0.0,
            ],
            ..RigidBodyOptions::default()
        },
        ..PlantOptions::default()
    }
}

/// The `dflat-sim` plant of `sitl.plant`.
fn plant_kind(p: SitlPlant) -> PlantKind {
    match p {
        SitlPlant::Planar => PlantKind::Planar,
        SitlPlant::Spatial => PlantKind::Spatial,
        SitlPlant::Full => PlantKind::RigidBody,
    }
}

/// Starts the SITL: binds its sockets, starts the plant and receive threads.
pub fn spawn(cfg: &SitlSettings, options: SitlOptions) -> Result<SitlHandle, SitlError> {
    let signing = sitl_signing(cfg, &options)?;
    let url = options.link.as_deref().unwrap_or(&cfg.sitl.url);
    let socket = bind("link", parse_udpin("link", url)?)?;
    let local_addr = socket.local_addr().map_err(|source| SitlError::Bind {
        what: "link",
        addr: parse_udpin("link", url).unwrap_or(SocketAddr::from(([0, 0, 0, 0], 0))),
        source,
    })?;
    let gcs_socket = match &options.gcs {
        Some(g) => Some(bind("gcs", parse_udpin("gcs", g)?)?),
        None => None,
    };
    let gcs_addr = gcs_socket.as_ref().and_then(|s| s.local_addr().ok());

    let core = SitlCore::new(cfg)?;
    let first = core.truth();
    let status = core.status();
    let truth_file = match &options.truth_csv {
        Some(path) => Some((path.clone(), create_truth_csv(path)?)),
        None => None,
    };
    let shared = Arc::new(Shared {
        start: Instant::now(),
        stop: AtomicBool::new(false),
        links: Links {
            vehicle: Arc::new(socket),
            gcs: gcs_socket.map(Arc::new),
            peers: Mutex::new(Peers::default()),
        },
        counters: Counters::default(),
        latency: latency::LatencyProbe::default(),
        published: Mutex::new(Published {
            status,
            truth: first,
            trace: Vec::new(),
        }),
    });
    let (inputs, inputs_rx) = std::sync::mpsc::channel();
    let own = (cfg.ids.system_id, cfg.ids.autopilot_component);

    let mut threads = Vec::new();

    let filter = SourceFilter {
        vehicle_system_id: cfg.ids.system_id,
        autopilot_component_id: cfg.ids.autopilot_component,
        own_component_id: cfg.ids.autopilot_component,
        gcs_system_ids: vec![cfg.ids.gcs_system_id],
        ..SourceFilter::default()
    };
    // The receive side verifies with its own copy (per-stream timestamps);
    // the plant thread's signs.
    let signed = signing.is_some();
    let mut link = LinkRx::new(filter);
    link.signing = signing.clone();
    let rx = VehicleRx {
        shared: shared.clone(),
        link,
        tap: options.tap.clone(),
        hover_thrust: cfg.sitl.hover_thrust,
        own,
        inputs: inputs.clone(),
    };
    // If a later thread cannot start, the earlier ones must stop.
    let stop_on_err = |e: SitlError| {
        shared.stop.store(true, Ordering::Relaxed);
        e
    };
    threads.push((
        "receive",
        spawn_thread("dflat-sitl-rx", move || rx.run()).map_err(stop_on_err)?,
    ));

    if let Some(gs) = shared.links.gcs.clone() {
        let gcs = GcsRx {
            shared: shared.clone(),
            socket: gs,
            own,
            inputs: inputs.clone(),
        };
        threads.push((
            "gcs",
            spawn_thread("dflat-sitl-gcs", move || gcs.run()).map_err(stop_on_err)?,
        ));
    }

    let sim = PlantLoop {
        shared: shared.clone(),
        core,
        inputs: inputs_rx,
        outbox: Outbox {
            shared: shared.clone(),
            signing,
            own,
            seq: 0,
        },
        record_trace: options.record_trace,
        truth_file,
    };
    threads.push((
        "plant",
        spawn_thread("dflat-sitl-plant", move || sim.run()).map_err(stop_on_err)?,
    ));

    tracing::info!(
        %local_addr,
        gcs = ?gcs_addr,
        plant = ?cfg.sitl.plant,
        signing = signed,
        "sitl started"
    );
    Ok(SitlHandle {
        shared,
        inputs,
        #[cfg(test)]
        signed,
        local_addr,
        gcs_addr,
        threads,
    })
}

fn spawn_thread(
    name: &'static str,
    f: impl FnOnce() -> Result<(), SitlError> + Send + 'static,
) -> Result<JoinHandle<Result<(), SitlError>>, SitlError> {
    std::thread::Builder::new()
        .name(name.into())
        .spawn(f)
        .map_err(|e| SitlError::Thread(name, e))
}

impl SitlHandle {
    /// Where the vehicle link listens (the port is real even if 0 was asked).
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Where the ground-station port listens, if there is one.
    pub fn gcs_addr(&self) -> Option<SocketAddr> {
        self.gcs_addr
    }

    /// The latest true state (telemetry rate).
    pub fn truth(&self) -> TruthSample {
        lock(&self.shared.published).truth
    }

    /// A copy of the truth trace so far (empty unless recorded).
    pub fn trace(&self) -> Vec<TruthSample> {
        lock(&self.shared.published).trace.clone()
    }

    /// The status after the latest plant step.
    fn status(&self) -> SitlStatus {
        lock(&self.shared.published).status
    }

    /// Passes `input` to the plant thread's next step (dropped once it
    /// has stopped).
    fn hook(&self, input: SitlInput) {
        // A closed channel only means the plant thread has stopped.
        let _ = self.inputs.send(input);
    }

    /// The counters now.
    pub fn counters(&self) -> SitlCounters {
        self.shared
            .counters
            .snapshot(self.shared.latency.snapshot())
    }

    /// Drops the next `n` LOCAL_POSITION_NED from the next plant step
    /// (one-shot; ATTITUDE goes on).
    pub fn drop_next_poses(&self, n: u32) {
        self.hook(SitlInput::DropNextPoses(n));
    }

    /// Sends the next LOCAL_POSITION_NED `delay` late (one-shot; to the
    /// plant step's resolution).
    pub fn delay_next_pose(&self, delay: Duration) {
        self.hook(SitlInput::DelayNextPose(delay.as_secs_f64()));
    }

    /// The current mode (as of the latest plant step).
    pub fn mode(&self) -> SitlMode {
        self.status().mode
    }

    /// Seconds since the SITL started (its `time_boot_ms` clock).
    pub fn elapsed(&self) -> f64 {
        self.shared.start.elapsed().as_secs_f64()
    }

    /// The pilot switches modes at the next plant step: to position mode
    /// (an override) or to offboard (engage / hand back; refused without a
    /// live stream, [`SitlCounters::offboard_refused`]).
    pub fn request_mode(&self, mode: SitlMode) {
        self.hook(SitlInput::ModeRequest(mode));
    }

    /// The pilot's stick: fly at `velocity` (local NED \[m/s\]) in position
    /// mode from the next plant step (`[0, 0, 0]`: brake and hold).
    pub fn set_pilot_velocity(&self, velocity: [f64; 3]) {
        self.hook(SitlInput::PilotVelocity(velocity));
    }

    /// Stops the pose stream (LOCAL_POSITION_NED and ATTITUDE) from the
    /// next plant step; HEARTBEAT and the plant go on.
    pub fn pause_pose(&self) {
        self.hook(SitlInput::PausePose(true));
    }

    /// Resumes the pose stream from the next plant step.
    pub fn resume_pose(&self) {
        self.hook(SitlInput::PausePose(false));
    }

    /// Position setpoints addressed to the autopilot accepted so far
    /// (flown in OFFBOARD by the SITL's position loop).
    pub fn position_setpoints_accepted(&self) -> u64 {
        self.status().setpoints_accepted
    }

    /// Whether the vehicle is armed (disarm is accepted over MAVLink).
    pub fn armed(&self) -> bool {
        self.status().armed
    }

    /// Whether the pose stream is paused (as of the latest plant step).
    pub fn pose_paused(&self) -> bool {
        self.status().pose_paused
    }

    /// Adds `offset` (NED \[m\]) to every reported position from the next
    /// plant step on: a pose jump as an estimator reset would cause. The
    /// truth is unchanged.
    pub fn set_pose_offset(&self, offset: [f64; 3]) {
        self.hook(SitlInput::PoseOffset(offset));
    }

    /// True when the plant state became non-finite.
    pub fn diverged(&self) -> bool {
        self.status().diverged
    }

    /// Asks the threads to stop without waiting.
    pub fn request_stop(&self) {
        self.shared.stop.store(true, Ordering::Relaxed);
    }

    /// Stops the SITL, waits for its threads, flushes the truth CSV and
    /// returns the report.
    pub fn stop(mut self) -> Result<SitlReport, SitlError> {
        self.request_stop();
        let mut first_error = None;
        for (name, t) in self.threads.drain(..) {
            let r = t.join().unwrap_or(Err(SitlError::Panicked(name)));
            if let Err(e) = r {
                first_error.get_or_insert(e);
            }
        }
        if let Some(e) = first_error {
            return Err(e);
        }
        let mut published = lock(&self.shared.published);
        let (status, last) = (published.status, published.truth);
        let trace = std::mem::take(&mut published.trace);
        drop(published);
        Ok(SitlReport {
            counters: self.counters(),
            trace,
            last,
            diverged: status.diverged,
            planner_start: status.planner_start,
        })
    }
}

impl Drop for SitlHandle {
    fn drop(&mut self) {
        self.request_stop();
    }
}

#[cfg(test)]
mod tests;
