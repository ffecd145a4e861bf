//! Where the flight records go, and what happens when the disk says no.
//!
//! [`open`] prepares one flight's records: it creates `logging.dir` and
//! the CSV and the `.tlog` tap with the flight's [`RecordBudget`]
//! (`records.max_mb`) and sync cadence (`records.sync_ms`). Once the
//! daemon's link is open, [`OpenRecords::prune`] deletes the oldest flights
//! until the directory plus this flight's quota fits `records.keep_mb`
//! ([`plan_pruning`], pure); a start whose link does not open deletes the
//! files it created instead ([`OpenRecords::discard`]), so a failed start
//! leaves the directory as it found it (but for `logging.dir` itself).
//!
//! **Disk trouble never grounds the vehicle.** A directory that cannot be
//! created or written (read-only, no permission, full) does not stop the
//! daemon: it flies without the records it could not open, says so once in
//! the log and — through the budget's disk notice, which the control loop
//! turns into one STATUSTEXT ([`notice_texts`]) — to the ground station, and
//! the summary counts what was dropped ([`RecordsSummary`]). The same
//! notice covers a disk that fills up or turns read-only during the flight
//! (the writers stop at their first error).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::SystemTime;

use dflat_link::dialect::MavSeverity;
use dflat_link::records::{NOTICE_DISK, NOTICE_QUOTA, RecordBudget};
use dflat_link::transport::{TapOptions, TlogTap, TransportError};
use serde::Serialize;
use tracing::{info, warn};

use crate::config::Config;
use crate::records::{CsvRecorder, flight_stem};

/// What happened to the records directory and quotas over a flight.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct RecordsSummary {
    /// The records directory (`None`: `logging.dir = ""`).
    pub dir: Option<PathBuf>,
    /// Why records were not opened at start, if they were not (disk
    /// trouble: the daemon flew without them).
    pub off_at_start: Option<String>,
    /// Flights deleted at start to fit `records.keep_mb` (oldest first).
    pub deleted: Vec<String>,
    /// Bytes those flights took.
    pub deleted_bytes: u64,
    /// The per-flight quota \[bytes\] (`None`: unbounded).
    pub max_bytes: Option<u64>,
    /// Bytes written this flight (CSV and `.tlog`).
    pub written_bytes: u64,
    /// The per-flight quota was used up (records dropped after it).
    pub quota_reached: bool,
    /// A write failed (disk full, read-only, I/O): the failing record
    /// stopped, the flight went on.
    pub disk_trouble: bool,
}

/// One flight's records as opened.
#[derive(Debug)]
pub struct OpenRecords {
    /// The CSV writer, if opened.
    pub csv: Option<CsvRecorder>,
    /// The `.tlog` tap, if opened.
    pub tap: Option<TlogTap>,
    /// The flight's byte budget and notices (shared by both writers).
    pub budget: Arc<RecordBudget>,
    /// What [`open`] did (completed by [`finish_summary`]).
    pub summary: RecordsSummary,
    /// This flight's stem (`flight-…`) and the files [`open`] created.
    stem: Option<String>,
    files: Vec<PathBuf>,
}

impl OpenRecords {
    /// Deletes the oldest flights of the records directory until what
    /// stays plus this flight's quota fits `records.keep_mb` (never this
    /// flight), into the summary (`deleted`, `deleted_bytes`). Called once
    /// the daemon is sure to fly: its link is open.
    pub fn prune(&mut self, config: &Config) {
        let r = &config.records;
        // No stem: no directory (`logging.dir` empty, or it could not be made).
        let (Some(keep), Some(dir), Some(stem)) = (
            r.keep_bytes(),
            self.summary.dir.clone(),
            self.stem.as_deref(),
        ) else {
            return;
        };
        match prune(&dir, keep, r.max_bytes().unwrap_or(0), stem) {
            Ok((deleted, freed)) => {
                self.summary.deleted = deleted;
                self.summary.deleted_bytes = freed;
            }
            Err(e) => warn!(dir = %dir.display(), error = %e, "records.keep_mb: cannot prune"),
        }
    }

