//! MAVLink 2 signing: round trip, wrong key, replay, unsigned commands.

use dflat_link::dialect::{MavFrame, PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA};
use dflat_link::{
    DaemonStatus, LinkRx, MavHeader, MavMessage, ONE_MINUTE, RxOutcome, SignatureCheck, Signing,
    SigningKey, SourceFilter, header, heartbeat_autopilot, heartbeat_onboard, parse_frame,
    serialize_v2,
};

const NOW: u64 = 1_000_000_000; // some wall-clock signing timestamp

fn key(b: u8) -> SigningKey {
    SigningKey::from_bytes([b; 32])
}

fn setpoint() -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        type_mask: PositionTargetTypemask::from_bits_truncate(0x0ff8),
        x: 1.0,
        y: 2.0,
        z: -3.0,
        ..SET_POSITION_TARGET_LOCAL_NED_DATA::default()
    })
}

fn gcs() -> MavHeader {
    header(255, 190, 0)
}

#[test]
fn sign_verify_round_trip() {
    let mut tx = Signing::new(key(1), 7, NOW);
    let mut rx = Signing::new(key(1), 0, 0);
    let msg = heartbeat_onboard(DaemonStatus::Boot);
    let enc = tx.sign(&header(1, 191, 3), &msg, NOW + 5).unwrap();
    let bytes = enc.as_bytes();
    assert!(enc.is_signed());
    assert_eq!(bytes[2] & 0x01, 0x01, "incompat flag SIGNED");
    assert_eq!(
        bytes.len(),
        serialize_v2(&header(1, 191, 3), &msg)
            .unwrap()
            .as_bytes()
            .len()
            + 13
    );
    let frame = parse_frame(bytes).unwrap();
    assert_eq!(frame.message, msg);
    let signed = frame.signed.expect("signed frame kept");
    assert_eq!(signed.link_id(), 7);
    assert_eq!(signed.timestamp(), NOW + 5);
    assert_eq!(
        rx.verify(&frame.header, Some(&signed), NOW),
        SignatureCheck::Valid {
            link_id: 7,
            timestamp: NOW + 5
        }
    );
    // Outgoing timestamps strictly increase even if the clock stands still.
    let enc2 = tx.sign(&header(1, 191, 4), &msg, NOW).unwrap();
    let f2 = parse_frame(enc2.as_bytes()).unwrap();
    assert_eq!(f2.signed.unwrap().timestamp(), NOW + 6);
    assert_eq!(tx.timestamp(), NOW + 7);
    // ... and never start below the given start value.
    let mut late = Signing::new(key(1), 7, NOW);
    let f3 = parse_frame(late.sign(&gcs(), &msg, 0).unwrap().as_bytes()).unwrap();
    assert_eq!(f3.signed.unwrap().timestamp(), NOW);
}

#[test]
fn frame_signed_with_another_key_is_rejected() {
    let mut tx = Signing::new(key(2), 0, NOW);
    let mut rx = LinkRx::new(SourceFilter::default());
    rx.signing = Some(Signing::new(key(1), 0, NOW));
    let f = parse_frame(tx.sign(&gcs(), &setpoint(), NOW).unwrap().as_bytes()).unwrap();
    assert_eq!(
        rx.authenticate(&f.header, &f.message, f.signed.as_ref(), NOW),
        Err(SignatureCheck::BadSignature)
    );
    assert_eq!(rx.stats.bad_signature, 1);
    // A tampered byte (same key) is a bad signature too.
    let mut tx1 = Signing::new(key(1), 0, NOW);
    let enc = tx1.sign(&gcs(), &setpoint(), NOW).unwrap();
    let mut bytes = enc.as_bytes().to_vec();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x55;
    let f = parse_frame(&bytes).unwrap();
    assert_eq!(
        rx.authenticate(&f.header, &f.message, f.signed.as_ref(), NOW),
        Err(SignatureCheck::BadSignature)
    );
    assert_eq!(rx.stats.bad_signature, 2);
}

#[test]
fn replayed_frame_is_rejected() {
    let mut tx = Signing::new(key(1), 0, NOW);
    let mut rx = LinkRx::new(SourceFilter::default());
    rx.signing = Some(Signing::new(key(1), 0, NOW));
    let old = parse_frame(tx.sign(&gcs(), &setpoint(), NOW).unwrap().as_bytes()).unwrap();
    let new = parse_frame(tx.sign(&gcs(), &setpoint(), NOW).unwrap().as_bytes()).unwrap();
    let ok = |rx: &mut LinkRx, f: &dflat_link::Frame| {
        rx.authenticate(&f.header, &f.message, f.signed.as_ref(), NOW)
    };
    assert!(ok(&mut rx, &new).is_ok());
    assert_eq!(
        ok(&mut rx, &new),
        Err(SignatureCheck::Replayed),
        "same timestamp"
    );
    assert_eq!(
        ok(&mut rx, &old),
        Err(SignatureCheck::Replayed),
        "older timestamp"
    );
    assert_eq!(rx.stats.replayed, 2);
    // A new stream more than a minute behind the newest timestamp is stale.
    let mut stale_tx = Signing::new(key(1), 9, NOW - 2 * ONE_MINUTE);
    let stale = parse_frame(stale_tx.sign(&gcs(), &setpoint(), 0).unwrap().as_bytes()).unwrap();
    assert_eq!(ok(&mut rx, &stale), Err(SignatureCheck::Replayed));
}

