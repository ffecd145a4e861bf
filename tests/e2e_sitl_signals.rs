//! End to end: `dflat sitl` on its own — it prints its address, streams
//! HEARTBEAT / LOCAL_POSITION_NED / ATTITUDE to whoever spoke to it, and
//! SIGUSR1 / SIGUSR2 pause / resume the pose stream (HEARTBEAT goes on).

#[path = "support/mod.rs"]
mod common;

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use common::*;
use dflat_link::MavMessage;

#[derive(Default, Debug)]
struct Seen {
    heartbeats: usize,
    positions: usize,
    attitudes: usize,
}

fn listen(socket: &UdpSocket, for_: Duration) -> Seen {
    let mut seen = Seen::default();
    let mut buf = [0u8; 4096];
    let until = Instant::now() + for_;
    while Instant::now() < until {
        if let Ok((n, _)) = socket.recv_from(&mut buf) {
            for f in dflat_link::frames(&buf[..n]).flatten() {
                assert_eq!((f.header.system_id, f.header.component_id), (1, 1));
                match f.message {
                    MavMessage::HEARTBEAT(_) => seen.heartbeats += 1,
                    MavMessage::LOCAL_POSITION_NED(_) => seen.positions += 1,
                    MavMessage::ATTITUDE(_) => seen.attitudes += 1,
                    _ => {}
                }
            }
        }
    }
    seen
}

#[test]
fn sitl_streams_telemetry_and_signals_pause_the_pose() {
    let dir = scratch("signals");
    let config = write_config(&dir, "s.toml", "[sitl]\nstart = [0.0, 0.0, -10.0]\n");
    let truth = dir.join("truth.csv");
    let mut sitl = spawn_sitl(&dir, &config, false, &truth);
    let client = UdpSocket::bind("127.0.0.1:0").unwrap();
    client
        .set_read_timeout(Some(Duration::from_millis(20)))
        .unwrap();
    let hb = dflat_link::heartbeat_onboard(dflat_link::DaemonStatus::Standby);
    send(&client, sitl.link, 1, 191, 0, &hb);

    let s = listen(&client, Duration::from_millis(1500));
    assert!(
        s.heartbeats >= 1 && s.positions >= 60 && s.attitudes >= 60,
        "{s:?}"
    );

    sitl.proc.signal("USR1");
    assert!(
        sitl.wait_for_line("sitl pose paused", Duration::from_secs(2))
            .is_some()
    );
    // Drain what was sent before the pause.
    let _ = listen(&client, Duration::from_millis(100));
    let s = listen(&client, Duration::from_millis(1200));
    assert!(
        s.positions == 0 && s.attitudes == 0,
        "pose still streaming: {s:?}"
    );
    assert!(s.heartbeats >= 1, "heartbeat stopped too: {s:?}");

    sitl.proc.signal("USR2");
    assert!(
        sitl.wait_for_line("sitl pose resumed", Duration::from_secs(2))
            .is_some()
    );
    let s = listen(&client, Duration::from_millis(500));
    assert!(s.positions >= 15, "pose did not resume: {s:?}");

    assert!(
        sitl.proc.interrupt_and_wait(Duration::from_secs(5)),
        "SITL did not exit cleanly"
    );
    let rows = dflat_sitl::read_truth_csv(&truth).unwrap();
    assert!(rows.len() > 100, "{} truth rows", rows.len());
    assert!(
        rows.iter()
            .all(|r| dist(r.position, [0.0, 0.0, -10.0]) < 1e-3),
        "the idle SITL drifted"
    );
}
