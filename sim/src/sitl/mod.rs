//! The SITL autopilot stand-in: a real-time plant behind a MAVLink link.
//!
//! What a flight controller (PX4 in offboard, ArduPilot in GUIDED_NOGPS)
//! looks like to the daemon, built from the lab's plants and sensing:
//!
//! * a plant thread integrates one of `dflat-sim`'s plants
//!   ([`PlanarPlant`](crate::plant::PlanarPlant),
//!   [`SpatialPlant`](crate::plant::SpatialPlant),
//!   [`RigidBodyPlant`](crate::plant::RigidBodyPlant), chosen by
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
//!   messages (HEARTBEAT, …) are still accepted, as the daemon's
//!   `link.signing_accept_unsigned_telemetry = true` does — looser than
//!   ArduPilot, which with signing on accepts unsigned frames only of
//!   RADIO_STATUS or on its USB channel. A dropped frame is not routed to
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
//! In-process hooks ([`SitlHandle`]): the true state and an optional trace,
//! one-shot pose faults and the pose → command latency ([`PoseLatency`]),
//! counters, the current mode, a tap of every received frame, a pose pause
//! switch (the pose stream stops, HEARTBEAT goes on) and a pose offset (an
//! estimator jump as the daemon sees it). `dflat sitl` (the binary crate's shell) maps
//! SIGUSR1 / SIGUSR2 to pause / resume and prints its bound addresses and
//! mode changes on stdout.

use std::f64::consts::PI;
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use crate::plant::{Plant, PlantKind, PlantOptions, PlantState, build_plant};
use crate::sensing::{GaussianOptions, GaussianSensor, Sensor};
use dflat_control::AttitudeCommand as PlantCommand;
use dflat_link::dialect::{MavAutopilot, MavState};
use dflat_link::{
    Frame, Inbound, LinkRx, MavHeader, MavMessage, RxOutcome, Signing, SourceFilter,
    euler_from_quaternion, frames, serialize_v2, timestamp_from_system_time,
};
use nalgebra::Vector3;
use thiserror::Error;

use dflat_link::transport::Endpoint;

mod config;
mod latency;
pub mod pilot;
pub use config::{SitlAutopilot, SitlConfig, SitlConfigError, SitlIds, SitlPlant, SitlSettings};
pub use latency::PoseLatency;
pub use pilot::{ModeMachine, PilotAction, PilotMode, SitlEngage};

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
/// ArduPilot Copter GUIDED_NOGPS, reported in offboard mode.
pub const ARDUPILOT_MODE_GUIDED_NOGPS: u32 = 20;
/// Deceleration the position mode brakes at when it takes over \[m/s²\]
/// (its stop point is held, not the point where it took over).
const HOLD_BRAKE: f64 = 2.5;

/// Horizontal gains of the hold loop: `a = KP·(p_hold − p) − KD·v`. With the
/// 0.2 s attitude lag the closed loop is well damped (≈ 1 rad/s).
const HOLD_KP: f64 = 1.0;
const HOLD_KD: f64 = 1.6;
/// Vertical gains of the hold loop (spatial and full plants).
const HOLD_KP_Z: f64 = 2.0;
const HOLD_KD_Z: f64 = 2.5;
/// Tilt the hold loop asks for at most \[deg\].
const HOLD_MAX_TILT_DEG: f64 = 20.0;
/// Read timeout of the receive threads: how fast they notice a stop.
const RX_POLL: Duration = Duration::from_millis(50);
/// Truth rows buffered between flushes of the truth CSV.
const CSV_FLUSH_ROWS: u64 = 25;

