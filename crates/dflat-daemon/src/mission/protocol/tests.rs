use dflat_link::dialect::{
    MISSION_CLEAR_ALL_DATA, MISSION_REQUEST_LIST_DATA, MavCmd, MavFrame, MavMissionResult,
    MavMissionType,
};
use dflat_link::mission::{ItemFields, mission_count, mission_item_int};

use super::*;

const OWN: (u8, u8) = (1, 191);
const GCS: (u8, u8) = (255, 190);
const RULES: ItemRules = ItemRules {
    int_scale: 1e4,
    fence_min: [-100.0, -100.0, -50.0],
    fence_max: [100.0, 100.0, 50.0],
    acceptance_radius: 1.0,
};

fn wp(seq: u16, x: f64, command: MavCmd) -> MavMessage {
    mission_item_int(
        OWN,
        &ItemFields {
            seq,
            frame: MavFrame::MAV_FRAME_LOCAL_NED,
            command,
            params: [0.0; 4],
            x: x * 1e4,
            y: 0.0,
            z: -10.0,
            current: 0,
            autocontinue: 1,
            int: true,
        },
    )
}

fn count(n: u16, t: MavMissionType) -> MavMessage {
    mission_count(OWN, n, t)
}

/// What a reply says, in a comparable form.
#[derive(Debug, PartialEq)]
enum Said {
    Request(u16),
    Ack(MavMissionResult),
    Count(u16),
    Item(u16, f64),
}

fn said(r: &Reply) -> Vec<Said> {
    r.messages
        .iter()
        .map(|m| match m {
            MavMessage::MISSION_REQUEST_INT(d) => {
                assert_eq!((d.target_system, d.target_component), GCS);
                Said::Request(d.seq)
            }
            MavMessage::MISSION_ACK(d) => {
                assert_eq!((d.target_system, d.target_component), GCS);
                Said::Ack(d.mavtype)
            }
            MavMessage::MISSION_COUNT(d) => Said::Count(d.count),
            MavMessage::MISSION_ITEM_INT(d) => Said::Item(d.seq, f64::from(d.x)),
            other => panic!("unexpected {other:?}"),
        })
        .collect()
}

const M: MavMissionType = MavMissionType::MAV_MISSION_TYPE_MISSION;

fn upload(p: &mut MissionProtocol, xs: &[f64], t0: f64) -> Reply {
    p.handle(&count(xs.len() as u16, M), GCS, t0);
    let mut last = Reply::default();
    for (i, x) in xs.iter().enumerate() {
        last = p.handle(
            &wp(i as u16, *x, MavCmd::MAV_CMD_NAV_WAYPOINT),
            GCS,
            t0 + 0.1,
        );
    }
    last
}

