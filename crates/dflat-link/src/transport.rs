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
//!   autopilot's HEARTBEAT); datagrams from any other address are dropped
//!   and counted ([`TransportCounters::foreign_datagrams`], said once in
//!   the log). Sends before there is a peer are dropped
//!   ([`SendOutcome::NoPeer`]).
//! * `udpout` binds the address of the interface that routes to `HOST:PORT`
//!   (ephemeral port) and `connect()`s the socket to it, so the kernel
//!   drops datagrams from any other sender. This is the daemon side.
//! * `tcpout` connects; with [`OpenOptions::reconnect`] a lost connection
//!   is re-established with [`Backoff`] (each reconnect logged and counted),
//!   otherwise it is [`TransportError::Closed`].
//! * `serial` opens the port with the mavlink crate's direct-serial
//!   transport (8N1, no flow control) in two blocking threads (reader,
//!   writer; the writer's queue is bounded, [`SERIAL_TX_QUEUE`], beyond it
//!   frames are dropped and counted). The mavlink reader verifies checksums
//!   itself and skips bad frames, so on serial links CRC failures are *not*
//!   counted; payload decoding errors still are. With
//!   [`OpenOptions::reconnect`] a port that closes is reopened with
//!   [`Backoff`].
//!
//! An optional [`TlogTap`] records every frame sent and received, with a µs
//! UNIX timestamp, in a `.tlog` file, written by its own thread so socket
//! tasks never wait on the disk.

use std::collections::VecDeque;
use std::fmt;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::str::FromStr;
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
use tokio::sync::{Mutex, mpsc, oneshot};

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
    /// Frames dropped because the serial writer's queue was full, or the
    /// link was down (TCP, serial reconnecting).
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

/// A parsed MAVLink connection string.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Endpoint {
    /// `udpin:HOST:PORT` — bind and reply to the last sender.
    UdpIn {
        /// Host name or address to bind (e.g. `0.0.0.0`, `127.0.0.1`).
        host: String,
        /// UDP port (0 = any free port, see [`Transport::local_addr`]).
        port: u16,
    },
    /// `udpout:HOST:PORT` — send to the address and receive replies.
    UdpOut {
        /// Host name or address of the peer.
        host: String,
        /// UDP port of the peer.
        port: u16,
    },
    /// `tcpout:HOST:PORT` — connect to a TCP server.
    TcpOut {
        /// Host name or address of the server.
        host: String,
        /// TCP port of the server.
        port: u16,
    },
    /// `serial:PATH:BAUD` — a serial port, 8N1.
    Serial {
        /// Device path, e.g. `/dev/ttyTHS2`.
        path: String,
        /// Baud rate \[bit/s\].
        baud: u32,
    },
}

impl Endpoint {
    /// Parses a connection string (see the variants). IPv6 hosts may be
    /// written in brackets: `udpout:[::1]:14540`.
    pub fn parse(url: &str) -> Result<Self, TransportError> {
        let bad = |reason: &str| TransportError::BadUrl {
            url: url.to_owned(),
            reason: format!(
                "{reason}; expected udpin:HOST:PORT, udpout:HOST:PORT, tcpout:HOST:PORT or serial:PATH:BAUD"
            ),
        };
        let url_trim = url.trim();
        let Some((scheme, rest)) = url_trim.split_once(':') else {
            return Err(bad("no `kind:` prefix"));
        };
        let Some((head, tail)) = rest.rsplit_once(':') else {
            return Err(bad("missing `:PORT` / `:BAUD`"));
        };
        if head.is_empty() {
            return Err(bad("empty host / path"));
        }
        let host = head
            .strip_prefix('[')
            .and_then(|h| h.strip_suffix(']'))
            .unwrap_or(head)
            .to_owned();
        let port = || {
            tail.parse::<u16>()
                .map_err(|_| bad(&format!("port `{tail}` is not an integer 0–65535")))
        };
        match scheme {
            "udpin" => Ok(Endpoint::UdpIn {
                host,
                port: port()?,
            }),
            "udpout" | "udp" => Ok(Endpoint::UdpOut {
                host,
                port: port()?,
            }),
            "tcpout" | "tcp" => Ok(Endpoint::TcpOut {
                host,
                port: port()?,
            }),
            "serial" => {
                let baud =
                    tail.parse::<u32>().ok().filter(|b| *b > 0).ok_or_else(|| {
                        bad(&format!("baud rate `{tail}` is not a positive integer"))
                    })?;
                Ok(Endpoint::Serial {
                    path: head.to_owned(),
                    baud,
                })
            }
            other => Err(bad(&format!("unknown kind `{other}`"))),
        }
    }

