//! MAVLink I/O shared by the daemon and the SITL autopilot.
//!
//! * [`Endpoint`] — a parsed connection string of the mavlink crate's syntax:
//!   `udpin:HOST:PORT`, `udpout:HOST:PORT`, `tcpout:HOST:PORT`,
//!   `serial:PATH:BAUD`.
//! * [`Transport`] — a cloneable handle over one open connection:
//!   [`Transport::send`] serializes and writes one MAVLink 2 frame,
//!   [`Transport::recv`] yields the next decoded frame *or framing error*.
//!
//! Received bytes go through dflat-link's [`FrameParser`], so checksum
//! failures, unknown message ids, truncated frames and garbage are reported
//! as [`RecvEvent::Error`] for counting (the mavlink crate's own readers skip
//! them silently).
//!
//! Semantics per kind:
//! * `udpin` binds `HOST:PORT`. With [`UdpInPeer::LastSender`] (the
//!   default of [`Transport::open`]; the autopilot side) it replies to the
//!   last sender; with [`UdpInPeer::Lock`] (the daemon) it talks to one
//!   peer: the configured address, or the one the caller locks with
//!   [`Transport::lock_peer`] (the daemon: the first sender of the
//!   autopilot's HEARTBEAT) and `connect()`s the socket to it, so the
//!   kernel drops datagrams from any other address from then on; those
//!   read before the lock are dropped here and counted
//!   ([`TransportCounters::foreign_datagrams`], said once in the log: a
//!   lower bound of what other senders sent). Sends before there is a peer are dropped
//!   ([`SendOutcome::NoPeer`]).
//! * `udpout` binds the address of the interface that routes to `HOST:PORT`
//!   (ephemeral port) and `connect()`s the socket to it, so the kernel
//!   drops datagrams from any other sender. This is the daemon side.
//! * `tcpout` connects; with [`OpenOptions::reconnect`] a lost connection
//!   is re-established with [`Backoff`] (each reconnect logged and counted),
//!   otherwise it is [`TransportError::Closed`].
//! * `serial` opens the port (8N1, no flow control) and reads and writes it
//!   in two blocking threads (the writer's queue is bounded,
//!   [`SERIAL_TX_QUEUE`], beyond it frames are dropped and counted). The
//!   bytes go through [`FrameParser`] as on TCP, so CRC failures and garbage
//!   are counted, and bytes without any valid frame are named in one warning
//!   as a likely wrong baud rate. A port that goes away (a USB adapter
//!   unplugged, a pty closed) is one warning per outage; sends are dropped
//!   and counted while it lasts ([`SendOutcome::NoPeer`]), and with
//!   [`OpenOptions::reconnect`] the path is reopened with [`Backoff`]
//!   (at most [`serial::REOPEN_MAX`] between attempts), else it is
//!   [`TransportError::Closed`]. See [`serial`].
//!
//! An optional [`TlogTap`] records every frame sent and received, with a µs
//! UNIX timestamp, in a `.tlog` file, written by its own thread so socket
//! tasks never wait on the disk.

use std::fmt;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex as StdMutex};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use crate::backoff::Backoff;
use crate::{
    EncodedFrame, FrameError, FrameParser, LinkError, MAX_FRAME_LEN, MavHeader, MavMessage,
    SignedFrame,
};
use thiserror::Error;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpStream, UdpSocket};
use tokio::sync::{Mutex, mpsc};

mod endpoint;
mod rx_state;
pub mod serial;
mod tlog_tap;

pub use endpoint::Endpoint;
use rx_state::RxState;
pub use tlog_tap::{TapOptions, TlogReport, TlogTap};

/// Largest UDP datagram accepted \[bytes\].
const DATAGRAM_MAX: usize = 65_536;
/// Read chunk for byte streams (TCP) \[bytes\].
const STREAM_CHUNK: usize = 4096;
/// Capacity of the tlog tap queue \[records\]; beyond it records are dropped
/// and counted.
const TAP_QUEUE: usize = 8192;
/// Capacity of the serial reader → async queue \[events\].
const SERIAL_QUEUE: usize = 1024;
/// Capacity of the serial writer's queue \[frames\]: about 0.1 s of a
/// 921600 baud link; beyond it frames are dropped and counted.
pub const SERIAL_TX_QUEUE: usize = 64;

