//! MAVLink 2 signing setup: the key file, the persisted timestamp.
//!
//! * Key file (`link.signing_key_file`): refused unless it is a regular file
//!   with mode 0600 owned by the user running the daemon. Contents: 64 hex
//!   digits, or 32 raw bytes, or a passphrase (key = SHA-256(passphrase),
//!   MAVProxy's `signing setup` convention) — see [`SigningKey::parse`].
//! * Timestamp file (`link.signing_timestamp_file`): the next outgoing
//!   signing timestamp as decimal text, written atomically (temporary file +
//!   rename) at start, at least every [`PERSIST_INTERVAL`] while sending,
//!   and at shutdown. On start the first timestamp is max(persisted + 1
//!   minute, wall clock) ([`restart_timestamp`]), so a computer without a
//!   real-time clock never reuses a timestamp (no replay window).

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use dflat_link::{Signing, SigningKey, restart_timestamp};
use thiserror::Error;

use crate::config::LinkConfig;

/// How often the send task persists the signing timestamp (the restart
/// margin is one minute).
pub const PERSIST_INTERVAL: Duration = Duration::from_secs(20);

/// The key file or the timestamp file is unusable.
#[derive(Debug, Error)]
pub enum SigningError {
    /// A file named by a `[link]` field is refused.
    #[error("field `{field}` = {path}: {reason}")]
    File {
        /// Dotted config field.
        field: &'static str,
        /// The file.
        path: PathBuf,
        /// Why, in words.
        reason: String,
    },
}

fn refuse(field: &'static str, path: &Path, reason: impl Into<String>) -> SigningError {
    SigningError::File {
        field,
        path: path.to_owned(),
        reason: reason.into(),
    }
}

const KEY_FIELD: &str = "link.signing_key_file";
const TS_FIELD: &str = "link.signing_timestamp_file";

/// Reads the key file named by `link.signing_key_file`, refusing it unless
/// it is a regular file with mode 0600 owned by the running user
/// ([`dflat_link::load_key_file`]).
pub fn load_key(path: &Path) -> Result<SigningKey, SigningError> {
    dflat_link::load_key_file(path).map_err(|e| refuse(KEY_FIELD, path, e.reason))
}

/// The persisted signing timestamp.
#[derive(Debug, Clone)]
pub struct TimestampStore {
    path: PathBuf,
}

impl TimestampStore {
    /// A store at `path`.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self { path: path.into() }
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The persisted timestamp; `None` if the file does not exist yet.
    /// A file that exists but does not hold a number is refused.
    pub fn load(&self) -> Result<Option<u64>, SigningError> {
        match std::fs::read(&self.path) {
            Ok(text) => dflat_link::parse_timestamp_file(&text)
                .map(Some)
                .ok_or_else(|| {
                    refuse(
                        TS_FIELD,
                        &self.path,
                        "does not hold a decimal timestamp (delete it only if the \
                     wall clock is known to be right)",
                    )
                }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(refuse(TS_FIELD, &self.path, e.to_string())),
        }
    }

    /// Writes `timestamp` atomically (temporary file, fsync, rename).
    pub fn store(&self, timestamp: u64) -> Result<(), SigningError> {
        let mut tmp = self.path.clone().into_os_string();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        let write = || -> std::io::Result<()> {
            let mut f = std::fs::File::create(&tmp)?;
            writeln!(f, "{timestamp}")?;
            f.sync_all()?;
            std::fs::rename(&tmp, &self.path)
        };
        write().map_err(|e| refuse(TS_FIELD, &self.path, e.to_string()))
    }
}

/// Signing from `[link]`: `None` when `signing_key_file` is empty. `now` is
/// the wall clock as a signing timestamp. Loads the key, restores the
/// timestamp (max(persisted + 1 minute, now)) and persists the start value.
pub fn setup(
    link: &LinkConfig,
    now: u64,
) -> Result<Option<(Signing, TimestampStore)>, SigningError> {
    if link.signing_key_file.trim().is_empty() {
        return Ok(None);
    }
    let key = load_key(Path::new(&link.signing_key_file))?;
    let store = TimestampStore::new(&link.signing_timestamp_file);
    let start = restart_timestamp(store.load()?, now);
    store.store(start)?;
    let mut signing = Signing::new(key, link.signing_link_id, start);
    // Validated with the config (names known, none that must be signed).
    signing.accept_unsigned = link
        .signing_accept_unsigned
        .iter()
        .filter_map(|n| dflat_link::unsigned_message_id(n).ok())
        .collect();
    Ok(Some((signing, store)))
}

#[cfg(test)]
mod tests {
    use std::os::unix::fs::PermissionsExt as _;

    use dflat_link::ONE_MINUTE;

    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("dflat-signing-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn key_file(dir: &Path, mode: u32) -> PathBuf {
        let path = dir.join("key");
        std::fs::write(&path, "correct horse battery staple\n").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        path
    }

    #[test]
    fn key_file_with_mode_0644_is_refused() {
        let dir = temp_dir("mode");
        let path = key_file(&dir, 0o644);
        let err = load_key(&path).unwrap_err().to_string();
        assert!(err.contains("link.signing_key_file"), "{err}");
        assert!(err.contains("0644"), "{err}");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(
            load_key(&path).unwrap(),
            SigningKey::from_passphrase("correct horse battery staple")
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn timestamp_is_persisted_and_restored_without_decrease() {
        let dir = temp_dir("ts");
        let key = key_file(&dir, 0o600);
        let link = LinkConfig {
            signing_key_file: key.display().to_string(),
            signing_timestamp_file: dir.join("ts").display().to_string(),
            ..LinkConfig::default()
        };
        // First start with a clock: starts at the wall clock, persisted.
        let now = 5_000_000_000;
        let (mut signing, store) = setup(&link, now).unwrap().unwrap();
        assert_eq!(store.load().unwrap(), Some(now));
        let hb = dflat_link::heartbeat_onboard(dflat_link::DaemonStatus::Boot);
        for _ in 0..10 {
            signing
                .sign(&dflat_link::header(1, 191, 0), &hb, now)
                .unwrap();
        }
        let used = signing.timestamp();
        store.store(used).unwrap();
        // Restart without a real-time clock (wall clock 0): never lower.
        let (restarted, _) = setup(&link, 0).unwrap().unwrap();
        assert_eq!(restarted.timestamp(), used + ONE_MINUTE);
        assert!(restarted.timestamp() > used);
        // Restart with a later clock: the clock wins.
        let (later, _) = setup(&link, used + 10 * ONE_MINUTE).unwrap().unwrap();
        assert_eq!(later.timestamp(), used + 10 * ONE_MINUTE);
        // A garbled file is refused, naming the field.
        std::fs::write(store.path(), "garbage").unwrap();
        let err = setup(&link, 0).unwrap_err().to_string();
        assert!(err.contains("link.signing_timestamp_file"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn signing_off_when_key_file_empty() {
        assert!(setup(&LinkConfig::default(), 0).unwrap().is_none());
    }
}
