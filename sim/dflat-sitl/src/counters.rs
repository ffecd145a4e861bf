//! The SITL's counters: what it received, sent (per destination) and
//! answered.

use std::sync::atomic::{AtomicU64, Ordering};

/// The SITL's own frames of one destination, by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SentCounts {
    /// HEARTBEAT (1 Hz, and on request).
    pub heartbeats: u64,
    /// LOCAL_POSITION_NED.
    pub positions: u64,
    /// VISION_POSITION_ESTIMATE.
    pub visions: u64,
    /// ATTITUDE.
    pub attitudes: u64,
    /// SYS_STATUS (1 Hz, and on request).
    pub sys_status: u64,
    /// Answers: COMMAND_ACK, PARAM_VALUE, STATUSTEXT, FTP replies,
    /// AUTOPILOT_VERSION.
    pub replies: u64,
}

impl SentCounts {
    /// Every frame counted here.
    pub fn total(&self) -> u64 {
        self.heartbeats
            + self.positions
            + self.visions
            + self.attitudes
            + self.sys_status
            + self.replies
    }
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
    /// SYS_STATUS sent on the vehicle link.
    pub sys_status_sent: u64,
    /// Answers sent on the vehicle link (see [`SentCounts::replies`]).
    pub replies_sent: u64,
    /// The SITL's own frames sent to the ground station, by kind.
    pub to_gcs: SentCounts,
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
    /// COMMAND_LONG / COMMAND_INT acknowledged (either link).
    pub commands_acked: u64,
    /// … of which UNSUPPORTED.
    pub commands_unsupported: u64,
    /// … of which DENIED.
    pub commands_denied: u64,
    /// PARAM_SET applied.
    pub params_set: u64,
    /// PARAM_SET / PARAM_REQUEST_READ refused (unknown, read-only, out of range).
    pub params_refused: u64,
    /// FTP requests answered (NAK, or ACK for session resets).
    pub ftp_answered: u64,
    /// SETUP_SIGNING refused (the key comes from `sitl.signing_key_file`).
    pub signing_setups_refused: u64,
    /// Framing errors (CRC, unknown id, truncation) on either link.
    pub frame_errors: u64,
    /// Frames received from the ground station.
    pub gcs_frames_in: u64,
    /// Frames from the ground station handled by the SITL and not routed
    /// (addressed to its own component).
    pub gcs_frames_kept: u64,
    /// Frames routed from the vehicle link to the ground station.
    pub gcs_frames_routed: u64,
    /// Frames sent to the ground station: routed plus the SITL's own
    /// ([`SitlCounters::to_gcs`]).
    pub gcs_frames_out: u64,
    /// Entries into the hold mode after commanded flight.
    pub hold_entries: u64,
    /// Mode changes (position ⇄ offboard).
    pub mode_changes: u64,
    /// Requests for offboard refused because no stream was alive.
    pub offboard_refused: u64,
    /// SET_POSITION_TARGET_LOCAL_NED samples the planner sent to the
    /// daemon (`[sitl.planner]`).
    pub planner_samples: u64,
    /// Plant integration steps.
    pub plant_steps: u64,
    /// Plant steps that ran late (the thread missed its deadline).
    pub late_steps: u64,
    /// The longest a plant step ran behind its due time while in
    /// offboard \[µs\] (the plant thread woke late: the machine starved
    /// it while the commands flew the plant).
    pub step_lag_max_us: u64,
    /// Failed socket sends.
    pub send_errors: u64,
    /// Pose departure → command arrival and the command cadence
    /// (see [`super::PoseLatency`]).
    pub pose_latency: super::PoseLatency,
}

/// What kind of own frame is sent (for the per-destination counts,
/// [`SentCounts`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SentKind {
    /// HEARTBEAT.
    Heartbeat,
    /// LOCAL_POSITION_NED.
    Position,
    /// VISION_POSITION_ESTIMATE.
    Vision,
    /// ATTITUDE.
    Attitude,
    /// SYS_STATUS.
    SysStatus,
    /// Anything else: answers, STATUSTEXT, the PX4 face's streams.
    Reply,
}

#[derive(Default)]
pub(super) struct SentAtomics {
    heartbeats: AtomicU64,
    positions: AtomicU64,
    visions: AtomicU64,
    attitudes: AtomicU64,
    sys_status: AtomicU64,
    replies: AtomicU64,
}

impl SentAtomics {
    pub(super) fn count(&self, kind: SentKind) {
        bump(match kind {
            SentKind::Heartbeat => &self.heartbeats,
            SentKind::Position => &self.positions,
            SentKind::Vision => &self.visions,
            SentKind::Attitude => &self.attitudes,
            SentKind::SysStatus => &self.sys_status,
            SentKind::Reply => &self.replies,
        });
    }

    fn snapshot(&self) -> SentCounts {
        SentCounts {
            heartbeats: get(&self.heartbeats),
            positions: get(&self.positions),
            visions: get(&self.visions),
            attitudes: get(&self.attitudes),
            sys_status: get(&self.sys_status),
            replies: get(&self.replies),
        }
    }
}

