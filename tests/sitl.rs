//! Flights against the real autopilots: PX4 (SIH) and ArduCopter built as SITL programs with
//! their own physics (`../shared/sitl`). Each test starts one SITL in a temporary folder,
//! flies `infotrack run` on the lab world as a user would, and checks what the firmware did.
//!
//! These tests need the SITL builds: they are `#[ignore]`d in the plain test run and run by
//! `scripts/sitl-test.sh` (called from `scripts/test.sh` when `../shared/sitl` exists; it
//! says so plainly when it does not), which prepares a runnable copy of the builds and
//! points `INFOTRACK_SITL` at it.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use infotrack::autopilot::link::{LinkConfig, VehicleLink};
use infotrack::autopilot::modes::Mode;
use infotrack::autopilot::tlog;
use mavlink::dialects::ardupilotmega::MavMessage;

/// A SITL process, stopped (SIGTERM, then kill) when dropped.
struct Sitl {
    child: Child,
    _dir: tempfile::TempDir,
}

impl Drop for Sitl {
    fn drop(&mut self) {
        unsafe {
            libc::kill(self.child.id() as i32, libc::SIGTERM);
        }
        let until = Instant::now() + Duration::from_secs(5);
        while Instant::now() < until {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn sitl_root() -> PathBuf {
    PathBuf::from(std::env::var("INFOTRACK_SITL").expect(
        "INFOTRACK_SITL is not set: run the SITL suite with scripts/sitl-test.sh, which prepares the builds",
    ))
}

fn start(script: &str, args: &[&str]) -> Sitl {
    let dir = tempfile::tempdir().unwrap();
    let log = std::fs::File::create(dir.path().join("console.log")).unwrap();
    let child = Command::new(sitl_root().join(script))
        .arg(dir.path().join("work"))
        .args(args)
        .stdout(Stdio::from(log.try_clone().unwrap()))
        .stderr(Stdio::from(log))
        .spawn()
        .unwrap();
    Sitl { child, _dir: dir }
}

/// The lab world with the timeouts a real boot needs (ArduCopter refuses to arm for ~45 s).
fn lab_config(dir: &Path) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut text = std::fs::read_to_string(root.join("config/default.toml")).unwrap();
    text.push_str("\n[daemon]\ntakeoff_timeout_s = 120.0\nconnect_timeout_s = 60.0\n");
    let p = dir.join("lab-sitl.toml");
    std::fs::write(&p, text).unwrap();
    p
}

/// What one flight produced.
struct Flight {
    stdout: String,
    summary: serde_json::Value,
    tlog: Vec<(u64, mavlink::MavHeader, MavMessage)>,
}

fn fly(vehicle: &str, seconds: u32) -> Flight {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(["run", "--quiet", "--vehicle", vehicle, "--duration"])
        .arg(seconds.to_string())
        .arg("--config")
        .arg(lab_config(dir.path()))
        .arg("--out")
        .arg(&out_dir)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "infotrack run failed\n{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let summary =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("summary.json")).unwrap())
            .unwrap();
    let tlog = tlog::read(&out_dir.join("link.tlog")).unwrap();
    Flight {
        stdout,
        summary,
        tlog,
    }
}

/// Setpoints per second over the tracking phase (the stream runs from before takeoff).
fn setpoint_rate_hz(f: &Flight) -> f64 {
    let stamps: Vec<u64> = f
        .tlog
        .iter()
        .filter(|(_, _, m)| matches!(m, MavMessage::SET_POSITION_TARGET_LOCAL_NED(_)))
        .map(|(t, _, _)| *t)
        .collect();
    let span_s = (stamps[stamps.len() - 1] - stamps[0]) as f64 * 1e-6;
    (stamps.len() - 1) as f64 / span_s
}

/// Listens to the vehicle for `seconds` after infotrack has gone: its mode and how much
/// its altitude changed.
async fn watch_after_stop(url: &str, seconds: f64) -> (Option<Mode>, f64) {
    let mut lc = LinkConfig::new(url);
    lc.system_id = 250;
    let link = VehicleLink::connect(lc).await.unwrap();
    link.wait_vehicle(Duration::from_secs(20)).await.unwrap();
    link.request_telemetry().await.unwrap();
    let alt = |l: &VehicleLink| l.position_enu().map(|p| p.z_up_m);
    let until = Instant::now() + Duration::from_secs(10);
    while alt(&link).is_none() && Instant::now() < until {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let before = alt(&link).expect("the vehicle reports its position");
    tokio::time::sleep(Duration::from_secs_f64(seconds)).await;
    let after = alt(&link).unwrap();
    assert!(
        before > 0.8,
        "the vehicle was not airborne at the stop ({before} m)"
    );
    (link.state().mode, after - before)
}

/// Filter steps of the tracking phase, from the table's header line (60 s at 3 Hz: 180).
fn filter_steps(f: &Flight) -> u64 {
    f.stdout
        .split('|')
        .find_map(|c| c.trim().strip_suffix(" filter steps")?.parse().ok())
        .unwrap_or(0)
}

fn fov(f: &Flight) -> f64 {
    f.summary["fov_percent"].as_f64().unwrap()
}

/// One line for the CI log: what the flight measured.
fn report(name: &str, f: &Flight) {
    let n = |k: &str| f.summary[k].as_f64().unwrap_or(f64::NAN);
    println!(
        "SITL {name}: tracking {:.3} m, estimation {:.3} m, FOV {:.1} %, {} filter steps, setpoints {:.1} Hz",
        n("tracking_error_m"),
        n("estimation_error_m"),
        n("fov_percent"),
        filter_steps(f),
        setpoint_rate_hz(f)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the SITL builds: run by scripts/sitl-test.sh"]
async fn px4_sih_flies_the_lab_and_holds_after_the_flight() {
    let _px4 = start("px4/start.sh", &["0", "offboard=14541"]);
    let f = tokio::task::spawn_blocking(|| fly("udpin:127.0.0.1:14541", 60))
        .await
        .unwrap();
    report("PX4 SIH", &f);
    // Takeoff, OFFBOARD, tracking began (its filter steps are the table's).
    assert!(f.stdout.contains("px4 vehicle"), "{}", f.stdout);
    assert!(filter_steps(&f) >= 150, "{}", f.stdout);
    assert!(f
        .tlog
        .iter()
        .any(|(_, _, m)| matches!(m, MavMessage::HEARTBEAT(h) if h.custom_mode == 0x0006_0000)));
    let rate = setpoint_rate_hz(&f);
    assert!((15.0..=25.0).contains(&rate), "setpoints at {rate:.1} Hz");
    // PX4's position loop at the lab's 1.2 m is loose (it hunts by ~0.2 m): the target is
    // in view about a third of the time (issue 13's 50 % is not met on PX4 yet). Single
    // wall-clock flights spread widely: 17.9-48 % seen over 12 runs (mean ~32 %), so the bar
    // is that tracking works at all (a lost tracker sees the target by chance, ~5 %).
    assert!(fov(&f) >= 12.0, "{}", f.stdout);
    let (mode, dz) = watch_after_stop("udpin:127.0.0.1:14541", 10.0).await;
    assert_eq!(mode, Some(Mode::Hold));
    assert!(dz.abs() < 0.5, "altitude changed by {dz} m in the hold");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the SITL builds: run by scripts/sitl-test.sh"]
async fn arducopter_flies_the_lab_and_brakes_after_the_flight() {
    // SERIAL0 would hold the boot until something connects; infotrack uses SERIAL1.
    let _ac = start("arducopter/start.sh", &["1", "serial0=tcp:0"]);
    let f = tokio::task::spawn_blocking(|| fly("tcpout:127.0.0.1:5772", 60))
        .await
        .unwrap();
    report("ArduCopter", &f);
    assert!(f.stdout.contains("ardupilot vehicle"), "{}", f.stdout);
    assert!(filter_steps(&f) >= 150, "{}", f.stdout);
    // GUIDED (4) entered.
    assert!(f
        .tlog
        .iter()
        .any(|(_, _, m)| matches!(m, MavMessage::HEARTBEAT(h) if h.custom_mode == 4)));
    let rate = setpoint_rate_hz(&f);
    assert!((15.0..=25.0).contains(&rate), "setpoints at {rate:.1} Hz");
    // One wall-clock flight varies a lot (61.9, 61.5 and 41.1 % seen): the bar is that
    // tracking works, not issue 13's 50 % (the mean over several flights is the measure).
    assert!(fov(&f) >= 25.0, "{}", f.stdout);
    // BRAKE holds the altitude with no RC (LOITER would descend to the ground).
    let (mode, dz) = watch_after_stop("tcpout:127.0.0.1:5772", 10.0).await;
    assert_eq!(mode, Some(Mode::Brake));
    assert!(dz.abs() < 0.5, "altitude changed by {dz} m in the hold");
}

/// `infotrack params apply` then `params check` with a shipped parameter file, against the
/// firmware: every parameter written and read back equal.
fn params_round_trip(url: &str, file: &Path) -> String {
    let run = |action: &str| {
        Command::new(env!("CARGO_BIN_EXE_infotrack"))
            .args(["params", action])
            .arg(file)
            .args(["--connect", url, "--timeout", "60"])
            .output()
            .unwrap()
    };
    let applied = run("apply");
    let out = String::from_utf8_lossy(&applied.stdout).into_owned();
    assert!(
        applied.status.success(),
        "params apply failed\n{out}\n{}",
        String::from_utf8_lossy(&applied.stderr)
    );
    let checked = run("check");
    let check = String::from_utf8_lossy(&checked.stdout).into_owned();
    assert!(
        checked.status.success(),
        "params check after apply\n{check}"
    );
    assert!(
        check.contains(", 0 not as the file says"),
        "params check after apply\n{check}"
    );
    eprintln!("SITL params {}:\n{check}", file.display());
    check
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the SITL builds: run by scripts/sitl-test.sh"]
async fn px4_takes_the_shipped_parameter_file() {
    let _px4 = start("px4/start.sh", &["0", "offboard=14541"]);
    let shipped =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware-params/px4-offboard-tracking.params");
    // The SITL build has no serial ports: their two parameters are not on it, and the file
    // is then applied not at all (nothing half-written).
    let whole = {
        let shipped = shipped.clone();
        tokio::task::spawn_blocking(move || {
            Command::new(env!("CARGO_BIN_EXE_infotrack"))
                .args(["params", "apply"])
                .arg(&shipped)
                .args(["--connect", "udpin:127.0.0.1:14541", "--timeout", "60"])
                .output()
                .unwrap()
        })
        .await
        .unwrap()
    };
    let out = String::from_utf8_lossy(&whole.stdout).into_owned();
    assert!(!whole.status.success(), "{out}");
    assert!(
        out.contains("MAV_1_CONFIG")
            && out.contains("NOT ON VEHICLE")
            && out.contains("not written"),
        "{out}"
    );
    assert!(!out.contains("applied"), "{out}");
    // Without the serial-port lines it is applied whole and reads back equal.
    let dir = tempfile::tempdir().unwrap();
    let sitl_file = dir.path().join("px4-sitl.params");
    let text: String = std::fs::read_to_string(&shipped)
        .unwrap()
        .lines()
        .filter(|l| !l.contains("MAV_1_CONFIG") && !l.contains("SER_TEL2_BAUD"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&sitl_file, text).unwrap();
    let check =
        tokio::task::spawn_blocking(move || params_round_trip("udpin:127.0.0.1:14541", &sitl_file))
            .await
            .unwrap();
    assert!(check.contains("COM_OF_LOSS_T"), "{check}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the SITL builds: run by scripts/sitl-test.sh"]
async fn arducopter_takes_the_shipped_parameter_file() {
    let _ac = start("arducopter/start.sh", &["1", "serial0=tcp:0"]);
    let check = tokio::task::spawn_blocking(|| {
        params_round_trip(
            "tcpout:127.0.0.1:5772",
            &Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("firmware-params/ardupilot-guided-tracking.parm"),
        )
    })
    .await
    .unwrap();
    assert!(check.contains("GUID_TIMEOUT"), "{check}");
}
