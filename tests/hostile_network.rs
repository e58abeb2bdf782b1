//! The hostile network: an attacker on the link (a relay that injects frames with the
//! vehicle's own ids) while `infotrack run` flies the mock. Whatever is injected, every
//! setpoint in the tlog is finite and inside the real geofence, and the vehicle ends where
//! a clean stop leaves it: in hold, at its altitude.

mod common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use common::relay::{frame, relay, Relay};
use common::{lab_config_with, output_text, udp_mock};
use infotrack::autopilot::modes::{Flavor, Mode};
use infotrack::mock::server::MockHandle;
use infotrack::mock::MockConfig;
use mavlink::dialects::ardupilotmega::*;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The lab's geofence (config/default.toml `[workspace_enu]`), world ENU, m.
const FENCE_EAST_M: (f64, f64) = (-3.0, 1.0);
const FENCE_NORTH_M: (f64, f64) = (-1.2, 2.0);

/// LOCAL_POSITION_NED from the vehicle's ids.
fn local(x: f32, y: f32, z: f32, v: f32, boot_ms: u32) -> Vec<u8> {
    let m = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        time_boot_ms: boot_ms,
        x,
        y,
        z,
        vx: v,
        vy: 0.0,
        vz: 0.0,
    });
    frame(1, 1, &m)
}

/// What a glitching or lying link says with the vehicle's ids: 10 km jumps, 10 km down and
/// up, 3e38 m/s, a yaw of 1e30, GLOBAL_POSITION_INT at -10 km, boot clocks that jump back
/// and forth (a reboot every frame), and bytes that are no frame at all.
fn poison(origin: (f64, f64)) -> Vec<Vec<u8>> {
    let global = |alt_mm: i32, rel_mm: i32| {
        frame(
            1,
            1,
            &MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                time_boot_ms: 5,
                lat: (origin.0 * 1e7) as i32,
                lon: (origin.1 * 1e7) as i32,
                alt: alt_mm,
                relative_alt: rel_mm,
                vx: 0,
                vy: 0,
                vz: 0,
                hdg: 0,
            }),
        )
    };
    let attitude = |yaw: f32, boot_ms: u32| {
        frame(
            1,
            1,
            &MavMessage::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms: boot_ms,
                roll: 0.0,
                pitch: 0.0,
                yaw,
                rollspeed: 0.0,
                pitchspeed: 0.0,
                yawspeed: 0.0,
            }),
        )
    };
    vec![
        local(10_000.0, 0.0, -1.2, 0.0, 5),
        local(0.5, -0.5, 10_000.0, 0.0, 5),
        local(0.5, -0.5, -10_000.0, 0.0, 5),
        local(0.5, -0.5, -1.2, 3e38, 5),
        global(-10_000_000, -10_000_000),
        global(-10_000_000, 1_200),
        attitude(1e30, 5),
        attitude(0.0, 4_000_000_000),
        attitude(0.0, 1),
        vec![0xfd, 0xff, 0x00, 0x13, 0x37, 0xde, 0xad, 0xbe, 0xef],
    ]
}

/// Flies `infotrack run` on the lab config `cfg` through a relay that injects `inject`
/// from `after` on; returns its output, the flight folder and the relay (what the GCS
/// heard).
async fn fly_through(
    vehicle: u16,
    cfg: Option<&Path>,
    inject: Vec<Vec<u8>>,
    after: Duration,
    seconds: u32,
) -> (std::process::Output, tempfile::TempDir, Relay) {
    let (relay, front) = relay(vehicle, inject, after).await;
    let dir = tempfile::tempdir().unwrap();
    let mut cmd = tokio::process::Command::new(env!("CARGO_BIN_EXE_infotrack"));
    cmd.args(["run", "--quiet", "--motion", "cv", "--duration"])
        .arg(seconds.to_string())
        .args(["--allow-simulation-on-vehicle", "--allow-auto-engage"])
        .arg("--vehicle")
        .arg(format!("udpout:127.0.0.1:{front}"))
        .arg("--out")
        .arg(dir.path())
        .current_dir(root());
    if let Some(c) = cfg {
        cmd.arg("--config").arg(c);
    }
    let out = cmd.output().await.unwrap();
    (out, dir, relay)
}

/// Every position setpoint infotrack sent, as world ENU (east, north, up) when the vehicle's
/// frame is the world's.
fn setpoints(dir: &Path) -> Vec<[f64; 3]> {
    let tlog = infotrack::autopilot::tlog::read(&dir.join("link.tlog")).unwrap();
    tlog.iter()
        .filter_map(|(_, _, m)| match m {
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(s) => {
                Some([s.y as f64, s.x as f64, -s.z as f64])
            }
            _ => None,
        })
        .collect()
}

