//! From a MAVSDK script (issue 26), end to end with the real daemon in
//! process and the SITL's ground-station port:
//!
//! * a ground station whose id `link.gcs_system_ids` does not name (MAVSDK's
//!   245 when only 255 is configured) is refused in words — a STATUSTEXT
//!   naming the id and the key, once per 10 s however often it sends,
//!   COMMAND_ACK DENIED for its commands — and its setpoint is never
//!   flown; with the default ids, 245's setpoint is flown;
//! * the SITL flies OFFBOARD position setpoints addressed to the autopilot
//!   with its own position loop: a streamed circle (4 m/s, radius 6 m,
//!   20 Hz position / velocity / acceleration) is tracked, and its error
//!   p95 is the anchor of the trajectory budget (printed);
//! * the SITL answers like a PX4: HOME_POSITION, EXTENDED_SYS_STATE,
//!   ATTITUDE_QUATERNION, AUTOPILOT_VERSION, SET_MESSAGE_INTERVAL, hold
//!   (AUTO_LOITER), goto, RTL, disarm, the mission protocol.

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use dflat_daemon::config::MissionStart;
use dflat_link::MavMessage;
use dflat_link::dialect::{
    COMMAND_INT_DATA, COMMAND_LONG_DATA, MISSION_CLEAR_ALL_DATA, MISSION_COUNT_DATA, MavCmd,
    MavFrame, MavLandedState, MavMissionResult, MavResult, PositionTargetTypemask,
    SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use dflat_sitl::{self as sitl, SitlHandle, SitlMode, SitlOptions, SitlSettings};

mod support;

use support::gcs::Gcs;

impl Gcs {
    /// Sends `target` the COMMAND_LONG `cmd` with params 1–3 `p`; returns
    /// when it was sent.
    fn command(&mut self, target: (u8, u8), cmd: MavCmd, p: [f32; 3]) -> Instant {
        let sent = Instant::now();
        self.send(&command(target, cmd, p));
        sent
    }

    /// (command, result) of a COMMAND_ACK addressed to this ground station.
    fn ack(&self, who: (u32, u8), since: Instant, cmd: MavCmd) -> Option<MavResult> {
        let me = (self.id, 190);
        self.wait(who, since, |m| match m {
            MavMessage::COMMAND_ACK(d)
                if d.command == cmd && (d.target_system, d.target_component) == me =>
            {
                Some(d.result)
            }
            _ => None,
        })
    }
}

fn text(m: &MavMessage) -> Option<String> {
    match m {
        MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
        _ => None,
    }
}

fn command(target: (u8, u8), command: MavCmd, p: [f32; 3]) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        command,
        param1: p[0],
        param2: p[1],
        param3: p[2],
        target_system: target.0,
        target_component: target.1,
        ..COMMAND_LONG_DATA::default()
    })
}

/// Position only (velocity, acceleration, yaw and yaw rate ignored).
const POSITION_ONLY: u16 = 8 | 16 | 32 | 64 | 128 | 256 | 1024 | 2048;
/// Position, velocity, acceleration (yaw and yaw rate ignored).
const PVA: u16 = 1024 | 2048;

fn setpoint(target: (u8, u8), p: [f64; 3], v: [f64; 3], a: [f64; 3], mask: u16) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        x: p[0] as f32,
        y: p[1] as f32,
        z: p[2] as f32,
        vx: v[0] as f32,
        vy: v[1] as f32,
        vz: v[2] as f32,
        afx: a[0] as f32,
        afy: a[1] as f32,
        afz: a[2] as f32,
        type_mask: PositionTargetTypemask::from_bits_truncate(mask),
        target_system: target.0,
        target_component: target.1,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        ..SET_POSITION_TARGET_LOCAL_NED_DATA::default()
    })
}

fn plant(name: &str) -> (dflat_daemon::config::Config, SitlSettings) {
    let (mut cfg, plant) = support::sitl_flight(name, dflat_sitl::SitlEngage::Auto);
    cfg.mission.start = MissionStart::Hold;
    (cfg, plant)
}

