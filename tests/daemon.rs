//! The daemon end to end: the closed loop (simulated target, rendered frames, AprilTag
//! detector, particle filter with the DMMN, EER) flying the mock autopilot through real
//! MAVLink, PX4 and ArduPilot flavours; faults inside the loop; SIGTERM; start-up errors.
//!
//! The daemon runs on the wall clock, so these flights take as long as they last (25 s).

use std::process::Command;
use std::time::Duration;

use infotrack::autopilot::modes::{Flavor, Mode};
use infotrack::autopilot::tlog;
use infotrack::config::Config;
use infotrack::daemon::{self, RunOptions, StopReason};
use infotrack::mock::server::{spawn, Faults};
use infotrack::mock::MockConfig;
use mavlink::dialects::ardupilotmega::MavMessage;

mod common;
use common::free_udp_port;

fn opts(duration_s: f64, tlog: Option<std::path::PathBuf>) -> RunOptions {
    RunOptions {
        duration_s,
        seed: 7,
        motion: "dmmn".into(),
        tlog,
        status_line: false,
        faults: vec![],
    }
}

fn lab() -> Config {
    let mut cfg = Config::default_lab();
    cfg.motion.onnxruntime_library = Some(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join(".deps/onnxruntime/libonnxruntime.so.1.31.1"),
    );
    cfg.motion.dmmn_model =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/dmmn.onnx");
    cfg
}

