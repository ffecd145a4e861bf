//! Serial ports (8N1, no flow control, the `serialport` crate the mavlink
//! crate uses too), read and written by two blocking threads.
//!
//! * **Bytes, not the mavlink crate's reader.** The reader thread feeds what
//!   it reads to dflat-link's [`FrameParser`](crate::FrameParser) (the same
//!   receive state as TCP), so checksum failures and bytes outside any frame
//!   are reported as [`RecvEvent::Error`] and counted like on every other
//!   link.
//! * **A wrong baud rate** shows as bytes without a valid frame: after
//!   [`GARBAGE_WARN_BYTES`] such bytes (with framing errors and no frame in
//!   between) the reader names the baud rate in one warning; a valid frame
//!   re-arms it.
//! * **A port that goes away** — a USB-serial adapter unplugged, a pty whose
//!   other side closed: end of file, `POLLHUP` (reported as "Broken pipe"),
//!   `EIO` on a read or a write — is one *outage*: one warning when it
//!   starts, sends dropped and counted
//!   ([`TransportCounters::send_dropped`](super::TransportCounters)) while it
//!   lasts, and with [`OpenOptions::reconnect`](super::OpenOptions) the path
//!   is opened again with [`Backoff`] (capped at [`REOPEN_MAX`] so a port
//!   that is back is found within half a second) and one `info` line when
//!   it is. Without `reconnect` the outage is [`TransportError::Closed`].

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex as StdMutex};
use std::time::{Duration, Instant};

use crate::backoff::Backoff;
use serialport::{DataBits, FlowControl, Parity, StopBits, TTYPort};
use tokio::sync::{Mutex, mpsc};

use super::rx_state::RxState;
use super::{
    AtomicCounters, Io, RecvEvent, SERIAL_QUEUE, SERIAL_TX_QUEUE, STREAM_CHUNK, TlogTap,
    TransportError,
};

/// Longest wait between two attempts to reopen a lost port: a port that is
/// back is open again within this (plus the open itself).
pub const REOPEN_MAX: Duration = Duration::from_millis(500);
/// Bytes received without one valid frame (and with framing errors) after
/// which the reader warns that the baud rate may be wrong.
pub const GARBAGE_WARN_BYTES: u64 = 1024;
/// Read and write timeout of the port: how often the reader looks whether
/// the transport is still wanted or the writer lost the port.
const POLL: Duration = Duration::from_millis(100);

/// Opens the port as the transport does (8N1, no flow control, exclusive).
fn open_port(path: &str, baud: u32) -> std::io::Result<TTYPort> {
    serialport::new(path, baud)
        .data_bits(DataBits::Eight)
        .parity(Parity::None)
        .stop_bits(StopBits::One)
        .flow_control(FlowControl::None)
        .timeout(POLL)
        .open_native()
        .map_err(std::io::Error::from)
}

/// A read or write error that means the port is gone (not a timeout).
fn is_loss(e: &std::io::Error) -> bool {
    !matches!(
        e.kind(),
        std::io::ErrorKind::TimedOut
            | std::io::ErrorKind::Interrupted
            | std::io::ErrorKind::WouldBlock
    )
}

/// What the reader, the writer and the transport's `send` share.
struct Port {
    /// `serial:PATH:BAUD`, for the log.
    name: String,
    /// The writer's handle on the open port; `None` during an outage.
    writer: StdMutex<Option<TTYPort>>,
    /// The port is open (sends are queued, not dropped).
    up: Arc<AtomicBool>,
    counters: Arc<AtomicCounters>,
}

impl Port {
    /// Marks the port lost. Says so once per outage (whoever notices first,
    /// the reader or the writer); `true` if this call started the outage.
    fn lost(&self, cause: &str) -> bool {
        let mut w = self.writer.lock().unwrap_or_else(|p| p.into_inner());
        self.lost_locked(&mut w, cause)
    }

    fn lost_locked(&self, w: &mut Option<TTYPort>, cause: &str) -> bool {
        if w.take().is_none() {
            return false;
        }
        self.up.store(false, Ordering::Release);
        tracing::warn!(
            endpoint = %self.name,
            cause,
            "serial port lost: sends dropped, reopening with backoff"
        );
        true
    }
}

