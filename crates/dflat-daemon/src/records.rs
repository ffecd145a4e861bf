//! Per-flight records: file names, the CSV row format and its writer thread.
//!
//! The control loop hands each tick's [`CsvRow`] (a small `Copy` value) to
//! [`CsvRecorder::record`], which never blocks and never allocates; a
//! dedicated thread formats each row into a buffer and writes it whole with
//! one `write` call ([`RecordFile`]): a SIGKILL loses at most the rows still
//! queued (milliseconds), never a user-space buffer, and never leaves a
//! torn row from our side. The file is `fdatasync`ed at least every
//! `records.sync_ms`. A full queue drops the row and counts it; the
//! per-flight quota and a disk error (full, read-only) stop the rows and
//! count them. [`CsvRecorder::finish`] writes everything queued and syncs.

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use dflat_link::records::{RecordBudget, RecordFile};

use serde::Serialize;

use dflat_control::disturbance::EstimatorStatus;

pub use crate::csv_schema::{CSV_HEADER, Column};
use crate::supervisor::FlightState;

/// Queue length between the control loop and the CSV thread \[rows\]
/// (80 s at 50 Hz).
const CSV_QUEUE: usize = 4096;

pub use dflat_records::names::{flight_stem, utc_stamp};

/// One control tick as recorded. Positions local NED \[m\], angles ZYX \[rad\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsvRow {
    /// Tick index k (deadline start + k·δt).
    pub tick: u64,
    /// Tick deadline since the daemon started \[s\].
    pub t: f64,
    /// State at the end of the tick.
    pub state: FlightState,
    /// Newest measured position used, if any.
    pub measured: Option<[f64; 3]>,
    /// Planned outputs y*_k … y*_{k+3}, if the controller ran.
    pub plan: Option<[[f64; 3]; 4]>,
    /// Reference y_ref,k, if the controller ran.
    pub reference: Option<[f64; 3]>,
    /// Command sent: roll, pitch, yaw \[rad\], normalised thrust \[0, 1\].
    pub command: Option<[f64; 4]>,
    /// Controller update time \[µs\], if it ran.
    pub solve_us: Option<u32>,
    /// Wake time − deadline \[µs\].
    pub jitter_us: u32,
    /// The disturbance estimate after the tick, if the controller runs an
    /// estimator and ran.
    pub disturbance: Option<CsvDisturbance>,
    /// Model-consistency residual \[m\]: measured position minus the
    /// position the previous tick's plan predicted for this one (y*_{k+1}).
    pub residual: Option<f64>,
    /// What the guards did this tick (`plan`, `held`, `level`, `jump`, `residual`),
    /// if anything.
    pub guard: Option<&'static str>,
    /// Age of the newest pose at the tick \[ms\]: tick time minus its
    /// capture time (empty before the first pose). Last column.
    pub pose_age_ms: Option<f64>,
    /// The tick's time \[s\] since the daemon started, exactly as the
    /// controller used it (wake time, shortest round-trip decimal), for an
    /// offline re-run (`dflat replay`). Last column.
    pub wake: f64,
    /// Link events the tick had applied so far, mission commands excluded
    /// (its cutoff in the flight's events: `dflat replay` batches the
    /// tlog's frames by it).
    pub events: u64,
}

/// The disturbance estimate as recorded per tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsvDisturbance {
    /// Acceleration offset d̂ (x, y, z) \[m/s²\], local NED.
    pub acceleration: [f64; 3],
    /// Thrust scale κ̂ \[-\] (actual / model thrust).
    pub thrust_scale: f64,
    /// Hover thrust normalised as sent to the autopilot \[0, 1\] (empty
    /// when it cannot be mapped).
    pub hover_thrust: Option<f64>,
    /// Estimator status (`settling`, `filling`, `tracking`, `frozen`).
    pub status: EstimatorStatus,
}

/// The estimator status as written to the CSV.
fn status_name(s: EstimatorStatus) -> &'static str {
    match s {
        EstimatorStatus::Settling => "settling",
        EstimatorStatus::Filling => "filling",
        EstimatorStatus::Tracking => "tracking",
        EstimatorStatus::Frozen => "frozen",
    }
}

fn opt3<W: Write>(w: &mut W, v: Option<[f64; 3]>, precision: usize) -> io::Result<()> {
    match v {
        Some([a, b, c]) => write!(w, ",{a:.precision$},{b:.precision$},{c:.precision$}"),
        None => w.write_all(b",,,"),
    }
}

