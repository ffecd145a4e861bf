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

use dflat_link::dialect::MavSeverity;
use dflat_link::transport::{RecvEvent, SendOutcome, Transport, TransportError};
use dflat_link::{
    DaemonStatus, ErrorCategory, Inbound, LinkError, LinkRx, MavHeader, MavMessage, PoseSource,
    RxOutcome, SetpointRejection, SignatureCheck, Signing, Verdict, heartbeat_onboard, statustext,
    timestamp_from_system_time,
};
use tokio::sync::mpsc;
use tracing::{debug, error, info, warn};

use super::{Outgoing, RxReport, Stop, TxReport, daemon_status, decode_state};
use crate::commands::{CommandContext, CommandRequest, RequestedMessage, answer, command_ack};
use crate::link_health::{
    BEAT_INTERVAL, CommandSlot, LinkHealth, LinkTask, REPLY_BURST, REPLY_RATE_HZ, ReplyBudget,
    StallHook,
};
use crate::mission::{ItemRules, Mission, MissionChange, MissionProtocol};
use crate::signing::{PERSIST_INTERVAL, TimestampStore};
use crate::tick::{Event, arrival_secs, event_from};
use dflat_link::dialect::MavResult;
use dflat_link::refusal::{RefusalLimiter, Say};

/// What the receive task needs to know of the daemon.
#[derive(Debug, Clone)]
pub(super) struct RxContext {
    /// The daemon's epoch: event times are seconds since it.
    pub epoch: Instant,
    /// The epoch on the system clock \[µs since 1970\]: a received frame
    /// is logged in the tlog at this plus its arrival in whole µs.
    pub epoch_unix_us: u64,
    /// The pose message the controller uses.
    pub pose_source: PoseSource,
    /// The daemon's (system, component).
    pub own: (u8, u8),
    /// The autopilot's component id.
    pub autopilot_component: u8,
    /// The fixed yaw ψ⋆ the model flies \[rad\].
    pub yaw: f64,
    /// `vehicle.yaw_mode = "fixed"`: a setpoint's yaw is not flown.
    pub yaw_fixed: bool,
    /// The published flight state (for the answers to REQUEST_MESSAGE).
    pub state: Arc<AtomicU8>,
    /// How uploaded mission items are read.
    pub mission_rules: ItemRules,
    /// Missions accepted by the protocol, to the control thread.
    pub missions: std::sync::mpsc::Sender<Option<Mission>>,
    /// Link-task liveness (a stall makes the HEARTBEAT answer CRITICAL).
    pub health: Arc<LinkHealth>,
    /// The test-only stall hook.
    pub stall: Option<StallHook>,
}

/// Sends a mission-protocol reply; hands a changed mission to the control
/// thread.
fn send_reply(reply: crate::mission::Reply, ctx: &RxContext, out: &Replies) {
    for m in reply.messages {
        out.send(m);
    }
    for text in &reply.texts {
        info!(text, "mission protocol");
        send_text(out, MavSeverity::MAV_SEVERITY_WARNING, text);
    }
    match reply.change {
        Some(MissionChange::Uploaded(m)) => {
            info!(items = m.len(), "mission uploaded");
            let _ = ctx.missions.send(Some(m));
        }
        Some(MissionChange::Cleared) => {
            info!("mission cleared");
            let _ = ctx.missions.send(None);
        }
        None => {}
    }
}

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

/// The STATUSTEXT that says why a trusted SET_POSITION_TARGET_LOCAL_NED was
/// refused; each cause has its own words (a ground station hides repeats).
pub fn setpoint_refusal_text(e: &LinkError) -> String {
    const VELOCITY_BITS: u16 = 8 | 16 | 32;
    match e {
        LinkError::SetpointRejected(SetpointRejection::Frame(frame)) => {
            format!(
                "dflat: setpoint refused: frame {} not LOCAL_NED",
                *frame as u32
            )
        }
        LinkError::SetpointRejected(SetpointRejection::PositionIgnored { type_mask })
            if type_mask & VELOCITY_BITS != VELOCITY_BITS =>
        {
            "dflat: setpoint refused: velocity-only unsupported".to_owned()
        }
        LinkError::SetpointRejected(SetpointRejection::PositionIgnored { type_mask }) => {
            format!("dflat: setpoint refused: x/y/z ignored {type_mask:#06x}")
        }
        // Each field its own words (and its own rate limit): a NaN x said
        // does not hide an infinite z or a NaN yaw after it.
        LinkError::NonFinite { field, .. } => {
            format!("dflat: setpoint refused: {field} not finite")
        }
        e if e.category() == ErrorCategory::NonFinite => {
            "dflat: setpoint refused: not finite".to_owned()
        }
        _ => "dflat: setpoint refused: malformed".to_owned(),
    }
}

