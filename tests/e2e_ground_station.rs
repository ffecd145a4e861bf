//! MAVLink manners, end to end: the test plays the ground station on the
//! SITL's GCS port (system 255), the real daemon runs in process on the
//! vehicle link.
//!
//! * The SITL alone: HEARTBEAT at 1 Hz to a lone ground station (3–6 in
//!   4 s, not the plant rate), counted in its GCS counters.
//! * With the daemon flying: both components' HEARTBEATs at 1 Hz;
//!   COMMAND_ACK from both for a supported and an unsupported command; the
//!   SITL's parameters listed and read; a setpoint addressed to the
//!   autopilot answered with a STATUSTEXT; distinct refusal texts for a
//!   velocity-only setpoint and a wrong frame; a setpoint's yaw refused
//!   with a message (`vehicle.yaw_mode = "fixed"`); the SITL's ATTITUDE
//!   carries body rates in flight; a
//!   command to the SITL is not routed to the daemon.

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use dflat_daemon::config::MissionStart;
use dflat_link::dialect::{
    COMMAND_LONG_DATA, MavCmd, MavFrame, MavResult, PositionTargetTypemask,
    SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use dflat_link::{MavMessage, serialize_v2};
use dflat_sitl::{self as sitl, SitlHandle, SitlOptions, SitlSettings};

mod support;

use support::gcs::Gcs;

fn heartbeats(m: &MavMessage) -> Option<()> {
    matches!(m, MavMessage::HEARTBEAT(_)).then_some(())
}

fn text(m: &MavMessage) -> Option<String> {
    match m {
        MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
        _ => None,
    }
}

fn command(target: (u8, u8), command: MavCmd, param1: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        command,
        param1,
        target_system: target.0,
        target_component: target.1,
        ..COMMAND_LONG_DATA::default()
    })
}

/// (command, result) of a COMMAND_ACK addressed to the test's GCS.
fn ack(m: &MavMessage) -> Option<(MavCmd, MavResult)> {
    match m {
        MavMessage::COMMAND_ACK(d) if (d.target_system, d.target_component) == (255, 190) => {
            Some((d.command, d.result))
        }
        _ => None,
    }
}

fn setpoint(target: (u8, u8), p: [f32; 3], mask: u16, frame: MavFrame) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        x: p[0],
        y: p[1],
        z: p[2],
        yaw: 1.0,
        type_mask: PositionTargetTypemask::from_bits_truncate(mask),
        target_system: target.0,
        target_component: target.1,
        coordinate_frame: frame,
        ..SET_POSITION_TARGET_LOCAL_NED_DATA::default()
    })
}

/// Position only (velocity, acceleration and yaw rate ignored), yaw used.
const POSITION_AND_YAW: u16 = 8 | 16 | 32 | 64 | 128 | 256 | 2048;
/// Velocity only (position, acceleration, yaw, yaw rate ignored).
const VELOCITY_ONLY: u16 = 1 | 2 | 4 | 64 | 128 | 256 | 1024 | 2048;

fn plant(name: &str) -> (dflat_daemon::config::Config, SitlSettings) {
    // Engaged as soon as the stream runs (the demo plays a pilot instead).
    let (mut cfg, plant) = support::sitl_flight(name, dflat_sitl::SitlEngage::Auto);
    cfg.mission.start = MissionStart::Hold;
    (cfg, plant)
}

fn with_gcs(plant: &SitlSettings) -> SitlHandle {
    sitl::spawn(
        plant,
        SitlOptions {
            gcs: Some("udpin:127.0.0.1:0".into()),
            ..SitlOptions::default()
        },
    )
    .unwrap()
}