fn check_flight(r: &daemon::DaemonReport) {
    let s = &r.summary;
    eprintln!(
        "{}: track {:.3} m, est {:.3} m, FOV {:.1}%, frames {}/{}, overruns {}",
        r.flavor,
        s.tracking_error_m,
        s.estimation_error_m,
        s.fov_percent,
        r.output.vision.detections,
        r.output.vision.frames,
        r.output.guidance_overruns
    );
    assert_eq!(r.stopped_by, StopReason::Duration);
    assert!(
        r.output.records.len() >= 60,
        "{} steps",
        r.output.records.len()
    );
    assert!(s.tracking_error_m.is_finite() && s.estimation_error_m.is_finite());
    assert!(s.cov_det.is_finite() && s.cov_det > 0.0);
    // The sim gives EER/DMMN 0.29 m tracking, 0.16 m estimation, 63% FOV over 90 s runs.
    assert!(
        s.fov_percent >= 40.0,
        "target in view {:.1}% of the time",
        s.fov_percent
    );
    assert!(
        s.estimation_error_m < 0.35,
        "estimation error {}",
        s.estimation_error_m
    );
    assert!(r.output.vision.detections > 10);
    assert_eq!(r.final_mode, Some(Mode::Hold), "clean stop holds");
    assert_eq!(r.geofence_refusals, 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn px4_closed_loop_through_the_mock() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("link.tlog");
    let cfg = lab();
    let r = daemon::run(&cfg, &opts(25.0, Some(log.clone())))
        .await
        .unwrap();
    assert_eq!(r.flavor, Flavor::Px4);
    check_flight(&r);
    assert!(
        r.unexpected_mode_changes.is_empty(),
        "{:?}",
        r.unexpected_mode_changes
    );
    // The tlog has both sides: our heartbeats and setpoints, the vehicle's telemetry.
    let msgs = tlog::read(&log).unwrap();
    let count = |f: fn(&MavMessage) -> bool| msgs.iter().filter(|(_, _, m)| f(m)).count();
    let setpoints = count(|m| matches!(m, MavMessage::SET_POSITION_TARGET_LOCAL_NED(_)));
    assert!(setpoints as f64 >= 10.0 * 25.0, "{setpoints} setpoints");
    assert!(count(|m| matches!(m, MavMessage::LOCAL_POSITION_NED(_))) > 100);
    assert!(msgs
        .iter()
        .any(|(_, h, m)| h.component_id == 191 && matches!(m, MavMessage::HEARTBEAT(_))));
    replays_exactly(&cfg, &r);
}

/// The flight log replays to the same estimates, bit for bit.
fn replays_exactly(cfg: &Config, r: &daemon::DaemonReport) {
    use infotrack::daemon::{flight_log, replay};
    let text = flight_log::render(&r.output.records, 7, "dmmn");
    let (seed, motion, steps) = flight_log::parse(&text, "flight.csv").unwrap();
    assert_eq!(
        (seed, motion.as_str(), steps.len()),
        (7, "dmmn", r.output.records.len())
    );
    let rep = replay::replay(cfg, &motion, seed, &steps).unwrap();
    assert_eq!(rep.max_estimate_diff_m, 0.0);
    assert!(rep.waypoints_compared > 10);
    assert!(rep.mean_waypoint_diff_m.is_finite());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ardupilot_closed_loop_through_the_mock() {
    let mut cfg = lab();
    cfg.daemon.vehicle = "mock:ardupilot".into();
    let r = daemon::run(&cfg, &opts(25.0, None)).await.unwrap();
    assert_eq!(r.flavor, Flavor::ArduPilot);
    check_flight(&r);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn packet_loss_link_cut_and_camera_freeze_inside_the_loop_are_survived() {
    use infotrack::daemon::pipeline::{Command as Cmd, TrackState};
    let cfg = lab();
    let mut o = opts(34.0, None);
    o.faults = ["loss=30@5+5", "link-cut@12+5", "camera-freeze@21+5"]
        .iter()
        .map(|f| f.parse().unwrap())
        .collect();
    let r = daemon::run(&cfg, &o).await.unwrap();
    let records = &r.output.records;
    let during = |a: f64, b: f64| {
        records
            .iter()
            .filter(move |x| x.step.t_s >= a && x.step.t_s < b)
    };
    // The cut: the link noticed, no commands on stale state, PX4's offboard failsafe fired
    // and PX4 went back to OFFBOARD by itself when setpoints resumed.
    assert!(r.link_losses >= 1, "the cut was not noticed");
    assert!(during(12.0, 18.0).any(|x| x.state == TrackState::LinkLost));
    assert!(
        r.unexpected_mode_changes
            .iter()
            .any(|(from, _)| *from == Mode::Offboard),
        "{:?}",
        r.unexpected_mode_changes
    );
    // The frozen camera: missed frames, hold, no negative information from images never taken.
    assert!(r.output.frames_missed >= 12, "{}", r.output.frames_missed);
    let frozen: Vec<_> = during(22.5, 26.0).collect();
    assert!(frozen
        .iter()
        .all(|x| x.state == TrackState::CameraLost && x.step.measurement_enu.is_none()));
    assert!(frozen.iter().any(|x| x.command == Some(Cmd::HoldHere)));
    // Afterwards: tracking again, frames and measurements, to the end.
    let after: Vec<_> = during(28.0, 40.0).collect();
    assert!(after
        .iter()
        .all(|x| x.state != TrackState::CameraLost && x.state != TrackState::LinkLost));
    assert!(
        after.iter().any(|x| x.step.measurement_enu.is_some()),
        "tracking did not resume"
    );
    assert_eq!(r.final_mode, Some(Mode::Hold));
    assert_eq!(r.mock.as_ref().unwrap().with(|m| m.mode()), Mode::Hold);
    // Blind steps (no frame) replay too.
    assert!(r.output.records.iter().any(|x| !x.frame));
    replays_exactly(&cfg, &r);
}

#[test]
fn fault_specs_parse_with_clear_errors() {
    use infotrack::daemon::{FaultKind, ScheduledFault};
    let f: ScheduledFault = "loss=30@5+2.5".parse().unwrap();
    assert_eq!(f.kind, FaultKind::PacketLoss(30.0));
    assert_eq!((f.at_s, f.duration_s), (5.0, 2.5));
    for bad in [
        "camera-freeze",
        "link-cut@5",
        "loss=130@1+1",
        "meteor@1+1",
        "link-cut@-1+2",
    ] {
        let e = bad.parse::<ScheduledFault>().unwrap_err();
        assert!(e.contains("KIND@START+DURATION"), "{bad}: {e}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_leaves_the_vehicle_in_hold() {
    let port = free_udp_port();
    let mock = spawn(
        &format!("udpin:127.0.0.1:{port}"),
        MockConfig::new(Flavor::ArduPilot),
        Faults::default(),
    )
    .await
    .unwrap();
    let child = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(["run", "--quiet", "--duration", "120", "--vehicle"])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until it is flying guided.
    let mut flying = false;
    for _ in 0..200 {
        tokio::time::sleep(Duration::from_millis(100)).await;
        if mock.with(|m| m.armed() && m.mode() == Mode::Guided && m.position_ned_m()[2] < -1.0) {
            flying = true;
            break;
        }
    }
    assert!(flying, "the daemon never took off");
    tokio::time::sleep(Duration::from_secs(3)).await;
    let pid = child.id().unwrap() as i32;
    // SAFETY: sending a signal to our own child process.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGTERM) }, 0);
    let out = tokio::time::timeout(Duration::from_secs(20), child.wait_with_output())
        .await
        .expect("the daemon did not stop")
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains("stopped by Signal"), "{stdout}");
    assert_eq!(mock.with(|m| m.mode()), Mode::Hold);
}

#[test]
fn bad_starts_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_infotrack"))
            .arg("run")
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    // A missing model file.
    let cfg = dir.path().join("nomodel.toml");
    let text = infotrack::config::DEFAULT_TOML.replace(
        "[motion]",
        "[motion]\ndmmn_model = \"/nonexistent/dmmn.onnx\"",
    );
    std::fs::write(&cfg, &text).unwrap();
    let e = run(&["--config", cfg.to_str().unwrap(), "--duration", "5"]);
    assert!(e.contains("/nonexistent/dmmn.onnx"), "{e}");
    // A bad config key.
    let cfg = dir.path().join("bad.toml");
    std::fs::write(
        &cfg,
        format!(
            "{}\n[daemon]\nsetpoint_hz = 2.0\n",
            infotrack::config::DEFAULT_TOML
        ),
    )
    .unwrap();
    let e = run(&["--config", cfg.to_str().unwrap()]);
    assert!(e.contains("daemon.setpoint_hz"), "{e}");
    // An unreachable vehicle.
    let cfg = dir.path().join("far.toml");
    std::fs::write(
        &cfg,
        format!(
            "{}\n[daemon]\nvehicle = \"udpout:127.0.0.1:{}\"\nconnect_timeout_s = 1.0\n",
            infotrack::config::DEFAULT_TOML,
            free_udp_port()
        ),
    )
    .unwrap();
    let e = run(&["--config", cfg.to_str().unwrap()]);
    assert!(e.contains("no autopilot heartbeat"), "{e}");
}