/// Writes one row (with newline) in [`CSV_HEADER`]'s column order
/// ([`Column::ALL`]). Absent
/// values are empty fields; positions have 0.1 mm, angles 1 µrad resolution.
pub fn write_row<W: Write>(w: &mut W, row: &CsvRow) -> io::Result<()> {
    write!(w, "{},{:.4},{}", row.tick, row.t, row.state.name())?;
    opt3(w, row.measured, 4)?;
    match row.plan {
        Some(plan) => {
            for p in plan {
                opt3(w, Some(p), 4)?;
            }
        }
        None => w.write_all(&[b','; 12])?,
    }
    opt3(w, row.reference, 4)?;
    match row.command {
        Some([r, p, y, t]) => write!(w, ",{r:.6},{p:.6},{y:.6},{t:.4}")?,
        None => w.write_all(b",,,,")?,
    }
    match row.solve_us {
        Some(s) => write!(w, ",{s}")?,
        None => w.write_all(b",")?,
    }
    write!(w, ",{}", row.jitter_us)?;
    match &row.disturbance {
        Some(d) => {
            let [x, y, z] = d.acceleration;
            write!(w, ",{x:.5},{y:.5},{z:.5},{:.5},", d.thrust_scale)?;
            if let Some(h) = d.hover_thrust {
                write!(w, "{h:.5}")?;
            }
            write!(w, ",{}", status_name(d.status))?;
        }
        None => w.write_all(b",,,,,,")?,
    }
    match row.residual {
        Some(r) => write!(w, ",{r:.4}")?,
        None => w.write_all(b",")?,
    }
    write!(w, ",{}", row.guard.unwrap_or(""))?;
    match row.pose_age_ms {
        Some(a) => write!(w, ",{a:.3}")?,
        None => w.write_all(b",")?,
    }
    writeln!(w, ",{},{}", row.wake, row.events)
}

/// Counters of a finished [`CsvRecorder`].
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize)]
pub struct CsvReport {
    /// The file written.
    pub path: PathBuf,
    /// Rows written.
    pub rows: u64,
    /// Rows dropped (queue full: the disk fell behind).
    pub dropped: u64,
    /// Write errors (the first is logged and stops the file).
    pub write_errors: u64,
    /// Rows dropped because the per-flight quota (`records.max_mb`) was
    /// used up.
    pub quota_dropped: u64,
    /// Rows dropped after a write error stopped the file (disk trouble).
    pub error_dropped: u64,
    /// Bytes written.
    pub bytes: u64,
    /// `fdatasync` calls made.
    pub syncs: u64,
}

/// The per-flight CSV, written by its own thread.
#[derive(Debug)]
pub struct CsvRecorder {
    tx: std::sync::mpsc::SyncSender<CsvRow>,
    dropped: Arc<AtomicU64>,
    thread: std::thread::JoinHandle<CsvReport>,
}

impl CsvRecorder {
    /// Creates (truncates) `path`, writes the header and starts the
    /// thread (no quota, synced every second).
    pub fn create(path: &Path) -> io::Result<Self> {
        Self::create_with(
            path,
            Arc::new(RecordBudget::new(None)),
            Duration::from_secs(1),
        )
    }

