//! The mission protocol, the daemon's side, as a pure state machine: the
//! messages in with their time, the answers out; [`MissionProtocol::poll`]
//! runs the timeouts. Time is seconds on any monotonic clock.
//!
//! * Upload: MISSION_COUNT(n) → MISSION_REQUEST_INT(0) … each
//!   MISSION_ITEM_INT(i) is checked ([`super::parse_item`]) and the next
//!   one requested → MISSION_ACK(ACCEPTED) and the new mission replaces the
//!   stored one. An item not answered within [`ITEM_TIMEOUT`] is requested
//!   again, at most [`MAX_RETRIES`] times; then the upload is cancelled
//!   (MISSION_ACK OPERATION_CANCELLED). A refused item ends the upload with
//!   MISSION_ACK (UNSUPPORTED, UNSUPPORTED_FRAME, INVALID_PARAMx) and a
//!   STATUSTEXT. In every failure the stored mission — and the one being
//!   flown — stays as it was. An item out of sequence is ignored (the
//!   expected one is requested again); a MISSION_COUNT from the same
//!   sender during an upload restarts it (its MISSION_ACK was lost);
//!   another sender gets MISSION_ACK DENIED while an upload runs.
//!   MISSION_COUNT(0) clears the mission.
//! * Download: MISSION_REQUEST_LIST → MISSION_COUNT; MISSION_REQUEST_INT(i)
//!   → MISSION_ITEM_INT(i) (the legacy MISSION_REQUEST → MISSION_ITEM); a
//!   sequence beyond the mission → MISSION_ACK INVALID_SEQUENCE. Nothing
//!   is held between requests, so a download has nothing to time out.
//! * MISSION_CLEAR_ALL → MISSION_ACK(ACCEPTED), the mission cleared.
//! * Only mission type MISSION (and ALL for a clear): FENCE and RALLY get
//!   MISSION_ACK UNSUPPORTED.
//!
//! Messages addressed to another component, or broadcast (component 0),
//! are not answered: the autopilot keeps its own mission.

use dflat_link::MavMessage;
use dflat_link::dialect::{MavMissionResult, MavMissionType};
use dflat_link::mission::{
    ItemFields, MissionMessage, mission_ack, mission_count, mission_item, mission_item_int,
    mission_request_int,
};

use super::items::{ItemRules, Mission, parse_item};

/// How long the daemon waits for a requested item before asking again \[s\]
/// (the specification's default item timeout, 1500 ms in PX4).
pub const ITEM_TIMEOUT: f64 = 1.5;
/// How many times an item is requested again before the upload is
/// cancelled.
pub const MAX_RETRIES: u32 = 5;
/// Most items a mission may have.
pub const MAX_ITEMS: u16 = 500;

/// What a message (or a timeout) changed, besides the answers.
#[derive(Debug, Clone, PartialEq)]
pub enum MissionChange {
    /// A complete upload was accepted: the new mission.
    Uploaded(Mission),
    /// The mission was cleared (MISSION_CLEAR_ALL, or MISSION_COUNT 0).
    Cleared,
}

/// What the daemon answers, and what changed.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Reply {
    /// Messages to send, in order.
    pub messages: Vec<MavMessage>,
    /// STATUSTEXTs to send (≤ 50 bytes each).
    pub texts: Vec<String>,
    /// The stored mission changed.
    pub change: Option<MissionChange>,
}

impl Reply {
    fn send(mut self, m: MavMessage) -> Self {
        self.messages.push(m);
        self
    }
}

/// An upload in progress.
#[derive(Debug, Clone, PartialEq)]
struct Upload {
    /// Who sends it (system, component).
    partner: (u8, u8),
    /// Items announced.
    count: u16,
    /// Items received so far (read and raw).
    mission: Mission,
    /// When the pending request was sent \[s\].
    requested_at: f64,
    /// Requests of the pending item so far beyond the first.
    retries: u32,
}

impl Upload {
    fn next(&self) -> u16 {
        self.mission.raw.len() as u16
    }
}

