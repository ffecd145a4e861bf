//! Crash-safe flight records, shared by their writer threads (the
//! daemon's CSV, the `.tlog` tap).
//!
//! * [`RecordBudget`]: a byte quota per flight and the disk-trouble and
//!   quota notices the control loop says once. Lock-free: writers call
//!   [`RecordBudget::try_take`] before each whole row or frame (a record
//!   is written whole or not at all) and [`RecordBudget::note_failure`]
//!   when the disk refused a write; the daemon polls
//!   [`RecordBudget::take_notices`].
//! * [`RecordFile`]: one file written one whole record per `write` call,
//!   straight from the caller's buffer (no user-space buffer that a
//!   SIGKILL would lose), `fdatasync`ed at least every `sync_every`. The
//!   first write error (disk full, read-only, I/O) stops the file: what
//!   follows is dropped and counted, a torn piece of the failed record is
//!   cut off when the file system allows it.

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Notice bit: a record write failed (disk full, read-only, I/O error).
pub const NOTICE_DISK: u8 = 1;
/// Notice bit: the per-flight quota (`records.max_mb`) is used up.
pub const NOTICE_QUOTA: u8 = 2;

/// A per-flight byte quota and the notices of its writers.
#[derive(Debug)]
pub struct RecordBudget {
    limit: u64,
    used: AtomicU64,
    /// Notice bits raised by the writers.
    raised: AtomicU8,
    /// Notice bits already handed out by [`take_notices`](Self::take_notices).
    taken: AtomicU8,
}

impl RecordBudget {
    /// A budget of `limit` bytes (`None`: unbounded).
    pub fn new(limit: Option<u64>) -> Self {
        Self {
            limit: limit.unwrap_or(u64::MAX),
            used: AtomicU64::new(0),
            raised: AtomicU8::new(0),
            taken: AtomicU8::new(0),
        }
    }

    /// Reserves `n` bytes for one whole record. `false` (nothing reserved,
    /// the quota notice raised) when they would pass the limit.
    pub fn try_take(&self, n: u64) -> bool {
        let ok = self
            .used
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |used| {
                used.checked_add(n).filter(|total| *total <= self.limit)
            })
            .is_ok();
        if !ok {
            self.raised.fetch_or(NOTICE_QUOTA, Ordering::Relaxed);
        }
        ok
    }

    /// Gives back `n` reserved bytes that were not written.
    pub fn give_back(&self, n: u64) {
        let _ = self
            .used
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |used| {
                Some(used.saturating_sub(n))
            });
    }

    /// Bytes reserved so far.
    pub fn used(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }

    /// The limit \[bytes\] (`u64::MAX`: unbounded).
    pub fn limit(&self) -> u64 {
        self.limit
    }

    /// A writer hit disk trouble: raises the disk notice.
    pub fn note_failure(&self) {
        self.raised.fetch_or(NOTICE_DISK, Ordering::Relaxed);
    }

    /// Notice bits raised so far (taken or not).
    pub fn raised(&self) -> u8 {
        self.raised.load(Ordering::Relaxed)
    }

    /// The notice bits raised since the last call (each bit once per run).
    pub fn take_notices(&self) -> u8 {
        let raised = self.raised.load(Ordering::Relaxed);
        let before = self.taken.fetch_or(raised, Ordering::Relaxed);
        raised & !before
    }
}

/// Counters of a [`RecordFile`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct RecordFileStats {
    /// Whole records written.
    pub records: u64,
    /// Bytes written (whole records only).
    pub bytes: u64,
    /// Records dropped because the per-flight quota was used up.
    pub quota_dropped: u64,
    /// Records dropped after a write error stopped the file.
    pub error_dropped: u64,
    /// Write or sync errors (the first stops the file and is logged).
    pub write_errors: u64,
    /// `fdatasync` calls that succeeded.
    pub syncs: u64,
}

/// One record file: whole records, one `write` each, synced on a cadence.
#[derive(Debug)]
pub struct RecordFile {
    file: File,
    path: PathBuf,
    budget: Arc<RecordBudget>,
    sync_every: Duration,
    last_sync: Instant,
    dirty: bool,
    broken: bool,
    stats: RecordFileStats,
}

impl RecordFile {
    /// Wraps an open (empty) file; `sync_every` is the longest time data
    /// stays unsynced while records keep coming (call
    /// [`sync_if_due`](Self::sync_if_due) when idle).
    pub fn new(file: File, path: &Path, budget: Arc<RecordBudget>, sync_every: Duration) -> Self {
        Self {
            file,
            path: path.to_owned(),
            budget,
            sync_every,
            last_sync: Instant::now(),
            dirty: false,
            broken: false,
            stats: RecordFileStats::default(),
        }
    }

