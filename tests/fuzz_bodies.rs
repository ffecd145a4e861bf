//! The link-security fuzz targets' bodies (`fuzz/src/link_bodies.rs`),
//! run here over hand-made seeds and pseudo-random bytes so that CI
//! exercises them on stable Rust (cargo-fuzz needs nightly). The seeds are
//! valid, signed, replayed, future-dated and corrupted frames, key and
//! timestamp files, tlogs (whole, torn, garbage) and commands.

#[path = "../fuzz/src/link_bodies.rs"]
mod link_bodies;

use dflat_link::dialect::{COMMAND_LONG_DATA, MavCmd};
use dflat_link::tlog::TlogWriter;
use dflat_link::{
    DaemonStatus, MavMessage, ONE_MINUTE, Signing, SigningKey, header, heartbeat_onboard,
    serialize_v2,
};

/// xorshift64: reproducible pseudo-random bytes.
fn random_bytes(seed: u64, len: usize) -> Vec<u8> {
    let mut x = seed | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect()
}

const NOW: u64 = 35_000_000_000_000;

fn command(target: (u8, u8), cmd: MavCmd, param1: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system: target.0,
        target_component: target.1,
        command: cmd,
        param1,
        ..COMMAND_LONG_DATA::default()
    })
}

/// Valid frames: unsigned, signed with the key, with another key,
/// future-dated, corrupted.
fn frame_seeds() -> Vec<Vec<u8>> {
    let hb = heartbeat_onboard(DaemonStatus::Active);
    let req = command((1, 191), MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0);
    let takeoff = command((0, 0), MavCmd::MAV_CMD_NAV_TAKEOFF, 0.0);
    let elsewhere = command((1, 1), MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0);
    let mut out = Vec::new();
    for (i, msg) in [&hb, &req, &takeoff, &elsewhere].into_iter().enumerate() {
        let h = header(255, 190, i as u8);
        let plain = serialize_v2(&h, msg).unwrap().as_bytes().to_vec();
        let mut ours = Signing::new(SigningKey::from_bytes([0x5a; 32]), 1, NOW);
        let signed = ours.sign(&h, msg, NOW).unwrap().as_bytes().to_vec();
        let future = ours
            .sign(&h, msg, NOW + 5 * ONE_MINUTE)
            .unwrap()
            .as_bytes()
            .to_vec();
        let mut theirs = Signing::new(SigningKey::from_bytes([0xc3; 32]), 1, NOW);
        let other = theirs.sign(&h, msg, NOW).unwrap().as_bytes().to_vec();
        let mut corrupt = signed.clone();
        let n = corrupt.len();
        corrupt[n - 1] ^= 1;
        let mut both = signed.clone();
        both.extend_from_slice(&signed); // a replay in the same stream
        for body in [plain, signed, future, other, corrupt, both] {
            out.push([vec![1u8], body.clone()].concat());
            out.push([vec![0u8], body].concat());
        }
    }
    out
}

#[test]
fn signing_verify_over_seeds_and_random_bytes() {
    for seed in frame_seeds() {
        link_bodies::signing_verify(&seed);
    }
    for k in 0..2000u64 {
        link_bodies::signing_verify(&random_bytes(k, (k % 300) as usize));
    }
}

#[test]
fn key_and_timestamp_files_over_seeds_and_random_bytes() {
    let seeds: Vec<Vec<u8>> = vec![
        b"0123456789\n".to_vec(),
        b"  42  ".to_vec(),
        b"281474976710655".to_vec(),
        b"281474976710656".to_vec(),
        b"99999999999999999999999".to_vec(),
        b"-1".to_vec(),
        b"".to_vec(),
        format!("{}\n", "ab".repeat(32)).into_bytes(),
        vec![0xff; 32],
        b"correct horse battery staple\n".to_vec(),
        [
            0o600u32.to_le_bytes(),
            1000u32.to_le_bytes(),
            1000u32.to_le_bytes(),
        ]
        .concat()
        .into_iter()
        .chain([64, 0])
        .collect(),
    ];
    for s in &seeds {
        link_bodies::key_and_timestamp_files(s);
    }
    for k in 0..3000u64 {
        link_bodies::key_and_timestamp_files(&random_bytes(k, (k % 80) as usize));
    }
}

#[test]
fn tlog_reader_over_seeds_and_random_bytes() {
    let mut w = TlogWriter::new(Vec::new());
    for (i, s) in frame_seeds().iter().enumerate() {
        if w.write_frame(i as u64 * 1000, &s[1..]).is_err() {
            continue;
        }
    }
    let whole = w.into_inner();
    link_bodies::tlog_reader(&whole);
    for cut in [1, 7, 8, 9, 20, whole.len() / 2, whole.len() - 1] {
        link_bodies::tlog_reader(&whole[..cut]);
    }
    for k in 0..2000u64 {
        let mut bytes = random_bytes(k, (k % 400) as usize);
        if k % 2 == 0 {
            // Mostly well-formed heads: timestamp, then a start marker.
            if bytes.len() > 9 {
                bytes[8] = 0xFD;
            }
        }
        link_bodies::tlog_reader(&bytes);
    }
}

#[test]
fn command_answers_over_seeds_and_random_bytes() {
    for seed in frame_seeds() {
        link_bodies::command_answers(&seed[1..]);
    }
    for k in 0..2000u64 {
        link_bodies::command_answers(&random_bytes(k, (k % 300) as usize));
    }
}
