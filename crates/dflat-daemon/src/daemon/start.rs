//! Start-up as typed handles, in order: the checks ([`Checked`]), the
//! records ([`PendingRecords`]: a link that does not open deletes them),
//! the link ([`OpenLink`]), the link tasks ([`LinkTasks`]) and the control
//! thread ([`ControlThread`]: dropped before the start completes, it stops
//! the parts and joins the thread).

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64};
use std::time::{Instant, SystemTime};

use dflat_link::transport::{Endpoint, OpenOptions, Transport, TransportError, UdpInPeer};
use dflat_link::{LinkRx, ThrustMapping, timestamp_from_system_time};
use tokio::sync::mpsc;
use tracing::{error, info, warn};

use super::{
    ControlReport, DaemonError, Outgoing, RxReport, Stop, TxReport, control_loop, link_tasks,
};
use crate::config::Config;
use crate::control::{configured_path, thrust_mapping};
use crate::link_health::{CommandSlot, LinkHealth, StallHook};
use crate::record_store::OpenRecords;
use crate::signing::TimestampStore;
use crate::tick::{Event, pose_source, source_filter};
use dflat_link::Signing;

/// What the checks before a start found: where the link goes, the udpin
/// peer (`link.peer`), the thrust mapping.
#[derive(Debug)]
pub(super) struct Checked {
    /// The link's endpoint.
    pub endpoint: Endpoint,
    /// `link.peer`, if set.
    pub peer: Option<SocketAddr>,
    /// The commands' thrust mapping.
    pub mapping: ThrustMapping,
}

/// The checks a start makes before it opens anything, whatever the
/// controller: the connection string and `link.peer` (parsed), the
/// configured path, the thrust mapping.
pub(super) fn start_checks(
    config: &Config,
    link_override: Option<&str>,
) -> Result<Checked, DaemonError> {
    let url = link_override.unwrap_or(&config.link.url);
    let endpoint = Endpoint::parse(url).map_err(DaemonError::Link)?;
    let peer = match config.link.peer.trim() {
        "" => None,
        p => Some(p.parse::<SocketAddr>().map_err(|e| {
            DaemonError::Link(TransportError::BadUrl {
                url: p.to_owned(),
                reason: format!("link.peer: {e}"),
            })
        })?),
    };
    if let Some(path) = configured_path(config) {
        path?;
    }
    let mapping = thrust_mapping(config);
    mapping
        .validate()
        .map_err(|e| DaemonError::Internal(format!("thrust mapping: {e}")))?;
    Ok(Checked {
        endpoint,
        peer,
        mapping,
    })
}

/// A flight's records, opened before the link (the link records into the
/// tap from its first frame): kept once the link is open, else discarded
/// (the writers stop and the files are deleted: a failed start leaves no
/// empty flight behind). [`OpenLink::open`] consumes it either way; if it
/// is dropped unkept on any other path (an early return, a panic), `Drop`
/// discards the records.
#[derive(Debug)]
pub(super) struct PendingRecords(Option<OpenRecords>);

impl PendingRecords {
    /// Opens the records of `config` (never a reason not to fly: disk
    /// trouble is noticed, not fatal).
    pub(super) fn open(config: &Config) -> Self {
        Self(Some(crate::record_store::open(config, SystemTime::now())))
    }

    /// The tap the link records into.
    fn tap(&self) -> Option<dflat_link::transport::TlogTap> {
        self.0.as_ref().and_then(|r| r.tap.clone())
    }

    /// The start goes on: the oldest flights are pruned (`records.keep_mb`)
    /// and the records are kept.
    fn keep(mut self, config: &Config) -> OpenRecords {
        let mut records = self.0.take().expect("pending records are kept once");
        records.prune(config);
        records
    }

    /// Deletes the records off the runtime's threads (the writers' close
    /// blocks) and waits for it.
    async fn discard(mut self) {
        if let Some(records) = self.0.take() {
            let _ = tokio::task::spawn_blocking(move || records.discard()).await;
        }
    }
}

impl Drop for PendingRecords {
    /// Records neither kept nor discarded are discarded here, on a thread
    /// of their own: the writers' close blocks on the runtime, which may be
    /// the one dropping them (a failed start's path, not a flight's).
    fn drop(&mut self) {
        if let Some(records) = self.0.take() {
            let spawned = std::thread::Builder::new()
                .name("dflat-discard".into())
                .spawn(move || records.discard());
            if let Err(e) = spawned {
                warn!(error = %e, "cannot discard the records of a failed start");
            }
        }
    }
}

/// The open link: its endpoint, the transport, the local address and
/// signing (with its timestamp store).
pub(super) struct OpenLink {
    /// Where it goes.
    pub endpoint: Endpoint,
    /// The transport (shared by the tasks).
    pub transport: Transport,
    /// The local socket address (UDP, TCP).
    pub local_addr: Option<SocketAddr>,
    /// MAVLink 2 signing, if on.
    pub signing: Option<(Signing, TimestampStore)>,
}

