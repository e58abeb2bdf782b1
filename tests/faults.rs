//! The fault table (README, "Faults and refusals"), row by row, against the real `infotrack` binary: each test
//! injects one fault a careful user or a hostile network produces and checks the outcome
//! the user needs (a clear error naming the cause, the flight going on, nothing addressed
//! to another vehicle). Rows whose test lives beside the feature it checks are named in
//! ARCHITECTURE.md's fault table (SIGKILL and SIGTERM in `daemon.rs`, parameter files in
//! `params_cli.rs`, `detect` in `detect_cli.rs`, the byte-stream fuzzing in
//! `fuzz_mavlink.rs`, the link cut, 30 % loss and camera freeze in `daemon.rs`).

mod common;

use std::path::PathBuf;
use std::process::{Command, Stdio};

use std::sync::atomic::Ordering;
use std::time::Duration;

use common::relay::{frame, relay};
use common::{free_udp_port, lab_config_with, mock_process, output_text, udp_mock};
use infotrack::autopilot::modes::Flavor;
use infotrack::mock::MockConfig;
use mavlink::dialects::ardupilotmega::*;
use tokio::net::UdpSocket;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Rows "values that abort the process": each size or rate beyond its bound is refused at
/// load with the key named, and the process exits with an error code, never an abort.
#[test]
fn sizes_and_rates_beyond_their_bounds_are_refused_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    for (key, value) in [
        ("filter.particles", toml::Value::Integer(1_000_000_000)),
        ("filter.history_len", toml::Value::Integer(100_000_000)),
        (
            "guidance.candidate_grid_side",
            toml::Value::Integer(1_000_000),
        ),
        ("timing.physics_hz", toml::Value::Float(1e12)),
        ("daemon.system_id", toml::Value::Integer(0)),
    ] {
        let cfg = lab_config_with(dir.path(), key, value);
        let out = Command::new(env!("CARGO_BIN_EXE_infotrack"))
            .args(["run", "--quiet", "--duration", "1", "--config"])
            .arg(&cfg)
            .current_dir(root())
            .output()
            .unwrap();
        let all = output_text(&out);
        assert_eq!(out.status.code(), Some(1), "{key}: {all}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(key), "{key} is named: {all}");
        assert!(!stderr.contains("panicked"), "{key}: {all}");
    }
}

/// What a hostile network adds: a second autopilot (system 42) with its own pose far away,
/// and NaN positions claiming to come from the vehicle itself.
fn hostile_frames() -> Vec<Vec<u8>> {
    let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    });
    let pose = |x: f32| {
        MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            time_boot_ms: 1,
            x,
            y: 40.0,
            z: -10.0,
            vx: 0.0,
            vy: 0.0,
            vz: 0.0,
        })
    };
    vec![
        frame(42, 1, &heartbeat),
        frame(42, 1, &pose(40.0)),
        frame(1, 1, &pose(f32::NAN)),
    ]
}

/// Rows "a second MAVLink system is adopted" and "NaN in LOCAL_POSITION_NED enters the
/// vehicle state": the link stays on the first autopilot, reports the other once, never
/// addresses it, and drops the NaN poses (none reach the flight records).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_vehicle_and_nan_poses_on_the_wire_are_refused() {
    let (_mock, vehicle) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let (relay, front) = relay(vehicle, hostile_frames(), Duration::ZERO).await;
    let dir = tempfile::tempdir().unwrap();
    let out = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(["run", "--quiet", "--duration", "12", "--motion", "cv"])
        .args([
            "--allow-simulation-on-vehicle",
            "--allow-auto-engage",
            "--vehicle",
        ])
        .arg(format!("udpout:127.0.0.1:{front}"))
        .arg("--out")
        .arg(dir.path())
        .current_dir(root())
        .output()
        .await
        .unwrap();
    let all = output_text(&out);
    assert!(out.status.success(), "{all}");
    assert!(
        relay.injected.load(Ordering::Relaxed),
        "nothing was injected"
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        stderr
            .matches("ignoring the autopilot of system 42 component 1")
            .count(),
        1,
        "reported once: {all}"
    );
    assert!(
        stderr.contains("telemetry message(s) with NaN or infinite fields"),
        "NaN poses reported: {all}"
    );

    // The hostile frames reached infotrack (they are in its tlog) and not one command went
    // to system 42.
    let tlog = infotrack::autopilot::tlog::read(&dir.path().join("link.tlog")).unwrap();
    let from_42 = tlog.iter().filter(|(_, h, _)| h.system_id == 42).count();
    assert!(from_42 > 50, "{from_42} frames from system 42 in the tlog");
    let targets: Vec<u8> = tlog
        .iter()
        .filter_map(|(_, _, m)| match m {
            MavMessage::COMMAND_LONG(c) => Some(c.target_system),
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(c) => Some(c.target_system),
            MavMessage::COMMAND_INT(c) => Some(c.target_system),
            _ => None,
        })
        .collect();
    assert!(targets.len() > 100, "{} commands", targets.len());
    assert!(targets.iter().all(|&t| t == 1), "a command went elsewhere");

    // No NaN and no pose of system 42 in the records: the agent stays in the lab.
    let steps = std::fs::read_to_string(dir.path().join("steps.csv")).unwrap();
    let header: Vec<&str> = steps.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (ax, ay) = (col("agent_x_enu_m"), col("agent_y_enu_m"));
    let rows: Vec<Vec<&str>> = steps
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert!(rows.len() > 20, "{} steps", rows.len());
    for r in &rows {
        let (x, y): (f64, f64) = (r[ax].parse().unwrap(), r[ay].parse().unwrap());
        assert!(
            x.is_finite() && y.is_finite() && x.abs() < 5.0 && y.abs() < 5.0,
            "{r:?}"
        );
    }
    // flight.csv writes NaN for what is absent (no measurement), never for the pose.
    let flight = std::fs::read_to_string(dir.path().join("flight.csv")).unwrap();
    let mut lines = flight.lines().skip(1);
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let pose: Vec<usize> = ["vehicle_n_m", "vehicle_e_m", "vehicle_d_m"]
        .iter()
        .map(|n| header.iter().position(|h| h == n).unwrap())
        .collect();
    for l in lines {
        let f: Vec<&str> = l.split(',').collect();
        for &i in &pose {
            let v: f64 = f[i].parse().unwrap();
            assert!(v.is_finite() && v.abs() < 5.0, "pose {v} in {l}");
        }
    }
}