    fn host_port(host: &str, port: u16) -> String {
        if host.contains(':') {
            format!("[{host}]:{port}")
        } else {
            format!("{host}:{port}")
        }
    }
}

impl FromStr for Endpoint {
    type Err = TransportError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Endpoint::parse(s)
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::UdpIn { host, port } => write!(f, "udpin:{}", Self::host_port(host, *port)),
            Endpoint::UdpOut { host, port } => {
                write!(f, "udpout:{}", Self::host_port(host, *port))
            }
            Endpoint::TcpOut { host, port } => {
                write!(f, "tcpout:{}", Self::host_port(host, *port))
            }
            Endpoint::Serial { path, baud } => write!(f, "serial:{path}:{baud}"),
        }
    }
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
    },
}

/// Receive side state: a scratch buffer, the stream parser and a mirror of
/// the parser's unconsumed bytes (to tap frames byte-exactly).
struct RxState {
    buf: Vec<u8>,
    parser: FrameParser,
    mirror: Vec<u8>,
    pending: VecDeque<RecvEvent>,
}

impl RxState {
    fn new(buf_len: usize) -> Self {
        Self {
            buf: vec![0; buf_len],
            parser: FrameParser::new(),
            mirror: Vec::with_capacity(4 * MAX_FRAME_LEN),
            pending: VecDeque::with_capacity(16),
        }
    }

    /// Feeds `len` bytes of `self.buf` to the parser and queues the events.
    /// `complete`: the bytes are a whole datagram (no frame continues).
    fn ingest(
        &mut self,
        len: usize,
        complete: bool,
        arrival: Instant,
        from: Option<SocketAddr>,
        tap: Option<&TlogTap>,
    ) {
        let bytes = &self.buf[..len];
        // Keep the mirror equal to the parser's buffer after `push`.
        let keep = self.parser.pending();
        let drop_n = self.mirror.len().saturating_sub(keep);
        self.mirror.drain(..drop_n);
        self.mirror.extend_from_slice(bytes);
        let skipped_before = self.parser.skipped_bytes();
        let errors_before = self.errors_queued();
        self.parser.push(bytes);
        let ts = unix_time_us();
        while let Some(item) = self.parser.next_frame() {
            match item {
                Ok(frame) => {
                    if let Some(tap) = tap.filter(|t| t.inbound) {
                        let end = self.mirror.len().saturating_sub(self.parser.pending());
                        match self.mirror.get(end.saturating_sub(frame.len)..end) {
                            Some(raw) if raw.len() == frame.len => tap.record(ts, raw),
                            _ => tap.record_message(ts, &frame.header, &frame.message),
                        }
                    }
                    self.pending.push_back(RecvEvent::Frame(Box::new(Received {
                        header: frame.header,
                        message: frame.message,
                        arrival,
                        signed: frame.signed,
                        from,
                    })));
                }
                Err(e) => self.pending.push_back(RecvEvent::Error(e)),
            }
        }
        let skipped = self.parser.skipped_bytes() > skipped_before;
        if complete {
            // `finish` also resets the parser's counters.
            for item in self.parser.finish() {
                match item {
                    Ok(frame) => {
                        if let Some(tap) = tap.filter(|t| t.inbound) {
                            tap.record_message(ts, &frame.header, &frame.message);
                        }
                        self.pending.push_back(RecvEvent::Frame(Box::new(Received {
                            header: frame.header,
                            message: frame.message,
                            arrival,
                            signed: frame.signed,
                            from,
                        })));
                    }
                    Err(e) => self.pending.push_back(RecvEvent::Error(e)),
                }
            }
            self.mirror.clear();
        }
        // Bytes outside any frame candidate: one error per chunk, unless a
        // bad candidate in this chunk already explains them.
        if skipped && self.errors_queued() == errors_before {
            self.pending
                .push_back(RecvEvent::Error(FrameError::NoMarker));
        }
    }

    /// Forgets a partial frame (the stream was reconnected).
    fn reset_stream(&mut self) {
        self.parser = FrameParser::new();
        self.mirror.clear();
    }

