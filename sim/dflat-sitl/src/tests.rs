//! The SITL's own tests: telemetry, hold, commands, routing, signing, and
//! what it answers a ground station.

use super::step::hold_law;
use super::*;
use dflat_link::{frames, serialize_v2};
use dflat_sim::plant::{PlantState, build_plant};
use nalgebra::Vector3;

#[test]
fn udpin_parses_and_others_are_refused() {
    assert_eq!(
        parse_udpin("link", "udpin:127.0.0.1:14540").unwrap(),
        "127.0.0.1:14540".parse().unwrap()
    );
    assert!(parse_udpin("link", "udpout:127.0.0.1:14540").is_err());
    assert!(parse_udpin("link", "udpin:nonsense").is_err());
}

#[test]
fn truth_rows_round_trip() {
    let s = TruthSample {
        t: 1.25,
        position: [1.0, -2.0, -10.0],
        velocity: [0.5, 0.0, 0.0],
        euler: [0.0, -0.1, 0.0],
        command: Some(ReceivedCommand {
            roll: 0.0,
            pitch: -0.1,
            yaw: 0.0,
            thrust: 0.5,
        }),
        mode: SitlMode::Offboard,
    };
    let mut buf = Vec::new();
    write_truth_row(&mut buf, &s).unwrap();
    let dir = std::env::temp_dir().join(format!("dflat-truth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("t.csv");
    let mut text = b"header\n".to_vec();
    text.extend_from_slice(&buf);
    std::fs::write(&path, text).unwrap();
    let rows = read_truth_csv(&path).unwrap();
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0].position, [1.0, -2.0, -10.0]);
    assert!(rows[0].commanded);
    let _ = std::fs::remove_dir_all(&dir);
}

fn test_config() -> SitlSettings {
    let mut cfg = SitlSettings::default();
    cfg.sitl.url = "udpin:127.0.0.1:0".into();
    cfg.sitl.start = [0.0, 0.0, -10.0];
    cfg
}

#[test]
fn holds_position_without_commands_and_streams_telemetry() {
    let cfg = test_config();
    let sitl = spawn(
        &cfg,
        SitlOptions {
            record_trace: true,
            ..SitlOptions::default()
        },
    )
    .unwrap();
    // A peer speaks (a heartbeat from the daemon's component).
    let client = UdpSocket::bind("127.0.0.1:0").unwrap();
    client
        .set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    let hb = dflat_link::heartbeat_onboard(dflat_link::DaemonStatus::Standby);
    let f = serialize_v2(&dflat_link::header(1, 191, 0), &hb).unwrap();
    client.send_to(f.as_bytes(), sitl.local_addr()).unwrap();
    let mut buf = [0u8; 2048];
    let mut positions = 0;
    let deadline = Instant::now() + Duration::from_millis(400);
    while Instant::now() < deadline {
        if let Ok((n, _)) = client.recv_from(&mut buf) {
            for fr in frames(&buf[..n]).flatten() {
                if matches!(fr.message, MavMessage::LOCAL_POSITION_NED(_)) {
                    assert_eq!(fr.header.system_id, 1);
                    assert_eq!(fr.header.component_id, 1);
                    positions += 1;
                }
            }
        }
    }
    assert!(positions >= 10, "{positions} positions in 0.4 s");
    assert_eq!(sitl.mode(), SitlMode::Hold);
    let report = sitl.stop().unwrap();
    let p = report.last.position;
    assert!(p[0].abs() < 1e-6 && p[1].abs() < 1e-6 && (p[2] + 10.0).abs() < 1e-6);
    assert!(!report.trace.is_empty());
}

#[test]
fn hold_loop_brings_the_plant_back() {
    let cfg = test_config();
    let popts = plant_options(&cfg);
    for kind in [PlantKind::Planar, PlantKind::Spatial, PlantKind::RigidBody] {
        let mut plant = build_plant(kind, &popts, 1).unwrap();
        let mut s = PlantState::hover(Vector3::new(3.0, -2.0, -8.0), GRAVITY);
        s.velocity = Vector3::new(2.0, 1.0, 0.0);
        plant.reset(&s);
        let target = Vector3::new(0.0, 0.0, -10.0);
        for _ in 0..(20.0 / popts.plant_dt) as usize {
            let c = hold_law(&popts, &plant.true_state(), &target, &Vector3::zeros());
            plant.apply(&c);
            plant.advance(popts.plant_dt);
        }
        let e = plant.position() - target;
        let horizontal = e.x.hypot(e.y);
        assert!(horizontal < 0.05, "{kind:?}: {e:?}");
        if kind != PlantKind::Planar {
            assert!(e.z.abs() < 0.05, "{kind:?}: {e:?}");
        }
    }
}

