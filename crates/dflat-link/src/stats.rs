//! Link counters: what arrived, what was dropped and why, what was sent.

use std::fmt::Write as _;

use mavlink::dialects::common::MavMessage;
use mavlink::error::MessageReadError;

use crate::inbound::ids;
use crate::{ErrorCategory, FrameError, LinkError};

/// Per-message-type counters for the contract's messages.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct MessageCounts {
    /// HEARTBEAT (0).
    pub heartbeat: u64,
    /// ATTITUDE (30).
    pub attitude: u64,
    /// LOCAL_POSITION_NED (32).
    pub local_position_ned: u64,
    /// SET_ATTITUDE_TARGET (82).
    pub set_attitude_target: u64,
    /// SET_POSITION_TARGET_LOCAL_NED (84).
    pub set_position_target_local_ned: u64,
    /// VISION_POSITION_ESTIMATE (102).
    pub vision_position_estimate: u64,
    /// STATUSTEXT (253).
    pub statustext: u64,
    /// ODOMETRY (331).
    pub odometry: u64,
    /// Any other message id.
    pub other: u64,
}

impl MessageCounts {
    /// Counts one message with id `msg_id`.
    pub fn record(&mut self, msg_id: u32) {
        let slot = match msg_id {
            ids::HEARTBEAT => &mut self.heartbeat,
            ids::ATTITUDE => &mut self.attitude,
            ids::LOCAL_POSITION_NED => &mut self.local_position_ned,
            ids::SET_ATTITUDE_TARGET => &mut self.set_attitude_target,
            ids::SET_POSITION_TARGET_LOCAL_NED => &mut self.set_position_target_local_ned,
            ids::VISION_POSITION_ESTIMATE => &mut self.vision_position_estimate,
            ids::STATUSTEXT => &mut self.statustext,
            ids::ODOMETRY => &mut self.odometry,
            _ => &mut self.other,
        };
        *slot += 1;
    }

    /// Sum over all types.
    pub fn total(&self) -> u64 {
        self.heartbeat
            + self.attitude
            + self.local_position_ned
            + self.set_attitude_target
            + self.set_position_target_local_ned
            + self.vision_position_estimate
            + self.statustext
            + self.odometry
            + self.other
    }

    fn write(&self, out: &mut String) {
        let fields = [
            ("hb", self.heartbeat),
            ("att", self.attitude),
            ("lpos", self.local_position_ned),
            ("att_tgt", self.set_attitude_target),
            ("pos_tgt", self.set_position_target_local_ned),
            ("vpe", self.vision_position_estimate),
            ("text", self.statustext),
            ("odom", self.odometry),
            ("other", self.other),
        ];
        for (i, (name, n)) in fields.iter().enumerate() {
            let sep = if i == 0 { "" } else { " " };
            let _ = write!(out, "{sep}{name}={n}");
        }
    }
}

/// Counters of one MAVLink link. Plain data: the daemon owns it, records
/// into it and logs [`LinkStats::summary`] when it likes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Frames that parsed (valid CRC), by type, before source filtering.
    pub received: MessageCounts,
    /// Messages sent, by type.
    pub sent: MessageCounts,
    /// Dropped: the sender is not one the filter trusts for that message.
    pub ignored_wrong_source: u64,
    /// Dropped: addressed to another system or component.
    pub ignored_not_addressed: u64,
    /// Frames with a checksum mismatch.
    pub crc_errors: u64,
    /// Frames with a message id outside the common dialect.
    pub unknown_messages: u64,
    /// Truncated frames, bad flags, undecodable payloads, bad quaternions.
    pub malformed: u64,
    /// Messages refused for NaN / infinite numbers.
    pub non_finite: u64,
    /// Well-formed messages outside the contract (frame, type_mask).
    pub rejected: u64,
    /// Outbound messages refused by a builder or failed to write.
    pub send_errors: u64,
    /// Signing on: unsigned frames refused (everything that must be signed,
    /// and what `accept_unsigned` does not list).
    pub unsigned: u64,
    /// Signing on: frames signed with another key (or altered).
    pub bad_signature: u64,
    /// Signing on: correctly signed frames with a stale timestamp (replay).
    pub replayed: u64,
    /// Signing on: correctly signed frames with a timestamp more than a
    /// minute ahead of the clock.
    pub future_timestamp: u64,
}

impl LinkStats {
    /// Counts a received, CRC-valid message by id.
    pub fn record_received(&mut self, msg_id: u32) {
        self.received.record(msg_id);
    }

    /// Counts a sent message.
    pub fn record_sent(&mut self, msg: &MavMessage) {
        self.sent.record(mavlink::Message::message_id(msg));
    }

    /// Counts an inbound error in its category.
    pub fn record_error(&mut self, error: &LinkError) {
        self.record_category(error.category());
    }

    /// Counts a framing / payload error from [`crate::FrameParser`] or [`crate::frames`].
    pub fn record_frame_error(&mut self, error: &FrameError) {
        self.record_category(error.category());
    }

    /// Counts an error returned by the mavlink crate's `recv` / `try_recv`.
    /// Returns `true` if it was an I/O error (the link itself is in trouble).
    ///
    /// Note that mavlink 0.21 never reports CRC failures here: its reader
    /// skips them silently. To count those, read bytes yourself and use
    /// [`crate::FrameParser`].
    pub fn record_read_error(&mut self, error: &MessageReadError) -> bool {
        match error {
            MessageReadError::Io(_) => true,
            MessageReadError::Parse(e) => {
                self.record_frame_error(&FrameError::from_parser_error(0, e));
                false
            }
        }
    }

    /// Counts an outbound failure (builder refused or write failed).
    pub fn record_send_error(&mut self, _error: &LinkError) {
        self.send_errors += 1;
    }

    /// Increments the counter for `category` (inbound meaning).
    pub fn record_category(&mut self, category: ErrorCategory) {
        let slot = match category {
            ErrorCategory::Crc => &mut self.crc_errors,
            ErrorCategory::UnknownMessage => &mut self.unknown_messages,
            ErrorCategory::Malformed => &mut self.malformed,
            ErrorCategory::NonFinite => &mut self.non_finite,
            ErrorCategory::Rejected => &mut self.rejected,
            ErrorCategory::InvalidArgument | ErrorCategory::Io => &mut self.send_errors,
        };
        *slot += 1;
    }

    /// Sum of all inbound error counters (not the ignored ones).
    pub fn inbound_errors(&self) -> u64 {
        self.crc_errors
            + self.unknown_messages
            + self.malformed
            + self.non_finite
            + self.rejected
            + self.unsigned
            + self.bad_signature
            + self.replayed
    }

    /// One-line summary, e.g.
    /// `rx hb=.. att=.. … | tx … | ignored src=.. dst=.. | errors crc=.. …`.
    pub fn summary(&self) -> String {
        let mut s = String::with_capacity(256);
        s.push_str("rx ");
        self.received.write(&mut s);
        s.push_str(" | tx ");
        self.sent.write(&mut s);
        let _ = write!(
            s,
            " | ignored src={} dst={} | errors crc={} unknown={} malformed={} nonfinite={} rejected={} send={} | signing unsigned={} badsig={} replayed={}",
            self.ignored_wrong_source,
            self.ignored_not_addressed,
            self.crc_errors,
            self.unknown_messages,
            self.malformed,
            self.non_finite,
            self.rejected,
            self.send_errors,
            self.unsigned,
            self.bad_signature,
            self.replayed,
        );
        s
    }
}