/// How a `udpin` transport chooses the peer it talks to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UdpInPeer {
    /// Reply to whoever sent last (the autopilot side, MAVLink routers).
    #[default]
    LastSender,
    /// One peer: this address if given, else none until the caller
    /// [locks](Transport::lock_peer) one. Datagrams from other addresses are
    /// dropped and counted.
    Lock(Option<SocketAddr>),
}

/// Options of [`Transport::open_with`].
#[derive(Debug, Clone, Default)]
pub struct OpenOptions {
    /// Record every frame sent and received here.
    pub tap: Option<TlogTap>,
    /// `udpin`: how the peer is chosen.
    pub udpin_peer: UdpInPeer,
    /// TCP / serial: reconnect with backoff when the connection is lost
    /// (else a lost connection is [`TransportError::Closed`]).
    pub reconnect: bool,
}

/// What a [`Transport`] counted of its peer handling.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct TransportCounters {
    /// Datagrams dropped because they came from an address other than the
    /// peer (udpout: after `connect()` the kernel drops most of them first).
    pub foreign_datagrams: u64,
    /// Connections re-established (TCP, serial).
    pub reconnects: u64,
    /// Frames dropped because the serial writer's queue was full, the
    /// link was down (TCP, serial reconnecting), or a serial write failed
    /// or timed out.
    pub send_dropped: u64,
}

#[derive(Debug, Default)]
struct AtomicCounters {
    foreign_datagrams: AtomicU64,
    reconnects: AtomicU64,
    send_dropped: AtomicU64,
}

/// Microseconds since the UNIX epoch on the system clock (0 if the clock is
/// before 1970).
pub fn unix_time_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

/// Why a connection could not be opened or used.
#[derive(Debug, Error)]
pub enum TransportError {
    /// The connection string is not one of the supported forms.
    #[error("invalid connection string `{url}`: {reason}")]
    BadUrl {
        /// The string given.
        url: String,
        /// What is wrong, and the accepted forms.
        reason: String,
    },
    /// The host name did not resolve to an address.
    #[error("{endpoint}: cannot resolve `{host}`")]
    Resolve {
        /// The endpoint.
        endpoint: String,
        /// The host part.
        host: String,
    },
    /// A socket, port or file operation failed.
    #[error("{endpoint}: {op}: {source}")]
    Io {
        /// The endpoint (or file).
        endpoint: String,
        /// The operation (bind, connect, send, recv, …).
        op: &'static str,
        /// The OS error.
        source: std::io::Error,
    },
    /// The peer closed the connection (TCP end of stream, serial port gone).
    #[error("{endpoint}: connection closed")]
    Closed {
        /// The endpoint.
        endpoint: String,
    },
    /// The message could not be serialized (e.g. system id > 255).
    #[error("cannot encode message: {0}")]
    Encode(#[from] LinkError),
}

/// One decoded frame as received.
#[derive(Debug, Clone, PartialEq)]
pub struct Received {
    /// Sender header (system id ≤ 255).
    pub header: MavHeader,
    /// The decoded message.
    pub message: MavMessage,
    /// When the bytes were read from the OS, on the monotonic clock (use it
    /// for staleness: it is the companion computer's own clock).
    pub arrival: Instant,
    /// The frame's bytes if it carried a MAVLink 2 signature (verify with
    /// `LinkRx::authenticate`).
    pub signed: Option<SignedFrame>,
    /// The datagram's source address (UDP); `None` for TCP and serial.
    pub from: Option<SocketAddr>,
}

/// What [`Transport::recv`] yields.
#[derive(Debug, Clone, PartialEq)]
pub enum RecvEvent {
    /// A frame with a valid checksum and a decodable payload.
    Frame(Box<Received>),
    /// A framing error to count (CRC mismatch, unknown id, truncated frame,
    /// undecodable payload, or bytes without a start marker).
    Error(FrameError),
}

/// What [`Transport::send`] did with a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SendOutcome {
    /// Written (or, for serial, queued to the writer thread); the frame's
    /// length in bytes.
    Sent(usize),
    /// No peer to send to: `udpin` before one spoke (or was locked), or a
    /// TCP / serial link while it reconnects. Dropped.
    NoPeer,
    /// The serial writer's bounded queue is full: dropped (counted in
    /// [`TransportCounters::send_dropped`]).
    QueueFull,
}

