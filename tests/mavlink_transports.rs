//! The vehicle link against the mock autopilot over the other transports and under faults:
//! serial through a pseudo-terminal null modem (with junk on the line), TCP, malformed
//! frames on UDP, MAVLink 2 signing, latency/duplication/reordering, a cut link and a
//! reboot.

use std::time::Duration;

use infotrack::autopilot::link::{LinkConfig, LinkEvent, VehicleLink};
use infotrack::autopilot::modes::{Flavor, Mode};
use infotrack::autopilot::params_file::ParamType;
use infotrack::autopilot::signing::SigningKey;
use infotrack::mock::null_modem::NullModem;
use infotrack::mock::server::{spawn, spawn_with, Faults, MockHandle, ServerOptions};
use infotrack::mock::{MockConfig, MockEvent};
use mavlink::dialects::ardupilotmega::*;
use mavlink::{MavHeader, MavlinkVersion};
use rand::{Rng, SeedableRng};

mod common;
use common::{expect_failsafe, fly_to, free_udp_port, udp_mock};

fn link_cfg(url: &str, sysid: u8) -> LinkConfig {
    let mut cfg = LinkConfig::new(url);
    cfg.system_id = sysid;
    cfg.ack_timeout = Duration::from_millis(300);
    cfg.attempts = 10;
    cfg
}

async fn connect(cfg: LinkConfig, flavor: Flavor) -> VehicleLink {
    let link = VehicleLink::connect(cfg).await.unwrap();
    assert_eq!(
        link.wait_vehicle(Duration::from_secs(5)).await.unwrap(),
        flavor
    );
    link
}

/// What ArduPilot prints on its first serial port while booting.
fn boot_text() -> Vec<u8> {
    b"\r\nArduCopter V4.5.7 (abc123)\r\nInit ArduCopter\r\nGPS: u-blox 1\r\n".to_vec()
}

/// What a receiver must survive: boot text, a frame with a broken checksum, a truncated
/// frame, a start byte with an absurd length, and random bytes with start markers in them.
/// A start byte with a large length
/// holds the parser until that many bytes have come, so this goes on a busy line only.
fn junk(seed: u64) -> Vec<u8> {
    let mut out = boot_text();
    let header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 9,
    };
    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        mavlink_version: 3,
        ..Default::default()
    });
    let mut frame = Vec::new();
    mavlink::write_versioned_msg(&mut frame, MavlinkVersion::V2, header, &hb).unwrap();
    let mut bad_crc = frame.clone();
    *bad_crc.last_mut().unwrap() ^= 0x5a;
    out.extend_from_slice(&bad_crc);
    out.extend_from_slice(&frame[..frame.len() / 2]);
    out.extend_from_slice(&[0xfd, 0xff, 0, 0, 0, 1, 1, 0, 0, 0]);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..600 {
        let b: u8 = rng.gen();
        out.push(if b < 12 {
            0xfd
        } else if b < 20 {
            0xfe
        } else {
            b
        });
    }
    out
}

