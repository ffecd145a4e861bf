//! The SITL's links: the vehicle link and the optional ground-station
//! port, the receive threads of both, what is routed where, and how the
//! SITL sends its own frames.
//!
//! Routing, as PX4 does it:
//! * vehicle link → GCS: every frame except those addressed to the
//!   SITL's own system and component;
//! * GCS → vehicle link: every frame except those addressed to the SITL's
//!   own system and component (handled here, [`super::services`], counted
//!   in `gcs_frames_kept`); broadcasts are handled *and* routed;
//! * the SITL's telemetry goes to both; its answers go back on the link
//!   the request came from.
//!
//! Signed frames are routed as received (their bytes, signature
//! included); the SITL verifies the vehicle link only, the daemon verifies
//! what the GCS sends it.

use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::Ordering;
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime};

use dflat_link::command::Addressing;
use dflat_link::{
    Frame, Inbound, LinkRx, MavHeader, MavMessage, RxOutcome, euler_from_quaternion, frames,
    serialize_v2, timestamp_from_system_time,
};

use super::counters::{Kind, bump};
use super::{RX_POLL, ReceivedCommand, Shared, SitlError, TapFrame, lock, services};

/// One of the SITL's two links.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) enum Link {
    /// The vehicle link (the daemon).
    Vehicle,
    /// The ground-station port.
    Gcs,
}

/// Where one of the SITL's own frames goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Dest {
    /// Both links (telemetry).
    Both,
    /// One link (an answer).
    Only(Link),
}

/// The sockets and their last peers.
pub(super) struct Links {
    pub(super) vehicle: Arc<UdpSocket>,
    pub(super) gcs: Option<Arc<UdpSocket>>,
    pub(super) peers: Mutex<Peers>,
}

/// The last sender on each link (`udpin` replies to it).
#[derive(Default)]
pub(super) struct Peers {
    pub(super) vehicle: Option<SocketAddr>,
    pub(super) gcs: Option<SocketAddr>,
}

impl Links {
    fn socket_and_peer(&self, link: Link) -> Option<(&UdpSocket, SocketAddr)> {
        let peers = lock(&self.peers);
        match link {
            Link::Vehicle => Some((&*self.vehicle, peers.vehicle?)),
            Link::Gcs => Some((self.gcs.as_deref()?, peers.gcs?)),
        }
    }
}

impl Shared {
    /// Sends the SITL's own `msg` (signed when signing is on) to `dest`,
    /// counted per destination as `kind`. True when it went to the vehicle
    /// link.
    pub(super) fn send_own(&self, msg: &MavMessage, dest: Dest, kind: Kind) -> bool {
        let frame = match self.encode(msg) {
            Ok(f) => f,
            Err(_) => {
                bump(&self.counters.send_errors);
                return false;
            }
        };
        let mut to_vehicle = false;
        for link in [Link::Vehicle, Link::Gcs] {
            if dest != Dest::Both && dest != Dest::Only(link) {
                continue;
            }
            let Some((socket, peer)) = self.links.socket_and_peer(link) else {
                continue;
            };
            match socket.send_to(frame.as_bytes(), peer) {
                Ok(_) if link == Link::Vehicle => {
                    to_vehicle = true;
                    self.counters.to_vehicle.count(kind);
                }
                Ok(_) => self.counters.to_gcs.count(kind),
                Err(_) => bump(&self.counters.send_errors),
            }
        }
        to_vehicle
    }

    /// `msg` from another sender on this machine (`header`: the planner's
    /// ids) to the vehicle link's peer (the daemon). Whether it left.
    pub(super) fn send_to_vehicle_as(&self, header: MavHeader, msg: &MavMessage) -> bool {
        let Ok(frame) = self.encode_as(header, msg) else {
            bump(&self.counters.send_errors);
            return false;
        };
        let Some((socket, peer)) = self.links.socket_and_peer(Link::Vehicle) else {
            return false;
        };
        match socket.send_to(frame.as_bytes(), peer) {
            Ok(_) => true,
            Err(_) => {
                bump(&self.counters.send_errors);
                false
            }
        }
    }