/// A cloneable handle over one open MAVLink connection. All clones share
/// the socket, the receive buffer and the tlog tap.
///
/// `recv` may be called from one task at a time (concurrent callers take
/// turns); `send` from any number of tasks. Both are cancel-safe: dropping
/// a pending `recv` loses no frame.
#[derive(Clone)]
pub struct Transport {
    inner: Arc<Inner>,
}

impl fmt::Debug for Transport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Transport")
            .field("endpoint", &self.inner.endpoint)
            .field("local_addr", &self.inner.local_addr)
            .finish()
    }
}

struct Inner {
    endpoint: Endpoint,
    name: String,
    local_addr: Option<SocketAddr>,
    io: Io,
    rx: Mutex<RxState>,
    tap: Option<TlogTap>,
    counters: Arc<AtomicCounters>,
}

/// How a UDP transport treats source addresses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum UdpMode {
    /// `udpin`, reply to the last sender.
    LastSender,
    /// `udpin`, one (locked) peer.
    Lock,
    /// `udpout`: connected to the peer.
    Connected,
}

enum Io {
    Udp {
        socket: UdpSocket,
        /// The peer sends go to (`udpin`: None until one spoke or was locked).
        peer: StdMutex<Option<SocketAddr>>,
        mode: UdpMode,
    },
    Tcp {
        addr: SocketAddr,
        reconnect: bool,
        read: Mutex<Option<OwnedReadHalf>>,
        write: Mutex<Option<OwnedWriteHalf>>,
    },
    Serial {
        /// Raw frames to the writer thread (bounded).
        tx: std::sync::mpsc::SyncSender<mavlink::MAVLinkV2MessageRaw>,
        /// Events from the reader thread.
        rx: Mutex<mpsc::Receiver<Result<RecvEvent, TransportError>>>,
        /// The port is open (false during an outage: sends are dropped).
        up: Arc<std::sync::atomic::AtomicBool>,
    },
}

impl Transport {
    /// Opens `endpoint` without a tlog tap.
    pub async fn open(endpoint: &Endpoint) -> Result<Self, TransportError> {
        Self::open_with_tap(endpoint, None).await
    }

    /// Opens `endpoint`; every frame sent or received is recorded in `tap`
    /// (keep a clone of the tap to [`TlogTap::close`] it at the end).
    pub async fn open_with_tap(
        endpoint: &Endpoint,
        tap: Option<TlogTap>,
    ) -> Result<Self, TransportError> {
        Self::open_with(
            endpoint,
            OpenOptions {
                tap,
                ..OpenOptions::default()
            },
        )
        .await
    }

