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
//! (`controller.dfmpc.multi_rate`) gets every pose through
//! [`Controller::observe`] at its capture time and, per tick,
//! [`Controller::update`] with the tick's wake time. The other controllers
//! get, per tick, the newest pose with its capture time; a tick that finds
//! no new pose passes the previous one with its old time, and the
//! controller substitutes its own prediction.
//!
//! Entry points: [`run`] (used by `dflat daemon`) and [`spawn`] /
//! [`DaemonHandle`] (in-process use: demo, tests).

mod control_loop;
mod link_tasks;
mod receive;
mod start;
use start::{ControlThread, LinkTasks, OpenLink, PendingRecords, Shared, start_checks};

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use dflat_control::Controller;
use dflat_link::transport::{TlogTap, Transport, TransportError};
use dflat_link::{DaemonStatus, LinkStats, MavMessage};
use thiserror::Error;
use tokio::sync::watch;
use tracing::{error, info, warn};

use crate::config::{Config, ModelKind, TickMode};
use crate::control::build_controller;
use crate::guard::GuardCounts;
use crate::link_health::{CommandSlot, LinkGuardSummary, LinkHealth, StallHook};
use crate::records::CsvReport;
use crate::signing::SigningError;
use crate::summary::{
    DisturbanceSummary, FlightSummary, Histogram, LinkSummary, SolveCounts, StateTimes,
    peak_rss_kib, process_cpu_seconds,
};
use crate::supervisor::FlightState;
use crate::tick::ControlCore;
pub use crate::tick::supervisor_config;
pub use receive::setpoint_refusal_text;