/// Every setpoint finite and inside the fence (`margin_m` for a vehicle frame that is not
/// the world's); at least `min` of them.
fn assert_inside_the_fence(dir: &Path, margin_m: f64, min: usize) {
    let sps = setpoints(dir);
    assert!(sps.len() >= min, "{} setpoints", sps.len());
    for [e, n, u] in &sps {
        assert!(
            e.is_finite() && n.is_finite() && u.is_finite(),
            "{e} {n} {u}"
        );
        assert!(
            (FENCE_EAST_M.0 - margin_m..=FENCE_EAST_M.1 + margin_m).contains(e)
                && (FENCE_NORTH_M.0 - margin_m..=FENCE_NORTH_M.1 + margin_m).contains(n),
            "setpoint ({e:.2}, {n:.2}) m ENU outside the fence"
        );
        assert!((0.0..=10.0).contains(u), "setpoint at {u} m up");
    }
}

/// The vehicle holds (its flavour's hold mode) at the lab's 1.2 m: not the ground, not 10 km.
fn assert_holds_at_the_lab_altitude(mock: &MockHandle, flavor: Flavor, all: &str) {
    let (mode, pos) = mock.with(|m| (m.mode(), m.position_ned_m()));
    assert_eq!(mode, Mode::hold_for(flavor), "{all}");
    assert!((-pos[2] - 1.2).abs() < 0.5, "holds at {} m up", -pos[2]);
}

/// An ArduPilot heartbeat from (`sys`, 1) in `custom_mode`, armed or not.
fn ardupilot_heartbeat(sys: u8, custom_mode: u32, armed: bool) -> Vec<u8> {
    let armed = if armed {
        MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
    } else {
        MavModeFlag::empty()
    };
    frame(
        sys,
        1,
        &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | armed,
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }),
    )
}

/// Poisoned telemetry with the vehicle's ids through the whole flight and at the stop: it
/// is dropped (and said so, at powers of two), never recorded, never flown toward; the
/// PX4 hold keeps the altitude.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn poisoned_telemetry_never_moves_a_setpoint_or_the_hold() {
    let m = MockConfig::new(Flavor::Px4);
    let origin = (m.origin_lat_deg, m.origin_lon_deg);
    let (mock, vehicle) = udp_mock(m).await;
    let (out, dir, _) = fly_through(vehicle, None, poison(origin), Duration::ZERO, 12).await;
    let all = output_text(&out);
    assert!(out.status.success(), "{all}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("the vehicle cannot have flown"), "{all}");
    // A reboot every injected frame, ~20 a second: said at powers of two only.
    let reboots = stderr.matches("vehicle rebooted").count();
    assert!(
        (1..=12).contains(&reboots),
        "{reboots} reboot warnings: {all}"
    );
    assert_inside_the_fence(dir.path(), 0.0, 100);
    // The records hold only where the vehicle was: inside the lab.
    let steps = std::fs::read_to_string(dir.path().join("steps.csv")).unwrap();
    let header: Vec<&str> = steps.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (ax, ay) = (col("agent_x_enu_m"), col("agent_y_enu_m"));
    for row in steps.lines().skip(1) {
        let f: Vec<f64> = row
            .split(',')
            .map(|v| v.parse().unwrap_or(f64::NAN))
            .collect();
        assert!(f[ax].abs() < 10.0 && f[ay].abs() < 10.0, "recorded {row}");
    }
    // The hold: PX4's AUTO.LOITER at the lab's 1.2 m, not the ground, not 10 km.
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_holds_at_the_lab_altitude(&mock, Flavor::Px4, &all);
}

/// A flood: 10,000 frames a second of other systems' traffic, spoofed heartbeats in other
/// modes and garbage, through the flight. The daemon keeps flying inside the fence.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_spoofed_and_garbage_frames_keeps_the_fence() {
    let (_mock, vehicle) = udp_mock(MockConfig::new(Flavor::ArduPilot)).await;
    // 1,000 frames every 100 ms.
    let mut flood = Vec::new();
    for k in 0..1_000u32 {
        flood.push(match k % 4 {
            0 => ardupilot_heartbeat(42, k % 20, false),
            1 => local(5_000.0, 5_000.0, -50.0, 0.0, k),
            2 => vec![0xfd, 9, 0, 0, k as u8, 1, 1, 0x21, 0, 0, 1, 2, 3],
            _ => (0..40).map(|i| (i as u32 * 31 + k) as u8).collect(),
        });
    }
    let (out, dir, _) = fly_through(vehicle, None, flood, Duration::ZERO, 10).await;
    let all = output_text(&out);
    assert!(out.status.success(), "{all}");
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("panicked"),
        "{all}"
    );
    assert_inside_the_fence(dir.path(), 0.0, 50);
}

