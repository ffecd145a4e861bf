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
    /// Valid signature, but the timestamp is more than [`ONE_MINUTE`] ahead
    /// of the wall clock (only checked when the clock is known, `now` > 0).
    /// Accepting it would let one frame push its stream (and the replay
    /// window of every new stream) into the future.
    FutureTimestamp,
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
    /// Accept every unsigned message outside [`Signing::must_be_signed`]
    /// (the SITL autopilot's looseness towards its ground station; the
    /// daemon never sets it, it uses [`accept_unsigned`](Self::accept_unsigned)).
    pub accept_unsigned_telemetry: bool,
    /// Message ids accepted unsigned (the daemon's
    /// `link.signing_accept_unsigned`). Ids in [`Signing::must_be_signed`]
    /// are refused unsigned even when listed.
    pub accept_unsigned: Vec<u32>,
}

impl fmt::Debug for Signing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Signing")
            .field("key", &self.key)
            .field("link_id", &self.link_id)
            .field("next", &self.next)
            .field("streams", &self.streams.len())
            .field("accept_unsigned_telemetry", &self.accept_unsigned_telemetry)
            .field("accept_unsigned", &self.accept_unsigned)
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
            accept_unsigned: Vec::new(),
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
    /// everything that moves the vehicle or changes the daemon's view of
    /// the autopilot ([`MUST_BE_SIGNED`]).
    pub fn must_be_signed(msg: &MavMessage) -> bool {
        must_be_signed_id(mavlink::Message::message_id(msg))
    }

    /// Whether an unsigned `msg` is let through: not in
    /// [`must_be_signed`](Self::must_be_signed), and listed in
    /// [`accept_unsigned`](Self::accept_unsigned) (or
    /// [`accept_unsigned_telemetry`](Self::accept_unsigned_telemetry) set).
    pub fn accepts_unsigned(&self, msg: &MavMessage) -> bool {
        let id = mavlink::Message::message_id(msg);
        !must_be_signed_id(id)
            && (self.accept_unsigned_telemetry || self.accept_unsigned.contains(&id))
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
        if !constant_time_eq(&value, raw.signature_value()) {
            return SignatureCheck::BadSignature;
        }
        let timestamp = frame.timestamp();
        if now > 0 && timestamp > now.saturating_add(ONE_MINUTE) {
            return SignatureCheck::FutureTimestamp;
        }
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

/// Message ids that must carry a valid signature while signing is on,
/// whatever `accept_unsigned` says: they move the vehicle or change the
/// daemon's view of the autopilot. HEARTBEAT (0, mode and armed state),
/// PARAM_VALUE (22), ATTITUDE (30), LOCAL_POSITION_NED (32), the mission
/// protocol (37–47, 51, 73), COMMAND_INT / COMMAND_LONG (75, 76: mission
/// start, pause, speed), SET_ATTITUDE_TARGET (82),
/// SET_POSITION_TARGET_LOCAL_NED (84), VISION_POSITION_ESTIMATE (102),
/// SETUP_SIGNING (256), ODOMETRY (331).
pub const MUST_BE_SIGNED: &[u32] = &[
    0, 22, 30, 32, 37, 38, 39, 40, 41, 42, 43, 44, 45, 46, 47, 51, 73, 75, 76, 82, 84, 102, 256,
    331,
];

/// Whether message id `id` is in [`MUST_BE_SIGNED`].
pub fn must_be_signed_id(id: u32) -> bool {
    MUST_BE_SIGNED.contains(&id)
}

/// The message id of `name` (a common-dialect message name, e.g.
/// `"SYS_STATUS"`) for `link.signing_accept_unsigned`; an error in words if
/// the name is unknown or the message must be signed ([`MUST_BE_SIGNED`]).
pub fn unsigned_message_id(name: &str) -> Result<u32, &'static str> {
    use mavlink::Message as _;
    let id = MavMessage::message_id_from_name(name.trim())
        .ok_or("a message name of the common dialect (e.g. \"SYS_STATUS\")")?;
    if must_be_signed_id(id) {
        return Err(
            "a message that may go unsigned: setpoints, pose, HEARTBEAT, ATTITUDE, \
                    PARAM_VALUE, missions and commands must always be signed",
        );
    }
    Ok(id)
}

/// Compares two byte strings in time that depends on their lengths only
/// (not on where they first differ), so a forger cannot learn a signature
/// byte by byte from response timing.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let diff = a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y));
    std::hint::black_box(diff) == 0
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

/// Largest key file read \[bytes\]: a key is 32 bytes, 64 hex digits or a
/// passphrase; anything longer is refused, not read.
pub const KEY_FILE_MAX: u64 = 4096;