/// Counters of the protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProtocolCounts {
    /// Uploads accepted.
    pub uploads: u64,
    /// Uploads that failed (refused item, timeout, denied).
    pub failed_uploads: u64,
    /// Items requested again after a timeout.
    pub retries: u64,
    /// Items served on download.
    pub items_served: u64,
}

/// The daemon's mission store and protocol (see the module docs).
#[derive(Debug, Clone)]
pub struct MissionProtocol {
    own: (u8, u8),
    rules: ItemRules,
    stored: Mission,
    upload: Option<Upload>,
    counts: ProtocolCounts,
}

const MISSION: MavMissionType = MavMissionType::MAV_MISSION_TYPE_MISSION;

impl MissionProtocol {
    /// An empty store for the component `own` = (system, component).
    pub fn new(own: (u8, u8), rules: ItemRules) -> Self {
        Self {
            own,
            rules,
            stored: Mission::default(),
            upload: None,
            counts: ProtocolCounts::default(),
        }
    }

    /// The stored mission.
    pub fn mission(&self) -> &Mission {
        &self.stored
    }

    /// True while an upload runs.
    pub fn uploading(&self) -> bool {
        self.upload.is_some()
    }

    /// The counters so far.
    pub fn counts(&self) -> ProtocolCounts {
        self.counts
    }

    /// One received message from `sender` = (system, component) at `now`
    /// \[s\]. Messages that are not the mission protocol's, or not
    /// addressed to this component, get an empty reply.
    pub fn handle(&mut self, msg: &MavMessage, sender: (u8, u8), now: f64) -> Reply {
        let Some((message, target)) = MissionMessage::from_message(msg) else {
            return Reply::default();
        };
        if target != self.own {
            return Reply::default();
        }
        let reply = Reply::default();
        match message {
            MissionMessage::Count {
                count,
                mission_type,
            } => {
                if mission_type != MISSION {
                    return reply.send(unsupported(sender, mission_type));
                }
                if let Some(u) = &self.upload
                    && u.partner != sender
                {
                    // One upload at a time; the running one goes on.
                    return reply.send(mission_ack(
                        sender,
                        MavMissionResult::MAV_MISSION_DENIED,
                        MISSION,
                    ));
                }
                if count == 0 {
                    self.upload = None;
                    self.stored = Mission::default();
                    let mut r = reply.send(accepted(sender));
                    r.change = Some(MissionChange::Cleared);
                    return r;
                }
                if count > MAX_ITEMS {
                    self.upload = None;
                    self.counts.failed_uploads += 1;
                    let mut r = reply.send(mission_ack(
                        sender,
                        MavMissionResult::MAV_MISSION_NO_SPACE,
                        MISSION,
                    ));
                    r.texts
                        .push(format!("dflat: mission of {count} items > {MAX_ITEMS}"));
                    return r;
                }
                self.upload = Some(Upload {
                    partner: sender,
                    count,
                    mission: Mission::default(),
                    requested_at: now,
                    retries: 0,
                });
                reply.send(mission_request_int(sender, 0, MISSION))
            }
            MissionMessage::Item { item, mission_type } => {
                self.item(sender, &item, mission_type, now)
            }
            MissionMessage::RequestList { mission_type } => {
                if mission_type != MISSION {
                    return reply.send(unsupported(sender, mission_type));
                }
                reply.send(mission_count(sender, self.stored.len() as u16, MISSION))
            }
            MissionMessage::Request {
                seq,
                mission_type,
                int,
            } => {
                if mission_type != MISSION {
                    return reply.send(unsupported(sender, mission_type));
                }
                match self.stored.raw.get(usize::from(seq)) {
                    Some(item) => {
                        self.counts.items_served += 1;
                        reply.send(if int {
                            mission_item_int(sender, &as_int(item, self.rules.int_scale))
                        } else {
                            mission_item(sender, &legacy(item, self.rules.int_scale))
                        })
                    }
                    None => reply.send(mission_ack(
                        sender,
                        MavMissionResult::MAV_MISSION_INVALID_SEQUENCE,
                        MISSION,
                    )),
                }
            }
            MissionMessage::ClearAll { mission_type } => {
                if !matches!(mission_type, MISSION | MavMissionType::MAV_MISSION_TYPE_ALL) {
                    return reply.send(unsupported(sender, mission_type));
                }
                self.upload = None;
                self.stored = Mission::default();
                let mut r = reply.send(mission_ack(
                    sender,
                    MavMissionResult::MAV_MISSION_ACCEPTED,
                    mission_type,
                ));
                r.change = Some(MissionChange::Cleared);
                r
            }
            MissionMessage::Ack { .. } => {
                // The end of a download, or the partner gave up an upload.
                if self.upload.as_ref().is_some_and(|u| u.partner == sender) {
                    self.upload = None;
                    self.counts.failed_uploads += 1;
                }
                reply
            }
        }
    }

