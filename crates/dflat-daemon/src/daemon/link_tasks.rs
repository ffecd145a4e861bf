//! The link tasks: receive (frames → events for the control thread, and the
//! answers a component owes: COMMAND_ACK, refusals), send (header,
//! sequence, signing, latency figures) and the 1 Hz HEARTBEAT.
//!
//! The send task serves, in this order: the command slot (the newest
//! SET_ATTITUDE_TARGET, dropped if older than one tick), the daemon's own
//! queue (HEARTBEAT, state texts) and, within [`ReplyBudget`], the replies
//! queue (answers and refusals from the receive task). Each task marks
//! itself alive in [`LinkHealth`] every [`BEAT_INTERVAL`].

use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime};

use dflat_link::transport::{RecvEvent, SendOutcome, Transport, TransportError};
use dflat_link::{
    DaemonStatus, LinkRx, MavHeader, MavMessage, Signing, heartbeat_onboard,
    timestamp_from_system_time,
};
use tokio::sync::mpsc;
use tracing::{debug, error, warn};

use super::receive::{FrameTime, Gate, ReceiveCore, RxContext, RxOutput};
use super::{Outgoing, RxReport, Stop, TxReport, daemon_status};
use crate::link_health::{
    BEAT_INTERVAL, CommandSlot, LinkHealth, LinkTask, REPLY_BURST, REPLY_RATE_HZ, ReplyBudget,
    StallHook,
};
use crate::signing::{PERSIST_INTERVAL, TimestampStore};
use crate::tick::Event;

/// The replies queue (bounded) and its drop counter.
#[derive(Debug, Clone)]
pub(super) struct Replies {
    /// To the send task.
    pub tx: mpsc::Sender<Outgoing>,
    /// Replies dropped because the queue was full.
    pub dropped: Arc<AtomicU64>,
}

