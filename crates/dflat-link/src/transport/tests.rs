use super::*;
use crate::tlog::TlogReader;
use crate::{DaemonStatus, heartbeat_onboard};
use std::time::Duration;

fn hdr(sys: u8, comp: u8, seq: u8) -> MavHeader {
    crate::header(sys, comp, seq)
}

#[test]
fn parses_connection_strings() {
    assert_eq!(
        Endpoint::parse("udpin:0.0.0.0:14540").unwrap(),
        Endpoint::UdpIn {
            host: "0.0.0.0".into(),
            port: 14540
        }
    );
    assert_eq!(
        Endpoint::parse("udpout:localhost:14550").unwrap(),
        Endpoint::UdpOut {
            host: "localhost".into(),
            port: 14550
        }
    );
    assert_eq!(
        Endpoint::parse("tcpout:[::1]:5760").unwrap(),
        Endpoint::TcpOut {
            host: "::1".into(),
            port: 5760
        }
    );
    assert_eq!(
        Endpoint::parse("serial:/dev/ttyTHS2:921600").unwrap(),
        Endpoint::Serial {
            path: "/dev/ttyTHS2".into(),
            baud: 921_600
        }
    );
    for s in [
        "udpin:0.0.0.0:14540",
        "udpout:[::1]:1",
        "serial:/dev/ttyUSB0:57600",
    ] {
        assert_eq!(Endpoint::parse(s).unwrap().to_string(), s);
    }
    for bad in [
        "",
        "udpin",
        "udpin:1.2.3.4",
        "udpin::5",
        "udpin:h:99999",
        "serial:/dev/x:0",
        "ftp:h:1",
    ] {
        let e = Endpoint::parse(bad).unwrap_err().to_string();
        assert!(e.contains("expected udpin"), "{bad}: {e}");
    }
}

async fn recv_frame(t: &Transport) -> Received {
    match tokio::time::timeout(Duration::from_secs(2), t.recv())
        .await
        .expect("timed out")
        .expect("recv")
    {
        RecvEvent::Frame(r) => *r,
        RecvEvent::Error(e) => panic!("unexpected frame error {e}"),
    }
}

#[tokio::test]
async fn udp_round_trip_and_udpin_replies_to_last_sender() {
    let server = Transport::open(&Endpoint::parse("udpin:127.0.0.1:0").unwrap())
        .await
        .unwrap();
    let port = server.local_addr().unwrap().port();
    // No peer yet: dropped.
    let hb = heartbeat_onboard(DaemonStatus::Active);
    assert_eq!(
        server.send(&hdr(1, 1, 0), &hb).await.unwrap(),
        SendOutcome::NoPeer
    );
    let client = Transport::open(&Endpoint::parse(&format!("udpout:127.0.0.1:{port}")).unwrap())
        .await
        .unwrap();
    assert!(matches!(
        client.send(&hdr(1, 191, 7), &hb).await.unwrap(),
        SendOutcome::Sent(_)
    ));
    let got = recv_frame(&server).await;
    assert_eq!(got.header, hdr(1, 191, 7));
    assert_eq!(got.message, hb);
    assert_eq!(
        server.peer().map(|a| a.port()),
        client.local_addr().map(|a| a.port())
    );
    // Reply reaches the client.
    assert!(matches!(
        server.send(&hdr(1, 1, 3), &hb).await.unwrap(),
        SendOutcome::Sent(_)
    ));
    let back = recv_frame(&client).await;
    assert_eq!(back.header, hdr(1, 1, 3));
}

#[tokio::test]
async fn garbage_and_bad_crc_are_reported() {
    let server = Transport::open(&Endpoint::parse("udpin:127.0.0.1:0").unwrap())
        .await
        .unwrap();
    let addr = server.local_addr().unwrap();
    let raw = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let hb = heartbeat_onboard(DaemonStatus::Standby);
    let good = crate::serialize_v2(&hdr(1, 1, 0), &hb).unwrap();
    let mut bad = good.as_bytes().to_vec();
    let n = bad.len();
    bad[n - 1] ^= 0xff; // corrupt the CRC
    raw.send_to(b"hello, not mavlink", addr).unwrap();
    raw.send_to(&bad, addr).unwrap();
    // Two frames in one datagram.
    let mut two = good.as_bytes().to_vec();
    two.extend_from_slice(good.as_bytes());
    raw.send_to(&two, addr).unwrap();
    let mut events = Vec::new();
    while let Ok(ev) = tokio::time::timeout(Duration::from_millis(300), server.recv()).await {
        events.push(ev.unwrap());
    }
    assert_eq!(events.len(), 4, "{events:?}");
    assert_eq!(events[0], RecvEvent::Error(FrameError::NoMarker));
    assert_eq!(events[1], RecvEvent::Error(FrameError::Crc { msg_id: 0 }));
    assert!(matches!(&events[2], RecvEvent::Frame(r) if r.message == hb));
    assert!(matches!(&events[3], RecvEvent::Frame(r) if r.message == hb));
}