/// Why the SITL could not start or finish.
#[derive(Debug, Error)]
pub enum SitlError {
    /// The connection string is not `udpin:HOST:PORT`.
    #[error("{what}: `{url}` is not a SITL endpoint (the SITL listens: udpin:HOST:PORT)")]
    Endpoint {
        /// Which endpoint (`link` or `gcs`).
        what: &'static str,
        /// The string given.
        url: String,
    },
    /// A socket could not be bound or configured.
    #[error("{what}: cannot listen on {addr}: {source}")]
    Bind {
        /// Which endpoint.
        what: &'static str,
        /// The address.
        addr: SocketAddr,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The plant options were refused by the lab.
    #[error("sitl plant: {0}")]
    Plant(#[from] crate::SimError),
    /// The truth CSV could not be created or written.
    #[error("truth CSV {file}: {source}")]
    Truth {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A SITL thread could not be started.
    #[error("cannot start the {0} thread: {1}")]
    Thread(&'static str, std::io::Error),
    /// A SITL thread panicked (a bug).
    #[error("the SITL {0} thread panicked")]
    Panicked(&'static str),
    /// `sitl.signing_key_file` is refused (mode, owner, contents).
    #[error("sitl.signing_key_file = {file}: {reason}")]
    SigningKey {
        /// The key file.
        file: PathBuf,
        /// Why, in words.
        reason: String,
    },
}

/// The SITL's signing link id (the daemon's default is 0).
pub const SIGNING_LINK_ID: u8 = 1;

/// What the autopilot stand-in is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SitlMode {
    /// Holding position on its own (start, and after a command timeout).
    Hold,
    /// Following SET_ATTITUDE_TARGET.
    Offboard,
}

impl SitlMode {
    /// Lower-case name, as printed and written to the truth CSV.
    pub fn as_str(self) -> &'static str {
        match self {
            SitlMode::Hold => "hold",
            SitlMode::Offboard => "offboard",
        }
    }

    /// HEARTBEAT `custom_mode` as `autopilot` reports it: PX4 POSCTL /
    /// OFFBOARD, ArduPilot LOITER (5) / GUIDED_NOGPS (20).
    pub fn custom_mode(self, autopilot: SitlAutopilot) -> u32 {
        match (autopilot, self) {
            (SitlAutopilot::Px4, SitlMode::Hold) => PX4_MODE_POSCTL,
            (SitlAutopilot::Px4, SitlMode::Offboard) => PX4_MODE_OFFBOARD,
            (SitlAutopilot::Ardupilot, SitlMode::Hold) => ARDUPILOT_MODE_LOITER,
            (SitlAutopilot::Ardupilot, SitlMode::Offboard) => ARDUPILOT_MODE_GUIDED_NOGPS,
        }
    }

    fn from_u8(v: u8) -> Self {
        if v == 1 {
            SitlMode::Offboard
        } else {
            SitlMode::Hold
        }
    }
}

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

/// Counters of a SITL run (a snapshot).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SitlCounters {
    /// HEARTBEATs sent on the vehicle link.
    pub heartbeats_sent: u64,
    /// LOCAL_POSITION_NED sent on the vehicle link.
    pub positions_sent: u64,
    /// VISION_POSITION_ESTIMATE sent on the vehicle link (`sitl.vision_rate_hz`).
    pub visions_sent: u64,
    /// ATTITUDE sent on the vehicle link.
    pub attitudes_sent: u64,
    /// Frames received on the vehicle link (valid CRC).
    pub frames_received: u64,
    /// SET_ATTITUDE_TARGET accepted.
    pub commands_accepted: u64,
    /// SET_ATTITUDE_TARGET from a wrong source or addressed elsewhere.
    pub commands_ignored: u64,
    /// SET_ATTITUDE_TARGET trusted but invalid (non-finite, bad quaternion, type_mask).
    pub commands_rejected: u64,
    /// Signing on: SET_ATTITUDE_TARGET refused for a missing, wrong or
    /// replayed signature (not applied).
    pub commands_unauthenticated: u64,
    /// Framing errors (CRC, unknown id, truncation) on either link.
    pub frame_errors: u64,
    /// Frames received from the ground station.
    pub gcs_frames_in: u64,
    /// Frames sent to the ground station (routed and own telemetry).
    pub gcs_frames_out: u64,
    /// Entries into the hold mode after commanded flight.
    pub hold_entries: u64,
    /// Mode changes (position ⇄ offboard).
    pub mode_changes: u64,
    /// Requests for offboard refused because no stream was alive.
    pub offboard_refused: u64,
    /// Plant integration steps.
    pub plant_steps: u64,
    /// Plant steps that ran late (the thread missed its deadline).
    pub late_steps: u64,
    /// Failed socket sends.
    pub send_errors: u64,
    /// Pose departure → command arrival and the command cadence
    /// (see [`PoseLatency`]).
    pub pose_latency: PoseLatency,
}

#[derive(Default)]
struct Counters {
    heartbeats_sent: AtomicU64,
    positions_sent: AtomicU64,
    visions_sent: AtomicU64,
    attitudes_sent: AtomicU64,
    frames_received: AtomicU64,
    commands_accepted: AtomicU64,
    commands_ignored: AtomicU64,
    commands_rejected: AtomicU64,
    commands_unauthenticated: AtomicU64,
    frame_errors: AtomicU64,
    gcs_frames_in: AtomicU64,
    gcs_frames_out: AtomicU64,
    hold_entries: AtomicU64,
    mode_changes: AtomicU64,
    offboard_refused: AtomicU64,
    plant_steps: AtomicU64,
    late_steps: AtomicU64,
    send_errors: AtomicU64,
}

fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

impl Counters {
    fn snapshot(&self) -> SitlCounters {
        let g = |c: &AtomicU64| c.load(Ordering::Relaxed);
        SitlCounters {
            heartbeats_sent: g(&self.heartbeats_sent),
            positions_sent: g(&self.positions_sent),
            visions_sent: g(&self.visions_sent),
            attitudes_sent: g(&self.attitudes_sent),
            frames_received: g(&self.frames_received),
            commands_accepted: g(&self.commands_accepted),
            commands_ignored: g(&self.commands_ignored),
            commands_rejected: g(&self.commands_rejected),
            commands_unauthenticated: g(&self.commands_unauthenticated),
            frame_errors: g(&self.frame_errors),
            gcs_frames_in: g(&self.gcs_frames_in),
            gcs_frames_out: g(&self.gcs_frames_out),
            hold_entries: g(&self.hold_entries),
            mode_changes: g(&self.mode_changes),
            offboard_refused: g(&self.offboard_refused),
            plant_steps: g(&self.plant_steps),
            late_steps: g(&self.late_steps),
            send_errors: g(&self.send_errors),
            pose_latency: PoseLatency::default(),
        }
    }
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
}

#[derive(Default)]
struct Peers {
    vehicle: Option<SocketAddr>,
    gcs: Option<SocketAddr>,
}

struct Shared {
    start: Instant,
    stop: AtomicBool,
    pose_paused: AtomicBool,
    diverged: AtomicBool,
    mode: AtomicU8,
    seq: AtomicU8,
    system_id: u8,
    component_id: u8,
    pose_offset: Mutex<[f64; 3]>,
    truth: Mutex<TruthSample>,
    trace: Mutex<Vec<TruthSample>>,
    command: Mutex<Option<(Instant, ReceivedCommand)>>,
    /// A mode request from the in-process hook, taken by the plant loop.
    mode_request: Mutex<Option<SitlMode>>,
    /// A stick velocity from the in-process hook, taken by the plant loop.
    pilot_velocity: Mutex<Option<[f64; 3]>>,
    peers: Mutex<Peers>,
    counters: Counters,
    /// Pose → command latency, one-shot pose faults.
    latency: latency::LatencyProbe,
    /// Signing of outgoing frames (`None` = unsigned). Shared because any
    /// thread may send the SITL's own frames.
    signing: Option<Mutex<Signing>>,
}

/// Locks a mutex, recovering the data if a thread panicked while holding it.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Shared {
    fn header(&self) -> MavHeader {
        dflat_link::header(
            self.system_id,
            self.component_id,
            self.seq.fetch_add(1, Ordering::Relaxed),
        )
    }

    fn elapsed(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// `msg` as an outgoing frame of the SITL: signed when signing is on.
    fn encode(&self, msg: &MavMessage) -> Result<dflat_link::EncodedFrame, dflat_link::LinkError> {
        let header = self.header();
        match &self.signing {
            Some(s) => {
                let now = timestamp_from_system_time(SystemTime::now());
                lock(s).sign(&header, msg, now)
            }
            None => serialize_v2(&header, msg),
        }
    }
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
/// command delay, mass factor, ±35° saturation, g = 9.81 m/s².
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
        ..PlantOptions::default()
    }
}

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

    let popts = plant_options(cfg);
    let mut plant = build_plant(plant_kind(cfg.sitl.plant), &popts, cfg.sitl.seed)?;
    let start = Vector3::from(cfg.sitl.start);
    plant.reset(&PlantState::hover(start, GRAVITY));
    let sensor = GaussianSensor::new(
        GaussianOptions::isotropic(cfg.sitl.noise_sigma),
        cfg.sitl.seed,
    )?;
    let vision = if cfg.sitl.vision_rate_hz > 0.0 {
        Some(VisionStream {
            sensor: GaussianSensor::new(
                GaussianOptions::isotropic(cfg.sitl.vision_noise_sigma),
                cfg.sitl.seed ^ VISION_SEED,
            )?,
            period: 1.0 / cfg.sitl.vision_rate_hz,
            latency: cfg.sitl.vision_latency_ms / 1000.0,
            next_capture: 1.0 / cfg.sitl.vision_rate_hz,
            pending: std::collections::VecDeque::with_capacity(VISION_QUEUE),
        })
    } else {
        None
    };

    let truth_file = match &options.truth_csv {
        Some(path) => Some((path.clone(), create_truth_csv(path)?)),
        None => None,
    };

    let first = TruthSample {
        t: 0.0,
        position: cfg.sitl.start,
        velocity: [0.0; 3],
        euler: [0.0; 3],
        command: None,
        mode: SitlMode::Hold,
    };
    let shared = Arc::new(Shared {
        start: Instant::now(),
        stop: AtomicBool::new(false),
        pose_paused: AtomicBool::new(false),
        diverged: AtomicBool::new(false),
        mode: AtomicU8::new(0),
        seq: AtomicU8::new(0),
        system_id: cfg.ids.system_id,
        component_id: cfg.ids.autopilot_component,
        pose_offset: Mutex::new([0.0; 3]),
        truth: Mutex::new(first),
        trace: Mutex::new(Vec::new()),
        command: Mutex::new(None),
        mode_request: Mutex::new(None),
        pilot_velocity: Mutex::new(None),
        peers: Mutex::new(Peers::default()),
        counters: Counters::default(),
        latency: latency::LatencyProbe::default(),
        signing: signing.clone().map(Mutex::new),
    });

    let socket = Arc::new(socket);
    let gcs_socket = gcs_socket.map(Arc::new);
    let mut threads = Vec::new();