/// Opens `path` at `baud` and starts the reader and writer threads.
pub(super) async fn open(
    name: &str,
    path: &str,
    baud: u32,
    tap: Option<TlogTap>,
    reconnect: bool,
    counters: Arc<AtomicCounters>,
) -> Result<Io, TransportError> {
    let io_err = |source| TransportError::Io {
        endpoint: name.to_owned(),
        op: "open",
        source,
    };
    let open_path = path.to_owned();
    let reader_port = tokio::task::spawn_blocking(move || open_port(&open_path, baud))
        .await
        .map_err(|e| io_err(std::io::Error::other(e.to_string())))?
        .map_err(io_err)?;
    let writer_port = reader_port
        .try_clone_native()
        .map_err(|e| io_err(e.into()))?;
    let up = Arc::new(AtomicBool::new(true));
    let port = Arc::new(Port {
        name: name.to_owned(),
        writer: StdMutex::new(Some(writer_port)),
        up: up.clone(),
        counters,
    });
    let (ev_tx, ev_rx) = mpsc::channel(SERIAL_QUEUE);
    let (raw_tx, raw_rx) =
        std::sync::mpsc::sync_channel::<mavlink::MAVLinkV2MessageRaw>(SERIAL_TX_QUEUE);

    let reader = Reader {
        port: port.clone(),
        path: path.to_owned(),
        baud,
        reconnect,
        tap,
        events: ev_tx,
        state: RxState::new(STREAM_CHUNK),
        garbage: Garbage::default(),
    };
    std::thread::Builder::new()
        .name("dflat-serial-rx".into())
        .spawn(move || reader.run(reader_port))
        .map_err(|source| TransportError::Io {
            endpoint: name.to_owned(),
            op: "spawn reader",
            source,
        })?;

    std::thread::Builder::new()
        .name("dflat-serial-tx".into())
        .spawn(move || {
            while let Ok(raw) = raw_rx.recv() {
                write_frame(&port, raw.raw_bytes());
            }
        })
        .map_err(|source| TransportError::Io {
            endpoint: name.to_owned(),
            op: "spawn writer",
            source,
        })?;

    Ok(Io::Serial {
        tx: raw_tx,
        rx: Mutex::new(ev_rx),
        up,
    })
}

/// Writes one frame; during an outage (or on a write that times out) it is
/// dropped and counted, and a write that fails starts an outage.
fn write_frame(port: &Port, bytes: &[u8]) {
    let mut w = port.writer.lock().unwrap_or_else(|p| p.into_inner());
    let result = match w.as_mut() {
        Some(tty) => tty.write_all(bytes),
        None => Err(std::io::Error::from(std::io::ErrorKind::NotConnected)),
    };
    if let Err(e) = result {
        port.counters.send_dropped.fetch_add(1, Ordering::Relaxed);
        if w.is_some() && is_loss(&e) {
            port.lost_locked(&mut w, &format!("write: {e}"));
        }
    }
}

/// Bytes without a valid frame since the last one (the baud-rate check).
#[derive(Debug, Default)]
struct Garbage {
    bytes: u64,
    errors: u64,
    warned: bool,
}

impl Garbage {
    /// Counts a chunk of `bytes` that held `frames` valid frames and
    /// `errors` framing errors; `true` when the baud-rate warning is due
    /// (once until a valid frame re-arms it).
    fn count(&mut self, bytes: u64, frames: usize, errors: usize) -> bool {
        if frames > 0 {
            *self = Self::default();
            return false;
        }
        self.bytes += bytes;
        self.errors += errors as u64;
        let due = !self.warned && self.bytes >= GARBAGE_WARN_BYTES && self.errors > 0;
        self.warned |= due;
        due
    }
}

/// The reader thread's state.
struct Reader {
    port: Arc<Port>,
    path: String,
    baud: u32,
    reconnect: bool,
    tap: Option<TlogTap>,
    events: mpsc::Sender<Result<RecvEvent, TransportError>>,
    state: RxState,
    garbage: Garbage,
}

impl Reader {
    fn run(mut self, mut tty: TTYPort) {
        loop {
            if self.events.is_closed() {
                return; // the transport was dropped
            }
            let n = match tty.read(&mut self.state.buf) {
                Ok(0) => Err("end of file".to_owned()),
                Ok(n) => Ok(n),
                Err(e) if !is_loss(&e) => {
                    if self.port.up.load(Ordering::Acquire) {
                        continue;
                    }
                    // The writer lost the port.
                    Err("write failed".to_owned())
                }
                Err(e) => Err(format!("read: {e}")),
            };
            match n {
                Ok(n) => {
                    if !self.ingest(n) {
                        return;
                    }
                }
                Err(cause) => {
                    self.port.lost(&cause);
                    drop(tty);
                    if !self.reconnect {
                        let _ = self.events.blocking_send(Err(TransportError::Closed {
                            endpoint: self.port.name.clone(),
                        }));
                        return;
                    }
                    match self.reopen() {
                        Some(t) => tty = t,
                        None => return,
                    }
                }
            }
        }
    }