/// The lab placed on Earth at the mock's origin (`[world] origin`).
fn lab_on_earth(dir: &Path, origin: (f64, f64)) -> PathBuf {
    let o: toml::Table = format!(
        "lat_deg = {}\nlon_deg = {}\nalt_m = 30.0",
        origin.0, origin.1
    )
    .parse()
    .unwrap();
    lab_config_with(dir, "world.origin", toml::Value::Table(o))
}

/// GPS_GLOBAL_ORIGIN, `north_m` north of `origin`, with the vehicle's ids.
fn spoofed_origin(origin: (f64, f64), north_m: f64) -> Vec<u8> {
    frame(
        1,
        1,
        &MavMessage::GPS_GLOBAL_ORIGIN(GPS_GLOBAL_ORIGIN_DATA {
            latitude: ((origin.0 + north_m / 110_800.0) * 1e7) as i32,
            longitude: (origin.1 * 1e7) as i32,
            altitude: 30_000,
            time_usec: 0,
        }),
    )
}

/// An origin spoofed 299 m off from the first heartbeat on: the world is never placed with
/// it (it disagrees with GLOBAL_POSITION_INT); if infotrack places the world with the real
/// one, the spoofed one that follows is an origin change: the flight stops in hold and says
/// why. Either way no setpoint leaves the real fence.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_spoofed_origin_at_start_never_moves_the_fence() {
    let m = MockConfig::new(Flavor::Px4);
    let origin = (m.origin_lat_deg, m.origin_lon_deg);
    let (mock, vehicle) = udp_mock(m).await;
    let cfgs = tempfile::tempdir().unwrap();
    let cfg = lab_on_earth(cfgs.path(), origin);
    let inject = vec![spoofed_origin(origin, 299.0)];
    let (out, dir, _) = fly_through(vehicle, Some(&cfg), inject, Duration::ZERO, 8).await;
    let all = output_text(&out);
    assert!(!out.status.success(), "{all}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("origin cannot be trusted")
            || stderr.contains("GPS_GLOBAL_ORIGIN changed in flight"),
        "{all}"
    );
    if dir.path().join("link.tlog").exists() {
        assert_inside_the_fence(dir.path(), 0.1, 0);
    }
    if mock.with(|m| m.armed()) {
        tokio::time::sleep(Duration::from_secs(2)).await;
        assert_eq!(
            mock.with(|m| m.mode()),
            Mode::hold_for(Flavor::Px4),
            "{all}"
        );
    }
}

/// The origin moved 299 m in flight: tracking stops, the vehicle holds, the terminal and
/// the ground station are told why, and the exit code says it failed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_origin_that_moves_in_flight_holds_and_says_why() {
    let m = MockConfig::new(Flavor::Px4);
    let origin = (m.origin_lat_deg, m.origin_lon_deg);
    let (mock, vehicle) = udp_mock(m).await;
    let cfgs = tempfile::tempdir().unwrap();
    let cfg = lab_on_earth(cfgs.path(), origin);
    let inject = vec![spoofed_origin(origin, 299.0)];
    // Takeoff to the start point takes ~6 s on the mock: the spoof comes during tracking.
    let (out, dir, relay) =
        fly_through(vehicle, Some(&cfg), inject, Duration::from_secs(12), 40).await;
    let all = output_text(&out);
    assert!(!out.status.success(), "{all}");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("GPS_GLOBAL_ORIGIN changed in flight"),
        "{all}"
    );
    let told = relay.texts.lock().unwrap().clone();
    assert!(
        told.iter().any(|t| t.contains("origin changed")),
        "the GCS heard {told:?}"
    );
    assert_inside_the_fence(dir.path(), 0.1, 50);
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_holds_at_the_lab_altitude(&mock, Flavor::Px4, &all);
}

/// Heartbeats spoofed with the vehicle's own ids in another mode (STABILIZE), ten a second:
/// whatever infotrack makes of the flapping mode, it never sends a setpoint outside the
/// fence, and at the end the vehicle holds at its altitude.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn spoofed_heartbeats_in_another_mode_never_take_the_vehicle_out_of_the_fence() {
    let (mock, vehicle) = udp_mock(MockConfig::new(Flavor::ArduPilot)).await;
    let stabilize = ardupilot_heartbeat(1, 0, true);
    let (out, dir, _) =
        fly_through(vehicle, None, vec![stabilize], Duration::from_secs(8), 20).await;
    let all = output_text(&out);
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("panicked"),
        "{all}"
    );
    assert_inside_the_fence(dir.path(), 0.0, 50);
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_holds_at_the_lab_altitude(&mock, Flavor::ArduPilot, &all);
}