/// Row "a full disk loses the records": every file the flight writes is capped at 16 KB
/// (RLIMIT_FSIZE, which fails writes as a full disk does); the flight flies its duration,
/// the failure is in the log and told to the ground station (a STATUSTEXT on the wire), and
/// what was written before stays readable.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_is_said_to_the_log_and_the_gcs_and_the_flight_goes_on() {
    let (_mock, vehicle) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let (relay, front) = relay(vehicle, Vec::new(), Duration::ZERO).await;
    let dir = tempfile::tempdir().unwrap();
    let mut cmd = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"));
    cmd.args(["run", "--quiet", "--duration", "25", "--motion", "cv"])
        .args([
            "--allow-simulation-on-vehicle",
            "--allow-auto-engage",
            "--vehicle",
        ])
        .arg(format!("udpout:127.0.0.1:{front}"))
        .arg("--out")
        .arg(dir.path())
        .current_dir(root())
        .stdin(Stdio::null());
    // SAFETY: only async-signal-safe calls between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            let cap = libc::rlimit {
                rlim_cur: 16 * 1024,
                rlim_max: 16 * 1024,
            };
            // Writes past the cap fail with EFBIG instead of raising SIGXFSZ.
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            if libc::setrlimit(libc::RLIMIT_FSIZE, &cap) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let out = cmd.output().await.unwrap();
    let all = output_text(&out);
    // The flight flies its duration and holds; the run then fails: its records are partial.
    assert_eq!(out.status.code(), Some(1), "{all}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("stopped by Duration"), "{all}");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("records in")
            && all.contains("stopped early"),
        "{all}"
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("flight records in") && stderr.contains("disk full?"),
        "{all}"
    );
    assert!(
        stderr.contains("link.tlog"),
        "the tlog's failure is said: {all}"
    );
    let texts = relay.texts.lock().unwrap().clone();
    assert_eq!(
        texts
            .iter()
            .filter(|t| *t == "infotrack: log write failed (disk full?)")
            .count(),
        1,
        "told to the GCS once: {texts:?}"
    );

    // What was written before parses: the tlog up to its cut, flight.csv's records.
    let tlog = infotrack::autopilot::tlog::read(&dir.path().join("link.tlog")).unwrap();
    assert!(tlog.len() > 50, "{} messages", tlog.len());
    let flight = std::fs::read_to_string(dir.path().join("flight.csv")).unwrap();
    assert!(flight.ends_with('\n'), "whole rows only");
    let (_, _, steps) = infotrack::daemon::flight_log::parse(&flight, "flight.csv").unwrap();
    assert!(steps.len() > 10, "{} records kept", steps.len());
}

