//! A serial line for the end-to-end tests, without socat: a pseudo-terminal
//! whose slave is the daemon's "serial port" (a symlink, as udev gives a
//! USB-serial adapter a stable name), bridged to the SITL's UDP port the way
//! a MAVLink router bridges a UART:
//!
//! * pty → UDP: the byte stream is cut into MAVLink frames, one datagram
//!   each (the SITL reads whole frames per datagram);
//! * UDP → pty: each datagram written as it came.
//!
//! [`PtyBridge::unplug`] closes the pty (the daemon's port hangs up, as when
//! an adapter is pulled) and removes the symlink; [`PtyBridge::replug`]
//! makes a new pty and points the symlink at it. With
//! [`PtyBridge::wrong_baud`] both directions go through a UART model of a
//! sender and a receiver at different rates ([`uart_resample`]): what a
//! port set to the wrong baud rate reads.
//!
//! Safe code only: nix's `openpty`, `tcsetattr`, `fcntl` and `poll`.

#![allow(dead_code)] // each test binary uses a subset

use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use nix::fcntl::{FcntlArg, FdFlag, OFlag, fcntl};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

/// One pseudo-terminal: the master (the bridge's end) and the slave (kept
/// open by the bridge so the master never reads EIO before the daemon
/// opens it).
struct Pty {
    master: File,
    _slave: OwnedFd,
    slave_path: PathBuf,
}

fn open_pty() -> Pty {
    let pty = nix::pty::openpty(None, None).expect("openpty");
    // openpty(3) leaves both ends inheritable: without FD_CLOEXEC the
    // daemon started after it would hold the master open, and closing the
    // bridge's end would not hang its port up.
    for fd in [&pty.master, &pty.slave] {
        fcntl(fd, FcntlArg::F_SETFD(FdFlag::FD_CLOEXEC)).expect("FD_CLOEXEC");
    }
    // Raw, no echo: bytes pass unchanged before the daemon sets the port up.
    let mut t = tcgetattr(&pty.slave).expect("tcgetattr");
    cfmakeraw(&mut t);
    tcsetattr(&pty.slave, SetArg::TCSANOW, &t).expect("tcsetattr");
    // Non-blocking master: bytes for a port nobody reads are dropped, as on
    // a UART, instead of blocking the bridge.
    fcntl(&pty.master, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).expect("O_NONBLOCK");
    let slave_path = nix::unistd::ttyname(&pty.slave).expect("ttyname");
    Pty {
        master: File::from(pty.master),
        _slave: pty.slave,
        slave_path,
    }
}

/// Whether this machine can make pseudo-terminals (a container without
/// `/dev/ptmx` cannot): the serial tests skip, saying so, where it cannot.
pub fn ptys_available() -> bool {
    nix::pty::openpty(None, None).is_ok()
}

/// Baud rates of the two ends when [`PtyBridge::wrong_baud`] is set: the
/// autopilot's side (`from`) and the daemon's (`to`).
#[derive(Debug, Clone, Copy)]
pub struct BaudMismatch {
    /// The autopilot's port rate \[bit/s\].
    pub autopilot: u32,
    /// The daemon's port rate \[bit/s\].
    pub daemon: u32,
}

struct Shared {
    pty: Mutex<Option<Arc<Pty>>>,
    stop: AtomicBool,
    mismatch: Option<BaudMismatch>,
    /// Bytes written to the pty (SITL → daemon).
    to_daemon: AtomicU64,
    /// Frames sent to the SITL (daemon → SITL).
    to_sitl: AtomicU64,
}

/// The bridge: a pty at `link` (a symlink) ⇄ the SITL's UDP port.
pub struct PtyBridge {
    /// The symlink the daemon opens (`serial:LINK:BAUD`).
    pub link: PathBuf,
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

impl PtyBridge {
    /// A bridge from a new pty, linked at `link`, to the SITL at `sitl`.
    pub fn start(link: &Path, sitl: SocketAddr) -> Self {
        Self::start_with(link, sitl, None)
    }

    /// As [`start`](Self::start), both directions garbled as by a baud-rate
    /// mismatch.
    pub fn wrong_baud(link: &Path, sitl: SocketAddr, mismatch: BaudMismatch) -> Self {
        Self::start_with(link, sitl, Some(mismatch))
    }

