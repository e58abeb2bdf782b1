//! The mock autopilot calibrated against the real ones: the response probe
//! (`tests/common/probe.rs`: takeoff, hover, a position step, a moving setpoint without and
//! with feed-forward, the hold) flown against each flavour of the mock must answer as the
//! SITL build of that firmware answered it (`tests/fixtures/sitl/`, recorded by
//! `scripts/record-sitl-responses.sh`).

use std::time::Duration;

use infotrack::autopilot::link::{LinkConfig, VehicleLink};
use infotrack::autopilot::modes::Flavor;
use infotrack::mock::MockConfig;

mod common;
#[path = "common/probe.rs"]
mod probe;

async fn probe_mock(flavor: Flavor, seed: u64) -> probe::Response {
    let mut cfg = MockConfig::new(flavor);
    cfg.response = infotrack::mock::vehicle::Response::sitl(flavor);
    cfg.seed = seed;
    let (mock, port) = common::udp_mock(cfg).await;
    let link = VehicleLink::connect(LinkConfig::new(&format!("udpout:127.0.0.1:{port}")))
        .await
        .unwrap();
    link.wait_vehicle(Duration::from_secs(5)).await.unwrap();
    link.request_telemetry().await.unwrap();
    assert!(
        common::eventually(5.0, || link.position_enu().is_some()
            && link.state().attitude.is_some())
        .await
    );
    let r = probe::fly(&link, Duration::from_secs(60)).await;
    mock.stop();
    if let Ok(dir) = std::env::var("INFOTRACK_PROBE_OUT") {
        let p = std::path::Path::new(&dir).join(format!("mock-{flavor}-{seed}.csv"));
        std::fs::write(p, r.to_csv()).unwrap();
    }
    r
}

/// The mock's vehicle wanders as PX4 SIH's does, one realisation per seed: the figures of
/// 21 flights (seeds 1-21, flown at once), each the median over the flights, stand for it.
/// Nine flights were too few: one flight's overshoot ranges over 0.0-0.45 m with the wander,
/// and the median of seeds 1-9 sat on the edge of PX4 SIH's range (a CI run failed on it).
async fn probe_mock_flights(flavor: Flavor) -> probe::Figures {
    let flights: Vec<_> = (1..=21)
        .map(|seed| tokio::spawn(probe_mock(flavor, seed)))
        .collect();
    let mut figures = Vec::new();
    for f in flights {
        figures.push(f.await.unwrap().figures());
    }
    println!("mock {flavor} flights: {figures:?}");
    probe::median(&figures)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_px4_mock_answers_the_probe_as_px4_sih_did() {
    let mock = probe_mock_flights(Flavor::Px4).await;
    println!("mock PX4: {mock:?}");
    probe::assert_within("mock PX4", &mock, "PX4 SIH", &probe::recorded("px4-sih"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_ardupilot_mock_answers_the_probe_as_arducopter_did() {
    let mock = probe_mock_flights(Flavor::ArduPilot).await;
    println!("mock ArduPilot: {mock:?}");
    probe::assert_within(
        "mock ArduPilot",
        &mock,
        "ArduCopter SITL",
        &probe::recorded("arducopter"),
    );
}

/// The probe can tell vehicles apart: the comparison fails for a vehicle whose position loop
/// is not the recorded one (here PX4's recording against ArduCopter's).
#[test]
fn the_comparison_tells_the_firmwares_apart() {
    let px4 = probe::recorded("px4-sih");
    let ac = probe::recorded("arducopter");
    for f in &px4 {
        let r = std::panic::catch_unwind(|| probe::assert_within("PX4", f, "ArduCopter", &ac));
        assert!(r.is_err(), "PX4 {f:?}\nArduCopter {ac:?}");
    }
}
