//! MAVLink 2 bytes ⇄ messages, with every failure surfaced for counting.
//!
//! The mavlink crate's readers skip frames with bad CRCs silently; this
//! module's parsers report them instead ([`FrameError::Crc`]), so daemon,
//! SITL, tlog tools and tests share one frame codec that can be counted.
//!
//! Each corrupt frame is reported once: after a bad candidate, further bad
//! candidates that start inside its claimed length (start markers inside the
//! corrupt payload) are skipped silently, while valid frames found there are
//! still returned.
//!
//! Signed MAVLink 2 frames are framed correctly and carried in
//! [`Frame::signed`]; their signatures are verified by
//! [`crate::Signing::verify`] (the parser has no key). The mavlink crate's non-standard 32-bit system id flag
//! (0x02) is refused ([`FrameError::UnsupportedFlags`]).

use std::io::Write;

use mavlink::dialects::common::MavMessage;
use mavlink::error::MessageWriteError;
use mavlink::{MAV_STX, MAV_STX_V2, MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message};

use crate::{FrameError, LinkError};

const IFLAG_SIGNED: u8 = 0x01;
const SIGNATURE_LEN: usize = 13;
const V1_HEADER_LEN: usize = 6; // STX, len, seq, sys, comp, msgid
const V2_HEADER_LEN: usize = 10; // STX, len, incompat, compat, seq, sys, comp, msgid×3
const CRC_LEN: usize = 2;

/// Largest MAVLink frame in bytes (signed MAVLink 2, 255-byte payload).
pub const MAX_FRAME_LEN: usize = V2_HEADER_LEN + 255 + CRC_LEN + SIGNATURE_LEN;

/// One parsed frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Sender header (system id always ≤ 255).
    pub header: MavHeader,
    /// The decoded message.
    pub message: MavMessage,
    /// MAVLink 1 or 2.
    pub version: MavlinkVersion,
    /// Length of the frame in bytes (including any signature).
    pub len: usize,
    /// The frame's bytes when it carries a MAVLink 2 signature (for
    /// [`crate::Signing::verify`]); `None` for unsigned frames.
    pub signed: Option<SignedFrame>,
}

/// The bytes of a signed MAVLink 2 frame, kept for signature verification
/// (fixed buffer, no allocation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignedFrame(pub(crate) MAVLinkV2MessageRaw);

impl SignedFrame {
    /// The signature's link id.
    pub fn link_id(&self) -> u8 {
        self.0.signature_link_id()
    }

    /// The signature's 48-bit timestamp (10 µs units since 2015-01-01 UTC).
    pub fn timestamp(&self) -> u64 {
        self.0.signature_timestamp()
    }

    /// The frame's bytes, 0xFD marker through signature.
    pub fn as_bytes(&self) -> &[u8] {
        self.0.raw_bytes()
    }
}

/// A serialized MAVLink 2 frame, held in a fixed buffer (no allocation).
#[derive(Debug, Clone, Copy)]
pub struct EncodedFrame(MAVLinkV2MessageRaw);

impl EncodedFrame {
    /// The frame's bytes, from the 0xFD marker through the checksum.
    pub fn as_bytes(&self) -> &[u8] {
        self.0.raw_bytes()
    }

    /// Message id in the frame.
    pub fn message_id(&self) -> u32 {
        self.0.message_id()
    }

    /// Whether the frame carries a signature.
    pub fn is_signed(&self) -> bool {
        self.0.incompatibility_flags() & IFLAG_SIGNED != 0
    }

    /// The mavlink crate's raw frame (for its serial writer).
    pub fn raw(&self) -> &MAVLinkV2MessageRaw {
        &self.0
    }

    pub(crate) fn from_raw(raw: MAVLinkV2MessageRaw) -> Self {
        Self(raw)
    }
}

pub(crate) fn check_system_id(header: &MavHeader) -> Result<(), LinkError> {
    if header.system_id > u32::from(u8::MAX) {
        Err(LinkError::SystemIdOutOfRange(header.system_id))
    } else {
        Ok(())
    }
}

/// A sender header. `system_id` is `u32` in mavlink 0.21; taking `u8` here
/// keeps it within standard MAVLink 2.
pub fn header(system_id: u8, component_id: u8, sequence: u8) -> MavHeader {
    MavHeader {
        system_id: u32::from(system_id),
        component_id,
        sequence,
    }
}

