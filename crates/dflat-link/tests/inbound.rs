//! Decoding, validation and source filtering of inbound messages.

use dflat_link::dialect::{
    LOCAL_POSITION_NED_DATA, MavFrame, ODOMETRY_DATA, PositionTargetTypemask,
    SET_POSITION_TARGET_LOCAL_NED_DATA, VISION_POSITION_ESTIMATE_DATA,
};
use dflat_link::dialect::{MavAutopilot, MavState};
use dflat_link::{
    AttitudeCommand, DaemonStatus, ErrorCategory, Inbound, LinkError, LinkRx, MavHeader,
    MavMessage, PoseSource, RxOutcome, SetpointRejection, SourceFilter, Target, Verdict, attitude,
    decode, header, heartbeat_autopilot, heartbeat_onboard, local_position_ned, odometry,
    quaternion_from_euler, set_attitude_target, vision_position_estimate,
};

const AUTOPILOT: MavHeader = MavHeader {
    system_id: 1,
    component_id: 1,
    sequence: 0,
};
const GCS: MavHeader = MavHeader {
    system_id: 255,
    component_id: 190,
    sequence: 0,
};

fn pose(msg: &MavMessage) -> dflat_link::Pose {
    match decode(&AUTOPILOT, msg) {
        Ok(Inbound::Pose(p)) => p,
        other => panic!("expected a pose, got {other:?}"),
    }
}

#[test]
fn pose_from_local_position_ned() {
    let msg = local_position_ned(1500, [1.0, -2.0, -3.5], [0.1, 0.2, 0.3]).unwrap();
    let p = pose(&msg);
    assert_eq!(p.source, PoseSource::LocalPositionNed);
    assert_eq!(p.time_usec, 1_500_000);
    assert_eq!(p.position, [1.0, -2.0, -3.5]);
    assert_eq!(p.yaw, None);
    assert_eq!(p.reset_counter, None);
}

#[test]
fn pose_from_odometry_takes_yaw_from_quaternion() {
    let msg = odometry(
        77_000_123,
        [4.0, 5.0, -6.0],
        [0.2, -0.1, -2.5],
        [0.0; 3],
        [0.0; 3],
        9,
    )
    .unwrap();
    let p = pose(&msg);
    assert_eq!(p.source, PoseSource::Odometry);
    assert_eq!(p.time_usec, 77_000_123);
    assert_eq!(p.position, [4.0, 5.0, -6.0]);
    assert!((p.yaw.unwrap() + 2.5).abs() < 1e-6);
    assert_eq!(p.reset_counter, Some(9));

    // A hand-built pure-yaw quaternion, LOCAL_FRD frame, slightly off unit norm.
    let q = quaternion_from_euler(0.0, 0.0, 0.7).map(|v| (v * 1.01) as f32);
    let msg = MavMessage::ODOMETRY(ODOMETRY_DATA {
        q,
        frame_id: MavFrame::MAV_FRAME_LOCAL_FRD,
        ..ODOMETRY_DATA::default()
    });
    assert!((pose(&msg).yaw.unwrap() - 0.7).abs() < 1e-6);
}

#[test]
fn odometry_frame_and_quaternion_are_checked() {
    let good = quaternion_from_euler(0.0, 0.0, 0.0).map(|v| v as f32);
    let enu = MavMessage::ODOMETRY(ODOMETRY_DATA {
        q: good,
        frame_id: MavFrame::MAV_FRAME_LOCAL_ENU,
        ..ODOMETRY_DATA::default()
    });
    assert!(matches!(
        decode(&AUTOPILOT, &enu),
        Err(LinkError::UnsupportedFrame {
            frame: MavFrame::MAV_FRAME_LOCAL_ENU,
            ..
        })
    ));
    let zero_q = MavMessage::ODOMETRY(ODOMETRY_DATA {
        q: [0.0; 4],
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        ..ODOMETRY_DATA::default()
    });
    let e = decode(&AUTOPILOT, &zero_q).unwrap_err();
    assert!(matches!(e, LinkError::BadQuaternion { .. }));
    assert_eq!(e.category(), ErrorCategory::Malformed);
    let nan_q = MavMessage::ODOMETRY(ODOMETRY_DATA {
        q: [f32::NAN, 0.0, 0.0, 0.0],
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        ..ODOMETRY_DATA::default()
    });
    assert_eq!(
        decode(&AUTOPILOT, &nan_q).unwrap_err().category(),
        ErrorCategory::NonFinite
    );
}