    /// Stops the writers and deletes the files [`open`] created: the start
    /// failed after them (the link would not open), and a failed start
    /// leaves no empty flight behind.
    pub fn discard(self) {
        if let Some(csv) = self.csv {
            drop(csv.finish());
        }
        if let Some(tap) = self.tap {
            drop(tap.close_blocking());
        }
        for f in &self.files {
            if let Err(e) = std::fs::remove_file(f) {
                warn!(file = %f.display(), error = %e, "cannot delete the records of a failed start");
            }
        }
    }
}

/// One flight in the records directory: its stem (`flight-…`) and the
/// bytes of all its files.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoredFlight {
    /// The file name up to its first `.` (`flight-20261102-134501`).
    pub stem: String,
    /// Total size of its files \[bytes\].
    pub bytes: u64,
}

/// Which flights to delete, oldest first, so that what stays plus
/// `reserve` (the new flight's quota) fits `keep` \[bytes\]. `flights`
/// sorted oldest first. Returns indices into `flights`.
pub fn plan_pruning(flights: &[StoredFlight], keep: u64, reserve: u64) -> Vec<usize> {
    let mut total: u64 = flights.iter().map(|f| f.bytes).sum();
    let mut out = Vec::new();
    for (i, f) in flights.iter().enumerate() {
        if total.saturating_add(reserve) <= keep {
            break;
        }
        total -= f.bytes;
        out.push(i);
    }
    out
}

/// The flights in `dir` (files named `flight-…`), oldest first (by name:
/// the names carry the UTC start time).
pub fn stored_flights(dir: &Path) -> std::io::Result<Vec<StoredFlight>> {
    let mut by_stem: std::collections::BTreeMap<String, u64> = Default::default();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        if !name.starts_with("flight-") {
            continue;
        }
        let Ok(meta) = entry.metadata() else { continue };
        if !meta.is_file() {
            continue;
        }
        let stem = name.split('.').next().unwrap_or(name).to_owned();
        *by_stem.entry(stem).or_default() += meta.len();
    }
    Ok(by_stem
        .into_iter()
        .map(|(stem, bytes)| StoredFlight { stem, bytes })
        .collect())
}

/// Deletes every `flight-…` file of the flights `plan_pruning` picks,
/// never those of the flight `current`. Returns the stems deleted and the
/// bytes freed.
fn prune(
    dir: &Path,
    keep: u64,
    reserve: u64,
    current: &str,
) -> std::io::Result<(Vec<String>, u64)> {
    let mut flights = stored_flights(dir)?;
    flights.retain(|f| f.stem != current);
    let victims = plan_pruning(&flights, keep, reserve);
    let mut deleted = Vec::new();
    let mut freed = 0;
    for i in victims {
        let f = &flights[i];
        let prefix = format!("{}.", f.stem);
        for entry in std::fs::read_dir(dir)?.flatten() {
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            if name.starts_with(&prefix) || name == f.stem {
                std::fs::remove_file(entry.path())?;
            }
        }
        info!(flight = %f.stem, bytes = f.bytes, "records.keep_mb: oldest flight deleted");
        deleted.push(f.stem.clone());
        freed += f.bytes;
    }
    Ok((deleted, freed))
}

