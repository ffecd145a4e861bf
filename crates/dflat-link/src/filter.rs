//! Who may say what: source filtering, and the receive pipeline that ties
//! filter, decoder and counters together.

use mavlink::dialects::common::MavMessage;
use mavlink::{MavHeader, Message};

use crate::inbound::{Inbound, decode};
use crate::{FrameError, LinkError, LinkStats, SignatureCheck, SignedFrame, Signing};

/// Trusted MAVLink ids for one endpoint (the daemon, or the SITL autopilot).
///
/// Rules, in order:
/// 1. Our own id (`vehicle_system_id`, `own_component_id`) is an echo:
///    ignored.
/// 2. HEARTBEAT, ATTITUDE, LOCAL_POSITION_NED: only from the autopilot
///    (`vehicle_system_id`, `autopilot_component_id`).
/// 3. ODOMETRY, VISION_POSITION_ESTIMATE: from the autopilot or from one of
///    `pose_components` of the own vehicle (e.g. 197, a VIO component), or
///    from the ground station (mocap relayed by a GCS).
/// 4. SET_POSITION_TARGET_LOCAL_NED: from a ground station (one of
///    `gcs_system_ids`, any component) or one of `setpoint_components` of the
///    own vehicle; and it must be addressed to us: `target_system` ∈ {0,
///    vehicle}, `target_component` ∈ {0, own component} — else
///    [`Verdict::IgnoreNotAddressed`].
/// 5. SET_ATTITUDE_TARGET (the SITL side): from any other component of the
///    own vehicle, addressed like rule 4.
/// 6. COMMAND_ACK: only from the autopilot (the answers to the daemon's
///    own requests), addressed like rule 4 (an autopilot's answer to a
///    ground station's command is not ours).
/// 7. Anything else: accepted from the autopilot or the ground station.
///
/// For the SITL, set `own_component_id` to the autopilot component (1).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceFilter {
    /// The vehicle's system id (default 1).
    pub vehicle_system_id: u8,
    /// The autopilot's component id (default 1, MAV_COMP_ID_AUTOPILOT1).
    pub autopilot_component_id: u8,
    /// This endpoint's component id (daemon default 191, MAV_COMP_ID_ONBOARD_COMPUTER).
    pub own_component_id: u8,
    /// The ground stations' system ids (default 255 — QGroundControl,
    /// MAVProxy — and 245 — MAVSDK).
    pub gcs_system_ids: Vec<u8>,
    /// Own-vehicle components allowed to send position setpoints (default none).
    pub setpoint_components: Vec<u8>,
    /// Own-vehicle components allowed to send ODOMETRY / VISION_POSITION_ESTIMATE
    /// besides the autopilot (default none).
    pub pose_components: Vec<u8>,
}

impl Default for SourceFilter {
    fn default() -> Self {
        Self {
            vehicle_system_id: 1,
            autopilot_component_id: 1,
            own_component_id: 191,
            gcs_system_ids: DEFAULT_GCS_SYSTEM_IDS.to_vec(),
            setpoint_components: Vec::new(),
            pose_components: Vec::new(),
        }
    }
}

/// The ground-station system ids trusted by default: 255 (QGroundControl,
/// MAVProxy) and 245 (MAVSDK).
pub const DEFAULT_GCS_SYSTEM_IDS: [u8; 2] = [255, 245];

/// The filter's decision for one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Verdict {
    /// Act on it.
    Accept,
    /// The sender is not trusted for this message.
    IgnoreWrongSource,
    /// The message is addressed to another system or component.
    IgnoreNotAddressed,
}

impl SourceFilter {
    fn is(&self, header: &MavHeader, system: u8, component: u8) -> bool {
        header.system_id == u32::from(system) && header.component_id == component
    }

    fn sent_by_vehicle(&self, header: &MavHeader) -> bool {
        header.system_id == u32::from(self.vehicle_system_id)
    }