/// Capacity of the receive task → control thread queue \[events\].
const EVENT_QUEUE: usize = 1024;
/// Capacity of the outbound queue to the send task \[messages\].
const OUTBOUND_QUEUE: usize = 256;
/// How long shutdown waits for the send task to drain \[s\].
const SEND_DRAIN_TIMEOUT: Duration = Duration::from_secs(2);

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
    /// `[realtime]` asked for a scheduling the system refused (the message
    /// names the field and what to grant).
    #[error("{0}")]
    Realtime(#[from] crate::realtime::RealtimeError),
    /// A thread could not be started or ended abnormally.
    #[error("internal: {0}")]
    Internal(String),
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
const ST_SHUTDOWN: u8 = 6;

fn encode_state(s: FlightState) -> u8 {
    s.index() as u8 + 1
}

fn decode_state(v: u8) -> Option<FlightState> {
    match v {
        1..=5 => Some(FlightState::ALL[usize::from(v - 1)]),
        _ => None,
    }
}

fn daemon_status(v: u8) -> DaemonStatus {
    match decode_state(v) {
        None if v == ST_BOOT => DaemonStatus::Boot,
        None => DaemonStatus::Poweroff,
        Some(FlightState::WaitingForPose | FlightState::Standby) => DaemonStatus::Standby,
        Some(FlightState::Holding | FlightState::Tracking) => DaemonStatus::Active,
        Some(FlightState::Failsafe) => DaemonStatus::Critical,
    }
}

/// Stop request shared by all parts: a flag for the control thread and a
/// watch for the tasks; and the graceful stop the control thread carries
/// out first (brake, level: `tick/envelope.rs`), after which it requests
/// the stop of the other parts itself.
#[derive(Debug)]
struct Stop {
    flag: AtomicBool,
    tx: watch::Sender<bool>,
    graceful: AtomicBool,
}

impl Stop {
    /// Asks for the graceful stop (SIGTERM, SIGINT, [`DaemonHandle::shutdown`]).
    fn ask(&self) {
        self.graceful.store(true, Ordering::SeqCst);
    }

    fn asked(&self) -> bool {
        self.graceful.load(Ordering::SeqCst)
    }

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
    tick_counts: crate::schedule::TickCounts,
    realtime: crate::realtime::RealtimeApplied,
    commands: u64,
    control_errors: u64,
    outbound_dropped: u64,
    solve: Histogram,
    jitter: Histogram,
    time_in_state: [f64; 5],
    state_changes: u64,
    stop: Option<crate::summary::StopSummary>,
    engagements: u64,
    disengagements: u64,
    final_state: FlightState,
    csv: Option<CsvReport>,
    disturbance: Option<DisturbanceSummary>,
    guards: GuardCounts,
    solves: SolveCounts,
    pose_window: Option<dflat_control::window::PoseWindowStats>,
    autopilot_streams: Vec<crate::stream_rates::StreamOutcome>,
}

/// What the receive task counted.
#[derive(Debug, Default)]
struct RxReport {
    stats: LinkStats,
    transport_errors: u64,
    events_dropped: u64,
    /// udpin: frames dropped before the peer was locked.
    foreign_frames: u64,
    /// udpin: the peer locked onto.
    peer: Option<SocketAddr>,
}

/// What the send task counted.
#[derive(Debug, Default)]
struct TxReport {
    stats: LinkStats,
    latency: Histogram,
    tick_to_send: Histogram,
    commands_stale: u64,
    replies_sent: u64,
    replies_pending: u64,
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
    health: Arc<LinkHealth>,
    parts: Parts,
}

#[derive(Debug)]
struct Parts {
    link: String,
    controller: String,
    model: String,
    rate_hz: f64,
    tick_mode: &'static str,
    started: Instant,
    cpu_at_start: Option<f64>,
    tap: Option<TlogTap>,
    transport: Transport,
    commands: Arc<CommandSlot<Outgoing>>,
    replies_dropped: Arc<AtomicU64>,
    records_budget: Arc<dflat_link::records::RecordBudget>,
    records_summary: crate::record_store::RecordsSummary,
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
    /// While engaged the control thread first brakes and levels the
    /// vehicle (`safety.stop_brake_ms`, `safety.stop_level_ms`), then the
    /// stream and the other parts stop.
    pub fn shutdown(&self) {
        self.stop.ask();
    }

    /// True once a stop was asked for ([`shutdown`](Self::shutdown)).
    pub fn stop_asked(&self) -> bool {
        self.stop.asked()
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
        // The control thread brakes and levels first, then stops the rest.
        self.stop.ask();
        let Parts {
            link,
            controller,
            model,
            rate_hz,
            tick_mode,
            started,
            cpu_at_start,
            tap,
            transport,
            commands,
            replies_dropped,
            records_budget,
            records_summary,
            control,
            rx,
            tx,
            heartbeat,
        } = self.parts;
        let control = tokio::task::spawn_blocking(move || control.join())
            .await
            .map_err(|e| DaemonError::Internal(format!("control thread join: {e}")))?
            .map_err(|_| DaemonError::Internal("control thread panicked".into()));
        // Whatever the control thread did, the tasks stop now.
        self.stop.request();
        let control = control?;
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
        let counters = transport.counters();
        let link_guard = LinkGuardSummary {
            foreign_frames: counters.foreign_datagrams + rx.foreign_frames,
            peer: rx.peer,
            reconnects: counters.reconnects,
            send_dropped: counters.send_dropped,
            future_timestamp: rx.stats.future_timestamp,
            commands_replaced: commands.replaced(),
            commands_stale: tx.commands_stale,
            replies_dropped: replies_dropped.load(Ordering::Relaxed) + tx.replies_pending,
            replies_sent: tx.replies_sent,
            link_stalls: self.health.stalls(),
        };
        let summary = FlightSummary {
            link,
            controller,
            model,
            rate_hz,
            duration_s,
            ticks: control.ticks,
            missed_ticks: control.missed,
            tick_mode: tick_mode.to_owned(),
            pose_ticks: control.tick_counts.by_pose,
            deadline_ticks: control.tick_counts.by_deadline,
            fallback_ticks: control.tick_counts.fallbacks,
            realtime: control.realtime,
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
            stop: control.stop,
            engagements: control.engagements,
            disengagements: control.disengagements,
            final_state: control.final_state,
            cpu_percent,
            peak_rss_kib: peak_rss_kib(),
            csv: control.csv,
            tlog,
            disturbance: control.disturbance,
            guards: control.guards,
            solves: control.solves,
            pose_window: control.pose_window,
            autopilot_streams: control.autopilot_streams,
            link_guard,
            records: crate::record_store::finish_summary(records_summary, &records_budget),
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

/// The daemon's signals: resolves on SIGINT or SIGTERM (the graceful
/// stop: brake, level, stream off, records and summary written). SIGHUP,
/// SIGUSR1 and SIGUSR2 never stop the daemon: each is logged (WARN) and
/// otherwise ignored — the configuration is read at start only, so a
/// terminal that hangs up, a `kill -HUP` or a `systemctl kill -s USR1`
/// leaves the flight alone (restart the service to re-read the config).
/// Ctrl-C only on non-Unix systems.
pub async fn daemon_signals() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let kept = [
            ("SIGHUP", SignalKind::hangup()),
            ("SIGUSR1", SignalKind::user_defined1()),
            ("SIGUSR2", SignalKind::user_defined2()),
        ];
        let mut handlers = Vec::new();
        for (name, kind) in kept {
            match signal(kind) {
                Ok(s) => handlers.push((name, s)),
                Err(e) => error!(error = %e, signal = name, "cannot install the signal handler"),
            }
        }
        let ignore = async move {
            let streams: Vec<_> = handlers
                .into_iter()
                .map(|(name, mut s)| {
                    Box::pin(async move {
                        loop {
                            if s.recv().await.is_none() {
                                return;
                            }
                            warn!(
                                signal = name,
                                "{name} ignored: the daemon keeps flying (the configuration is read at start only)"
                            );
                        }
                    })
                })
                .collect();
            futures_join_all(streams).await;
        };
        tokio::select! {
            () = shutdown_signal() => {}
            () = ignore => std::future::pending::<()>().await,
        }
    }
    #[cfg(not(unix))]
    shutdown_signal().await
}

/// Polls every future to its end (each here runs for ever).
#[cfg(unix)]
async fn futures_join_all<F: Future<Output = ()> + Unpin>(mut futures: Vec<F>) {
    std::future::poll_fn(|cx| {
        futures.retain_mut(|f| std::pin::Pin::new(f).poll(cx).is_pending());
        if futures.is_empty() {
            std::task::Poll::Ready(())
        } else {
            std::task::Poll::Pending
        }
    })
    .await
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

/// What the daemon checks before it opens anything, beyond
/// [`Config::validate`]: the connection string (`link_override` or
/// `link.url`) and `link.peer`, the configured path, the controller, the
/// thrust mapping and the signing key (read, not used). `dflat
/// check-config` runs the same checks, so it refuses exactly what a start
/// refuses (run it as the daemon's user: the key's owner is checked).
/// Creates and writes nothing.
pub fn preflight(config: &Config, link_override: Option<&str>) -> Result<(), DaemonError> {
    start_checks(config, link_override)?;
    build_controller(config)?;
    let key = config.link.signing_key_file.trim();
    if !key.is_empty() {
        crate::signing::load_key(std::path::Path::new(key))?;
    }
    Ok(())
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
    controller: Box<dyn Controller>,
) -> Result<DaemonHandle, DaemonError> {
    let checked = start_checks(&config, link_override.as_deref())?;
    let signing = OpenLink::signing(&config)?;
    // Records: never a reason not to fly (disk trouble is noticed).
    let records = PendingRecords::open(&config);
    let (mut link, mut records) = OpenLink::open(&config, &checked, signing, records).await?;
    say_started(&config, &link, controller.name());
    let (stop_tx, stop_rx) = watch::channel(false);
    let epoch = Instant::now();
    let shared = Shared {
        stop: Arc::new(Stop {
            flag: AtomicBool::new(false),
            tx: stop_tx,
            graceful: AtomicBool::new(false),
        }),
        state: Arc::new(AtomicU8::new(ST_BOOT)),
        ticks: Arc::new(AtomicU64::new(0)),
        fault: Arc::new(std::sync::Mutex::new(None)),
        epoch,
        health: Arc::new(LinkHealth::new(epoch)),
        stall: StallHook::from_env(),
    };
    let epoch_unix_us = dflat_link::transport::unix_time_us();
    let cpu_at_start = process_cpu_seconds();
    let (tasks, ends) = LinkTasks::start(&config, &mut link, &shared, epoch_unix_us);
    let records_budget = records.budget.clone();
    let controller_name = controller.name().to_owned();
    let control = control_loop::ControlLoop {
        core: ControlCore::new(&config, controller, checked.mapping),
        events: ends.events,
        missions: ends.missions,
        out: ends.out,
        commands: tasks.commands.clone(),
        health: shared.health.clone(),
        stop: shared.stop.clone(),
        state: shared.state.clone(),
        ticks: shared.ticks.clone(),
        epoch,
        csv: records.csv.take(),
        records: records_budget.clone(),
        period: period(&config),
        pose_lock: config.controller.tick == TickMode::Pose,
        pose_wait: config.controller.pose_wait_ms / 1000.0,
        pose_timeout: config.safety.pose_timeout_ms / 1000.0,
        realtime: config.realtime.clone(),
        realtime_result: None,
    };
    let control = ControlThread::start(control, shared.stop.clone())
        .await?
        .into_handle()?;
    Ok(DaemonHandle {
        stop: shared.stop,
        stop_rx,
        state: shared.state,
        ticks: shared.ticks,
        local_addr: link.local_addr,
        fault: shared.fault,
        health: shared.health,
        parts: Parts {
            link: link.endpoint.to_string(),
            controller: controller_name,
            model: match config.vehicle.model {
                ModelKind::Planar => "planar".into(),
                ModelKind::Spatial => "spatial".into(),
            },
            rate_hz: config.controller.rate_hz,
            tick_mode: match config.controller.tick {
                TickMode::Pose => "pose",
                TickMode::Clock => "clock",
            },
            started: epoch,
            cpu_at_start,
            tap: records.tap.take(),
            transport: link.transport,
            commands: tasks.commands,
            replies_dropped: tasks.replies_dropped,
            records_budget,
            records_summary: std::mem::take(&mut records.summary),
            control,
            rx: tasks.rx,
            tx: tasks.tx,
            heartbeat: tasks.heartbeat,
        },
    })
}

/// The control period of `config`.
fn period(config: &Config) -> Duration {
    Duration::from_secs_f64(1.0 / config.controller.rate_hz)
}

/// Logs the start: the link, the controller and the model; the deprecated
/// `link.gcs_system_id`; the test-only stall hook.
fn say_started(config: &Config, link: &OpenLink, controller: &str) {
    info!(
        link = %link.endpoint,
        local = ?link.local_addr,
        controller,
        model = ?config.vehicle.model,
        rate_hz = config.controller.rate_hz,
        "daemon started"
    );
    let v = &config.vehicle;
    if v.delay_ms > 0.0 || v.drag_h > 0.0 || v.drag_v > 0.0 || v.drag_rotor > 0.0 {
        let ticks = crate::control::delay_ticks(config);
        info!(
            delay_ms = v.delay_ms,
            delay_ticks = ticks,
            flown_ms = ticks as f64 * 1e3 / config.controller.rate_hz,
            drag_h = v.drag_h,
            drag_v = v.drag_v,
            drag_rotor = v.drag_rotor,
            "vehicle model: input delay rounded to control ticks, linear and rotor drag"
        );
    }
    if let Some(h) = StallHook::from_env() {
        warn!(
            task = h.task.name(),
            after_s = h.after_s,
            "test-only stall hook set (DFLAT_TEST_STALL_TASK)"
        );
    }
    if let Some(id) = config.link.gcs_system_id {
        warn!(
            id,
            "link.gcs_system_id is deprecated: read as link.gcs_system_ids = [{id}] (MAVSDK's 245 is not heard); set link.gcs_system_ids instead"
        );
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