/// Reads a signing key file (64 hex digits, 32 raw bytes or a passphrase,
/// see [`SigningKey::parse`]), refusing it unless it is a regular file with
/// mode 0600 owned by the running user. Used by the daemon and the SITL.
///
/// The file is opened once, without following a symbolic link
/// (`O_NOFOLLOW`) and without blocking on a FIFO (`O_NONBLOCK`); the checks
/// are made with `fstat` on that open descriptor and the contents read from
/// it, so the file checked is the file read (no race with a rename).
pub fn load_key_file(path: &std::path::Path) -> Result<SigningKey, KeyFileError> {
    use std::io::Read as _;
    use std::os::unix::fs::{MetadataExt as _, OpenOptionsExt as _};
    let refuse = |reason: String| KeyFileError {
        path: path.to_owned(),
        reason,
    };
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(path)
        .map_err(|e| {
            if e.raw_os_error() == Some(libc::ELOOP) {
                refuse("is a symbolic link: name the key file itself".into())
            } else {
                refuse(e.to_string())
            }
        })?;
    let meta = file.metadata().map_err(|e| refuse(e.to_string()))?;
    check_key_metadata(
        meta.is_file(),
        meta.mode(),
        meta.uid(),
        meta.len(),
        effective_uid(),
    )
    .map_err(refuse)?;
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(KEY_FILE_MAX + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| refuse(e.to_string()))?;
    if bytes.len() as u64 > KEY_FILE_MAX {
        return Err(refuse(format!("longer than {KEY_FILE_MAX} bytes")));
    }
    SigningKey::parse(&bytes).map_err(|e| refuse(e.to_string()))
}

/// The checks [`load_key_file`] makes on the key file's `fstat`: a regular
/// file, mode exactly 0600, owned by `euid` (when known), at most
/// [`KEY_FILE_MAX`] bytes. Pure, for tests and fuzzing.
pub fn check_key_metadata(
    regular: bool,
    mode: u32,
    uid: u32,
    len: u64,
    euid: Option<u32>,
) -> Result<(), String> {
    if !regular {
        return Err("not a regular file".into());
    }
    let mode = mode & 0o7777;
    if mode != 0o600 {
        return Err(format!(
            "mode {mode:04o} refused: the key file must be mode 0600 (chmod 600)"
        ));
    }
    if let Some(euid) = euid
        && uid != euid
    {
        return Err(format!(
            "owned by uid {uid}, not by the running user (uid {euid})"
        ));
    }
    if len > KEY_FILE_MAX {
        return Err(format!("longer than {KEY_FILE_MAX} bytes"));
    }
    Ok(())
}

/// Parses a persisted signing timestamp file's contents: one decimal
/// number (surrounding whitespace ignored) no larger than [`TIMESTAMP_MAX`].
pub fn parse_timestamp_file(contents: &[u8]) -> Option<u64> {
    let text = std::str::from_utf8(contents).ok()?.trim();
    if text.is_empty() || text.len() > 20 || !text.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    text.parse::<u64>().ok().filter(|t| *t <= TIMESTAMP_MAX)
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
    fn key_file_is_read_through_one_descriptor_without_following_links() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = std::env::temp_dir().join(format!("dflat-keyfile-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let key = dir.join("key");
        std::fs::write(&key, "ab".repeat(32)).unwrap();
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(
            load_key_file(&key).unwrap(),
            SigningKey::from_bytes([0xab; 32])
        );
        // A symbolic link to a good key file is refused, naming why.
        let link = dir.join("link");
        std::os::unix::fs::symlink(&key, &link).unwrap();
        let e = load_key_file(&link).unwrap_err();
        assert!(e.reason.contains("symbolic link"), "{e}");
        // A directory, a too-long file, a group-readable file: refused.
        assert!(load_key_file(&dir).is_err());
        let long = dir.join("long");
        std::fs::write(&long, vec![b'a'; 5000]).unwrap();
        std::fs::set_permissions(&long, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert!(load_key_file(&long).unwrap_err().reason.contains("longer"));
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o640)).unwrap();
        assert!(load_key_file(&key).unwrap_err().reason.contains("0640"));
        let _ = std::fs::remove_dir_all(&dir);
        // The pure checks and the timestamp parser.
        assert!(check_key_metadata(true, 0o100600, 5, 64, Some(5)).is_ok());
        assert!(check_key_metadata(true, 0o100600, 5, 64, Some(6)).is_err());
        assert!(check_key_metadata(false, 0o600, 5, 64, Some(5)).is_err());
        assert_eq!(parse_timestamp_file(b" 123\n"), Some(123));
        assert_eq!(parse_timestamp_file(b"-1"), None);
        assert_eq!(parse_timestamp_file(b"281474976710656"), None);
        assert_eq!(parse_timestamp_file(b""), None);
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
