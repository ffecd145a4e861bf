//! Error types and the counting categories they fall into.

use mavlink::dialects::common::MavFrame;
use mavlink::error::ParserError;
use thiserror::Error;

/// Why a message could not be decoded, built or written.
///
/// Every variant maps to one [`ErrorCategory`] (see [`LinkError::category`])
/// so the daemon can count failures without matching on details.
#[derive(Debug, Error)]
pub enum LinkError {
    /// A number the contract uses was NaN or infinite (inbound: message
    /// rejected; outbound: nothing is built, so no NaN ever leaves).
    #[error("{message}: non-finite {field}")]
    NonFinite {
        /// MAVLink message name.
        message: &'static str,
        /// Field name.
        field: &'static str,
    },
    /// A quaternion was zero or far from unit norm (tolerance ±10 %).
    #[error("{message}: quaternion norm {norm} is not a rotation")]
    BadQuaternion {
        /// MAVLink message name.
        message: &'static str,
        /// Euclidean norm of the received quaternion.
        norm: f64,
    },
    /// The message's coordinate frame is not one the contract accepts.
    #[error("{message}: frame {frame:?} is not supported (accepted: {accepted})")]
    UnsupportedFrame {
        /// MAVLink message name.
        message: &'static str,
        /// The frame that was sent.
        frame: MavFrame,
        /// The accepted frames, in words.
        accepted: &'static str,
    },
    /// A type_mask asks for a mode the contract does not implement.
    #[error("{message}: type_mask {type_mask:#06x} is not supported ({reason})")]
    UnsupportedTypeMask {
        /// MAVLink message name.
        message: &'static str,
        /// The raw type_mask bits.
        type_mask: u16,
        /// Why, in words.
        reason: &'static str,
    },
    /// SET_POSITION_TARGET_LOCAL_NED was well-formed but not a usable setpoint.
    #[error("position setpoint rejected: {0}")]
    SetpointRejected(SetpointRejection),
    /// A header's system id does not fit MAVLink 2's 8-bit field (the mavlink
    /// crate would otherwise set its non-standard 32-bit-sysid flag).
    #[error("system id {0} does not fit the 8-bit MAVLink 2 field")]
    SystemIdOutOfRange(u32),
    /// A numeric argument was outside its allowed range.
    #[error("{name} = {value} is outside {allowed}")]
    OutOfRange {
        /// Argument name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The allowed range, in words.
        allowed: &'static str,
    },
    /// Framing or payload decoding failed.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// Writing serialized bytes failed.
    #[error("write failed: {0}")]
    Io(#[from] std::io::Error),
}

/// Why a SET_POSITION_TARGET_LOCAL_NED (84) was refused.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum SetpointRejection {
    /// `coordinate_frame` was not MAV_FRAME_LOCAL_NED (1).
    #[error("coordinate_frame {0:?} is not MAV_FRAME_LOCAL_NED")]
    Frame(MavFrame),
    /// One or more of the x/y/z ignore bits (1|2|4) were set.
    #[error("type_mask {type_mask:#06x} ignores part of the position")]
    PositionIgnored {
        /// The raw type_mask bits.
        type_mask: u16,
    },
}

/// Why bytes could not be turned into a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum FrameError {
    /// The frame checksum did not match (corruption or a foreign dialect).
    #[error("CRC mismatch for message id {msg_id}")]
    Crc {
        /// Message id claimed by the (possibly corrupt) header.
        msg_id: u32,
    },
    /// The message id is not in the common dialect, so its CRC cannot be checked.
    #[error("message id {msg_id} is not in the common dialect")]
    UnknownMessage {
        /// Message id from the header.
        msg_id: u32,
    },
    /// MAVLink 2 incompatibility flags other than "signed" were set.
    #[error("unsupported MAVLink 2 incompatibility flags {flags:#04x}")]
    UnsupportedFlags {
        /// The incompatibility flags byte.
        flags: u8,
    },
    /// The CRC matched but the payload did not decode.
    #[error("message id {msg_id}: {fault}")]
    Payload {
        /// Message id.
        msg_id: u32,
        /// What was wrong with the payload.
        fault: PayloadFault,
    },
    /// The bytes ended inside a frame.
    #[error("truncated frame: {available} of {needed} bytes")]
    Truncated {
        /// Bytes present from the start marker on.
        available: usize,
        /// Bytes the header says the frame needs (at least).
        needed: usize,
    },
    /// The bytes do not start with a MAVLink start marker (0xFD or 0xFE).
    #[error("no MAVLink start marker")]
    NoMarker,
}

