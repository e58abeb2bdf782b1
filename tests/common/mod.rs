//! Helpers shared by the integration tests that fly the mock autopilot.
#![allow(dead_code)]

pub mod relay;

use std::time::Duration;

use infotrack::autopilot::link::{LinkEvent, VehicleLink};
use infotrack::autopilot::modes::Mode;
use infotrack::frames::PositionEnu;

/// A UDP port free at the time of asking.
pub fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Waits (at most 10 s) until a process listens on loopback UDP `port`, read from the
/// kernel's socket table (`/proc/net/udp`) so the check never holds the port itself. A fixed
/// sleep after spawning a mock process raced its start on a busy machine: a command sent
/// before the mock had bound its port was lost and the test failed.
pub fn wait_for_udp_listener(port: u16) {
    let bound = || {
        ["/proc/net/udp", "/proc/net/udp6"].iter().any(|table| {
            std::fs::read_to_string(table).is_ok_and(|text| {
                text.lines().skip(1).any(|line| {
                    let local = line.split_whitespace().nth(1).unwrap_or("");
                    local
                        .rsplit_once(':')
                        .and_then(|(_, hex)| u16::from_str_radix(hex, 16).ok())
                        == Some(port)
                })
            })
        })
    };
    let until = std::time::Instant::now() + Duration::from_secs(10);
    while !bound() {
        assert!(
            std::time::Instant::now() < until,
            "nothing listens on UDP port {port} 10 s after the mock process was started"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `infotrack mock-autopilot` in its own process, killed (and reaped) on drop.
pub struct MockProcess(std::process::Child);

impl Drop for MockProcess {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `infotrack mock-autopilot --flavor <flavor>` listening on loopback UDP `port`,
/// signing with the key file `key` if one is given, and returns once it has bound the port.
pub fn mock_process(flavor: &str, port: u16, key: Option<&std::path::Path>) -> MockProcess {
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_infotrack"));
    command
        .args(["mock-autopilot", "--flavor", flavor, "--listen"])
        .arg(format!("udpin:127.0.0.1:{port}"));
    if let Some(key) = key {
        command.arg("--signing-key").arg(key);
    }
    let mock = MockProcess(command.spawn().expect("spawn infotrack mock-autopilot"));
    wait_for_udp_listener(port);
    mock
}

/// Flies to (x, y) ENU at `alt` and waits until the reported position is within 0.5 m.
pub async fn fly_to(link: &VehicleLink, x: f64, y: f64, alt: f64) {
    let p = PositionEnu {
        x_east_m: x,
        y_north_m: y,
        z_up_m: alt,
    };
    link.set_setpoint(p, 0.0).unwrap();
    link.wait_for(
        |s| {
            s.local_ned
                .map(|(_, n, _)| {
                    let e = n.to_enu();
                    (e.x_east_m - x).hypot(e.y_north_m - y) < 0.5 && (e.z_up_m - alt).abs() < 0.5
                })
                .unwrap_or(false)
        },
        &format!("reaching ({x}, {y}, {alt})"),
        Duration::from_secs(20),
    )
    .await
    .unwrap();
}

/// Waits for a mode change the link did not ask for, to `want`.
pub async fn expect_failsafe(
    link: &VehicleLink,
    rx: &mut tokio::sync::broadcast::Receiver<LinkEvent>,
    want: Mode,
) {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(15);
    loop {
        match tokio::time::timeout_at(deadline, rx.recv()).await {
            Ok(Ok(LinkEvent::ModeChanged {
                to,
                commanded: false,
                ..
            })) if to == want => break,
            Ok(Ok(_)) | Ok(Err(_)) => continue,
            Err(_) => panic!("no failsafe to {want:?}; state {:?}", link.state().mode),
        }
    }
    assert!(link
        .state()
        .unexpected_mode_changes
        .iter()
        .any(|(_, to)| *to == want));
}

/// A mock autopilot listening on a free loopback UDP port, without faults; and the port.
/// A port free when asked can be taken by a concurrent test before the mock binds it: then
/// another is asked for (at most 20 times).
pub async fn udp_mock(
    cfg: infotrack::mock::MockConfig,
) -> (infotrack::mock::server::MockHandle, u16) {
    let mut tries = 0;
    loop {
        let port = free_udp_port();
        match infotrack::mock::server::spawn(
            &format!("udpin:127.0.0.1:{port}"),
            cfg.clone(),
            infotrack::mock::server::Faults::default(),
        )
        .await
        {
            Ok(mock) => return (mock, port),
            Err(e) if e.kind() == std::io::ErrorKind::AddrInUse && tries < 20 => tries += 1,
            Err(e) => panic!("the mock autopilot could not listen on UDP port {port}: {e}"),
        }
    }
}

/// Polls `pred` every 50 ms for at most `secs`; whether it came true.
pub async fn eventually(secs: f64, pred: impl Fn() -> bool) -> bool {
    let until = tokio::time::Instant::now() + Duration::from_secs_f64(secs);
    while tokio::time::Instant::now() < until {
        if pred() {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    pred()
}

/// Sends SIGTERM to a child process and waits (at most 20 s) for it to exit.
pub async fn sigterm(child: tokio::process::Child) -> std::process::Output {
    let pid = child.id().expect("the child is running") as i32;
    // SAFETY: sending a signal to our own child process.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGTERM) }, 0);
    tokio::time::timeout(Duration::from_secs(20), child.wait_with_output())
        .await
        .expect("the process did not stop on SIGTERM")
        .unwrap()
}

/// The lab config (`config/default.toml`) with `key` (dotted, `section.name`) set to
/// `value`, written into `dir`.
pub fn lab_config_with(dir: &std::path::Path, key: &str, value: toml::Value) -> std::path::PathBuf {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("config/default.toml")).unwrap();
    let mut table: toml::Table = text.parse().unwrap();
    let (section, name) = key.split_once('.').unwrap();
    table
        .entry(section)
        .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        .as_table_mut()
        .unwrap()
        .insert(name.to_string(), value);
    let path = dir.join(format!("{}.toml", key.replace('.', "-")));
    std::fs::write(&path, toml::to_string(&table).unwrap()).unwrap();
    path
}

/// This build's `infotrack` with `args`, run from the project's folder (where the shipped
/// configs and fixtures are), to its end.
pub fn infotrack_in_project(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the binary runs")
}

/// A finished process's exit code, stdout and stderr, for assertions and their messages.
pub fn output_text(o: &std::process::Output) -> String {
    format!(
        "rc {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The table under the dotted `key`'s last part (any depth, created where missing) and that
/// part's name.
pub fn table_for<'a>(table: &'a mut toml::Table, key: &'a str) -> (&'a mut toml::Table, &'a str) {
    let (path, last) = key.rsplit_once('.').unwrap_or(("", key));
    let mut t = table;
    for p in path.split('.').filter(|p| !p.is_empty()) {
        t = t
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .unwrap();
    }
    (t, last)
}

/// The camera of [`film_a_tag`]: ideal, 640 x 480, the config's field of view, nadir.
pub fn filming_camera(
    cfg: &infotrack::config::Config,
) -> infotrack::vision::camera_model::CameraModel {
    use infotrack::vision::camera_model::{CameraModel, CameraMount, Intrinsics};
    CameraModel {
        intrinsics: Intrinsics::ideal(640, 480, cfg.camera.fov_x_rad),
        mount: CameraMount::nadir(),
    }
}

/// Where [`film_a_tag`] films from: over the origin at the agent's altitude, nose north.
pub fn filming_pose(
    cfg: &infotrack::config::Config,
) -> infotrack::vision::camera_model::VehiclePoseNed {
    infotrack::vision::camera_model::VehiclePoseNed {
        position_ned_m: [0.0, 0.0, -cfg.agent.altitude_m],
        roll_rad: 0.0,
        pitch_rad: 0.0,
        yaw_rad: 0.0,
    }
}

/// A real camera's film for the daemon to fly with: 120 rendered frames (4 s at 30 fps) of
/// the config's tag at `tag_enu_m`, seen from [`filming_pose`], as `camera.avi` (FFV1) in
/// `dir`, and the camera's calibration as `camera.yaml`. Returns both paths.
pub fn film_a_tag(
    dir: &std::path::Path,
    cfg: &infotrack::config::Config,
    tag_enu_m: [f64; 2],
) -> (std::path::PathBuf, std::path::PathBuf) {
    use infotrack::render::{render, RenderOptions, SceneEnu, TargetAppearance};
    use infotrack::vision::{cv_io, tag_family::TagBitmap};
    use opencv::prelude::*;
    let cam = filming_camera(cfg);
    let calib = dir.join("camera.yaml");
    cv_io::save_calibration(&calib, &cam.intrinsics).unwrap();
    let pose = filming_pose(cfg);
    let scene = SceneEnu {
        target: Some(TargetAppearance {
            position_enu_m: tag_enu_m,
            heading_enu_rad: 0.3,
            tag: TagBitmap::tag36h11(cfg.vision.tag_id).unwrap(),
            tag_size_m: cfg.vision.tag_size_m,
        }),
        occluders: vec![],
        ground_seed: 2,
    };
    let video = dir.join("camera.avi");
    let mut w = opencv::videoio::VideoWriter::new(
        &video.display().to_string(),
        opencv::videoio::VideoWriter::fourcc('F', 'F', 'V', '1').unwrap(),
        30.0,
        opencv::core::Size::new(640, 480),
        false,
    )
    .unwrap();
    let opts = RenderOptions {
        supersample: 2,
        noise_sigma: 2.0,
        ..Default::default()
    };
    for k in 0..120 {
        w.write(&cv_io::mat_from_gray(&render(&cam, &pose, &scene, &opts, k)).unwrap())
            .unwrap();
    }
    w.release().unwrap();
    (video, calib)
}

/// A campaign's results without its step times (measurements of the machine that ran them)
/// and without what says how they were made (`merged_from`): what one process and its
/// merged shards must agree on.
pub fn results_only(v: &serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match v {
        Value::Object(m) => Value::Object(
            m.iter()
                .filter(|(k, _)| {
                    !["filter_step_ms", "guidance_step_ms", "merged_from"].contains(&k.as_str())
                })
                .map(|(k, x)| (k.clone(), results_only(x)))
                .collect(),
        ),
        Value::Array(a) => Value::Array(a.iter().map(results_only).collect()),
        x => x.clone(),
    }
}

/// Every Markdown page under `dir`, recursively, sorted: the book's pages under `docs/src`.
pub fn markdown_pages(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    fn walk(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).expect("the folder lists") {
            let path = entry.expect("an entry of the folder").path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "md") {
                out.push(path);
            }
        }
    }
    let mut pages = Vec::new();
    walk(dir, &mut pages);
    pages.sort();
    pages
}
