//! Serial ports through the mavlink crate's direct-serial transport,
//! in two blocking threads; the port is reopened with backoff when it
//! closes (if asked).

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex as StdMutex};
use std::time::{Duration, Instant};

use crate::FrameError;
use crate::backoff::Backoff;
use mavlink::error::MessageReadError;
use mavlink::{Connectable, MAVLinkMessageRaw, MavConnection, SerialConfig};
use tokio::sync::{Mutex, mpsc};

use super::{
    AtomicCounters, Io, Received, RecvEvent, SERIAL_QUEUE, SERIAL_TX_QUEUE, TlogTap,
    TransportError, unix_time_us,
};

type Conn = mavlink::Connection<crate::MavMessage>;
/// The open port, `None` while it is being reopened.
type Slot = Arc<StdMutex<Option<Arc<Conn>>>>;

fn connect(path: &str, baud: u32) -> std::io::Result<Conn> {
    SerialConfig::new(path.to_owned(), baud)
        .timeout(Duration::from_millis(100))
        .connect::<crate::MavMessage>()
}

fn current(slot: &Slot) -> Option<Arc<Conn>> {
    slot.lock().unwrap_or_else(|p| p.into_inner()).clone()
}

pub(super) async fn open(
    name: &str,
    path: &str,
    baud: u32,
    tap: Option<TlogTap>,
    reconnect: bool,
    counters: Arc<AtomicCounters>,
) -> Result<Io, TransportError> {
    let open_path = path.to_owned();
    let conn = tokio::task::spawn_blocking(move || connect(&open_path, baud))
        .await
        .map_err(|e| TransportError::Io {
            endpoint: name.to_owned(),
            op: "open",
            source: std::io::Error::other(e.to_string()),
        })?
        .map_err(|source| TransportError::Io {
            endpoint: name.to_owned(),
            op: "open",
            source,
        })?;
    let slot: Slot = Arc::new(StdMutex::new(Some(Arc::new(conn))));
    let (ev_tx, ev_rx) = mpsc::channel(SERIAL_QUEUE);
    let (raw_tx, raw_rx) =
        std::sync::mpsc::sync_channel::<mavlink::MAVLinkV2MessageRaw>(SERIAL_TX_QUEUE);

    let reader = slot.clone();
    let reader_name = name.to_owned();
    let reader_path = path.to_owned();
    let reader_counters = counters.clone();
    std::thread::Builder::new()
        .name("dflat-serial-rx".into())
        .spawn(move || {
            loop {
                let Some(conn) = current(&reader) else {
                    return;
                };
                let item = match conn.recv_raw() {
                    Ok(raw) => {
                        let arrival = Instant::now();
                        let bytes = match &raw {
                            MAVLinkMessageRaw::V1(r) => r.raw_bytes(),
                            MAVLinkMessageRaw::V2(r) => r.raw_bytes(),
                        };
                        match crate::parse_frame(bytes) {
                            Ok(frame) => {
                                if let Some(tap) = tap.as_ref().filter(|t| t.inbound) {
                                    tap.record(unix_time_us(), bytes);
                                }
                                Ok(RecvEvent::Frame(Box::new(Received {
                                    header: frame.header,
                                    message: frame.message,
                                    arrival,
                                    signed: frame.signed,
                                    from: None,
                                })))
                            }
                            Err(e) => Ok(RecvEvent::Error(e)),
                        }
                    }
                    Err(MessageReadError::Parse(e)) => {
                        Ok(RecvEvent::Error(FrameError::from_parser_error(0, &e)))
                    }
                    Err(MessageReadError::Io(e)) => {
                        let closed = e.kind() == std::io::ErrorKind::UnexpectedEof;
                        if closed && reconnect {
                            drop(conn);
                            *reader.lock().unwrap_or_else(|p| p.into_inner()) = None;
                            tracing::warn!(endpoint = %reader_name, "serial port closed: reopening");
                            let mut backoff = Backoff::new();
                            let conn = loop {
                                std::thread::sleep(backoff.next_delay());
                                if ev_tx.is_closed() {
                                    return; // the transport was dropped
                                }
                                match connect(&reader_path, baud) {
                                    Ok(c) => break c,
                                    Err(e) => tracing::debug!(endpoint = %reader_name, error = %e, "reopen failed"),
                                }
                            };
                            *reader.lock().unwrap_or_else(|p| p.into_inner()) =
                                Some(Arc::new(conn));
                            let n = reader_counters.reconnects.fetch_add(1, Ordering::Relaxed) + 1;
                            tracing::info!(
                                endpoint = %reader_name,
                                attempts = backoff.attempts(),
                                reconnects = n,
                                "serial link reopened"
                            );
                            continue;
                        }
                        let err = if closed {
                            TransportError::Closed {
                                endpoint: reader_name.clone(),
                            }
                        } else {
                            TransportError::Io {
                                endpoint: reader_name.clone(),
                                op: "recv",
                                source: e,
                            }
                        };
                        let _ = ev_tx.blocking_send(Err(err));
                        if closed {
                            return;
                        }
                        std::thread::sleep(Duration::from_millis(100));
                        continue;
                    }
                };
                if ev_tx.blocking_send(item).is_err() {
                    return; // the transport was dropped
                }
            }
        })
        .map_err(|source| TransportError::Io {
            endpoint: name.to_owned(),
            op: "spawn reader",
            source,
        })?;

    let writer_name = name.to_owned();
    let writer = slot;
    std::thread::Builder::new()
        .name("dflat-serial-tx".into())
        .spawn(move || {
            while let Ok(raw) = raw_rx.recv() {
                let Some(conn) = current(&writer) else {
                    // Reopening: the frame is dropped (a newer command follows).
                    counters.send_dropped.fetch_add(1, Ordering::Relaxed);
                    continue;
                };
                if let Err(e) = conn.send_raw(&MAVLinkMessageRaw::V2(raw)) {
                    tracing::warn!(endpoint = %writer_name, error = %e, "serial write failed");
                }
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
    })
}
