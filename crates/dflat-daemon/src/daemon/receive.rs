//! The receive path as a pure step: a received frame and the time in; the
//! events for the control thread, the replies (answers, refusals,
//! notices, the mission protocol's) and the missions accepted out. The
//! receive task (`daemon/link_tasks.rs`) is the I/O around it: it reads
//! the transport and the clocks, locks the udpin peer, writes the tlog and
//! hands the outputs on.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::AtomicU8;
use std::time::Instant;

use dflat_link::dialect::{MavResult, MavSeverity};
use dflat_link::refusal::{RefusalLimiter, Say};
use dflat_link::transport::Received;
use dflat_link::{
    DaemonStatus, ErrorCategory, FrameError, Inbound, LinkError, LinkRx, MavMessage, PoseSource,
    RxOutcome, SetpointRejection, SignatureCheck, Verdict, heartbeat_onboard, statustext,
};
use tracing::{debug, info, warn};

use super::{daemon_status, decode_state};
use crate::commands::{CommandContext, CommandRequest, RequestedMessage, answer, command_ack};
use crate::link_health::{LinkHealth, StallHook};
use crate::mission::{ItemRules, Mission, MissionChange, MissionProtocol, Reply};
use crate::tick::{Event, MissionAction, arrival_secs, event_from};

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

/// What a step produced, in order.
#[derive(Debug, Default)]
pub(super) struct RxOutput {
    /// Messages for the replies queue.
    pub replies: Vec<MavMessage>,
    /// Events for the control thread.
    pub events: Vec<Event>,
    /// Missions accepted (`None`: cleared), for the control thread.
    pub missions: Vec<Option<Mission>>,
    /// The frame passed the filter and authentication: the tlog records it.
    pub record: bool,
}

/// What becomes of a frame while a udpin link has no peer yet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Gate {
    /// Look at it (the peer is locked, or the link has no peer to lock).
    Pass,
    /// The autopilot's (authentic) HEARTBEAT: lock the peer to this
    /// address, then look at it.
    Lock(SocketAddr),
    /// Dropped, counted: not the autopilot's HEARTBEAT.
    Foreign,
}

/// The facts of the moment a step needs, read by the task.
#[derive(Debug, Clone, Copy)]
pub(super) struct FrameTime {
    /// The frame's arrival \[whole µs since the daemon's epoch\].
    pub arrival_us: u64,
    /// Now \[s since the daemon's epoch\] (the refusals' clock).
    pub now: f64,
    /// Now as a MAVLink 2 signing timestamp.
    pub signing_now: u64,
    /// The published flight state (for the answers to REQUEST_MESSAGE).
    pub state: u8,
    /// A link task has stalled (HEARTBEAT answers CRITICAL).
    pub fault: bool,
}

/// Notices said once per run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Notice {
    /// A setpoint addressed to the autopilot.
    Addressing = 1,
    /// A setpoint's yaw with a fixed yaw.
    Yaw = 2,
    /// A frame before the udpin lock.
    Unlocked = 4,
}

/// The receive path's state (see the module docs).
#[derive(Debug)]
pub(super) struct ReceiveCore {
    link: LinkRx,
    /// The daemon's (system, component).
    own: (u8, u8),
    autopilot_component: u8,
    pose_source: PoseSource,
    /// The fixed yaw ψ⋆ \[rad\], and whether a setpoint's yaw is not flown.
    yaw: f64,
    yaw_fixed: bool,
    /// Refusals said once per sender and reason per 10 s, with a count.
    refusals: RefusalLimiter<(u8, u8)>,
    missions: MissionProtocol,
    /// The [`Notice`]s said (bits).
    said: u8,
}

impl ReceiveCore {
    /// The step around `link` for the daemon `ctx` describes.
    pub(super) fn new(link: LinkRx, ctx: &RxContext) -> Self {
        let ids = (ctx.own, ctx.autopilot_component);
        let yaw = (ctx.yaw, ctx.yaw_fixed);
        Self::from_parts(link, ids, ctx.pose_source, ctx.mission_rules, yaw)
    }