    fn errors_queued(&self) -> usize {
        self.pending
            .iter()
            .filter(|e| matches!(e, RecvEvent::Error(_)))
            .count()
    }
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

mod serial {
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
}

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
    inbound: bool,
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
        let ts = unix_time_us();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tlog::TlogReader;
    use crate::{DaemonStatus, heartbeat_onboard};
    use std::time::Duration;

    fn hdr(sys: u8, comp: u8, seq: u8) -> MavHeader {
        crate::header(sys, comp, seq)
    }

    #[test]
    fn parses_connection_strings() {
        assert_eq!(
            Endpoint::parse("udpin:0.0.0.0:14540").unwrap(),
            Endpoint::UdpIn {
                host: "0.0.0.0".into(),
                port: 14540
            }
        );
        assert_eq!(
            Endpoint::parse("udpout:localhost:14550").unwrap(),
            Endpoint::UdpOut {
                host: "localhost".into(),
                port: 14550
            }
        );
        assert_eq!(
            Endpoint::parse("tcpout:[::1]:5760").unwrap(),
            Endpoint::TcpOut {
                host: "::1".into(),
                port: 5760
            }
        );
        assert_eq!(
            Endpoint::parse("serial:/dev/ttyTHS2:921600").unwrap(),
            Endpoint::Serial {
                path: "/dev/ttyTHS2".into(),
                baud: 921_600
            }
        );
        for s in [
            "udpin:0.0.0.0:14540",
            "udpout:[::1]:1",
            "serial:/dev/ttyUSB0:57600",
        ] {
            assert_eq!(Endpoint::parse(s).unwrap().to_string(), s);
        }
        for bad in [
            "",
            "udpin",
            "udpin:1.2.3.4",
            "udpin::5",
            "udpin:h:99999",
            "serial:/dev/x:0",
            "ftp:h:1",
        ] {
            let e = Endpoint::parse(bad).unwrap_err().to_string();
            assert!(e.contains("expected udpin"), "{bad}: {e}");
        }
    }

    async fn recv_frame(t: &Transport) -> Received {
        match tokio::time::timeout(Duration::from_secs(2), t.recv())
            .await
            .expect("timed out")
            .expect("recv")
        {
            RecvEvent::Frame(r) => *r,
            RecvEvent::Error(e) => panic!("unexpected frame error {e}"),
        }
    }

    #[tokio::test]
    async fn udp_round_trip_and_udpin_replies_to_last_sender() {
        let server = Transport::open(&Endpoint::parse("udpin:127.0.0.1:0").unwrap())
            .await
            .unwrap();
        let port = server.local_addr().unwrap().port();
        // No peer yet: dropped.
        let hb = heartbeat_onboard(DaemonStatus::Active);
        assert_eq!(
            server.send(&hdr(1, 1, 0), &hb).await.unwrap(),
            SendOutcome::NoPeer
        );
        let client =
            Transport::open(&Endpoint::parse(&format!("udpout:127.0.0.1:{port}")).unwrap())
                .await
                .unwrap();
        assert!(matches!(
            client.send(&hdr(1, 191, 7), &hb).await.unwrap(),
            SendOutcome::Sent(_)
        ));
        let got = recv_frame(&server).await;
        assert_eq!(got.header, hdr(1, 191, 7));
        assert_eq!(got.message, hb);
        assert_eq!(
            server.peer().map(|a| a.port()),
            client.local_addr().map(|a| a.port())
        );
        // Reply reaches the client.
        assert!(matches!(
            server.send(&hdr(1, 1, 3), &hb).await.unwrap(),
            SendOutcome::Sent(_)
        ));
        let back = recv_frame(&client).await;
        assert_eq!(back.header, hdr(1, 1, 3));
    }

    #[tokio::test]
    async fn garbage_and_bad_crc_are_reported() {
        let server = Transport::open(&Endpoint::parse("udpin:127.0.0.1:0").unwrap())
            .await
            .unwrap();
        let addr = server.local_addr().unwrap();
        let raw = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let hb = heartbeat_onboard(DaemonStatus::Standby);
        let good = crate::serialize_v2(&hdr(1, 1, 0), &hb).unwrap();
        let mut bad = good.as_bytes().to_vec();
        let n = bad.len();
        bad[n - 1] ^= 0xff; // corrupt the CRC
        raw.send_to(b"hello, not mavlink", addr).unwrap();
        raw.send_to(&bad, addr).unwrap();
        // Two frames in one datagram.
        let mut two = good.as_bytes().to_vec();
        two.extend_from_slice(good.as_bytes());
        raw.send_to(&two, addr).unwrap();
        let mut events = Vec::new();
        while let Ok(ev) = tokio::time::timeout(Duration::from_millis(300), server.recv()).await {
            events.push(ev.unwrap());
        }
        assert_eq!(events.len(), 4, "{events:?}");
        assert_eq!(events[0], RecvEvent::Error(FrameError::NoMarker));
        assert_eq!(events[1], RecvEvent::Error(FrameError::Crc { msg_id: 0 }));
        assert!(matches!(&events[2], RecvEvent::Frame(r) if r.message == hb));
        assert!(matches!(&events[3], RecvEvent::Frame(r) if r.message == hb));
    }