#[tokio::test]
async fn tcp_stream_split_across_reads() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let client_task = tokio::spawn(async move {
        Transport::open(&Endpoint::parse(&format!("tcpout:127.0.0.1:{port}")).unwrap())
            .await
            .unwrap()
    });
    let (mut sock, _) = listener.accept().await.unwrap();
    let client = client_task.await.unwrap();
    let hb = heartbeat_onboard(DaemonStatus::Active);
    let frame = crate::serialize_v2(&hdr(1, 1, 9), &hb).unwrap();
    let bytes = frame.as_bytes();
    sock.write_all(&bytes[..5]).await.unwrap();
    sock.flush().await.unwrap();
    tokio::time::sleep(Duration::from_millis(20)).await;
    sock.write_all(&bytes[5..]).await.unwrap();
    let got = recv_frame(&client).await;
    assert_eq!(got.header.sequence, 9);
    client.send(&hdr(1, 191, 1), &hb).await.unwrap();
    let mut buf = vec![0u8; bytes.len()];
    sock.read_exact(&mut buf).await.unwrap();
    assert_eq!(crate::parse_frame(&buf).unwrap().message, hb);
    drop(sock);
    let end = tokio::time::timeout(Duration::from_secs(2), client.recv())
        .await
        .unwrap();
    assert!(matches!(end, Err(TransportError::Closed { .. })));
}