    fn item(
        &mut self,
        sender: (u8, u8),
        item: &ItemFields,
        mission_type: MavMissionType,
        now: f64,
    ) -> Reply {
        let reply = Reply::default();
        let Some(upload) = self.upload.as_mut().filter(|u| u.partner == sender) else {
            // No upload from this sender: an item out of the blue.
            return reply;
        };
        if mission_type != MISSION {
            return reply;
        }
        if item.seq != upload.next() {
            // Out of sequence (a duplicate after a retry): ignored; the
            // expected item stays requested.
            return reply;
        }
        match parse_item(item, &self.rules) {
            Ok(read) => {
                upload.mission.raw.push(*item);
                upload.mission.items.push(read);
                if upload.next() < upload.count {
                    upload.requested_at = now;
                    upload.retries = 0;
                    let next = upload.next();
                    return reply.send(mission_request_int(sender, next, MISSION));
                }
                let done = self.upload.take().map(|u| u.mission).unwrap_or_default();
                self.stored = done.clone();
                self.counts.uploads += 1;
                let mut r = reply.send(accepted(sender));
                r.change = Some(MissionChange::Uploaded(done));
                r
            }
            Err(e) => {
                self.upload = None;
                self.counts.failed_uploads += 1;
                let mut r = reply.send(mission_ack(sender, e.result, MISSION));
                r.texts.push(e.text);
                r
            }
        }
    }

    /// The timeouts at `now` \[s\]: an item not received in time is
    /// requested again, or the upload cancelled.
    pub fn poll(&mut self, now: f64) -> Reply {
        let reply = Reply::default();
        let Some(upload) = self.upload.as_mut() else {
            return reply;
        };
        if now - upload.requested_at < ITEM_TIMEOUT {
            return reply;
        }
        let partner = upload.partner;
        if upload.retries >= MAX_RETRIES {
            let got = upload.next();
            let count = upload.count;
            self.upload = None;
            self.counts.failed_uploads += 1;
            let mut r = reply.send(mission_ack(
                partner,
                MavMissionResult::MAV_MISSION_OPERATION_CANCELLED,
                MISSION,
            ));
            r.texts
                .push(format!("dflat: mission upload timed out at {got}/{count}"));
            return r;
        }
        upload.retries += 1;
        upload.requested_at = now;
        self.counts.retries += 1;
        let next = upload.next();
        reply.send(mission_request_int(partner, next, MISSION))
    }
}

fn accepted(to: (u8, u8)) -> MavMessage {
    mission_ack(to, MavMissionResult::MAV_MISSION_ACCEPTED, MISSION)
}

fn unsupported(to: (u8, u8), mission_type: MavMissionType) -> MavMessage {
    mission_ack(to, MavMissionResult::MAV_MISSION_UNSUPPORTED, mission_type)
}

/// An item received as MISSION_ITEM_INT, as the legacy MISSION_ITEM
/// carries it (x, y in metres).
fn legacy(item: &ItemFields, int_scale: f64) -> ItemFields {
    if !item.int {
        return *item;
    }
    ItemFields {
        x: item.x / int_scale,
        y: item.y / int_scale,
        int: false,
        ..*item
    }
}

/// An item received as the legacy MISSION_ITEM, as MISSION_ITEM_INT
/// carries it (x, y in metres × the scale).
fn as_int(item: &ItemFields, int_scale: f64) -> ItemFields {
    if item.int {
        return *item;
    }
    ItemFields {
        x: item.x * int_scale,
        y: item.y * int_scale,
        int: true,
        ..*item
    }
}

#[cfg(test)]
mod tests;