    fn start_with(link: &Path, sitl: SocketAddr, mismatch: Option<BaudMismatch>) -> Self {
        let socket = Arc::new(UdpSocket::bind("127.0.0.1:0").expect("bind bridge socket"));
        socket.connect(sitl).expect("connect to the SITL");
        socket
            .set_read_timeout(Some(Duration::from_millis(20)))
            .expect("timeout");
        let shared = Arc::new(Shared {
            pty: Mutex::new(None),
            stop: AtomicBool::new(false),
            mismatch,
            to_daemon: AtomicU64::new(0),
            to_sitl: AtomicU64::new(0),
        });
        let bridge = Self {
            link: link.to_owned(),
            shared: shared.clone(),
            threads: Vec::new(),
        };
        bridge.plug();
        let (s1, sock1) = (shared.clone(), socket.clone());
        let (s2, sock2) = (shared, socket);
        let mut bridge = bridge;
        bridge
            .threads
            .push(std::thread::spawn(move || pty_to_udp(&s1, &sock1)));
        bridge
            .threads
            .push(std::thread::spawn(move || udp_to_pty(&s2, &sock2)));
        bridge
    }

    fn plug(&self) {
        let pty = open_pty();
        let _ = std::fs::remove_file(&self.link);
        std::os::unix::fs::symlink(&pty.slave_path, &self.link).expect("symlink the pty");
        *self.shared.pty.lock().unwrap() = Some(Arc::new(pty));
    }

    /// Pulls the "adapter": the symlink goes, the pty closes (the daemon's
    /// port hangs up). Returns when the master is closed.
    pub fn unplug(&self) {
        let _ = std::fs::remove_file(&self.link);
        let pty = self.shared.pty.lock().unwrap().take();
        if let Some(mut pty) = pty {
            // The bridge's threads hold a clone for at most one poll (20 ms).
            loop {
                match Arc::try_unwrap(pty) {
                    Ok(p) => {
                        drop(p);
                        break;
                    }
                    Err(p) => {
                        pty = p;
                        std::thread::sleep(Duration::from_millis(1));
                    }
                }
            }
        }
    }

    /// Plugs a new "adapter" in: a new pty behind the same symlink. Returns
    /// the moment it is there, in µs since the UNIX epoch (the clock of the
    /// daemon's `.tlog`).
    pub fn replug(&self) -> u64 {
        self.plug();
        unix_us()
    }

    /// Bytes written to the daemon's pty so far.
    pub fn bytes_to_daemon(&self) -> u64 {
        self.shared.to_daemon.load(Ordering::Relaxed)
    }

    /// Datagrams sent to the SITL so far.
    pub fn frames_to_sitl(&self) -> u64 {
        self.shared.to_sitl.load(Ordering::Relaxed)
    }
}

impl Drop for PtyBridge {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.link);
    }
}

/// Microseconds since the UNIX epoch.
pub fn unix_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

fn current(shared: &Shared) -> Option<Arc<Pty>> {
    shared.pty.lock().unwrap().clone()
}

fn pty_to_udp(shared: &Shared, socket: &UdpSocket) {
    let mut buf = [0u8; 4096];
    let mut pending: Vec<u8> = Vec::with_capacity(8192);
    while !shared.stop.load(Ordering::Relaxed) {
        let Some(pty) = current(shared) else {
            pending.clear();
            std::thread::sleep(Duration::from_millis(5));
            continue;
        };
        let mut fds = [PollFd::new(pty.master.as_fd(), PollFlags::POLLIN)];
        if !matches!(poll(&mut fds, PollTimeout::from(20u16)), Ok(n) if n > 0) {
            continue;
        }
        let n = match (&pty.master).read(&mut buf) {
            Ok(n) if n > 0 => n,
            // EIO: no slave open (between the daemon's close and reopen).
            _ => {
                drop(pty);
                std::thread::sleep(Duration::from_millis(5));
                continue;
            }
        };
        drop(pty);
        if let Some(m) = shared.mismatch {
            // Garbage to the SITL, as its UART would read it.
            let garbled = uart_resample(&buf[..n], m.daemon, m.autopilot);
            if !garbled.is_empty() && socket.send(&garbled).is_ok() {
                shared.to_sitl.fetch_add(1, Ordering::Relaxed);
            }
            continue;
        }
        pending.extend_from_slice(&buf[..n]);
        while let Some(len) = next_frame(&mut pending) {
            if socket.send(&pending[..len]).is_ok() {
                shared.to_sitl.fetch_add(1, Ordering::Relaxed);
            }
            pending.drain(..len);
        }
    }
}