    let filter = SourceFilter {
        vehicle_system_id: cfg.ids.system_id,
        autopilot_component_id: cfg.ids.autopilot_component,
        own_component_id: cfg.ids.autopilot_component,
        gcs_system_id: cfg.ids.gcs_system_id,
        ..SourceFilter::default()
    };
    // The receive side verifies with its own copy (per-stream timestamps);
    // the shared one signs.
    let mut link = LinkRx::new(filter);
    link.signing = signing;
    let rx = VehicleRx {
        shared: shared.clone(),
        socket: socket.clone(),
        gcs_socket: gcs_socket.clone(),
        link,
        tap: options.tap.clone(),
        hover_thrust: cfg.sitl.hover_thrust,
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

    if let Some(gs) = gcs_socket.clone() {
        let gcs = GcsRx {
            shared: shared.clone(),
            socket: gs,
            vehicle_socket: socket.clone(),
        };
        threads.push((
            "gcs",
            spawn_thread("dflat-sitl-gcs", move || gcs.run()).map_err(stop_on_err)?,
        ));
    }

    let sim = PlantLoop {
        shared: shared.clone(),
        socket,
        gcs_socket,
        plant,
        sensor,
        vision,
        options: popts,
        plant_rate_hz: cfg.sitl.plant_rate_hz,
        telemetry_rate_hz: cfg.sitl.telemetry_rate_hz,
        command_timeout: Duration::from_secs_f64(cfg.sitl.command_timeout_s),
        hover_thrust: cfg.sitl.hover_thrust,
        autopilot: cfg.sitl.autopilot,
        modes: ModeMachine::new(cfg.sitl.engage, cfg.sitl.pilot.clone()),
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
        signing = shared.signing.is_some(),
        "sitl started"
    );
    Ok(SitlHandle {
        shared,
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

fn create_truth_csv(path: &Path) -> Result<BufWriter<File>, SitlError> {
    let err = |source| SitlError::Truth {
        file: path.to_owned(),
        source,
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(err)?;
    }
    let mut w = BufWriter::new(File::create(path).map_err(err)?);
    writeln!(
        w,
        "t,x,y,z,vx,vy,vz,roll,pitch,yaw,cmd_roll,cmd_pitch,cmd_yaw,cmd_thrust,mode"
    )
    .map_err(err)?;
    Ok(w)
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
        *lock(&self.shared.truth)
    }

    /// A copy of the truth trace so far (empty unless recorded).
    pub fn trace(&self) -> Vec<TruthSample> {
        lock(&self.shared.trace).clone()
    }

    /// The counters now.
    pub fn counters(&self) -> SitlCounters {
        let mut c = self.shared.counters.snapshot();
        c.pose_latency = self.shared.latency.snapshot();
        c
    }

    /// Drops the next `n` LOCAL_POSITION_NED (one-shot; ATTITUDE goes on).
    pub fn drop_next_poses(&self, n: u32) {
        self.shared.latency.drop_next(n);
    }

    /// Sends the next LOCAL_POSITION_NED `delay` late (one-shot; to the
    /// plant step's resolution).
    pub fn delay_next_pose(&self, delay: Duration) {
        self.shared.latency.delay_next(delay);
    }

    /// The current mode.
    pub fn mode(&self) -> SitlMode {
        SitlMode::from_u8(self.shared.mode.load(Ordering::Relaxed))
    }

    /// Seconds since the SITL started (its `time_boot_ms` clock).
    pub fn elapsed(&self) -> f64 {
        self.shared.elapsed()
    }

    /// The pilot switches modes at the next plant step: to position mode
    /// (an override) or to offboard (engage / hand back; refused without a
    /// live stream, [`SitlCounters::offboard_refused`]).
    pub fn request_mode(&self, mode: SitlMode) {
        *lock(&self.shared.mode_request) = Some(mode);
    }

    /// The pilot's stick: fly at `velocity` (local NED \[m/s\]) in position
    /// mode from the next plant step (`[0, 0, 0]`: brake and hold).
    pub fn set_pilot_velocity(&self, velocity: [f64; 3]) {
        *lock(&self.shared.pilot_velocity) = Some(velocity);
    }

    /// Stops the pose stream (LOCAL_POSITION_NED and ATTITUDE); HEARTBEAT
    /// and the plant go on.
    pub fn pause_pose(&self) {
        self.shared.pose_paused.store(true, Ordering::Relaxed);
    }

    /// Resumes the pose stream.
    pub fn resume_pose(&self) {
        self.shared.pose_paused.store(false, Ordering::Relaxed);
    }

    /// Whether the pose stream is paused.
    pub fn pose_paused(&self) -> bool {
        self.shared.pose_paused.load(Ordering::Relaxed)
    }

    /// Adds `offset` (NED \[m\]) to every reported position from now on: a
    /// pose jump as an estimator reset would cause. The truth is unchanged.
    pub fn set_pose_offset(&self, offset: [f64; 3]) {
        *lock(&self.shared.pose_offset) = offset;
    }

    /// True when the plant state became non-finite.
    pub fn diverged(&self) -> bool {
        self.shared.diverged.load(Ordering::Relaxed)
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
        Ok(SitlReport {
            counters: self.counters(),
            trace: std::mem::take(&mut *lock(&self.shared.trace)),
            last: self.truth(),
            diverged: self.diverged(),
        })
    }
}

impl Drop for SitlHandle {
    fn drop(&mut self) {
        self.request_stop();
    }
}

/// Sends `msg` from the SITL to the vehicle peer and the GCS peer (signed
/// when signing is on).
fn send_own(
    shared: &Shared,
    socket: &UdpSocket,
    gcs_socket: Option<&UdpSocket>,
    msg: &MavMessage,
) -> bool {
    let frame = match shared.encode(msg) {
        Ok(f) => f,
        Err(_) => {
            bump(&shared.counters.send_errors);
            return false;
        }
    };
    let (vehicle, gcs) = {
        let p = lock(&shared.peers);
        (p.vehicle, p.gcs)
    };
    let mut sent = false;
    if let Some(peer) = vehicle {
        match socket.send_to(frame.as_bytes(), peer) {
            Ok(_) => sent = true,
            Err(_) => bump(&shared.counters.send_errors),
        }
    }
    if let (Some(gs), Some(peer)) = (gcs_socket, gcs)
        && gs.send_to(frame.as_bytes(), peer).is_ok()
    {
        bump(&shared.counters.gcs_frames_out);
    }
    sent
}

/// Receives on the vehicle link: commands in, routing to the GCS.
struct VehicleRx {
    shared: Arc<Shared>,
    socket: Arc<UdpSocket>,
    gcs_socket: Option<Arc<UdpSocket>>,
    link: LinkRx,
    tap: Option<Sender<TapFrame>>,
    hover_thrust: f64,
}

impl VehicleRx {
    fn run(mut self) -> Result<(), SitlError> {
        let mut buf = vec![0u8; 65_536];
        let mut forward = Vec::with_capacity(4096);
        while !self.shared.stop.load(Ordering::Relaxed) {
            let (n, from) = match self.socket.recv_from(&mut buf) {
                Ok(x) => x,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                            | std::io::ErrorKind::ConnectionRefused
                            | std::io::ErrorKind::ConnectionReset
                    ) =>
                {
                    continue;
                }
                Err(e) => {
                    tracing::warn!(error = %e, "sitl: receive failed");
                    std::thread::sleep(RX_POLL);
                    continue;
                }
            };
            let at = Instant::now();
            lock(&self.shared.peers).vehicle = Some(from);
            forward.clear();
            for item in frames(&buf[..n]) {
                let frame = match item {
                    Ok(f) => f,
                    Err(e) => {
                        bump(&self.shared.counters.frame_errors);
                        tracing::debug!(error = %e, "sitl: bad frame");
                        continue;
                    }
                };
                bump(&self.shared.counters.frames_received);
                if let Some(tap) = &self.tap {
                    // A closed tap only means nobody listens any more.
                    let _ = tap.send(TapFrame {
                        at,
                        header: frame.header,
                        message: frame.message.clone(),
                    });
                }
                if !self.authenticate(&frame) {
                    continue;
                }
                self.handle(at, &frame.header, &frame.message);
                if self.gcs_socket.is_some() && !self.addressed_to_autopilot(&frame.message) {
                    append_routed(&mut forward, &frame);
                }
            }
            if !forward.is_empty()
                && let Some(gs) = &self.gcs_socket
            {
                let peer = lock(&self.shared.peers).gcs;
                if let Some(peer) = peer
                    && gs.send_to(&forward, peer).is_ok()
                {
                    bump(&self.shared.counters.gcs_frames_out);
                }
            }
        }
        Ok(())
    }

    /// The signing gate ([`LinkRx::authenticate`]): `true` to go on with
    /// the frame. With signing off everything passes; with signing on a
    /// wrong signature or a replayed timestamp is refused for every
    /// message, a missing one for commands (and for everything if the
    /// signing's `accept_unsigned_telemetry` is off). A refused
    /// SET_ATTITUDE_TARGET is counted in `commands_unauthenticated`.
    fn authenticate(&mut self, frame: &Frame) -> bool {
        if self.link.signing.is_none() {
            return true;
        }
        let now = timestamp_from_system_time(SystemTime::now());
        match self
            .link
            .authenticate(&frame.header, &frame.message, frame.signed.as_ref(), now)
        {
            Ok(()) => true,
            Err(check) => {
                if matches!(frame.message, MavMessage::SET_ATTITUDE_TARGET(_)) {
                    bump(&self.shared.counters.commands_unauthenticated);
                    tracing::debug!(?check, "sitl: command refused by signing");
                }
                false
            }
        }
    }

    /// True for messages addressed to this autopilot specifically (not routed on).
    fn addressed_to_autopilot(&self, msg: &MavMessage) -> bool {
        use dflat_link::mavlink::Message as _;
        msg.target_system_id() == Some(self.shared.system_id)
            && msg.target_component_id() == Some(self.shared.component_id)
    }

    fn handle(&mut self, at: Instant, header: &MavHeader, msg: &MavMessage) {
        let is_command = matches!(msg, MavMessage::SET_ATTITUDE_TARGET(_));
        match self.link.handle(header, msg) {
            RxOutcome::Accepted(Inbound::AttitudeTarget(t)) => {
                let Some(q) = t.q else {
                    bump(&self.shared.counters.commands_rejected);
                    return;
                };
                let [roll, pitch, yaw] = euler_from_quaternion(q);
                let thrust = t.thrust.unwrap_or(self.hover_thrust);
                if !(roll.is_finite() && pitch.is_finite() && yaw.is_finite()) {
                    bump(&self.shared.counters.commands_rejected);
                    return;
                }
                *lock(&self.shared.command) = Some((
                    at,
                    ReceivedCommand {
                        roll,
                        pitch,
                        yaw,
                        thrust: thrust.clamp(0.0, 1.0),
                    },
                ));
                bump(&self.shared.counters.commands_accepted);
                self.shared.latency.command(at);
            }
            RxOutcome::Accepted(_) => {}
            RxOutcome::Ignored(_) if is_command => bump(&self.shared.counters.commands_ignored),
            RxOutcome::Rejected(e) if is_command => {
                tracing::debug!(error = %e, "sitl: command rejected");
                bump(&self.shared.counters.commands_rejected);
            }
            RxOutcome::Ignored(_) | RxOutcome::Rejected(_) => {}
        }
    }
}

/// Appends a received frame to a datagram being routed on: a signed frame
/// as its bytes (re-serializing would strip the signature), an unsigned one
/// re-serialized as MAVLink 2.
fn append_routed(out: &mut Vec<u8>, frame: &Frame) {
    match &frame.signed {
        Some(signed) => out.extend_from_slice(signed.as_bytes()),
        None => {
            if let Ok(enc) = serialize_v2(&frame.header, &frame.message) {
                out.extend_from_slice(enc.as_bytes());
            }
        }
    }
}

/// Receives on the GCS port and routes to the vehicle link.
struct GcsRx {
    shared: Arc<Shared>,
    socket: Arc<UdpSocket>,
    vehicle_socket: Arc<UdpSocket>,
}

impl GcsRx {
    fn run(self) -> Result<(), SitlError> {
        let mut buf = vec![0u8; 65_536];
        let mut forward = Vec::with_capacity(4096);
        while !self.shared.stop.load(Ordering::Relaxed) {
            let (n, from) = match self.socket.recv_from(&mut buf) {
                Ok(x) => x,
                Err(_) => continue,
            };
            lock(&self.shared.peers).gcs = Some(from);
            forward.clear();
            for item in frames(&buf[..n]) {
                match item {
                    Ok(f) => {
                        bump(&self.shared.counters.gcs_frames_in);
                        append_routed(&mut forward, &f);
                    }
                    Err(_) => bump(&self.shared.counters.frame_errors),
                }
            }
            let peer = lock(&self.shared.peers).vehicle;
            if let Some(peer) = peer
                && !forward.is_empty()
                && self.vehicle_socket.send_to(&forward, peer).is_err()
            {
                bump(&self.shared.counters.send_errors);
            }
        }
        Ok(())
    }
}

/// Seed offset of the vision stand-in's noise (independent of the
/// LOCAL_POSITION_NED noise).
const VISION_SEED: u64 = 0x5649_5349_4f4e;
/// Vision samples in flight at most (latency × rate; older ones dropped).
const VISION_QUEUE: usize = 256;

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
    pending: std::collections::VecDeque<(f64, [f64; 3], [f64; 3])>,
}

/// The real-time plant loop: integrate, command or hold, send telemetry.
struct PlantLoop {
    shared: Arc<Shared>,
    socket: Arc<UdpSocket>,
    gcs_socket: Option<Arc<UdpSocket>>,
    plant: Box<dyn Plant>,
    sensor: GaussianSensor,
    vision: Option<VisionStream>,
    options: PlantOptions,
    plant_rate_hz: f64,
    telemetry_rate_hz: f64,
    command_timeout: Duration,
    hover_thrust: f64,
    autopilot: SitlAutopilot,
    modes: ModeMachine,
    record_trace: bool,
    truth_file: Option<(PathBuf, BufWriter<File>)>,
}

impl PlantLoop {
    fn run(mut self) -> Result<(), SitlError> {
        let dt = 1.0 / self.plant_rate_hz;
        let telemetry_every = (self.plant_rate_hz / self.telemetry_rate_hz)
            .round()
            .max(1.0) as u64;
        let heartbeat_every = self.plant_rate_hz.round().max(1.0) as u64;
        let start = self.shared.start;
        let mut steps: u64 = 0;
        let mut mode = SitlMode::Hold;
        let mut hold_target = self.plant.position();
        let mut rows: u64 = 0;
        let mut csv_error = None;
        let t0 = self.plant.true_state();
        self.sensor.reset(0.0, &t0);
        // First heartbeat right away (sent once a peer is known).
        let mut heartbeat_due = true;

        while !self.shared.stop.load(Ordering::Relaxed) {
            let next = start + Duration::from_secs_f64((steps + 1) as f64 * dt);
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            }
            let elapsed = start.elapsed().as_secs_f64();
            let due = (elapsed / dt).floor() as u64;
            let n = due.saturating_sub(steps).max(1);
            if n > 1 {
                self.shared
                    .counters
                    .late_steps
                    .fetch_add(n - 1, Ordering::Relaxed);
            }
            let before = steps;

            // The mode (pilot, stream), then the command or the hold.
            let received = (*lock(&self.shared.command))
                .filter(|(at, _)| at.elapsed() < self.command_timeout)
                .map(|(_, c)| c);
            if let Some(v) = lock(&self.shared.pilot_velocity).take() {
                self.modes.set_velocity(v);
            }
            let request = lock(&self.shared.mode_request).take();
            let elapsed_t = steps as f64 * dt;
            let step = self.modes.step(elapsed_t, received.is_some(), request);
            if step.refused {
                bump(&self.shared.counters.offboard_refused);
                tracing::warn!("sitl: offboard refused, no setpoint stream");
                let text = dflat_link::statustext(
                    dflat_link::dialect::MavSeverity::MAV_SEVERITY_WARNING,
                    "SITL: offboard refused, no setpoint stream",
                );
                self.send(&text);
            }
            if step.changed {
                mode = self.modes.mode();
                bump(&self.shared.counters.mode_changes);
                heartbeat_due = true;
                if mode == SitlMode::Hold {
                    // Brake and hold where the vehicle stops.
                    let s = self.plant.true_state();
                    let v = s.velocity;
                    hold_target = s.position + v * (v.norm() / (2.0 * HOLD_BRAKE));
                    bump(&self.shared.counters.hold_entries);
                    tracing::info!(stream = received.is_some(), "sitl: position mode");
                } else {
                    tracing::info!("sitl: offboard");
                }
            }
            let fresh = received.filter(|_| mode == SitlMode::Offboard);
            let command = match fresh {
                Some(c) => self.plant_command(&c),
                None => {
                    let v = Vector3::from(self.modes.velocity());
                    hold_target += v * (n as f64 * dt);
                    self.hold_command(&hold_target, &v)
                }
            };
            self.shared
                .mode
                .store(u8::from(mode == SitlMode::Offboard), Ordering::Relaxed);
            self.plant.apply(&command);
            self.plant.advance(n as f64 * dt);
            steps += n;
            self.shared
                .counters
                .plant_steps
                .fetch_add(n, Ordering::Relaxed);

            let mut state = self.plant.true_state();
            if !state.is_finite() {
                if !self.shared.diverged.swap(true, Ordering::Relaxed) {
                    tracing::error!("sitl: plant state is not finite; resetting to hover");
                }
                self.plant.reset(&PlantState::hover(hold_target, GRAVITY));
                state = self.plant.true_state();
            }
            let t = steps as f64 * dt;
            if let Some(msg) = self.shared.latency.due_delayed(Instant::now())
                && self.send(&msg)
            {
                self.pose_sent();
            }
            self.sensor.observe(t, &state);
            self.vision(t, &state);

            if before / heartbeat_every != steps / heartbeat_every {
                heartbeat_due = true;
            }
            if heartbeat_due {
                let autopilot = match self.autopilot {
                    SitlAutopilot::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
                    SitlAutopilot::Ardupilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                };
                let hb = dflat_link::heartbeat_autopilot(
                    autopilot,
                    true,
                    mode.custom_mode(self.autopilot),
                    MavState::MAV_STATE_ACTIVE,
                );
                if self.send(&hb) {
                    bump(&self.shared.counters.heartbeats_sent);
                }
                // Due once per slot, whoever listens: a ground station
                // alone on the GCS port gets 1 Hz, not the plant rate.
                heartbeat_due = false;
            }
            if before / telemetry_every != steps / telemetry_every {
                let sample = TruthSample {
                    t,
                    position: state.position.into(),
                    velocity: state.velocity.into(),
                    euler: [state.roll, state.pitch, state.yaw],
                    command: fresh,
                    mode,
                };
                self.telemetry(&sample, &state);
                *lock(&self.shared.truth) = sample;
                if self.record_trace {
                    lock(&self.shared.trace).push(sample);
                }
                if let Some((path, w)) = &mut self.truth_file {
                    let r = write_truth_row(w, &sample).and_then(|()| {
                        rows += 1;
                        if rows.is_multiple_of(CSV_FLUSH_ROWS) {
                            w.flush()
                        } else {
                            Ok(())
                        }
                    });
                    if let Err(source) = r {
                        // Keep flying without the record; report at stop.
                        tracing::error!(file = %path.display(), error = %source, "sitl: truth CSV write failed; no more rows");
                        csv_error = Some(SitlError::Truth {
                            file: path.clone(),
                            source,
                        });
                        self.truth_file = None;
                    }
                }
            }
        }
        if let Some((path, w)) = &mut self.truth_file {
            w.flush().map_err(|source| SitlError::Truth {
                file: path.clone(),
                source,
            })?;
        }
        csv_error.map_or(Ok(()), Err)
    }