    /// The step around `link` for the daemon `own` = (system, component)
    /// flying with the autopilot `ids.1`: poses from `pose_source`, mission
    /// items read by `rules`, `yaw` = (ψ⋆ \[rad\], fixed).
    pub(super) fn from_parts(
        link: LinkRx,
        (own, autopilot_component): ((u8, u8), u8),
        pose_source: PoseSource,
        rules: ItemRules,
        (yaw, yaw_fixed): (f64, bool),
    ) -> Self {
        Self {
            link,
            own,
            autopilot_component,
            pose_source,
            yaw,
            yaw_fixed,
            refusals: RefusalLimiter::default(),
            missions: MissionProtocol::new(own, rules),
            said: 0,
        }
    }

    /// The link's counters so far.
    pub(super) fn stats(&self) -> dflat_link::LinkStats {
        self.link.stats
    }

    /// True the first time `notice` is asked for.
    fn first(&mut self, notice: Notice) -> bool {
        let bit = notice as u8;
        let first = self.said & bit == 0;
        self.said |= bit;
        first
    }

    /// The mission protocol's timers at `now` \[s\].
    pub(super) fn poll(&mut self, now: f64) -> RxOutput {
        let mut out = RxOutput::default();
        let reply = self.missions.poll(now);
        mission_reply(reply, &mut out);
        out
    }

    /// A framing error at `now` \[s\]: counted; a setpoint whose payload does
    /// not decode is refused in words (rate-limited; its sender is not
    /// known, so one key for all of them).
    pub(super) fn on_frame_error(&mut self, e: &FrameError, now: f64) -> RxOutput {
        let mut out = RxOutput::default();
        debug!(error = %e, "frame error");
        self.link.frame_error(e);
        if let Some(text) = undecodable_setpoint_text(e) {
            let say = self.refusals.refuse((0, 0), &text, now);
            say_refusal(
                &mut out,
                say,
                &text,
                || info!(error = %e, "setpoint refused"),
            );
        }
        out
    }

    /// Before the udpin lock (`unlocked`): only the autopilot's HEARTBEAT
    /// (signed, with signing on, checked at `signing_now`) is looked at,
    /// and it locks the peer.
    pub(super) fn gate(&mut self, frame: &Received, unlocked: bool, signing_now: u64) -> Gate {
        if !unlocked {
            return Gate::Pass;
        }
        let from_autopilot = matches!(frame.message, MavMessage::HEARTBEAT(_))
            && frame.header.system_id == u32::from(self.own.0)
            && frame.header.component_id == self.autopilot_component;
        let authentic = from_autopilot
            && self.link.signing.as_mut().is_none_or(|s| {
                matches!(
                    s.verify(&frame.header, frame.signed.as_ref(), signing_now),
                    SignatureCheck::Valid { .. }
                )
            });
        match frame.from {
            Some(from) if authentic => Gate::Lock(from),
            _ => {
                if self.first(Notice::Unlocked) {
                    info!(
                        from = ?frame.from,
                        "udpin: frame dropped before the autopilot's HEARTBEAT locked the peer (said once)"
                    );
                }
                Gate::Foreign
            }
        }
    }

