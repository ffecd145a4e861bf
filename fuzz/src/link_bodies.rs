//! Bodies of the link-security fuzz targets: `signing_verify`,
//! `key_and_timestamp_files`, `tlog_reader`, `command_answers`. Each takes
//! arbitrary bytes and checks its invariants with `assert!` (a violation is
//! a crash libFuzzer keeps). Uses only `dflat-link` and `dflat-daemon`, so
//! the main workspace's tests run the same bodies over seeds and random
//! bytes (`tests/fuzz_bodies.rs`) without libFuzzer or nightly.

use dflat_daemon::commands::{CommandContext, CommandRequest, answer};
use dflat_link::dialect::{MavMessage as Msg, MavResult};
use dflat_link::tlog::{TlogReader, TlogWriter};
use dflat_link::{
    MAX_FRAME_LEN, ONE_MINUTE, SignatureCheck, Signing, SigningKey, TIMESTAMP_MAX,
    check_key_metadata, constant_time_eq, frames, parse_timestamp_file,
};

/// The key the fuzzed verifier holds.
const KEY: [u8; 32] = [0x5a; 32];
/// "Now" of the verifier, as a signing timestamp (2026).
const NOW: u64 = 35_000_000_000_000;

/// Every frame in `data` through [`Signing::verify`] (and
/// `LinkRx::authenticate`): nothing panics; a frame is `Valid` only if it
/// was signed with [`KEY`] — checked by re-signing what verified — and then
/// the same bytes replayed are refused; no timestamp accepted is more than
/// a minute ahead of `now`.
pub fn signing_verify(data: &[u8]) {
    let [flags, rest @ ..] = data else {
        return;
    };
    let now = if flags & 1 != 0 { NOW } else { 0 };
    let mut verifier = Signing::new(SigningKey::from_bytes(KEY), 0, NOW);
    verifier.accept_unsigned = vec![u32::from(*flags)];
    let mut rx = dflat_link::LinkRx::new(dflat_link::SourceFilter::default());
    rx.signing = Some(verifier.clone());
    // Frames the fuzzer wrote, and the same frames signed with the key.
    let mut signer = Signing::new(SigningKey::from_bytes(KEY), 3, NOW);
    for frame in frames(rest).flatten() {
        let check = verifier.verify(&frame.header, frame.signed.as_ref(), now);
        if let SignatureCheck::Valid { timestamp, .. } = check {
            assert!(frame.signed.is_some());
            assert!(now == 0 || timestamp <= now + ONE_MINUTE);
            // Replaying the same bytes is refused.
            assert_eq!(
                verifier.verify(&frame.header, frame.signed.as_ref(), now),
                SignatureCheck::Replayed
            );
        }
        let auth = rx.authenticate(&frame.header, &frame.message, frame.signed.as_ref(), now);
        if auth.is_ok() && frame.signed.is_none() {
            // Unsigned passes only where allowed, never for what must be signed.
            assert!(!Signing::must_be_signed(&frame.message));
        }
        if frame.header.system_id <= 255
            && let Ok(signed) = signer.sign(&frame.header, &frame.message, NOW)
        {
            let parsed = dflat_link::parse_frame(signed.as_bytes()).expect("own frame parses");
            let mut fresh = Signing::new(SigningKey::from_bytes(KEY), 0, NOW);
            assert!(matches!(
                fresh.verify(&parsed.header, parsed.signed.as_ref(), NOW),
                SignatureCheck::Valid { .. }
            ));
            // Another key never verifies it.
            let mut other = Signing::new(SigningKey::from_bytes([0xc3; 32]), 0, NOW);
            assert_eq!(
                other.verify(&parsed.header, parsed.signed.as_ref(), NOW),
                SignatureCheck::BadSignature
            );
        }
    }
    let (a, b) = rest.split_at(rest.len() / 2);
    assert_eq!(constant_time_eq(a, b), a == b);
}

/// Key-file contents, timestamp-file contents and key metadata: parsing
/// never panics; a parsed timestamp is ≤ 48 bits and prints back to the
/// same digits; the metadata check accepts only a regular file of mode
/// 0600 owned by the user, no longer than the limit.
pub fn key_and_timestamp_files(data: &[u8]) {
    let _ = SigningKey::parse(data);
    if let Some(t) = parse_timestamp_file(data) {
        assert!(t <= TIMESTAMP_MAX);
        let text = std::str::from_utf8(data).expect("parsed as text").trim();
        assert_eq!(
            text.trim_start_matches('0'),
            t.to_string().trim_start_matches('0')
        );
    }
    if data.len() >= 14 {
        let mode = u32::from_le_bytes([data[0], data[1], data[2], data[3]]);
        let uid = u32::from_le_bytes([data[4], data[5], data[6], data[7]]);
        let euid = u32::from_le_bytes([data[8], data[9], data[10], data[11]]);
        let len = u64::from(u16::from_le_bytes([data[12], data[13]]));
        let regular = data.len().is_multiple_of(2);
        let ok = check_key_metadata(regular, mode, uid, len, Some(euid)).is_ok();
        assert_eq!(
            ok,
            regular && mode & 0o7777 == 0o600 && uid == euid && len <= dflat_link::KEY_FILE_MAX
        );
    }
}

/// Arbitrary bytes as a `.tlog`: reading never panics and stops after the
/// first error; every record read writes back to the same bytes.
pub fn tlog_reader(data: &[u8]) {
    let mut out = TlogWriter::new(Vec::new());
    let mut consumed = 0usize;
    let mut errors = 0;
    for record in TlogReader::new(data) {
        match record {
            Ok(r) => {
                assert!(r.frame.len() <= MAX_FRAME_LEN + 256);
                let _ = r.parse();
                consumed += 8 + r.frame.len();
                if out.write_frame(r.timestamp_us, &r.frame).is_err() {
                    // The writer refuses what is not one frame; the reader
                    // only frames by length: both are fine.
                    return;
                }
            }
            Err(_) => errors += 1,
        }
    }
    assert!(errors <= 1);
    let written = out.into_inner();
    assert_eq!(&written[..], &data[..consumed]);
}

/// Every frame in `data` as a command to the daemon: the answer (if any)
/// is a COMMAND_ACK for that command, addressed to its sender, and a
/// command addressed elsewhere is not answered. The first byte picks the
/// daemon's state (a mission uploaded, streaming, engaged), so the mission
/// commands' answers are fuzzed in every state.
pub fn command_answers(data: &[u8]) {
    let own = (1u8, 191u8);
    let bits = data.first().copied().unwrap_or(0);
    let ctx = CommandContext {
        has_mission: bits & 1 != 0,
        streaming: bits & 2 != 0,
        engaged: bits & 4 != 0,
    };
    for frame in frames(data).flatten() {
        let sender = (
            u8::try_from(frame.header.system_id).unwrap_or(u8::MAX),
            frame.header.component_id,
        );
        let Some(req) = CommandRequest::from_message(&frame.message, sender.0, sender.1) else {
            continue;
        };
        let Some(reply) = answer(&req, own, &ctx) else {
            continue;
        };
        assert_ne!(
            req.addressing(own),
            dflat_link::Addressing::Elsewhere,
            "answered a command addressed elsewhere"
        );
        let Msg::COMMAND_ACK(ack) = &reply.ack else {
            panic!("the answer is not a COMMAND_ACK: {:?}", reply.ack);
        };
        assert_eq!(ack.command, req.command);
        assert_eq!((ack.target_system, ack.target_component), sender);
        if reply.then.is_some() {
            assert_eq!(ack.result, MavResult::MAV_RESULT_ACCEPTED);
        }
    }
}