    fn send(&self, msg: &MavMessage) -> bool {
        send_own(&self.shared, &self.socket, self.gcs_socket.as_deref(), msg)
    }

    /// A LOCAL_POSITION_NED left (the latency's pose stream without vision).
    fn pose_sent(&self) {
        if self.vision.is_none() {
            self.shared.latency.pose_sent(Instant::now());
        }
        bump(&self.shared.counters.positions_sent);
    }

    /// The vision stand-in at SITL time `t`: capture when due, send what
    /// has waited its latency.
    fn vision(&mut self, t: f64, state: &PlantState) {
        let Some(v) = &mut self.vision else {
            return;
        };
        let paused = self.shared.pose_paused.load(Ordering::Relaxed);
        if t + 1e-9 >= v.next_capture {
            // Skip captures missed by a late step rather than bunching them.
            while v.next_capture <= t + 1e-9 {
                v.next_capture += v.period;
            }
            v.sensor.observe(t, state);
            if !paused && let Some(m) = v.sensor.measure(t) {
                let offset = *lock(&self.shared.pose_offset);
                let p = [
                    m.position.x + offset[0],
                    m.position.y + offset[1],
                    m.position.z + offset[2],
                ];
                if v.pending.len() == VISION_QUEUE {
                    v.pending.pop_front();
                }
                v.pending
                    .push_back((t, p, [state.roll, state.pitch, state.yaw]));
            }
        }
        let mut due = Vec::new();
        while let Some(&(capture, p, euler)) = v.pending.front() {
            if capture + v.latency > t + 1e-9 {
                break;
            }
            v.pending.pop_front();
            due.push((capture, p, euler));
        }
        for (capture, p, euler) in due {
            let usec = (capture * 1e6).round() as u64;
            if let Ok(msg) = dflat_link::vision_position_estimate(usec, p, euler, 0, None)
                && self.send(&msg)
            {
                self.shared.latency.pose_sent(Instant::now());
                bump(&self.shared.counters.visions_sent);
            }
        }
    }