impl OpenLink {
    /// MAVLink 2 signing as `[link]` sets it up (before anything opens).
    pub(super) fn signing(
        config: &Config,
    ) -> Result<Option<(Signing, TimestampStore)>, DaemonError> {
        let now = timestamp_from_system_time(SystemTime::now());
        Ok(crate::signing::setup(&config.link, now)?)
    }

    /// Opens the link `checked` names with `signing`, recording into
    /// `records`' tap. On an error the records are discarded (the link's
    /// error is the one reported).
    pub(super) async fn open(
        config: &Config,
        checked: &Checked,
        signing: Option<(Signing, TimestampStore)>,
        records: PendingRecords,
    ) -> Result<(Self, OpenRecords), DaemonError> {
        if let Some((s, store)) = &signing {
            info!(
                link_id = s.link_id(),
                timestamp = s.timestamp(),
                timestamp_file = %store.path().display(),
                accept_unsigned = ?s.accept_unsigned,
                "MAVLink 2 signing on"
            );
        }
        // udpin: one peer (link.peer, or the first sender of the
        // autopilot's HEARTBEAT); udpout connects; tcp / serial reconnect.
        if checked.peer.is_some() && !matches!(checked.endpoint, Endpoint::UdpIn { .. }) {
            warn!(link = %checked.endpoint, "link.peer applies to udpin links only: ignored");
        }
        let options = OpenOptions {
            tap: records.tap(),
            udpin_peer: UdpInPeer::Lock(checked.peer),
            reconnect: true,
        };
        let transport = match Transport::open_with(&checked.endpoint, options).await {
            Ok(t) => t,
            Err(e) => {
                records.discard().await;
                return Err(DaemonError::Link(e));
            }
        };
        let link = Self {
            endpoint: checked.endpoint.clone(),
            local_addr: transport.local_addr(),
            transport,
            signing,
        };
        Ok((link, records.keep(config)))
    }
}

/// What the parts share: the stop, the published state and tick count,
/// the link's fault, the epoch, liveness and the stall hook.
#[derive(Clone)]
pub(super) struct Shared {
    /// The stop request.
    pub stop: Arc<Stop>,
    /// The published flight state.
    pub state: Arc<AtomicU8>,
    /// Ticks run.
    pub ticks: Arc<AtomicU64>,
    /// Why the link closed, if it did.
    pub fault: Arc<std::sync::Mutex<Option<TransportError>>>,
    /// The daemon's epoch.
    pub epoch: Instant,
    /// Link-task liveness.
    pub health: Arc<LinkHealth>,
    /// The test-only stall hook.
    pub stall: Option<StallHook>,
}

/// The queues between the parts, the control thread's ends.
pub(super) struct ControlEnds {
    /// Events from the receive task.
    pub events: std::sync::mpsc::Receiver<Event>,
    /// Missions from the receive task.
    pub missions: std::sync::mpsc::Receiver<Option<crate::mission::Mission>>,
    /// The daemon's own queue to the send task.
    pub out: mpsc::Sender<Outgoing>,
}

/// The running link tasks: receive, send, HEARTBEAT.
#[derive(Debug)]
pub(super) struct LinkTasks {
    /// The receive task.
    pub rx: tokio::task::JoinHandle<RxReport>,
    /// The send task.
    pub tx: tokio::task::JoinHandle<TxReport>,
    /// The HEARTBEAT task.
    pub heartbeat: tokio::task::JoinHandle<()>,
    /// The command slot the control thread fills.
    pub commands: Arc<CommandSlot<Outgoing>>,
    /// Replies dropped because their queue was full.
    pub replies_dropped: Arc<AtomicU64>,
}