#[test]
fn pose_from_vision_position_estimate() {
    let msg = vision_position_estimate(123, [0.5, 0.25, -1.0], [0.0, 0.1, 3.0], 2, None).unwrap();
    let p = pose(&msg);
    assert_eq!(p.source, PoseSource::VisionPositionEstimate);
    assert_eq!(p.time_usec, 123);
    assert_eq!(p.position, [0.5, 0.25, -1.0]);
    assert!((p.yaw.unwrap() - 3.0).abs() < 1e-6);
    assert_eq!(p.reset_counter, Some(2));
}

#[test]
fn non_finite_positions_are_rejected() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let lpn = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            y: bad,
            ..LOCAL_POSITION_NED_DATA::default()
        });
        let vpe = MavMessage::VISION_POSITION_ESTIMATE(VISION_POSITION_ESTIMATE_DATA {
            z: bad,
            ..VISION_POSITION_ESTIMATE_DATA::default()
        });
        for msg in [lpn, vpe] {
            let e = decode(&AUTOPILOT, &msg).unwrap_err();
            assert!(matches!(e, LinkError::NonFinite { .. }), "{e}");
            assert_eq!(e.category(), ErrorCategory::NonFinite);
        }
    }
    // Unused fields may be NaN (velocity of LOCAL_POSITION_NED is not read).
    let msg = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        vx: f32::NAN,
        ..LOCAL_POSITION_NED_DATA::default()
    });
    assert!(decode(&AUTOPILOT, &msg).is_ok());
}

#[test]
fn attitude_decodes_angles_and_rates() {
    let msg = attitude(40, [0.1, 0.2, 0.3], [1.0, 2.0, 3.0]).unwrap();
    let Ok(Inbound::Attitude(a)) = decode(&AUTOPILOT, &msg) else {
        panic!()
    };
    assert_eq!(a.time_boot_ms, 40);
    assert!((a.yaw - 0.3).abs() < 1e-7 && (a.rates[2] - 3.0).abs() < 1e-7);
}

#[test]
fn heartbeat_decodes_armed_flag() {
    let msg = heartbeat_autopilot(
        MavAutopilot::MAV_AUTOPILOT_PX4,
        true,
        42,
        MavState::MAV_STATE_ACTIVE,
    );
    let Ok(Inbound::Heartbeat(h)) = decode(&AUTOPILOT, &msg) else {
        panic!()
    };
    assert!(h.armed);
    assert_eq!(h.custom_mode, 42);
    assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_PX4);
}

fn setpoint(frame: MavFrame, mask: PositionTargetTypemask) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms: 9,
        x: 1.0,
        y: 2.0,
        z: -3.0,
        vx: f32::NAN, // ignored fields may be anything
        yaw: 0.5,
        type_mask: mask,
        target_system: 1,
        target_component: 191,
        coordinate_frame: frame,
        ..SET_POSITION_TARGET_LOCAL_NED_DATA::default()
    })
}

#[test]
fn setpoint_in_local_ned_is_accepted() {
    let mask = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE;
    let Ok(Inbound::PositionSetpoint(s)) =
        decode(&GCS, &setpoint(MavFrame::MAV_FRAME_LOCAL_NED, mask))
    else {
        panic!()
    };
    assert_eq!(s.position, [1.0, 2.0, -3.0]);
    assert_eq!(s.yaw, Some(0.5));
    let no_yaw = mask | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE;
    let Ok(Inbound::PositionSetpoint(s)) =
        decode(&GCS, &setpoint(MavFrame::MAV_FRAME_LOCAL_NED, no_yaw))
    else {
        panic!()
    };
    assert_eq!(s.yaw, None);
}

