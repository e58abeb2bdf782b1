//! `[world] origin`: infotrack reads the vehicle's local origin (GPS_GLOBAL_ORIGIN) and
//! converts between the vehicle's frame and the world's, both ways (telemetry in, setpoints
//! out); a vehicle whose origin is farther than `world.origin_tolerance_m` is refused before
//! anything is commanded, with both origins and the distance.

mod common;

use std::path::{Path, PathBuf};

use common::{lab_config_with, udp_mock};
use infotrack::autopilot::modes::Flavor;
use infotrack::mock::MockConfig;

fn lab_with_world(dir: &Path, lat: f64, lon: f64) -> PathBuf {
    let origin: toml::Table = format!("lat_deg = {lat}\nlon_deg = {lon}\nalt_m = 30.0")
        .parse()
        .unwrap();
    lab_config_with(dir, "world.origin", toml::Value::Table(origin))
}

async fn fly(cfg: &Path, port: u16) -> std::process::Output {
    fly_logged(cfg, port, None).await
}

async fn fly_logged(cfg: &Path, port: u16, out: Option<&Path>) -> std::process::Output {
    let mut cmd = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"));
    cmd.arg("run");
    if let Some(o) = out {
        cmd.arg("--out").arg(o);
    }
    cmd.args(["--quiet", "--duration", "3", "--motion", "cv", "--config"])
        .arg(cfg)
        .args([
            "--allow-simulation-on-vehicle",
            "--allow-auto-engage",
            "--vehicle",
        ])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .await
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_vehicle_flies_only_from_the_worlds_origin() {
    let dir = tempfile::tempdir().unwrap();
    let m = MockConfig::new(Flavor::Px4);
    let (lat, lon) = (m.origin_lat_deg, m.origin_lon_deg);

    // The vehicle's origin is the world's: it flies.
    let (_mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let out = fly(&lab_with_world(dir.path(), lat, lon), port).await;
    let all = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{all}");

    // 2 km north of it (a degree of latitude is ~110.8 km here): refused, nothing armed.
    let (mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let out = fly(
        &lab_with_world(dir.path(), lat + 2000.0 / 110_800.0, lon),
        port,
    )
    .await;
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success());
    assert!(
        err.contains("m from the world's") && err.contains("world.origin_tolerance_m = 1000 m"),
        "{err}"
    );
    let said: f64 = err
        .split(" is ")
        .nth(1)
        .and_then(|t| t.split(" m from").next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no distance in {err}"));
    assert!((said - 2000.0).abs() < 5.0, "{said} m");
    assert!(!mock.with(|m| m.armed()));

    // A latitude that is not one is refused at load.
    let out = fly(&lab_with_world(dir.path(), 95.0, lon), port).await;
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(err.contains("world.origin.lat_deg"), "{err}");
}

/// The vehicle powered up 1 m west and 1 m north of the world's origin: what it reports is
/// moved into the world (the flight log's first position is the world's start point, 1.4 m
/// from where the vehicle's own frame has it) and what it is sent is moved out of it (the
/// start point's setpoints arrive as start - offset in its local NED).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vehicle_origin_off_the_worlds_is_converted_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let m = MockConfig::new(Flavor::Px4);
    let vehicle_origin = infotrack::geodesy::GeodeticWgs84 {
        lat_deg: m.origin_lat_deg,
        lon_deg: m.origin_lon_deg,
        alt_m: m.origin_alt_m,
    };
    // The world's origin is 1 m east and 1 m south of the vehicle's.
    let world = vehicle_origin.offset_by_enu([1.0, -1.0, 0.0]);
    let (_mock, port) = udp_mock(m).await;
    let out_dir = dir.path().join("flight");
    let out = fly_logged(
        &lab_with_world(dir.path(), world.lat_deg, world.lon_deg),
        port,
        Some(&out_dir),
    )
    .await;
    let all = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{all}");

    // In: the first logged position (tracking starts at the start point) is world ENU
    // (-0.5, 0.5), i.e. NED (0.5, -0.5); unconverted it would be NED (-0.5, 0.5).
    let log = std::fs::read_to_string(out_dir.join("flight.csv")).unwrap();
    let first: Vec<f64> = log
        .lines()
        .find(|l| l.chars().next().is_some_and(|c| c.is_ascii_digit()))
        .unwrap()
        .split(',')
        .skip(1)
        .take(2)
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        (first[0] - 0.5).abs() < 0.2 && (first[1] + 0.5).abs() < 0.2,
        "first logged vehicle position (north, east) {first:?}"
    );

    // Out: the setpoints that took it there, in the vehicle's local NED: the start point
    // minus the offset, north 0.5 - 1 = -0.5, east -0.5 + 1 = 0.5.
    let tlog = infotrack::autopilot::tlog::read(&out_dir.join("link.tlog")).unwrap();
    let sent: Vec<(f32, f32)> = tlog
        .iter()
        .filter(|(_, h, _)| h.component_id == 191)
        .filter_map(|(_, _, msg)| match msg {
            mavlink::dialects::ardupilotmega::MavMessage::SET_POSITION_TARGET_LOCAL_NED(p) => {
                Some((p.x, p.y))
            }
            _ => None,
        })
        .collect();
    let takeoff = sent[0];
    assert!(
        takeoff.0.abs() < 0.05 && takeoff.1.abs() < 0.05,
        "takeoff above the vehicle's own origin: {takeoff:?}"
    );
    let start = sent
        .iter()
        .find(|p| (p.0 - takeoff.0).abs() > 0.05 || (p.1 - takeoff.1).abs() > 0.05)
        .unwrap();
    assert!(
        (start.0 + 0.5).abs() < 1e-3 && (start.1 - 0.5).abs() < 1e-3,
        "start point sent as {start:?}"
    );
}