impl LinkTasks {
    /// Starts the link tasks on `link` (its signing moves to the send
    /// task); returns them and the control thread's ends of the queues.
    pub(super) fn start(
        config: &Config,
        link: &mut OpenLink,
        shared: &Shared,
        epoch_unix_us: u64,
    ) -> (Self, ControlEnds) {
        let (event_tx, event_rx) = std::sync::mpsc::sync_channel::<Event>(super::EVENT_QUEUE);
        let (out_tx, out_rx) = mpsc::channel::<Outgoing>(super::OUTBOUND_QUEUE);
        let (mission_tx, mission_rx) = std::sync::mpsc::channel();
        let (reply_tx, reply_rx) = mpsc::channel::<Outgoing>(crate::link_health::REPLY_QUEUE);
        let replies_dropped = Arc::new(AtomicU64::new(0));
        let commands = Arc::new(CommandSlot::<Outgoing>::default());
        let own = (config.link.system_id, config.link.component_id);
        let signing = link.signing.take();
        let mut link_rx = LinkRx::new(source_filter(&config.link));
        link_rx.signing = signing.as_ref().map(|(s, _)| s.clone());
        let rx_ctx = super::receive::RxContext {
            epoch: shared.epoch,
            epoch_unix_us,
            pose_source: pose_source(config.link.pose_source),
            own,
            autopilot_component: config.link.autopilot_component,
            yaw: config.vehicle.yaw_deg.to_radians(),
            yaw_fixed: config.vehicle.yaw_mode == crate::config::YawMode::Fixed,
            state: shared.state.clone(),
            mission_rules: crate::mission::ItemRules::of(&config.mission),
            missions: mission_tx,
            health: shared.health.clone(),
            stall: shared.stall,
        };
        let replies = link_tasks::Replies {
            tx: reply_tx,
            dropped: replies_dropped.clone(),
        };
        let rx = tokio::spawn(link_tasks::receive_task(
            link.transport.clone(),
            link_rx,
            rx_ctx,
            event_tx,
            replies,
            shared.stop.clone(),
            shared.fault.clone(),
        ));
        let inputs = link_tasks::SendInputs {
            commands: commands.clone(),
            out: out_rx,
            replies: reply_rx,
            max_command_age: super::period(config),
            health: shared.health.clone(),
            stall: shared.stall,
            epoch: shared.epoch,
        };
        let tx = tokio::spawn(link_tasks::send_task(
            link.transport.clone(),
            inputs,
            shared.stop.clone(),
            own,
            signing,
        ));
        let heartbeat = tokio::spawn(link_tasks::heartbeat_task(
            out_tx.clone(),
            shared.state.clone(),
            shared.stop.clone(),
            shared.health.clone(),
            shared.stall,
            shared.epoch,
        ));
        let tasks = Self {
            rx,
            tx,
            heartbeat,
            commands,
            replies_dropped,
        };
        let ends = ControlEnds {
            events: event_rx,
            missions: mission_rx,
            out: out_tx,
        };
        (tasks, ends)
    }
}

/// The control thread, once started. Dropped before the start completes
/// (the real-time settings refused), it asks every part to stop and joins
/// the thread.
#[derive(Debug)]
pub(super) struct ControlThread {
    handle: Option<std::thread::JoinHandle<ControlReport>>,
    stop: Arc<Stop>,
}

impl ControlThread {
    /// Starts `control` on its own thread and waits until it has applied
    /// `[realtime]`: refused, the start fails (the other parts stop with the
    /// stop request).
    pub(super) async fn start(
        mut control: control_loop::ControlLoop,
        stop: Arc<Stop>,
    ) -> Result<Self, DaemonError> {
        let (rt_tx, rt_rx) = tokio::sync::oneshot::channel();
        control.realtime_result = Some(rt_tx);
        let handle = std::thread::Builder::new()
            .name("dflat-control".into())
            .spawn(move || control.run())
            .map_err(|e| DaemonError::Internal(format!("cannot start the control thread: {e}")))?;
        let thread = Self {
            handle: Some(handle),
            stop,
        };
        // Refused or ended: `thread` is dropped, the parts stop.
        match rt_rx.await {
            Ok(Ok(_)) => Ok(thread),
            Ok(Err(e)) => {
                error!(error = %e, "real-time settings refused");
                Err(DaemonError::Realtime(e))
            }
            Err(_) => Err(DaemonError::Internal(
                "control thread ended at start".into(),
            )),
        }
    }

    /// The started thread, handed over to the running daemon.
    pub(super) fn into_handle(
        mut self,
    ) -> Result<std::thread::JoinHandle<ControlReport>, DaemonError> {
        self.handle
            .take()
            .ok_or_else(|| DaemonError::Internal("control thread handed over twice".into()))
    }
}

impl Drop for ControlThread {
    fn drop(&mut self) {
        if let Some(handle) = self.handle.take() {
            self.stop.request();
            let _ = handle.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flight files in `dir`.
    fn flight_files(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
        std::fs::read_dir(dir)
            .map(|d| {
                d.filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| p.to_string_lossy().contains("flight-"))
                    .collect()
            })
            .unwrap_or_default()
    }

    #[tokio::test(flavor = "current_thread")]
    async fn records_dropped_unkept_are_discarded() {
        let dir = std::env::temp_dir().join(format!("dflat-pending-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut cfg = Config::default();
        cfg.logging.dir = dir.display().to_string();
        let pending = PendingRecords::open(&cfg);
        assert!(!flight_files(&dir).is_empty(), "the records opened");
        // Dropped inside the runtime whose task writes the tap: no panic,
        // no deadlock, and the files go.
        drop(pending);
        for _ in 0..500 {
            if flight_files(&dir).is_empty() {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(10)).await;
        }
        assert!(flight_files(&dir).is_empty(), "{:?}", flight_files(&dir));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[tokio::test(flavor = "current_thread")]
    async fn kept_records_stay() {
        let dir = std::env::temp_dir().join(format!("dflat-kept-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut cfg = Config::default();
        cfg.logging.dir = dir.display().to_string();
        let records = PendingRecords::open(&cfg).keep(&cfg);
        assert!(!flight_files(&dir).is_empty());
        drop(records);
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        assert!(
            !flight_files(&dir).is_empty(),
            "kept records are not deleted"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