    /// Whom `msg` addresses, seen from the SITL (`None`: no target).
    pub(super) fn addressing(&self, msg: &MavMessage) -> Option<Addressing> {
        use dflat_link::mavlink::Message as _;
        let system = msg.target_system_id()?;
        let component = msg.target_component_id().unwrap_or(0);
        Some(Addressing::of(
            system,
            component,
            (self.system_id, self.component_id),
        ))
    }
}

/// Receives from `socket` with the poll timeout; `None` on a timeout or a
/// transient error.
fn recv(socket: &UdpSocket, buf: &mut [u8]) -> Option<(usize, SocketAddr)> {
    match socket.recv_from(buf) {
        Ok(x) => Some(x),
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock
                    | std::io::ErrorKind::TimedOut
                    | std::io::ErrorKind::Interrupted
                    | std::io::ErrorKind::ConnectionRefused
                    | std::io::ErrorKind::ConnectionReset
            ) =>
        {
            None
        }
        Err(e) => {
            tracing::warn!(error = %e, "sitl: receive failed");
            std::thread::sleep(RX_POLL);
            None
        }
    }
}

/// Appends a received frame to a datagram being routed on: a signed frame
/// as its bytes (re-serializing would strip the signature), an unsigned one
/// re-serialized as MAVLink 2.
fn append_routed(out: &mut Vec<u8>, frame: &Frame) {
    match &frame.signed {
        Some(signed) => out.extend_from_slice(signed.as_bytes()),
        None => {
            if let Ok(enc) = serialize_v2(&frame.header, &frame.message) {
                out.extend_from_slice(enc.as_bytes());
            }
        }
    }
}

/// Receives on the vehicle link: commands in, requests answered, routing
/// to the GCS.
pub(super) struct VehicleRx {
    pub(super) shared: Arc<Shared>,
    pub(super) link: LinkRx,
    pub(super) tap: Option<Sender<TapFrame>>,
    pub(super) hover_thrust: f64,
}

impl VehicleRx {
    pub(super) fn run(mut self) -> Result<(), SitlError> {
        let mut buf = vec![0u8; 65_536];
        let mut forward = Vec::with_capacity(4096);
        let socket = self.shared.links.vehicle.clone();
        while !self.shared.stop.load(Ordering::Relaxed) {
            let Some((n, from)) = recv(&socket, &mut buf) else {
                continue;
            };
            let at = Instant::now();
            lock(&self.shared.links.peers).vehicle = Some(from);
            forward.clear();
            let mut routed = 0;
            for item in frames(&buf[..n]) {
                let frame = match item {
                    Ok(f) => f,
                    Err(e) => {
                        bump(&self.shared.counters.frame_errors);
                        tracing::debug!(error = %e, "sitl: bad frame");
                        continue;
                    }
                };
                bump(&self.shared.counters.frames_received);
                if let Some(tap) = &self.tap {
                    // A closed tap only means nobody listens any more.
                    let _ = tap.send(TapFrame {
                        at,
                        header: frame.header,
                        message: frame.message.clone(),
                    });
                }
                if !self.authenticate(&frame) {
                    continue;
                }
                self.handle(at, &frame.header, &frame.message);
                let addressing =
                    services::serve(&self.shared, Link::Vehicle, &frame.header, &frame.message);
                if self.shared.links.gcs.is_some() && addressing != Some(Addressing::ToUs) {
                    append_routed(&mut forward, &frame);
                    routed += 1;
                }
            }
            if routed > 0
                && let Some((gs, peer)) = self.shared.links.socket_and_peer(Link::Gcs)
            {
                match gs.send_to(&forward, peer) {
                    Ok(_) => {
                        self.shared
                            .counters
                            .gcs_frames_routed
                            .fetch_add(routed, Ordering::Relaxed);
                    }
                    Err(_) => bump(&self.shared.counters.send_errors),
                }
            }
        }
        Ok(())
    }