#[tokio::test]
async fn tlog_tap_records_both_directions() {
    let dir = std::env::temp_dir().join(format!("dflat-tap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("t.tlog");
    let tap = TlogTap::create(&path).unwrap();
    let server = Transport::open_with_tap(
        &Endpoint::parse("udpin:127.0.0.1:0").unwrap(),
        Some(tap.clone()),
    )
    .await
    .unwrap();
    let port = server.local_addr().unwrap().port();
    let client = Transport::open(&Endpoint::parse(&format!("udpout:127.0.0.1:{port}")).unwrap())
        .await
        .unwrap();
    let hb = heartbeat_onboard(DaemonStatus::Active);
    let before = unix_time_us();
    client.send(&hdr(1, 191, 0), &hb).await.unwrap();
    recv_frame(&server).await;
    server.send(&hdr(1, 1, 0), &hb).await.unwrap();
    let report = tap.close().await.unwrap();
    assert_eq!(report.records, 2);
    assert_eq!(report.dropped, 0);
    let file = std::fs::File::open(&path).unwrap();
    let records: Vec<_> = TlogReader::new(std::io::BufReader::new(file))
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(records.len(), 2);
    assert_eq!(records[0].parse().unwrap().header, hdr(1, 191, 0));
    assert_eq!(records[1].parse().unwrap().header, hdr(1, 1, 0));
    assert!(records[0].timestamp_us >= before && records[1].timestamp_us >= before);
    // Closed: further records are dropped, a second close says so.
    tap.record(0, good_bytes().as_slice());
    assert!(tap.close().await.is_none());
    let _ = std::fs::remove_dir_all(&dir);
}

fn good_bytes() -> Vec<u8> {
    crate::serialize_v2(&hdr(1, 1, 0), &heartbeat_onboard(DaemonStatus::Boot))
        .unwrap()
        .as_bytes()
        .to_vec()
}

#[tokio::test]
async fn udpout_hears_only_its_peer() {
    let peer = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let client = Transport::open(
        &Endpoint::parse(&format!("udpout:{}", peer.local_addr().unwrap())).unwrap(),
    )
    .await
    .unwrap();
    let local = client.local_addr().unwrap();
    // Bound to the interface that routes to the peer (loopback here).
    assert!(local.ip().is_loopback(), "{local}");
    let hb = heartbeat_onboard(DaemonStatus::Active);
    let frame = crate::serialize_v2(&hdr(1, 1, 1), &hb).unwrap();
    let intruder = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    intruder.send_to(frame.as_bytes(), local).unwrap();
    peer.send_to(frame.as_bytes(), local).unwrap();
    let got = recv_frame(&client).await;
    assert_eq!(got.from, Some(peer.local_addr().unwrap()));
    // Nothing else arrives: the intruder's datagram never reached us.
    assert!(
        tokio::time::timeout(Duration::from_millis(200), client.recv())
            .await
            .is_err()
    );
}

#[tokio::test]
async fn udpin_lock_drops_other_senders() {
    let server = Transport::open_with(
        &Endpoint::parse("udpin:127.0.0.1:0").unwrap(),
        OpenOptions {
            udpin_peer: UdpInPeer::Lock(None),
            ..OpenOptions::default()
        },
    )
    .await
    .unwrap();
    let addr = server.local_addr().unwrap();
    let hb = heartbeat_onboard(DaemonStatus::Active);
    assert!(server.awaiting_peer());
    assert_eq!(
        server.send(&hdr(1, 191, 0), &hb).await.unwrap(),
        SendOutcome::NoPeer
    );
    let autopilot = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let intruder = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let frame = crate::serialize_v2(&hdr(1, 1, 0), &hb).unwrap();
    autopilot.send_to(frame.as_bytes(), addr).unwrap();
    let first = recv_frame(&server).await;
    server.lock_peer(first.from.unwrap()).await.unwrap();
    assert!(!server.awaiting_peer());
    assert!(
        server
            .lock_peer(intruder.local_addr().unwrap())
            .await
            .is_err()
    );
    intruder.send_to(frame.as_bytes(), addr).unwrap();
    autopilot.send_to(frame.as_bytes(), addr).unwrap();
    let next = recv_frame(&server).await;
    assert_eq!(next.from, Some(autopilot.local_addr().unwrap()));
    // Replies go to the locked peer, not to the last sender.
    server.send(&hdr(1, 191, 1), &hb).await.unwrap();
    let mut buf = [0u8; 512];
    autopilot
        .set_read_timeout(Some(Duration::from_secs(2)))
        .unwrap();
    assert!(autopilot.recv(&mut buf).unwrap() > 0);
    // A configured peer: locked from the start.
    let fixed = Transport::open_with(
        &Endpoint::parse("udpin:127.0.0.1:0").unwrap(),
        OpenOptions {
            udpin_peer: UdpInPeer::Lock(Some(autopilot.local_addr().unwrap())),
            ..OpenOptions::default()
        },
    )
    .await
    .unwrap();
    assert!(!fixed.awaiting_peer());
    let faddr = fixed.local_addr().unwrap();
    intruder.send_to(frame.as_bytes(), faddr).unwrap();
    autopilot.send_to(frame.as_bytes(), faddr).unwrap();
    let got = recv_frame(&fixed).await;
    assert_eq!(got.from, Some(autopilot.local_addr().unwrap()));
}

#[tokio::test]
async fn tcp_reconnects_with_backoff() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let client_task = tokio::spawn(async move {
        Transport::open_with(
            &Endpoint::parse(&format!("tcpout:127.0.0.1:{port}")).unwrap(),
            OpenOptions {
                reconnect: true,
                ..OpenOptions::default()
            },
        )
        .await
        .unwrap()
    });
    let (first, _) = listener.accept().await.unwrap();
    let client = client_task.await.unwrap();
    drop(first); // the server goes away
    let hb = heartbeat_onboard(DaemonStatus::Active);
    let frame = crate::serialize_v2(&hdr(1, 1, 4), &hb).unwrap();
    let server = tokio::spawn(async move {
        let (mut again, _) = listener.accept().await.unwrap();
        again.write_all(frame.as_bytes()).await.unwrap();
        again
    });
    let got = recv_frame(&client).await;
    assert_eq!(got.header.sequence, 4);
    assert_eq!(client.counters().reconnects, 1);
    drop(server.await.unwrap());
}

#[tokio::test]
async fn serial_open_failure_is_an_error() {
    let e = Transport::open(&Endpoint::parse("serial:/dev/does-not-exist-dflat:57600").unwrap())
        .await
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("serial:/dev/does-not-exist-dflat:57600"),
        "{e}"
    );
}
