//! The ground stations a user has: 255 (QGroundControl, MAVProxy) and 245
//! (MAVSDK) by default; any other system's requests are recognised as an
//! unknown ground station (to be refused in words), never accepted.

use dflat_link::dialect::{
    COMMAND_LONG_DATA, MISSION_COUNT_DATA, MavCmd, MavFrame, PositionTargetTypemask,
    SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use dflat_link::{DEFAULT_GCS_SYSTEM_IDS, MavHeader, MavMessage, SourceFilter, Verdict};

fn from(system: u8, component: u8) -> MavHeader {
    MavHeader {
        system_id: system.into(),
        component_id: component,
        sequence: 0,
    }
}

fn setpoint(target: (u8, u8)) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        target_system: target.0,
        target_component: target.1,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        type_mask: PositionTargetTypemask::empty(),
        x: 5.0,
        ..Default::default()
    })
}

fn command(target: (u8, u8)) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system: target.0,
        target_component: target.1,
        command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
        ..Default::default()
    })
}

#[test]
fn mavsdk_and_qgc_ids_are_trusted_by_default() {
    let f = SourceFilter::default();
    assert_eq!(f.gcs_system_ids, DEFAULT_GCS_SYSTEM_IDS.to_vec());
    for gcs in [255, 245] {
        assert_eq!(
            f.check(&from(gcs, 190), &setpoint((1, 191))),
            Verdict::Accept
        );
        assert_eq!(
            f.unknown_ground_station(&from(gcs, 190), &setpoint((1, 191))),
            None
        );
    }
}

#[test]
fn another_system_is_an_unknown_ground_station() {
    let f = SourceFilter {
        gcs_system_ids: vec![255],
        ..SourceFilter::default()
    };
    let mavsdk = from(245, 190);
    assert_eq!(
        f.check(&mavsdk, &setpoint((1, 191))),
        Verdict::IgnoreWrongSource
    );
    assert_eq!(
        f.unknown_ground_station(&mavsdk, &setpoint((1, 191))),
        Some(245)
    );
    assert_eq!(
        f.unknown_ground_station(&mavsdk, &setpoint((0, 0))),
        Some(245),
        "a broadcast setpoint is a request to us too"
    );
    assert_eq!(
        f.unknown_ground_station(&mavsdk, &command((1, 191))),
        Some(245)
    );
    let mission = MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
        target_system: 1,
        target_component: 191,
        count: 3,
        ..Default::default()
    });
    assert_eq!(f.unknown_ground_station(&mavsdk, &mission), Some(245));
    // Not ours to refuse: addressed to the autopilot, a broadcast command
    // (declined by silence), the own vehicle's components, telemetry.
    assert_eq!(f.unknown_ground_station(&mavsdk, &setpoint((1, 1))), None);
    assert_eq!(f.unknown_ground_station(&mavsdk, &command((0, 0))), None);
    assert_eq!(
        f.unknown_ground_station(&from(1, 1), &command((1, 191))),
        None
    );
    assert_eq!(
        f.unknown_ground_station(
            &mavsdk,
            &dflat_link::local_position_ned(0, [0.0; 3], [0.0; 3]).unwrap()
        ),
        None
    );
}