    fn telemetry(&mut self, sample: &TruthSample, state: &PlantState) {
        if self.shared.pose_paused.load(Ordering::Relaxed) {
            return;
        }
        let time_boot_ms = (sample.t * 1000.0).round() as u32;
        let measured = self.sensor.measure(sample.t);
        let offset = *lock(&self.shared.pose_offset);
        let p = measured.map_or(state.position, |m| m.position);
        let position = [p.x + offset[0], p.y + offset[1], p.z + offset[2]];
        if let Ok(msg) = dflat_link::local_position_ned(time_boot_ms, position, sample.velocity) {
            let fate = self.shared.latency.pose_fate(Instant::now(), &msg);
            if fate == latency::PoseFate::Send && self.send(&msg) {
                self.pose_sent();
            }
        }
        let rates = state.body_rates.into();
        if let Ok(msg) = dflat_link::attitude(time_boot_ms, sample.euler, rates)
            && self.send(&msg)
        {
            bump(&self.shared.counters.attitudes_sent);
        }
    }

    /// The plant command for a received one: angles as sent, normalised
    /// thrust → specific thrust via the plant's hover value.
    fn plant_command(&self, c: &ReceivedCommand) -> PlantCommand {
        PlantCommand {
            pitch: c.pitch,
            roll: c.roll,
            yaw: c.yaw,
            thrust: c.thrust / self.hover_thrust * GRAVITY,
        }
    }