fn attitude_target(target: (u8, u8), pitch: f64) -> MavMessage {
    dflat_link::set_attitude_target(
        dflat_link::Target {
            system: target.0,
            component: target.1,
        },
        0,
        &dflat_link::AttitudeCommand {
            roll: 0.0,
            pitch,
            yaw: 0.0,
            thrust: 0.5,
        },
    )
    .unwrap()
}

/// A SITL of [`test_config`] with a GCS port, and two client sockets
/// (100 ms read timeout) to play the daemon and the ground station.
fn with_gcs(options: SitlOptions) -> (SitlHandle, UdpSocket, UdpSocket) {
    let sitl = spawn(
        &test_config(),
        SitlOptions {
            gcs: Some("udpin:127.0.0.1:0".into()),
            ..options
        },
    )
    .unwrap();
    let daemon = UdpSocket::bind("127.0.0.1:0").unwrap();
    let gcs = UdpSocket::bind("127.0.0.1:0").unwrap();
    for s in [&daemon, &gcs] {
        s.set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
    }
    (sitl, daemon, gcs)
}

fn send(client: &UdpSocket, to: SocketAddr, sys: u8, comp: u8, msg: &MavMessage) {
    let f = serialize_v2(&dflat_link::header(sys, comp, 0), msg).unwrap();
    client.send_to(f.as_bytes(), to).unwrap();
}

