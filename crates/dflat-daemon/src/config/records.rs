//! `[records]`: how the flight records (`logging.dir`) are written — sync
//! cadence and disk quotas.

use serde::{Deserialize, Serialize};

use super::ConfigError;

/// `[records]`: crash safety and disk quotas of the flight records.
///
/// Each CSV row and `.tlog` frame is written whole with one `write` call
/// and the files are `fdatasync`ed at least every `sync_ms`, so after a
/// crash (SIGKILL, power loss) the records hold the flight up to about
/// `sync_ms` before it. A flight writes at most `max_mb`; before a flight
/// starts, the oldest flights in `logging.dir` are deleted until the
/// directory plus this flight's `max_mb` fits in `keep_mb`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordsConfig {
    /// Longest time written records stay unsynced \[ms\] (100–10000).
    pub sync_ms: f64,
    /// Most one flight writes, CSV and `.tlog` together \[MiB\]
    /// (0 = unbounded; else 1–1000000). Past it, records are dropped and
    /// counted (said once).
    pub max_mb: f64,
    /// Most the flights in `logging.dir` may take together \[MiB\]
    /// (0 = unbounded; else at least `max_mb`, at most 10000000). The
    /// oldest flights (`flight-*` files, by name) are deleted first, at
    /// start; the summary lists them.
    pub keep_mb: f64,
}

impl Default for RecordsConfig {
    fn default() -> Self {
        Self {
            sync_ms: 1000.0,
            max_mb: 256.0,
            keep_mb: 2048.0,
        }
    }
}

/// Bytes in a MiB.
pub const MIB: f64 = 1024.0 * 1024.0;

impl RecordsConfig {
    /// The per-flight quota \[bytes\], `None` when unbounded.
    pub fn max_bytes(&self) -> Option<u64> {
        (self.max_mb > 0.0).then_some((self.max_mb * MIB) as u64)
    }

    /// The directory quota \[bytes\], `None` when unbounded.
    pub fn keep_bytes(&self) -> Option<u64> {
        (self.keep_mb > 0.0).then_some((self.keep_mb * MIB) as u64)
    }

    /// The sync cadence.
    pub fn sync_every(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.sync_ms / 1000.0)
    }

    /// Range checks; `err(field, value, allowed)` builds the error.
    pub(super) fn validate(
        &self,
        err: impl Fn(&str, f64, &str) -> ConfigError,
    ) -> Result<(), ConfigError> {
        let check = |field: &str, x: f64, lo: f64, hi: f64, zero_ok: bool| {
            let ok = x.is_finite() && ((zero_ok && x == 0.0) || (x >= lo && x <= hi));
            if ok {
                Ok(())
            } else {
                let allowed = if zero_ok {
                    format!("0 (unbounded) or {lo} to {hi}")
                } else {
                    format!("{lo} to {hi}")
                };
                Err(err(field, x, &allowed))
            }
        };
        check("records.sync_ms", self.sync_ms, 100.0, 10_000.0, false)?;
        check("records.max_mb", self.max_mb, 1.0, 1e6, true)?;
        check("records.keep_mb", self.keep_mb, 1.0, 1e7, true)?;
        if self.keep_mb > 0.0 && (self.max_mb == 0.0 || self.keep_mb < self.max_mb) {
            return Err(err(
                "records.keep_mb",
                self.keep_mb,
                "0 (unbounded), or at least records.max_mb (which must then be bounded)",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::config::Config;
    use std::path::Path;

    #[test]
    fn defaults_are_bounded_and_bad_values_are_refused_by_name() {
        let c = Config::default();
        assert_eq!(c.records.sync_ms, 1000.0);
        assert_eq!(c.records.max_bytes(), Some(256 * 1024 * 1024));
        assert_eq!(c.records.keep_bytes(), Some(2048 * 1024 * 1024));
        let f = Path::new("t.toml");
        for (text, field) in [
            ("[records]\nsync_ms = 50", "records.sync_ms"),
            ("[records]\nmax_mb = -1", "records.max_mb"),
            ("[records]\nkeep_mb = 100\nmax_mb = 200", "records.keep_mb"),
            ("[records]\nkeep_mb = 100\nmax_mb = 0", "records.keep_mb"),
        ] {
            let e = Config::parse(text, f).expect_err(text).to_string();
            assert!(e.contains(field), "{text}: {e}");
        }
        let ok = Config::parse("[records]\nmax_mb = 0\nkeep_mb = 0\nsync_ms = 200", f).unwrap();
        assert_eq!(ok.records.max_bytes(), None);
        assert_eq!(ok.records.keep_bytes(), None);
    }
}