    fn hold_command(&self, target: &Vector3<f64>, velocity: &Vector3<f64>) -> PlantCommand {
        hold_law(&self.options, &self.plant.true_state(), target, velocity)
    }
}

/// The autopilot's own position hold (position mode): PD on the true
/// state towards `target` moving at the pilot's `velocity` → tilt and
/// thrust (the autopilot knows its own hover thrust and mass).
fn hold_law(
    options: &PlantOptions,
    s: &PlantState,
    target: &Vector3<f64>,
    velocity: &Vector3<f64>,
) -> PlantCommand {
    let e = target - s.position;
    let max_a = GRAVITY * HOLD_MAX_TILT_DEG.to_radians().tan();
    let limit = |a: f64| a.clamp(-max_a, max_a);
    let ax = limit(HOLD_KP * e.x + HOLD_KD * (velocity.x - s.velocity.x));
    let ay = limit(HOLD_KP * e.y + HOLD_KD * (velocity.y - s.velocity.y));
    let az = limit(HOLD_KP_Z * e.z + HOLD_KD_Z * (velocity.z - s.velocity.z));
    // Into the yaw frame: forward / right accelerations.
    let (sy, cy) = s.yaw.sin_cos();
    let a_fwd = cy * ax + sy * ay;
    let a_right = -sy * ax + cy * ay;
    let pitch = (-a_fwd / GRAVITY).atan();
    let roll = (a_right * pitch.cos() / GRAVITY).atan();
    let specific = (GRAVITY - az) / (pitch.cos() * roll.cos()).max(0.5);
    PlantCommand {
        pitch,
        roll,
        yaw: wrap(s.yaw),
        thrust: options.thrust_command_for(specific),
    }
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

fn write_truth_row(w: &mut impl std::io::Write, s: &TruthSample) -> std::io::Result<()> {
    let [x, y, z] = s.position;
    let [vx, vy, vz] = s.velocity;
    let [r, p, yw] = s.euler;
    write!(
        w,
        "{:.4},{x:.5},{y:.5},{z:.5},{vx:.5},{vy:.5},{vz:.5},{r:.6},{p:.6},{yw:.6},",
        s.t
    )?;
    match s.command {
        Some(c) => write!(
            w,
            "{:.6},{:.6},{:.6},{:.5},",
            c.roll, c.pitch, c.yaw, c.thrust
        )?,
        None => write!(w, ",,,,")?,
    }
    writeln!(w, "{}", s.mode.as_str())
}

/// One row of a truth CSV written by the SITL.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthRow {
    /// SITL time \[s\].
    pub t: f64,
    /// True position, NED \[m\].
    pub position: [f64; 3],
    /// True velocity, NED \[m/s\].
    pub velocity: [f64; 3],
    /// Whether a command was in force.
    pub commanded: bool,
}