#[test]
fn an_upload_requests_each_item_and_is_accepted() {
    let mut p = MissionProtocol::new(OWN, RULES);
    let r = p.handle(&count(2, M), GCS, 0.0);
    assert_eq!(said(&r), [Said::Request(0)]);
    let r = p.handle(&wp(0, 5.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 0.1);
    assert_eq!(said(&r), [Said::Request(1)]);
    assert!(r.change.is_none() && p.mission().is_empty());
    let r = p.handle(&wp(1, 8.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 0.2);
    assert_eq!(
        said(&r),
        [Said::Ack(MavMissionResult::MAV_MISSION_ACCEPTED)]
    );
    let Some(MissionChange::Uploaded(m)) = r.change else {
        panic!("{r:?}")
    };
    assert_eq!(m.items[1].position(), Some([8.0, 0.0, -10.0]));
    assert_eq!(p.mission().len(), 2);
    assert!(!p.uploading());
    assert_eq!(p.counts().uploads, 1);
}

#[test]
fn a_download_returns_what_was_uploaded() {
    let mut p = MissionProtocol::new(OWN, RULES);
    upload(&mut p, &[5.0, 8.0], 0.0);
    let list = MavMessage::MISSION_REQUEST_LIST(MISSION_REQUEST_LIST_DATA {
        target_system: 1,
        target_component: 191,
        mission_type: M,
    });
    assert_eq!(said(&p.handle(&list, GCS, 1.0)), [Said::Count(2)]);
    let req = |seq| mission_request_int(OWN, seq, M);
    assert_eq!(
        said(&p.handle(&req(1), GCS, 1.1)),
        [Said::Item(1, 80_000.0)]
    );
    assert_eq!(
        said(&p.handle(&req(2), GCS, 1.2)),
        [Said::Ack(MavMissionResult::MAV_MISSION_INVALID_SEQUENCE)]
    );
}

#[test]
fn a_refused_item_ends_the_upload_and_keeps_the_stored_mission() {
    let mut p = MissionProtocol::new(OWN, RULES);
    upload(&mut p, &[5.0], 0.0);
    let table = [
        (
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            0.0,
            MavMissionResult::MAV_MISSION_UNSUPPORTED,
        ),
        (
            MavCmd::MAV_CMD_NAV_WAYPOINT,
            1e4,
            MavMissionResult::MAV_MISSION_INVALID_PARAM5_X,
        ),
    ];
    for (command, x, result) in table {
        p.handle(&count(2, M), GCS, 10.0);
        p.handle(&wp(0, 1.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 10.1);
        let r = p.handle(&wp(1, x, command), GCS, 10.2);
        assert_eq!(said(&r), [Said::Ack(result)], "{command:?}");
        assert_eq!(r.texts.len(), 1);
        assert!(r.change.is_none());
        assert!(!p.uploading());
        assert_eq!(p.mission().items[0].position(), Some([5.0, 0.0, -10.0]));
    }
    assert_eq!(p.counts().failed_uploads, 2);
}

#[test]
fn a_partial_upload_is_retried_then_cancelled() {
    let mut p = MissionProtocol::new(OWN, RULES);
    upload(&mut p, &[5.0], 0.0);
    p.handle(&count(3, M), GCS, 10.0);
    p.handle(&wp(0, 1.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 10.1);
    // Nothing before the timeout.
    assert!(p.poll(10.1 + ITEM_TIMEOUT * 0.9).messages.is_empty());
    let mut t = 10.1;
    for _ in 0..MAX_RETRIES {
        t += ITEM_TIMEOUT;
        assert_eq!(said(&p.poll(t)), [Said::Request(1)]);
    }
    t += ITEM_TIMEOUT;
    let r = p.poll(t);
    assert_eq!(
        said(&r),
        [Said::Ack(MavMissionResult::MAV_MISSION_OPERATION_CANCELLED)]
    );
    assert!(r.texts[0].contains("timed out at 1/3"), "{:?}", r.texts);
    assert!(r.change.is_none() && !p.uploading());
    assert_eq!(p.mission().len(), 1, "the stored mission is untouched");
    assert_eq!(p.counts().retries, u64::from(MAX_RETRIES));
    // Late items of the cancelled upload are not answered.
    let late = p.handle(&wp(1, 2.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, t + 0.1);
    assert!(late.messages.is_empty());
}

#[test]
fn out_of_sequence_items_are_ignored_and_a_retry_resumes() {
    let mut p = MissionProtocol::new(OWN, RULES);
    p.handle(&count(2, M), GCS, 0.0);
    assert!(
        p.handle(&wp(1, 1.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 0.1)
            .messages
            .is_empty()
    );
    assert_eq!(said(&p.poll(ITEM_TIMEOUT)), [Said::Request(0)]);
    p.handle(&wp(0, 1.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 1.6);
    // A duplicate of item 0 (our request crossed it) is ignored too.
    assert!(
        p.handle(&wp(0, 1.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 1.7)
            .messages
            .is_empty()
    );
    let r = p.handle(&wp(1, 2.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 1.8);
    assert_eq!(
        said(&r),
        [Said::Ack(MavMissionResult::MAV_MISSION_ACCEPTED)]
    );
}

#[test]
fn other_types_senders_and_addressees() {
    let mut p = MissionProtocol::new(OWN, RULES);
    for t in [
        MavMissionType::MAV_MISSION_TYPE_FENCE,
        MavMissionType::MAV_MISSION_TYPE_RALLY,
    ] {
        assert_eq!(
            said(&p.handle(&count(1, t), GCS, 0.0)),
            [Said::Ack(MavMissionResult::MAV_MISSION_UNSUPPORTED)]
        );
    }
    // Addressed to the autopilot, or broadcast: not ours.
    let to_autopilot = mission_count((1, 1), 1, M);
    assert!(p.handle(&to_autopilot, GCS, 0.0).messages.is_empty());
    assert!(
        p.handle(&mission_count((1, 0), 1, M), GCS, 0.0)
            .messages
            .is_empty()
    );
    // A second sender during an upload is denied; the first goes on.
    p.handle(&count(1, M), GCS, 0.0);
    let other = (254, 1);
    let r = p.handle(&count(1, M), other, 0.1);
    assert_eq!(r.messages.len(), 1);
    assert!(matches!(&r.messages[0], MavMessage::MISSION_ACK(d)
        if d.mavtype == MavMissionResult::MAV_MISSION_DENIED && d.target_system == 254));
    let r = p.handle(&wp(0, 3.0, MavCmd::MAV_CMD_NAV_WAYPOINT), GCS, 0.2);
    assert_eq!(
        said(&r),
        [Said::Ack(MavMissionResult::MAV_MISSION_ACCEPTED)]
    );
}

#[test]
fn clearing_empties_the_store() {
    let mut p = MissionProtocol::new(OWN, RULES);
    upload(&mut p, &[5.0, 6.0], 0.0);
    let clear = MavMessage::MISSION_CLEAR_ALL(MISSION_CLEAR_ALL_DATA {
        target_system: 1,
        target_component: 191,
        mission_type: M,
    });
    let r = p.handle(&clear, GCS, 1.0);
    assert_eq!(
        said(&r),
        [Said::Ack(MavMissionResult::MAV_MISSION_ACCEPTED)]
    );
    assert_eq!(r.change, Some(MissionChange::Cleared));
    assert!(p.mission().is_empty());
    upload(&mut p, &[5.0], 2.0);
    let r = p.handle(&count(0, M), GCS, 3.0);
    assert_eq!(r.change, Some(MissionChange::Cleared));
    assert!(p.mission().is_empty());
}