    /// Creates (truncates) `path`, writes the header and starts the
    /// thread: rows within `budget`, synced at least every `sync_every`.
    pub fn create_with(
        path: &Path,
        budget: Arc<RecordBudget>,
        sync_every: Duration,
    ) -> io::Result<Self> {
        let file = File::create(path)?;
        let (tx, rx) = std::sync::mpsc::sync_channel::<CsvRow>(CSV_QUEUE);
        let dropped = Arc::new(AtomicU64::new(0));
        let path = path.to_owned();
        let thread = std::thread::Builder::new()
            .name("dflat-csv".into())
            .spawn(move || {
                let mut file = RecordFile::new(file, &path, budget, sync_every);
                // One row's text, reused: formatted here, written whole.
                let mut line: Vec<u8> = Vec::with_capacity(512);
                line.extend_from_slice(CSV_HEADER.as_bytes());
                line.push(b'\n');
                file.write_record(&line);
                let mut format_errors = 0u64;
                loop {
                    let row = match rx.recv_timeout(sync_every) {
                        Ok(row) => row,
                        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                            file.sync_if_due();
                            continue;
                        }
                        // Ends when the sender is dropped (finish), after draining.
                        Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
                    };
                    line.clear();
                    match write_row(&mut line, &row) {
                        Ok(()) => {
                            file.write_record(&line);
                        }
                        Err(_) => format_errors += 1,
                    }
                }
                file.sync();
                let stats = file.stats();
                CsvReport {
                    path,
                    // The header is not a row.
                    rows: stats.records.saturating_sub(1),
                    dropped: 0,
                    write_errors: stats.write_errors + format_errors,
                    quota_dropped: stats.quota_dropped,
                    error_dropped: stats.error_dropped,
                    bytes: stats.bytes,
                    syncs: stats.syncs,
                }
            })?;
        Ok(Self {
            tx,
            dropped,
            thread,
        })
    }

    /// Queues one row. Never blocks, never allocates.
    pub fn record(&self, row: &CsvRow) {
        if self.tx.try_send(*row).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Writes every queued row, flushes and ends the thread (blocks until done).
    pub fn finish(self) -> CsvReport {
        drop(self.tx);
        let dropped = self.dropped.load(Ordering::Relaxed);
        match self.thread.join() {
            Ok(mut report) => {
                report.dropped = dropped;
                report
            }
            Err(_) => CsvReport {
                dropped,
                write_errors: 1,
                ..CsvReport::default()
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, SystemTime, UNIX_EPOCH};

    #[test]
    fn utc_stamps() {
        assert_eq!(utc_stamp(UNIX_EPOCH), "19700101-000000");
        // 2000-02-29 12:34:56 UTC = 951827696.
        assert_eq!(
            utc_stamp(UNIX_EPOCH + Duration::from_secs(951_827_696)),
            "20000229-123456"
        );
        // 2026-11-02 00:00:00 UTC = 1793577600.
        assert_eq!(
            utc_stamp(UNIX_EPOCH + Duration::from_secs(1_793_577_600)),
            "20261102-000000"
        );
        // 2100-03-01 (not a leap year) 23:59:59.
        assert_eq!(
            utc_stamp(UNIX_EPOCH + Duration::from_secs(4_107_628_799)),
            "21000301-235959"
        );
    }

    fn row() -> CsvRow {
        CsvRow {
            tick: 7,
            t: 0.14,
            state: FlightState::Tracking,
            measured: Some([1.0, -2.5, -10.0]),
            plan: Some([[1.0, 2.0, 3.0]; 4]),
            reference: Some([0.0, 0.0, -10.0]),
            command: Some([0.01, -0.2, 0.0, 0.5]),
            solve_us: Some(42),
            jitter_us: 120,
            disturbance: None,
            residual: Some(0.0123),
            guard: None,
            pose_age_ms: Some(4.25),
            wake: 0.140_123_456_789,
            events: 31,
        }
    }

    #[test]
    fn row_format_matches_header() {
        let mut out = Vec::new();
        write_row(&mut out, &row()).unwrap();
        let line = String::from_utf8(out).unwrap();
        assert_eq!(
            line,
            "7,0.1400,TRACKING,1.0000,-2.5000,-10.0000,\
1.0000,2.0000,3.0000,1.0000,2.0000,3.0000,1.0000,2.0000,3.0000,1.0000,2.0000,3.0000,\
0.0000,0.0000,-10.0000,0.010000,-0.200000,0.000000,0.5000,42,120,,,,,,,0.0123,,4.250,0.140123456789,31\n"
        );
        let columns = CSV_HEADER.split(',').count();
        assert_eq!(line.trim_end().split(',').count(), columns);
        // A tick without control: empty fields, same column count.
        let mut out = Vec::new();
        write_row(
            &mut out,
            &CsvRow {
                state: FlightState::Failsafe,
                measured: None,
                plan: None,
                reference: None,
                command: None,
                solve_us: None,
                residual: None,
                guard: Some("level"),
                pose_age_ms: None,
                ..row()
            },
        )
        .unwrap();
        let line = String::from_utf8(out).unwrap();
        assert_eq!(line.trim_end().split(',').count(), columns);
        assert!(line.starts_with("7,0.1400,FAILSAFE,,,,"), "{line}");
        assert!(
            line.ends_with(",,120,,,,,,,,level,,0.140123456789,31\n"),
            "{line}"
        );
        // With an estimate.
        let mut out = Vec::new();
        let disturbance = Some(CsvDisturbance {
            acceleration: [0.1, -0.2, 0.0],
            thrust_scale: 1.04,
            hover_thrust: Some(0.48),
            status: EstimatorStatus::Tracking,
        });
        write_row(
            &mut out,
            &CsvRow {
                disturbance,
                ..row()
            },
        )
        .unwrap();
        let line = String::from_utf8(out).unwrap();
        assert_eq!(line.trim_end().split(',').count(), columns);
        assert!(
            line.ends_with(",120,0.10000,-0.20000,0.00000,1.04000,0.48000,tracking,0.0123,,4.250,0.140123456789,31\n"),
            "{line}"
        );
    }

    #[test]
    fn recorder_writes_everything_on_finish_and_names_are_unique() {
        let dir = std::env::temp_dir().join(format!("dflat-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let now = SystemTime::now();
        let stem = flight_stem(&dir, now);
        let path = stem.with_extension("csv");
        let rec = CsvRecorder::create(&path).unwrap();
        for k in 0..1000 {
            rec.record(&CsvRow { tick: k, ..row() });
        }
        let report = rec.finish();
        assert_eq!(
            (report.rows, report.dropped, report.write_errors),
            (1000, 0, 0)
        );
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text.lines().count(), 1001);
        assert_eq!(text.lines().next().unwrap(), CSV_HEADER);
        // Same second again: a different stem.
        let again = flight_stem(&dir, now);
        assert_ne!(again, stem);
        assert!(again.to_string_lossy().ends_with("-2"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