/// Serializes `msg` as an unsigned MAVLink 2 frame (trailing zero payload
/// bytes truncated, as the protocol requires). Refuses system ids > 255.
pub fn serialize_v2(header: &MavHeader, msg: &MavMessage) -> Result<EncodedFrame, LinkError> {
    check_system_id(header)?;
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(*header, msg);
    Ok(EncodedFrame(raw))
}

/// Writes `msg` as an unsigned MAVLink 2 frame to `w` (via
/// `mavlink::write_v2_msg`); returns the bytes written.
pub fn write_v2<W: Write>(
    w: &mut W,
    header: &MavHeader,
    msg: &MavMessage,
) -> Result<usize, LinkError> {
    check_system_id(header)?;
    mavlink::write_v2_msg(w, *header, msg).map_err(|e| match e {
        MessageWriteError::Io(io) => LinkError::Io(io),
        other => LinkError::Io(std::io::Error::other(other.to_string())),
    })
}

/// Parses exactly one frame at the start of `bytes` (MAVLink 1 or 2); bytes
/// after it are ignored ([`Frame::len`] says how many were used).
pub fn parse_frame(bytes: &[u8]) -> Result<Frame, FrameError> {
    match bytes.first() {
        Some(&b) if b == MAV_STX_V2 || b == MAV_STX => {}
        _ => return Err(FrameError::NoMarker),
    }
    match examine(bytes) {
        Examined::Frame { result, .. } => result,
        Examined::Bad { error, .. } => Err(error),
        Examined::Incomplete { needed } => Err(FrameError::Truncated {
            available: bytes.len(),
            needed,
        }),
    }
}

/// Iterates over every frame and framing error in a complete buffer (one UDP
/// datagram, a whole file). Bytes ending inside a frame yield
/// [`FrameError::Truncated`]. Never panics.
pub fn frames(bytes: &[u8]) -> FrameIter<'_> {
    FrameIter {
        buf: bytes,
        cursor: Cursor::default(),
    }
}

/// Iterator returned by [`frames`].
#[derive(Debug, Clone)]
pub struct FrameIter<'a> {
    buf: &'a [u8],
    cursor: Cursor,
}

impl FrameIter<'_> {
    /// Bytes skipped so far while looking for a start marker.
    pub fn skipped_bytes(&self) -> u64 {
        self.cursor.skipped
    }
}

impl Iterator for FrameIter<'_> {
    type Item = Result<Frame, FrameError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.cursor.next(self.buf, true)
    }
}

/// Incremental parser for byte streams (serial, TCP) or datagrams.
///
/// [`push`](Self::push) bytes, then call [`next_frame`](Self::next_frame)
/// until it returns `None` (it waits for more bytes when a frame is
/// incomplete). The buffer only holds unconsumed bytes (at most one partial
/// frame plus the last push).
#[derive(Debug, Clone, Default)]
pub struct FrameParser {
    buf: Vec<u8>,
    cursor: Cursor,
}