#[test]
fn unsigned_setpoint_is_rejected_while_signing_is_on() {
    let mut rx = LinkRx::new(SourceFilter::default());
    let sp = setpoint();
    // Signing off: passes.
    assert!(rx.authenticate(&gcs(), &sp, None, NOW).is_ok());
    let mut signing = Signing::new(key(1), 0, NOW);
    signing.accept_unsigned_telemetry = true;
    rx.signing = Some(signing);
    assert_eq!(
        rx.authenticate(&gcs(), &sp, None, NOW),
        Err(SignatureCheck::Unsigned)
    );
    assert_eq!(rx.stats.unsigned, 1);
    // HEARTBEAT (mode, armed) must be signed even with
    // accept_unsigned_telemetry; a message outside the protected set passes.
    let hb = heartbeat_autopilot(
        dflat_link::dialect::MavAutopilot::MAV_AUTOPILOT_PX4,
        true,
        0,
        dflat_link::dialect::MavState::MAV_STATE_ACTIVE,
    );
    let ap = header(1, 1, 0);
    assert_eq!(
        rx.authenticate(&ap, &hb, None, NOW),
        Err(SignatureCheck::Unsigned)
    );
    let sys = MavMessage::SYS_STATUS(Default::default());
    assert!(rx.authenticate(&ap, &sys, None, NOW).is_ok());
    if let Some(s) = rx.signing.as_mut() {
        s.accept_unsigned_telemetry = false;
    }
    assert_eq!(
        rx.authenticate(&ap, &sys, None, NOW),
        Err(SignatureCheck::Unsigned)
    );
    assert_eq!(rx.stats.unsigned, 3);
    // The per-message list: SYS_STATUS listed passes, HEARTBEAT listed does not.
    if let Some(s) = rx.signing.as_mut() {
        s.accept_unsigned = vec![1, 0];
    }
    assert!(rx.authenticate(&ap, &sys, None, NOW).is_ok());
    assert_eq!(
        rx.authenticate(&ap, &hb, None, NOW),
        Err(SignatureCheck::Unsigned)
    );
    assert!(matches!(rx.handle(&ap, &hb), RxOutcome::Accepted(_)));
    // Every protected message is refused unsigned whatever the lists say.
    for msg in [
        hb.clone(),
        MavMessage::LOCAL_POSITION_NED(Default::default()),
        MavMessage::ODOMETRY(Default::default()),
        MavMessage::VISION_POSITION_ESTIMATE(Default::default()),
        MavMessage::ATTITUDE(Default::default()),
        MavMessage::PARAM_VALUE(Default::default()),
        MavMessage::MISSION_ITEM_INT(Default::default()),
        MavMessage::MISSION_COUNT(Default::default()),
        MavMessage::COMMAND_LONG(Default::default()),
        MavMessage::SET_ATTITUDE_TARGET(Default::default()),
        sp.clone(),
    ] {
        assert!(Signing::must_be_signed(&msg), "{msg:?}");
    }
    assert_eq!(dflat_link::unsigned_message_id("SYS_STATUS"), Ok(1));
    assert!(dflat_link::unsigned_message_id("HEARTBEAT").is_err());
    assert!(dflat_link::unsigned_message_id("NOT_A_MESSAGE").is_err());
    // The same setpoint signed with the key passes.
    let mut tx = Signing::new(key(1), 0, NOW);
    let f = parse_frame(tx.sign(&gcs(), &sp, NOW).unwrap().as_bytes()).unwrap();
    assert!(
        rx.authenticate(&f.header, &f.message, f.signed.as_ref(), NOW)
            .is_ok()
    );
}

#[test]
fn future_dated_signature_is_refused_and_comparison_is_exact() {
    let mut rx = LinkRx::new(SourceFilter::default());
    rx.signing = Some(Signing::new(key(1), 0, NOW));
    // A sender whose clock is 5 minutes ahead of ours.
    let mut ahead = Signing::new(key(1), 0, NOW + 5 * ONE_MINUTE);
    let f = parse_frame(ahead.sign(&gcs(), &setpoint(), 0).unwrap().as_bytes()).unwrap();
    assert_eq!(
        rx.authenticate(&f.header, &f.message, f.signed.as_ref(), NOW),
        Err(SignatureCheck::FutureTimestamp)
    );
    assert_eq!(rx.stats.future_timestamp, 1);
    // Without a clock (now = 0) the bound is not applied.
    assert!(
        rx.authenticate(&f.header, &f.message, f.signed.as_ref(), 0)
            .is_ok()
    );
    assert!(dflat_link::constant_time_eq(b"abcdef", b"abcdef"));
    assert!(!dflat_link::constant_time_eq(b"abcdef", b"abcdeg"));
    assert!(!dflat_link::constant_time_eq(b"abc", b"abcd"));
}