fn with_gcs(plant: &SitlSettings, trace: bool) -> SitlHandle {
    sitl::spawn(
        plant,
        SitlOptions {
            gcs: Some("udpin:127.0.0.1:0".into()),
            record_trace: trace,
            ..SitlOptions::default()
        },
    )
    .unwrap()
}

fn horizontal(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unknown_ground_station_is_refused_in_words_and_never_flown() {
    let (mut cfg, plant) = plant("gcs-unknown");
    cfg.link.gcs_system_ids = vec![255];
    let sitl = with_gcs(&plant, false);
    let link = format!("udpout:127.0.0.1:{}", sitl.local_addr().port());
    let daemon = dflat_daemon::spawn(cfg, Some(link)).await.unwrap();
    let mut mavsdk = Gcs::new(sitl.gcs_addr().unwrap(), 245);
    let until = Instant::now() + Duration::from_secs(10);
    while sitl.mode() != SitlMode::Offboard && Instant::now() < until {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert_eq!(sitl.mode(), SitlMode::Offboard, "the daemon flies");
    tokio::time::sleep(Duration::from_millis(500)).await;

    let start = sitl.truth().position;
    // MAVSDK's setpoints at 10 Hz for 2 s, 5 m north, and a command.
    let t0 = mavsdk.command((1, 191), MavCmd::MAV_CMD_REQUEST_MESSAGE, [0.0; 3]);
    for _ in 0..20 {
        let goal = [start[0] + 5.0, start[1], start[2]];
        mavsdk.send(&setpoint((1, 191), goal, [0.0; 3], [0.0; 3], POSITION_ONLY));
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let denied = mavsdk.ack((1, 191), t0, MavCmd::MAV_CMD_REQUEST_MESSAGE);
    tokio::time::sleep(Duration::from_millis(500)).await;
    let texts = mavsdk.from((1, 191), t0, |m| {
        text(m).filter(|t| t.contains("link.gcs_system_ids"))
    });
    let moved = horizontal(sitl.truth().position, start);
    eprintln!("ack {denied:?}; texts {texts:?}; moved {moved:.3} m");
    assert_eq!(denied, Some(MavResult::MAV_RESULT_DENIED));
    assert_eq!(texts.len(), 1, "said once per 10 s: {texts:?}");
    assert!(texts[0].contains("245"), "{texts:?}");
    assert!(moved < 0.3, "a refused setpoint was flown: {moved} m");

    daemon.shutdown();
    daemon.join().await.unwrap();
    sitl.stop().unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mavsdk_245_is_heard_by_default() {
    let (cfg, plant) = plant("gcs-245");
    assert_eq!(cfg.link.ground_station_ids(), vec![255, 245]);
    let sitl = with_gcs(&plant, false);
    let link = format!("udpout:127.0.0.1:{}", sitl.local_addr().port());
    let daemon = dflat_daemon::spawn(cfg, Some(link)).await.unwrap();
    let mut mavsdk = Gcs::new(sitl.gcs_addr().unwrap(), 245);
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let start = sitl.truth().position;
    let t0 = mavsdk.command((1, 191), MavCmd::MAV_CMD_REQUEST_MESSAGE, [0.0; 3]);
    let goal = [start[0] + 4.0, start[1], start[2]];
    for _ in 0..3 {
        mavsdk.send(&setpoint((1, 191), goal, [0.0; 3], [0.0; 3], POSITION_ONLY));
    }
    let accepted = mavsdk.ack((1, 191), t0, MavCmd::MAV_CMD_REQUEST_MESSAGE);
    let until = Instant::now() + Duration::from_secs(8);
    while Instant::now() < until && horizontal(sitl.truth().position, goal) > 0.2 {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let moved = horizontal(sitl.truth().position, start);
    let refused = mavsdk.from((1, 191), t0, |m| {
        text(m).filter(|t| t.contains("link.gcs_system_ids"))
    });
    eprintln!("ack {accepted:?}; flown {moved:.2} m; refusals {refused:?}");
    assert_eq!(accepted, Some(MavResult::MAV_RESULT_ACCEPTED));
    assert!(moved > 3.8, "245's setpoint not flown: {moved} m");
    assert!(refused.is_empty());
    daemon.shutdown();
    daemon.join().await.unwrap();
    sitl.stop().unwrap();
}

/// The reference circle: radius `r`, speed `v`, centred so that it starts
/// at `start` heading east; (p, v, a) at time `t` \[s\].
fn circle(start: [f64; 3], r: f64, v: f64, t: f64) -> ([f64; 3], [f64; 3], [f64; 3]) {
    let w = v / r;
    let c = [start[0] - r, start[1]];
    let th = w * t;
    let (s, co) = th.sin_cos();
    (
        [c[0] + r * co, c[1] + r * s, start[2]],
        [-r * w * s, r * w * co, 0.0],
        [-r * w * w * co, -r * w * w * s, 0.0],
    )
}

#[test]
fn the_sitl_flies_a_streamed_circle_with_its_position_loop() {
    let (_, plant) = plant("sitl-circle");
    let sitl = support::traced_sitl(&plant);
    // A companion on the vehicle link streams to the autopilot (1/1).
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to = sitl.local_addr();
    let start = sitl.truth().position;
    let (radius, speed, rate) = (6.0, 4.0, 20.0);
    let period = 2.0 * std::f64::consts::PI * radius / speed;
    let settle = 4.0;
    let span = settle + period * 1.25;
    let t0 = sitl.elapsed();
    let mut sent = 0u32;
    let mut seq = 0u8;
    loop {
        let t = sitl.elapsed() - t0;
        if t > span {
            break;
        }
        let (p, v, a) = circle(start, radius, speed, t);
        support::send(&socket, to, 1, 191, seq, &setpoint((1, 1), p, v, a, PVA));
        seq = seq.wrapping_add(1);
        sent += 1;
        let next = t0 + f64::from(sent) / rate;
        let wait = next - sitl.elapsed();
        if wait > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(wait));
        }
    }
    let accepted = sitl.position_setpoints_accepted();
    let report = sitl.stop().unwrap();
    let samples: Vec<_> = report
        .trace
        .iter()
        .filter(|s| s.t - t0 >= settle && s.t - t0 <= span)
        .collect();
    assert!(
        samples.iter().all(|s| s.mode == SitlMode::Offboard),
        "flown in OFFBOARD"
    );
    let mut errors: Vec<f64> = samples
        .iter()
        .map(|s| horizontal(s.position, circle(start, radius, speed, s.t - t0).0))
        .collect();
    errors.sort_by(f64::total_cmp);
    let p95 = support::quantile(&errors, 0.95);
    let max = errors.last().copied().unwrap_or(f64::NAN);
    // Command smoothness from the true attitude (telemetry rate).
    let tilts: Vec<f64> = samples
        .iter()
        .map(|s| s.euler[0].abs().max(s.euler[1].abs()).to_degrees())
        .collect();
    let max_tilt = tilts.iter().copied().fold(0.0, f64::max);
    let step = samples
        .windows(2)
        .map(|w| {
            (w[1].euler[0] - w[0].euler[0])
                .abs()
                .max((w[1].euler[1] - w[0].euler[1]).abs())
                .to_degrees()
        })
        .fold(0.0, f64::max);
    eprintln!(
        "SITL position loop, streamed circle r {radius} m, {speed} m/s, {rate} Hz p/v/a: \
         error p95 {p95:.3} m, max {max:.3} m over {} samples; max tilt {max_tilt:.1} deg, \
         largest attitude step {step:.2} deg per {:.0} ms; {accepted} of {sent} setpoints accepted",
        samples.len(),
        1000.0 / plant.sitl.telemetry_rate_hz
    );
    assert!(samples.len() > 200, "trace too short");
    assert!(accepted >= u64::from(sent) * 9 / 10, "{accepted} of {sent}");
    // The loop tracks the circle (a broken sign or missing feed-forward
    // gives errors of metres); the figure itself is the printed anchor.
    assert!(p95 < 0.25, "p95 {p95} m");
    assert!(max_tilt < 30.5, "tilt {max_tilt}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_sitl_answers_like_a_px4_an_sdk_can_script() {
    let (_, plant) = plant("sitl-px4-face");
    let sitl = with_gcs(&plant, false);
    let mut gcs = Gcs::new(sitl.gcs_addr().unwrap(), 245);
    tokio::time::sleep(Duration::from_millis(500)).await;
    let ap = (1u32, 1u8);
    let t0 = Instant::now();
    for id in [242.0, 245.0, 31.0, 148.0] {
        gcs.send(&command(
            (1, 1),
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [id, 0.0, 0.0],
        ));
    }
    let home = gcs.wait(ap, t0, |m| match m {
        MavMessage::HOME_POSITION(d) => Some((d.x, d.y, d.z, d.latitude)),
        _ => None,
    });
    let landed = gcs.wait(ap, t0, |m| match m {
        MavMessage::EXTENDED_SYS_STATE(d) => Some(d.landed_state),
        _ => None,
    });
    let quaternion = gcs.wait(ap, t0, |m| match m {
        MavMessage::ATTITUDE_QUATERNION(d) => Some(d.q1),
        _ => None,
    });
    let version = gcs.wait(ap, t0, |m| match m {
        MavMessage::AUTOPILOT_VERSION(d) => Some((d.uid, d.flight_sw_version)),
        _ => None,
    });
    eprintln!("home {home:?} landed {landed:?} q1 {quaternion:?} version {version:?}");
    let s = plant.sitl.start;
    assert_eq!(
        home.map(|h| (h.0, h.1, h.2)),
        Some((s[0] as f32, s[1] as f32, s[2] as f32))
    );
    assert_eq!(landed, Some(MavLandedState::MAV_LANDED_STATE_IN_AIR));
    assert!(quaternion.is_some_and(|q| q > 0.9));
    assert!(version.is_some_and(|(uid, v)| uid != 0 && v != 0));

    // SET_MESSAGE_INTERVAL: ATTITUDE_QUATERNION at 50 Hz for 1 s.
    let t1 = gcs.command(
        (1, 1),
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        [31.0, 20_000.0, 0.0],
    );
    assert_eq!(
        gcs.ack(ap, t1, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    tokio::time::sleep(Duration::from_millis(200)).await;
    let t2 = Instant::now();
    tokio::time::sleep(Duration::from_secs(1)).await;
    // Judged on the SITL's own clock (time_boot_ms), not the test's.
    let stamps = gcs.from(ap, t2, |m| match m {
        MavMessage::ATTITUDE_QUATERNION(d) => Some(d.time_boot_ms),
        _ => None,
    });
    let mut gaps: Vec<u32> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_unstable();
    let median = gaps.get(gaps.len() / 2).copied();
    eprintln!(
        "ATTITUDE_QUATERNION at 20 ms: {} in 1 s, median gap {median:?} ms",
        stamps.len()
    );
    assert!(stamps.len() >= 10, "{stamps:?}");
    assert!(median.is_some_and(|g| (15..=25).contains(&g)), "{gaps:?}");

    // Hold (AUTO_LOITER), then goto 8 m north, then RTL: flown by the
    // SITL's position loop.
    let t3 = gcs.command((1, 1), MavCmd::MAV_CMD_DO_SET_MODE, [1.0, 4.0, 3.0]);
    assert_eq!(
        gcs.ack(ap, t3, MavCmd::MAV_CMD_DO_SET_MODE),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(sitl.mode(), SitlMode::Loiter);
    let origin = dflat_sitl::px4_face::GeoOrigin::PX4_SITL;
    let (lat, lon, alt) = origin.global([s[0] + 8.0, s[1], s[2]]);
    let t4 = Instant::now();
    gcs.send(&MavMessage::COMMAND_INT(COMMAND_INT_DATA {
        command: MavCmd::MAV_CMD_DO_REPOSITION,
        param1: -1.0,
        param4: f32::NAN,
        x: (lat * 1e7).round() as i32,
        y: (lon * 1e7).round() as i32,
        z: alt as f32,
        frame: MavFrame::MAV_FRAME_GLOBAL,
        target_system: 1,
        target_component: 1,
        ..COMMAND_INT_DATA::default()
    }));
    assert_eq!(
        gcs.ack(ap, t4, MavCmd::MAV_CMD_DO_REPOSITION),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    let goal = [s[0] + 8.0, s[1], s[2]];
    let until = Instant::now() + Duration::from_secs(8);
    while Instant::now() < until && horizontal(sitl.truth().position, goal) > 0.2 {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let at_goal = horizontal(sitl.truth().position, goal);
    eprintln!("goto 8 m: {at_goal:.2} m from the goal");
    assert!(at_goal < 0.3, "{at_goal}");
    let t5 = gcs.command((1, 1), MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH, [0.0; 3]);
    assert_eq!(
        gcs.ack(ap, t5, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    let until = Instant::now() + Duration::from_secs(8);
    while Instant::now() < until && horizontal(sitl.truth().position, s) > 0.2 {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let home_err = horizontal(sitl.truth().position, s);
    eprintln!("RTL: {home_err:.2} m from home, mode {:?}", sitl.mode());
    assert_eq!(sitl.mode(), SitlMode::Rtl);
    assert!(home_err < 0.3, "{home_err}");

    // Missions answered (unsupported upload, clear-all accepted), takeoff
    // refused in words, disarm accepted.
    let t6 = Instant::now();
    gcs.send(&MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
        count: 2,
        target_system: 1,
        target_component: 1,
        ..MISSION_COUNT_DATA::default()
    }));
    gcs.send(&MavMessage::MISSION_CLEAR_ALL(MISSION_CLEAR_ALL_DATA {
        target_system: 1,
        target_component: 1,
        ..MISSION_CLEAR_ALL_DATA::default()
    }));
    gcs.send(&command((1, 1), MavCmd::MAV_CMD_NAV_TAKEOFF, [0.0; 3]));
    gcs.send(&command(
        (1, 1),
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [0.0; 3],
    ));
    tokio::time::sleep(Duration::from_millis(500)).await;
    let mission = gcs.from(ap, t6, |m| match m {
        MavMessage::MISSION_ACK(d) => Some(d.mavtype),
        _ => None,
    });
    eprintln!("mission acks {mission:?}");
    assert_eq!(
        mission,
        vec![
            MavMissionResult::MAV_MISSION_UNSUPPORTED,
            MavMissionResult::MAV_MISSION_ACCEPTED
        ]
    );
    assert_eq!(
        gcs.ack(ap, t6, MavCmd::MAV_CMD_NAV_TAKEOFF),
        Some(MavResult::MAV_RESULT_DENIED)
    );
    assert!(
        gcs.wait(ap, t6, |m| text(m)
            .filter(|t| t.contains("takeoff refused")))
            .is_some()
    );
    assert_eq!(
        gcs.ack(ap, t6, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    assert!(!sitl.armed());

    // Refusals are said once: 30 requests of an unsent message in 1.5 s,
    // one text.
    let t7 = Instant::now();
    for _ in 0..30 {
        gcs.send(&command(
            (1, 1),
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [77.0, 0.0, 0.0],
        ));
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let said = gcs
        .from(ap, t7, |m| text(m).filter(|t| t.contains("message 77")))
        .len();
    let acks = gcs
        .from(ap, t7, |m| match m {
            MavMessage::COMMAND_ACK(d) if d.command == MavCmd::MAV_CMD_REQUEST_MESSAGE => Some(()),
            _ => None,
        })
        .len();
    eprintln!("30 refused requests: {acks} acks, {said} texts");
    assert_eq!((acks, said), (30, 1));
    sitl.stop().unwrap();
}