/// The STATUSTEXT for a SET_POSITION_TARGET_LOCAL_NED (84) whose payload
/// did not decode (e.g. coordinate_frame 99); `None` for other frames.
pub fn undecodable_setpoint_text(e: &dflat_link::FrameError) -> Option<String> {
    match e {
        dflat_link::FrameError::Payload {
            msg_id: 84,
            fault: dflat_link::PayloadFault::InvalidEnum { enum_type, value },
        } => Some(format!(
            "dflat: setpoint refused: {} {value} unknown",
            enum_type.trim_start_matches("Mav")
        )),
        dflat_link::FrameError::Payload { msg_id: 84, .. } => {
            Some("dflat: setpoint refused: malformed".to_owned())
        }
        _ => None,
    }
}

fn send_text(out: &Replies, severity: MavSeverity, text: &str) {
    out.send(statustext(severity, text));
}

/// Waits until stopped (a stalled task's last state: no work, no beats).
async fn stalled(task: LinkTask, stop_rx: &mut tokio::sync::watch::Receiver<bool>) {
    warn!(task = task.name(), "test hook: link task stalled");
    let _ = stop_rx.wait_for(|s| *s).await;
}

/// Receives frames until stopped: signing check, filter and decode, events
/// for the control thread, answers to commands, refusal texts.
pub(super) async fn receive_task(
    transport: Transport,
    mut link: LinkRx,
    ctx: RxContext,
    events: std::sync::mpsc::SyncSender<Event>,
    out: Replies,
    stop: Arc<Stop>,
    fault: Arc<std::sync::Mutex<Option<TransportError>>>,
) -> RxReport {
    let mut stop_rx = stop.tx.subscribe();
    let mut report = RxReport::default();
    // Refusals said once per sender and reason per 10 s, with a count.
    let mut refusals: RefusalLimiter<(u8, u8)> = RefusalLimiter::default();
    let mut told_addressing = false;
    let mut told_yaw = false;
    let mut missions = MissionProtocol::new(ctx.own, ctx.mission_rules);
    let mut mission_timer = tokio::time::interval(Duration::from_millis(100));
    mission_timer.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut told_unlocked = false;
    let mut beat = tokio::time::interval(BEAT_INTERVAL);
    beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let received = tokio::select! {
            biased;
            _ = stop_rx.wait_for(|s| *s) => break,
            _ = mission_timer.tick() => {
                let now = ctx.epoch.elapsed().as_secs_f64();
                send_reply(missions.poll(now), &ctx, &out);
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
                debug!(error = %e, "frame error");
                link.frame_error(&e);
                // A SET_POSITION_TARGET_LOCAL_NED whose payload does not
                // decode (a coordinate_frame the dialect does not define):
                // say why, rate-limited (its sender is not known: the
                // frame never decoded, so one key for all of them).
                if let Some(text) = undecodable_setpoint_text(&e) {
                    let say = refusals.refuse((0, 0), &text, ctx.epoch.elapsed().as_secs_f64());
                    say_refusal(&out, say, &text, || info!(error = %e, "setpoint refused"));
                }
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
        // Whole µs since the epoch: the tlog records the same instant, so a
        // replay finds the arrival bit for bit (`tick::arrival_secs`).
        let arrival_us = u64::try_from(
            frame
                .arrival
                .saturating_duration_since(ctx.epoch)
                .as_micros(),
        )
        .unwrap_or(u64::MAX);
        let arrival = arrival_secs(arrival_us);
        let is_setpoint = matches!(frame.message, MavMessage::SET_POSITION_TARGET_LOCAL_NED(_));
        // udpin without a peer yet: only the autopilot's HEARTBEAT (signed,
        // with signing on) is looked at; it locks the peer.
        let unlocked = transport.awaiting_peer();
        if unlocked {
            let from_autopilot = matches!(frame.message, MavMessage::HEARTBEAT(_))
                && frame.header.system_id == u32::from(ctx.own.0)
                && frame.header.component_id == ctx.autopilot_component;
            let authentic = from_autopilot
                && link.signing.as_mut().is_none_or(|s| {
                    let now = timestamp_from_system_time(SystemTime::now());
                    matches!(
                        s.verify(&frame.header, frame.signed.as_ref(), now),
                        SignatureCheck::Valid { .. }
                    )
                });
            match frame.from {
                Some(from) if authentic => {
                    if let Err(e) = transport.lock_peer(from).await {
                        warn!(error = %e, "cannot lock the udpin peer");
                        continue;
                    }
                    report.peer = Some(from);
                }
                _ => {
                    report.foreign_frames += 1;
                    if !told_unlocked {
                        told_unlocked = true;
                        info!(
                            from = ?frame.from,
                            "udpin: frame dropped before the autopilot's HEARTBEAT locked the peer (said once)"
                        );
                    }
                    continue;
                }
            }
        }
        if link.signing.is_some() && !unlocked {
            let now = timestamp_from_system_time(SystemTime::now());
            if let Err(check) =
                link.authenticate(&frame.header, &frame.message, frame.signed.as_ref(), now)
            {
                if is_setpoint {
                    let text = match check {
                        SignatureCheck::Unsigned => "dflat: setpoint refused: unsigned",
                        SignatureCheck::Replayed => "dflat: setpoint refused: replayed",
                        _ => "dflat: setpoint refused: bad signature",
                    };
                    let sender = (frame.header.system_id as u8, frame.header.component_id);
                    let say = refusals.refuse(sender, text, ctx.epoch.elapsed().as_secs_f64());
                    say_refusal(&out, say, text, || {
                        info!(?check, "setpoint refused by signing")
                    });
                }
                continue;
            }
        }
        let outcome = link.handle(&frame.header, &frame.message);
        // The tlog holds only what passed the filter and authentication
        // (the tap's `inbound` is off; the rest is counted in `link`).
        if let Some(tap) = transport.tap()
            && matches!(outcome, RxOutcome::Accepted(_) | RxOutcome::Rejected(_))
        {
            tap.record_received_at(&frame, ctx.epoch_unix_us.saturating_add(arrival_us));
        }
        let sender = (frame.header.system_id as u8, frame.header.component_id);
        let event = match &outcome {
            RxOutcome::Accepted(inbound) => {
                if let Inbound::PositionSetpoint(s) = inbound
                    && let Some(yaw) = s.yaw
                    && ctx.yaw_fixed
                    && !told_yaw
                    && (dflat_link::math::wrap_pi(yaw - ctx.yaw)).abs() > 1f64.to_radians()
                {
                    // The model flies a fixed yaw ψ⋆: the position is
                    // flown, the yaw is not (said once).
                    told_yaw = true;
                    info!(yaw, "setpoint yaw ignored (fixed yaw)");
                    let text = format!(
                        "dflat: setpoint yaw ignored, yaw fixed {:.0} deg",
                        ctx.yaw.to_degrees()
                    );
                    send_text(&out, MavSeverity::MAV_SEVERITY_NOTICE, &text);
                }
                if let Some(req) = CommandRequest::from_message(&frame.message, sender.0, sender.1)
                {
                    let has_mission = missions.mission().has_navigation();
                    if let Some(action) =
                        answer_command(&req, &ctx, has_mission, &out, &mut refusals)
                        && events.try_send(Event::Mission { arrival, action }).is_err()
                    {
                        report.events_dropped += 1;
                    }
                }
                if matches!(inbound, Inbound::Other(_)) {
                    send_reply(missions.handle(&frame.message, sender, arrival), &ctx, &out);
                }
                event_from(inbound, ctx.pose_source, arrival)
            }
            RxOutcome::Ignored(Verdict::IgnoreNotAddressed) if is_setpoint => {
                if let MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) = &frame.message
                    && d.target_system == ctx.own.0
                    && d.target_component == ctx.autopilot_component
                    && !told_addressing
                {
                    // Where PX4 and ArduPilot users send them: say where
                    // they go instead (once).
                    told_addressing = true;
                    info!("setpoint addressed to the autopilot ignored");
                    let text = format!(
                        "dflat: setpoints go to {}/{}, not the autopilot",
                        ctx.own.0, ctx.own.1
                    );
                    send_text(&out, MavSeverity::MAV_SEVERITY_WARNING, &text);
                }
                None
            }
            RxOutcome::Rejected(e) if is_setpoint => {
                let text = setpoint_refusal_text(e);
                let say = refusals.refuse(sender, &text, ctx.epoch.elapsed().as_secs_f64());
                say_refusal(&out, say, &text, || info!(error = %e, "setpoint refused"));
                None
            }
            RxOutcome::Ignored(Verdict::IgnoreWrongSource) => {
                if let Some(id) = link
                    .filter
                    .unknown_ground_station(&frame.header, &frame.message)
                {
                    refuse_unknown_gcs(id, &frame.message, sender, &ctx, &mut refusals, &out);
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

/// Sends `text` as a WARNING STATUSTEXT as the limiter says: the first
/// time (and `log`, the caller's INFO/WARN line), again with the count of
/// repeats held back once the interval passed; repeats in between only at
/// DEBUG.
fn say_refusal(out: &Replies, say: Say, text: &str, log: impl FnOnce()) {
    match say {
        Say::First => log(),
        Say::Again { held_back } => debug!(text, held_back, "refusal repeated"),
        Say::Quiet => {
            debug!(text, "refusal repeated (not said)");
            return;
        }
    }
    send_text(out, MavSeverity::MAV_SEVERITY_WARNING, &say.text(text));
}

/// The refusal of a request (setpoint, command, mission) from system `id`,
/// a ground station `link.gcs_system_ids` does not name: never acted on; a
/// command gets COMMAND_ACK DENIED every time; the STATUSTEXT naming the id
/// and the key to set, and a WARN line, once per sender per 10 s.
fn refuse_unknown_gcs(
    id: u8,
    msg: &MavMessage,
    sender: (u8, u8),
    ctx: &RxContext,
    refusals: &mut RefusalLimiter<(u8, u8)>,
    out: &Replies,
) {
    if let Some(req) = CommandRequest::from_message(msg, sender.0, sender.1) {
        out.send(command_ack(&req, MavResult::MAV_RESULT_DENIED));
    }
    use dflat_link::mavlink::Message as _;
    let text = format!("dflat: id {id} not in link.gcs_system_ids");
    let say = refusals.refuse(sender, &text, ctx.epoch.elapsed().as_secs_f64());
    say_refusal(out, say, &text, || {
        warn!(
            system = id,
            component = sender.1,
            message = msg.message_name(),
            "request from a ground station not in link.gcs_system_ids refused; add its id there to accept it"
        );
    });
}

/// COMMAND_ACK (and what REQUEST_MESSAGE asked for) for a command the
/// daemon answers ([`crate::commands`]); the mission command accepted, for
/// the control thread.
fn answer_command(
    req: &CommandRequest,
    ctx: &RxContext,
    has_mission: bool,
    out: &Replies,
    refusals: &mut RefusalLimiter<(u8, u8)>,
) -> Option<crate::tick::MissionAction> {
    let state = ctx.state.load(Ordering::Relaxed);
    let context = CommandContext::new(has_mission, decode_state(state));
    let reply = answer(req, ctx.own, &context)?;
    debug!(command = ?req.command, "command answered");
    out.send(reply.ack);
    if let Some(reason) = &reply.reason {
        // Said once per sender and reason per 10 s (SDKs retry requests).
        let sender = (req.sender_system, req.sender_component);
        match refusals.refuse(sender, reason, ctx.epoch.elapsed().as_secs_f64()) {
            Say::Quiet => debug!(reason, "command refusal repeated (not said)"),
            say => send_text(out, MavSeverity::MAV_SEVERITY_INFO, &say.text(reason)),
        }
    }
    match reply.then {
        Some(RequestedMessage::Heartbeat) => {
            let status = if ctx.health.fault() {
                DaemonStatus::Critical
            } else {
                daemon_status(state)
            };
            out.send(heartbeat_onboard(status));
        }
        Some(RequestedMessage::Status) => {
            let name = decode_state(state).map_or("starting", |s| s.name());
            send_text(
                out,
                MavSeverity::MAV_SEVERITY_INFO,
                &format!("dflat: state {name}"),
            );
        }
        None => {}
    }
    reply.action
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
    mut signing: Option<(Signing, TimestampStore)>,
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
    let mut persisted = Instant::now();
    let persist = |s: &Signing, store: &TimestampStore| {
        if let Err(e) = store.store(s.timestamp()) {
            warn!(error = %e, "cannot persist the signing timestamp");
        }
    };
    let mut sequence: u8 = 0;
    let mut no_peer = 0u64;
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
            Ok(SendOutcome::NoPeer | SendOutcome::QueueFull) => {
                no_peer += 1;
                if no_peer == 1 {
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
    while replies.try_recv().is_ok() {
        report.replies_pending += 1;
    }
    if let Some((s, store)) = &signing {
        persist(s, store);
    }
    report
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Each refused field has its own words (and so its own rate limit): a
    /// NaN x said does not hide an infinite z or a NaN yaw after it; a
    /// coordinate frame the dialect does not define is said too.
    #[test]
    fn refusals_name_the_field_and_the_unknown_frame() {
        let text = |field| {
            setpoint_refusal_text(&LinkError::NonFinite {
                message: "SET_POSITION_TARGET_LOCAL_NED",
                field,
            })
        };
        let (x, z, yaw) = (text("x"), text("z"), text("yaw"));
        assert_eq!(z, "dflat: setpoint refused: z not finite");
        assert!(x != z && z != yaw && x != yaw);
        let frame = dflat_link::FrameError::Payload {
            msg_id: 84,
            fault: dflat_link::PayloadFault::InvalidEnum {
                enum_type: "MavFrame",
                value: 99,
            },
        };
        let said = undecodable_setpoint_text(&frame).unwrap();
        assert_eq!(said, "dflat: setpoint refused: Frame 99 unknown");
        assert!(said.len() <= 50);
        let other = dflat_link::FrameError::Payload {
            msg_id: 33,
            fault: dflat_link::PayloadFault::Other,
        };
        assert_eq!(undecodable_setpoint_text(&other), None);
    }
}