#[test]
fn follows_addressed_commands_then_holds_after_timeout() {
    let mut cfg = test_config();
    cfg.sitl.command_timeout_s = 0.2;
    let sitl = spawn(&cfg, SitlOptions::default()).unwrap();
    let to = sitl.local_addr();
    let client = UdpSocket::bind("127.0.0.1:0").unwrap();
    // Addressed elsewhere, or from another system: ignored.
    send(&client, to, 1, 191, &attitude_target((1, 2), -0.2));
    send(&client, to, 7, 191, &attitude_target((1, 1), -0.2));
    // Nose down for 0.6 s: accelerates north.
    let until = Instant::now() + Duration::from_millis(600);
    while Instant::now() < until {
        send(&client, to, 1, 191, &attitude_target((1, 1), -0.2));
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(sitl.mode(), SitlMode::Offboard);
    let moving = sitl.truth();
    assert!(moving.velocity[0] > 0.3, "{moving:?}");
    assert!(moving.command.is_some_and(|c| (c.pitch + 0.2).abs() < 1e-3));
    // Silence: the stand-in holds on its own and stops.
    std::thread::sleep(Duration::from_millis(400));
    assert_eq!(sitl.mode(), SitlMode::Hold);
    let c = sitl.counters();
    assert_eq!(c.commands_ignored, 2, "{c:?}");
    assert!(c.commands_accepted >= 20, "{c:?}");
    assert_eq!(c.hold_entries, 1);
    let report = sitl.stop().unwrap();
    assert!(!report.diverged);
}

#[test]
fn routes_between_gcs_and_vehicle_link() {
    let (sitl, daemon, gcs) = with_gcs(SitlOptions::default());
    let hb = dflat_link::heartbeat_onboard(dflat_link::DaemonStatus::Standby);
    send(&daemon, sitl.local_addr(), 1, 191, &hb);
    send(&gcs, sitl.gcs_addr().unwrap(), 255, 190, &hb);
    std::thread::sleep(Duration::from_millis(50));
    // GCS → daemon.
    send(&gcs, sitl.gcs_addr().unwrap(), 255, 190, &hb);
    // daemon → GCS (a heartbeat: broadcast, routed).
    send(&daemon, sitl.local_addr(), 1, 191, &hb);
    let seen_by = |s: &UdpSocket, sys: u32| {
        let mut buf = [0u8; 4096];
        let until = Instant::now() + Duration::from_millis(500);
        while Instant::now() < until {
            if let Ok((n, _)) = s.recv_from(&mut buf)
                && frames(&buf[..n])
                    .flatten()
                    .any(|f| f.header.system_id == sys)
            {
                return true;
            }
        }
        false
    };
    assert!(
        seen_by(&daemon, 255),
        "GCS frame not routed to the vehicle link"
    );
    assert!(seen_by(&gcs, 1), "nothing routed to the GCS");
    let c = sitl.stop().unwrap().counters;
    assert!(c.gcs_frames_in >= 2 && c.gcs_frames_out >= 1, "{c:?}");
}

fn key(byte: u8) -> dflat_link::SigningKey {
    dflat_link::SigningKey::from_bytes([byte; 32])
}

/// Signing with `key` as `link_id`, starting at the wall clock.
fn signing(key: dflat_link::SigningKey, link_id: u8) -> Signing {
    Signing::new(key, link_id, timestamp_from_system_time(SystemTime::now()))
}

fn sign(signing: &mut Signing, sys: u8, comp: u8, seq: u8, msg: &MavMessage) -> Vec<u8> {
    let now = timestamp_from_system_time(SystemTime::now());
    let f = signing
        .sign(&dflat_link::header(sys, comp, seq), msg, now)
        .unwrap();
    f.as_bytes().to_vec()
}

/// The SITL's signing as `sitl.signing_key_file` sets it up.
fn sitl_signing_with(byte: u8) -> Signing {
    let mut s = signing(key(byte), SIGNING_LINK_ID);
    s.accept_unsigned_telemetry = true;
    s
}

#[test]
fn with_signing_only_signed_commands_are_applied() {
    let cfg = test_config();
    let sitl = spawn(
        &cfg,
        SitlOptions {
            signing: Some(sitl_signing_with(0x5a)),
            ..SitlOptions::default()
        },
    )
    .unwrap();
    let to = sitl.local_addr();
    let client = UdpSocket::bind("127.0.0.1:0").unwrap();
    client
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let cmd = attitude_target((1, 1), -0.2);
    // Unsigned, and signed with another key: refused and counted.
    let mut stranger = signing(key(0x33), 0);
    for _ in 0..5 {
        send(&client, to, 1, 191, &cmd);
        let f = sign(&mut stranger, 1, 191, 0, &cmd);
        client.send_to(&f, to).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(100));
    let c = sitl.counters();
    assert_eq!(c.commands_unauthenticated, 10, "{c:?}");
    assert_eq!(c.commands_accepted, 0, "{c:?}");
    assert_eq!(sitl.mode(), SitlMode::Hold);
    assert!(sitl.truth().command.is_none());
    // Signed with the SITL's key: applied.
    let mut ours = signing(key(0x5a), 0);
    let until = Instant::now() + Duration::from_millis(300);
    while Instant::now() < until {
        let f = sign(&mut ours, 1, 191, 0, &cmd);
        client.send_to(&f, to).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(60));
    assert_eq!(sitl.mode(), SitlMode::Offboard);
    let c = sitl.counters();
    assert!(c.commands_accepted >= 5, "{c:?}");
    assert_eq!(c.commands_unauthenticated, 10, "{c:?}");
    // A replayed signed command is refused.
    let f = sign(&mut ours, 1, 191, 0, &cmd);
    client.send_to(&f, to).unwrap();
    client.send_to(&f, to).unwrap();
    std::thread::sleep(Duration::from_millis(60));
    let after = sitl.counters();
    assert_eq!(
        after.commands_accepted,
        c.commands_accepted + 1,
        "{after:?}"
    );
    assert_eq!(after.commands_unauthenticated, 11, "{after:?}");
    // The SITL's telemetry is signed with its key, as link 1.
    let mut verifier = signing(key(0x5a), 0);
    let mut buf = [0u8; 2048];
    let mut verified = 0;
    let deadline = Instant::now() + Duration::from_millis(300);
    while Instant::now() < deadline {
        let Ok((n, _)) = client.recv_from(&mut buf) else {
            continue;
        };
        for fr in frames(&buf[..n]).flatten() {
            let now = timestamp_from_system_time(SystemTime::now());
            let check = verifier.verify(&fr.header, fr.signed.as_ref(), now);
            assert!(
                matches!(
                    check,
                    dflat_link::SignatureCheck::Valid {
                        link_id: SIGNING_LINK_ID,
                        ..
                    }
                ),
                "{:?}: {check:?}",
                fr.message
            );
            verified += 1;
        }
    }
    assert!(verified >= 10, "{verified} verified frames");
    sitl.stop().unwrap();
}

#[test]
fn signed_frames_are_routed_with_their_signature() {
    let (sitl, daemon, gcs) = with_gcs(SitlOptions {
        signing: Some(sitl_signing_with(0x5a)),
        ..SitlOptions::default()
    });
    let (link, gcs_port) = (sitl.local_addr(), sitl.gcs_addr().unwrap());
    let hb = dflat_link::heartbeat_onboard(dflat_link::DaemonStatus::Standby);
    let mut daemon_signing = signing(key(0x5a), 0);
    let mut gcs_signing = signing(key(0x5a), 2);
    let mut stranger = signing(key(0x33), 0);
    daemon
        .send_to(&sign(&mut daemon_signing, 1, 191, 0, &hb), link)
        .unwrap();
    gcs.send_to(&sign(&mut gcs_signing, 255, 190, 0, &hb), gcs_port)
        .unwrap();
    std::thread::sleep(Duration::from_millis(50));
    // daemon → GCS: a wrong key (seq 7) is dropped, unsigned (8) and
    // signed (9) heartbeats are routed, the signed one byte for byte.
    daemon
        .send_to(&sign(&mut stranger, 1, 191, 7, &hb), link)
        .unwrap();
    let unsigned_hb = serialize_v2(&dflat_link::header(1, 191, 8), &hb).unwrap();
    daemon.send_to(unsigned_hb.as_bytes(), link).unwrap();
    let signed_hb = sign(&mut daemon_signing, 1, 191, 9, &hb);
    daemon.send_to(&signed_hb, link).unwrap();
    // GCS → daemon, byte for byte.
    let gcs_hb = sign(&mut gcs_signing, 255, 190, 1, &hb);
    gcs.send_to(&gcs_hb, gcs_port).unwrap();
    let collect = |s: &UdpSocket, sys: u32| {
        let mut buf = [0u8; 4096];
        let mut seen = Vec::new();
        let until = Instant::now() + Duration::from_millis(400);
        while Instant::now() < until {
            if let Ok((n, _)) = s.recv_from(&mut buf) {
                seen.extend(
                    frames(&buf[..n])
                        .flatten()
                        .filter(|f| f.header.system_id == sys),
                );
            }
        }
        seen
    };
    let at_gcs: Vec<_> = collect(&gcs, 1)
        .into_iter()
        .filter(|f| f.header.component_id == 191)
        .collect();
    let seqs: Vec<u8> = at_gcs.iter().map(|f| f.header.sequence).collect();
    assert!(!seqs.contains(&7), "badly signed frame routed: {seqs:?}");
    // With signing on, HEARTBEAT is one of the messages that must be
    // signed (it carries the mode and armed state).
    assert!(!seqs.contains(&8), "unsigned heartbeat routed: {seqs:?}");
    let routed = at_gcs.iter().find(|f| f.header.sequence == 9);
    assert_eq!(
        routed.and_then(|f| f.signed.as_ref()).map(|s| s.as_bytes()),
        Some(&signed_hb[..]),
        "signed heartbeat not routed unchanged"
    );
    let at_daemon = collect(&daemon, 255);
    assert!(
        at_daemon
            .iter()
            .any(|f| f.signed.as_ref().map(|s| s.as_bytes()) == Some(&gcs_hb[..])),
        "GCS frame not routed unchanged: {at_daemon:?}"
    );
    sitl.stop().unwrap();
}

#[test]
fn sitl_key_file_is_checked_at_start() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = std::env::temp_dir().join(format!("dflat-sitl-key-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("key");
    std::fs::write(&path, format!("{}\n", "5a".repeat(32))).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
    let mut cfg = test_config();
    cfg.sitl.signing_key_file = path.display().to_string();
    let err = spawn(&cfg, SitlOptions::default()).unwrap_err().to_string();
    assert!(err.contains("sitl.signing_key_file"), "{err}");
    assert!(
        err.contains("0644") && err.contains(&path.display().to_string()),
        "{err}"
    );
    assert!(!err.contains("link.signing_key_file"), "{err}");
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
    let sitl = spawn(&cfg, SitlOptions::default()).unwrap();
    assert!(sitl.signed);
    sitl.stop().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}