    /// A frame (already through [`Self::gate`]; `locked_now`: it locked the
    /// peer, its signature already checked there) at `time`.
    pub(super) fn on_frame(
        &mut self,
        frame: &Received,
        locked_now: bool,
        time: FrameTime,
    ) -> RxOutput {
        let mut out = RxOutput::default();
        let is_setpoint = matches!(frame.message, MavMessage::SET_POSITION_TARGET_LOCAL_NED(_));
        let sender = (frame.header.system_id as u8, frame.header.component_id);
        if self.link.signing.is_some() && !locked_now {
            let signed = frame.signed.as_ref();
            if let Err(check) =
                self.link
                    .authenticate(&frame.header, &frame.message, signed, time.signing_now)
            {
                if is_setpoint {
                    let text = match check {
                        SignatureCheck::Unsigned => "dflat: setpoint refused: unsigned",
                        SignatureCheck::Replayed => "dflat: setpoint refused: replayed",
                        _ => "dflat: setpoint refused: bad signature",
                    };
                    let say = self.refusals.refuse(sender, text, time.now);
                    say_refusal(&mut out, say, text, || {
                        info!(?check, "setpoint refused by signing")
                    });
                }
                return out;
            }
        }
        let outcome = self.link.handle(&frame.header, &frame.message);
        // The tlog holds only what passed the filter and authentication.
        out.record = matches!(outcome, RxOutcome::Accepted(_) | RxOutcome::Rejected(_));
        let event = match &outcome {
            RxOutcome::Accepted(inbound) => self.accepted(inbound, frame, time, &mut out),
            RxOutcome::Ignored(Verdict::IgnoreNotAddressed) if is_setpoint => {
                self.not_addressed(&frame.message, &mut out);
                None
            }
            RxOutcome::Rejected(e) if is_setpoint => {
                let text = setpoint_refusal_text(e);
                let say = self.refusals.refuse(sender, &text, time.now);
                say_refusal(
                    &mut out,
                    say,
                    &text,
                    || info!(error = %e, "setpoint refused"),
                );
                None
            }
            RxOutcome::Ignored(Verdict::IgnoreWrongSource) => {
                if let Some(id) = self
                    .link
                    .filter
                    .unknown_ground_station(&frame.header, &frame.message)
                {
                    self.refuse_unknown_gcs(id, &frame.message, sender, time.now, &mut out);
                }
                None
            }
            _ => None,
        };
        out.events.extend(event);
        out
    }

    /// An accepted message: the yaw notice, a command's answer, the mission
    /// protocol; its event for the control thread.
    fn accepted(
        &mut self,
        inbound: &Inbound,
        frame: &Received,
        time: FrameTime,
        out: &mut RxOutput,
    ) -> Option<Event> {
        let arrival = arrival_secs(time.arrival_us);
        let sender = (frame.header.system_id as u8, frame.header.component_id);
        if let Inbound::PositionSetpoint(s) = inbound
            && let Some(yaw) = s.yaw
            && self.yaw_fixed
            && (dflat_link::math::wrap_pi(yaw - self.yaw)).abs() > 1f64.to_radians()
            && self.first(Notice::Yaw)
        {
            // The model flies a fixed yaw ψ⋆: the position is flown, the
            // yaw is not (said once).
            info!(yaw, "setpoint yaw ignored (fixed yaw)");
            let text = format!(
                "dflat: setpoint yaw ignored, yaw fixed {:.0} deg",
                self.yaw.to_degrees()
            );
            out.replies
                .push(statustext(MavSeverity::MAV_SEVERITY_NOTICE, &text));
        }
        if let Some(req) = CommandRequest::from_message(&frame.message, sender.0, sender.1)
            && let Some(action) = self.answer_command(&req, time, out)
        {
            out.events.push(Event::Mission { arrival, action });
        }
        if matches!(inbound, Inbound::Other(_)) {
            let reply = self.missions.handle(&frame.message, sender, arrival);
            mission_reply(reply, out);
        }
        event_from(inbound, self.pose_source, arrival)
    }