async fn serial_flight(flavor: Flavor) {
    let nm = NullModem::new().unwrap();
    // The vehicle prints its boot text on the line before anyone listens, as ArduPilot does.
    nm.inject_to_companion(&boot_text());
    let mock = spawn(
        &format!("serial:{}:57600", nm.vehicle_path()),
        MockConfig::new(flavor),
        Faults::default(),
    )
    .await
    .unwrap();
    // As the GCS for ArduPilot, so that its GCS failsafe counts our heartbeats.
    let sysid = if flavor == Flavor::ArduPilot { 255 } else { 1 };
    let link = connect(
        link_cfg(&format!("serial:{}:921600", nm.companion_path()), sysid),
        flavor,
    )
    .await;
    link.request_telemetry().await.unwrap();
    if flavor == Flavor::ArduPilot {
        link.param_set("FS_GCS_ENABLE", 1.0, ParamType::Int8)
            .await
            .unwrap();
    } else {
        link.param_set("COM_OBL_RC_ACT", 3.0, ParamType::Int32)
            .await
            .unwrap();
    }
    link.take_off(5.0, Duration::from_secs(15)).await.unwrap();
    for (i, (x, y)) in [(8.0, 0.0), (8.0, 8.0), (-4.0, 4.0)]
        .into_iter()
        .enumerate()
    {
        // Junk both ways while flying.
        nm.inject_to_companion(&junk(10 + i as u64));
        nm.inject_to_vehicle(&junk(20 + i as u64));
        fly_to(&link, x, y, 5.0).await;
    }
    let mut rx = link.events();
    link.pause_setpoints(true);
    if flavor == Flavor::ArduPilot {
        link.pause_heartbeat(true);
    }
    expect_failsafe(&link, &mut rx, Mode::ReturnToLaunch).await;
    assert!(mock
        .take_events()
        .iter()
        .any(|e| matches!(e, MockEvent::Failsafe { .. })));
    link.pause_heartbeat(false);
    link.hold().await.unwrap();
    assert_eq!(mock.with(|m| m.mode()), Mode::hold_for(flavor));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn px4_over_a_pseudo_terminal_with_junk_on_the_line() {
    serial_flight(Flavor::Px4).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ardupilot_over_a_pseudo_terminal_with_junk_on_the_line() {
    serial_flight(Flavor::ArduPilot).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn px4_over_tcp() {
    let port = free_udp_port();
    // A tcpin mock is ready only once its companion has connected: start it aside.
    let mock = tokio::spawn(async move {
        spawn(
            &format!("tcpin:127.0.0.1:{port}"),
            MockConfig::new(Flavor::Px4),
            Faults::default(),
        )
        .await
    });
    let mut link = None;
    for _ in 0..50 {
        match VehicleLink::connect(link_cfg(&format!("tcpout:127.0.0.1:{port}"), 1)).await {
            Ok(l) => {
                link = Some(l);
                break;
            }
            // Not listening yet.
            Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
    let link = link.expect("the tcpin mock never listened");
    let mock = mock.await.unwrap().unwrap();
    assert_eq!(
        link.wait_vehicle(Duration::from_secs(5)).await.unwrap(),
        Flavor::Px4
    );
    link.request_telemetry().await.unwrap();
    link.take_off(3.0, Duration::from_secs(15)).await.unwrap();
    fly_to(&link, -3.0, 6.0, 3.0).await;
    let p = mock.with(|m| m.position_ned_m());
    // ENU (-3 east, 6 north) is NED (6 north, -3 east).
    assert!(
        (p[0] - 6.0).abs() < 0.5 && (p[1] + 3.0).abs() < 0.5,
        "{p:?}"
    );

    // The vehicle end closes the stream (a companion-port restart): the link reports the
    // vehicle lost, dials again until a vehicle listens there, and gets it back.
    let mut events = link.events();
    mock.stop();
    let again = tokio::spawn(async move {
        // Longer than the link's 3 s heartbeat timeout.
        tokio::time::sleep(Duration::from_secs(4)).await;
        spawn(
            &format!("tcpin:127.0.0.1:{port}"),
            MockConfig::new(Flavor::Px4),
            Faults::default(),
        )
        .await
    });
    let mut seen = Vec::new();
    let until = tokio::time::Instant::now() + Duration::from_secs(20);
    while !seen.contains(&"back") && tokio::time::Instant::now() < until {
        match tokio::time::timeout(Duration::from_millis(500), events.recv()).await {
            Ok(Ok(LinkEvent::VehicleLost)) => seen.push("lost"),
            Ok(Ok(LinkEvent::VehicleBack)) => seen.push("back"),
            _ => {}
        }
    }
    assert_eq!(seen, ["lost", "back"]);
    let fresh = again.await.unwrap().unwrap();
    // Both directions work on the new stream: a command is acknowledged.
    link.request_telemetry().await.unwrap();
    assert!(!fresh.with(|m| m.armed()));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn malformed_udp_datagrams_wedge_neither_side() {
    let (mock, port) = udp_mock(MockConfig::new(Flavor::ArduPilot)).await;
    let link = connect(
        link_cfg(&format!("udpout:127.0.0.1:{port}"), 1),
        Flavor::ArduPilot,
    )
    .await;
    let junk_socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    for seed in 0..20 {
        let j = junk(seed);
        for chunk in j.chunks(97) {
            junk_socket.send_to(chunk, ("127.0.0.1", port)).unwrap();
        }
        junk_socket.send_to(&[], ("127.0.0.1", port)).unwrap();
    }
    // The mock answers the last sender on udpin (the transport's rule); our heartbeats and
    // retries win it back. Everything must still work.
    link.request_telemetry().await.unwrap();
    link.set_mode(Mode::Guided).await.unwrap();
    link.arm().await.unwrap();
    assert!(mock.with(|m| m.armed()));
    assert_eq!(
        link.param_read("WPNAV_SPEED").await.unwrap(),
        (1000.0, ParamType::Real32)
    );
}

fn key(byte: u8) -> SigningKey {
    SigningKey([byte; 32])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn signing_unsigned_and_wrongly_signed_commands_are_refused() {
    let port = free_udp_port();
    let mock = spawn_with(
        &format!("udpin:127.0.0.1:{port}"),
        MockConfig::new(Flavor::ArduPilot),
        ServerOptions {
            faults: Faults::default(),
            signing_key: Some(key(7)),
        },
    )
    .await
    .unwrap();
    let url = format!("udpout:127.0.0.1:{port}");

    // Unsigned: the link hears the vehicle (an unsigned receiver takes signed frames), but
    // its commands are dropped.
    {
        let mut cfg = link_cfg(&url, 1);
        cfg.attempts = 3;
        let link = connect(cfg, Flavor::ArduPilot).await;
        let err = link.set_mode(Mode::Guided).await.unwrap_err().to_string();
        assert!(err.contains("no COMMAND_ACK"), "{err}");
        assert!(
            err.contains("signing mismatch: the vehicle signs its messages")
                && err.contains("no daemon.signing_key"),
            "the error names the cause: {err}"
        );
        assert!(
            mock.rejected_unsigned() >= 3,
            "{}",
            mock.rejected_unsigned()
        );
        assert_eq!(mock.with(|m| m.mode()), Mode::Stabilized);
    }
    // Signed with another key: the vehicle's frames fail our check, ours fail its.
    {
        let mut cfg = link_cfg(&url, 1);
        cfg.signing_key = Some(key(8));
        let link = VehicleLink::connect(cfg).await.unwrap();
        // Long enough for the vehicle's 1 Hz heartbeat to reach this new link twice.
        let err = link
            .wait_vehicle(Duration::from_millis(2500))
            .await
            .unwrap_err()
            .to_string();
        assert!(err.contains("no autopilot heartbeat"), "{err}");
        assert!(
            err.contains("signed with a different key than daemon.signing_key"),
            "the error names the cause: {err}"
        );
        assert_eq!(mock.with(|m| m.mode()), Mode::Stabilized);
    }
    // The right key: commands go through.
    let mut cfg = link_cfg(&url, 1);
    cfg.signing_key = Some(key(7));
    cfg.signing_link_id = 2;
    let link = connect(cfg, Flavor::ArduPilot).await;
    link.set_mode(Mode::Guided).await.unwrap();
    link.arm().await.unwrap();
    assert!(mock.with(|m| m.armed()));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_signing_link_names_a_vehicle_that_does_not_sign() {
    let port = free_udp_port();
    let _mock = spawn(
        &format!("udpin:127.0.0.1:{port}"),
        MockConfig::new(Flavor::Px4),
        Faults::default(),
    )
    .await
    .unwrap();
    let mut cfg = link_cfg(&format!("udpout:127.0.0.1:{port}"), 1);
    cfg.signing_key = Some(key(7));
    let link = VehicleLink::connect(cfg).await.unwrap();
    let err = link
        .wait_vehicle(Duration::from_millis(1500))
        .await
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("no autopilot heartbeat")
            && err.contains("unsigned frame(s) were refused because daemon.signing_key is set"),
        "{err}"
    );
}

async fn mock_with(flavor: Flavor, faults: Faults) -> (MockHandle, VehicleLink) {
    let port = free_udp_port();
    let mock = spawn(
        &format!("udpin:127.0.0.1:{port}"),
        MockConfig::new(flavor),
        faults,
    )
    .await
    .unwrap();
    let mut cfg = link_cfg(&format!("udpout:127.0.0.1:{port}"), 1);
    cfg.heartbeat_timeout = Duration::from_millis(1500);
    let link = connect(cfg, flavor).await;
    (mock, link)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn latency_duplication_and_reordering_still_complete_the_sequence() {
    for flavor in [Flavor::Px4, Flavor::ArduPilot] {
        let (_mock, link) = mock_with(
            flavor,
            Faults {
                loss_percent: 5.0,
                delay: Duration::from_millis(60),
                duplicate_percent: 20.0,
                reorder_percent: 20.0,
                seed: 3,
            },
        )
        .await;
        link.request_telemetry().await.unwrap();
        let name = match flavor {
            Flavor::Px4 => "MPC_XY_CRUISE",
            Flavor::ArduPilot => "WPNAV_ACCEL",
        };
        link.param_set(name, 321.0, ParamType::Real32)
            .await
            .unwrap();
        link.take_off(4.0, Duration::from_secs(20)).await.unwrap();
        fly_to(&link, 5.0, 5.0, 4.0).await;
        link.hold().await.unwrap();
        // Reordered telemetry is not mistaken for a reboot.
        assert_eq!(link.state().reboots, 0, "{flavor}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cut_link_and_a_reboot_are_detected_and_reported() {
    let (mock, link) = mock_with(Flavor::Px4, Faults::default()).await;
    link.request_telemetry().await.unwrap();
    link.param_set("COM_OBL_RC_ACT", 5.0, ParamType::Int32)
        .await
        .unwrap();
    link.take_off(4.0, Duration::from_secs(15)).await.unwrap();
    let mut rx = link.events();

    // Cut for 3 s: the link reports the vehicle lost, the vehicle's offboard failsafe fires
    // (no setpoints reach it), and both come back when the cable does.
    mock.cut_link(Duration::from_secs(3));
    let mut seen = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    while !seen.contains(&"back") {
        match tokio::time::timeout_at(deadline, rx.recv()).await {
            Ok(Ok(LinkEvent::VehicleLost)) => seen.push("lost"),
            Ok(Ok(LinkEvent::VehicleBack)) => seen.push("back"),
            Ok(Ok(_)) | Ok(Err(_)) => {}
            Err(_) => panic!("events so far: {seen:?}"),
        }
    }
    assert_eq!(seen, vec!["lost", "back"]);
    assert!(mock.take_events().iter().any(|e| matches!(
        e,
        MockEvent::Failsafe {
            mode: Mode::Hold,
            ..
        }
    )));
    // Setpoints reach it again: PX4 goes back to OFFBOARD by itself.
    link.wait_for(
        |s| s.mode == Some(Mode::Offboard),
        "offboard after the cut",
        Duration::from_secs(5),
    )
    .await
    .unwrap();

    // A reboot: silent for 1 s, then a fresh, disarmed vehicle whose boot clock restarted.
    mock.reboot(Duration::from_secs(1));
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    loop {
        match tokio::time::timeout_at(deadline, rx.recv()).await {
            Ok(Ok(LinkEvent::VehicleRebooted)) => break,
            Ok(Ok(_)) | Ok(Err(_)) => {}
            Err(_) => panic!("no reboot reported"),
        }
    }
    link.wait_for(
        |s| !s.armed,
        "disarmed after reboot",
        Duration::from_secs(3),
    )
    .await
    .unwrap();
    assert_eq!(link.state().reboots, 1);
    // Parameters survive the reboot.
    assert_eq!(
        link.param_read("COM_OBL_RC_ACT").await.unwrap(),
        (5.0, ParamType::Int32)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_telemetry_log_reads_back_as_a_connection() {
    // The link records every message it sends and receives in its tlog; opened as a
    // `file:` connection (as rust-mavlink opens one), the same messages come back in order.
    let (_mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("link.tlog");
    let mut cfg = link_cfg(&format!("udpout:127.0.0.1:{port}"), 1);
    cfg.tlog = Some(path.clone());
    let link = connect(cfg, Flavor::Px4).await;
    link.request_telemetry().await.unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    link.flush_tlog();
    drop(link);
    // Read both ways from one copy: the link's tasks may still be winding down.
    let copy = dir.path().join("copy.tlog");
    std::fs::copy(&path, &copy).unwrap();
    let path = copy;
    let recorded = infotrack::autopilot::tlog::read(&path).unwrap();
    assert!(recorded.len() > 20, "{} messages", recorded.len());
    let file = format!("file:{}", path.display());
    infotrack::autopilot::link::check_url(&file).unwrap();
    let conn = infotrack::autopilot::connection::Connection::open(&file, None)
        .await
        .unwrap();
    let mut read_back = Vec::new();
    while let Ok(Ok((header, msg))) =
        tokio::time::timeout(Duration::from_secs(2), conn.recv()).await
    {
        read_back.push((header, msg));
    }
    let recorded: Vec<_> = recorded.into_iter().map(|(_, h, m)| (h, m)).collect();
    assert!(
        read_back[..] == recorded[..read_back.len().min(recorded.len())],
        "the messages differ"
    );
    // rust-mavlink's `file:` reader scans the bytes for frames, timestamps included, and
    // waits for a whole candidate frame before it checks its CRC: a timestamp byte that
    // looks like a frame's start within the file's last frame's length of its end hides
    // the frames after it (the end of the file comes first). Anything missing must be
    // that tail; our own reader (`tlog::read`) reads every record.
    if read_back.len() < recorded.len() {
        let bytes = std::fs::read(&path).unwrap();
        let hidden_from = record_offsets(&bytes)[read_back.len()];
        assert!(
            bytes.len() - hidden_from <= 8 + 280,
            "{} of {} messages read back, the missing ones from byte {hidden_from} of {}",
            read_back.len(),
            recorded.len(),
            bytes.len()
        );
    }
}

/// Where each record of a tlog starts: an 8-byte timestamp, then a MAVLink 2 frame (10
/// header bytes, the payload, 2 CRC bytes, 13 signature bytes when signed).
fn record_offsets(bytes: &[u8]) -> Vec<usize> {
    let mut at = 0;
    let mut starts = Vec::new();
    while at + 8 + 10 <= bytes.len() {
        starts.push(at);
        let f = at + 8;
        at = f + 10 + bytes[f + 1] as usize + 2 + if bytes[f + 2] & 1 != 0 { 13 } else { 0 };
    }
    starts
}