impl FrameParser {
    /// An empty parser.
    pub fn new() -> Self {
        Self {
            buf: Vec::with_capacity(4 * MAX_FRAME_LEN),
            cursor: Cursor::default(),
        }
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.cursor.pos > 0 {
            self.buf.drain(..self.cursor.pos);
            self.cursor.suppress_until = self.cursor.suppress_until.saturating_sub(self.cursor.pos);
            self.cursor.pos = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// The next frame or framing error, or `None` when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        self.cursor.next(&self.buf, false)
    }

    /// End of stream: reports leftover bytes of an incomplete frame as
    /// [`FrameError::Truncated`] (and any frames behind it), then clears.
    pub fn finish(&mut self) -> Vec<Result<Frame, FrameError>> {
        let mut out = Vec::new();
        while let Some(item) = self.cursor.next(&self.buf, true) {
            out.push(item);
        }
        self.buf.clear();
        self.cursor = Cursor::default();
        out
    }

    /// Unconsumed bytes held (a partial frame).
    pub fn pending(&self) -> usize {
        self.buf.len() - self.cursor.pos
    }

    /// Bytes skipped so far while looking for a start marker.
    pub fn skipped_bytes(&self) -> u64 {
        self.cursor.skipped
    }
}

/// Scan position shared by [`FrameIter`] and [`FrameParser`].
#[derive(Debug, Clone, Copy, Default)]
struct Cursor {
    /// Next byte to examine.
    pos: usize,
    /// Bad candidates starting before this index are not reported again.
    suppress_until: usize,
    /// Bytes skipped looking for a marker.
    skipped: u64,
}

impl Cursor {
    /// Next event in `buf[pos..]`. With `complete`, no more bytes will come:
    /// an incomplete candidate is reported and scanning goes on behind it.
    fn next(&mut self, buf: &[u8], complete: bool) -> Option<Result<Frame, FrameError>> {
        loop {
            let rest = buf.get(self.pos..).unwrap_or(&[]);
            let Some(offset) = rest.iter().position(|&b| b == MAV_STX_V2 || b == MAV_STX) else {
                self.skipped += rest.len() as u64;
                self.pos = buf.len();
                return None;
            };
            self.skipped += offset as u64;
            self.pos += offset;
            let report = self.pos >= self.suppress_until;
            match examine(&buf[self.pos..]) {
                Examined::Frame { len, result } => {
                    self.pos += len;
                    return Some(result);
                }
                Examined::Bad { error, claimed_len } => {
                    self.suppress_until = self.suppress_until.max(self.pos + claimed_len);
                    self.pos += 1;
                    if report {
                        return Some(Err(error));
                    }
                }
                Examined::Incomplete { needed } => {
                    if !complete {
                        return None;
                    }
                    let available = buf.len() - self.pos;
                    self.suppress_until = buf.len();
                    self.pos += 1;
                    if report {
                        return Some(Err(FrameError::Truncated { available, needed }));
                    }
                }
            }
        }
    }
}

// Transient: built and matched immediately, so the size difference is harmless.
#[allow(clippy::large_enum_variant)]
enum Examined {
    /// CRC valid: consume `len` bytes.
    Frame {
        len: usize,
        result: Result<Frame, FrameError>,
    },
    /// Not a valid frame: skip one byte.
    Bad {
        error: FrameError,
        claimed_len: usize,
    },
    /// More bytes needed (at least `needed` from the marker).
    Incomplete { needed: usize },
}

/// Examines the candidate frame at `buf[0]`, which is a start marker.
fn examine(buf: &[u8]) -> Examined {
    let v2 = buf[0] == MAV_STX_V2;
    let header_len = if v2 { V2_HEADER_LEN } else { V1_HEADER_LEN };
    if buf.len() < 3 {
        return Examined::Incomplete {
            needed: header_len + CRC_LEN,
        };
    }
    let payload_len = usize::from(buf[1]);
    let signature_len = if v2 {
        let flags = buf[2];
        if flags & !IFLAG_SIGNED != 0 {
            return Examined::Bad {
                error: FrameError::UnsupportedFlags { flags },
                claimed_len: header_len + payload_len + CRC_LEN,
            };
        }
        if flags & IFLAG_SIGNED != 0 {
            SIGNATURE_LEN
        } else {
            0
        }
    } else {
        0
    };
    let total = header_len + payload_len + CRC_LEN + signature_len;
    if buf.len() < total {
        return Examined::Incomplete { needed: total };
    }
    let msg_id = if v2 {
        u32::from_le_bytes([buf[7], buf[8], buf[9], 0])
    } else {
        u32::from(buf[5])
    };
    let crc_at = header_len + payload_len;
    let expected = u16::from_le_bytes([buf[crc_at], buf[crc_at + 1]]);
    let actual = mavlink::calculate_crc(&buf[1..crc_at], MavMessage::extra_crc(msg_id));
    if actual != expected {
        let error = if MavMessage::default_message_from_id(msg_id).is_none() {
            FrameError::UnknownMessage { msg_id }
        } else {
            FrameError::Crc { msg_id }
        };
        return Examined::Bad {
            error,
            claimed_len: total,
        };
    }
    let (version, sender) = if v2 {
        (MavlinkVersion::V2, header(buf[5], buf[6], buf[4]))
    } else {
        (MavlinkVersion::V1, header(buf[3], buf[4], buf[2]))
    };
    let signed = (signature_len > 0).then(|| {
        let mut raw = MAVLinkV2MessageRaw::new();
        // `total` ≤ MAX_FRAME_LEN, the raw buffer's size.
        if let (Some(dst), Some(src)) = (raw.as_mut_slice().get_mut(..total), buf.get(..total)) {
            dst.copy_from_slice(src);
        }
        SignedFrame(raw)
    });
    let result = MavMessage::parse(version, msg_id, &buf[header_len..crc_at])
        .map(|message| Frame {
            header: sender,
            message,
            version,
            len: total,
            signed,
        })
        .map_err(|e| FrameError::from_parser_error(msg_id, &e));
    Examined::Frame { len: total, result }
}