/// What was wrong with a payload whose CRC matched.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum PayloadFault {
    /// An enum field held a value the dialect does not define.
    #[error("invalid value {value} for enum {enum_type}")]
    InvalidEnum {
        /// Enum type name.
        enum_type: &'static str,
        /// The value received.
        value: u64,
    },
    /// The payload is longer than the message definition allows.
    #[error("payload of {actual} bytes exceeds {maximum}")]
    TooLong {
        /// Allowed maximum.
        maximum: usize,
        /// Received length.
        actual: usize,
    },
    /// The message id is unknown to the dialect.
    #[error("unknown message")]
    UnknownMessage,
    /// Any other decoder failure.
    #[error("malformed payload")]
    Other,
}

impl FrameError {
    /// Converts a mavlink [`ParserError`] for message `msg_id` (as returned by
    /// `MavConnection::try_recv` inside `MessageReadError::Parse`).
    pub fn from_parser_error(msg_id: u32, error: &ParserError) -> Self {
        let fault = match error {
            ParserError::InvalidEnum { enum_type, value } => PayloadFault::InvalidEnum {
                enum_type,
                value: *value,
            },
            ParserError::UnknownMessage { id } => {
                return FrameError::UnknownMessage { msg_id: *id };
            }
            ParserError::InvalidPayloadSize {
                maximum, actual, ..
            } => PayloadFault::TooLong {
                maximum: *maximum,
                actual: *actual,
            },
            ParserError::BytesError(_) => PayloadFault::Other,
        };
        FrameError::Payload { msg_id, fault }
    }

    /// The counting category of this error.
    pub fn category(&self) -> ErrorCategory {
        match self {
            FrameError::Crc { .. } => ErrorCategory::Crc,
            FrameError::UnknownMessage { .. } => ErrorCategory::UnknownMessage,
            FrameError::UnsupportedFlags { .. }
            | FrameError::Payload { .. }
            | FrameError::Truncated { .. }
            | FrameError::NoMarker => ErrorCategory::Malformed,
        }
    }
}

/// Coarse error classes, one counter each in [`crate::LinkStats`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorCategory {
    /// Checksum mismatch.
    Crc,
    /// Message id outside the common dialect.
    UnknownMessage,
    /// Framing, payload, quaternion or header defects.
    Malformed,
    /// NaN or infinite numbers.
    NonFinite,
    /// Well-formed but outside the contract (frame, type_mask, setpoint).
    Rejected,
    /// An outbound argument was out of range.
    InvalidArgument,
    /// Writing failed.
    Io,
}

impl LinkError {
    /// The counting category of this error.
    pub fn category(&self) -> ErrorCategory {
        match self {
            LinkError::NonFinite { .. } => ErrorCategory::NonFinite,
            LinkError::BadQuaternion { .. } | LinkError::SystemIdOutOfRange(_) => {
                ErrorCategory::Malformed
            }
            LinkError::UnsupportedFrame { .. }
            | LinkError::UnsupportedTypeMask { .. }
            | LinkError::SetpointRejected(_) => ErrorCategory::Rejected,
            LinkError::OutOfRange { .. } => ErrorCategory::InvalidArgument,
            LinkError::Frame(e) => e.category(),
            LinkError::Io(_) => ErrorCategory::Io,
        }
    }
}
