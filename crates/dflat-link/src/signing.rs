//! MAVLink 2 message signing (<https://mavlink.io/en/guide/message_signing.html>).
//!
//! A signed frame carries 13 more bytes: link id (1), a 48-bit timestamp in
//! 10 µs units since 2015-01-01 00:00 UTC (6), and the first 6 bytes of
//! SHA-256(secret key ‖ frame from 0xFD through CRC ‖ link id ‖ timestamp).
//! The digest is the mavlink crate's
//! [`MAVLinkV2MessageRaw::calculate_signature`]; the timestamp state lives
//! here because the daemon must seed it from a persisted value (the crate's
//! `SigningData` always starts from the wall clock).
//!
//! Pure: no clock, no files. Callers pass "now" as a signing timestamp
//! ([`timestamp_from_system_time`]) and persist [`Signing::timestamp`].

use std::collections::HashMap;
use std::fmt;
use std::time::{SystemTime, UNIX_EPOCH};

use mavlink::dialects::common::MavMessage;
use mavlink::{MAVLinkV2MessageRaw, MavHeader};
use sha2::{Digest, Sha256};
use thiserror::Error;

use crate::LinkError;
use crate::frame::{EncodedFrame, SignedFrame, check_system_id};

/// 2015-01-01 00:00:00 UTC as a UNIX time \[s\]: the signing epoch.
pub const SIGNING_EPOCH_UNIX_S: u64 = 1_420_070_400;
/// Signing timestamp units per second (one unit = 10 µs).
pub const TIMESTAMP_UNITS_PER_S: u64 = 100_000;
/// Largest 48-bit timestamp.
pub const TIMESTAMP_MAX: u64 = (1 << 48) - 1;
/// One minute in timestamp units: the restart margin, and how much older
/// than the newest known timestamp a new stream may start.
pub const ONE_MINUTE: u64 = 60 * TIMESTAMP_UNITS_PER_S;

/// A 32-byte MAVLink 2 secret key. Its `Debug` output is redacted.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; 32]);

impl fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("SigningKey(<redacted>)")
    }
}

/// Why a key file's contents are not a key.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum KeyFormatError {
    /// Nothing but whitespace.
    #[error("empty key (expected 32 raw bytes, 64 hex digits or a passphrase)")]
    Empty,
    /// A text key that is neither hex nor valid UTF-8.
    #[error("key is neither 32 raw bytes, 64 hex digits nor a UTF-8 passphrase")]
    NotText,
}

impl SigningKey {
    /// A key from its 32 bytes.
    pub fn from_bytes(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    /// MAVProxy's convention: key = SHA-256(passphrase) (`signing setup
    /// PASSPHRASE`; also QGroundControl's).
    pub fn from_passphrase(passphrase: &str) -> Self {
        Self(Sha256::digest(passphrase.as_bytes()).into())
    }

    /// Parses a key file's contents, in this order:
    /// 1. 64 hexadecimal digits (surrounding whitespace ignored): the key;
    /// 2. exactly 32 bytes, not all printable ASCII: the raw key;
    /// 3. otherwise UTF-8 text, trailing `\r`/`\n` removed: a passphrase,
    ///    key = SHA-256(passphrase) as MAVProxy's `signing setup` does.
    pub fn parse(contents: &[u8]) -> Result<Self, KeyFormatError> {
        let printable = |b: &u8| b.is_ascii_graphic() || *b == b' ';
        if contents.len() == 32 && !contents.iter().all(printable) {
            let mut key = [0u8; 32];
            key.copy_from_slice(contents);
            return Ok(Self(key));
        }
        let text = std::str::from_utf8(contents).map_err(|_| KeyFormatError::NotText)?;
        let trimmed = text.trim();
        if trimmed.is_empty() {
            return Err(KeyFormatError::Empty);
        }
        if trimmed.len() == 64 && trimmed.bytes().all(|b| b.is_ascii_hexdigit()) {
            let mut key = [0u8; 32];
            for (i, pair) in trimmed.as_bytes().chunks_exact(2).enumerate() {
                let hex = std::str::from_utf8(pair).map_err(|_| KeyFormatError::NotText)?;
                key[i] = u8::from_str_radix(hex, 16).map_err(|_| KeyFormatError::NotText)?;
            }
            return Ok(Self(key));
        }
        Ok(Self::from_passphrase(text.trim_end_matches(['\r', '\n'])))
    }
}

/// A signing timestamp from a wall-clock time (0 before 2015, e.g. a
/// computer without a real-time clock; saturates at 48 bits).
pub fn timestamp_from_system_time(t: SystemTime) -> u64 {
    let us = t
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_micros())
        .unwrap_or(0);
    let since = us.saturating_sub(u128::from(SIGNING_EPOCH_UNIX_S) * 1_000_000) / 10;
    u64::try_from(since).unwrap_or(u64::MAX).min(TIMESTAMP_MAX)
}

