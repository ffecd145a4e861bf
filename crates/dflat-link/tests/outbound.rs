//! Outbound builders: SET_ATTITUDE_TARGET, HEARTBEAT, STATUSTEXT.

use dflat_link::dialect::{
    AttitudeTargetTypemask, MavAutopilot, MavModeFlag, MavSeverity, MavState, MavType,
};
use dflat_link::{
    AttitudeCommand, DaemonStatus, LinkError, MavMessage, Outbound, Target, euler_from_quaternion,
    header, heartbeat_autopilot, heartbeat_onboard, parse_frame, serialize_v2, set_attitude_target,
    statustext, truncate_text,
};

fn command() -> AttitudeCommand {
    AttitudeCommand {
        roll: 0.1,
        pitch: -0.2,
        yaw: 1.3,
        thrust: 0.55,
    }
}

#[test]
fn set_attitude_target_bytes_round_trip() {
    let target = Target {
        system: 7,
        component: 3,
    };
    let msg = set_attitude_target(target, 123_456, &command()).unwrap();
    let hdr = header(1, 191, 42);
    let bytes = serialize_v2(&hdr, &msg).unwrap();
    assert_eq!(bytes.as_bytes()[0], 0xFD);
    let frame = parse_frame(bytes.as_bytes()).unwrap();
    assert_eq!(frame.header, hdr);
    assert_eq!(frame.len, bytes.as_bytes().len());
    assert_eq!(frame.message, msg);
    let MavMessage::SET_ATTITUDE_TARGET(d) = frame.message else {
        panic!("wrong message: {:?}", frame.message);
    };
    assert_eq!(d.time_boot_ms, 123_456);
    assert_eq!((d.target_system, d.target_component), (7, 3));
    assert_eq!(d.type_mask.bits(), 1 | 2 | 4);
    assert_eq!(
        d.type_mask,
        AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
            | AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
            | AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
    );
    assert!((d.thrust - 0.55).abs() < 1e-7);
    let q = d.q.map(f64::from);
    let [r, p, y] = euler_from_quaternion(q);
    assert!((r - 0.1).abs() < 1e-6 && (p + 0.2).abs() < 1e-6 && (y - 1.3).abs() < 1e-6);
    assert_eq!(d.thrust_body, [0.0; 3]);
}

#[test]
fn non_finite_command_is_refused() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut c = command();
        c.pitch = bad;
        assert!(matches!(
            set_attitude_target(Target::default(), 0, &c),
            Err(LinkError::NonFinite { .. })
        ));
        let mut c = command();
        c.thrust = bad;
        assert!(matches!(
            set_attitude_target(Target::default(), 0, &c),
            Err(LinkError::NonFinite { .. })
        ));
    }
    let mut c = command();
    c.thrust = 1.01;
    assert!(matches!(
        set_attitude_target(Target::default(), 0, &c),
        Err(LinkError::OutOfRange { .. })
    ));
}

#[test]
fn onboard_heartbeat_fields_are_explicit() {
    let MavMessage::HEARTBEAT(d) = heartbeat_onboard(DaemonStatus::Active) else {
        panic!()
    };
    assert_eq!(d.mavtype, MavType::MAV_TYPE_ONBOARD_CONTROLLER);
    assert_eq!(d.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
    assert_eq!(d.system_status, MavState::MAV_STATE_ACTIVE);
    // The crate's Default for MavModeFlag is SAFETY_ARMED: must not leak in.
    assert_eq!(d.base_mode, MavModeFlag::empty());
    assert_eq!(d.mavlink_version, 3);
}

#[test]
fn autopilot_heartbeat_reports_armed() {
    let MavMessage::HEARTBEAT(d) = heartbeat_autopilot(
        MavAutopilot::MAV_AUTOPILOT_PX4,
        true,
        6 << 16,
        MavState::MAV_STATE_ACTIVE,
    ) else {
        panic!()
    };
    assert_eq!(d.mavtype, MavType::MAV_TYPE_QUADROTOR);
    assert!(
        d.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
    );
    let MavMessage::HEARTBEAT(d) = heartbeat_autopilot(
        MavAutopilot::MAV_AUTOPILOT_GENERIC,
        false,
        0,
        MavState::MAV_STATE_STANDBY,
    ) else {
        panic!()
    };
    assert!(
        !d.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
    );
}

#[test]
fn statustext_truncates_on_char_boundary() {
    // 49 ASCII bytes + a 3-byte char straddling the 50-byte limit.
    let text = format!("{}€tail", "a".repeat(49));
    let MavMessage::STATUSTEXT(d) = statustext(MavSeverity::MAV_SEVERITY_WARNING, &text) else {
        panic!()
    };
    assert_eq!(d.severity, MavSeverity::MAV_SEVERITY_WARNING);
    assert_eq!(d.text.to_str().unwrap(), "a".repeat(49));
    // Exactly 50 bytes fit without a terminator.
    let fifty = "é".repeat(25);
    let MavMessage::STATUSTEXT(d) = statustext(MavSeverity::MAV_SEVERITY_INFO, &fifty) else {
        panic!()
    };
    assert_eq!(d.text.to_str().unwrap(), fifty);
    assert_eq!(truncate_text("short", 50), "short");
    assert_eq!(truncate_text("ab\0cd", 50), "ab");
    assert_eq!(truncate_text("ßßß", 3), "ß");
    // And it survives the wire.
    let msg = statustext(MavSeverity::MAV_SEVERITY_INFO, "failsafe: pose timeout");
    let frame = parse_frame(serialize_v2(&header(1, 191, 0), &msg).unwrap().as_bytes()).unwrap();
    assert_eq!(frame.message, msg);
}

#[test]
fn outbound_enum_builds_the_same_messages() {
    let out = Outbound::AttitudeTarget {
        target: Target::default(),
        time_boot_ms: 5,
        command: command(),
    };
    assert_eq!(
        out.to_message().unwrap(),
        set_attitude_target(Target::default(), 5, &command()).unwrap()
    );
    let bad = Outbound::LocalPositionNed {
        time_boot_ms: 0,
        position: [0.0, f64::NAN, 0.0],
        velocity: [0.0; 3],
    };
    assert!(matches!(bad.to_message(), Err(LinkError::NonFinite { .. })));
}

#[test]
fn system_id_above_255_is_refused() {
    let mut hdr = header(1, 191, 0);
    hdr.system_id = 300;
    assert!(matches!(
        serialize_v2(&hdr, &heartbeat_onboard(DaemonStatus::Boot)),
        Err(LinkError::SystemIdOutOfRange(300))
    ));
}