#[test]
fn setpoint_in_other_frames_or_without_position_is_rejected() {
    let empty = PositionTargetTypemask::empty();
    for frame in [
        MavFrame::MAV_FRAME_BODY_FRD,
        MavFrame::MAV_FRAME_LOCAL_OFFSET_NED,
        MavFrame::MAV_FRAME_LOCAL_FRD,
        MavFrame::MAV_FRAME_LOCAL_ENU,
        MavFrame::MAV_FRAME_GLOBAL,
    ] {
        let e = decode(&GCS, &setpoint(frame, empty)).unwrap_err();
        assert!(
            matches!(e, LinkError::SetpointRejected(SetpointRejection::Frame(f)) if f == frame),
            "{e}"
        );
        assert_eq!(e.category(), ErrorCategory::Rejected);
    }
    let z_ignored = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE;
    let e = decode(&GCS, &setpoint(MavFrame::MAV_FRAME_LOCAL_NED, z_ignored)).unwrap_err();
    assert!(matches!(
        e,
        LinkError::SetpointRejected(SetpointRejection::PositionIgnored { type_mask: 4 })
    ));
}

#[test]
fn source_filter_rules() {
    let f = SourceFilter::default();
    let hb = heartbeat_autopilot(
        MavAutopilot::MAV_AUTOPILOT_GENERIC,
        false,
        0,
        MavState::MAV_STATE_STANDBY,
    );
    let pos = local_position_ned(0, [0.0; 3], [0.0; 3]).unwrap();
    let sp = setpoint(
        MavFrame::MAV_FRAME_LOCAL_NED,
        PositionTargetTypemask::empty(),
    );

    assert_eq!(f.check(&AUTOPILOT, &hb), Verdict::Accept);
    assert_eq!(f.check(&AUTOPILOT, &pos), Verdict::Accept);
    // Another vehicle, another component, the GCS: not trusted for state.
    assert_eq!(f.check(&header(2, 1, 0), &pos), Verdict::IgnoreWrongSource);
    assert_eq!(f.check(&header(1, 100, 0), &hb), Verdict::IgnoreWrongSource);
    assert_eq!(f.check(&GCS, &pos), Verdict::IgnoreWrongSource);
    // Our own echo.
    assert_eq!(
        f.check(&header(1, 191, 0), &heartbeat_onboard(DaemonStatus::Active)),
        Verdict::IgnoreWrongSource
    );
    // Setpoints: from the GCS, addressed to us.
    assert_eq!(f.check(&GCS, &sp), Verdict::Accept);
    assert_eq!(f.check(&AUTOPILOT, &sp), Verdict::IgnoreWrongSource);
    assert_eq!(f.check(&header(1, 195, 0), &sp), Verdict::IgnoreWrongSource);
    let allowed = SourceFilter {
        setpoint_components: vec![195],
        ..SourceFilter::default()
    };
    assert_eq!(allowed.check(&header(1, 195, 0), &sp), Verdict::Accept);
    let MavMessage::SET_POSITION_TARGET_LOCAL_NED(mut d) = sp.clone() else {
        panic!()
    };
    d.target_component = 1; // meant for the autopilot
    let to_autopilot = MavMessage::SET_POSITION_TARGET_LOCAL_NED(d.clone());
    assert_eq!(f.check(&GCS, &to_autopilot), Verdict::IgnoreNotAddressed);
    d.target_system = 0;
    d.target_component = 0; // broadcast
    let broadcast = MavMessage::SET_POSITION_TARGET_LOCAL_NED(d);
    assert_eq!(f.check(&GCS, &broadcast), Verdict::Accept);
    // Vision poses may also come from configured companion components.
    let vpe = vision_position_estimate(0, [0.0; 3], [0.0; 3], 0, None).unwrap();
    assert_eq!(
        f.check(&header(1, 197, 0), &vpe),
        Verdict::IgnoreWrongSource
    );
    let vio = SourceFilter {
        pose_components: vec![197],
        ..SourceFilter::default()
    };
    assert_eq!(vio.check(&header(1, 197, 0), &vpe), Verdict::Accept);
}