/// Reads the truth CSV written with [`SitlOptions::truth_csv`] (rows that do
/// not parse, e.g. a partly written last line, are skipped).
pub fn read_truth_csv(path: &Path) -> std::io::Result<Vec<TruthRow>> {
    let text = std::fs::read_to_string(path)?;
    Ok(text
        .lines()
        .skip(1)
        .filter_map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            if f.len() != 15 {
                return None;
            }
            let n = |i: usize| f[i].parse::<f64>().ok();
            Some(TruthRow {
                t: n(0)?,
                position: [n(1)?, n(2)?, n(3)?],
                velocity: [n(4)?, n(5)?, n(6)?],
                commanded: f[14] == "offboard",
            })
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn udpin_parses_and_others_are_refused() {
        assert_eq!(
            parse_udpin("link", "udpin:127.0.0.1:14540").unwrap(),
            "127.0.0.1:14540".parse().unwrap()
        );
        assert!(parse_udpin("link", "udpout:127.0.0.1:14540").is_err());
        assert!(parse_udpin("link", "udpin:nonsense").is_err());
    }

    #[test]
    fn truth_rows_round_trip() {
        let s = TruthSample {
            t: 1.25,
            position: [1.0, -2.0, -10.0],
            velocity: [0.5, 0.0, 0.0],
            euler: [0.0, -0.1, 0.0],
            command: Some(ReceivedCommand {
                roll: 0.0,
                pitch: -0.1,
                yaw: 0.0,
                thrust: 0.5,
            }),
            mode: SitlMode::Offboard,
        };
        let mut buf = Vec::new();
        write_truth_row(&mut buf, &s).unwrap();
        let dir = std::env::temp_dir().join(format!("dflat-truth-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.csv");
        let mut text = b"header\n".to_vec();
        text.extend_from_slice(&buf);
        std::fs::write(&path, text).unwrap();
        let rows = read_truth_csv(&path).unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].position, [1.0, -2.0, -10.0]);
        assert!(rows[0].commanded);
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn test_config() -> SitlSettings {
        let mut cfg = SitlSettings::default();
        cfg.sitl.url = "udpin:127.0.0.1:0".into();
        cfg.sitl.start = [0.0, 0.0, -10.0];
        cfg
    }

    #[test]
    fn holds_position_without_commands_and_streams_telemetry() {
        let cfg = test_config();
        let sitl = spawn(
            &cfg,
            SitlOptions {
                record_trace: true,
                ..SitlOptions::default()
            },
        )
        .unwrap();
        // A peer speaks (a heartbeat from the daemon's component).
        let client = UdpSocket::bind("127.0.0.1:0").unwrap();
        client
            .set_read_timeout(Some(Duration::from_millis(500)))
            .unwrap();
        let hb = dflat_link::heartbeat_onboard(dflat_link::DaemonStatus::Standby);
        let f = serialize_v2(&dflat_link::header(1, 191, 0), &hb).unwrap();
        client.send_to(f.as_bytes(), sitl.local_addr()).unwrap();
        let mut buf = [0u8; 2048];
        let mut positions = 0;
        let deadline = Instant::now() + Duration::from_millis(400);
        while Instant::now() < deadline {
            if let Ok((n, _)) = client.recv_from(&mut buf) {
                for fr in frames(&buf[..n]).flatten() {
                    if matches!(fr.message, MavMessage::LOCAL_POSITION_NED(_)) {
                        assert_eq!(fr.header.system_id, 1);
                        assert_eq!(fr.header.component_id, 1);
                        positions += 1;
                    }
                }
            }
        }
        assert!(positions >= 10, "{positions} positions in 0.4 s");
        assert_eq!(sitl.mode(), SitlMode::Hold);
        let report = sitl.stop().unwrap();
        let p = report.last.position;
        assert!(p[0].abs() < 1e-6 && p[1].abs() < 1e-6 && (p[2] + 10.0).abs() < 1e-6);
        assert!(!report.trace.is_empty());
    }

    #[test]
    fn hold_loop_brings_the_plant_back() {
        let cfg = test_config();
        let popts = plant_options(&cfg);
        for kind in [PlantKind::Planar, PlantKind::Spatial, PlantKind::RigidBody] {
            let mut plant = build_plant(kind, &popts, 1).unwrap();
            let mut s = PlantState::hover(Vector3::new(3.0, -2.0, -8.0), GRAVITY);
            s.velocity = Vector3::new(2.0, 1.0, 0.0);
            plant.reset(&s);
            let target = Vector3::new(0.0, 0.0, -10.0);
            for _ in 0..(20.0 / popts.plant_dt) as usize {
                let c = hold_law(&popts, &plant.true_state(), &target, &Vector3::zeros());
                plant.apply(&c);
                plant.advance(popts.plant_dt);
            }
            let e = plant.position() - target;
            let horizontal = e.x.hypot(e.y);
            assert!(horizontal < 0.05, "{kind:?}: {e:?}");
            if kind != PlantKind::Planar {
                assert!(e.z.abs() < 0.05, "{kind:?}: {e:?}");
            }
        }
    }

    fn attitude_target(target: (u8, u8), pitch: f64) -> MavMessage {
        dflat_link::set_attitude_target(
            dflat_link::Target {
                system: target.0,
                component: target.1,
            },
            0,
            &dflat_link::AttitudeCommand {
                roll: 0.0,
                pitch,
                yaw: 0.0,
                thrust: 0.5,
            },
        )
        .unwrap()
    }

    /// A SITL of [`test_config`] with a GCS port, and two client sockets
    /// (100 ms read timeout) to play the daemon and the ground station.
    fn with_gcs(options: SitlOptions) -> (SitlHandle, UdpSocket, UdpSocket) {
        let sitl = spawn(
            &test_config(),
            SitlOptions {
                gcs: Some("udpin:127.0.0.1:0".into()),
                ..options
            },
        )
        .unwrap();
        let daemon = UdpSocket::bind("127.0.0.1:0").unwrap();
        let gcs = UdpSocket::bind("127.0.0.1:0").unwrap();
        for s in [&daemon, &gcs] {
            s.set_read_timeout(Some(Duration::from_millis(100)))
                .unwrap();
        }
        (sitl, daemon, gcs)
    }

    fn send(client: &UdpSocket, to: SocketAddr, sys: u8, comp: u8, msg: &MavMessage) {
        let f = serialize_v2(&dflat_link::header(sys, comp, 0), msg).unwrap();
        client.send_to(f.as_bytes(), to).unwrap();
    }

    #[test]
    fn follows_addressed_commands_then_holds_after_timeout() {
        let mut cfg = test_config();
        cfg.sitl.command_timeout_s = 0.2;
        let sitl = spawn(&cfg, SitlOptions::default()).unwrap();
        let to = sitl.local_addr();
        let client = UdpSocket::bind("127.0.0.1:0").unwrap();
        // Addressed elsewhere, or from another system: ignored.
        send(&client, to, 1, 191, &attitude_target((1, 2), -0.2));
        send(&client, to, 7, 191, &attitude_target((1, 1), -0.2));
        // Nose down for 0.6 s: accelerates north.
        let until = Instant::now() + Duration::from_millis(600);
        while Instant::now() < until {
            send(&client, to, 1, 191, &attitude_target((1, 1), -0.2));
            std::thread::sleep(Duration::from_millis(20));
        }
        assert_eq!(sitl.mode(), SitlMode::Offboard);
        let moving = sitl.truth();
        assert!(moving.velocity[0] > 0.3, "{moving:?}");
        assert!(moving.command.is_some_and(|c| (c.pitch + 0.2).abs() < 1e-3));
        // Silence: the stand-in holds on its own and stops.
        std::thread::sleep(Duration::from_millis(400));
        assert_eq!(sitl.mode(), SitlMode::Hold);
        let c = sitl.counters();
        assert_eq!(c.commands_ignored, 2, "{c:?}");
        assert!(c.commands_accepted >= 20, "{c:?}");
        assert_eq!(c.hold_entries, 1);
        let report = sitl.stop().unwrap();
        assert!(!report.diverged);
    }

    #[test]
    fn routes_between_gcs_and_vehicle_link() {
        let (sitl, daemon, gcs) = with_gcs(SitlOptions::default());
        let hb = dflat_link::heartbeat_onboard(dflat_link::DaemonStatus::Standby);
        send(&daemon, sitl.local_addr(), 1, 191, &hb);
        send(&gcs, sitl.gcs_addr().unwrap(), 255, 190, &hb);
        std::thread::sleep(Duration::from_millis(50));
        // GCS → daemon.
        send(&gcs, sitl.gcs_addr().unwrap(), 255, 190, &hb);
        // daemon → GCS (a heartbeat: broadcast, routed).
        send(&daemon, sitl.local_addr(), 1, 191, &hb);
        let seen_by = |s: &UdpSocket, sys: u32| {
            let mut buf = [0u8; 4096];
            let until = Instant::now() + Duration::from_millis(500);
            while Instant::now() < until {
                if let Ok((n, _)) = s.recv_from(&mut buf)
                    && frames(&buf[..n])
                        .flatten()
                        .any(|f| f.header.system_id == sys)
                {
                    return true;
                }
            }
            false
        };
        assert!(
            seen_by(&daemon, 255),
            "GCS frame not routed to the vehicle link"
        );
        assert!(seen_by(&gcs, 1), "nothing routed to the GCS");
        let c = sitl.stop().unwrap().counters;
        assert!(c.gcs_frames_in >= 2 && c.gcs_frames_out >= 1, "{c:?}");
    }

    fn key(byte: u8) -> dflat_link::SigningKey {
        dflat_link::SigningKey::from_bytes([byte; 32])
    }

    /// Signing with `key` as `link_id`, starting at the wall clock.
    fn signing(key: dflat_link::SigningKey, link_id: u8) -> Signing {
        Signing::new(key, link_id, timestamp_from_system_time(SystemTime::now()))
    }

    fn sign(signing: &mut Signing, sys: u8, comp: u8, seq: u8, msg: &MavMessage) -> Vec<u8> {
        let now = timestamp_from_system_time(SystemTime::now());
        let f = signing
            .sign(&dflat_link::header(sys, comp, seq), msg, now)
            .unwrap();
        f.as_bytes().to_vec()
    }

    /// The SITL's signing as `sitl.signing_key_file` sets it up.
    fn sitl_signing_with(byte: u8) -> Signing {
        let mut s = signing(key(byte), SIGNING_LINK_ID);
        s.accept_unsigned_telemetry = true;
        s
    }

    #[test]
    fn with_signing_only_signed_commands_are_applied() {
        let cfg = test_config();
        let sitl = spawn(
            &cfg,
            SitlOptions {
                signing: Some(sitl_signing_with(0x5a)),
                ..SitlOptions::default()
            },
        )
        .unwrap();
        let to = sitl.local_addr();
        let client = UdpSocket::bind("127.0.0.1:0").unwrap();
        client
            .set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        let cmd = attitude_target((1, 1), -0.2);
        // Unsigned, and signed with another key: refused and counted.
        let mut stranger = signing(key(0x33), 0);
        for _ in 0..5 {
            send(&client, to, 1, 191, &cmd);
            let f = sign(&mut stranger, 1, 191, 0, &cmd);
            client.send_to(&f, to).unwrap();
            std::thread::sleep(Duration::from_millis(20));
        }
        std::thread::sleep(Duration::from_millis(100));
        let c = sitl.counters();
        assert_eq!(c.commands_unauthenticated, 10, "{c:?}");
        assert_eq!(c.commands_accepted, 0, "{c:?}");
        assert_eq!(sitl.mode(), SitlMode::Hold);
        assert!(sitl.truth().command.is_none());
        // Signed with the SITL's key: applied.
        let mut ours = signing(key(0x5a), 0);
        let until = Instant::now() + Duration::from_millis(300);
        while Instant::now() < until {
            let f = sign(&mut ours, 1, 191, 0, &cmd);
            client.send_to(&f, to).unwrap();
            std::thread::sleep(Duration::from_millis(20));
        }
        std::thread::sleep(Duration::from_millis(60));
        assert_eq!(sitl.mode(), SitlMode::Offboard);
        let c = sitl.counters();
        assert!(c.commands_accepted >= 5, "{c:?}");
        assert_eq!(c.commands_unauthenticated, 10, "{c:?}");
        // A replayed signed command is refused.
        let f = sign(&mut ours, 1, 191, 0, &cmd);
        client.send_to(&f, to).unwrap();
        client.send_to(&f, to).unwrap();
        std::thread::sleep(Duration::from_millis(60));
        let after = sitl.counters();
        assert_eq!(
            after.commands_accepted,
            c.commands_accepted + 1,
            "{after:?}"
        );
        assert_eq!(after.commands_unauthenticated, 11, "{after:?}");
        // The SITL's telemetry is signed with its key, as link 1.
        let mut verifier = signing(key(0x5a), 0);
        let mut buf = [0u8; 2048];
        let mut verified = 0;
        let deadline = Instant::now() + Duration::from_millis(300);
        while Instant::now() < deadline {
            let Ok((n, _)) = client.recv_from(&mut buf) else {
                continue;
            };
            for fr in frames(&buf[..n]).flatten() {
                let now = timestamp_from_system_time(SystemTime::now());
                let check = verifier.verify(&fr.header, fr.signed.as_ref(), now);
                assert!(
                    matches!(
                        check,
                        dflat_link::SignatureCheck::Valid {
                            link_id: SIGNING_LINK_ID,
                            ..
                        }
                    ),
                    "{:?}: {check:?}",
                    fr.message
                );
                verified += 1;
            }
        }
        assert!(verified >= 10, "{verified} verified frames");
        sitl.stop().unwrap();
    }

    #[test]
    fn signed_frames_are_routed_with_their_signature() {
        let (sitl, daemon, gcs) = with_gcs(SitlOptions {
            signing: Some(sitl_signing_with(0x5a)),
            ..SitlOptions::default()
        });
        let (link, gcs_port) = (sitl.local_addr(), sitl.gcs_addr().unwrap());
        let hb = dflat_link::heartbeat_onboard(dflat_link::DaemonStatus::Standby);
        let mut daemon_signing = signing(key(0x5a), 0);
        let mut gcs_signing = signing(key(0x5a), 2);
        let mut stranger = signing(key(0x33), 0);
        daemon
            .send_to(&sign(&mut daemon_signing, 1, 191, 0, &hb), link)
            .unwrap();
        gcs.send_to(&sign(&mut gcs_signing, 255, 190, 0, &hb), gcs_port)
            .unwrap();
        std::thread::sleep(Duration::from_millis(50));
        // daemon → GCS: a wrong key (seq 7) is dropped, unsigned (8) and
        // signed (9) heartbeats are routed, the signed one byte for byte.
        daemon
            .send_to(&sign(&mut stranger, 1, 191, 7, &hb), link)
            .unwrap();
        let unsigned_hb = serialize_v2(&dflat_link::header(1, 191, 8), &hb).unwrap();
        daemon.send_to(unsigned_hb.as_bytes(), link).unwrap();
        let signed_hb = sign(&mut daemon_signing, 1, 191, 9, &hb);
        daemon.send_to(&signed_hb, link).unwrap();
        // GCS → daemon, byte for byte.
        let gcs_hb = sign(&mut gcs_signing, 255, 190, 1, &hb);
        gcs.send_to(&gcs_hb, gcs_port).unwrap();
        let collect = |s: &UdpSocket, sys: u32| {
            let mut buf = [0u8; 4096];
            let mut seen = Vec::new();
            let until = Instant::now() + Duration::from_millis(400);
            while Instant::now() < until {
                if let Ok((n, _)) = s.recv_from(&mut buf) {
                    seen.extend(
                        frames(&buf[..n])
                            .flatten()
                            .filter(|f| f.header.system_id == sys),
                    );
                }
            }
            seen
        };
        let at_gcs: Vec<_> = collect(&gcs, 1)
            .into_iter()
            .filter(|f| f.header.component_id == 191)
            .collect();
        let seqs: Vec<u8> = at_gcs.iter().map(|f| f.header.sequence).collect();
        assert!(!seqs.contains(&7), "badly signed frame routed: {seqs:?}");
        assert!(seqs.contains(&8), "unsigned heartbeat not routed: {seqs:?}");
        let routed = at_gcs.iter().find(|f| f.header.sequence == 9);
        assert_eq!(
            routed.and_then(|f| f.signed.as_ref()).map(|s| s.as_bytes()),
            Some(&signed_hb[..]),
            "signed heartbeat not routed unchanged"
        );
        let at_daemon = collect(&daemon, 255);
        assert!(
            at_daemon
                .iter()
                .any(|f| f.signed.as_ref().map(|s| s.as_bytes()) == Some(&gcs_hb[..])),
            "GCS frame not routed unchanged: {at_daemon:?}"
        );
        sitl.stop().unwrap();
    }

    #[test]
    fn sitl_key_file_is_checked_at_start() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = std::env::temp_dir().join(format!("dflat-sitl-key-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("key");
        std::fs::write(&path, format!("{}\n", "5a".repeat(32))).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let mut cfg = test_config();
        cfg.sitl.signing_key_file = path.display().to_string();
        let err = spawn(&cfg, SitlOptions::default()).unwrap_err().to_string();
        assert!(err.contains("sitl.signing_key_file"), "{err}");
        assert!(
            err.contains("0644") && err.contains(&path.display().to_string()),
            "{err}"
        );
        assert!(!err.contains("link.signing_key_file"), "{err}");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        let sitl = spawn(&cfg, SitlOptions::default()).unwrap();
        assert!(sitl.shared.signing.is_some());
        sitl.stop().unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