/// Opens one flight's records (see the module docs). Never fails: what
/// cannot be opened is left off, logged once and noticed.
pub fn open(config: &Config, started: SystemTime) -> OpenRecords {
    let r = &config.records;
    let budget = Arc::new(RecordBudget::new(r.max_bytes()));
    let mut summary = RecordsSummary {
        max_bytes: r.max_bytes(),
        ..RecordsSummary::default()
    };
    let mut out = OpenRecords {
        csv: None,
        tap: None,
        budget: budget.clone(),
        summary: RecordsSummary::default(),
        stem: None,
        files: Vec::new(),
    };
    if config.logging.dir.trim().is_empty() {
        out.summary = summary;
        return out;
    }
    let dir = PathBuf::from(&config.logging.dir);
    summary.dir = Some(dir.clone());
    let off = |summary: &mut RecordsSummary, what: String| {
        warn!(reason = %what, "flying without records");
        summary.off_at_start = Some(what);
        budget.note_failure();
    };
    if let Err(e) = std::fs::create_dir_all(&dir) {
        off(&mut summary, format!("{}: {e}", dir.display()));
        out.summary = summary;
        return out;
    }
    let stem = flight_stem(&dir, started);
    out.stem = stem.file_name().and_then(|n| n.to_str()).map(str::to_owned);
    let mut failures = Vec::new();
    if config.logging.csv {
        let path = stem.with_extension("csv");
        match CsvRecorder::create_with(&path, budget.clone(), r.sync_every()) {
            Ok(c) => {
                out.csv = Some(c);
                out.files.push(path);
            }
            Err(e) => failures.push(format!("{}: {e}", path.display())),
        }
    }
    if config.logging.tlog {
        let path = stem.with_extension("tlog");
        let options = TapOptions {
            budget: budget.clone(),
            sync_every: r.sync_every(),
            // Inbound frames are recorded by the receive task once they
            // passed the filter and authentication.
            inbound: false,
        };
        match TlogTap::create_with(&path, options) {
            Ok(t) => {
                out.tap = Some(t);
                out.files.push(path);
            }
            Err(TransportError::Io { source, .. }) => {
                failures.push(format!("{}: {source}", path.display()));
            }
            Err(e) => failures.push(format!("{}: {e}", path.display())),
        }
    }
    if !failures.is_empty() {
        off(&mut summary, failures.join("; "));
    }
    out.summary = summary;
    out
}

/// Completes the summary at the end of the flight from the budget.
pub fn finish_summary(mut summary: RecordsSummary, budget: &RecordBudget) -> RecordsSummary {
    summary.written_bytes = budget.used();
    let raised = budget.raised();
    summary.quota_reached = raised & NOTICE_QUOTA != 0;
    summary.disk_trouble = raised & NOTICE_DISK != 0;
    summary
}

/// The log lines and STATUSTEXTs (≤ 50 bytes) of the notice bits `bits`
/// newly raised ([`RecordBudget::take_notices`]).
pub fn notice_texts(bits: u8) -> Vec<(MavSeverity, &'static str)> {
    let mut out = Vec::new();
    if bits & NOTICE_DISK != 0 {
        // Logged where it happened (the writer or `open`).
        out.push((
            MavSeverity::MAV_SEVERITY_WARNING,
            "dflat: disk trouble, flying without records",
        ));
    }
    if bits & NOTICE_QUOTA != 0 {
        warn!("records.max_mb reached: flying without further records");
        out.push((
            MavSeverity::MAV_SEVERITY_WARNING,
            "dflat: records quota reached, not recording",
        ));
    }
    out
}

