//! Frame codec: serialization, parsing, error reporting, robustness.

use dflat_link::dialect::MavSeverity;
use dflat_link::dialect::{MavAutopilot, MavState};
use dflat_link::{
    AttitudeCommand, DaemonStatus, FrameError, FrameParser, LinkRx, LinkStats, MavMessage,
    MavlinkVersion, SourceFilter, Target, frames, header, heartbeat_autopilot, heartbeat_onboard,
    local_position_ned, parse_frame, serialize_v2, set_attitude_target, statustext, write_v2,
};
use proptest::prelude::*;

fn sample_messages() -> Vec<MavMessage> {
    vec![
        heartbeat_autopilot(
            MavAutopilot::MAV_AUTOPILOT_PX4,
            true,
            7,
            MavState::MAV_STATE_ACTIVE,
        ),
        local_position_ned(100, [1.0, 2.0, -3.0], [0.5, 0.0, 0.0]).unwrap(),
        set_attitude_target(
            Target::default(),
            200,
            &AttitudeCommand {
                roll: 0.1,
                pitch: 0.2,
                yaw: 0.3,
                thrust: 0.4,
            },
        )
        .unwrap(),
        statustext(MavSeverity::MAV_SEVERITY_NOTICE, "hello"),
    ]
}

fn stream(msgs: &[MavMessage]) -> Vec<u8> {
    let mut out = Vec::new();
    for (i, m) in msgs.iter().enumerate() {
        write_v2(&mut out, &header(1, 1, i as u8), m).unwrap();
    }
    out
}

#[test]
fn write_v2_equals_serialize_v2() {
    let m = heartbeat_onboard(DaemonStatus::Standby);
    let hdr = header(1, 191, 5);
    let mut buf = Vec::new();
    let n = write_v2(&mut buf, &hdr, &m).unwrap();
    assert_eq!(n, buf.len());
    assert_eq!(buf, serialize_v2(&hdr, &m).unwrap().as_bytes());
}

#[test]
fn parses_concatenated_frames_with_garbage_between() {
    let msgs = sample_messages();
    let mut bytes = vec![0x00, 0x11, 0x22];
    for (i, m) in msgs.iter().enumerate() {
        bytes.extend_from_slice(serialize_v2(&header(1, 1, i as u8), m).unwrap().as_bytes());
        bytes.extend_from_slice(&[0x55, 0xAA]);
    }
    let mut it = frames(&bytes);
    let got: Vec<_> = it.by_ref().map(|r| r.unwrap().message).collect();
    assert_eq!(got, msgs);
    assert_eq!(it.skipped_bytes(), 3 + 2 * msgs.len() as u64);
}

#[test]
fn corrupt_frame_is_counted_once_and_neighbours_survive() {
    let msgs = sample_messages();
    let mut bytes = Vec::new();
    let mut starts = Vec::new();
    for (i, m) in msgs.iter().enumerate() {
        starts.push(bytes.len());
        write_v2(&mut bytes, &header(1, 1, i as u8), m).unwrap();
    }
    // Corrupt a payload byte of the SET_ATTITUDE_TARGET frame (index 2).
    bytes[starts[2] + 12] ^= 0x5A;
    let results: Vec<_> = frames(&bytes).collect();
    assert_eq!(results.len(), 4, "{results:?}");
    assert!(matches!(results[2], Err(FrameError::Crc { msg_id: 82 })));
    let ok: Vec<_> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
    assert_eq!(ok.len(), 3);
    assert_eq!(ok[2].message, msgs[3]);

    let mut stats = LinkStats::default();
    for r in &results {
        if let Err(e) = r {
            stats.record_frame_error(e);
        }
    }
    assert_eq!(stats.crc_errors, 1);
    assert_eq!(stats.malformed, 0);
}

#[test]
fn unknown_ids_bad_flags_and_truncation_are_reported() {
    // A MAVLink 2 frame claiming message id 60000 (not in common).
    let mut unknown = vec![0xFD, 1, 0, 0, 0, 1, 1, 0x60, 0xEA, 0x00, 0x42, 0, 0];
    let crc = dflat_link::mavlink::calculate_crc(&unknown[1..11], 0);
    unknown[11..13].copy_from_slice(&(crc ^ 0xFFFF).to_le_bytes());
    assert_eq!(
        parse_frame(&unknown),
        Err(FrameError::UnknownMessage { msg_id: 60000 })
    );

    let hb = serialize_v2(&header(1, 1, 0), &heartbeat_onboard(DaemonStatus::Boot)).unwrap();
    let mut flagged = hb.as_bytes().to_vec();
    flagged[2] = 0x02; // mavlink-rs' non-standard 32-bit system id flag
    assert_eq!(
        parse_frame(&flagged),
        Err(FrameError::UnsupportedFlags { flags: 0x02 })
    );

    let short = &hb.as_bytes()[..hb.as_bytes().len() - 1];
    assert!(matches!(
        parse_frame(short),
        Err(FrameError::Truncated { .. })
    ));
    let results: Vec<_> = frames(short).collect();
    assert!(matches!(results[..], [Err(FrameError::Truncated { .. })]));
    assert_eq!(parse_frame(&[0x00, 0xFD]), Err(FrameError::NoMarker));
    assert!(frames(&[]).next().is_none());
}

