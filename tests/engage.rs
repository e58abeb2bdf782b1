//! `daemon.engage = "pilot"` against the mock autopilot, both flavours, through the real
//! binary: infotrack never arms; the pilot takes off with the RC and switches to OFFBOARD
//! (PX4) or GUIDED (ArduPilot); infotrack tracks only then, lets go at once when the pilot
//! switches away, takes over again at the next switch, and never changes the pilot's mode
//! when it stops. The GCS hears each hand-over (STATUSTEXT, read back from the tlog).

mod common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use common::{eventually, lab_config_with, sigterm, udp_mock};
use infotrack::autopilot::modes::{Flavor, Mode};
use infotrack::mock::server::MockHandle;
use infotrack::mock::MockConfig;
use mavlink::dialects::ardupilotmega::MavMessage;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The lab config with `daemon.engage = "pilot"`.
fn pilot_config(dir: &Path) -> PathBuf {
    lab_config_with(dir, "daemon.engage", toml::Value::String("pilot".into()))
}

/// `infotrack run` on `cfg` against the mock at `port`, until SIGTERM (`--duration 0`).
fn run_until_stopped(cfg: &Path, port: u16, out: Option<&Path>) -> tokio::process::Child {
    run_for(cfg, port, out, "0")
}

/// `infotrack run` on `cfg` against the mock at `port` with `--duration duration_s`.
fn run_for(cfg: &Path, port: u16, out: Option<&Path>, duration_s: &str) -> tokio::process::Child {
    let mut c = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"));
    c.args([
        "run",
        "--quiet",
        "--duration",
        duration_s,
        "--motion",
        "cv",
        "--config",
    ])
    .arg(cfg)
    .args([
        "--allow-simulation-on-vehicle",
        "--allow-auto-engage",
        "--vehicle",
    ])
    .arg(format!("udpout:127.0.0.1:{port}"))
    .current_dir(root())
    .stdout(std::process::Stdio::piped())
    .stderr(std::process::Stdio::piped());
    if let Some(dir) = out {
        c.arg("--out").arg(dir);
    }
    c.spawn().unwrap()
}

/// The pilot flips the switch to `mode`, retrying for up to 5 s (PX4 refuses OFFBOARD
/// until infotrack's stream is fresh).
async fn switch(mock: &MockHandle, mode: Mode) {
    let mut last = Err(infotrack::mock::autopilot::PilotRefused(String::new()));
    for _ in 0..100 {
        last = mock.with(|m| m.pilot_switch(mode));
        if last.is_ok() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("the switch to {mode:?} was refused: {last:?}");
}

/// The values of `column` in a CSV record file (a `#` preamble line is skipped).
fn csv_column(path: &Path, column: &str) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let at = lines
        .next()
        .unwrap()
        .split(',')
        .position(|c| c == column)
        .unwrap();
    lines
        .map(|l| l.split(',').nth(at).unwrap().to_string())
        .collect()
}

fn horizontal(mock: &MockHandle) -> [f64; 2] {
    mock.with(|m| {
        let p = m.position_ned_m();
        [p[0], p[1]]
    })
}

fn statustexts(tlog: &Path) -> Vec<String> {
    infotrack::autopilot::tlog::read(tlog)
        .unwrap()
        .into_iter()
        .filter_map(|(_, _, m)| match m {
            MavMessage::STATUSTEXT(t) => Some(t.text.to_str().unwrap_or("").to_string()),
            _ => None,
        })
        .collect()
}