    fn sent_by_gcs(&self, header: &MavHeader) -> bool {
        u8::try_from(header.system_id).is_ok_and(|s| self.gcs_system_ids.contains(&s))
    }

    fn sent_by_autopilot(&self, header: &MavHeader) -> bool {
        self.is(header, self.vehicle_system_id, self.autopilot_component_id)
    }

    fn addressed_to_us(&self, msg: &MavMessage) -> bool {
        let system_ok = msg
            .target_system_id()
            .is_none_or(|s| s == 0 || s == self.vehicle_system_id);
        let component_ok = msg
            .target_component_id()
            .is_none_or(|c| c == 0 || c == self.own_component_id);
        system_ok && component_ok
    }

    /// Decides whether to act on `msg` from the sender in `header`.
    pub fn check(&self, header: &MavHeader, msg: &MavMessage) -> Verdict {
        if self.is(header, self.vehicle_system_id, self.own_component_id) {
            return Verdict::IgnoreWrongSource;
        }
        let trusted = match msg {
            MavMessage::HEARTBEAT(_)
            | MavMessage::ATTITUDE(_)
            | MavMessage::PARAM_VALUE(_)
            | MavMessage::LOCAL_POSITION_NED(_) => self.sent_by_autopilot(header),
            MavMessage::ODOMETRY(_) | MavMessage::VISION_POSITION_ESTIMATE(_) => {
                self.sent_by_autopilot(header)
                    || self.sent_by_gcs(header)
                    || (self.sent_by_vehicle(header)
                        && self.pose_components.contains(&header.component_id))
            }
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(_) => {
                self.sent_by_gcs(header)
                    || (self.sent_by_vehicle(header)
                        && self.setpoint_components.contains(&header.component_id))
            }
            MavMessage::SET_ATTITUDE_TARGET(_) => self.sent_by_vehicle(header),
            MavMessage::COMMAND_ACK(_) => self.sent_by_autopilot(header),
            _ => self.sent_by_autopilot(header) || self.sent_by_gcs(header),
        };
        if !trusted {
            return Verdict::IgnoreWrongSource;
        }
        match msg {
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(_)
            | MavMessage::SET_ATTITUDE_TARGET(_)
            | MavMessage::COMMAND_ACK(_)
                if !self.addressed_to_us(msg) =>
            {
                Verdict::IgnoreNotAddressed
            }
            _ => Verdict::Accept,
        }
    }
}

impl SourceFilter {
    /// The sender's system id when `msg` is a request that moves the
    /// vehicle or asks something of this endpoint — a position setpoint, a
    /// command, a mission message — addressed to us (or broadcast) by
    /// another system that is not one of `gcs_system_ids`: a ground station
    /// the configuration does not name. The caller refuses it in words
    /// (it is never acted on: [`check`](Self::check) ignores it).
    pub fn unknown_ground_station(&self, header: &MavHeader, msg: &MavMessage) -> Option<u8> {
        let system = u8::try_from(header.system_id).ok()?;
        if system == self.vehicle_system_id || self.gcs_system_ids.contains(&system) {
            return None;
        }
        // Commands only when addressed to this component: a broadcast is
        // declined by silence (MAVLink's convention), not refused.
        let command = matches!(
            msg,
            MavMessage::COMMAND_LONG(_) | MavMessage::COMMAND_INT(_)
        );
        if command && msg.target_component_id() != Some(self.own_component_id) {
            return None;
        }
        let request = command
            || matches!(
                msg,
                MavMessage::SET_POSITION_TARGET_LOCAL_NED(_)
                    | MavMessage::MISSION_COUNT(_)
                    | MavMessage::MISSION_ITEM_INT(_)
                    | MavMessage::MISSION_CLEAR_ALL(_)
                    | MavMessage::MISSION_REQUEST_LIST(_)
            );
        (request && self.addressed_to_us(msg)).then_some(system)
    }
}

