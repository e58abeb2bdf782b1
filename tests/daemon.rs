//! The daemon end to end: the closed loop (simulated target, rendered frames, AprilTag
//! detector, particle filter with the DMMN, EER) flying the mock autopilot through real
//! MAVLink, PX4 and ArduPilot flavours; faults inside the loop; SIGTERM; start-up errors.
//!
//! The closed-loop flights run the daemon on its simulated clock (`daemon::run_simulated`,
//! as `infotrack sim --closed-loop` does): the paper's 90 s in about 20 s of test time,
//! through the same code, sockets and frames as the wall-clock daemon. SIGTERM and the real
//! camera are tested on the wall clock.

use std::process::Command;
use std::time::Duration;

use infotrack::autopilot::modes::{Flavor, Mode};
use infotrack::autopilot::tlog;
use infotrack::config::Config;
use infotrack::daemon::{self, RunOptions, StopReason};
use infotrack::mock::MockConfig;
use mavlink::dialects::ardupilotmega::MavMessage;

mod common;
use common::{eventually, free_udp_port, sigterm, udp_mock};

fn opts(duration_s: f64, tlog: Option<std::path::PathBuf>) -> RunOptions {
    RunOptions {
        duration_s,
        seed: 7,
        motion: "dmmn".into(),
        tlog,
        records_dir: None,
        visual_record: None,
        status_line: false,
        faults: vec![],
        // The tests fly a separate mock process over a MAVLink URL, as a SITL would be.
        permits: daemon::VehiclePermits {
            simulation: true,
            auto_engage: true,
        },
        simulators: infotrack::wiring::simulators(),
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
    // The issue asks for the target in view at least half the time. Over seeds 1-16 the
    // closed loop gives 46-64 % (mean 58.5 %); seed 7, the config's, 60.2 %.
    assert!(
        s.fov_percent >= 50.0,
        "target in view {:.1}% of the time",
        s.fov_percent
    );
    assert!(
        s.estimation_error_m < 0.35,
        "estimation error {}",
        s.estimation_error_m
    );
    assert!(r.output.vision.detections > 10);
    assert_eq!(
        r.final_mode,
        Some(Mode::hold_for(r.flavor)),
        "clean stop holds"
    );
    assert_eq!(r.geofence_refusals, 0);
}

#[test]
fn px4_closed_loop_through_the_mock_matches_the_simulator() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("link.tlog");
    let cfg = lab();
    let wall = std::time::Instant::now();
    let r = daemon::run_simulated(&cfg, &opts(90.0, Some(log.clone()))).unwrap();
    let wall_s = wall.elapsed().as_secs_f64();
    let flown_s = r.output.records.last().unwrap().step.t_s;
    eprintln!("90 s of flight in {wall_s:.1} s of wall time");
    assert!(flown_s > 89.0, "flew {flown_s} s");
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
    assert!(setpoints as f64 >= 10.0 * 90.0, "{setpoints} setpoints");
    // Every setpoint holds the heading the tracker's footprint is drawn for: the nose north
    // (NED yaw 0), the image's width along world east. Yaw ENU 0 (the nose east) would
    // turn a real camera's view across the model's.
    let yaws_in = |yaw_of: fn(&MavMessage) -> Option<f32>| -> Vec<f32> {
        msgs.iter().filter_map(|(_, _, m)| yaw_of(m)).collect()
    };
    let yaws = yaws_in(|m| match m {
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(s) => Some(s.yaw),
        _ => None,
    });
    assert!(
        yaws.iter().all(|y| y.abs() < 1e-6),
        "setpoint yaws (NED) not all 0: {:?}",
        yaws.iter().find(|y| y.abs() >= 1e-6)
    );
    let attitude_yaws = yaws_in(|m| match m {
        MavMessage::ATTITUDE(a) => Some(a.yaw),
        _ => None,
    });
    assert!(!attitude_yaws.is_empty());
    assert!(
        attitude_yaws.last().unwrap().abs() < 1e-3,
        "{attitude_yaws:?}"
    );
    // Simulated time in the log: 90 s of time stamps, however fast it flew.
    let span_s = (msgs.last().unwrap().0 - msgs[0].0) as f64 * 1e-6;
    assert!(span_s > 90.0 && span_s < 100.0, "tlog spans {span_s} s");
    assert!(count(|m| matches!(m, MavMessage::LOCAL_POSITION_NED(_))) > 100);
    assert!(msgs
        .iter()
        .any(|(_, h, m)| h.component_id == 191 && matches!(m, MavMessage::HEARTBEAT(_))));
    // The ground station hears the tracker: its events as STATUSTEXT, its state as
    // NAMED_VALUE_FLOAT once a second.
    let ours: Vec<&MavMessage> = msgs
        .iter()
        .filter(|(_, h, _)| h.component_id == 191)
        .map(|(_, _, m)| m)
        .collect();
    let texts: Vec<String> = ours
        .iter()
        .filter_map(|m| match m {
            MavMessage::STATUSTEXT(t) => Some(t.text.to_str().unwrap_or("").to_string()),
            _ => None,
        })
        .collect();
    for want in [
        "infotrack: tracking started (dmmn)",
        "infotrack: target acquired",
        "infotrack: stopped (duration), vehicle in hold",
    ] {
        assert!(texts.iter().any(|t| t == want), "`{want}` not in {texts:?}");
    }
    let neff = ours
        .iter()
        .filter(|m| matches!(m, MavMessage::NAMED_VALUE_FLOAT(v) if v.name.to_str().unwrap_or("") == "IT_NEFF"))
        .count();
    assert!((80..=95).contains(&neff), "{neff} IT_NEFF values in 90 s");
    // The estimate on the GCS map: ADS-B traffic `TARGET` once a second whose WGS84
    // position, taken back to world ENU about the mock's origin, is where the filter's
    // estimate was (east stays east, north stays north).
    let mock_cfg = MockConfig::new(Flavor::Px4);
    let origin = infotrack::geodesy::GeodeticWgs84 {
        lat_deg: mock_cfg.origin_lat_deg,
        lon_deg: mock_cfg.origin_lon_deg,
        alt_m: mock_cfg.origin_alt_m,
    };
    let on_map: Vec<[f64; 3]> = ours
        .iter()
        .filter_map(|m| match m {
            MavMessage::ADSB_VEHICLE(a) if a.callsign.to_str().unwrap_or("") == "TARGET" => {
                Some(origin.enu_of(&infotrack::geodesy::GeodeticWgs84 {
                    lat_deg: a.lat as f64 * 1e-7,
                    lon_deg: a.lon as f64 * 1e-7,
                    alt_m: a.altitude as f64 * 1e-3,
                }))
            }
            _ => None,
        })
        .collect();
    assert!(
        (80..=95).contains(&on_map.len()),
        "{} on the map",
        on_map.len()
    );
    let mut off: Vec<f64> = on_map
        .iter()
        .map(|p| {
            r.output
                .records
                .iter()
                .map(|s| (s.step.estimate_enu.x - p[0]).hypot(s.step.estimate_enu.y - p[1]))
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    off.sort_by(f64::total_cmp);
    assert!(
        off[off.len() / 2] < 0.1,
        "median {} m off an estimate",
        off[off.len() / 2]
    );
    assert!(
        on_map.iter().all(|p| p[2].abs() < 0.5),
        "on the ground: {on_map:?}"
    );
    replays_exactly(&cfg, &r);

    // `infotrack sim --vision` (same frames, detector and filter, but an ideal agent and no
    // MAVLink) for the same seed: the closed loop must land within its spread.
    let sim = infotrack::sim::MonteCarlo {
        guidance: vec![infotrack::guidance::GuidanceKind::Eer],
        estimators: vec![infotrack::sim::EstimatorKind::parse("dmmn").unwrap()],
        runs: 3,
        seed: 7,
        duration_s: 90.0,
        keep_outputs: false,
        progress: false,
        vision: true,
        trace_first_run: false,
        shard: None,
    }
    .run(&cfg)
    .unwrap();
    let c = &sim.results[0];
    let s = &r.summary;
    // Three runs underestimate the spread; the floors are the sd of 6 sim --vision runs
    // (seed 7): 0.129 m, 0.175 m, 10.9 %.
    for (name, flown, m, floor) in [
        (
            "tracking error",
            s.tracking_error_m,
            &c.tracking_error_m,
            0.129,
        ),
        (
            "estimation error",
            s.estimation_error_m,
            &c.estimation_error_m,
            0.175,
        ),
        ("%FOV", s.fov_percent, &c.fov_percent, 10.9),
    ] {
        let band = 3.0 * m.sd.max(floor);
        eprintln!(
            "{name}: closed loop {flown:.3}, sim {:.3} +- {:.3}",
            m.mean, m.sd
        );
        assert!(
            (flown - m.mean).abs() <= band,
            "{name}: closed loop {flown} vs sim {} +- {}",
            m.mean,
            m.sd
        );
    }
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

/// Field scale, closed loop: `config/outdoor.toml` (a car at 10 m/s on 5 km of roads, the
/// drone at 45 m, a 1280 px camera, a 1.2 m roof tag) flown through the PX4 mock with the
/// constant-velocity filter. The target is the car in view >= 60 % of the time with
/// tracking error <= 20 m; seeds 1-3 over the full 300 s gave 74-85 % and 11-18 m, this
/// seed over 120 s 83 % and 11 m (82.7 % and 7.9 m since the road constraint reads the
/// tracks' headings).
#[test]
fn outdoor_closed_loop_keeps_the_car_in_view() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/outdoor.toml");
    let mut cfg = Config::load(&path).unwrap();
    cfg.motion.onnxruntime_library = lab().motion.onnxruntime_library;
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("link.tlog");
    let r = daemon::run_simulated(
        &cfg,
        &RunOptions {
            seed: 2,
            motion: "cv".into(),
            ..opts(120.0, Some(log.clone()))
        },
    )
    .unwrap();
    // With a cue the view turns its long side along the track (`guidance.view_heading`
    // absent: `along_track`): the setpoints ask for more than one heading, and the mock,
    // as PX4 does, turns to them at MPC_YAWRAUTO_MAX (45 deg/s), never faster.
    let msgs = tlog::read(&log).unwrap();
    let asked: Vec<f32> = msgs
        .iter()
        .filter_map(|(_, _, m)| match m {
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(s) => Some(s.yaw),
            _ => None,
        })
        .collect();
    assert!(
        asked.iter().any(|y| (y - asked[0]).abs() > 0.3),
        "one heading only: {}",
        asked[0]
    );
    let attitude: Vec<(u64, f32)> = msgs
        .iter()
        .filter_map(|(_, _, m)| match m {
            MavMessage::ATTITUDE(a) => Some((u64::from(a.time_boot_ms), a.yaw)),
            _ => None,
        })
        .collect();
    assert!(
        attitude
            .iter()
            .any(|(_, y)| (y - attitude[0].1).abs() > 0.3),
        "the vehicle never turned"
    );
    for w in attitude.windows(2) {
        let dt_s = (w[1].0 - w[0].0) as f64 / 1e3;
        let turn = infotrack::frames::wrap_angle(f64::from(w[1].1 - w[0].1)).abs();
        assert!(
            turn <= 45f64.to_radians() * dt_s + 1e-3,
            "turned {turn} rad in {dt_s} s"
        );
    }
    let s = &r.summary;
    let frames = r.output.vision;
    eprintln!(
        "outdoor: track {:.1} m, FOV {:.1} %, tag in {}/{} frames",
        s.tracking_error_m, s.fov_percent, frames.detections, frames.frames
    );
    assert_eq!(r.stopped_by, StopReason::Duration);
    assert!(s.fov_percent >= 60.0, "car in view {:.1} %", s.fov_percent);
    assert!(
        s.tracking_error_m <= 20.0,
        "tracking error {:.1} m",
        s.tracking_error_m
    );
    assert!(
        frames.detections * 2 >= frames.frames,
        "tag in {}/{} frames",
        frames.detections,
        frames.frames
    );
    assert_eq!(r.geofence_refusals, 0);
}

#[test]
fn ardupilot_closed_loop_through_the_mock() {
    let mut cfg = lab();
    cfg.daemon.vehicle = "mock:ardupilot".into();
    let r = daemon::run_simulated(&cfg, &opts(90.0, None)).unwrap();
    assert_eq!(r.flavor, Flavor::ArduPilot);
    check_flight(&r);
}

#[test]
fn packet_loss_link_cut_and_camera_freeze_inside_the_loop_are_survived() {
    use infotrack::daemon::pipeline::{Command as Cmd, TrackState};
    let cfg = lab();
    let mut o = opts(34.0, None);
    o.faults = ["loss=30@5+5", "link-cut@12+5", "camera-freeze@21+5"]
        .iter()
        .map(|f| f.parse().unwrap())
        .collect();
    let r = daemon::run_simulated(&cfg, &o).unwrap();
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
    assert_eq!(r.final_mode, Some(Mode::hold_for(r.flavor)));
    let mock = r.mock.as_ref().unwrap().as_any();
    let mock = mock
        .downcast_ref::<infotrack::mock::server::MockHandle>()
        .unwrap();
    assert_eq!(mock.with(|m| m.mode()), Mode::Hold);
    // The log names the faults in force, the vehicle's mode and the entropy at each step.
    assert!(during(5.5, 9.5).all(|x| x.faults == "loss=30"));
    assert!(during(22.5, 25.5).all(|x| x.faults == "camera-freeze"));
    assert!(during(28.0, 40.0).all(|x| x.faults.is_empty()));
    let offboard = records
        .iter()
        .filter(|x| x.vehicle_mode == Some(Mode::Offboard))
        .count();
    assert!(offboard > records.len() / 2, "{offboard} steps in OFFBOARD");
    assert!(records.last().unwrap().entropy.is_finite());
    let csv = infotrack::daemon::flight_log::render(records, 7, "dmmn");
    assert!(csv.contains(",Offboard,camera-freeze\n") && csv.contains(",loss=30\n"));
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
        assert!(e.to_string().contains("KIND@START+DURATION"), "{bad}: {e}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_leaves_the_vehicle_in_hold() {
    let (mock, port) = udp_mock(MockConfig::new(Flavor::ArduPilot)).await;
    let child = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args([
            "run",
            "--quiet",
            "--duration",
            "120",
            "--allow-simulation-on-vehicle",
            "--allow-auto-engage",
            "--vehicle",
        ])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until it is flying guided at the scenario's start point (world ENU (-0.5, 0.5)
    // at 1.2 m, i.e. NED (0.5, -0.5, -1.2)), where tracking begins.
    let at_start = eventually(30.0, || {
        mock.with(|m| {
            let p = m.position_ned_m();
            m.armed()
                && m.mode() == Mode::Guided
                && (p[0] - 0.5).hypot(p[1] + 0.5) < 0.1
                && (p[2] + 1.2).abs() < 0.1
        })
    })
    .await;
    assert!(at_start, "the daemon never reached the start point");
    tokio::time::sleep(Duration::from_secs(3)).await;
    let out = sigterm(child).await;
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains("stopped by Signal"), "{stdout}");
    // The altitude holds over the next 10 s: with no RC throttle ArduCopter's LOITER
    // descends to the ground (its SITL did; the mock imitates it), so the hold is BRAKE.
    let alt = || mock.with(|m| -m.position_ned_m()[2]);
    let before = alt();
    tokio::time::sleep(Duration::from_secs(10)).await;
    assert!(
        (alt() - before).abs() < 0.5 && before > 1.0,
        "altitude {before} m -> {} m after the hold",
        alt()
    );
    assert_eq!(mock.with(|m| m.mode()), Mode::Brake);
}

/// Nothing lost: a flight killed with SIGKILL (no chance to write anything at exit) leaves
/// `steps.csv`, `flight.csv` and `summary.json` that parse, with records written within
/// the last second and a second before the kill at most missing from the steps.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigkill_mid_flight_leaves_parseable_records_up_to_the_last_second() {
    let (_mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("flight");
    let mut child = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args([
            "run",
            "--quiet",
            "--duration",
            "120",
            "--motion",
            "cv",
            "--out",
        ])
        .arg(&out)
        .args([
            "--allow-simulation-on-vehicle",
            "--allow-auto-engage",
            "--vehicle",
        ])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let rows = |name: &str| {
        std::fs::read_to_string(out.join(name))
            .map(|t| t.lines().count())
            .unwrap_or(0)
    };
    // Tracking for a while: 3 filter steps a second, summary every 5 s.
    let tracking = eventually(60.0, || rows("flight.csv") > 2 + 3 * 7).await;
    assert!(tracking, "no records after 60 s");
    tokio::time::sleep(Duration::from_millis(700)).await;
    let pid = child.id().unwrap() as i32;
    // SAFETY: killing our own child process.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
    let killed_at = std::time::SystemTime::now();
    child.wait().await.unwrap();

    let text = std::fs::read_to_string(out.join("flight.csv")).unwrap();
    let (seed, motion, steps) = infotrack::daemon::flight_log::parse(&text, "flight.csv").unwrap();
    assert_eq!((seed, motion.as_str()), (7, "cv"));
    assert!(steps.len() >= 21, "{} steps", steps.len());
    let modified = std::fs::metadata(out.join("flight.csv"))
        .unwrap()
        .modified()
        .unwrap();
    let age = killed_at.duration_since(modified).unwrap_or_default();
    assert!(
        age <= Duration::from_millis(1500),
        "the newest record reached the disk {age:?} before the kill"
    );
    // steps.csv: the header and complete rows (at most the last one cut short).
    let steps_csv = std::fs::read_to_string(out.join("steps.csv")).unwrap();
    let mut lines: Vec<&str> = steps_csv.lines().collect();
    assert_eq!(lines.remove(0), infotrack::report::csv::HEADER);
    if !steps_csv.ends_with('\n') {
        lines.pop();
    }
    let fields = infotrack::report::csv::HEADER.split(',').count();
    assert!(lines.iter().all(|l| l.split(',').count() == fields));
    assert!(
        lines.len() + 3 >= steps.len(),
        "{} rows in steps.csv, {} in flight.csv",
        lines.len(),
        steps.len()
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert!(summary["tracking_error_m"].as_f64().unwrap().is_finite());
    // The snapshot of a flight that never reached its clean end says so.
    assert_eq!(summary["partial"], true, "{summary}");
    // Whole rows only: the files end at a row's end.
    assert!(text.ends_with('\n') && steps_csv.ends_with('\n'));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_during_takeoff_holds_and_says_so() {
    let (mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let child = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args([
            "run",
            "--quiet",
            "--allow-simulation-on-vehicle",
            "--allow-auto-engage",
            "--vehicle",
        ])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    assert!(
        eventually(15.0, || mock.with(|m| m.armed())).await,
        "the daemon never armed"
    );
    let out = sigterm(child).await;
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("during takeoff") && stderr.contains("hold"),
        "{stderr}"
    );
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
    let e = run(&[
        "--config",
        cfg.to_str().unwrap(),
        "--allow-simulation-on-vehicle",
        "--allow-auto-engage",
    ]);
    assert!(e.contains("no autopilot heartbeat"), "{e}");
    // A real vehicle cannot fly on the simulated clock.
    let out = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(["sim", "--closed-loop", "--config", cfg.to_str().unwrap()])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("simulated clock") && e.contains("udpout:127.0.0.1"),
        "{e}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_real_camera_source_is_projected_with_the_pose_at_capture_time() {
    use infotrack::daemon::pipeline::TrackState;
    // A camera that films a tag at (0.1, 0.15) m ENU from where the vehicle will hover:
    // (0, 0) at the agent's 1.2 m, nose north (the vehicle holds the setpoints' yaw, the
    // heading the footprint model is drawn for: NED 0).
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = lab();
    let tag = [0.1, 0.15];
    let (video, calib) = common::film_a_tag(dir.path(), &cfg, tag);
    let cam = common::filming_camera(&cfg);
    let pose = common::filming_pose(&cfg);
    cfg.daemon.camera = video.display().to_string();
    cfg.daemon.calibration = Some(calib);
    // Hover: the vehicle may not wander from where the film was taken.
    cfg.agent.start_enu_m = [0.0, 0.0];
    cfg.agent.speed_limit_mps = 0.005;
    cfg.validate().unwrap();
    let r = daemon::run(&cfg, &opts(14.0, None)).await.unwrap();
    let recs = &r.output.records;
    let measured: Vec<_> = recs.iter().filter_map(|x| x.step.measurement_enu).collect();
    eprintln!(
        "{} frames, {} detections, {} measurements",
        r.output.vision.frames,
        r.output.vision.detections,
        measured.len()
    );
    assert!(measured.len() >= 5);
    // Each measurement is the filmed tag's pixel projected with the pose recorded for its
    // frame (the pose at capture time); the vehicle drifts a little from where the film was
    // taken, and that drift must show up exactly as the projection predicts.
    let px = cam.world_enu_to_pixel(tag, 0.0, &pose).unwrap();
    for x in recs.iter().filter(|x| x.step.measurement_enu.is_some()) {
        let z = x.step.measurement_enu.unwrap();
        let want = cam.pixel_to_ground_enu(px[0], px[1], &x.pose).unwrap();
        let e = (z.x - want[0]).hypot(z.y - want[1]);
        assert!(
            e < 0.005,
            "t={}: measured {z:?}, expected {want:?}",
            x.step.t_s
        );
        let drift = x.pose.position_ned_m[0].hypot(x.pose.position_ned_m[1]);
        assert!(drift < 0.1, "the vehicle wandered {drift} m");
    }
    let last_measured = recs
        .iter()
        .rev()
        .find(|x| x.step.measurement_enu.is_some())
        .unwrap();
    let est = last_measured.step.estimate_enu;
    assert!(
        (est.x - tag[0]).hypot(est.y - tag[1]) < 0.1,
        "estimate {est:?}"
    );
    // No ground truth in the field.
    assert!(recs.iter().all(|x| x.step.target_enu.x.is_nan()));
    // The file ends: the camera is lost, the vehicle holds.
    assert_eq!(recs.last().unwrap().state, TrackState::CameraLost);
    assert_eq!(r.final_mode, Some(Mode::Hold));
}

#[test]
fn field_configs_load_and_name_their_camera_when_it_is_missing() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    for (file, url) in [
        ("config/px4.toml", "udpin:0.0.0.0:14540"),
        ("config/ardupilot.toml", "serial:/dev/ttyAMA0:921600"),
    ] {
        let cfg = Config::load(&root.join(file)).unwrap();
        assert_eq!(cfg.daemon.vehicle, url);
        // The pilot takes off and hands over in the field; the simulated lab flies itself.
        assert_eq!(cfg.daemon.engage, infotrack::config::Engage::Pilot);
        assert_eq!(cfg.daemon.camera, "v4l2:0");
        let calib = root.join(cfg.daemon.calibration.as_ref().unwrap());
        let intr = infotrack::vision::cv_io::load_calibration(&calib).unwrap();
        assert_eq!((intr.width_px, intr.height_px), (1280, 720));
    }
    let lab = Config::load(&root.join("config/default.toml")).unwrap();
    assert_eq!(lab.daemon.engage, infotrack::config::Engage::Auto);
    if std::path::Path::new("/dev/video0").exists() {
        eprintln!("a camera is attached: the missing-camera check does not apply here");
        return;
    }
    // No camera on this machine: a clear error before anything connects or flies.
    let out = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args([
            "run",
            "--config",
            "config/px4.toml",
            "--duration",
            "1",
            "--quiet",
        ])
        .current_dir(root)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("camera `v4l2:0`") && e.contains("could not open"),
        "{e}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_takeoff_is_a_clear_error_and_leaves_the_vehicle_in_hold() {
    // A vehicle whose estimator never settles refuses to arm.
    let mut mc = MockConfig::new(Flavor::Px4);
    mc.estimator_ready_after_s = 1e6;
    let (mock, port) = udp_mock(mc).await;
    let mut cfg = lab();
    cfg.daemon.vehicle = format!("udpout:127.0.0.1:{port}");
    cfg.daemon.takeoff_timeout_s = 5.0;
    let err = daemon::run(&cfg, &opts(10.0, None))
        .await
        .err()
        .expect("the takeoff cannot succeed")
        .to_string();
    // Retried until the takeoff's time was up; the vehicle's own reason is named.
    assert!(err.contains("ARM") && err.contains("refused"), "{err}");
    assert!(err.contains("no position estimate"), "{err}");
    assert!(!mock.with(|m| m.armed()));
    // It had switched to OFFBOARD for the takeoff; the daemon put it back in hold.
    assert_eq!(mock.with(|m| m.mode()), Mode::Hold);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vehicle_that_hovers_without_settling_still_begins_tracking() {
    // PX4 SIH's position loop hunts by ~8 cm around a setpoint and never settles within
    // the lab's 5 cm gate: after daemon.start_settle_s close to the start point, tracking
    // begins anyway (before, the daemon timed out at the start point).
    let mut mc = MockConfig::new(Flavor::Px4);
    mc.hover_wander_m = 0.08;
    let (_mock, port) = udp_mock(mc).await;
    let mut cfg = lab();
    cfg.daemon.vehicle = format!("udpout:127.0.0.1:{port}");
    cfg.daemon.takeoff_timeout_s = 20.0;
    cfg.daemon.start_settle_s = 2.0;
    let r = daemon::run(&cfg, &opts(4.0, None))
        .await
        .expect("tracking begins near the start point");
    assert!(
        r.output.records.len() >= 9,
        "{} filter steps",
        r.output.records.len()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn arming_waits_for_a_vehicle_that_becomes_ready() {
    // ArduCopter refuses to arm for ~40 s after boot, and resets the GUIDED set during its
    // first 2.2 s to STABILIZE (the SITL build did): the daemon retries until it may, flies
    // in GUIDED, and reports the reset apart from the failsafes.
    let mut mc = MockConfig::new(Flavor::ArduPilot);
    mc.estimator_ready_after_s = 6.0;
    mc.startup_s = 2.2;
    let (mock, port) = udp_mock(mc).await;
    let mut cfg = lab();
    cfg.daemon.vehicle = format!("udpout:127.0.0.1:{port}");
    let r = daemon::run(&cfg, &opts(2.0, None))
        .await
        .expect("arming succeeds once the vehicle is ready");
    assert!(!r.output.records.is_empty());
    assert!(mock.with(|m| m.armed()));
    assert_eq!(
        r.mode_changes_before_arming,
        vec![(Mode::Guided, Mode::Stabilized)]
    );
    assert!(
        r.unexpected_mode_changes.is_empty(),
        "{:?}",
        r.unexpected_mode_changes
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_guided_set_just_before_arducopters_start_up_completes_is_set_again() {
    // ArduCopter accepts GUIDED during its first 2.2 s and drops it back to STABILIZE when
    // its start-up completes. A companion that boots with the autopilot may set GUIDED
    // just before that, with no heartbeat between to show it: the mode the vehicle accepted
    // but never showed, on the ground, is asked for again, whenever the daemon starts.
    for late_s in [0.0, 0.6, 1.2, 1.8] {
        let mut mc = MockConfig::new(Flavor::ArduPilot);
        mc.startup_s = 2.2;
        let (mock, port) = udp_mock(mc).await;
        tokio::time::sleep(Duration::from_secs_f64(late_s)).await;
        let mut cfg = lab();
        cfg.daemon.vehicle = format!("udpout:127.0.0.1:{port}");
        let r = daemon::run(&cfg, &opts(1.0, None))
            .await
            .unwrap_or_else(|e| panic!("started {late_s} s after the vehicle: {e}"));
        assert!(!r.output.records.is_empty(), "started {late_s} s after");
        assert!(mock.with(|m| m.armed()), "started {late_s} s after");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_daemon_without_the_simulators_refuses_the_mock_and_the_synthetic_camera() {
    // The daemon reaches the mock and the simulator only through what the program hands
    // it: without them a `mock:` vehicle or the synthetic camera is an error, not a flight.
    let bare = RunOptions {
        simulators: daemon::Simulators::default(),
        ..opts(5.0, None)
    };
    let err = daemon::run(&lab(), &bare)
        .await
        .err()
        .expect("no mock")
        .to_string();
    assert!(err.contains("does not provide"), "{err}");
    // A real vehicle (a mock process over UDP) with the synthetic camera: the pipeline,
    // built first, says what is missing before anything is sent.
    let (mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let mut cfg = lab();
    cfg.daemon.vehicle = format!("udpout:127.0.0.1:{port}");
    let err = daemon::run(&cfg, &bare)
        .await
        .err()
        .expect("no synthetic camera")
        .to_string();
    assert!(
        err.contains("synthetic") && err.contains("does not provide"),
        "{err}"
    );
    assert_eq!(mock.with(|m| m.setpoints_received()), 0);
}