    #[tokio::test]
    async fn tcp_stream_split_across_reads() {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let port = listener.local_addr().unwrap().port();
        let client_task = tokio::spawn(async move {
            Transport::open(&Endpoint::parse(&format!("tcpout:127.0.0.1:{port}")).unwrap())
                .await
                .unwrap()
        });
        let (mut sock, _) = listener.accept().await.unwrap();
        let client = client_task.await.unwrap();
        let hb = heartbeat_onboard(DaemonStatus::Active);
        let frame = crate::serialize_v2(&hdr(1, 1, 9), &hb).unwrap();
        let bytes = frame.as_bytes();
        sock.write_all(&bytes[..5]).await.unwrap();
        sock.flush().await.unwrap();
        tokio::time::sleep(Duration::from_millis(20)).await;
        sock.write_all(&bytes[5..]).await.unwrap();
        let got = recv_frame(&client).await;
        assert_eq!(got.header.sequence, 9);
        client.send(&hdr(1, 191, 1), &hb).await.unwrap();
        let mut buf = vec![0u8; bytes.len()];
        sock.read_exact(&mut buf).await.unwrap();
        assert_eq!(crate::parse_frame(&buf).unwrap().message, hb);
        drop(sock);
        let end = tokio::time::timeout(Duration::from_secs(2), client.recv())
            .await
            .unwrap();
        assert!(matches!(end, Err(TransportError::Closed { .. })));
    }

