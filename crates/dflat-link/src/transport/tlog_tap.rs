//! The [`TlogTap`]: every frame sent and received, with a µs UNIX
//! timestamp, in a `.tlog` file, written by its own thread so socket tasks
//! never wait on the disk.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use tokio::sync::oneshot;

use super::{Received, TAP_QUEUE, TransportError, unix_time_us};
use crate::{MAX_FRAME_LEN, MavHeader, MavMessage};

/// Counters of a [`TlogTap`], returned by [`TlogTap::close`].
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize)]
pub struct TlogReport {
    /// The file written.
    pub path: PathBuf,
    /// Records written.
    pub records: u64,
    /// Records dropped because the writer fell behind (queue full) or the
    /// tap was already closed.
    pub dropped: u64,
    /// Write errors (the first one is logged and stops the file).
    pub write_errors: u64,
    /// Records dropped because the per-flight quota was used up.
    pub quota_dropped: u64,
    /// Records dropped after a write error stopped the file.
    pub error_dropped: u64,
    /// Bytes written.
    pub bytes: u64,
    /// `fdatasync` calls made.
    pub syncs: u64,
}

/// How a [`TlogTap`] writes: its quota and sync cadence.
#[derive(Debug, Clone)]
pub struct TapOptions {
    /// The flight's byte quota, shared with its other records.
    pub budget: Arc<crate::records::RecordBudget>,
    /// Longest time written frames stay unsynced \[s\] (`fdatasync`).
    pub sync_every: std::time::Duration,
    /// The transport records every frame it receives (`true`), or the
    /// caller records the frames it accepts with
    /// [`TlogTap::record_received`] (`false`: only frames that passed the
    /// source filter and authentication go into the tlog).
    pub inbound: bool,
}

impl Default for TapOptions {
    fn default() -> Self {
        Self {
            budget: Arc::new(crate::records::RecordBudget::new(None)),
            sync_every: std::time::Duration::from_secs(1),
            inbound: true,
        }
    }
}

// Records are inline so that queuing one never allocates; the channel's
// slots are sized for them once.
#[allow(clippy::large_enum_variant)]
enum TapMsg {
    Record {
        ts_us: u64,
        len: u16,
        bytes: [u8; MAX_FRAME_LEN],
    },
    Close(oneshot::Sender<TlogReport>),
}

/// A `.tlog` recorder running on its own thread. Cloneable; all clones feed
/// the same file. [`record`](Self::record) never blocks (a full queue drops
/// and counts the record); [`close`](Self::close) flushes and ends it.
#[derive(Clone)]
pub struct TlogTap {
    /// [`TapOptions::inbound`].
    pub(super) inbound: bool,
    tx: std::sync::mpsc::SyncSender<TapMsg>,
    dropped: Arc<AtomicU64>,
    path: Arc<PathBuf>,
}

impl fmt::Debug for TlogTap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TlogTap").field("path", &self.path).finish()
    }
}

impl TlogTap {
    /// Creates (truncates) `path` and starts the writer thread (no quota,
    /// synced every second).
    pub fn create(path: &Path) -> Result<Self, TransportError> {
        Self::create_with(path, TapOptions::default())
    }