/// Row "a signing mismatch is reported as a silent vehicle or a missing ACK": the daemon's
/// error names the mismatch, both ways (the vehicle signs and we do not; we sign with
/// another key).
#[test]
fn a_signing_mismatch_is_named_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let write_key = |name: &str, byte: &str| {
        let k = dir.path().join(name);
        std::fs::write(&k, format!("{}\n", byte.repeat(32))).unwrap();
        k
    };
    let vehicle_key = write_key("vehicle.key", "5a");
    let other_key = write_key("other.key", "a5");
    let port = free_udp_port();
    let _mock = mock_process("px4", port, Some(&vehicle_key));
    let fly = |config: Option<PathBuf>| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_infotrack"));
        c.args([
            "run",
            "--quiet",
            "--duration",
            "5",
            "--allow-simulation-on-vehicle",
            "--allow-auto-engage",
            "--vehicle",
        ])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .current_dir(root());
        if let Some(cfg) = config {
            c.arg("--config").arg(cfg);
        }
        c.output().unwrap()
    };
    let unsigned = fly(None);
    let all = output_text(&unsigned);
    assert!(!unsigned.status.success(), "{all}");
    assert!(
        all.contains("signing mismatch: the vehicle signs its messages")
            && all.contains("no daemon.signing_key"),
        "{all}"
    );
    let cfg = lab_config_with(
        dir.path(),
        "daemon.signing_key",
        toml::Value::String(other_key.display().to_string()),
    );
    let wrong = fly(Some(cfg));
    let all = output_text(&wrong);
    assert!(!wrong.status.success(), "{all}");
    assert!(
        all.contains("no autopilot heartbeat")
            && all.contains("signed with a different key than daemon.signing_key"),
        "{all}"
    );
}

/// Row "the mock accepts ARM and SET_MESSAGE_INTERVAL with NaN": the mock process refuses
/// both, and says why in a STATUSTEXT, as the real autopilots' parameter checks do.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_mock_process_refuses_nan_commands_and_says_why() {
    for flavor in ["px4", "ardupilot"] {
        let port = free_udp_port();
        let _mock = mock_process(flavor, port, None);
        let sock = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        sock.connect(("127.0.0.1", port)).await.unwrap();
        let command = |cmd: MavCmd, p1: f32| {
            frame(
                255,
                190,
                &MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                    param1: p1,
                    param2: 1e5,
                    command: cmd,
                    target_system: 1,
                    target_component: 1,
                    ..Default::default()
                }),
            )
        };
        for (cmd, reason) in [
            (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, "neither 0 nor 1"),
            (MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, "message id"),
        ] {
            sock.send(&command(cmd, f32::NAN)).await.unwrap();
            let (mut ack, mut said) = (None, String::new());
            let until = tokio::time::Instant::now() + Duration::from_secs(3);
            let mut buf = [0u8; 2048];
            while ack.is_none() || said.is_empty() {
                let Ok(Ok(n)) = tokio::time::timeout_at(until, sock.recv(&mut buf)).await else {
                    break;
                };
                let mut r = mavlink::MavlinkReader::new(&buf[..n]);
                match r.read_message::<MavMessage>(mavlink::MavlinkVersion::V2) {
                    Ok((_, MavMessage::COMMAND_ACK(a))) if a.command == cmd => ack = Some(a.result),
                    Ok((_, MavMessage::STATUSTEXT(t))) => {
                        said += t.text.to_str().unwrap_or("");
                    }
                    _ => {}
                }
            }
            assert!(
                ack.is_some_and(|r| r != MavResult::MAV_RESULT_ACCEPTED),
                "{flavor} {cmd:?}: {ack:?}"
            );
            assert!(said.contains(reason), "{flavor} {cmd:?}: {said}");
        }
    }
}

/// Row "a failure after takeoff leaves the vehicle armed with no hold": the tracker's
/// thread dies in flight; the supervisor puts the vehicle in hold, it keeps its altitude,
/// and the run ends with an error that says so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pipeline_that_dies_in_flight_leaves_the_vehicle_in_hold() {
    for flavor in [Flavor::Px4, Flavor::ArduPilot] {
        let (mock, port) = udp_mock(MockConfig::new(flavor)).await;
        let out = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
            .args(["run", "--quiet", "--duration", "60", "--motion", "cv"])
            .args([
                "--inject",
                "pipeline-panic@3+1",
                "--allow-simulation-on-vehicle",
                "--allow-auto-engage",
                "--vehicle",
            ])
            .arg(format!("udpout:127.0.0.1:{port}"))
            .current_dir(root())
            .output()
            .await
            .unwrap();
        let all = output_text(&out);
        assert!(!out.status.success(), "{flavor:?}: {all}");
        assert!(
            all.contains("the pipeline thread died with a panic (the vehicle was put in hold)"),
            "{flavor:?}: {all}"
        );
        let hold = infotrack::autopilot::modes::Mode::hold_for(flavor);
        assert_eq!(mock.with(|m| m.mode()), hold, "{flavor:?}");
        assert!(mock.with(|m| m.armed()), "{flavor:?}: still flying");
        let alt = || mock.with(|m| -m.position_ned_m()[2]);
        let before = alt();
        tokio::time::sleep(Duration::from_secs(3)).await;
        assert!(
            before > 1.0 && (alt() - before).abs() < 0.3,
            "{flavor:?}: altitude {before} -> {}",
            alt()
        );
    }
}