#[test]
fn signed_and_v1_frames_parse() {
    let msg = heartbeat_onboard(DaemonStatus::Active);
    // Signed: set the flag, recompute the CRC, append a 13-byte signature.
    let mut signed = serialize_v2(&header(1, 191, 3), &msg)
        .unwrap()
        .as_bytes()
        .to_vec();
    signed[2] = 0x01;
    let crc_at = signed.len() - 2;
    let crc = dflat_link::mavlink::calculate_crc(&signed[1..crc_at], 50); // HEARTBEAT CRC_EXTRA
    signed[crc_at..].copy_from_slice(&crc.to_le_bytes());
    signed.extend_from_slice(&[7u8; 13]);
    let f = parse_frame(&signed).unwrap();
    assert_eq!(f.message, msg);
    assert_eq!(f.len, signed.len());

    let mut v1 = Vec::new();
    dflat_link::mavlink::write_v1_msg(&mut v1, header(1, 1, 9), &msg).unwrap();
    assert_eq!(v1[0], 0xFE);
    let f = parse_frame(&v1).unwrap();
    assert_eq!(f.version, MavlinkVersion::V1);
    assert_eq!(f.message, msg);
    assert_eq!(f.header, header(1, 1, 9));
}

#[test]
fn link_rx_counts_frame_errors() {
    let mut rx = LinkRx::new(SourceFilter::default());
    rx.frame_error(&FrameError::Crc { msg_id: 0 });
    rx.frame_error(&FrameError::UnknownMessage { msg_id: 9999 });
    rx.frame_error(&FrameError::Truncated {
        available: 3,
        needed: 12,
    });
    assert_eq!(
        (
            rx.stats.crc_errors,
            rx.stats.unknown_messages,
            rx.stats.malformed
        ),
        (1, 1, 1)
    );
}

fn collect_streaming(bytes: &[u8], chunks: &[usize]) -> Vec<Result<MavMessage, FrameError>> {
    let mut parser = FrameParser::new();
    let mut out = Vec::new();
    let mut rest = bytes;
    let mut i = 0;
    while !rest.is_empty() {
        let n = chunks
            .get(i)
            .copied()
            .unwrap_or(rest.len())
            .clamp(1, rest.len());
        i += 1;
        parser.push(&rest[..n]);
        rest = &rest[n..];
        while let Some(r) = parser.next_frame() {
            out.push(r.map(|f| f.message));
        }
        assert!(parser.pending() <= dflat_link::MAX_FRAME_LEN + n);
    }
    out.extend(parser.finish().into_iter().map(|r| r.map(|f| f.message)));
    out
}

#[test]
fn streaming_parser_handles_one_byte_chunks() {
    let msgs = sample_messages();
    let bytes = stream(&msgs);
    let got = collect_streaming(&bytes, &vec![1; bytes.len()]);
    let got: Vec<_> = got.into_iter().map(Result::unwrap).collect();
    assert_eq!(got, msgs);
}

proptest! {
    #[test]
    fn random_bytes_never_panic_and_errors_are_counted(
        bytes in proptest::collection::vec(any::<u8>(), 0..2048),
        chunks in proptest::collection::vec(1usize..300, 0..64),
    ) {
        let markers = bytes.iter().filter(|&&b| b == 0xFD || b == 0xFE).count();
        let results: Vec<_> = frames(&bytes).map(|r| r.map(|f| f.message)).collect();
        let mut stats = LinkStats::default();
        let mut errors = 0u64;
        for r in &results {
            if let Err(e) = r {
                stats.record_frame_error(e);
                errors += 1;
            }
        }
        prop_assert_eq!(stats.inbound_errors(), errors);
        prop_assert!(results.len() <= markers);
        // Streaming in arbitrary chunks gives exactly the same events.
        prop_assert_eq!(collect_streaming(&bytes, &chunks), results);
    }

    #[test]
    fn valid_frames_survive_marker_free_garbage(
        garbage in proptest::collection::vec(
            any::<u8>().prop_filter("no start markers", |b| *b != 0xFD && *b != 0xFE), 0..64),
        corrupt in any::<bool>(),
    ) {
        let msgs = sample_messages();
        let mut bytes = garbage.clone();
        bytes.extend_from_slice(&stream(&msgs));
        bytes.extend_from_slice(&garbage);
        let mut bad = bytes.clone();
        if corrupt {
            // Flip one payload byte of the first frame.
            bad[garbage.len() + 10] ^= 0x01;
        }
        let results: Vec<_> = frames(&bad).collect();
        let ok: Vec<_> = results.iter().filter_map(|r| r.as_ref().ok().map(|f| f.message.clone())).collect();
        let errs = results.iter().filter(|r| r.is_err()).count();
        if corrupt {
            prop_assert_eq!(&ok[..], &msgs[1..]);
            prop_assert_eq!(errs, 1);
        } else {
            prop_assert_eq!(&ok[..], &msgs[..]);
            prop_assert_eq!(errs, 0);
        }
    }
}
