//! A ground station for the end-to-end tests: a UDP socket that sends from
//! system `id`, component 190, and keeps every frame it receives with its
//! arrival time.

use std::net::{SocketAddr, UdpSocket};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use dflat_link::{MavHeader, MavMessage, frames, serialize_v2};

/// Every frame received: arrival, header, message.
pub type Seen = Arc<Mutex<Vec<(Instant, MavHeader, MavMessage)>>>;

/// The ground station.
pub struct Gcs {
    socket: UdpSocket,
    to: SocketAddr,
    /// Its system id.
    pub id: u8,
    /// What it received (the receive thread ends with the last clone).
    pub seen: Seen,
    seq: u8,
}

impl Gcs {
    /// A ground station of system `id` talking to `to` (the SITL's GCS
    /// port); it sends a HEARTBEAT first, which makes it known there.
    pub fn new(to: SocketAddr, id: u8) -> Self {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let seen: Seen = Arc::default();
        let (rx, store) = (socket.try_clone().unwrap(), seen.clone());
        std::thread::spawn(move || {
            let mut buf = [0u8; 65_536];
            loop {
                match rx.recv_from(&mut buf) {
                    Ok((n, _)) => {
                        let mut s = store.lock().unwrap();
                        for f in frames(&buf[..n]).flatten() {
                            s.push((Instant::now(), f.header, f.message));
                        }
                    }
                    Err(e)
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                        ) => {}
                    Err(_) => break,
                }
                if Arc::strong_count(&store) == 1 {
                    break;
                }
            }
        });
        let mut gcs = Self {
            socket,
            to,
            id,
            seen,
            seq: 0,
        };
        gcs.send(&MavMessage::HEARTBEAT(Default::default()));
        gcs
    }

    /// Sends `msg` from (`id`, 190).
    pub fn send(&mut self, msg: &MavMessage) {
        let f = serialize_v2(&dflat_link::header(self.id, 190, self.seq), msg).unwrap();
        self.seq = self.seq.wrapping_add(1);
        self.socket.send_to(f.as_bytes(), self.to).unwrap();
    }

    /// Frames from `who` = (system, component) received after `since`
    /// matching `pick`.
    pub fn from<T>(
        &self,
        who: (u32, u8),
        since: Instant,
        pick: impl Fn(&MavMessage) -> Option<T>,
    ) -> Vec<T> {
        self.seen
            .lock()
            .unwrap()
            .iter()
            .filter(|(at, h, _)| *at >= since && (h.system_id, h.component_id) == who)
            .filter_map(|(_, _, m)| pick(m))
            .collect()
    }

    /// Waits up to 3 s for a frame from `who` after `since` matching `pick`.
    pub fn wait<T>(
        &self,
        who: (u32, u8),
        since: Instant,
        pick: impl Fn(&MavMessage) -> Option<T>,
    ) -> Option<T> {
        self.wait_for(who, since, Duration::from_secs(3), pick)
    }

    /// Waits up to `limit` for a frame from `who` after `since` matching
    /// `pick`.
    pub fn wait_for<T>(
        &self,
        who: (u32, u8),
        since: Instant,
        limit: Duration,
        pick: impl Fn(&MavMessage) -> Option<T>,
    ) -> Option<T> {
        let until = Instant::now() + limit;
        while Instant::now() < until {
            if let Some(t) = self.from(who, since, &pick).into_iter().next() {
                return Some(t);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        None
    }
}