    #[tokio::test]
    async fn tlog_tap_records_both_directions() {
        let dir = std::env::temp_dir().join(format!("dflat-tap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.tlog");
        let tap = TlogTap::create(&path).unwrap();
        let server = Transport::open_with_tap(
            &Endpoint::parse("udpin:127.0.0.1:0").unwrap(),
            Some(tap.clone()),
        )
        .await
        .unwrap();
        let port = server.local_addr().unwrap().port();
        let client =
            Transport::open(&Endpoint::parse(&format!("udpout:127.0.0.1:{port}")).unwrap())
                .await
                .unwrap();
        let hb = heartbeat_onboard(DaemonStatus::Active);
        let before = unix_time_us();
        client.send(&hdr(1, 191, 0), &hb).await.unwrap();
        recv_frame(&server).await;
        server.send(&hdr(1, 1, 0), &hb).await.unwrap();
        let report = tap.close().await.unwrap();
        assert_eq!(report.records, 2);
        assert_eq!(report.dropped, 0);
        let file = std::fs::File::open(&path).unwrap();
        let records: Vec<_> = TlogReader::new(std::io::BufReader::new(file))
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(records.len(), 2);
        assert_eq!(records[0].parse().unwrap().header, hdr(1, 191, 0));
        assert_eq!(records[1].parse().unwrap().header, hdr(1, 1, 0));
        assert!(records[0].timestamp_us >= before && records[1].timestamp_us >= before);
        // Closed: further records are dropped, a second close says so.
        tap.record(0, good_bytes().as_slice());
        assert!(tap.close().await.is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn good_bytes() -> Vec<u8> {
        crate::serialize_v2(&hdr(1, 1, 0), &heartbeat_onboard(DaemonStatus::Boot))
            .unwrap()
            .as_bytes()
            .to_vec()
    }

    #[tokio::test]
    async fn udpout_hears_only_its_peer() {
        let peer = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let client = Transport::open(
            &Endpoint::parse(&format!("udpout:{}", peer.local_addr().unwrap())).unwrap(),
        )
        .await
        .unwrap();
        let local = client.local_addr().unwrap();
        // Bound to the interface that routes to the peer (loopback here).
        assert!(local.ip().is_loopback(), "{local}");
        let hb = heartbeat_onboard(DaemonStatus::Active);
        let frame = crate::serialize_v2(&hdr(1, 1, 1), &hb).unwrap();
        let intruder = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        intruder.send_to(frame.as_bytes(), local).unwrap();
        peer.send_to(frame.as_bytes(), local).unwrap();
        let got = recv_frame(&client).await;
        assert_eq!(got.from, Some(peer.local_addr().unwrap()));
        // Nothing else arrives: the intruder's datagram never reached us.
        assert!(
            tokio::time::timeout(Duration::from_millis(200), client.recv())
                .await
                .is_err()
        );
    }

    #[tokio::test]
    async fn udpin_lock_drops_other_senders() {
        let server = Transport::open_with(
            &Endpoint::parse("udpin:127.0.0.1:0").unwrap(),
            OpenOptions {
                udpin_peer: UdpInPeer::Lock(None),
                ..OpenOptions::default()
            },
        )
        .await
        .unwrap();
        let addr = server.local_addr().unwrap();
        let hb = heartbeat_onboard(DaemonStatus::Active);
        assert!(server.awaiting_peer());
        assert_eq!(
            server.send(&hdr(1, 191, 0), &hb).await.unwrap(),
            SendOutcome::NoPeer
        );
        let autopilot = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let intruder = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let frame = crate::serialize_v2(&hdr(1, 1, 0), &hb).unwrap();
        autopilot.send_to(frame.as_bytes(), addr).unwrap();
        let first = recv_frame(&server).await;
        server.lock_peer(first.from.unwrap()).await.unwrap();
        assert!(!server.awaiting_peer());
        assert!(
            server
                .lock_peer(intruder.local_addr().unwrap())
                .await
                .is_err()
        );
        intruder.send_to(frame.as_bytes(), addr).unwrap();
        autopilot.send_to(frame.as_bytes(), addr).unwrap();
        let next = recv_frame(&server).await;
        assert_eq!(next.from, Some(autopilot.local_addr().unwrap()));
        // Replies go to the locked peer, not to the last sender.
        server.send(&hdr(1, 191, 1), &hb).await.unwrap();
        let mut buf = [0u8; 512];
        autopilot
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        assert!(autopilot.recv(&mut buf).unwrap() > 0);
        // A configured peer: locked from the start.
        let fixed = Transport::open_with(
            &Endpoint::parse("udpin:127.0.0.1:0").unwrap(),
            OpenOptions {
                udpin_peer: UdpInPeer::Lock(Some(autopilot.local_addr().unwrap())),
                ..OpenOptions::default()
            },
        )
        .await
        .unwrap();
        assert!(!fixed.awaiting_peer());
        let faddr = fixed.local_addr().unwrap();
        intruder.send_to(frame.as_bytes(), faddr).unwrap();
        autopilot.send_to(frame.as_bytes(), faddr).unwrap();
        let got = recv_frame(&fixed).await;
        assert_eq!(got.from, Some(autopilot.local_addr().unwrap()));
    }

    #[tokio::test]
    async fn tcp_reconnects_with_backoff() {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let port = listener.local_addr().unwrap().port();
        let client_task = tokio::spawn(async move {
            Transport::open_with(
                &Endpoint::parse(&format!("tcpout:127.0.0.1:{port}")).unwrap(),
                OpenOptions {
                    reconnect: true,
                    ..OpenOptions::default()
                },
            )
            .await
            .unwrap()
        });
        let (first, _) = listener.accept().await.unwrap();
        let client = client_task.await.unwrap();
        drop(first); // the server goes away
        let hb = heartbeat_onboard(DaemonStatus::Active);
        let frame = crate::serialize_v2(&hdr(1, 1, 4), &hb).unwrap();
        let server = tokio::spawn(async move {
            let (mut again, _) = listener.accept().await.unwrap();
            again.write_all(frame.as_bytes()).await.unwrap();
            again
        });
        let got = recv_frame(&client).await;
        assert_eq!(got.header.sequence, 4);
        assert_eq!(client.counters().reconnects, 1);
        drop(server.await.unwrap());
    }

    #[tokio::test]
    async fn serial_open_failure_is_an_error() {
        let e =
            Transport::open(&Endpoint::parse("serial:/dev/does-not-exist-dflat:57600").unwrap())
                .await
                .unwrap_err();
        assert!(
            e.to_string()
                .contains("serial:/dev/does-not-exist-dflat:57600"),
            "{e}"
        );
    }
}