/// The first outgoing timestamp after a restart: max(persisted + 1 minute,
/// wall clock). Persisting at least once a minute thus guarantees that no
/// timestamp is reused even when the wall clock restarted at 1970.
pub fn restart_timestamp(persisted: Option<u64>, now: u64) -> u64 {
    persisted
        .map_or(0, |p| p.saturating_add(ONE_MINUTE))
        .max(now)
        .min(TIMESTAMP_MAX)
}

/// The outcome of [`Signing::verify`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SignatureCheck {
    /// Signed with our key, timestamp newer than the stream's last.
    Valid {
        /// The sender's link id.
        link_id: u8,
        /// The signature timestamp.
        timestamp: u64,
    },
    /// No signature (MAVLink 1, or MAVLink 2 without the signed flag).
    Unsigned,
    /// Signed, but not with our key (or altered).
    BadSignature,
    /// Valid signature, but the timestamp is not newer than the last one of
    /// its (link id, system, component) stream, or a new stream starts more
    /// than a minute behind the newest known timestamp.
    Replayed,
}

/// Signing state of one link: the key, our link id, the next outgoing
/// timestamp and, per incoming (link id, system, component) stream, the last
/// accepted timestamp.
#[derive(Clone)]
pub struct Signing {
    key: SigningKey,
    link_id: u8,
    /// Next outgoing timestamp (strictly above every one used).
    next: u64,
    /// Newest timestamp known (ours, incoming, wall clock).
    newest: u64,
    streams: HashMap<(u8, u8, u8), u64>,
    /// Accept unsigned messages other than commands (setpoints, attitude
    /// targets) — see [`Signing::is_command`].
    pub accept_unsigned_telemetry: bool,
}

impl fmt::Debug for Signing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Signing")
            .field("key", &self.key)
            .field("link_id", &self.link_id)
            .field("next", &self.next)
            .field("streams", &self.streams.len())
            .field("accept_unsigned_telemetry", &self.accept_unsigned_telemetry)
            .finish()
    }
}

impl Signing {
    /// Signing with `key` as `link_id`; the first outgoing timestamp is at
    /// least `start` (use [`restart_timestamp`]). Unsigned telemetry is
    /// refused until [`accept_unsigned_telemetry`](Self::accept_unsigned_telemetry)
    /// is set.
    pub fn new(key: SigningKey, link_id: u8, start: u64) -> Self {
        let start = start.min(TIMESTAMP_MAX);
        Self {
            key,
            link_id,
            next: start,
            newest: start,
            streams: HashMap::new(),
            accept_unsigned_telemetry: false,
        }
    }

    /// Our link id.
    pub fn link_id(&self) -> u8 {
        self.link_id
    }

    /// The next outgoing timestamp: greater than every timestamp signed so
    /// far. This is the value to persist.
    pub fn timestamp(&self) -> u64 {
        self.next
    }

    /// Messages that always need a valid signature while signing is on:
    /// SET_POSITION_TARGET_LOCAL_NED and SET_ATTITUDE_TARGET.
    pub fn is_command(msg: &MavMessage) -> bool {
        matches!(
            msg,
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(_) | MavMessage::SET_ATTITUDE_TARGET(_)
        )
    }

    /// Serializes and signs `msg`. The timestamp is max(next, `now`), then
    /// advances by one. Refuses system ids > 255.
    pub fn sign(
        &mut self,
        header: &MavHeader,
        msg: &MavMessage,
        now: u64,
    ) -> Result<EncodedFrame, LinkError> {
        check_system_id(header)?;
        let timestamp = self.next.max(now.min(TIMESTAMP_MAX));
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message_for_signing(*header, msg);
        *raw.signature_link_id_mut() = self.link_id;
        raw.signature_timestamp_bytes_mut()
            .copy_from_slice(&timestamp.to_le_bytes()[..6]);
        let mut value = [0u8; 6];
        raw.calculate_signature(&self.key.0, &mut value);
        raw.signature_value_mut().copy_from_slice(&value);
        self.next = timestamp.saturating_add(1).min(TIMESTAMP_MAX);
        self.newest = self.newest.max(timestamp);
        Ok(EncodedFrame::from_raw(raw))
    }