    /// Opens `endpoint` with `options` (tap, `udpin` peer policy,
    /// reconnection of stream links).
    pub async fn open_with(
        endpoint: &Endpoint,
        options: OpenOptions,
    ) -> Result<Self, TransportError> {
        let OpenOptions {
            tap,
            udpin_peer,
            reconnect,
        } = options;
        let counters = Arc::new(AtomicCounters::default());
        let name = endpoint.to_string();
        let io_err = |op: &'static str| {
            let name = name.clone();
            move |source: std::io::Error| TransportError::Io {
                endpoint: name,
                op,
                source,
            }
        };
        let (io, local_addr, buf_len) = match endpoint {
            Endpoint::UdpIn { host, port } => {
                let addr = resolve(&name, host, *port).await?;
                let socket = UdpSocket::bind(addr).await.map_err(io_err("bind"))?;
                let local = socket.local_addr().map_err(io_err("local_addr"))?;
                let (mode, peer) = match udpin_peer {
                    UdpInPeer::LastSender => (UdpMode::LastSender, None),
                    UdpInPeer::Lock(peer) => (UdpMode::Lock, peer),
                };
                if let Some(peer) = peer {
                    socket.connect(peer).await.map_err(io_err("connect"))?;
                }
                let io = Io::Udp {
                    socket,
                    peer: StdMutex::new(peer),
                    mode,
                };
                (io, Some(local), DATAGRAM_MAX)
            }
            Endpoint::UdpOut { host, port } => {
                let addr = resolve(&name, host, *port).await?;
                let socket = bind_towards(addr).await.map_err(io_err("bind"))?;
                socket.connect(addr).await.map_err(io_err("connect"))?;
                let local = socket.local_addr().map_err(io_err("local_addr"))?;
                let io = Io::Udp {
                    socket,
                    peer: StdMutex::new(Some(addr)),
                    mode: UdpMode::Connected,
                };
                (io, Some(local), DATAGRAM_MAX)
            }
            Endpoint::TcpOut { host, port } => {
                let addr = resolve(&name, host, *port).await?;
                let stream = tcp_connect(addr).await.map_err(io_err("connect"))?;
                let local = stream.local_addr().map_err(io_err("local_addr"))?;
                let (read, write) = stream.into_split();
                let io = Io::Tcp {
                    addr,
                    reconnect,
                    read: Mutex::new(Some(read)),
                    write: Mutex::new(Some(write)),
                };
                (io, Some(local), STREAM_CHUNK)
            }
            Endpoint::Serial { path, baud } => {
                let io = serial::open(&name, path, *baud, tap.clone(), reconnect, counters.clone())
                    .await?;
                (io, None, 0)
            }
        };
        tracing::debug!(endpoint = %name, ?local_addr, "link open");
        Ok(Self {
            inner: Arc::new(Inner {
                endpoint: endpoint.clone(),
                name,
                local_addr,
                io,
                rx: Mutex::new(RxState::new(buf_len)),
                tap,
                counters,
            }),
        })
    }

    /// `udpin` with [`UdpInPeer::Lock`]: talk only to `peer` from now on
    /// (the socket is `connect()`ed to it, so the kernel drops other
    /// senders). An error for other kinds of transport, or if a different
    /// peer is already locked.
    pub async fn lock_peer(&self, peer: SocketAddr) -> Result<(), TransportError> {
        let io_err = |op: &'static str, source| TransportError::Io {
            endpoint: self.inner.name.clone(),
            op,
            source,
        };
        let Io::Udp {
            socket,
            peer: current,
            mode: UdpMode::Lock,
        } = &self.inner.io
        else {
            return Err(io_err(
                "lock peer",
                std::io::Error::other("not a udpin link with a locked peer"),
            ));
        };
        {
            let mut cur = current.lock().unwrap_or_else(|p| p.into_inner());
            match *cur {
                Some(p) if p == peer => return Ok(()),
                Some(p) => {
                    return Err(io_err(
                        "lock peer",
                        std::io::Error::other(format!("already locked onto {p}")),
                    ));
                }
                None => *cur = Some(peer),
            }
        }
        socket
            .connect(peer)
            .await
            .map_err(|e| io_err("connect", e))?;
        tracing::info!(endpoint = %self.inner.name, %peer, "udpin peer locked");
        Ok(())
    }

    /// `udpin` with [`UdpInPeer::Lock`] and no peer yet: the caller decides
    /// which sender to [lock](Self::lock_peer) onto.
    pub fn awaiting_peer(&self) -> bool {
        match &self.inner.io {
            Io::Udp {
                peer,
                mode: UdpMode::Lock,
                ..
            } => peer.lock().unwrap_or_else(|p| p.into_inner()).is_none(),
            _ => false,
        }
    }

    /// What this transport counted (foreign datagrams, reconnects, dropped
    /// sends).
    pub fn counters(&self) -> TransportCounters {
        let c = &self.inner.counters;
        TransportCounters {
            foreign_datagrams: c.foreign_datagrams.load(Ordering::Relaxed),
            reconnects: c.reconnects.load(Ordering::Relaxed),
            send_dropped: c.send_dropped.load(Ordering::Relaxed),
        }
    }

    /// Counts a datagram from a foreign address (the first one is logged).
    fn foreign(&self, from: SocketAddr) {
        let n = self
            .inner
            .counters
            .foreign_datagrams
            .fetch_add(1, Ordering::Relaxed);
        if n == 0 {
            tracing::warn!(
                endpoint = %self.inner.name,
                %from,
                "datagram from an address other than the peer dropped (said once; counted in the summary)"
            );
        }
    }

    /// The endpoint this transport was opened on.
    pub fn endpoint(&self) -> &Endpoint {
        &self.inner.endpoint
    }

    /// The local socket address (UDP, TCP); `None` for serial. With
    /// `udpin:127.0.0.1:0` this is the port the OS chose.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.inner.local_addr
    }

    /// The UDP peer sends go to: `udpout`'s target, or `udpin`'s last
    /// sender (`None` until one spoke). `None` for TCP / serial.
    pub fn peer(&self) -> Option<SocketAddr> {
        match &self.inner.io {
            Io::Udp { peer, .. } => *peer.lock().unwrap_or_else(|p| p.into_inner()),
            _ => None,
        }
    }

    /// The tlog tap, if any.
    pub fn tap(&self) -> Option<&TlogTap> {
        self.inner.tap.as_ref()
    }

    /// Serializes `msg` with `header` (MAVLink 2, unsigned; the caller owns
    /// the sequence number) and writes it. Does not allocate.
    pub async fn send(
        &self,
        header: &MavHeader,
        msg: &MavMessage,
    ) -> Result<SendOutcome, TransportError> {
        let frame = crate::serialize_v2(header, msg)?;
        self.send_frame(&frame).await
    }

    /// Writes an already serialized (possibly signed) frame.
    pub async fn send_frame(&self, frame: &EncodedFrame) -> Result<SendOutcome, TransportError> {
        let bytes = frame.as_bytes();
        let io_err = |op: &'static str, source| TransportError::Io {
            endpoint: self.inner.name.clone(),
            op,
            source,
        };
        match &self.inner.io {
            Io::Udp { socket, peer, .. } => {
                let target = *peer.lock().unwrap_or_else(|p| p.into_inner());
                let Some(target) = target else {
                    return Ok(SendOutcome::NoPeer);
                };
                socket
                    .send_to(bytes, target)
                    .await
                    .map_err(|e| io_err("send", e))?;
            }
            Io::Tcp {
                write, reconnect, ..
            } => {
                let mut w = write.lock().await;
                let Some(stream) = w.as_mut() else {
                    self.inner
                        .counters
                        .send_dropped
                        .fetch_add(1, Ordering::Relaxed);
                    return Ok(SendOutcome::NoPeer);
                };
                if let Err(e) = stream.write_all(bytes).await {
                    if *reconnect {
                        // The receive side notices too and reconnects.
                        *w = None;
                    }
                    return Err(io_err("send", e));
                }
            }
            Io::Serial { up, .. } if !up.load(Ordering::Acquire) => {
                self.inner
                    .counters
                    .send_dropped
                    .fetch_add(1, Ordering::Relaxed);
                return Ok(SendOutcome::NoPeer);
            }
            Io::Serial { tx, .. } => match tx.try_send(*frame.raw()) {
                Ok(()) => {}
                Err(std::sync::mpsc::TrySendError::Full(_)) => {
                    self.inner
                        .counters
                        .send_dropped
                        .fetch_add(1, Ordering::Relaxed);
                    return Ok(SendOutcome::QueueFull);
                }
                Err(std::sync::mpsc::TrySendError::Disconnected(_)) => {
                    return Err(TransportError::Closed {
                        endpoint: self.inner.name.clone(),
                    });
                }
            },
        }
        if let Some(tap) = &self.inner.tap {
            tap.record(unix_time_us(), bytes);
        }
        Ok(SendOutcome::Sent(bytes.len()))
    }

    /// The next received frame or framing error. Errors are I/O failures of
    /// the connection itself: on UDP they are usually transient (e.g. an
    /// ICMP "port unreachable" reported by the OS), [`TransportError::Closed`]
    /// is final.
    pub async fn recv(&self) -> Result<RecvEvent, TransportError> {
        if let Io::Serial { rx, .. } = &self.inner.io {
            let mut rx = rx.lock().await;
            return match rx.recv().await {
                Some(item) => item,
                None => Err(TransportError::Closed {
                    endpoint: self.inner.name.clone(),
                }),
            };
        }
        let mut state = self.inner.rx.lock().await;
        loop {
            if let Some(event) = state.pending.pop_front() {
                return Ok(event);
            }
            let io_err = |source| TransportError::Io {
                endpoint: self.inner.name.clone(),
                op: "recv",
                source,
            };
            match &self.inner.io {
                Io::Udp { socket, peer, mode } => {
                    let (n, from) = socket.recv_from(&mut state.buf).await.map_err(io_err)?;
                    let arrival = Instant::now();
                    let current = *peer.lock().unwrap_or_else(|p| p.into_inner());
                    match mode {
                        UdpMode::LastSender => {
                            *peer.lock().unwrap_or_else(|p| p.into_inner()) = Some(from);
                        }
                        // Queued before connect(), or a kernel without the
                        // filter: checked here too.
                        UdpMode::Lock | UdpMode::Connected => {
                            if current.is_some_and(|p| p != from) {
                                self.foreign(from);
                                continue;
                            }
                        }
                    }
                    state.ingest(n, true, arrival, Some(from), self.inner.tap.as_ref());
                }
                Io::Tcp {
                    addr,
                    reconnect,
                    read,
                    write,
                } => {
                    let got = {
                        let mut r = read.lock().await;
                        let RxState { buf, .. } = &mut *state;
                        match r.as_mut() {
                            Some(stream) => Some(stream.read(buf).await),
                            None => None,
                        }
                    };
                    let arrival = Instant::now();
                    let lost = match got {
                        Some(Ok(0)) | None => None,
                        Some(Ok(n)) => {
                            state.ingest(n, false, arrival, None, self.inner.tap.as_ref());
                            continue;
                        }
                        Some(Err(e)) => Some(e),
                    };
                    if !*reconnect {
                        return Err(match lost {
                            Some(e) => io_err(e),
                            None => TransportError::Closed {
                                endpoint: self.inner.name.clone(),
                            },
                        });
                    }
                    tracing::warn!(
                        endpoint = %self.inner.name,
                        error = ?lost.map(|e| e.to_string()),
                        "TCP link lost: reconnecting"
                    );
                    *read.lock().await = None;
                    *write.lock().await = None;
                    state.reset_stream();
                    let stream = self.tcp_reconnect(*addr).await;
                    let (r, w) = stream.into_split();
                    *read.lock().await = Some(r);
                    *write.lock().await = Some(w);
                }
                Io::Serial { .. } => unreachable!("handled above"),
            }
        }
    }
}