fn udp_to_pty(shared: &Shared, socket: &UdpSocket) {
    let mut buf = [0u8; 65536];
    while !shared.stop.load(Ordering::Relaxed) {
        let n = match socket.recv(&mut buf) {
            Ok(n) => n,
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => continue,
            Err(_) => {
                std::thread::sleep(Duration::from_millis(5));
                continue;
            }
        };
        let Some(pty) = current(shared) else {
            continue; // unplugged: the bytes are lost, as on a dead UART
        };
        let bytes = match shared.mismatch {
            Some(m) => uart_resample(&buf[..n], m.autopilot, m.daemon),
            None => buf[..n].to_vec(),
        };
        // Non-blocking: a full buffer (nobody reading) drops the bytes.
        if (&pty.master).write_all(&bytes).is_ok() {
            shared
                .to_daemon
                .fetch_add(bytes.len() as u64, Ordering::Relaxed);
        }
    }
}

/// Drops bytes before the next start marker and returns the length of the
/// complete MAVLink 1 or 2 frame at the start of `pending`, if there is one.
fn next_frame(pending: &mut Vec<u8>) -> Option<usize> {
    let start = pending.iter().position(|&b| b == 0xFD || b == 0xFE)?;
    pending.drain(..start);
    let len = match pending[0] {
        0xFD => {
            let payload = *pending.get(1)? as usize;
            let signed = pending.get(2)? & 0x01 != 0;
            10 + payload + 2 + if signed { 13 } else { 0 }
        }
        _ => 6 + *pending.get(1)? as usize + 2,
    };
    (pending.len() >= len).then_some(len)
}

/// What a UART receiving at `rx_baud` reads from a line driven at
/// `tx_baud` (8N1, idle high, the sender's bytes back to back): the
/// receiver waits for a falling edge, samples the middle of each of its
/// own bit times, and, as Linux does for a framing error (stop bit low,
/// no `IGNPAR` / `PARMRK`), delivers a byte it could not frame as `0x00`.
pub fn uart_resample(bytes: &[u8], tx_baud: u32, rx_baud: u32) -> Vec<u8> {
    // The line, one level per sender bit.
    let mut line = Vec::with_capacity(bytes.len() * 10 + 10);
    for &b in bytes {
        line.push(false);
        line.extend((0..8).map(|i| b >> i & 1 == 1));
        line.push(true);
    }
    line.push(true);
    let level = |t: f64| -> bool {
        let i = t.floor();
        if i < 0.0 {
            return true;
        }
        line.get(i as usize).copied().unwrap_or(true)
    };
    // One receiver bit in sender bits.
    let r = f64::from(tx_baud) / f64::from(rx_baud);
    let end = line.len() as f64;
    let step = r.min(1.0) / 4.0;
    let mut out = Vec::new();
    let mut t = 0.0;
    while t < end {
        if level(t) {
            t += step;
            continue;
        }
        // Falling edge at t: sample the middle of each bit.
        let sample = |k: f64| level(t + (k + 0.5) * r);
        let mut byte = 0u8;
        for i in 0..8 {
            if sample(1.0 + f64::from(i)) {
                byte |= 1 << i;
            }
        }
        let framed = !sample(0.0) && sample(9.0);
        out.push(if framed { byte } else { 0 });
        // The receiver looks for the next start bit after its stop bit.
        t += 9.5 * r;
        while t < end && !level(t) {
            t += step;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_rate_is_the_identity() {
        let bytes: Vec<u8> = (0..=255).collect();
        assert_eq!(uart_resample(&bytes, 921_600, 921_600), bytes);
    }

    #[test]
    fn a_slow_sender_reads_as_garbage() {
        let frame = [0xFD, 9, 0, 0, 0, 1, 1, 0, 0, 0];
        let read = uart_resample(&frame, 57_600, 921_600);
        assert!(read.len() > frame.len());
        assert!(!read.contains(&0xFD));
    }
}