    /// Verifies a received frame's signature (`signed` = [`crate::Frame::signed`]).
    /// `now` is the wall clock as a signing timestamp (0 without a clock).
    /// A valid frame advances its stream's timestamp.
    pub fn verify(
        &mut self,
        header: &MavHeader,
        signed: Option<&SignedFrame>,
        now: u64,
    ) -> SignatureCheck {
        let Some(frame) = signed else {
            return SignatureCheck::Unsigned;
        };
        self.newest = self.newest.max(now.min(TIMESTAMP_MAX));
        let raw = &frame.0;
        let mut value = [0u8; 6];
        raw.calculate_signature(&self.key.0, &mut value);
        if value != raw.signature_value() {
            return SignatureCheck::BadSignature;
        }
        let timestamp = frame.timestamp();
        let link_id = frame.link_id();
        let system = u8::try_from(header.system_id).unwrap_or(u8::MAX);
        let stream = (link_id, system, header.component_id);
        let fresh = match self.streams.get(&stream) {
            Some(&last) => timestamp > last,
            None => timestamp.saturating_add(ONE_MINUTE) >= self.newest,
        };
        if !fresh {
            return SignatureCheck::Replayed;
        }
        self.streams.insert(stream, timestamp);
        self.newest = self.newest.max(timestamp);
        SignatureCheck::Valid { link_id, timestamp }
    }
}

/// A signing key file that is refused, with the reason in words.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{path}: {reason}")]
pub struct KeyFileError {
    /// The file.
    pub path: std::path::PathBuf,
    /// Why it is refused.
    pub reason: String,
}

/// The effective user id of this process (from `/proc/self/status`;
/// `None` where unavailable).
fn effective_uid() -> Option<u32> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("Uid:"))?;
    line.split_whitespace().nth(2)?.parse().ok()
}

/// Reads a signing key file (64 hex digits, 32 raw bytes or a passphrase,
/// see [`SigningKey::parse`]), refusing it unless it is a regular file with
/// mode 0600 owned by the running user. Used by the daemon and the SITL.
pub fn load_key_file(path: &std::path::Path) -> Result<SigningKey, KeyFileError> {
    use std::os::unix::fs::MetadataExt as _;
    let refuse = |reason: String| KeyFileError {
        path: path.to_owned(),
        reason,
    };
    let meta = std::fs::metadata(path).map_err(|e| refuse(e.to_string()))?;
    if !meta.is_file() {
        return Err(refuse("not a regular file".into()));
    }
    let mode = meta.mode() & 0o7777;
    if mode != 0o600 {
        return Err(refuse(format!(
            "mode {mode:04o} refused: the key file must be mode 0600 (chmod 600)"
        )));
    }
    if let Some(uid) = effective_uid()
        && meta.uid() != uid
    {
        return Err(refuse(format!(
            "owned by uid {}, not by the running user (uid {uid})",
            meta.uid()
        )));
    }
    let bytes = std::fs::read(path).map_err(|e| refuse(e.to_string()))?;
    SigningKey::parse(&bytes).map_err(|e| refuse(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_formats() {
        let hex = "00".repeat(31) + "ff";
        assert_eq!(
            SigningKey::parse(format!("{hex}\n").as_bytes()),
            Ok(SigningKey::from_bytes({
                let mut k = [0u8; 32];
                k[31] = 0xff;
                k
            }))
        );
        let raw = [7u8; 32];
        assert_eq!(SigningKey::parse(&raw), Ok(SigningKey::from_bytes(raw)));
        assert_eq!(
            SigningKey::parse(b"secret words\n"),
            Ok(SigningKey::from_passphrase("secret words"))
        );
        assert_eq!(SigningKey::parse(b" \n"), Err(KeyFormatError::Empty));
        assert_eq!(
            SigningKey::parse(&[0xff, 0xfe]),
            Err(KeyFormatError::NotText)
        );
        assert_eq!(
            format!("{:?}", SigningKey::from_bytes(raw)),
            "SigningKey(<redacted>)"
        );
    }

    #[test]
    fn passphrase_is_sha256() {
        // SHA-256("abc")
        let k = SigningKey::from_passphrase("abc");
        assert_eq!(k.0[..4], [0xba, 0x78, 0x16, 0xbf]);
    }

    #[test]
    fn timestamps() {
        let t = UNIX_EPOCH + std::time::Duration::from_secs(SIGNING_EPOCH_UNIX_S + 2);
        assert_eq!(timestamp_from_system_time(t), 200_000);
        assert_eq!(timestamp_from_system_time(UNIX_EPOCH), 0);
        assert_eq!(restart_timestamp(None, 5), 5);
        assert_eq!(restart_timestamp(Some(10), 5), 10 + ONE_MINUTE);
        assert_eq!(
            restart_timestamp(Some(10), 10 + 2 * ONE_MINUTE),
            10 + 2 * ONE_MINUTE
        );
    }
}