    /// Writes one whole record with one `write` call (unless the quota is
    /// used up or the file stopped: then it is dropped and counted).
    /// Returns whether it was written.
    pub fn write_record(&mut self, bytes: &[u8]) -> bool {
        if self.broken {
            self.stats.error_dropped += 1;
            return false;
        }
        let n = bytes.len() as u64;
        if !self.budget.try_take(n) {
            self.stats.quota_dropped += 1;
            return false;
        }
        match self.file.write_all(bytes) {
            Ok(()) => {
                self.stats.records += 1;
                self.stats.bytes += n;
                self.dirty = true;
                self.sync_if_due();
                true
            }
            Err(e) => {
                self.budget.give_back(n);
                self.stats.error_dropped += 1;
                self.fail("write", &e);
                // Cut a torn piece of this record off, if the disk lets us.
                let _ = self.file.set_len(self.stats.bytes);
                false
            }
        }
    }

    /// `fdatasync`s when data is unsynced and `sync_every` has passed.
    pub fn sync_if_due(&mut self) {
        if self.dirty && !self.broken && self.last_sync.elapsed() >= self.sync_every {
            self.sync();
        }
    }

    /// `fdatasync`s now if anything is unsynced (at the end of a flight).
    pub fn sync(&mut self) {
        if !self.dirty || self.broken {
            return;
        }
        self.last_sync = Instant::now();
        match self.file.sync_data() {
            Ok(()) => {
                self.dirty = false;
                self.stats.syncs += 1;
            }
            Err(e) => self.fail("sync", &e),
        }
    }

    fn fail(&mut self, op: &str, e: &io::Error) {
        self.stats.write_errors += 1;
        self.broken = true;
        // Said once per flight, whichever record file fails first.
        let first = self.budget.raised() & NOTICE_DISK == 0;
        self.budget.note_failure();
        if first {
            tracing::warn!(file = %self.path.display(), op, error = %e, "disk trouble: flying without records (drops are counted)");
        } else {
            tracing::debug!(file = %self.path.display(), op, error = %e, "record file stopped");
        }
    }

    /// True once a write error stopped the file.
    pub fn stopped(&self) -> bool {
        self.broken
    }

    /// The counters so far.
    pub fn stats(&self) -> RecordFileStats {
        self.stats
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_file_writes_whole_records_within_the_quota() {
        let dir = std::env::temp_dir().join(format!("dflat-recfile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("r.csv");
        let budget = Arc::new(RecordBudget::new(Some(25)));
        let mut f = RecordFile::new(
            File::create(&path).unwrap(),
            &path,
            budget.clone(),
            Duration::ZERO,
        );
        assert!(f.write_record(b"0123456789\n"));
        assert!(f.write_record(b"abcdefghij\n"));
        assert!(!f.write_record(b"ABCDEFGHIJ\n"), "over the quota");
        let s = f.stats();
        assert_eq!((s.records, s.bytes, s.quota_dropped), (2, 22, 1));
        assert!(s.syncs >= 1, "synced with a zero interval");
        assert_eq!(std::fs::read(&path).unwrap(), b"0123456789\nabcdefghij\n");
        assert_eq!(budget.take_notices(), NOTICE_QUOTA);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_full_disk_stops_the_file_and_raises_the_notice_once() {
        // /dev/full: every write fails with ENOSPC.
        let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
            return; // not on Linux
        };
        let budget = Arc::new(RecordBudget::new(None));
        let mut f = RecordFile::new(full, Path::new("/dev/full"), budget.clone(), Duration::ZERO);
        assert!(!f.write_record(b"row\n"));
        assert!(f.stopped());
        assert!(!f.write_record(b"row\n"));
        let s = f.stats();
        assert_eq!((s.records, s.write_errors, s.error_dropped), (0, 1, 2));
        assert_eq!(
            budget.used(),
            0,
            "nothing reserved for what was not written"
        );
        assert_eq!(budget.take_notices(), NOTICE_DISK);
        assert_eq!(budget.take_notices(), 0);
    }

    #[test]
    fn whole_records_only_and_each_notice_once() {
        let b = RecordBudget::new(Some(100));
        assert!(b.try_take(60));
        assert_eq!(b.take_notices(), 0);
        assert!(!b.try_take(41), "would pass the limit: refused whole");
        assert_eq!(b.used(), 60);
        assert!(b.try_take(40));
        assert_eq!(b.used(), 100);
        assert!(!b.try_take(1));
        assert_eq!(b.take_notices(), NOTICE_QUOTA);
        assert_eq!(b.take_notices(), 0, "said once");
        b.note_failure();
        b.note_failure();
        assert_eq!(b.take_notices(), NOTICE_DISK);
        assert_eq!(b.take_notices(), 0);
        assert_eq!(b.raised(), NOTICE_DISK | NOTICE_QUOTA);
        b.give_back(30);
        assert_eq!(b.used(), 70);
        let unbounded = RecordBudget::new(None);
        assert!(unbounded.try_take(u64::MAX / 2));
        assert!(unbounded.try_take(u64::MAX / 2));
    }
}
