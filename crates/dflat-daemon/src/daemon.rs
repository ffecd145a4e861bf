//! The flight-control daemon: link tasks, the control thread, shutdown.
//!
//! ```text
//!             ┌──────── receive task ────────┐  events (bounded)  ┌──── control thread ─────┐
//! transport ──┤ frame → LinkRx (filter,      ├───────────────────►│ absolute deadlines      │
//!             │ decode, count) → pose / hb / │                    │ supervisor → controller │
//!             │ attitude / setpoint          │                    │ → SET_ATTITUDE_TARGET   │
//!             └──────────────────────────────┘                    │ CSV row → csv thread    │
//!                                                                 └───────────┬─────────────┘
//!             ┌──────── send task ───────────┐   outbound (bounded)           │
//! transport ◄─┤ header + sequence, send,     │◄───────────────────────────────┴── heartbeat task (1 Hz)
//!             │ count, pose→command latency  │
//!             └──────────────────────────────┘
//! ```
//!
//! The control loop runs on its own OS thread and never awaits I/O: it
//! drains the event queue, decides, solves and hands the command to the
//! send task with `try_send`. Staleness (the pose timeout) uses *arrival*
//! times on this computer's monotonic clock.
//!
//! Pose times: each pose is stamped with its capture time on this
//! computer's clock, from its own timestamp and a clock-offset estimate
//! ([`crate::clock`], `link.pose_time`). A multi-rate DF-MPC
//! (`controller.multi_rate`) gets every pose through
//! [`Controller::observe`] at its capture time and, per tick,
//! [`Controller::update`] with the tick's wake time. The other controllers
//! get, per tick, the newest pose with its capture time; a tick that finds
//! no new pose passes the previous one with its old time, and the
//! controller substitutes its own prediction.
//!
//! Entry points: [`run`] (used by `dflat daemon`) and [`spawn`] /
//! [`DaemonHandle`] (in-process use: demo, tests).

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime};

use dflat_control::reference::Reference;
use dflat_control::{Controller, Measurement};
use dflat_link::dialect::MavSeverity;
use dflat_link::{
    AttitudeCommand, DaemonStatus, Inbound, LinkRx, LinkStats, MavHeader, MavMessage, PoseSource,
    RxOutcome, SignatureCheck, Signing, SourceFilter, Target, ThrustMapping, heartbeat_onboard,
    set_attitude_target, statustext, timestamp_from_system_time,
};
use nalgebra::Vector3;
use thiserror::Error;
use tokio::sync::{mpsc, watch};
use tracing::{debug, error, info, warn};

use crate::clock::PoseClock;
use crate::config::{Config, ModelKind, PoseSourceKind, PoseTime};
use crate::control::{build_controller, configured_path, reference_for, thrust_mapping};
use crate::guard::{
    CommandGuard, Fallback, FallbackKind, GuardCounts, ResidualMonitor, WatchdogCadence,
    is_pose_jump,
};
use crate::records::CsvDisturbance;
use crate::records::{CsvRecorder, CsvReport, CsvRow, flight_stem};
use crate::schedule::Schedule;
use crate::signing::{PERSIST_INTERVAL, SigningError, TimestampStore};
use crate::summary::{
    DisturbanceSummary, FlightSummary, Histogram, LinkSummary, SolveCounts, StateTimes,
    peak_rss_kib, process_cpu_seconds,
};
use crate::supervisor::{
    Cause, FlightState, Goal, SetpointOutcome, Supervisor, SupervisorConfig, Transition,
};
use dflat_link::transport::{Endpoint, RecvEvent, SendOutcome, TlogTap, Transport, TransportError};

/// Capacity of the receive task → control thread queue \[events\].
const EVENT_QUEUE: usize = 1024;
/// Capacity of the outbound queue to the send task \[messages\].
const OUTBOUND_QUEUE: usize = 256;
/// Smallest interval between two "setpoint refused" STATUSTEXTs \[s\].
const REFUSAL_TEXT_INTERVAL: f64 = 1.0;
/// How long shutdown waits for the send task to drain \[s\].
const SEND_DRAIN_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a residual failsafe lasts before pose may re-engage \[s\].
const RESIDUAL_FAILSAFE_LATCH: f64 = 2.0;

/// `STATUS=` for systemd (no-op when not under systemd).
fn notify_status(state: FlightState) {
    let text = format!("state {}", state.name());
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Status(&text)]);
}

