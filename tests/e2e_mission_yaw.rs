//! Missions over MAVLink to the daemon (1/191) and yaw, end to end: the
//! test is the ground station on the SITL's GCS port (255/190), the real
//! daemon runs in process on the vehicle link, the SITL flies yaw (its
//! pitch and roll act in the body frame at the actual heading).
//!
//! One flight: a refused item (NAV_TAKEOFF: MISSION_ACK UNSUPPORTED and a
//! STATUSTEXT); a four-item upload (DO_CHANGE_SPEED, three waypoints, one
//! with a 90° yaw) accepted and downloaded back; MISSION_START, PAUSE and
//! CONTINUE acknowledged; a partial upload during the flight that times
//! out (MISSION_ACK OPERATION_CANCELLED) while the mission flies on to its
//! last MISSION_ITEM_REACHED; MISSION_CURRENT on the way. Judged: the
//! vehicle stops during the pause; the heading follows the commanded yaw
//! within the yaw loop's lag and the commanded yaw turns no faster than
//! `vehicle.max_yaw_rate_deg_s`; the cross-track error to the mission's
//! polyline; the largest tilt step per command. Then the flight's records
//! (CSV and tlog) re-run by `dflat replay` with its configuration: every
//! command reproduced — the uploads, the refused and the timed-out ones,
//! and the mission commands included.

use std::time::{Duration, Instant};

use dflat_daemon::config::MissionStart;
use dflat_link::MavMessage;
use dflat_link::dialect::{
    COMMAND_LONG_DATA, MISSION_REQUEST_LIST_DATA, MavCmd, MavFrame, MavMissionResult,
    MavMissionType, MavResult,
};
use dflat_link::mission::{ItemFields, mission_count, mission_item_int, mission_request_int};
use dflat_sitl::{self as sitl, SitlOptions};

mod support;

use support::gcs::Gcs;

/// The daemon: system 1, component 191.
const DAEMON: (u32, u8) = (1, 191);

impl Gcs {
    /// Uploads `items` to 1/191, answering each MISSION_REQUEST_INT;
    /// returns the MISSION_ACK's result.
    fn upload(&mut self, items: &[ItemFields]) -> Option<MavMissionResult> {
        let since = Instant::now();
        let t = MavMissionType::MAV_MISSION_TYPE_MISSION;
        self.send(&mission_count((1, 191), items.len() as u16, t));
        let mut answered = 0;
        let until = Instant::now() + Duration::from_secs(5);
        while Instant::now() < until {
            if let Some(result) = self.from(DAEMON, since, ack_of).into_iter().next() {
                return Some(result);
            }
            let asked = self.from(DAEMON, since, |m| match m {
                MavMessage::MISSION_REQUEST_INT(d) => Some(d.seq),
                _ => None,
            });
            for seq in asked.into_iter().skip(answered) {
                answered += 1;
                if let Some(item) = items.get(usize::from(seq)) {
                    self.send(&mission_item_int((1, 191), item));
                }
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
    }
}

fn ack_of(m: &MavMessage) -> Option<MavMissionResult> {
    match m {
        MavMessage::MISSION_ACK(d) if (d.target_system, d.target_component) == (255, 190) => {
            Some(d.mavtype)
        }
        _ => None,
    }
}

fn text(m: &MavMessage) -> Option<String> {
    match m {
        MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
        _ => None,
    }
}

fn command(cmd: MavCmd, param1: f32, param2: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        command: cmd,
        param1,
        param2,
        target_system: 1,
        target_component: 191,
        ..COMMAND_LONG_DATA::default()
    })
}

fn command_ack(cmd: MavCmd) -> impl Fn(&MavMessage) -> Option<MavResult> {
    move |m| match m {
        MavMessage::COMMAND_ACK(d) if d.command == cmd => Some(d.result),
        _ => None,
    }
}

/// A local-NED item, x and y as metres × 1e4 (the specification).
fn item(seq: u16, command: MavCmd, params: [f32; 4], xyz: [f64; 3]) -> ItemFields {
    ItemFields {
        seq,
        frame: MavFrame::MAV_FRAME_LOCAL_NED,
        command,
        params,
        x: xyz[0] * 1e4,
        y: xyz[1] * 1e4,
        z: xyz[2] as f32,
        current: 0,
        autocontinue: 1,
        int: true,
    }
}

