//! The SITL's links: the vehicle link and the optional ground-station
//! port, the receive threads of both (they pass commands and requests to
//! the step, [`super::step`], through the input channel), what is routed
//! where, and how the plant thread sends what the step returns
//! ([`Outbox`]).
//!
//! Routing, as PX4 does it:
//! * vehicle link → GCS: every frame except those addressed to the
//!   SITL's own system and component;
//! * GCS → vehicle link: every frame except those addressed to the SITL's
//!   own system and component (handled by the step,
//!   [`super::step::SitlInput::Frame`], counted in `gcs_frames_kept`);
//!   broadcasts are handled *and* routed;
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
    Frame, Inbound, LinkRx, MavMessage, RxOutcome, Signing, euler_from_quaternion, frames,
    serialize_v2, timestamp_from_system_time,
};

use super::counters::bump;
use super::step::{Dest, Link, Origin, Outgoing, SitlInput, addressing, served};
use super::{RX_POLL, ReceivedCommand, Shared, SitlError, TapFrame, lock};

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

/// The sending side of the plant thread: encodes (and signs, when signing
/// is on) what the step returns and sends it to its links' peers.
pub(super) struct Outbox {
    pub(super) shared: Arc<Shared>,
    /// Signing of outgoing frames (`None` = unsigned).
    pub(super) signing: Option<Signing>,
    /// The SITL's (system, component).
    pub(super) own: (u8, u8),
    /// The SITL's own sequence.
    pub(super) seq: u8,
}

impl Outbox {
    /// Sends `out`: the SITL's own frames (with its header and next
    /// sequence) to their destinations, counted per destination and kind;
    /// the planner's with its header to the vehicle link, counted in
    /// `planner_samples`. True when it went to the vehicle link.
    pub(super) fn send(&mut self, out: &Outgoing) -> bool {
        let header = match out.origin {
            Origin::Own(_) => {
                let h = dflat_link::header(self.own.0, self.own.1, self.seq);
                self.seq = self.seq.wrapping_add(1);
                h
            }
            Origin::Planner(h) => h,
        };
        let counters = &self.shared.counters;
        let encoded = match &mut self.signing {
            Some(s) => {
                let now = timestamp_from_system_time(SystemTime::now());
                s.sign(&header, &out.message, now)
            }
            None => serialize_v2(&header, &out.message),
        };
        let Ok(frame) = encoded else {
            bump(&counters.send_errors);
            return false;
        };
        let mut to_vehicle = false;
        for link in [Link::Vehicle, Link::Gcs] {
            if out.to != Dest::Both && out.to != Dest::Only(link) {
                continue;
            }
            let Some((socket, peer)) = self.shared.links.socket_and_peer(link) else {
                continue;
            };
            match (socket.send_to(frame.as_bytes(), peer), out.origin) {
                (Err(_), _) => bump(&counters.send_errors),
                (Ok(_), Origin::Own(kind)) if link == Link::Vehicle => {
                    to_vehicle = true;
                    counters.to_vehicle.count(kind);
                }
                (Ok(_), Origin::Own(kind)) => counters.to_gcs.count(kind),
                (Ok(_), Origin::Planner(_)) => {
                    to_vehicle |= link == Link::Vehicle;
                    bump(&counters.planner_samples);
                }
            }
        }
        to_vehicle
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

/// Seconds from the SITL's start to `at` (its clock).
fn sitl_time(shared: &Shared, at: Instant) -> f64 {
    at.saturating_duration_since(shared.start).as_secs_f64()
}

/// Receives on the vehicle link: commands and requests to the plant
/// thread's step, routing to the GCS.
pub(super) struct VehicleRx {
    pub(super) shared: Arc<Shared>,
    pub(super) link: LinkRx,
    pub(super) tap: Option<Sender<TapFrame>>,
    pub(super) hover_thrust: f64,
    /// The SITL's (system, component).
    pub(super) own: (u8, u8),
    /// Into the step.
    pub(super) inputs: Sender<SitlInput>,
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
                self.handle(at, &frame);
                let addressing = addressing(self.own, &frame.message);
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

    /// A SET_ATTITUDE_TARGET decoded into the step (counted accepted,
    /// ignored or rejected); a request to the autopilot passed on to it.
    fn handle(&mut self, at: Instant, frame: &Frame) {
        let (header, msg) = (&frame.header, &frame.message);
        if served(self.own, header, msg) {
            // A closed channel only means the plant thread has stopped.
            let _ = self.inputs.send(SitlInput::Frame {
                at: sitl_time(&self.shared, at),
                link: Link::Vehicle,
                header: *header,
                message: Box::new(msg.clone()),
            });
        }
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
                let _ = self.inputs.send(SitlInput::Command {
                    at: sitl_time(&self.shared, at),
                    command: ReceivedCommand {
                        roll,
                        pitch,
                        yaw,
                        thrust: thrust.clamp(0.0, 1.0),
                    },
                });
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

/// Receives on the GCS port: requests to the SITL passed to the step, the
/// rest routed to the vehicle link.
pub(super) struct GcsRx {
    pub(super) shared: Arc<Shared>,
    pub(super) socket: Arc<UdpSocket>,
    /// The SITL's (system, component).
    pub(super) own: (u8, u8),
    /// Into the step.
    pub(super) inputs: Sender<SitlInput>,
}

impl GcsRx {
    pub(super) fn run(self) -> Result<(), SitlError> {
        let mut buf = vec![0u8; 65_536];
        let mut forward = Vec::with_capacity(4096);
        while !self.shared.stop.load(Ordering::Relaxed) {
            let Some((n, from)) = recv(&self.socket, &mut buf) else {
                continue;
            };
            let at = sitl_time(&self.shared, Instant::now());
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
                if served(self.own, &frame.header, &frame.message) {
                    let _ = self.inputs.send(SitlInput::Frame {
                        at,
                        link: Link::Gcs,
                        header: frame.header,
                        message: Box::new(frame.message.clone()),
                    });
                }
                if addressing(self.own, &frame.message) == Some(Addressing::ToUs) {
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