impl Replies {
    fn send(&self, message: MavMessage) {
        if self.tx.try_send(Outgoing::plain(message)).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Waits until stopped (a stalled task's last state: no work, no beats).
async fn stalled(task: LinkTask, stop_rx: &mut tokio::sync::watch::Receiver<bool>) {
    warn!(task = task.name(), "test hook: link task stalled");
    let _ = stop_rx.wait_for(|s| *s).await;
}

/// Receives frames until stopped: the I/O around the receive step
/// ([`ReceiveCore`]): the transport, the clocks, the udpin lock, the tlog,
/// and the step's outputs handed on (events, replies, missions).
pub(super) async fn receive_task(
    transport: Transport,
    link: LinkRx,
    ctx: RxContext,
    events: std::sync::mpsc::SyncSender<Event>,
    out: Replies,
    stop: Arc<Stop>,
    fault: Arc<std::sync::Mutex<Option<TransportError>>>,
) -> RxReport {
    let mut stop_rx = stop.tx.subscribe();
    let mut report = RxReport::default();
    let mut core = ReceiveCore::new(link, &ctx);
    let mut mission_timer = tokio::time::interval(Duration::from_millis(100));
    mission_timer.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut beat = tokio::time::interval(BEAT_INTERVAL);
    beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let now = || ctx.epoch.elapsed().as_secs_f64();
    loop {
        let received = tokio::select! {
            biased;
            _ = stop_rx.wait_for(|s| *s) => break,
            _ = mission_timer.tick() => {
                hand_on(core.poll(now()), &ctx, &events, &out, &mut report);
                continue;
            }
            _ = beat.tick() => {
                if StallHook::due(ctx.stall, LinkTask::Receive, ctx.epoch.elapsed()) {
                    None
                } else {
                    ctx.health.beat(LinkTask::Receive, Instant::now());
                    continue;
                }
            }
            r = transport.recv() => Some(r),
        };
        let Some(received) = received else {
            stalled(LinkTask::Receive, &mut stop_rx).await;
            break;
        };
        let frame = match received {
            Ok(RecvEvent::Frame(frame)) => frame,
            Ok(RecvEvent::Error(e)) => {
                hand_on(
                    core.on_frame_error(&e, now()),
                    &ctx,
                    &events,
                    &out,
                    &mut report,
                );
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
        let signing_now = || timestamp_from_system_time(SystemTime::now());
        let locked_now = match core.gate(&frame, transport.awaiting_peer(), signing_now()) {
            Gate::Pass => false,
            Gate::Lock(from) => {
                if let Err(e) = transport.lock_peer(from).await {
                    warn!(error = %e, "cannot lock the udpin peer");
                    continue;
                }
                report.peer = Some(from);
                true
            }
            Gate::Foreign => {
                report.foreign_frames += 1;
                continue;
            }
        };
        // Whole µs since the epoch: the tlog records the same instant, so a
        // replay finds the arrival bit for bit (`tick::arrival_secs`).
        let arrival_us = u64::try_from(
            frame
                .arrival
                .saturating_duration_since(ctx.epoch)
                .as_micros(),
        )
        .unwrap_or(u64::MAX);
        let time = FrameTime {
            arrival_us,
            now: now(),
            signing_now: signing_now(),
            state: ctx.state.load(Ordering::Relaxed),
            fault: ctx.health.fault(),
        };
        let output = core.on_frame(&frame, locked_now, time);
        if output.record
            && let Some(tap) = transport.tap()
        {
            tap.record_received_at(&frame, ctx.epoch_unix_us.saturating_add(arrival_us));
        }
        hand_on(output, &ctx, &events, &out, &mut report);
    }
    report.stats = core.stats();
    report
}

/// Hands a receive step's outputs on: replies to the send task, missions
/// and events to the control thread (an event dropped when its queue is
/// full is counted).
fn hand_on(
    output: RxOutput,
    ctx: &RxContext,
    events: &std::sync::mpsc::SyncSender<Event>,
    out: &Replies,
    report: &mut RxReport,
) {
    for message in output.replies {
        out.send(message);
    }
    for mission in output.missions {
        let _ = ctx.missions.send(mission);
    }
    for event in output.events {
        if events.try_send(event).is_err() {
            report.events_dropped += 1;
        }
    }
}

/// What the send task takes from: the command slot, the daemon's own
/// queue, the replies queue.
pub(super) struct SendInputs {
    /// The newest SET_ATTITUDE_TARGET.
    pub commands: Arc<CommandSlot<Outgoing>>,
    /// HEARTBEAT and the control thread's texts.
    pub out: mpsc::Receiver<Outgoing>,
    /// Answers and refusals of the receive task (rate-limited).
    pub replies: mpsc::Receiver<Outgoing>,
    /// A command older than this when its turn comes is dropped (one tick).
    pub max_command_age: Duration,
    /// Liveness.
    pub health: Arc<LinkHealth>,
    /// The test-only stall hook.
    pub stall: Option<StallHook>,
    /// The daemon's epoch.
    pub epoch: Instant,
}

/// Sends what the other parts queue: header and sequence, signing (the
/// timestamp persisted every [`PERSIST_INTERVAL`]), counters and the
/// pose → command and tick → send latencies. Commands first, then the
/// daemon's own messages, then replies within the [`ReplyBudget`].
pub(super) async fn send_task(
    transport: Transport,
    inputs: SendInputs,
    stop: Arc<Stop>,
    (system_id, component_id): (u8, u8),
    signing: Option<(Signing, TimestampStore)>,
) -> TxReport {
    let SendInputs {
        commands,
        mut out,
        mut replies,
        max_command_age,
        health,
        stall,
        epoch,
    } = inputs;
    let mut report = TxReport::default();
    let mut sender = Sender {
        transport,
        ids: (system_id, component_id),
        sequence: 0,
        signing,
        persisted: Instant::now(),
        no_peer: 0,
    };
    let mut budget = ReplyBudget::new(REPLY_RATE_HZ, REPLY_BURST, 0.0);
    let mut beat = tokio::time::interval(BEAT_INTERVAL / 2);
    beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut stop_rx = stop.tx.subscribe();
    let mut replies_open = true;
    let secs = |t: Instant| t.saturating_duration_since(epoch).as_secs_f64();
    // Ends when the daemon's own queue closes (control thread and heartbeat
    // task gone), after a last look at the slot.
    loop {
        let reply_ready = replies_open && budget.available(secs(Instant::now()));
        let item = tokio::select! {
            biased;
            () = commands.notified() => match commands.take() {
                Some(item) => item,
                None => continue,
            },
            item = out.recv() => match item {
                Some(item) => item,
                None => match commands.take() {
                    Some(item) => item,
                    None => break,
                },
            },
            item = replies.recv(), if reply_ready => match item {
                Some(item) => {
                    budget.take(secs(Instant::now()));
                    report.replies_sent += 1;
                    item
                }
                None => {
                    replies_open = false;
                    continue;
                }
            },
            _ = beat.tick() => {
                if StallHook::due(stall, LinkTask::Send, epoch.elapsed()) {
                    stalled(LinkTask::Send, &mut stop_rx).await;
                    break;
                }
                health.beat(LinkTask::Send, Instant::now());
                continue;
            }
        };
        if let Some(tick) = item.tick
            && tick.elapsed() > max_command_age
        {
            report.commands_stale += 1;
            continue;
        }
        sender.send(&item, &mut report).await;
    }
    while replies.try_recv().is_ok() {
        report.replies_pending += 1;
    }
    if let Some((s, store)) = &sender.signing {
        persist(s, store);
    }
    report
}

/// Persists the signing timestamp (a failure is logged).
fn persist(s: &Signing, store: &TimestampStore) {
    if let Err(e) = store.store(s.timestamp()) {
        warn!(error = %e, "cannot persist the signing timestamp");
    }
}

/// The send task's writer: header and sequence, signing (the timestamp
/// persisted every [`PERSIST_INTERVAL`]), counters and latencies.
struct Sender {
    transport: Transport,
    /// The daemon's (system, component).
    ids: (u8, u8),
    sequence: u8,
    signing: Option<(Signing, TimestampStore)>,
    /// When the signing timestamp was last persisted.
    persisted: Instant,
    /// Messages dropped without a peer (or with the serial queue full).
    no_peer: u64,
}

impl Sender {
    /// Sends `item` (signed with signing on), counted into `report`.
    async fn send(&mut self, item: &Outgoing, report: &mut TxReport) {
        let (system_id, component_id) = self.ids;
        let transport = &self.transport;
        let header = MavHeader {
            system_id: u32::from(system_id),
            component_id,
            sequence: self.sequence,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let sent = match self.signing.as_mut() {
            Some((s, store)) => {
                let now = timestamp_from_system_time(SystemTime::now());
                let frame = s.sign(&header, &item.message, now);
                if self.persisted.elapsed() >= PERSIST_INTERVAL {
                    persist(s, store);
                    self.persisted = Instant::now();
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
            Ok(SendOutcome::NoPeer | SendOutcome::QueueFull) => {
                self.no_peer += 1;
                if self.no_peer == 1 {
                    warn!(
                        "no peer (udpin before the lock, or the link is reconnecting) or the serial queue is full: outbound messages dropped"
                    );
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
}

/// HEARTBEAT at 1 Hz with the daemon's status; POWEROFF when stopping.
pub(super) async fn heartbeat_task(
    out: mpsc::Sender<Outgoing>,
    state: Arc<AtomicU8>,
    stop: Arc<Stop>,
    health: Arc<LinkHealth>,
    stall: Option<StallHook>,
    epoch: Instant,
) {
    let mut stop_rx = stop.tx.subscribe();
    let mut interval = tokio::time::interval(Duration::from_secs(1));
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut beat = tokio::time::interval(BEAT_INTERVAL);
    beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let stall_now = tokio::select! {
            biased;
            _ = stop_rx.wait_for(|s| *s) => break,
            _ = beat.tick() => {
                if StallHook::due(stall, LinkTask::Heartbeat, epoch.elapsed()) {
                    true
                } else {
                    health.beat(LinkTask::Heartbeat, Instant::now());
                    continue;
                }
            }
            _ = interval.tick() => false,
        };
        if stall_now {
            stalled(LinkTask::Heartbeat, &mut stop_rx).await;
            break;
        }
        // A stalled link task: CRITICAL until restarted.
        let status = if health.fault() {
            DaemonStatus::Critical
        } else {
            daemon_status(state.load(Ordering::Relaxed))
        };
        if out
            .try_send(Outgoing::plain(heartbeat_onboard(status)))
            .is_err()
        {
            debug!("outbound queue full: heartbeat dropped");
        }
    }
    let _ = out.try_send(Outgoing::plain(heartbeat_onboard(DaemonStatus::Poweroff)));
}
