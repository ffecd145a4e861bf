//! Structured input → CRC-valid MAVLink frames with random payloads for the
//! contract's message ids (0, 30, 32, 82, 84, 102, 253, 331), other ids of
//! the common dialect and unknown ids → the same path as `decode_bytes`.
//!
//! Checks, besides "no panic": every frame built is framed exactly (no CRC
//! or truncation error, the length the header says); the stream of frames
//! with marker-free garbage between them parses to exactly the per-frame
//! results; every accepted pose / setpoint / attitude is finite; the
//! supervisor's goal stays finite and inside the fence; counters add up.
#![no_main]

use std::sync::OnceLock;

use dflat_fuzz::mavlink::{self, Message};
use dflat_fuzz::{Harness, Lcg, check_chunked_equals_whole, config};
use dflat_link::{FrameError, MavMessage, parse_frame};
use libfuzzer_sys::arbitrary::{self, Arbitrary};
use libfuzzer_sys::fuzz_target;

const CONTRACT_IDS: [u32; 8] = [0, 30, 32, 82, 84, 102, 253, 331];

/// Every message id of the common dialect.
fn known_ids() -> &'static [u32] {
    static IDS: OnceLock<Vec<u32>> = OnceLock::new();
    IDS.get_or_init(|| {
        (0..=u32::from(u16::MAX))
            .filter(|id| MavMessage::default_message_from_id(*id).is_some())
            .collect()
    })
}

#[derive(Debug, Arbitrary)]
enum Id {
    Contract(u8),
    Known(u16),
    Any(u32),
}

#[derive(Debug, Arbitrary)]
enum Sender {
    Autopilot,
    Gcs(u8),
    VehicleComponent(u8),
    Own,
    Any(u8, u8),
}

#[derive(Debug, Arbitrary)]
struct Spec {
    id: Id,
    sender: Sender,
    sequence: u8,
    /// Address SET_POSITION_TARGET_LOCAL_NED / SET_ATTITUDE_TARGET to the
    /// daemon and put 84 in LOCAL_NED, so the filter lets it through.
    address_to_us: bool,
    /// MAVLink 1 framing (ids ≤ 255 only).
    v1: bool,
    /// Signed MAVLink 2 frame with this (unchecked) signature.
    signature: Option<[u8; 13]>,
    payload: Vec<u8>,
    /// Bytes before the frame; start markers are removed from them.
    garbage: Vec<u8>,
}

#[derive(Debug, Arbitrary)]
struct Input {
    flags: u8,
    chunk_seed: u8,
    frames: Vec<Spec>,
}

fn build(spec: &Spec) -> Vec<u8> {
    let msg_id = match spec.id {
        Id::Contract(i) => CONTRACT_IDS[usize::from(i) % CONTRACT_IDS.len()],
        Id::Known(i) => known_ids()[usize::from(i) % known_ids().len()],
        Id::Any(id) => id & 0x00ff_ffff,
    };
    let (sys, comp) = match spec.sender {
        Sender::Autopilot => (1, 1),
        Sender::Gcs(c) => (255, c),
        Sender::VehicleComponent(c) => (1, c),
        Sender::Own => (1, 191),
        Sender::Any(s, c) => (s, c),
    };
    let mut payload: Vec<u8> = spec.payload.iter().copied().take(255).collect();
    if spec.address_to_us {
        // (offset of target_system, target_component[, frame]) in the payload.
        let fix: &[(usize, u8)] = match msg_id {
            84 => &[(54, 1), (55, 191), (56, 1)], // MAV_FRAME_LOCAL_NED
            82 => &[(36, 1), (37, 191)],
            _ => &[],
        };
        for &(at, v) in fix {
            if payload.len() <= at {
                payload.resize(at + 1, 0);
            }
            payload[at] = v;
        }
    }
    let v1 = spec.v1 && msg_id <= 255;
    let mut out: Vec<u8> = spec
        .garbage
        .iter()
        .copied()
        .filter(|b| *b != mavlink::MAV_STX && *b != mavlink::MAV_STX_V2)
        .collect();
    let start = out.len();
    if v1 {
        out.extend_from_slice(&[
            mavlink::MAV_STX,
            payload.len() as u8,
            spec.sequence,
            sys,
            comp,
            msg_id as u8,
        ]);
    } else {
        let id = msg_id.to_le_bytes();
        out.extend_from_slice(&[
            mavlink::MAV_STX_V2,
            payload.len() as u8,
            u8::from(spec.signature.is_some()),
            0,
            spec.sequence,
            sys,
            comp,
            id[0],
            id[1],
            id[2],
        ]);
    }
    out.extend_from_slice(&payload);
    let crc = mavlink::calculate_crc(&out[start + 1..], MavMessage::extra_crc(msg_id));
    out.extend_from_slice(&crc.to_le_bytes());
    if let (false, Some(sig)) = (v1, spec.signature) {
        out.extend_from_slice(&sig);
    }
    out
}

fuzz_target!(|input: Input| {
    let mut h = Harness::new(&config(input.flags));
    let mut stream = Vec::new();
    let mut expected = Vec::new();
    for spec in input.frames.iter().take(64) {
        let bytes = build(spec);
        let frame_at = bytes
            .iter()
            .position(|b| *b == mavlink::MAV_STX || *b == mavlink::MAV_STX_V2)
            .expect("a start marker");
        let frame = &bytes[frame_at..];
        let parsed = parse_frame(frame);
        match &parsed {
            Ok(f) => {
                assert_eq!(f.len, frame.len());
                let _ = dflat_link::serialize_v2(&f.header, &f.message);
                let _ = f.message.message_id();
            }
            // The CRC is right, so only the payload may be refused.
            Err(FrameError::Payload { .. } | FrameError::UnknownMessage { .. }) => {}
            Err(e) => panic!("CRC-valid frame refused: {e:?} ({spec:?})"),
        }
        expected.push(parsed);
        stream.extend_from_slice(&bytes);
    }

    // The whole stream, in chunks, through the daemon's path: exactly the
    // per-frame results (garbage has no markers, so no other events).
    let mut lcg = Lcg(u64::from(input.chunk_seed));
    let mut got_ok = 0usize;
    let mut rest = &stream[..];
    while !rest.is_empty() {
        let n = (lcg.next_u32() as usize % 400 + 1).min(rest.len());
        h.push(&rest[..n], &mut |f| {
            got_ok += 1;
            f64::from(f.header.sequence) * 1e-3
        });
        rest = &rest[n..];
    }
    h.finish();
    h.advance(1.0);
    assert_eq!(got_ok, expected.iter().filter(|r| r.is_ok()).count());
    assert_eq!(
        h.frame_errors,
        expected.iter().filter(|r| r.is_err()).count() as u64
    );
    let st = &h.link.stats;
    assert_eq!(st.crc_errors, 0, "{}", st.summary());

    let mut lcg = Lcg(u64::from(input.chunk_seed) ^ 0x5bd1_e995);
    check_chunked_equals_whole(&stream, &mut || lcg.next_u32() as usize % 64 + 1);
});
