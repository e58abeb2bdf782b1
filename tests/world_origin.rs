//! `[world] origin`: infotrack flies a world on Earth only when the vehicle's local origin
//! (GPS_GLOBAL_ORIGIN) is the world's, within `world.origin_tolerance_m`; a vehicle powered
//! up elsewhere is refused before anything is commanded, with both origins and the distance.

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
    tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args([
            "run",
            "--quiet",
            "--duration",
            "3",
            "--motion",
            "cv",
            "--config",
        ])
        .arg(cfg)
        .arg("--vehicle")
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

    // 100 m north of it (a degree of latitude is ~110.8 km here): refused, nothing armed.
    let (mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let out = fly(
        &lab_with_world(dir.path(), lat + 100.0 / 110_800.0, lon),
        port,
    )
    .await;
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success());
    assert!(
        err.contains("m from the world's") && err.contains("world.origin_tolerance_m = 5 m"),
        "{err}"
    );
    let said: f64 = err
        .split(" is ")
        .nth(1)
        .and_then(|t| t.split(" m from").next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no distance in {err}"));
    assert!((said - 100.0).abs() < 0.5, "{said} m");
    assert!(!mock.with(|m| m.armed()));

    // A latitude that is not one is refused at load.
    let out = fly(&lab_with_world(dir.path(), 95.0, lon), port).await;
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(err.contains("world.origin.lat_deg"), "{err}");
}
