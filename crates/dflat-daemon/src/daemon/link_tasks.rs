//! The link tasks: receive (frames → events for the control thread, and the
//! answers a component owes: COMMAND_ACK, refusals), send (header,
//! sequence, signing, latency figures) and the 1 Hz HEARTBEAT.

use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
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
use crate::commands::{CommandRequest, RequestedMessage, answer};
use crate::signing::{PERSIST_INTERVAL, TimestampStore};
use crate::tick::{Event, REFUSAL_TEXT_INTERVAL, event_from};

/// What the receive task needs to know of the daemon.
#[derive(Debug, Clone)]
pub(super) struct RxContext {
    /// The daemon's epoch: event times are seconds since it.
    pub epoch: Instant,
    /// The pose message the controller uses.
    pub pose_source: PoseSource,
    /// The daemon's (system, component).
    pub own: (u8, u8),
    /// The autopilot's component id.
    pub autopilot_component: u8,
    /// The fixed yaw ψ⋆ the model flies \[rad\].
    pub yaw: f64,
    /// The published flight state (for the answers to REQUEST_MESSAGE).
    pub state: Arc<AtomicU8>,
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
        e if e.category() == ErrorCategory::NonFinite => {
            "dflat: setpoint refused: not finite".to_owned()
        }
        _ => "dflat: setpoint refused: malformed".to_owned(),
    }
}

fn send_text(out: &mpsc::Sender<Outgoing>, severity: MavSeverity, text: &str) {
    let _ = out.try_send(Outgoing::plain(statustext(severity, text)));
}

/// Receives frames until stopped: signing check, filter and decode, events
/// for the control thread, answers to commands, refusal texts.
pub(super) async fn receive_task(
    transport: Transport,
    mut link: LinkRx,
    ctx: RxContext,
    events: std::sync::mpsc::SyncSender<Event>,
    out: mpsc::Sender<Outgoing>,
    stop: Arc<Stop>,
    fault: Arc<std::sync::Mutex<Option<TransportError>>>,
) -> RxReport {
    let mut stop_rx = stop.tx.subscribe();
    let mut report = RxReport::default();
    let mut last_refusal: Option<Instant> = None;
    let mut told_addressing = false;
    let mut told_yaw = false;
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
        let arrival = frame
            .arrival
            .saturating_duration_since(ctx.epoch)
            .as_secs_f64();
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
                    send_text(&out, MavSeverity::MAV_SEVERITY_WARNING, text);
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
            tap.record_received(&frame);
        }
        let sender = (frame.header.system_id as u8, frame.header.component_id);
        let event = match &outcome {
            RxOutcome::Accepted(inbound) => {
                if let Inbound::PositionSetpoint(s) = inbound
                    && let Some(yaw) = s.yaw
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
                    answer_command(&req, &ctx, &out);
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
                let due =
                    last_refusal.is_none_or(|t| t.elapsed().as_secs_f64() >= REFUSAL_TEXT_INTERVAL);
                if due {
                    last_refusal = Some(Instant::now());
                    info!(error = %e, "setpoint refused");
                    send_text(
                        &out,
                        MavSeverity::MAV_SEVERITY_WARNING,
                        &setpoint_refusal_text(e),
                    );
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

/// COMMAND_ACK (and what REQUEST_MESSAGE asked for) for a command the
/// daemon answers ([`crate::commands`]).
fn answer_command(req: &CommandRequest, ctx: &RxContext, out: &mpsc::Sender<Outgoing>) {
    let Some(reply) = answer(req, ctx.own) else {
        return;
    };
    debug!(command = ?req.command, "command answered");
    let _ = out.try_send(Outgoing::plain(reply.ack));
    if let Some(reason) = &reply.reason {
        send_text(out, MavSeverity::MAV_SEVERITY_INFO, reason);
    }
    let state = ctx.state.load(Ordering::Relaxed);
    match reply.then {
        Some(RequestedMessage::Heartbeat) => {
            let _ = out.try_send(Outgoing::plain(heartbeat_onboard(daemon_status(state))));
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
}

/// Sends what the other parts queue: header and sequence, signing (the
/// timestamp persisted every [`PERSIST_INTERVAL`]), counters and the
/// pose → command and tick → send latencies.
pub(super) async fn send_task(
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

/// HEARTBEAT at 1 Hz with the daemon's status; POWEROFF when stopping.
pub(super) async fn heartbeat_task(
    out: mpsc::Sender<Outgoing>,
    state: Arc<AtomicU8>,
    stop: Arc<Stop>,
) {
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