/// The yaw of a SET_ATTITUDE_TARGET's quaternion \[rad\].
fn yaw_of(q: [f32; 4]) -> f64 {
    let q = q.map(f64::from);
    dflat_link::math::yaw_from_quaternion(q)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mission_is_uploaded_started_paused_continued_and_its_yaw_flown() {
    let (mut cfg, plant) = support::sitl_flight("mission-yaw", dflat_sitl::SitlEngage::Auto);
    cfg.mission.start = MissionStart::Hold;
    let records = std::env::temp_dir().join(format!("dflat-mission-yaw-{}", std::process::id()));
    cfg.logging.dir = records.to_string_lossy().into_owned();
    cfg.logging.tlog = true;
    let flown = cfg.clone();
    let max_yaw_rate = cfg.vehicle.max_yaw_rate_deg_s.to_radians();
    let start = plant.sitl.start;
    let (tx, tap) = std::sync::mpsc::channel();
    // The plant runs in real time: its trace time is about the time since
    // here (used to pick the trace's windows, not to judge timing).
    let sim_t0 = Instant::now();
    let sim = sitl::spawn(
        &plant,
        SitlOptions {
            gcs: Some("udpin:127.0.0.1:0".into()),
            tap: Some(tx),
            record_trace: true,
            ..SitlOptions::default()
        },
    )
    .unwrap();
    let link = format!("udpout:127.0.0.1:{}", sim.local_addr().port());
    let daemon = dflat_daemon::spawn(cfg, Some(link)).await.unwrap();
    let mut gcs = Gcs::new(sim.gcs_addr().unwrap(), 255);
    tokio::time::sleep(Duration::from_millis(1500)).await;

    // A refused item: the upload ends with UNSUPPORTED and words.
    let at = |dx: f64, dy: f64| [start[0] + dx, start[1] + dy, start[2]];
    let t0 = Instant::now();
    let refused = gcs.upload(&[
        item(0, MavCmd::MAV_CMD_NAV_WAYPOINT, [0.0; 4], at(2.0, 0.0)),
        item(1, MavCmd::MAV_CMD_NAV_TAKEOFF, [0.0; 4], at(0.0, 0.0)),
    ]);
    let words = gcs.wait_for(DAEMON, t0, Duration::from_secs(1), |m| {
        text(m).filter(|t| t.contains("unsupported"))
    });
    eprintln!("refused upload: {refused:?}, {words:?}");
    assert_eq!(refused, Some(MavMissionResult::MAV_MISSION_UNSUPPORTED));
    assert!(words.is_some());
    // MISSION_START without a mission is denied.
    let t1 = Instant::now();
    gcs.send(&command(MavCmd::MAV_CMD_MISSION_START, 0.0, 0.0));
    let denied = gcs.wait_for(
        DAEMON,
        t1,
        Duration::from_secs(2),
        command_ack(MavCmd::MAV_CMD_MISSION_START),
    );
    assert_eq!(denied, Some(MavResult::MAV_RESULT_DENIED));

    // The mission: 4 m/s, an L (8 m north, then 6 m east, facing east
    // from the corner on), and back 6 m west.
    let waypoints = [at(8.0, 0.0), at(8.0, 6.0), at(8.0, 0.0)];
    let mission = [
        item(
            0,
            MavCmd::MAV_CMD_DO_CHANGE_SPEED,
            [1.0, 4.0, -1.0, 0.0],
            [0.0; 3],
        ),
        item(
            1,
            MavCmd::MAV_CMD_NAV_WAYPOINT,
            [0.0, 0.5, 0.0, f32::NAN],
            waypoints[0],
        ),
        item(
            2,
            MavCmd::MAV_CMD_NAV_WAYPOINT,
            [0.0, 0.5, 0.0, 90.0],
            waypoints[1],
        ),
        item(
            3,
            MavCmd::MAV_CMD_NAV_WAYPOINT,
            [0.0, 0.5, 0.0, f32::NAN],
            waypoints[2],
        ),
    ];
    assert_eq!(
        gcs.upload(&mission),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
    // Downloaded back as uploaded.
    let t2 = Instant::now();
    gcs.send(&MavMessage::MISSION_REQUEST_LIST(
        MISSION_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 191,
            mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
        },
    ));
    gcs.send(&mission_request_int(
        (1, 191),
        2,
        MavMissionType::MAV_MISSION_TYPE_MISSION,
    ));
    let count = gcs.wait_for(DAEMON, t2, Duration::from_secs(2), |m| match m {
        MavMessage::MISSION_COUNT(d) => Some(d.count),
        _ => None,
    });
    let item2 = gcs.wait_for(DAEMON, t2, Duration::from_secs(2), |m| match m {
        MavMessage::MISSION_ITEM_INT(d) => Some((d.seq, d.y, d.param4)),
        _ => None,
    });
    eprintln!("download: count {count:?}, item 2 {item2:?}");
    assert_eq!(count, Some(4));
    assert_eq!(
        item2,
        Some((2, ((start[1] + 6.0) * 1e4).round() as i32, 90.0))
    );

    // Start; a partial upload right after it times out while the mission
    // flies on.
    let t3 = Instant::now();
    gcs.send(&command(MavCmd::MAV_CMD_MISSION_START, 0.0, 0.0));
    let started = gcs.wait_for(
        DAEMON,
        t3,
        Duration::from_secs(2),
        command_ack(MavCmd::MAV_CMD_MISSION_START),
    );
    assert_eq!(started, Some(MavResult::MAV_RESULT_ACCEPTED));
    gcs.send(&mission_count(
        (1, 191),
        3,
        MavMissionType::MAV_MISSION_TYPE_MISSION,
    ));
    // Pause after 1.5 s, hold 2 s, continue.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let t4 = Instant::now();
    gcs.send(&command(MavCmd::MAV_CMD_DO_PAUSE_CONTINUE, 0.0, 0.0));
    let paused = gcs.wait_for(
        DAEMON,
        t4,
        Duration::from_secs(2),
        command_ack(MavCmd::MAV_CMD_DO_PAUSE_CONTINUE),
    );
    assert_eq!(paused, Some(MavResult::MAV_RESULT_ACCEPTED));
    tokio::time::sleep(Duration::from_millis(2500)).await;
    let t5 = Instant::now();
    gcs.send(&command(MavCmd::MAV_CMD_DO_PAUSE_CONTINUE, 1.0, 0.0));
    let continued = gcs.wait_for(
        DAEMON,
        t5,
        Duration::from_secs(2),
        command_ack(MavCmd::MAV_CMD_DO_PAUSE_CONTINUE),
    );
    assert_eq!(continued, Some(MavResult::MAV_RESULT_ACCEPTED));
    let last = gcs.wait_for(DAEMON, t3, Duration::from_secs(25), |m| match m {
        MavMessage::MISSION_ITEM_REACHED(d) if d.seq == 3 => Some(()),
        _ => None,
    });
    // The partial upload's end (1.5 s × 6 requests), and the stored
    // mission after it.
    gcs.wait_for(DAEMON, t3, Duration::from_secs(12), ack_of);
    let t6 = Instant::now();
    gcs.send(&MavMessage::MISSION_REQUEST_LIST(
        MISSION_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 191,
            mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
        },
    ));
    let count_after = gcs.wait_for(DAEMON, t6, Duration::from_secs(2), |m| match m {
        MavMessage::MISSION_COUNT(d) => Some(d.count),
        _ => None,
    });
    let cancelled = gcs.from(DAEMON, t3, ack_of);
    let reached = gcs.from(DAEMON, t3, |m| match m {
        MavMessage::MISSION_ITEM_REACHED(d) => Some(d.seq),
        _ => None,
    });
    let current = gcs.from(DAEMON, t3, |m| match m {
        MavMessage::MISSION_CURRENT(d) => Some((d.seq, d.total, d.mission_state as u8)),
        _ => None,
    });
    let texts = gcs.from(DAEMON, t0, text);
    eprintln!("reached {reached:?}; acks after start {cancelled:?}; texts {texts:?}");
    eprintln!("MISSION_CURRENT (seq, total, state): {current:?}");
    tokio::time::sleep(Duration::from_millis(500)).await;
    daemon.shutdown();
    let summary = daemon.join().await.unwrap();
    let report = sim.stop().unwrap();
    // The replay of the flight's records reproduces every command.
    let csv_path = summary.csv.as_ref().expect("the flight's CSV").path.clone();
    let csv = dflat::tools::read_csv(&csv_path).unwrap();
    let replayed = dflat::tools::replay::replay(&csv_path, &csv, &flown).unwrap();
    eprintln!(
        "replay: {} of {} commands identical, {} ticks where one side streamed, largest difference {:.2e} rad",
        replayed.identical, replayed.compared, replayed.stream_differs, replayed.max_angle_diff
    );
    assert!(replayed.compared > 500, "{} compared", replayed.compared);
    assert_eq!(replayed.identical, replayed.compared);
    assert_eq!(replayed.stream_differs, 0);
    let _ = std::fs::remove_dir_all(&records);
    assert!(last.is_some(), "the mission's last item was not reached");
    assert_eq!(reached, vec![1, 2, 3]);
    assert_eq!(
        count_after,
        Some(4),
        "the failed upload changed the mission"
    );
    assert_eq!(
        cancelled,
        vec![MavMissionResult::MAV_MISSION_OPERATION_CANCELLED],
        "the partial upload times out, nothing else"
    );
    assert!(
        current.iter().any(|c| c.2 == 4),
        "no PAUSED MISSION_CURRENT"
    );
    assert_eq!(current.last().map(|c| (c.0, c.2)), Some((3, 5)));

    // The truth: stopped during the pause; the cross-track error; the heading.
    let trace = &report.trace;
    let t_of = |at: Instant| at.duration_since(sim_t0).as_secs_f64();
    let (t_start, pause_at, resume_at) = (t_of(t3), t_of(t4), t_of(t5));
    let in_window = |s: &dflat_sitl::TruthSample, a: f64, b: f64| s.t >= a && s.t <= b;
    let speed = |s: &dflat_sitl::TruthSample| s.velocity[0].hypot(s.velocity[1]);
    let paused_speed = trace
        .iter()
        .filter(|s| in_window(s, resume_at - 0.3, resume_at - 0.05))
        .map(speed)
        .fold(0.0, f64::max);
    let mut polyline = vec![start];
    polyline.extend(waypoints);
    let cross: Vec<f64> = trace
        .iter()
        .filter(|s| s.t >= t_start)
        .map(|s| support::path_distance(&polyline, s.position))
        .collect();
    let cross_p95 = support::quantile(&cross, 0.95);
    let cross_max = cross.iter().copied().fold(0.0, f64::max);
    // Heading vs the command that reached the plant.
    let lag = trace
        .iter()
        .filter(|s| s.t >= t_start)
        .filter_map(|s| {
            s.command
                .map(|c| dflat_link::math::wrap_pi(s.euler[2] - c.yaw).abs())
        })
        .fold(0.0, f64::max);
    let final_heading = report.last.euler[2];
    // The daemon's commands: yaw rate by its own timestamps, tilt steps.
    let targets: Vec<(u32, f64, f64)> = tap
        .try_iter()
        .filter_map(|f| match f.message {
            MavMessage::SET_ATTITUDE_TARGET(d) => {
                let [r, p, _] = dflat_link::euler_from_quaternion(d.q.map(f64::from));
                Some((d.time_boot_ms, yaw_of(d.q), (p.cos() * r.cos()).acos()))
            }
            _ => None,
        })
        .collect();
    // The yaw rate over 10 commands (time_boot_ms is whole milliseconds).
    let mut unwrapped = vec![0.0];
    let mut tilt_step: f64 = 0.0;
    for w in targets.windows(2) {
        let last = unwrapped[unwrapped.len() - 1];
        unwrapped.push(last + dflat_link::math::wrap_pi(w[1].1 - w[0].1));
        tilt_step = tilt_step.max((w[1].2 - w[0].2).abs());
    }
    let mut yaw_rate: f64 = 0.0;
    for i in 10..targets.len() {
        let dt = f64::from(targets[i].0.saturating_sub(targets[i - 10].0)) / 1000.0;
        if dt > 0.0 {
            yaw_rate = yaw_rate.max((unwrapped[i] - unwrapped[i - 10]).abs() / dt);
        }
    }
    eprintln!(
        "pause: speed {paused_speed:.3} m/s before continue; cross-track p95 {cross_p95:.3} m, \
         max {cross_max:.3} m; heading lag ≤ {:.2}°, final heading {:.1}°; command yaw rate \
         ≤ {:.1}°/s (limit {:.0}); largest tilt step {:.2}°/tick over {} commands",
        lag.to_degrees(),
        final_heading.to_degrees(),
        yaw_rate.to_degrees(),
        max_yaw_rate.to_degrees(),
        tilt_step.to_degrees(),
        targets.len()
    );
    assert!(pause_at < resume_at);
    assert!(
        paused_speed < 0.3,
        "still moving when paused: {paused_speed}"
    );
    assert!(cross_p95 < 0.5, "cross-track p95 {cross_p95}");
    assert!(
        (final_heading.to_degrees() - 90.0).abs() < 2.0,
        "heading {final_heading}"
    );
    assert!(yaw_rate <= max_yaw_rate * 1.02, "yaw rate {yaw_rate}");
    // The yaw loop's lag at the yaw-rate limit: rate × τ_ψ (0.1 s) plus a
    // command period of hold.
    assert!(
        lag <= max_yaw_rate * (0.1 + 0.02) + 1f64.to_radians(),
        "heading lag {}°",
        lag.to_degrees()
    );
    assert!(targets.len() > 500);
    // No goal change jumps the command (issue 22's 5°/tick). Measured
    // 3.11°/tick; 12.6°/tick while the SITL applied pitch and roll at the
    // lagging actual heading instead of the command's thrust axis.
    assert!(
        tilt_step <= 5f64.to_radians(),
        "tilt step {:.2}°/tick",
        tilt_step.to_degrees()
    );
}