/// The summary's records lines (after the CSV and `.tlog` lines): what
/// `r` says, with the writers' reports `csv` and `tlog`.
pub fn write_summary(
    f: &mut std::fmt::Formatter<'_>,
    r: &RecordsSummary,
    csv: Option<&crate::records::CsvReport>,
    tlog: Option<&dflat_link::transport::TlogReport>,
) -> std::fmt::Result {
    if r.dir.is_none() {
        return Ok(());
    }
    let mib = |b: u64| b as f64 / crate::config::MIB;
    if let Some(why) = &r.off_at_start {
        write!(
            f,
            "\n  records       OFF at start, flew without them: {why}"
        )?;
    }
    let quota = r
        .max_bytes
        .map_or("unbounded".to_owned(), |m| format!("{:.1} MiB", mib(m)));
    write!(
        f,
        "\n  records       {:.2} MiB written (quota {quota})",
        mib(r.written_bytes)
    )?;
    if r.quota_reached {
        write!(
            f,
            "\n  records       quota reached: {} rows, {} frames not recorded",
            csv.map_or(0, |c| c.quota_dropped),
            tlog.map_or(0, |t| t.quota_dropped)
        )?;
    }
    if r.disk_trouble {
        write!(
            f,
            "\n  records       disk trouble ({} write errors): {} rows, {} frames dropped",
            csv.map_or(0, |c| c.write_errors) + tlog.map_or(0, |t| t.write_errors),
            csv.map_or(0, |c| c.error_dropped),
            tlog.map_or(0, |t| t.error_dropped)
        )?;
    }
    if !r.deleted.is_empty() {
        write!(
            f,
            "\n  records       deleted {} oldest flights ({:.1} MiB) for records.keep_mb: {}",
            r.deleted.len(),
            mib(r.deleted_bytes),
            r.deleted.join(", ")
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(stem: &str, bytes: u64) -> StoredFlight {
        StoredFlight {
            stem: stem.into(),
            bytes,
        }
    }

    #[test]
    fn pruning_deletes_the_oldest_until_the_new_flight_fits() {
        let flights = [f("a", 40), f("b", 30), f("c", 20)];
        assert!(plan_pruning(&flights, 200, 100).is_empty(), "90 + 100 fits");
        assert_eq!(plan_pruning(&flights, 150, 100), vec![0], "50 + 100 fits");
        assert_eq!(plan_pruning(&flights, 130, 100), vec![0, 1]);
        assert_eq!(plan_pruning(&flights, 100, 100), vec![0, 1, 2]);
        assert_eq!(
            plan_pruning(&flights, 50, 100),
            vec![0, 1, 2],
            "never more than all"
        );
        assert!(plan_pruning(&[], 10, 100).is_empty());
    }

    #[test]
    fn the_directory_is_pruned_by_flight_and_the_new_flight_opens() {
        let dir = std::env::temp_dir().join(format!("dflat-prune-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mib = 1024 * 1024;
        for (stem, n) in [
            ("flight-20260101-000000", 3 * mib),
            ("flight-20260102-000000", 3 * mib),
            ("flight-20260103-000000", mib),
        ] {
            std::fs::write(dir.join(format!("{stem}.csv")), vec![b'x'; n / 2]).unwrap();
            std::fs::write(dir.join(format!("{stem}.tlog")), vec![b'x'; n / 2]).unwrap();
        }
        std::fs::write(dir.join("notes.txt"), b"not a flight").unwrap();
        let mut cfg = Config::default();
        cfg.logging.dir = dir.display().to_string();
        cfg.records.max_mb = 2.0;
        cfg.records.keep_mb = 5.0;
        let mut rec = open(&cfg, SystemTime::now());
        // Opening prunes nothing; the daemon prunes once its link is open.
        assert!(rec.summary.deleted.is_empty());
        assert!(dir.join("flight-20260101-000000.csv").exists());
        rec.prune(&cfg);
        // 7 MiB stored + 2 reserved > 5: the two oldest go (1 + 2 ≤ 5),
        // never the flight just opened.
        assert_eq!(
            rec.summary.deleted,
            vec!["flight-20260101-000000", "flight-20260102-000000"]
        );
        assert_eq!(rec.summary.deleted_bytes, 6 * mib as u64);
        assert!(dir.join("flight-20260103-000000.csv").exists());
        assert!(dir.join("notes.txt").exists());
        assert!(rec.csv.is_some() && rec.tap.is_some());
        assert!(rec.summary.off_at_start.is_none());
        assert_eq!(rec.budget.take_notices(), 0);
        drop(rec.csv.map(CsvRecorder::finish));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn an_unusable_directory_leaves_the_records_off_and_raises_the_notice() {
        let mut cfg = Config::default();
        // A directory below a regular file cannot be created, even by root.
        let file = std::env::temp_dir().join(format!("dflat-notadir-{}", std::process::id()));
        std::fs::write(&file, b"x").unwrap();
        cfg.logging.dir = file.join("flights").display().to_string();
        let rec = open(&cfg, SystemTime::now());
        assert!(rec.csv.is_none() && rec.tap.is_none());
        assert!(rec.summary.off_at_start.is_some());
        assert_eq!(rec.budget.take_notices(), NOTICE_DISK);
        let s = finish_summary(rec.summary, &rec.budget);
        assert!(s.disk_trouble);
        assert_eq!(notice_texts(NOTICE_DISK).len(), 1);
        assert!(notice_texts(NOTICE_DISK)[0].1.len() <= 50);
        assert!(notice_texts(NOTICE_QUOTA)[0].1.len() <= 50);
        let _ = std::fs::remove_file(&file);
    }
}
