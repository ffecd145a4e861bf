//! `.tlog` write → read round trip.

use dflat_link::tlog::{TlogError, TlogReader, TlogWriter};
use dflat_link::{
    AttitudeCommand, DaemonStatus, Target, header, heartbeat_onboard, local_position_ned,
    serialize_v2, set_attitude_target,
};

#[test]
fn tlog_round_trip() {
    let msgs = [
        heartbeat_onboard(DaemonStatus::Standby),
        local_position_ned(10, [1.0, 2.0, -3.0], [0.0; 3]).unwrap(),
        set_attitude_target(
            Target::default(),
            20,
            &AttitudeCommand {
                roll: 0.0,
                pitch: -0.1,
                yaw: 0.0,
                thrust: 0.5,
            },
        )
        .unwrap(),
    ];
    let t0 = 1_700_000_000_000_000u64;
    let mut w = TlogWriter::new(Vec::new());
    for (i, m) in msgs.iter().enumerate() {
        let hdr = header(1, 191, i as u8);
        if i == 0 {
            w.write_message(t0, &hdr, m).unwrap();
        } else {
            let bytes = serialize_v2(&hdr, m).unwrap();
            w.write_frame(t0 + 20_000 * i as u64, bytes.as_bytes())
                .unwrap();
        }
    }
    assert_eq!(w.records(), 3);
    let bytes = w.into_inner();
    // First record: big-endian timestamp, then the 0xFD marker.
    assert_eq!(&bytes[..8], &t0.to_be_bytes());
    assert_eq!(bytes[8], 0xFD);

    let records: Vec<_> = TlogReader::new(bytes.as_slice())
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(records.len(), 3);
    for (i, (r, m)) in records.iter().zip(&msgs).enumerate() {
        assert_eq!(r.timestamp_us, t0 + 20_000 * i as u64);
        let frame = r.parse().unwrap();
        assert_eq!(&frame.message, m);
        assert_eq!(frame.header.sequence, i as u8);
    }
}

#[test]
fn tlog_rejects_non_frames_and_reports_truncation() {
    let mut w = TlogWriter::new(Vec::new());
    assert!(matches!(
        w.write_frame(0, &[1, 2, 3]),
        Err(TlogError::NotAFrame { .. })
    ));
    let frame = serialize_v2(&header(1, 1, 0), &heartbeat_onboard(DaemonStatus::Boot)).unwrap();
    assert!(matches!(
        w.write_frame(0, &frame.as_bytes()[..5]),
        Err(TlogError::NotAFrame { .. })
    ));
    w.write_frame(1, frame.as_bytes()).unwrap();
    let mut bytes = w.into_inner();
    bytes.truncate(bytes.len() - 1);
    let results: Vec<_> = TlogReader::new(bytes.as_slice()).collect();
    assert_eq!(results.len(), 1);
    assert!(matches!(
        results[0],
        Err(TlogError::Truncated { offset: 0 })
    ));

    let garbage = [0u8; 16];
    let results: Vec<_> = TlogReader::new(&garbage[..]).collect();
    assert!(matches!(
        results[..],
        [Err(TlogError::BadMarker { offset: 8, byte: 0 })]
    ));
    assert!(TlogReader::new(&[][..]).next().is_none());
}