async fn pilot_hands_over_and_takes_back(flavor: Flavor) {
    let companion = Mode::companion_for(flavor);
    let (mock, port) = udp_mock(MockConfig::new(flavor)).await;
    let dir = tempfile::tempdir().unwrap();
    let flight = dir.path().join("flight");
    let child = run_until_stopped(&pilot_config(dir.path()), port, Some(&flight));

    // On the ground: infotrack never arms, never changes the mode, sends no setpoint.
    let initial = mock.with(|m| m.mode());
    tokio::time::sleep(Duration::from_secs(3)).await;
    let before = mock.with(|m| (m.armed(), m.mode(), m.setpoints_received()));
    assert_eq!(before, (false, initial, 0), "{flavor:?}");

    // The pilot takes off in the position mode.
    mock.with(|m| m.pilot_take_off(1.2));
    let airborne = eventually(15.0, || mock.with(|m| -m.position_ned_m()[2] > 1.0)).await;
    assert!(airborne, "{flavor:?}: the pilot's takeoff");
    tokio::time::sleep(Duration::from_secs(2)).await;
    // Airborne, not engaged: PX4 gets the vehicle's own position streamed (so OFFBOARD can
    // be entered), ArduPilot nothing; the pilot's mode stays.
    let streamed = mock.with(|m| m.setpoints_received());
    match flavor {
        Flavor::Px4 => assert!(streamed > 10, "PX4 stream before OFFBOARD: {streamed}"),
        Flavor::ArduPilot => assert_eq!(streamed, 0, "ArduPilot: nothing before GUIDED"),
    }
    assert_eq!(mock.with(|m| m.mode()), Mode::Position, "{flavor:?}");
    let hover = horizontal(&mock);

    // The switch: infotrack tracks (the vehicle moves toward the EER's waypoints).
    switch(&mock, companion).await;
    let moved = eventually(15.0, || {
        let p = horizontal(&mock);
        (p[0] - hover[0]).hypot(p[1] - hover[1]) > 0.2
    })
    .await;
    assert!(moved, "{flavor:?}: no tracking after the switch");

    // The pilot takes it back: infotrack stops commanding as soon as the vehicle's
    // heartbeat (1 Hz, as both firmwares send it) says so, and does not take it back.
    switch(&mock, Mode::Position).await;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let released_at = horizontal(&mock);
    let count = mock.with(|m| m.setpoints_received());
    tokio::time::sleep(Duration::from_secs(3)).await;
    let p = horizontal(&mock);
    assert!(
        (p[0] - released_at[0]).hypot(p[1] - released_at[1]) < 0.1,
        "{flavor:?}: the vehicle moved after the release"
    );
    assert_eq!(mock.with(|m| m.mode()), Mode::Position, "{flavor:?}");
    if flavor == Flavor::ArduPilot {
        assert_eq!(
            mock.with(|m| m.setpoints_received()),
            count,
            "ArduPilot: nothing sent after the release"
        );
    }

    // Again: engaged at the next switch; then the pilot switches away and infotrack stops
    // (SIGTERM) without touching the pilot's mode.
    switch(&mock, companion).await;
    tokio::time::sleep(Duration::from_secs(3)).await;
    switch(&mock, Mode::Position).await;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let out = sigterm(child).await;
    let all = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{flavor:?}: {all}");
    assert_eq!(mock.with(|m| m.mode()), Mode::Position, "{flavor:?}: {all}");

    let texts = statustexts(&dir.path().join("flight/link.tlog"));
    let count = |s: &str| texts.iter().filter(|t| t.contains(s)).count();
    assert_eq!(count("engaged by the pilot"), 2, "{texts:?}");
    assert_eq!(count("released"), 2, "{texts:?}");
    assert_eq!(count("stopped (signal); pilot has it"), 1, "{texts:?}");
    // The terminal tells the GCS's story, in the same order, and calls the pilot's
    // hand-over what it is.
    let stderr = String::from_utf8_lossy(&out.stderr);
    let mut rest: &str = &stderr;
    for t in &texts {
        let at = rest.find(t.as_str()).unwrap_or_else(|| {
            panic!("`{t}` is not on the terminal after the texts before it:\n{stderr}")
        });
        rest = &rest[at + t.len()..];
    }
    assert!(!stderr.contains("failsafe?"), "{stderr}");
    assert!(
        stderr.contains("waiting for the vehicle at") && stderr.contains("vehicle ready"),
        "{stderr}"
    );
    assert!(stderr.contains("the hand-over to infotrack"), "{stderr}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn px4_pilot_hands_over_in_offboard_and_takes_back() {
    pilot_hands_over_and_takes_back(Flavor::Px4).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ardupilot_pilot_hands_over_in_guided_and_takes_back() {
    pilot_hands_over_and_takes_back(Flavor::ArduPilot).await;
}

/// While infotrack has the vehicle, its clean stop holds it (as with `auto`); a pilot
/// config with the in-process mock (no pilot) is refused before anything starts.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn engaged_at_the_stop_it_holds_and_the_in_process_mock_is_refused() {
    let (mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let dir = tempfile::tempdir().unwrap();
    let cfg = pilot_config(dir.path());
    let child = run_until_stopped(&cfg, port, None);
    tokio::time::sleep(Duration::from_secs(2)).await;
    mock.with(|m| m.pilot_take_off(1.2));
    assert!(eventually(15.0, || mock.with(|m| -m.position_ned_m()[2] > 1.0)).await);
    switch(&mock, Mode::Offboard).await;
    tokio::time::sleep(Duration::from_secs(3)).await;
    let out = sigterm(child).await;
    assert!(out.status.success());
    assert_eq!(mock.with(|m| m.mode()), Mode::Hold);

    let refused = std::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(["run", "--quiet", "--duration", "1", "--config"])
        .arg(&cfg)
        .current_dir(root())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        err.contains("daemon.engage = \"pilot\" needs a vehicle with a pilot"),
        "{err}"
    );
}

/// `--duration` is the time infotrack has the vehicle for: a flight the pilot has not handed
/// over does not end by it, one handed over ends that long after the switch, and the
/// metrics are those of the engaged steps only.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_duration_and_the_metrics_count_from_the_pilots_hand_over() {
    let (mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let dir = tempfile::tempdir().unwrap();
    let flight = dir.path().join("flight");
    let mut child = run_for(&pilot_config(dir.path()), port, Some(&flight), "4");
    mock.with(|m| m.pilot_take_off(1.2));
    assert!(eventually(15.0, || mock.with(|m| -m.position_ned_m()[2] > 1.0)).await);
    tokio::time::sleep(Duration::from_secs(6)).await;
    assert!(
        child.try_wait().unwrap().is_none(),
        "ended before the hand-over"
    );
    switch(&mock, Mode::Offboard).await;
    let switched = std::time::Instant::now();
    let out = tokio::time::timeout(Duration::from_secs(20), child.wait_with_output())
        .await
        .expect("no end 20 s after the hand-over")
        .unwrap();
    let engaged_s = switched.elapsed().as_secs_f64();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        (3.5..10.0).contains(&engaged_s),
        "ended {engaged_s:.1} s after the switch"
    );

    // The summary's tracking error is the mean over the steps from the hand-over on.
    let modes = csv_column(&flight.join("flight.csv"), "vehicle_mode");
    let errors: Vec<f64> = csv_column(&flight.join("steps.csv"), "tracking_error_m")
        .iter()
        .map(|e| e.parse().unwrap())
        .collect();
    assert_eq!(modes.len(), errors.len());
    let first_engaged = modes
        .iter()
        .position(|m| m == "Offboard")
        .expect("no engaged step");
    assert!(first_engaged > 6, "{first_engaged} standby steps");
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(flight.join("summary.json")).unwrap())
            .unwrap();
    let reported = summary["tracking_error_m"].as_f64().unwrap();
    // The supervisor's moment of hand-over falls within a step of the first engaged record.
    let near = (first_engaged.saturating_sub(2)..=first_engaged + 2)
        .any(|k| (mean(&errors[k..]) - reported).abs() < 1e-4);
    assert!(
        near,
        "summary {reported} is not the mean from the hand-over on"
    );
    assert!(
        (mean(&errors) - reported).abs() > 1e-3,
        "the standby steps were counted"
    );
}