    /// The signing gate ([`LinkRx::authenticate`]): `true` to go on with
    /// the frame. With signing off everything passes; with signing on a
    /// wrong signature or a replayed timestamp is refused for every
    /// message, a missing one for commands (and for everything if the
    /// signing's `accept_unsigned_telemetry` is off). A refused
    /// SET_ATTITUDE_TARGET is counted in `commands_unauthenticated`.
    fn authenticate(&mut self, frame: &Frame) -> bool {
        if self.link.signing.is_none() {
            return true;
        }
        let now = timestamp_from_system_time(SystemTime::now());
        match self
            .link
            .authenticate(&frame.header, &frame.message, frame.signed.as_ref(), now)
        {
            Ok(()) => true,
            Err(check) => {
                if matches!(frame.message, MavMessage::SET_ATTITUDE_TARGET(_)) {
                    bump(&self.shared.counters.commands_unauthenticated);
                    tracing::debug!(?check, "sitl: command refused by signing");
                }
                false
            }
        }
    }

    fn handle(&mut self, at: Instant, header: &MavHeader, msg: &MavMessage) {
        let is_command = matches!(msg, MavMessage::SET_ATTITUDE_TARGET(_));
        let counters = &self.shared.counters;
        match self.link.handle(header, msg) {
            RxOutcome::Accepted(Inbound::AttitudeTarget(t)) => {
                let Some(q) = t.q else {
                    bump(&counters.commands_rejected);
                    return;
                };
                let [roll, pitch, yaw] = euler_from_quaternion(q);
                let thrust = t.thrust.unwrap_or(self.hover_thrust);
                if !(roll.is_finite() && pitch.is_finite() && yaw.is_finite()) {
                    bump(&counters.commands_rejected);
                    return;
                }
                *lock(&self.shared.command) = Some((
                    at,
                    ReceivedCommand {
                        roll,
                        pitch,
                        yaw,
                        thrust: thrust.clamp(0.0, 1.0),
                    },
                ));
                bump(&counters.commands_accepted);
                self.shared.latency.command(at);
            }
            RxOutcome::Accepted(_) => {}
            RxOutcome::Ignored(_) if is_command => bump(&counters.commands_ignored),
            RxOutcome::Rejected(e) if is_command => {
                tracing::debug!(error = %e, "sitl: command rejected");
                bump(&counters.commands_rejected);
            }
            RxOutcome::Ignored(_) | RxOutcome::Rejected(_) => {}
        }
    }
}

/// Receives on the GCS port: requests to the SITL answered, the rest
/// routed to the vehicle link.
pub(super) struct GcsRx {
    pub(super) shared: Arc<Shared>,
    pub(super) socket: Arc<UdpSocket>,
}

impl GcsRx {
    pub(super) fn run(self) -> Result<(), SitlError> {
        let mut buf = vec![0u8; 65_536];
        let mut forward = Vec::with_capacity(4096);
        while !self.shared.stop.load(Ordering::Relaxed) {
            let Some((n, from)) = recv(&self.socket, &mut buf) else {
                continue;
            };
            lock(&self.shared.links.peers).gcs = Some(from);
            forward.clear();
            for item in frames(&buf[..n]) {
                let frame = match item {
                    Ok(f) => f,
                    Err(_) => {
                        bump(&self.shared.counters.frame_errors);
                        continue;
                    }
                };
                bump(&self.shared.counters.gcs_frames_in);
                let addressing =
                    services::serve(&self.shared, Link::Gcs, &frame.header, &frame.message);
                if addressing == Some(Addressing::ToUs) {
                    bump(&self.shared.counters.gcs_frames_kept);
                } else {
                    append_routed(&mut forward, &frame);
                }
            }
            let peer = lock(&self.shared.links.peers).vehicle;
            if let Some(peer) = peer
                && !forward.is_empty()
                && self.shared.links.vehicle.send_to(&forward, peer).is_err()
            {
                bump(&self.shared.counters.send_errors);
            }
        }
        Ok(())
    }
}