    /// Parses `n` bytes read into the buffer and hands on what they held;
    /// `false` once the transport is gone.
    fn ingest(&mut self, n: usize) -> bool {
        let errors_before = self.state.errors_queued();
        self.state
            .ingest(n, false, Instant::now(), None, self.tap.as_ref());
        let frames = self.state.pending.len() - self.state.errors_queued();
        let errors = self.state.errors_queued() - errors_before;
        if self.garbage.count(n as u64, frames, errors) {
            let g = &self.garbage;
            tracing::warn!(
                endpoint = %self.port.name,
                bytes = g.bytes,
                framing_errors = g.errors,
                baud = self.baud,
                "serial link: bytes but no valid MAVLink frame: wrong baud rate? \
                 This end runs at {} baud; the autopilot's port (PX4 SER_TEL2_BAUD, \
                 ArduPilot SERIALn_BAUD) must be set to the same (counted as malformed / crc \
                 in the link errors; said once until a frame arrives)",
                self.baud
            );
        }
        while let Some(event) = self.state.pending.pop_front() {
            if self.events.blocking_send(Ok(event)).is_err() {
                return false;
            }
        }
        true
    }

    /// Opens the path again until it works (backoff up to [`REOPEN_MAX`]);
    /// `None` if the transport was dropped meanwhile.
    fn reopen(&mut self) -> Option<TTYPort> {
        let lost_at = Instant::now();
        let mut backoff = Backoff::new();
        let mut last_error = String::new();
        loop {
            std::thread::sleep(backoff.next_delay().min(REOPEN_MAX));
            if self.events.is_closed() {
                return None;
            }
            let opened = open_port(&self.path, self.baud)
                .and_then(|r| r.try_clone_native().map(|w| (r, w)).map_err(Into::into));
            match opened {
                Ok((reader, writer)) => {
                    // A partial frame from before the outage is gone.
                    self.state.reset_stream();
                    self.garbage = Garbage::default();
                    *self.port.writer.lock().unwrap_or_else(|p| p.into_inner()) = Some(writer);
                    self.port.up.store(true, Ordering::Release);
                    let n = self
                        .port
                        .counters
                        .reconnects
                        .fetch_add(1, Ordering::Relaxed)
                        + 1;
                    tracing::info!(
                        endpoint = %self.port.name,
                        down_s = format_args!("{:.2}", lost_at.elapsed().as_secs_f64()),
                        attempts = backoff.attempts(),
                        reconnects = n,
                        "serial link reopened"
                    );
                    return Some(reader);
                }
                Err(e) => {
                    let text = e.to_string();
                    if text != last_error {
                        tracing::debug!(endpoint = %self.port.name, error = %text, "reopen failed");
                        last_error = text;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn garbage_warns_once_until_a_frame_rearms_it() {
        let mut g = Garbage::default();
        // Bytes without errors (a frame still arriving) never warn.
        assert!(!g.count(2 * GARBAGE_WARN_BYTES, 0, 0));
        let mut g = Garbage::default();
        assert!(!g.count(GARBAGE_WARN_BYTES / 2, 0, 3));
        assert!(g.count(GARBAGE_WARN_BYTES / 2, 0, 3), "1 KiB of garbage");
        assert!(!g.count(GARBAGE_WARN_BYTES, 0, 9), "said once");
        assert!(!g.count(100, 1, 0), "a frame re-arms");
        assert_eq!((g.bytes, g.errors), (0, 0));
        assert!(!g.count(GARBAGE_WARN_BYTES - 1, 0, 1));
        assert!(g.count(1, 0, 0), "and it warns again");
    }

    #[test]
    fn timeouts_are_not_losses() {
        use std::io::{Error, ErrorKind};
        assert!(!is_loss(&Error::from(ErrorKind::TimedOut)));
        assert!(!is_loss(&Error::from(ErrorKind::Interrupted)));
        assert!(is_loss(&Error::from(ErrorKind::BrokenPipe)));
        assert!(is_loss(&Error::other("EIO")));
    }
}