/// What [`LinkRx::handle`] made of one message (already counted).
#[derive(Debug)]
pub enum RxOutcome {
    /// Trusted and valid: act on it.
    Accepted(Inbound),
    /// Dropped by the source filter.
    Ignored(Verdict),
    /// Trusted but invalid (non-finite, wrong frame, bad quaternion, …).
    Rejected(LinkError),
}

/// Receive pipeline: filter → decode → count. Pure and synchronous; the
/// daemon feeds it what its connection (or [`crate::FrameParser`]) yields.
#[derive(Debug, Clone, Default)]
pub struct LinkRx {
    /// The source filter.
    pub filter: SourceFilter,
    /// The counters.
    pub stats: LinkStats,
    /// MAVLink 2 signing; `None` = off (everything passes
    /// [`authenticate`](Self::authenticate)).
    pub signing: Option<Signing>,
}

impl LinkRx {
    /// A pipeline with zeroed counters.
    pub fn new(filter: SourceFilter) -> Self {
        Self {
            filter,
            stats: LinkStats::default(),
            signing: None,
        }
    }

    /// Signing gate, before [`handle`](Self::handle). With signing off:
    /// `Ok`. With signing on: a bad signature or a replayed timestamp is
    /// refused for every message, and so is a timestamp more than a minute
    /// ahead of the clock; an unsigned frame is refused unless
    /// [`Signing::accepts_unsigned`] (never for [`Signing::must_be_signed`]:
    /// setpoints, pose, HEARTBEAT, PARAM_VALUE, missions, commands).
    /// Refusals are counted (`unsigned`, `bad_signature`, `replayed`,
    /// `future_timestamp`) and returned. `now`: the wall clock as a signing timestamp.
    pub fn authenticate(
        &mut self,
        header: &MavHeader,
        msg: &MavMessage,
        signed: Option<&SignedFrame>,
        now: u64,
    ) -> Result<(), SignatureCheck> {
        let Some(signing) = self.signing.as_mut() else {
            return Ok(());
        };
        let check = signing.verify(header, signed, now);
        let refused = match check {
            SignatureCheck::Valid { .. } => return Ok(()),
            SignatureCheck::Unsigned if signing.accepts_unsigned(msg) => {
                return Ok(());
            }
            SignatureCheck::Unsigned => &mut self.stats.unsigned,
            SignatureCheck::BadSignature => &mut self.stats.bad_signature,
            SignatureCheck::Replayed => &mut self.stats.replayed,
            SignatureCheck::FutureTimestamp => &mut self.stats.future_timestamp,
        };
        *refused += 1;
        self.stats.record_received(msg.message_id());
        tracing::debug!(
            sysid = header.system_id,
            compid = header.component_id,
            ?check,
            "frame refused by signing"
        );
        Err(check)
    }

    /// Filters, decodes and counts one received message.
    pub fn handle(&mut self, header: &MavHeader, msg: &MavMessage) -> RxOutcome {
        self.stats.record_received(msg.message_id());
        match self.filter.check(header, msg) {
            Verdict::Accept => {}
            verdict @ Verdict::IgnoreWrongSource => {
                self.stats.ignored_wrong_source += 1;
                return RxOutcome::Ignored(verdict);
            }
            verdict @ Verdict::IgnoreNotAddressed => {
                self.stats.ignored_not_addressed += 1;
                return RxOutcome::Ignored(verdict);
            }
        }
        match decode(header, msg) {
            Ok(inbound) => RxOutcome::Accepted(inbound),
            Err(error) => {
                self.stats.record_error(&error);
                tracing::debug!(
                    sysid = header.system_id,
                    compid = header.component_id,
                    %error,
                    "inbound message rejected"
                );
                RxOutcome::Rejected(error)
            }
        }
    }

    /// Counts a framing error (CRC, unknown id, truncation, …).
    pub fn frame_error(&mut self, error: &FrameError) {
        self.stats.record_frame_error(error);
    }
}