#[derive(Default)]
pub(super) struct Counters {
    pub(super) to_vehicle: SentAtomics,
    pub(super) to_gcs: SentAtomics,
    pub(super) frames_received: AtomicU64,
    pub(super) commands_accepted: AtomicU64,
    pub(super) commands_ignored: AtomicU64,
    pub(super) commands_rejected: AtomicU64,
    pub(super) commands_unauthenticated: AtomicU64,
    pub(super) commands_acked: AtomicU64,
    pub(super) commands_unsupported: AtomicU64,
    pub(super) commands_denied: AtomicU64,
    pub(super) params_set: AtomicU64,
    pub(super) params_refused: AtomicU64,
    pub(super) ftp_answered: AtomicU64,
    pub(super) signing_setups_refused: AtomicU64,
    pub(super) frame_errors: AtomicU64,
    pub(super) gcs_frames_in: AtomicU64,
    pub(super) gcs_frames_kept: AtomicU64,
    pub(super) gcs_frames_routed: AtomicU64,
    pub(super) hold_entries: AtomicU64,
    pub(super) mode_changes: AtomicU64,
    pub(super) offboard_refused: AtomicU64,
    pub(super) planner_samples: AtomicU64,
    pub(super) plant_steps: AtomicU64,
    pub(super) late_steps: AtomicU64,
    pub(super) step_lag_max_us: AtomicU64,
    pub(super) send_errors: AtomicU64,
    pub(super) poses_dropped: AtomicU64,
    pub(super) poses_delayed: AtomicU64,
}

pub(super) fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

fn get(c: &AtomicU64) -> u64 {
    c.load(Ordering::Relaxed)
}

impl Counters {
    /// Adds the increments of one step ([`super::SitlOutput::counts`]:
    /// the counters the step keeps).
    pub(super) fn add(&self, c: &SitlCounters) {
        let add = |a: &AtomicU64, n: u64| {
            if n > 0 {
                a.fetch_add(n, Ordering::Relaxed);
            }
        };
        add(&self.plant_steps, c.plant_steps);
        add(&self.late_steps, c.late_steps);
        add(&self.hold_entries, c.hold_entries);
        add(&self.mode_changes, c.mode_changes);
        add(&self.offboard_refused, c.offboard_refused);
        add(&self.commands_acked, c.commands_acked);
        add(&self.commands_unsupported, c.commands_unsupported);
        add(&self.commands_denied, c.commands_denied);
        add(&self.params_set, c.params_set);
        add(&self.params_refused, c.params_refused);
        add(&self.ftp_answered, c.ftp_answered);
        add(&self.signing_setups_refused, c.signing_setups_refused);
        add(&self.poses_dropped, c.pose_latency.poses_dropped);
        add(&self.poses_delayed, c.pose_latency.poses_delayed);
    }

    /// A plant step ran `lag` behind its due time (the shell's clock).
    pub(super) fn step_lag(&self, lag: std::time::Duration) {
        let us = u64::try_from(lag.as_micros()).unwrap_or(u64::MAX);
        self.step_lag_max_us.fetch_max(us, Ordering::Relaxed);
    }

    /// The counters now, with the latency probe's figures `latency`.
    pub(super) fn snapshot(&self, latency: super::PoseLatency) -> SitlCounters {
        let v = self.to_vehicle.snapshot();
        let to_gcs = self.to_gcs.snapshot();
        let routed = get(&self.gcs_frames_routed);
        SitlCounters {
            heartbeats_sent: v.heartbeats,
            positions_sent: v.positions,
            visions_sent: v.visions,
            attitudes_sent: v.attitudes,
            sys_status_sent: v.sys_status,
            replies_sent: v.replies,
            to_gcs,
            frames_received: get(&self.frames_received),
            commands_accepted: get(&self.commands_accepted),
            commands_ignored: get(&self.commands_ignored),
            commands_rejected: get(&self.commands_rejected),
            commands_unauthenticated: get(&self.commands_unauthenticated),
            commands_acked: get(&self.commands_acked),
            commands_unsupported: get(&self.commands_unsupported),
            commands_denied: get(&self.commands_denied),
            params_set: get(&self.params_set),
            params_refused: get(&self.params_refused),
            ftp_answered: get(&self.ftp_answered),
            signing_setups_refused: get(&self.signing_setups_refused),
            frame_errors: get(&self.frame_errors),
            gcs_frames_in: get(&self.gcs_frames_in),
            gcs_frames_kept: get(&self.gcs_frames_kept),
            gcs_frames_routed: routed,
            gcs_frames_out: routed + to_gcs.total(),
            hold_entries: get(&self.hold_entries),
            mode_changes: get(&self.mode_changes),
            offboard_refused: get(&self.offboard_refused),
            planner_samples: get(&self.planner_samples),
            plant_steps: get(&self.plant_steps),
            late_steps: get(&self.late_steps),
            step_lag_max_us: get(&self.step_lag_max_us),
            send_errors: get(&self.send_errors),
            pose_latency: super::PoseLatency {
                poses_dropped: get(&self.poses_dropped),
                poses_delayed: get(&self.poses_delayed),
                ..latency
            },
        }
    }
}