impl Transport {
    /// Connects to `addr` until it works, waiting [`Backoff`] between
    /// attempts; counts and logs the reconnection.
    async fn tcp_reconnect(&self, addr: SocketAddr) -> TcpStream {
        let mut backoff = Backoff::new();
        loop {
            tokio::time::sleep(backoff.next_delay()).await;
            match tcp_connect(addr).await {
                Ok(stream) => {
                    let n = self
                        .inner
                        .counters
                        .reconnects
                        .fetch_add(1, Ordering::Relaxed)
                        + 1;
                    tracing::info!(
                        endpoint = %self.inner.name,
                        attempts = backoff.attempts(),
                        reconnects = n,
                        "TCP link reconnected"
                    );
                    return stream;
                }
                Err(e) => {
                    tracing::debug!(endpoint = %self.inner.name, error = %e, "reconnect failed")
                }
            }
        }
    }
}

async fn tcp_connect(addr: SocketAddr) -> std::io::Result<TcpStream> {
    let stream = TcpStream::connect(addr).await?;
    stream.set_nodelay(true)?;
    Ok(stream)
}

/// A UDP socket bound to the address of the interface the kernel routes
/// `peer` through (ephemeral port): a probe socket `connect()`ed to the
/// peer tells the source address the route picks.
async fn bind_towards(peer: SocketAddr) -> std::io::Result<UdpSocket> {
    let any: SocketAddr = if peer.is_ipv4() {
        SocketAddr::from(([0, 0, 0, 0], 0))
    } else {
        SocketAddr::from(([0u16; 8], 0))
    };
    let probe = std::net::UdpSocket::bind(any)?;
    probe.connect(peer)?;
    let local = SocketAddr::new(probe.local_addr()?.ip(), 0);
    drop(probe);
    UdpSocket::bind(local).await
}

async fn resolve(endpoint: &str, host: &str, port: u16) -> Result<SocketAddr, TransportError> {
    let mut addrs = tokio::net::lookup_host((host, port))
        .await
        .map_err(|source| TransportError::Io {
            endpoint: endpoint.to_owned(),
            op: "resolve",
            source,
        })?;
    addrs.next().ok_or_else(|| TransportError::Resolve {
        endpoint: endpoint.to_owned(),
        host: host.to_owned(),
    })
}

#[cfg(test)]
mod tests;