/// COMMAND_ACK: the autopilot's answers to this daemon (or to nobody)
/// only; its answer to a ground station's command, and a ground station's
/// own acks, are not acted on.
#[test]
fn command_acks_only_from_the_autopilot_to_us() {
    use dflat_link::dialect::{COMMAND_ACK_DATA, MavCmd, MavResult};
    let f = SourceFilter::default();
    let ack = |target_system, target_component| {
        MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            result: MavResult::MAV_RESULT_ACCEPTED,
            progress: 0,
            result_param2: 0,
            target_system,
            target_component,
        })
    };
    assert_eq!(f.check(&AUTOPILOT, &ack(1, 191)), Verdict::Accept);
    assert_eq!(f.check(&AUTOPILOT, &ack(0, 0)), Verdict::Accept);
    assert_eq!(
        f.check(&AUTOPILOT, &ack(255, 190)),
        Verdict::IgnoreNotAddressed
    );
    assert_eq!(f.check(&GCS, &ack(1, 191)), Verdict::IgnoreWrongSource);
    let mut rx = LinkRx::new(f);
    assert!(matches!(
        rx.handle(&AUTOPILOT, &ack(1, 191)),
        RxOutcome::Accepted(Inbound::CommandAck(a)) if a.result == MavResult::MAV_RESULT_ACCEPTED
    ));
}

#[test]
fn sitl_side_accepts_attitude_targets_from_the_daemon() {
    let sitl = SourceFilter {
        own_component_id: 1,
        ..SourceFilter::default()
    };
    let cmd = AttitudeCommand {
        roll: 0.05,
        pitch: -0.1,
        yaw: 0.2,
        thrust: 0.5,
    };
    let msg = set_attitude_target(Target::default(), 10, &cmd).unwrap();
    let daemon = header(1, 191, 0);
    assert_eq!(sitl.check(&daemon, &msg), Verdict::Accept);
    assert_eq!(
        sitl.check(&header(3, 191, 0), &msg),
        Verdict::IgnoreWrongSource
    );
    let Ok(Inbound::AttitudeTarget(t)) = decode(&daemon, &msg) else {
        panic!()
    };
    assert_eq!(t.body_rates, [None, None, None]);
    assert!((t.thrust.unwrap() - 0.5).abs() < 1e-7);
    let e = dflat_link::euler_from_quaternion(t.q.unwrap());
    assert!((e[0] - 0.05).abs() < 1e-6 && (e[1] + 0.1).abs() < 1e-6 && (e[2] - 0.2).abs() < 1e-6);
}

#[test]
fn link_rx_counts_every_outcome() {
    let mut rx = LinkRx::new(SourceFilter::default());
    let pos = local_position_ned(0, [1.0, 2.0, 3.0], [0.0; 3]).unwrap();
    assert!(matches!(
        rx.handle(&AUTOPILOT, &pos),
        RxOutcome::Accepted(Inbound::Pose(_))
    ));
    assert!(matches!(
        rx.handle(&header(9, 1, 0), &pos),
        RxOutcome::Ignored(Verdict::IgnoreWrongSource)
    ));
    let nan = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        x: f32::NAN,
        ..LOCAL_POSITION_NED_DATA::default()
    });
    assert!(matches!(
        rx.handle(&AUTOPILOT, &nan),
        RxOutcome::Rejected(LinkError::NonFinite { .. })
    ));
    let bad_sp = setpoint(
        MavFrame::MAV_FRAME_BODY_FRD,
        PositionTargetTypemask::empty(),
    );
    assert!(matches!(rx.handle(&GCS, &bad_sp), RxOutcome::Rejected(_)));
    assert_eq!(rx.stats.received.local_position_ned, 3);
    assert_eq!(rx.stats.received.set_position_target_local_ned, 1);
    assert_eq!(rx.stats.ignored_wrong_source, 1);
    assert_eq!(rx.stats.non_finite, 1);
    assert_eq!(rx.stats.rejected, 1);
    let summary = rx.stats.summary();
    assert!(summary.contains("lpos=3"), "{summary}");
    assert!(summary.contains("nonfinite=1"), "{summary}");
}