/// Why the daemon could not start or stopped with an error.
#[derive(Debug, Error)]
pub enum DaemonError {
    /// The connection string is invalid, or the link could not be opened.
    #[error("link: {0}")]
    Link(#[source] TransportError),
    /// The link failed during the flight (TCP closed, serial port gone).
    #[error("link lost: {0}")]
    LinkLost(#[source] TransportError),
    /// The controller or the path could not be built from the configuration.
    #[error("controller: {0}")]
    Controller(#[from] dflat_control::ControlError),
    /// The records directory or files could not be created.
    #[error("records: {path}: {source}")]
    Records {
        /// The directory or file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// MAVLink signing is configured but its key or timestamp file is
    /// refused (the message names the `[link]` field).
    #[error("signing: {0}")]
    Signing(#[from] SigningError),
    /// A thread could not be started or ended abnormally.
    #[error("internal: {0}")]
    Internal(String),
}

/// An inbound fact for the control thread, stamped with its arrival time.
#[derive(Debug, Clone, Copy)]
enum Event {
    Pose {
        arrival: Instant,
        /// The source's timestamp \[s\] on its own clock (`None`: 0 / none).
        source_time: Option<f64>,
        position: [f64; 3],
        yaw: Option<f64>,
        /// The estimator reset counter (ODOMETRY, VISION_POSITION_ESTIMATE).
        reset_counter: Option<u8>,
    },
    Attitude {
        yaw: f64,
    },
    Heartbeat {
        arrival: Instant,
    },
    Setpoint {
        arrival: Instant,
        position: [f64; 3],
    },
}

/// A message for the send task. For attitude commands, `tick` is the
/// tick's wake time and `pose_arrival` the arrival of its pose if that
/// arrived since the previous command (for the latency figures).
#[derive(Debug)]
struct Outgoing {
    message: MavMessage,
    tick: Option<Instant>,
    pose_arrival: Option<Instant>,
}

impl Outgoing {
    fn plain(message: MavMessage) -> Self {
        Self {
            message,
            tick: None,
            pose_arrival: None,
        }
    }
}

/// Published daemon state (for HEARTBEAT and [`DaemonHandle::state`]).
const ST_BOOT: u8 = 0;
const ST_SHUTDOWN: u8 = 5;

fn encode_state(s: FlightState) -> u8 {
    s.index() as u8 + 1
}

fn decode_state(v: u8) -> Option<FlightState> {
    match v {
        1..=4 => Some(FlightState::ALL[usize::from(v - 1)]),
        _ => None,
    }
}

fn daemon_status(v: u8) -> DaemonStatus {
    match decode_state(v) {
        None if v == ST_BOOT => DaemonStatus::Boot,
        None => DaemonStatus::Poweroff,
        Some(FlightState::WaitingForPose) => DaemonStatus::Standby,
        Some(FlightState::Holding | FlightState::Tracking) => DaemonStatus::Active,
        Some(FlightState::Failsafe) => DaemonStatus::Critical,
    }
}

/// Stop request shared by all parts: a flag for the control thread and a
/// watch for the tasks.
#[derive(Debug)]
struct Stop {
    flag: AtomicBool,
    tx: watch::Sender<bool>,
}

impl Stop {
    fn request(&self) {
        self.flag.store(true, Ordering::SeqCst);
        self.tx.send_replace(true);
    }

    fn requested(&self) -> bool {
        self.flag.load(Ordering::SeqCst)
    }
}

/// What the control thread measured.
#[derive(Debug)]
struct ControlReport {
    ticks: u64,
    missed: u64,
    commands: u64,
    control_errors: u64,
    outbound_dropped: u64,
    solve: Histogram,
    jitter: Histogram,
    time_in_state: [f64; 4],
    state_changes: u64,
    final_state: FlightState,
    csv: Option<CsvReport>,
    disturbance: Option<DisturbanceSummary>,
    guards: GuardCounts,
    solves: SolveCounts,
}

/// What the receive task counted.
#[derive(Debug, Default)]
struct RxReport {
    stats: LinkStats,
    transport_errors: u64,
    events_dropped: u64,
}

/// What the send task counted.
#[derive(Debug, Default)]
struct TxReport {
    stats: LinkStats,
    latency: Histogram,
    tick_to_send: Histogram,
}

/// A running daemon (see [`spawn`]).
#[derive(Debug)]
pub struct DaemonHandle {
    stop: Arc<Stop>,
    stop_rx: watch::Receiver<bool>,
    state: Arc<AtomicU8>,
    ticks: Arc<AtomicU64>,
    local_addr: Option<SocketAddr>,
    fault: Arc<std::sync::Mutex<Option<TransportError>>>,
    parts: Parts,
}

#[derive(Debug)]
struct Parts {
    link: String,
    controller: String,
    model: String,
    rate_hz: f64,
    started: Instant,
    cpu_at_start: Option<f64>,
    tap: Option<TlogTap>,
    control: std::thread::JoinHandle<ControlReport>,
    rx: tokio::task::JoinHandle<RxReport>,
    tx: tokio::task::JoinHandle<TxReport>,
    heartbeat: tokio::task::JoinHandle<()>,
}

impl DaemonHandle {
    /// The flight state, or `None` before the first tick and after shutdown.
    pub fn state(&self) -> Option<FlightState> {
        decode_state(self.state.load(Ordering::Relaxed))
    }

    /// Control ticks run so far.
    pub fn ticks(&self) -> u64 {
        self.ticks.load(Ordering::Relaxed)
    }

    /// The daemon's local socket address (UDP/TCP links).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// Asks the daemon to stop (idempotent); then [`join`](Self::join) it.
    pub fn shutdown(&self) {
        self.stop.request();
    }

    /// Resolves once a stop was requested — by [`shutdown`](Self::shutdown)
    /// or by the daemon itself when its link failed.
    pub async fn stopped(&self) {
        let mut rx = self.stop_rx.clone();
        // An error means the sender is gone, which only happens at teardown.
        let _ = rx.wait_for(|stop| *stop).await;
    }

    /// Stops the daemon (if not yet stopped), waits for all parts, flushes
    /// the records and returns the summary. Errors if the link failed.
    pub async fn join(self) -> Result<FlightSummary, DaemonError> {
        self.stop.request();
        let Parts {
            link,
            controller,
            model,
            rate_hz,
            started,
            cpu_at_start,
            tap,
            control,
            rx,
            tx,
            heartbeat,
        } = self.parts;
        let control = tokio::task::spawn_blocking(move || control.join())
            .await
            .map_err(|e| DaemonError::Internal(format!("control thread join: {e}")))?
            .map_err(|_| DaemonError::Internal("control thread panicked".into()))?;
        let join_err = |what: &str, e: tokio::task::JoinError| {
            DaemonError::Internal(format!("{what} task: {e}"))
        };
        heartbeat.await.map_err(|e| join_err("heartbeat", e))?;
        let rx = rx.await.map_err(|e| join_err("receive", e))?;
        let tx = match tokio::time::timeout(SEND_DRAIN_TIMEOUT, tx).await {
            Ok(r) => r.map_err(|e| join_err("send", e))?,
            Err(_) => {
                warn!("send task did not drain within {SEND_DRAIN_TIMEOUT:?}");
                TxReport::default()
            }
        };
        let tlog = match &tap {
            Some(tap) => tap.close().await,
            None => None,
        };
        let duration_s = started.elapsed().as_secs_f64();
        let cpu_percent = match (cpu_at_start, process_cpu_seconds()) {
            (Some(a), Some(b)) if duration_s > 0.0 => Some(100.0 * (b - a) / duration_s),
            _ => None,
        };
        self.state.store(ST_SHUTDOWN, Ordering::Relaxed);
        let summary = FlightSummary {
            link,
            controller,
            model,
            rate_hz,
            duration_s,
            ticks: control.ticks,
            missed_ticks: control.missed,
            commands: control.commands,
            control_errors: control.control_errors,
            solve_us: control.solve.percentiles(),
            jitter_us: control.jitter.percentiles(),
            latency_us: tx.latency.percentiles(),
            tick_to_send_us: tx.tick_to_send.percentiles(),
            link_stats: LinkSummary::new(&rx.stats, &tx.stats, rx.transport_errors),
            events_dropped: rx.events_dropped,
            outbound_dropped: control.outbound_dropped,
            time_in_state_s: StateTimes::from_array(control.time_in_state),
            state_changes: control.state_changes,
            final_state: control.final_state,
            cpu_percent,
            peak_rss_kib: peak_rss_kib(),
            csv: control.csv,
            tlog,
            disturbance: control.disturbance,
            guards: control.guards,
            solves: control.solves,
        };
        let fault = self.fault.lock().unwrap_or_else(|p| p.into_inner()).take();
        match fault {
            Some(e) => Err(DaemonError::LinkLost(e)),
            None => Ok(summary),
        }
    }
}

/// Runs the daemon until `shutdown` resolves (or the link fails), then
/// stops streaming, flushes the records and returns the summary.
///
/// `link_override` replaces `link.url`. Needs a tokio runtime with the
/// `time` and `net` drivers; the control loop runs on its own OS thread.
pub async fn run(
    config: Config,
    link_override: Option<String>,
    shutdown: impl Future<Output = ()>,
) -> Result<FlightSummary, DaemonError> {
    let handle = spawn(config, link_override).await?;
    tokio::select! {
        () = shutdown => info!("shutdown requested"),
        () = handle.stopped() => {}
    }
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    handle.join().await
}

/// Resolves on SIGINT or SIGTERM (Ctrl-C only on non-Unix systems). If the
/// handlers cannot be installed, logs it and never resolves.
pub async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match (
            signal(SignalKind::interrupt()),
            signal(SignalKind::terminate()),
        ) {
            (Ok(mut int), Ok(mut term)) => {
                tokio::select! {
                    _ = int.recv() => info!("SIGINT"),
                    _ = term.recv() => info!("SIGTERM"),
                }
            }
            (Err(e), _) | (_, Err(e)) => {
                error!(error = %e, "cannot install signal handlers");
                std::future::pending::<()>().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        if let Err(e) = tokio::signal::ctrl_c().await {
            error!(error = %e, "cannot install the Ctrl-C handler");
            std::future::pending::<()>().await;
        }
    }
}

/// Opens the link, creates the records and starts all parts. Returns once
/// the daemon is running (state `WaitingForPose` after the first tick).
pub async fn spawn(
    config: Config,
    link_override: Option<String>,
) -> Result<DaemonHandle, DaemonError> {
    let controller = build_controller(&config)?;
    spawn_with_controller(config, link_override, controller).await
}

/// As [`spawn`], with a controller of the caller's own instead of the one
/// `controller.kind` builds: the daemon's link, supervisor, guards and
/// records around any [`Controller`] (a research controller, or a test
/// double). Its commands use the configured thrust mapping and vehicle
/// limits.
pub async fn spawn_with_controller(
    config: Config,
    link_override: Option<String>,
    mut controller: Box<dyn Controller>,
) -> Result<DaemonHandle, DaemonError> {
    let url = link_override.unwrap_or_else(|| config.link.url.clone());
    let endpoint = Endpoint::parse(&url).map_err(DaemonError::Link)?;
    if let Some(path) = configured_path(&config) {
        path?;
    }
    let signing =
        crate::signing::setup(&config.link, timestamp_from_system_time(SystemTime::now()))?;
    if let Some((s, store)) = &signing {
        info!(
            link_id = s.link_id(),
            timestamp = s.timestamp(),
            timestamp_file = %store.path().display(),
            accept_unsigned_telemetry = s.accept_unsigned_telemetry,
            "MAVLink 2 signing on"
        );
    }
    let mapping = thrust_mapping(&config);
    mapping
        .validate()
        .map_err(|e| DaemonError::Internal(format!("thrust mapping: {e}")))?;
    controller.reset();

    // Records.
    let started_wall = SystemTime::now();
    let (csv, tap) = if config.logging.dir.trim().is_empty() {
        (None, None)
    } else {
        let dir = PathBuf::from(&config.logging.dir);
        std::fs::create_dir_all(&dir).map_err(|source| DaemonError::Records {
            path: dir.clone(),
            source,
        })?;
        let stem = flight_stem(&dir, started_wall);
        let csv = if config.logging.csv {
            let path = stem.with_extension("csv");
            Some(
                CsvRecorder::create(&path)
                    .map_err(|source| DaemonError::Records { path, source })?,
            )
        } else {
            None
        };
        let tap = if config.logging.tlog {
            let path = stem.with_extension("tlog");
            Some(TlogTap::create(&path).map_err(|e| match e {
                TransportError::Io { source, .. } => DaemonError::Records { path, source },
                other => DaemonError::Internal(other.to_string()),
            })?)
        } else {
            None
        };
        (csv, tap)
    };

    let controller_name = controller.name().to_owned();
    let transport = Transport::open_with_tap(&endpoint, tap.clone())
        .await
        .map_err(DaemonError::Link)?;
    let local_addr = transport.local_addr();
    info!(
        link = %endpoint,
        local = ?local_addr,
        controller = controller.name(),
        model = ?config.vehicle.model,
        rate_hz = config.controller.rate_hz,
        "daemon started"
    );

    let (stop_tx, stop_rx) = watch::channel(false);
    let stop = Arc::new(Stop {
        flag: AtomicBool::new(false),
        tx: stop_tx,
    });
    let state = Arc::new(AtomicU8::new(ST_BOOT));
    let ticks = Arc::new(AtomicU64::new(0));
    let fault = Arc::new(std::sync::Mutex::new(None));
    let epoch = Instant::now();
    let cpu_at_start = process_cpu_seconds();

    let (event_tx, event_rx) = std::sync::mpsc::sync_channel::<Event>(EVENT_QUEUE);
    let (out_tx, out_rx) = mpsc::channel::<Outgoing>(OUTBOUND_QUEUE);

    let link_cfg = &config.link;
    let own = (link_cfg.system_id, link_cfg.component_id);
    let mut filter = SourceFilter {
        vehicle_system_id: link_cfg.system_id,
        autopilot_component_id: link_cfg.autopilot_component,
        own_component_id: link_cfg.component_id,
        gcs_system_id: link_cfg.gcs_system_id,
        setpoint_components: Vec::new(),
        pose_components: link_cfg.pose_components.clone(),
    };
    if link_cfg.vehicle_setpoints {
        filter.setpoint_components = (1..=255u8)
            .filter(|c| *c != link_cfg.component_id)
            .collect();
    }
    let pose_source = match link_cfg.pose_source {
        PoseSourceKind::LocalPositionNed => PoseSource::LocalPositionNed,
        PoseSourceKind::Odometry => PoseSource::Odometry,
        PoseSourceKind::VisionPositionEstimate => PoseSource::VisionPositionEstimate,
    };

    let mut link_rx = LinkRx::new(filter);
    link_rx.signing = signing.as_ref().map(|(s, _)| s.clone());
    let rx = tokio::spawn(receive_task(
        transport.clone(),
        link_rx,
        pose_source,
        event_tx,
        out_tx.clone(),
        stop.clone(),
        fault.clone(),
    ));
    let tx = tokio::spawn(send_task(transport, out_rx, own, signing));
    let heartbeat = tokio::spawn(heartbeat_task(out_tx.clone(), state.clone(), stop.clone()));

    let loop_ctx = ControlLoop {
        supervisor: Supervisor::new(supervisor_config(&config)),
        controller,
        mapping,
        target: Target {
            system: config.link.system_id,
            component: config.link.autopilot_component,
        },
        config: config.clone(),
        events: event_rx,
        out: out_tx,
        stop: stop.clone(),
        state: state.clone(),
        ticks: ticks.clone(),
        epoch,
        csv,
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
        counts: GuardCounts::default(),
    };
    let control = std::thread::Builder::new()
        .name("dflat-control".into())
        .spawn(move || loop_ctx.run())
        .map_err(|e| DaemonError::Internal(format!("cannot start the control thread: {e}")))?;

    Ok(DaemonHandle {
        stop,
        stop_rx,
        state,
        ticks,
        local_addr,
        fault,
        parts: Parts {
            link: endpoint.to_string(),
            controller: controller_name,
            model: match config.vehicle.model {
                ModelKind::Planar => "planar".into(),
                ModelKind::Spatial => "spatial".into(),
            },
            rate_hz: config.controller.rate_hz,
            started: epoch,
            cpu_at_start,
            tap,
            control,
            rx,
            tx,
            heartbeat,
        },
    })
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
        geofence: m.geofence,
        path_ends,
        path_trigger_radius: m.path_trigger_radius,
        start_path: m.start == crate::config::MissionStart::Path,
        repeat_path: m.repeat,
    }
}

// ---------------------------------------------------------------------------
// Tasks
// ---------------------------------------------------------------------------

async fn receive_task(
    transport: Transport,
    mut link: LinkRx,
    pose_source: PoseSource,
    events: std::sync::mpsc::SyncSender<Event>,
    out: mpsc::Sender<Outgoing>,
    stop: Arc<Stop>,
    fault: Arc<std::sync::Mutex<Option<TransportError>>>,
) -> RxReport {
    let mut stop_rx = stop.tx.subscribe();
    let mut report = RxReport::default();
    let mut last_refusal: Option<Instant> = None;
    loop {
        let received = tokio::select! {
            biased;
            _ = stop_rx.wait_for(|s| *s) => break,
            r = transport.recv() => r,
        };
        let frame = match received {
            Ok(RecvEvent::Frame(frame)) => frame,
            Ok(RecvEvent::Error(e)) => {
                debug!(error = %e, "frame error");
                link.frame_error(&e);
                continue;
            }
            Err(e @ TransportError::Closed { .. }) => {
                error!(error = %e, "link closed: stopping");
                *fault.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
                stop.request();
                break;
            }
            Err(e) => {
                report.transport_errors += 1;
                if report.transport_errors == 1 || report.transport_errors.is_multiple_of(100) {
                    warn!(error = %e, count = report.transport_errors, "link receive error");
                }
                // Do not spin on a persistent socket error.
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            }
        };
        let arrival = frame.arrival;
        let is_setpoint = matches!(frame.message, MavMessage::SET_POSITION_TARGET_LOCAL_NED(_));
        if link.signing.is_some() {
            let now = timestamp_from_system_time(SystemTime::now());
            if let Err(check) =
                link.authenticate(&frame.header, &frame.message, frame.signed.as_ref(), now)
            {
                let due =
                    last_refusal.is_none_or(|t| t.elapsed().as_secs_f64() >= REFUSAL_TEXT_INTERVAL);
                if is_setpoint && due {
                    last_refusal = Some(Instant::now());
                    let text = match check {
                        SignatureCheck::Unsigned => "dflat: setpoint refused: unsigned",
                        SignatureCheck::Replayed => "dflat: setpoint refused: replayed",
                        _ => "dflat: setpoint refused: bad signature",
                    };
                    info!(?check, "setpoint refused by signing");
                    let _ = out.try_send(Outgoing::plain(statustext(
                        MavSeverity::MAV_SEVERITY_WARNING,
                        text,
                    )));
                }
                continue;
            }
        }
        let event = match link.handle(&frame.header, &frame.message) {
            RxOutcome::Accepted(Inbound::Pose(p)) if p.source == pose_source => Some(Event::Pose {
                arrival,
                source_time: (p.time_usec > 0).then_some(p.time_usec as f64 * 1e-6),
                position: p.position,
                yaw: p.yaw,
                reset_counter: p.reset_counter,
            }),
            RxOutcome::Accepted(Inbound::Attitude(a)) => Some(Event::Attitude { yaw: a.yaw }),
            RxOutcome::Accepted(Inbound::Heartbeat(_)) => Some(Event::Heartbeat { arrival }),
            RxOutcome::Accepted(Inbound::PositionSetpoint(s)) => Some(Event::Setpoint {
                arrival,
                position: s.position,
            }),
            RxOutcome::Rejected(e) if is_setpoint => {
                let due =
                    last_refusal.is_none_or(|t| t.elapsed().as_secs_f64() >= REFUSAL_TEXT_INTERVAL);
                if due {
                    last_refusal = Some(Instant::now());
                    let text = match e.category() {
                        dflat_link::ErrorCategory::NonFinite => {
                            "dflat: setpoint refused: not finite"
                        }
                        _ => "dflat: setpoint refused: not LOCAL_NED position",
                    };
                    info!(error = %e, "setpoint refused");
                    let _ = out.try_send(Outgoing::plain(statustext(
                        MavSeverity::MAV_SEVERITY_WARNING,
                        text,
                    )));
                }
                None
            }
            _ => None,
        };
        if let Some(event) = event
            && events.try_send(event).is_err()
        {
            report.events_dropped += 1;
        }
    }
    report.stats = link.stats;
    report
}

async fn send_task(
    transport: Transport,
    mut out: mpsc::Receiver<Outgoing>,
    (system_id, component_id): (u8, u8),
    mut signing: Option<(Signing, TimestampStore)>,
) -> TxReport {
    let mut report = TxReport::default();
    let mut persisted = Instant::now();
    let persist = |s: &Signing, store: &TimestampStore| {
        if let Err(e) = store.store(s.timestamp()) {
            warn!(error = %e, "cannot persist the signing timestamp");
        }
    };
    let mut sequence: u8 = 0;
    let mut no_peer = 0u64;
    // Ends when every sender (control thread, heartbeat, receive task) is gone.
    while let Some(item) = out.recv().await {
        let header = MavHeader {
            system_id: u32::from(system_id),
            component_id,
            sequence,
        };
        sequence = sequence.wrapping_add(1);
        let sent = match signing.as_mut() {
            Some((s, store)) => {
                let now = timestamp_from_system_time(SystemTime::now());
                let frame = s.sign(&header, &item.message, now);
                if persisted.elapsed() >= PERSIST_INTERVAL {
                    persist(s, store);
                    persisted = Instant::now();
                }
                match frame {
                    Ok(frame) => transport.send_frame(&frame).await,
                    Err(e) => Err(e.into()),
                }
            }
            None => transport.send(&header, &item.message).await,
        };
        match sent {
            Ok(SendOutcome::Sent(_)) => {
                report.stats.record_sent(&item.message);
                let us = |t: Instant| t.elapsed().as_micros().min(u128::from(u64::MAX)) as u64;
                if let Some(arrival) = item.pose_arrival {
                    report.latency.record(us(arrival));
                }
                if let Some(tick) = item.tick {
                    report.tick_to_send.record(us(tick));
                }
            }
            Ok(SendOutcome::NoPeer) => {
                no_peer += 1;
                if no_peer == 1 {
                    warn!("no peer yet on the udpin link: outbound messages dropped");
                }
            }
            Err(e) => {
                report.stats.send_errors += 1;
                if report.stats.send_errors == 1 || report.stats.send_errors.is_multiple_of(100) {
                    warn!(error = %e, count = report.stats.send_errors, "link send error");
                }
            }
        }
    }
    if let Some((s, store)) = &signing {
        persist(s, store);
    }
    report
}

async fn heartbeat_task(out: mpsc::Sender<Outgoing>, state: Arc<AtomicU8>, stop: Arc<Stop>) {
    let mut stop_rx = stop.tx.subscribe();
    let mut interval = tokio::time::interval(Duration::from_secs(1));
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            biased;
            _ = stop_rx.wait_for(|s| *s) => break,
            _ = interval.tick() => {}
        }
        let status = daemon_status(state.load(Ordering::Relaxed));
        if out
            .try_send(Outgoing::plain(heartbeat_onboard(status)))
            .is_err()
        {
            debug!("outbound queue full: heartbeat dropped");
        }
    }
    let _ = out.try_send(Outgoing::plain(heartbeat_onboard(DaemonStatus::Poweroff)));
}

// ---------------------------------------------------------------------------
// The control thread
// ---------------------------------------------------------------------------

struct ControlLoop {
    supervisor: Supervisor,
    controller: Box<dyn Controller>,
    mapping: ThrustMapping,
    target: Target,
    config: Config,
    events: std::sync::mpsc::Receiver<Event>,
    out: mpsc::Sender<Outgoing>,
    stop: Arc<Stop>,
    state: Arc<AtomicU8>,
    ticks: Arc<AtomicU64>,
    epoch: Instant,
    csv: Option<CsvRecorder>,
    /// Capture times of the poses on this computer's clock.
    clock: PoseClock,
    /// The exit point's limits.
    guard: CommandGuard,
    /// Held command / level hover after a failed or late tick.
    fallback: Fallback,
    /// Model-consistency residual.
    residual: ResidualMonitor,
    /// What the guards did.
    counts: GuardCounts,
}

/// Per-run mutable state of the loop (apart from the supervisor/controller).
struct LoopState {
    /// Newest pose (by capture time).
    pose: Option<PoseSample>,
    /// Yaw from ATTITUDE \[rad\].
    attitude_yaw: Option<f64>,
    /// Arrival of the pose used by the previous command (latency marking).
    last_used_arrival: Option<Instant>,
    reference: Option<Reference>,
    reference_generation: u64,
    last_refusal_text: Option<f64>,
    commands: u64,
    control_errors: u64,
    error_streak: u64,
    outbound_dropped: u64,
    /// The disturbance estimate at the last tick the controller ran.
    disturbance: Option<DisturbanceSummary>,
    /// A guard event since the last CSV row (pose jump).
    guard_note: Option<&'static str>,
    /// The fallback in use (announced once per kind), if any.
    fallback: Option<FallbackKind>,
    /// Flags of the controller's successful ticks.
    solves: SolveCounts,
}

/// One pose as the control loop keeps it.
#[derive(Debug, Clone, Copy)]
struct PoseSample {
    /// Arrival on this computer.
    arrival: Instant,
    /// Capture time on this computer's clock, seconds since the epoch.
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

impl ControlLoop {
    fn secs(&self, t: Instant) -> f64 {
        t.saturating_duration_since(self.epoch).as_secs_f64()
    }

    fn send(&self, item: Outgoing, ls: &mut LoopState) {
        if self.out.try_send(item).is_err() {
            ls.outbound_dropped += 1;
        }
    }

    fn announce(&self, tr: &Transition, ls: &mut LoopState) {
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
        self.send(Outgoing::plain(statustext(severity, &tr.text())), ls);
        self.state.store(encode_state(tr.to), Ordering::Relaxed);
        notify_status(tr.to);
    }

    /// Re-anchors after a pose jump to `pose`: controller window reset (a
    /// multi-rate one gets this pose), held / predicted state forgotten,
    /// the reference holds the new position.
    fn re_anchor(&mut self, t: f64, pose: &PoseSample, ls: &mut LoopState) {
        self.counts.pose_jumps += 1;
        self.controller.reset();
        if self.controller.multi_rate() {
            self.observe(pose, ls.attitude_yaw);
        }
        self.fallback.forget();
        self.residual.forget();
        ls.guard_note = Some("jump");
        warn!(position = ?pose.position, "pose jump: re-anchored");
        match self.supervisor.re_anchor(t, pose.position) {
            Some(tr) => self.announce(&tr, ls),
            None => self.send(
                Outgoing::plain(statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "dflat: pose jump, re-anchored",
                )),
                ls,
            ),
        }
        self.refresh_reference(ls);
    }

    fn run(mut self) -> ControlReport {
        let period = Duration::from_secs_f64(1.0 / self.config.controller.rate_hz);
        let mut schedule = Schedule::new(period);
        let mut solve_hist = Histogram::new();
        let mut jitter = Histogram::new();
        let mut ls = LoopState {
            pose: None,
            attitude_yaw: None,
            last_used_arrival: None,
            reference: None,
            reference_generation: self.supervisor.goal_generation(),
            last_refusal_text: None,
            commands: 0,
            control_errors: 0,
            error_streak: 0,
            outbound_dropped: 0,
            disturbance: None,
            guard_note: None,
            fallback: None,
            solves: SolveCounts::default(),
        };
        let multi_rate = self.controller.multi_rate();
        let start = Instant::now();
        self.state
            .store(encode_state(self.supervisor.state()), Ordering::Relaxed);
        // systemd: ready once this loop runs; the watchdog is fed from the
        // loop itself (a stuck loop gets the daemon restarted). No-ops when
        // not under systemd.
        if let Err(e) = sd_notify::notify(&[sd_notify::NotifyState::Ready]) {
            debug!(error = %e, "sd_notify READY failed");
        }
        notify_status(self.supervisor.state());
        let mut watchdog = WatchdogCadence::new(sd_notify::watchdog_enabled());
        if let Some(w) = &watchdog {
            info!(interval = ?w.interval(), "systemd watchdog fed from the control loop");
        }

        loop {
            let deadline = start + schedule.next_deadline();
            let now = Instant::now();
            if now < deadline {
                std::thread::sleep(deadline - now);
            }
            if self.stop.requested() {
                break;
            }
            let wake = Instant::now();
            if let Some(w) = watchdog.as_mut()
                && w.due(wake)
            {
                let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
            }
            let Some(slot) = schedule.on_wake(wake.saturating_duration_since(start)) else {
                continue;
            };
            let _span = tracing::debug_span!("tick", k = slot.tick).entered();
            if slot.missed > 0 {
                debug!(missed = slot.missed, "ticks skipped");
            }
            let t = self.secs(wake);

            // 1. Inbound facts up to now.
            while let Ok(event) = self.events.try_recv() {
                self.apply(event, &mut ls);
            }

            // 2. Decide.
            let decision = self.supervisor.tick(t);
            if decision.reset_controller {
                self.reset_controller(&ls);
                ls.last_used_arrival = None;
            }
            if let Some(tr) = decision.transition {
                self.announce(&tr, &mut ls);
            }
            self.refresh_reference(&mut ls);

            // 3. Control.
            let mut row = CsvRow {
                tick: slot.tick,
                t: (wake - slot.jitter)
                    .saturating_duration_since(self.epoch)
                    .as_secs_f64(),
                state: self.supervisor.state(),
                measured: ls.pose.map(|p| p.position),
                plan: None,
                reference: None,
                command: None,
                solve_us: None,
                jitter_us: u32::try_from(slot.jitter.as_micros()).unwrap_or(u32::MAX),
                disturbance: None,
                residual: None,
                guard: ls.guard_note.take(),
            };
            // The model-consistency residual: this tick's measurement
            // against the previous plan's prediction for it.
            if decision.stream
                && let Some(pose) = ls.pose
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
                    self.counts.residual_failsafes += 1;
                    warn!(residual = ?r, "model residual above the threshold: failsafe");
                    self.reset_controller(&ls);
                    ls.last_used_arrival = None;
                    self.announce(&tr, &mut ls);
                    row.guard = Some("residual");
                }
            }
            if self.supervisor.state().streams()
                && let (Some(pose), Some(reference)) = (ls.pose, ls.reference.as_mut())
            {
                let arrival = pose.arrival;
                // Multi-rate: the samples were observed as they arrived; the
                // tick passes its own time. Otherwise the newest pose with
                // its capture time (not newer than the last: no new pose).
                let measurement = Measurement {
                    t: if multi_rate { t } else { pose.capture },
                    position: Vector3::from(pose.position),
                    yaw: self.yaw_of(pose.yaw, ls.attitude_yaw),
                };
                let t0 = Instant::now();
                // A panicking controller is a bug, but it must not take the
                // loop down with it: treat it as a failed tick and reset.
                let controller = &mut self.controller;
                let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    controller.update(&measurement, reference)
                }))
                .unwrap_or_else(|_| {
                    controller.reset();
                    Err(dflat_control::ControlError::Solver(
                        "controller panicked (reset)".into(),
                    ))
                });
                if result.is_err() && multi_rate {
                    // After a reset (panic) the window needs a sample again
                    // (a repeated sample replaces the one held).
                    self.observe(&pose, ls.attitude_yaw);
                }
                let solve = t0.elapsed();
                let solve_us = solve.as_micros().min(u128::from(u32::MAX)) as u32;
                solve_hist.record(u64::from(solve_us));
                row.solve_us = Some(solve_us);
                let path_done =
                    matches!(self.supervisor.goal(), Goal::Path) && reference.is_finished();
                let produced = result.map_err(|e| e.to_string()).and_then(|out| {
                    let thrust = self
                        .mapping
                        .normalized(out.command.thrust)
                        .map_err(|e| e.to_string())?;
                    let command = AttitudeCommand {
                        roll: out.command.roll,
                        pitch: out.command.pitch,
                        yaw: out.command.yaw,
                        thrust,
                    };
                    let command = self
                        .guard
                        .check(command, &mut self.counts)
                        .map_err(|e| e.to_string())?;
                    Ok((out, command))
                });
                // The one exit point: a guarded controller command, or the
                // fallback (held command, then level hover).
                let (command, out) = match produced {
                    Ok((out, command)) if solve <= period => {
                        if ls.error_streak > 0 {
                            info!(ticks = ls.error_streak, "controller recovered");
                        }
                        ls.error_streak = 0;
                        ls.fallback = None;
                        ls.solves.record(&out);
                        self.fallback.good(command);
                        self.residual
                            .predict([out.plan[1].x, out.plan[1].y, out.plan[1].z]);
                        (command, Some(out))
                    }
                    failed => {
                        match failed {
                            Ok(_) => {
                                self.counts.deadline_overruns += 1;
                                if ls.error_streak == 0 {
                                    warn!(solve_us, "deadline overrun: fallback command");
                                }
                            }
                            Err(e) => {
                                ls.control_errors += 1;
                                self.counts.controller_failures += 1;
                                if ls.error_streak == 0 {
                                    warn!(error = %e, "controller failed: fallback command");
                                }
                            }
                        }
                        ls.error_streak += 1;
                        // The previous plan, one step further per failed
                        // tick (DF-MPC; recorded in its window), guarded
                        // like any command; else held / level hover.
                        let planned = self
                            .controller
                            .plan_fallback(&measurement, self.fallback.hold_ticks as usize)
                            .and_then(|out| {
                                let thrust = self.mapping.normalized(out.command.thrust).ok()?;
                                let command = AttitudeCommand {
                                    roll: out.command.roll,
                                    pitch: out.command.pitch,
                                    yaw: out.command.yaw,
                                    thrust,
                                };
                                let command = self.guard.check(command, &mut self.counts).ok()?;
                                Some((command, out.plan[1]))
                            });
                        match planned {
                            Some((_, next)) => self.residual.predict([next.x, next.y, next.z]),
                            None => self.residual.forget(),
                        }
                        let (command, kind) = self.fallback.command(planned.map(|(c, _)| c));
                        let (counter, note, text) = match kind {
                            FallbackKind::Plan => (
                                &mut self.counts.plan_steps,
                                "plan",
                                "dflat: control failed, flying the previous plan",
                            ),
                            FallbackKind::Held => (
                                &mut self.counts.held,
                                "held",
                                "dflat: control failed, holding last command",
                            ),
                            FallbackKind::LevelHover => (
                                &mut self.counts.level_hover,
                                "level",
                                "dflat: control failed, level hover",
                            ),
                        };
                        *counter += 1;
                        row.guard = Some(note);
                        if ls.fallback != Some(kind) {
                            ls.fallback = Some(kind);
                            self.send(
                                Outgoing::plain(statustext(
                                    MavSeverity::MAV_SEVERITY_CRITICAL,
                                    text,
                                )),
                                &mut ls,
                            );
                        }
                        (command, None)
                    }
                };
                // The fallback is finite by construction; checked all the same.
                let time_boot_ms = (t * 1000.0) as u64 as u32;
                let message = self
                    .guard
                    .check(command, &mut self.counts)
                    .map_err(|e| e.to_string())
                    .and_then(|c| {
                        set_attitude_target(self.target, time_boot_ms, &c)
                            .map(|m| (c, m))
                            .map_err(|e| e.to_string())
                    });
                match message {
                    Ok((command, message)) => {
                        let fresh = ls.last_used_arrival != Some(arrival);
                        ls.last_used_arrival = Some(arrival);
                        self.send(
                            Outgoing {
                                message,
                                tick: Some(wake),
                                pose_arrival: fresh.then_some(arrival),
                            },
                            &mut ls,
                        );
                        ls.commands += 1;
                        row.command =
                            Some([command.roll, command.pitch, command.yaw, command.thrust]);
                    }
                    Err(e) => {
                        error!(error = %e, "guarded command not encodable: nothing sent");
                    }
                }
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
                        ls.disturbance = Some(DisturbanceSummary {
                            report,
                            hover_thrust_normalized: hover,
                        });
                    }
                }
                if path_done {
                    if let Some(tr) = self.supervisor.on_path_finished(t) {
                        self.announce(&tr, &mut ls);
                    }
                    // Holding the end, or the path again (`mission.repeat`).
                    self.refresh_reference(&mut ls);
                }
            }
            row.state = self.supervisor.state();
            jitter.record(slot.jitter.as_micros().min(u128::from(u64::MAX)) as u64);
            if let Some(csv) = &self.csv {
                csv.record(&row);
            }
            self.ticks.fetch_add(1, Ordering::Relaxed);
        }

        // Shutdown: the stream has stopped (this loop no longer runs).
        let now = self.secs(Instant::now());
        info!(
            state = self.supervisor.state().name(),
            "control loop stopped"
        );
        self.send(
            Outgoing::plain(statustext(
                MavSeverity::MAV_SEVERITY_NOTICE,
                "dflat: shutdown, attitude stream off",
            )),
            &mut ls,
        );
        self.state.store(ST_SHUTDOWN, Ordering::Relaxed);
        let csv = self.csv.take().map(CsvRecorder::finish);
        ControlReport {
            ticks: self.ticks.load(Ordering::Relaxed),
            missed: schedule.missed_total(),
            commands: ls.commands,
            control_errors: ls.control_errors,
            outbound_dropped: ls.outbound_dropped,
            solve: solve_hist,
            jitter,
            time_in_state: self.supervisor.time_in_states(now),
            state_changes: self.supervisor.transitions(),
            final_state: self.supervisor.state(),
            csv,
            disturbance: ls.disturbance,
            guards: self.counts,
            solves: ls.solves,
        }
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
    fn observe(&mut self, pose: &PoseSample, attitude_yaw: Option<f64>) {
        let sample = Measurement {
            t: pose.capture,
            position: Vector3::from(pose.position),
            yaw: self.yaw_of(pose.yaw, attitude_yaw),
        };
        self.controller.observe(&sample);
    }

    /// Resets the controller (failsafe: window and disturbance estimate
    /// forgotten); a multi-rate controller gets the newest pose again so
    /// that it can run at the next tick.
    fn reset_controller(&mut self, ls: &LoopState) {
        self.controller.reset();
        self.fallback.forget();
        self.residual.forget();
        if self.controller.multi_rate()
            && let Some(pose) = ls.pose
        {
            self.observe(&pose, ls.attitude_yaw);
        }
    }

    fn apply(&mut self, event: Event, ls: &mut LoopState) {
        match event {
            Event::Pose {
                arrival,
                source_time,
                position,
                yaw,
                reset_counter,
            } => {
                let arrival_s = self.secs(arrival);
                self.supervisor.on_pose(arrival_s, position);
                let capture = match self.config.link.pose_time {
                    PoseTime::Source => self.clock.capture_time(arrival_s, source_time),
                    PoseTime::Arrival => arrival_s,
                };
                let mut pose = PoseSample {
                    arrival,
                    capture,
                    source_time,
                    position,
                    yaw,
                    reset_counter,
                };
                // A jump from the newest pose (further than the vehicle can
                // fly in between, or an estimator reset): re-anchor below.
                let s = &self.config.safety;
                let jump = ls.pose.is_some_and(|p| {
                    capture >= p.capture
                        && is_pose_jump(
                            p.position,
                            position,
                            capture - p.capture,
                            s.max_speed_mps,
                            1.0 / self.config.controller.rate_hz,
                            s.pose_jump_margin_m,
                            (p.reset_counter, reset_counter),
                        )
                });
                // Every sample to a multi-rate controller (late ones too).
                if !jump {
                    self.observe(&pose, ls.attitude_yaw);
                }
                // The newest for the others, by the source's own clock when
                // both have one (a falling offset estimate may map a newer
                // pose before the previous capture), else by capture time;
                // its time must then be newer than the previous one's, or
                // the controller takes the tick as one without a new pose.
                let newer = |p: &PoseSample| match (source_time, p.source_time) {
                    (Some(a), Some(b)) if (a - b).abs() < crate::clock::SOURCE_RESET => a > b,
                    _ => capture > p.capture,
                };
                match ls.pose {
                    None => ls.pose = Some(pose),
                    Some(p) if newer(&p) => {
                        pose.capture = pose.capture.max(p.capture + 1e-6);
                        ls.pose = Some(pose);
                    }
                    Some(_) => {}
                }
                if jump {
                    // The jumped pose is the newest one now.
                    ls.pose = Some(pose);
                    self.re_anchor(arrival_s, &pose, ls);
                }
            }
            Event::Attitude { yaw } => ls.attitude_yaw = Some(yaw),
            Event::Heartbeat { arrival } => self.supervisor.on_heartbeat(self.secs(arrival)),
            Event::Setpoint { arrival, position } => {
                let t = self.secs(arrival);
                match self.supervisor.on_setpoint(t, position) {
                    SetpointOutcome::Accepted { goal, transition } => {
                        debug!(?goal, "setpoint accepted");
                        if let Some(tr) = transition {
                            self.announce(&tr, ls);
                        }
                        self.refresh_reference(ls);
                    }
                    SetpointOutcome::Unchanged => {}
                    SetpointOutcome::Refused(refusal) => {
                        let due = ls
                            .last_refusal_text
                            .is_none_or(|last| t - last >= REFUSAL_TEXT_INTERVAL);
                        if due {
                            ls.last_refusal_text = Some(t);
                            info!(?refusal, "setpoint refused");
                            self.send(
                                Outgoing::plain(statustext(
                                    MavSeverity::MAV_SEVERITY_WARNING,
                                    &refusal.text(),
                                )),
                                ls,
                            );
                        }
                    }
                }
            }
        }
    }

    /// Rebuilds the reference when the supervisor's goal changed.
    fn refresh_reference(&mut self, ls: &mut LoopState) {
        let generation = self.supervisor.goal_generation();
        if generation == ls.reference_generation {
            return;
        }
        ls.reference_generation = generation;
        ls.reference = match reference_for(&self.config, self.supervisor.goal()) {
            Some(Ok(r)) => Some(r),
            Some(Err(e)) => {
                // Validated at start; a setpoint is checked finite. Keep flying
                // the previous reference rather than none.
                error!(error = %e, "cannot build the reference; keeping the previous one");
                ls.reference.take()
            }
            None => None,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_codes_round_trip() {
        for s in FlightState::ALL {
            assert_eq!(decode_state(encode_state(s)), Some(s));
        }
        assert_eq!(decode_state(ST_BOOT), None);
        assert_eq!(decode_state(ST_SHUTDOWN), None);
        assert_eq!(daemon_status(ST_BOOT), DaemonStatus::Boot);
        assert_eq!(daemon_status(ST_SHUTDOWN), DaemonStatus::Poweroff);
        assert_eq!(
            daemon_status(encode_state(FlightState::Failsafe)),
            DaemonStatus::Critical
        );
        assert_eq!(
            daemon_status(encode_state(FlightState::Tracking)),
            DaemonStatus::Active
        );
    }

    #[test]
    fn supervisor_config_from_defaults() {
        let c = supervisor_config(&Config::default());
        assert_eq!(c.pose_timeout, 0.1);
        assert_eq!(c.autopilot_timeout, 3.0);
        assert_eq!(
            c.path_ends,
            Some(([-20.0, -30.0, -10.0], [0.0, 0.0, -10.0]))
        );
        assert!(!c.start_path);
    }
}