    /// A setpoint not addressed to the daemon: where PX4 and ArduPilot
    /// users send them (to the autopilot), say where they go instead (once).
    fn not_addressed(&mut self, message: &MavMessage, out: &mut RxOutput) {
        if let MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) = message
            && d.target_system == self.own.0
            && d.target_component == self.autopilot_component
            && self.first(Notice::Addressing)
        {
            info!("setpoint addressed to the autopilot ignored");
            let text = format!(
                "dflat: setpoints go to {}/{}, not the autopilot",
                self.own.0, self.own.1
            );
            out.replies
                .push(statustext(MavSeverity::MAV_SEVERITY_WARNING, &text));
        }
    }

    /// The refusal of a request (setpoint, command, mission) from system
    /// `id`, a ground station `link.gcs_system_ids` does not name: never
    /// acted on; a command gets COMMAND_ACK DENIED every time; the
    /// STATUSTEXT naming the id and the key to set, and a WARN line, once
    /// per sender per 10 s.
    fn refuse_unknown_gcs(
        &mut self,
        id: u8,
        msg: &MavMessage,
        sender: (u8, u8),
        now: f64,
        out: &mut RxOutput,
    ) {
        if let Some(req) = CommandRequest::from_message(msg, sender.0, sender.1) {
            out.replies
                .push(command_ack(&req, MavResult::MAV_RESULT_DENIED));
        }
        use dflat_link::mavlink::Message as _;
        let text = format!("dflat: id {id} not in link.gcs_system_ids");
        let say = self.refusals.refuse(sender, &text, now);
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
    /// daemon answers ([`crate::commands`]); the mission command accepted,
    /// for the control thread.
    fn answer_command(
        &mut self,
        req: &CommandRequest,
        time: FrameTime,
        out: &mut RxOutput,
    ) -> Option<MissionAction> {
        let has_mission = self.missions.mission().has_navigation();
        let context = CommandContext::new(has_mission, decode_state(time.state));
        let reply = answer(req, self.own, &context)?;
        debug!(command = ?req.command, "command answered");
        out.replies.push(reply.ack);
        if let Some(reason) = &reply.reason {
            // Said once per sender and reason per 10 s (SDKs retry requests).
            let sender = (req.sender_system, req.sender_component);
            match self.refusals.refuse(sender, reason, time.now) {
                Say::Quiet => debug!(reason, "command refusal repeated (not said)"),
                say => out.replies.push(statustext(
                    MavSeverity::MAV_SEVERITY_INFO,
                    &say.text(reason),
                )),
            }
        }
        match reply.then {
            Some(RequestedMessage::Heartbeat) => {
                let status = if time.fault {
                    DaemonStatus::Critical
                } else {
                    daemon_status(time.state)
                };
                out.replies.push(heartbeat_onboard(status));
            }
            Some(RequestedMessage::Status) => {
                let name = decode_state(time.state).map_or("starting", |s| s.name());
                out.replies.push(statustext(
                    MavSeverity::MAV_SEVERITY_INFO,
                    &format!("dflat: state {name}"),
                ));
            }
            None => {}
        }
        reply.action
    }
}

/// A mission-protocol reply into `out`: its messages, its texts (as
/// WARNING), and a changed mission for the control thread.
fn mission_reply(reply: Reply, out: &mut RxOutput) {
    out.replies.extend(reply.messages);
    for text in &reply.texts {
        info!(text, "mission protocol");
        out.replies
            .push(statustext(MavSeverity::MAV_SEVERITY_WARNING, text));
    }
    match reply.change {
        Some(MissionChange::Uploaded(m)) => {
            info!(items = m.len(), "mission uploaded");
            out.missions.push(Some(m));
        }
        Some(MissionChange::Cleared) => {
            info!("mission cleared");
            out.missions.push(None);
        }
        None => {}
    }
}