#[test]
fn a_lone_ground_station_gets_heartbeats_at_1_hz() {
    let (_, plant) = plant("gcs-alone");
    let sitl = with_gcs(&plant);
    let start = Instant::now();
    let gcs = Gcs::new(sitl.gcs_addr().unwrap(), 255);
    std::thread::sleep(Duration::from_millis(300));
    let since = Instant::now();
    std::thread::sleep(Duration::from_secs(4));
    // Parameter writes, FTP and signing set-up, answered by the SITL.
    let mut gcs = gcs;
    let set = |name: &str, value: f32| {
        MavMessage::PARAM_SET(dflat_link::dialect::PARAM_SET_DATA {
            param_value: value,
            target_system: 1,
            target_component: 1,
            param_id: dflat_link::params::param_id(name),
            param_type: dflat_link::dialect::MavParamType::MAV_PARAM_TYPE_REAL32,
        })
    };
    gcs.send(&set("COM_OF_LOSS_T", 1.5));
    gcs.send(&set("MPC_THR_HOVER", 0.3));
    let mut open = [0u8; 251];
    open[3] = 4; // OpenFileRO
    gcs.send(&MavMessage::FILE_TRANSFER_PROTOCOL(
        dflat_link::dialect::FILE_TRANSFER_PROTOCOL_DATA {
            target_network: 0,
            target_system: 1,
            target_component: 1,
            payload: open,
        },
    ));
    gcs.send(&MavMessage::SETUP_SIGNING(
        dflat_link::dialect::SETUP_SIGNING_DATA {
            target_system: 1,
            target_component: 1,
            ..Default::default()
        },
    ));
    let set_value = gcs.wait((1, 1), since, |m| match m {
        MavMessage::PARAM_VALUE(d) if d.param_id.to_str() == Ok("COM_OF_LOSS_T") => {
            Some(d.param_value)
        }
        _ => None,
    });
    let read_only = gcs.wait((1, 1), since, |m| {
        text(m).filter(|t| t.contains("read-only"))
    });
    let nak = gcs.wait((1, 1), since, |m| match m {
        MavMessage::FILE_TRANSFER_PROTOCOL(d) => Some((d.payload[3], d.payload[12])),
        _ => None,
    });
    let signing = gcs.wait((1, 1), since, |m| {
        text(m).filter(|t| t.contains("SETUP_SIGNING"))
    });
    eprintln!("PARAM_SET {set_value:?}, {read_only:?}, FTP {nak:?}, {signing:?}");
    assert_eq!(set_value, Some(1.5));
    assert!(read_only.is_some() && signing.is_some());
    assert_eq!(nak, Some((129, 10)), "FTP NAK FileNotFound");
    // The rates on the SITL's own clock (its plant steps) and counters,
    // not on the test's sleep: 1 Hz each, and the GCS got what was sent.
    let hb = gcs.from((1, 1), start, heartbeats).len() as u64;
    let status = gcs
        .from((1, 1), start, |m| {
            matches!(m, MavMessage::SYS_STATUS(_)).then_some(())
        })
        .len() as u64;
    let c = sitl.stop().unwrap().counters;
    let sitl_s = c.plant_steps as f64 / plant.sitl.plant_rate_hz;
    eprintln!(
        "lone GCS: {hb} HEARTBEATs, {status} SYS_STATUS received; in {sitl_s:.2} s of SITL time counters to_gcs {:?}, vehicle hb {}",
        c.to_gcs, c.heartbeats_sent
    );
    for (what, sent) in [
        ("HEARTBEAT", c.to_gcs.heartbeats),
        ("SYS_STATUS", c.to_gcs.sys_status),
    ] {
        assert!(
            (sent as f64 - sitl_s).abs() <= 1.5,
            "{sent} {what}s in {sitl_s:.2} s of SITL time: {c:?}"
        );
    }
    // Sent after the count are not received; none is lost on loopback.
    assert!(
        hb <= c.to_gcs.heartbeats && hb + 2 >= c.to_gcs.heartbeats,
        "{hb} HEARTBEATs received of {}",
        c.to_gcs.heartbeats
    );
    assert!(
        status <= c.to_gcs.sys_status && status + 2 >= c.to_gcs.sys_status,
        "{status} SYS_STATUS received of {}",
        c.to_gcs.sys_status
    );
    assert_eq!(c.heartbeats_sent, 0, "no vehicle peer: {c:?}");
    assert!(
        c.to_gcs.positions > 100,
        "telemetry to the GCS counted: {c:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ground_station_talks_to_both_components() {
    let (mut cfg, plant) = plant("gcs-daemon");
    // The refusal of a setpoint's yaw is `yaw_mode = "fixed"`'s (the yaw is
    // flown by default: tests/e2e_mission_yaw.rs).
    cfg.vehicle.yaw_mode = dflat_daemon::config::YawMode::Fixed;
    let hover = plant.sitl.hover_thrust;
    let sitl = with_gcs(&plant);
    let link = format!("udpout:127.0.0.1:{}", sitl.local_addr().port());
    let daemon = dflat_daemon::spawn(cfg, Some(link)).await.unwrap();
    let mut gcs = Gcs::new(sitl.gcs_addr().unwrap(), 255);
    tokio::time::sleep(Duration::from_millis(1500)).await;

    // Commands to both components: supported and not.
    let t0 = Instant::now();
    for comp in [191, 1] {
        gcs.send(&command((1, comp), MavCmd::MAV_CMD_REQUEST_MESSAGE, 0.0));
        gcs.send(&command((1, comp), MavCmd::MAV_CMD_NAV_TAKEOFF, 0.0));
    }
    gcs.send(&command((1, 1), MavCmd::MAV_CMD_REQUEST_MESSAGE, 30.0));
    // Parameters.
    gcs.send(&dflat_link::params::param_request_list((1, 1)));
    gcs.send(&dflat_link::params::param_request_read(
        (1, 1),
        "COM_OF_LOSS_T",
    ));
    // A setpoint where PX4 users send it: to the autopilot.
    gcs.send(&setpoint(
        (1, 1),
        [0.0, 0.0, -10.0],
        POSITION_AND_YAW,
        MavFrame::MAV_FRAME_LOCAL_NED,
    ));
    tokio::time::sleep(Duration::from_millis(500)).await;
    let mut acks = Vec::new();
    for comp in [191, 1] {
        acks.push(gcs.wait((1, comp), t0, |m| {
            ack(m).filter(|a| a.0 == MavCmd::MAV_CMD_REQUEST_MESSAGE)
        }));
        acks.push(gcs.wait((1, comp), t0, |m| {
            ack(m).filter(|a| a.0 == MavCmd::MAV_CMD_NAV_TAKEOFF)
        }));
    }
    eprintln!("acks (daemon, daemon, sitl, sitl): {acks:?}");
    let accepted = MavResult::MAV_RESULT_ACCEPTED;
    let unsupported = MavResult::MAV_RESULT_UNSUPPORTED;
    assert_eq!(acks[0].map(|a| a.1), Some(accepted));
    assert_eq!(acks[1].map(|a| a.1), Some(unsupported));
    assert_eq!(acks[2].map(|a| a.1), Some(accepted));
    // The SITL's plant starts in the air: takeoff refused in words.
    assert_eq!(acks[3].map(|a| a.1), Some(MavResult::MAV_RESULT_DENIED));
    let attitude = gcs.wait((1, 1), t0, |m| {
        matches!(m, MavMessage::ATTITUDE(_)).then_some(())
    });
    assert!(attitude.is_some());
    let params = gcs.from((1, 1), t0, |m| match m {
        MavMessage::PARAM_VALUE(d) => Some((
            d.param_id.to_str().unwrap_or("").to_owned(),
            d.param_value,
            d.param_count,
        )),
        _ => None,
    });
    eprintln!("params: {params:?}");
    assert!(
        params.iter().any(|(n, v, c)| n == "MPC_THR_HOVER"
            && (f64::from(*v) - hover).abs() < 1e-6
            && *c == 4)
    );
    assert!(
        params
            .iter()
            .any(|(n, v, _)| n == "MPC_TILTMAX_AIR" && (*v - 35.0).abs() < 1e-4)
    );
    let loss = params.iter().filter(|(n, ..)| n == "COM_OF_LOSS_T").count();
    assert_eq!(loss, 2, "listed and read: {params:?}");
    // The SITL keeps frames addressed to it (as PX4 does) and flies them
    // in OFFBOARD; with the daemon's attitude stream alive too, the latest
    // type wins and it says so. Sent straight to the daemon's socket from
    // another one, the frame is not heard at all: the daemon's socket is
    // connected to the autopilot (the kernel drops other senders), so it
    // says nothing.
    let sitl_told = gcs.wait((1, 1), t0, |m| {
        text(m).filter(|t| t.contains("2 setpoint streams"))
    });
    let direct = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to_autopilot = setpoint(
        (1, 1),
        [0.0, 0.0, -10.0],
        POSITION_AND_YAW,
        MavFrame::MAV_FRAME_LOCAL_NED,
    );
    let f = serialize_v2(&dflat_link::header(255, 190, 0), &to_autopilot).unwrap();
    direct
        .send_to(f.as_bytes(), daemon.local_addr().unwrap())
        .unwrap();
    let daemon_told = gcs.wait((1, 191), t0, |m| {
        text(m).filter(|t| t.contains("setpoints go to 1/191"))
    });
    eprintln!("setpoint to 1/1: SITL {sitl_told:?}, daemon {daemon_told:?}");
    assert!(sitl_told.is_some() && daemon_told.is_none());

    // Refusals with distinct words (the daemon rate-limits them to 1/s).
    let t1 = Instant::now();
    gcs.send(&setpoint(
        (1, 191),
        [1.0, 0.0, 0.0],
        VELOCITY_ONLY,
        MavFrame::MAV_FRAME_LOCAL_NED,
    ));
    tokio::time::sleep(Duration::from_millis(1100)).await;
    gcs.send(&setpoint(
        (1, 191),
        [0.0, 0.0, -10.0],
        POSITION_AND_YAW,
        MavFrame::MAV_FRAME_BODY_FRD,
    ));
    let velocity = gcs.wait((1, 191), t1, |m| {
        text(m).filter(|t| t.contains("velocity-only"))
    });
    let frame = gcs.wait((1, 191), t1, |m| {
        text(m).filter(|t| t.contains("not LOCAL_NED"))
    });
    eprintln!("refusals: {velocity:?} / {frame:?}");
    assert!(velocity.is_some() && frame.is_some());
    assert_ne!(velocity, frame);

    // A setpoint 4 m north with a yaw: flown, the yaw refused in words; the
    // SITL's ATTITUDE carries body rates on the way.
    let t2 = Instant::now();
    for _ in 0..3 {
        gcs.send(&setpoint(
            (1, 191),
            [4.0, 0.0, -10.0],
            POSITION_AND_YAW,
            MavFrame::MAV_FRAME_LOCAL_NED,
        ));
    }
    let yaw = gcs.wait((1, 191), t2, |m| {
        text(m).filter(|t| t.contains("yaw ignored"))
    });
    eprintln!("yaw: {yaw:?}");
    assert!(yaw.is_some(), "setpoint yaw neither flown nor refused");
    tokio::time::sleep(Duration::from_secs(3)).await;
    let rates = gcs.from((1, 1), t2, |m| match m {
        MavMessage::ATTITUDE(d) => Some((d.pitch.abs(), d.pitchspeed.abs().max(d.rollspeed.abs()))),
        _ => None,
    });
    let (max_pitch, max_rate) = rates
        .iter()
        .fold((0f32, 0f32), |(p, r), (a, b)| (p.max(*a), r.max(*b)));
    eprintln!(
        "ATTITUDE in flight: max |pitch| {max_pitch:.3} rad, max body rate {max_rate:.3} rad/s"
    );
    assert!(max_pitch > 0.1, "the vehicle did not fly: {max_pitch}");
    assert!(max_rate > 0.1, "ATTITUDE without body rates: {max_rate}");
    let hb_daemon = gcs.from((1, 191), t0, heartbeats).len() as u64;
    let hb_sitl = gcs.from((1, 1), t0, heartbeats).len() as u64;

    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let c = sitl.stop().unwrap().counters;
    eprintln!("sitl counters: {c:?}");
    // Both components' HEARTBEATs at 1 Hz, each on its own clock and
    // counters (the daemon's run time, the SITL's plant steps), not the
    // test's: none of the periodic ones missed, and beyond them only the
    // few sent at once (on REQUEST_MESSAGE above, on a state or mode
    // change). The GCS got some of each, routed, no more than were sent.
    let daemon_hb = summary.link_stats.sent.heartbeat;
    let sitl_s = c.plant_steps as f64 / plant.sitl.plant_rate_hz;
    eprintln!(
        "{daemon_hb} daemon HEARTBEATs in {:.2} s of its run, {} SITL HEARTBEATs in {sitl_s:.2} s of SITL time; the GCS got {hb_daemon} and {hb_sitl} after the commands",
        summary.duration_s, c.to_gcs.heartbeats
    );
    let at_1_hz = |n: u64, s: f64| n as f64 >= s - 1.0 && n as f64 <= s + 4.0;
    assert!(
        at_1_hz(daemon_hb, summary.duration_s),
        "{daemon_hb} daemon HEARTBEATs in {:.2} s",
        summary.duration_s
    );
    assert!(
        at_1_hz(c.to_gcs.heartbeats, sitl_s),
        "{} SITL HEARTBEATs to the GCS in {sitl_s:.2} s",
        c.to_gcs.heartbeats
    );
    assert!(
        (2..=daemon_hb).contains(&hb_daemon),
        "{hb_daemon} of {daemon_hb} routed"
    );
    assert!(
        (2..=c.to_gcs.heartbeats).contains(&hb_sitl),
        "{hb_sitl} of {} received",
        c.to_gcs.heartbeats
    );
    // Commands, requests and the setpoint to the SITL itself stayed there.
    // The SITL acked the ground station's three commands and the daemon's
    // two stream-rate requests (LOCAL_POSITION_NED, ATTITUDE:
    // `link.request_streams`).
    assert!(c.gcs_frames_kept >= 6, "{c:?}");
    assert_eq!(
        (c.commands_acked, c.commands_unsupported, c.commands_denied),
        (3 + 2, 0, 1),
        "{c:?}"
    );
}
