//! The vehicle link against the mock autopilot as a real peer over real UDP sockets: take
//! off, enter offboard/guided, fly setpoints, failsafe, parameters, packet loss.

use std::time::Duration;

use infotrack::autopilot::link::{LinkConfig, LinkError, VehicleLink};
use infotrack::autopilot::modes::{Flavor, Mode};
use infotrack::autopilot::params_file::ParamType;
use infotrack::frames::PositionEnu;
use infotrack::mock::server::{spawn, Faults};
use infotrack::mock::{MockConfig, MockEvent};

mod common;
use common::{expect_failsafe, fly_to, free_udp_port};

async fn setup(
    flavor: Flavor,
    loss_percent: f64,
    link_sysid: u8,
) -> (infotrack::mock::server::MockHandle, VehicleLink) {
    setup_with(MockConfig::new(flavor), loss_percent, link_sysid).await
}

async fn setup_with(
    mock_cfg: MockConfig,
    loss_percent: f64,
    link_sysid: u8,
) -> (infotrack::mock::server::MockHandle, VehicleLink) {
    let flavor = mock_cfg.flavor;
    let port = free_udp_port();
    let mock = spawn(
        &format!("udpin:127.0.0.1:{port}"),
        mock_cfg,
        Faults {
            loss_percent,
            seed: 7,
            ..Faults::default()
        },
    )
    .await
    .unwrap();
    let mut cfg = LinkConfig::new(&format!("udpout:127.0.0.1:{port}"));
    cfg.system_id = link_sysid;
    cfg.ack_timeout = Duration::from_millis(300);
    cfg.attempts = 10;
    let link = VehicleLink::connect(cfg).await.unwrap();
    assert_eq!(
        link.wait_vehicle(Duration::from_secs(5)).await.unwrap(),
        flavor
    );
    (mock, link)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn px4_offboard_flight_failsafe_and_hold() {
    let (mock, link) = setup(Flavor::Px4, 0.0, 1).await;
    link.request_telemetry().await.unwrap();
    // The failsafe action: hold (5), an INT32 sent bytewise.
    link.param_set("COM_OBL_RC_ACT", 5.0, ParamType::Int32)
        .await
        .unwrap();
    assert_eq!(
        link.param_read("COM_OBL_RC_ACT").await.unwrap(),
        (5.0, ParamType::Int32)
    );
    assert_eq!(mock.with(|m| m.params().get("COM_OBL_RC_ACT", -1.0)), 5.0);

    link.take_off(5.0, Duration::from_secs(15)).await.unwrap();
    assert_eq!(link.state().mode, Some(Mode::Offboard));
    for (x, y) in [(10.0, 0.0), (10.0, 10.0), (-5.0, 5.0)] {
        fly_to(&link, x, y, 5.0).await;
    }
    // ENU east 10 is NED y = 10 on the vehicle's side: the frames agree end to end.
    let mut rx = link.events();
    link.pause_setpoints(true);
    expect_failsafe(&link, &mut rx, Mode::Hold).await;
    assert!(mock.take_events().iter().any(|e| matches!(
        e,
        MockEvent::Failsafe {
            mode: Mode::Hold,
            ..
        }
    )));
    // Setpoints resume: PX4 returns to OFFBOARD by itself; then a clean stop holds.
    link.pause_setpoints(false);
    link.wait_for(
        |s| s.mode == Some(Mode::Offboard),
        "offboard again",
        Duration::from_secs(5),
    )
    .await
    .unwrap();
    link.hold().await.unwrap();
    assert_eq!(mock.with(|m| m.mode()), Mode::Hold);
}

/// A mock whose failsafe holds the mode for `locked_s` after boot.
fn mode_locked_for(flavor: Flavor, locked_s: f64) -> MockConfig {
    let mut cfg = MockConfig::new(flavor);
    cfg.mode_locked_until_s = locked_s;
    cfg
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_takeoff_waits_out_a_mode_change_rejected_as_temporary() {
    // PX4 SIH answered DO_SET_MODE TEMPORARILY_REJECTED while a failsafe held: the
    // takeoff tries again until the failsafe clears, for both flavours.
    for flavor in [Flavor::Px4, Flavor::ArduPilot] {
        let (mock, link) = setup_with(mode_locked_for(flavor, 4.0), 0.0, 1).await;
        link.request_telemetry().await.unwrap();
        link.take_off(5.0, Duration::from_secs(20))
            .await
            .unwrap_or_else(|e| panic!("{flavor}: {e}"));
        assert!(mock.with(|m| m.armed()), "{flavor}");
        assert_eq!(
            link.state().mode,
            Some(Mode::companion_for(flavor)),
            "{flavor}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mode_change_still_rejected_when_the_time_is_up_names_the_vehicles_reason() {
    let (mock, link) = setup_with(mode_locked_for(Flavor::Px4, 1e6), 0.0, 1).await;
    link.request_telemetry().await.unwrap();
    let e = link
        .take_off(5.0, Duration::from_secs(3))
        .await
        .expect_err("the failsafe never clears");
    let said = e.to_string();
    assert!(
        matches!(
            e,
            LinkError::ModeRejected {
                mode: Mode::Offboard,
                ..
            }
        ),
        "{said}"
    );
    assert!(said.contains("Failsafe: mode change rejected"), "{said}");
    assert!(!mock.with(|m| m.armed()));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ardupilot_guided_flight_and_gcs_failsafe() {
    // As the GCS (system 255): its heartbeats are the ones ArduPilot's GCS failsafe counts.
    let (mock, link) = setup(Flavor::ArduPilot, 0.0, 255).await;
    link.request_telemetry().await.unwrap();
    link.param_set("FS_GCS_ENABLE", 1.0, ParamType::Int8)
        .await
        .unwrap();
    link.param_set("FS_GCS_TIMEOUT", 2.0, ParamType::Real32)
        .await
        .unwrap();
    link.take_off(5.0, Duration::from_secs(15)).await.unwrap();
    assert_eq!(link.state().mode, Some(Mode::Guided));
    assert!(
        mock.take_events().is_empty(),
        "the takeoff was not cancelled"
    );
    for (x, y) in [(8.0, 0.0), (8.0, 8.0), (0.0, 4.0)] {
        fly_to(&link, x, y, 5.0).await;
    }
    let mut rx = link.events();
    link.pause_setpoints(true);
    link.pause_heartbeat(true);
    expect_failsafe(&link, &mut rx, Mode::ReturnToLaunch).await;
    link.pause_heartbeat(false);
    link.hold().await.unwrap();
    assert_eq!(mock.with(|m| m.mode()), Mode::Brake);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_takeoff_the_pilot_interrupts_stops_at_once_and_says_why() {
    for flavor in [Flavor::Px4, Flavor::ArduPilot] {
        // The pilot takes the vehicle (POSCTL / LOITER) once it climbs: infotrack gives up
        // the takeoff instead of waiting out its timeout or switching back.
        let (mock, link) = setup(flavor, 0.0, 1).await;
        link.request_telemetry().await.unwrap();
        let takes_it = async {
            // Once infotrack has seen the climb begin.
            while link.position_enu().is_none_or(|p| p.z_up_m < 1.0) {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            mock.with(|m| m.pilot_switch(Mode::Position)).unwrap();
        };
        let began = std::time::Instant::now();
        let (taken_off, ()) = tokio::join!(link.take_off(30.0, Duration::from_secs(60)), takes_it);
        let err = taken_off.unwrap_err().to_string();
        assert!(began.elapsed() < Duration::from_secs(10), "{err}");
        let climb = if flavor == Flavor::Px4 {
            "OFFBOARD"
        } else {
            "GUIDED"
        };
        assert!(
            err.starts_with("takeoff abandoned: the vehicle left")
                && err.contains(climb)
                && err.contains("m up"),
            "{flavor:?}: {err}"
        );
        assert_eq!(mock.with(|m| m.mode()), Mode::Position, "{flavor:?}");

        // The arm switch (or an auto-disarm) on the ground, before the vehicle leaves it.
        let (mock, link) = setup(flavor, 0.0, 1).await;
        link.request_telemetry().await.unwrap();
        // A vehicle that does not climb (its climb speed set to 0) stays on the ground.
        let climb_speed = if flavor == Flavor::Px4 {
            "MPC_Z_VEL_MAX_UP"
        } else {
            "WPNAV_SPEED_UP"
        };
        link.param_set(climb_speed, 0.0, ParamType::Real32)
            .await
            .unwrap();
        let disarms = async {
            // Once infotrack has seen it armed (the heartbeat comes at 1 Hz).
            while !link.state().armed {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            tokio::time::sleep(Duration::from_millis(300)).await;
            mock.with(|m| m.pilot_disarm()).unwrap();
        };
        let (taken_off, ()) = tokio::join!(link.take_off(30.0, Duration::from_secs(60)), disarms);
        let err = taken_off.unwrap_err().to_string();
        assert!(
            err.starts_with("takeoff abandoned: the vehicle disarmed during the climb to 30 m"),
            "{flavor:?}: {err}"
        );
    }
}

/// A clean stop on PX4 holds at the altitude infotrack was flying, not at the height of the
/// moment of the switch (AUTO.LOITER's own): here the stop comes mid-climb from 4 m to 9 m,
/// and the hold goes on to 9 m over its stopping point (MAV_CMD_DO_CHANGE_ALTITUDE, as PX4
/// SIH takes it). ArduPilot's BRAKE stops where it is, as before.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_px4_stop_mid_climb_holds_at_the_altitude_flown() {
    for flavor in [Flavor::Px4, Flavor::ArduPilot] {
        let (mock, link) = setup(flavor, 0.0, 1).await;
        link.request_telemetry().await.unwrap();
        link.take_off(4.0, Duration::from_secs(20)).await.unwrap();
        fly_to(&link, 3.0, 2.0, 4.0).await;
        let p = PositionEnu {
            x_east_m: 3.0,
            y_north_m: 2.0,
            z_up_m: 9.0,
        };
        link.set_setpoint(p, 0.0).unwrap();
        link.wait_for(
            |s| s.local_ned.is_some_and(|(_, n, _)| -n.z_down_m > 5.0),
            "the climb under way",
            Duration::from_secs(10),
        )
        .await
        .unwrap();
        link.hold().await.unwrap();
        let at_switch_m = link.position_enu().unwrap().z_up_m;
        tokio::time::sleep(Duration::from_secs(6)).await;
        let held_m = -mock.with(|m| m.position_ned_m()[2]);
        assert_eq!(mock.with(|m| m.mode()), Mode::hold_for(flavor));
        if flavor == Flavor::Px4 {
            assert!(
                (held_m - 9.0).abs() < 0.3,
                "held at {held_m:.2} m, switched at {at_switch_m:.2} m"
            );
        } else {
            assert!(
                held_m < 8.0,
                "{flavor:?}: BRAKE climbed on to {held_m:.2} m"
            );
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn thirty_percent_packet_loss_still_completes_the_sequence() {
    for flavor in [Flavor::Px4, Flavor::ArduPilot] {
        let (_mock, link) = setup(flavor, 30.0, 1).await;
        link.request_telemetry().await.unwrap();
        link.take_off(4.0, Duration::from_secs(20)).await.unwrap();
        fly_to(&link, 6.0, -3.0, 4.0).await;
        link.hold().await.unwrap();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vehicle_that_never_answers_is_a_timeout_not_a_hang() {
    let port = free_udp_port();
    let link = VehicleLink::connect(LinkConfig::new(&format!("udpout:127.0.0.1:{port}")))
        .await
        .unwrap();
    let err = link
        .wait_vehicle(Duration::from_millis(600))
        .await
        .unwrap_err()
        .to_string();
    assert!(err.contains("no autopilot heartbeat"), "{err}");
    let err = VehicleLink::connect(LinkConfig::new("udp:nowhere:14550"))
        .await
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("unknown scheme"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn setpoints_outside_the_geofence_are_refused() {
    let port = free_udp_port();
    let mut cfg = LinkConfig::new(&format!("udpout:127.0.0.1:{port}"));
    cfg.geofence_enu = Some(infotrack::world::geometry::BoundsEnu {
        x_min_m: -10.0,
        x_max_m: 10.0,
        y_min_m: -10.0,
        y_max_m: 10.0,
    });
    let link = VehicleLink::connect(cfg).await.unwrap();
    let p = PositionEnu {
        x_east_m: 11.0,
        y_north_m: 0.0,
        z_up_m: 5.0,
    };
    assert!(link.set_setpoint(p, 0.0).is_err());
}

/// A setpoint with a NaN anywhere (position, velocity, the heading the view asks for) is
/// refused, with or without a geofence, and a finite one is accepted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn non_finite_setpoints_are_refused() {
    let port = free_udp_port();
    let link = VehicleLink::connect(LinkConfig::new(&format!("udpout:127.0.0.1:{port}")))
        .await
        .unwrap();
    let p = PositionEnu {
        x_east_m: 1.0,
        y_north_m: 2.0,
        z_up_m: 5.0,
    };
    let v = infotrack::world::geometry::Enu2::new(1.0, 0.0);
    assert!(link.set_moving_setpoint(p, v, 0.3).is_ok());
    assert!(link.set_moving_setpoint(p, v, f64::NAN).is_err());
    let nan_v = infotrack::world::geometry::Enu2::new(f64::NAN, 0.0);
    assert!(link.set_moving_setpoint(p, nan_v, 0.3).is_err());
    let nan_p = PositionEnu {
        x_east_m: f64::NAN,
        ..p
    };
    let e = link.set_setpoint(nan_p, 0.3).unwrap_err().to_string();
    assert!(e.contains("non-finite"), "{e}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unknown_parameters_are_reported() {
    let (_mock, link) = setup(Flavor::Px4, 0.0, 1).await;
    let err = link
        .param_read("NO_SUCH_PARAM")
        .await
        .unwrap_err()
        .to_string();
    assert!(err.contains("NO_SUCH_PARAM"), "{err}");
}