/// `text` as a WARNING STATUSTEXT as the limiter says: the first time (and
/// `log`, the caller's INFO/WARN line), again with the count of repeats
/// held back once the interval passed; repeats in between only at DEBUG.
fn say_refusal(out: &mut RxOutput, say: Say, text: &str, log: impl FnOnce()) {
    match say {
        Say::First => log(),
        Say::Again { held_back } => debug!(text, held_back, "refusal repeated"),
        Say::Quiet => {
            debug!(text, "refusal repeated (not said)");
            return;
        }
    }
    out.replies.push(statustext(
        MavSeverity::MAV_SEVERITY_WARNING,
        &say.text(text),
    ));
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use dflat_link::dialect::{
        COMMAND_LONG_DATA, MavCmd, MavFrame, PositionTargetTypemask,
        SET_POSITION_TARGET_LOCAL_NED_DATA,
    };
    use dflat_link::{DaemonStatus, MavHeader};

    use super::*;
    use crate::config::Config;
    use crate::tick::source_filter;

    /// The step of the default configuration (daemon 1/191, autopilot
    /// 1/1, ground station 255), yaw fixed at 0.
    fn core() -> ReceiveCore {
        let cfg = Config::default();
        let link = LinkRx::new(source_filter(&cfg.link));
        let rules = ItemRules::of(&cfg.mission);
        ReceiveCore::from_parts(
            link,
            ((1, 191), 1),
            PoseSource::Odometry,
            rules,
            (0.0, true),
        )
    }

    fn frame(from: (u8, u8), message: MavMessage) -> Received {
        Received {
            header: MavHeader {
                system_id: from.0.into(),
                component_id: from.1,
                sequence: 0,
            },
            message,
            arrival: Instant::now(),
            signed: None,
            from: Some("127.0.0.1:14550".parse().unwrap()),
        }
    }

    fn setpoint(target: (u8, u8), yaw: f32) -> MavMessage {
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
            target_system: target.0,
            target_component: target.1,
            coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
            // Position and yaw: velocity (8, 16, 32), acceleration (64,
            // 128, 256) and yaw rate (2048) ignored.
            type_mask: PositionTargetTypemask::from_bits_truncate(
                8 | 16 | 32 | 64 | 128 | 256 | 2048,
            ),
            x: 5.0,
            z: -2.0,
            yaw,
            ..Default::default()
        })
    }

    const AT: FrameTime = FrameTime {
        arrival_us: 1_500_000,
        now: 1.5,
        signing_now: 0,
        state: 0,
        fault: false,
    };

    fn texts(out: &RxOutput) -> Vec<String> {
        out.replies
            .iter()
            .filter_map(|m| match m {
                MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_setpoint_becomes_an_event_at_its_arrival_and_its_yaw_is_said_once() {
        let mut core = core();
        let out = core.on_frame(&frame((255, 190), setpoint((1, 191), 1.0)), false, AT);
        assert!(out.record);
        match out.events.as_slice() {
            [
                Event::Setpoint {
                    arrival, position, ..
                },
            ] => {
                assert_eq!(*arrival, 1.5);
                assert_eq!(*position, [5.0, 0.0, -2.0]);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            texts(&out),
            ["dflat: setpoint yaw ignored, yaw fixed 0 deg"]
        );
        let again = core.on_frame(&frame((255, 190), setpoint((1, 191), 1.0)), false, AT);
        assert_eq!(again.events.len(), 1);
        assert!(texts(&again).is_empty());
    }

    #[test]
    fn a_setpoint_sent_to_the_autopilot_is_redirected_in_words_once() {
        let mut core = core();
        let out = core.on_frame(&frame((255, 190), setpoint((1, 1), 0.0)), false, AT);
        assert!(out.events.is_empty());
        assert_eq!(
            texts(&out),
            ["dflat: setpoints go to 1/191, not the autopilot"]
        );
        let again = core.on_frame(&frame((255, 190), setpoint((1, 1), 0.0)), false, AT);
        assert!(again.events.is_empty() && again.replies.is_empty());
    }

    #[test]
    fn an_unknown_ground_station_is_denied_and_named() {
        let mut core = core();
        let command = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: 1,
            target_component: 191,
            command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
            ..Default::default()
        });
        let out = core.on_frame(&frame((7, 190), command), false, AT);
        assert!(out.events.is_empty() && !out.record);
        assert!(matches!(
            out.replies.first(),
            Some(MavMessage::COMMAND_ACK(d)) if d.result == MavResult::MAV_RESULT_DENIED
        ));
        assert_eq!(texts(&out), ["dflat: id 7 not in link.gcs_system_ids"]);
    }

    #[test]
    fn before_the_udpin_lock_only_the_autopilots_heartbeat_passes_and_locks() {
        let mut core = core();
        let heartbeat = heartbeat_onboard(DaemonStatus::Active);
        let gcs = frame((255, 190), heartbeat.clone());
        assert_eq!(core.gate(&gcs, true, 0), Gate::Foreign);
        let autopilot = frame((1, 1), heartbeat);
        assert_eq!(
            core.gate(&autopilot, true, 0),
            Gate::Lock("127.0.0.1:14550".parse().unwrap())
        );
        // Once locked (or without a peer to lock), everything is looked at.
        assert_eq!(core.gate(&gcs, false, 0), Gate::Pass);
    }
}

#[cfg(test)]
mod refusal_text_tests {
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