    /// Creates (truncates) `path` and starts the writer thread: each frame
    /// is one `write` of its whole record, synced at least every
    /// `options.sync_every`, within `options.budget`; a write error stops
    /// the file (counted, the budget's disk notice raised).
    pub fn create_with(path: &Path, options: TapOptions) -> Result<Self, TransportError> {
        let io_err = |op, source| TransportError::Io {
            endpoint: path.display().to_string(),
            op,
            source,
        };
        let file = std::fs::File::create(path).map_err(|e| io_err("create tlog", e))?;
        let inbound = options.inbound;
        let (tx, rx) = std::sync::mpsc::sync_channel::<TapMsg>(TAP_QUEUE);
        let dropped = Arc::new(AtomicU64::new(0));
        let thread_dropped = dropped.clone();
        let thread_path = path.to_owned();
        std::thread::Builder::new()
            .name("dflat-tlog".into())
            .spawn(move || {
                let mut file = crate::records::RecordFile::new(
                    file,
                    &thread_path,
                    options.budget,
                    options.sync_every,
                );
                let mut record = [0u8; 8 + MAX_FRAME_LEN];
                let mut bad_frames = 0u64;
                let mut reply = None;
                loop {
                    let msg = match rx.recv_timeout(options.sync_every) {
                        Ok(msg) => msg,
                        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                            file.sync_if_due();
                            continue;
                        }
                        Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
                    };
                    match msg {
                        TapMsg::Record { ts_us, len, bytes } => {
                            match crate::tlog::encode_record(
                                ts_us,
                                &bytes[..usize::from(len)],
                                &mut record,
                            ) {
                                Ok(n) => {
                                    file.write_record(&record[..n]);
                                }
                                Err(_) => bad_frames += 1,
                            }
                        }
                        TapMsg::Close(r) => {
                            reply = Some(r);
                            break;
                        }
                    }
                }
                file.sync();
                let stats = file.stats();
                let report = TlogReport {
                    path: thread_path.clone(),
                    records: stats.records,
                    dropped: thread_dropped.load(Ordering::Relaxed) + bad_frames,
                    write_errors: stats.write_errors,
                    quota_dropped: stats.quota_dropped,
                    error_dropped: stats.error_dropped,
                    bytes: stats.bytes,
                    syncs: stats.syncs,
                };
                if let Some(r) = reply {
                    let _ = r.send(report);
                }
            })
            .map_err(|e| io_err("spawn tlog writer", e))?;
        Ok(Self {
            inbound,
            tx,
            dropped,
            path: Arc::new(path.to_owned()),
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Queues one frame (`bytes`: exactly one MAVLink frame) with its
    /// timestamp \[µs since the UNIX epoch\]. Never blocks, never allocates.
    pub fn record(&self, ts_us: u64, bytes: &[u8]) {
        if bytes.len() > MAX_FRAME_LEN {
            self.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let mut buf = [0u8; MAX_FRAME_LEN];
        buf[..bytes.len()].copy_from_slice(bytes);
        let msg = TapMsg::Record {
            ts_us,
            len: bytes.len() as u16,
            bytes: buf,
        };
        if self.tx.try_send(msg).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Queues a received frame that the caller accepted (with
    /// [`TapOptions::inbound`] off): its own bytes when signed, else
    /// re-serialized (MAVLink 2), stamped now.
    pub fn record_received(&self, frame: &Received) {
        self.record_received_at(frame, unix_time_us());
    }

    /// [`record_received`](Self::record_received) stamped `ts` \[µs since
    /// the UNIX epoch\] (the daemon stamps the frame's own arrival, so a
    /// replay recovers it exactly).
    pub fn record_received_at(&self, frame: &Received, ts: u64) {
        match &frame.signed {
            Some(signed) => self.record(ts, signed.as_bytes()),
            None => self.record_message(ts, &frame.header, &frame.message),
        }
    }

    /// Serializes `msg` (MAVLink 2) and queues it like [`record`](Self::record).
    pub fn record_message(&self, ts_us: u64, header: &MavHeader, msg: &MavMessage) {
        match crate::serialize_v2(header, msg) {
            Ok(frame) => self.record(ts_us, frame.as_bytes()),
            Err(_) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Writes everything queued so far, flushes the file and stops the
    /// writer; later records are dropped (and counted). Returns the counters,
    /// or `None` if the tap was already closed.
    pub async fn close(&self) -> Option<TlogReport> {
        let (reply, done) = oneshot::channel();
        // A blocking send: the queue may be full; the writer drains it.
        let tx = self.tx.clone();
        let sent = tokio::task::spawn_blocking(move || tx.send(TapMsg::Close(reply)).is_ok())
            .await
            .unwrap_or(false);
        if !sent {
            return None;
        }
        done.await.ok()
    }

    /// Blocking variant of [`close`](Self::close) for non-async callers.
    pub fn close_blocking(&self) -> Option<TlogReport> {
        let (reply, done) = oneshot::channel();
        self.tx.send(TapMsg::Close(reply)).ok()?;
        done.blocking_recv().ok()
    }
}
