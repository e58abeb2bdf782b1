//! The link's unit tests.

use super::*;

fn header(system_id: u8, component_id: u8) -> MavHeader {
    MavHeader {
        system_id: system_id as u32,
        component_id,
        sequence: 0,
    }
}

fn autopilot_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        ..Default::default()
    })
}

fn position(x: f32) -> MavMessage {
    MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        x,
        y: 2.0,
        z: -10.0,
        ..Default::default()
    })
}

fn feed(vehicle: Option<(u8, u8)>, msgs: &[(MavHeader, MavMessage)]) -> VehicleState {
    let state = Mutex::new(VehicleState::default());
    let (events, _) = broadcast::channel(64);
    let ids = Ids {
        me: (1, 191),
        vehicle,
    };
    for (h, m) in msgs {
        on_message(&state, &events, ids, h, m);
    }
    let s = state.lock().clone();
    s
}

/// The fault campaign's second vehicle (system 42 with heartbeats and a pose) is
/// ignored and reported once; the vehicle's pose is the one kept.
#[test]
fn the_link_locks_onto_the_first_autopilot_and_ignores_another() {
    let s = feed(
        None,
        &[
            (header(1, 1), autopilot_heartbeat()),
            (header(1, 1), position(5.0)),
            (header(42, 1), autopilot_heartbeat()),
            (header(42, 1), position(40.0)),
            (header(42, 1), autopilot_heartbeat()),
            // A component of the vehicle's own system that is not the autopilot.
            (header(1, 154), position(99.0)),
        ],
    );
    assert_eq!(s.address, Some((1, 1)));
    assert_eq!(s.local_ned.unwrap().1.x_north_m, 5.0);
    assert_eq!(
        s.ignored_autopilots.iter().copied().collect::<Vec<_>>(),
        vec![(42, 1)]
    );
    // A component of the vehicle's system that claims to be an autopilot, heard first,
    // gives way to the flight controller's component 1; system 42 never gets in.
    let s = feed(
        None,
        &[
            (header(1, 100), autopilot_heartbeat()),
            (header(42, 1), autopilot_heartbeat()),
            (header(1, 1), autopilot_heartbeat()),
            (header(1, 1), position(7.0)),
            (header(1, 100), autopilot_heartbeat()),
        ],
    );
    assert_eq!(s.address, Some((1, 1)));
    assert_eq!(s.local_ned.unwrap().1.x_north_m, 7.0);
    // Heard first, system 42 would have been the vehicle; configured, only system 5 is.
    let s = feed(
        Some((5, 1)),
        &[
            (header(42, 1), autopilot_heartbeat()),
            (header(42, 1), position(40.0)),
            (header(5, 1), autopilot_heartbeat()),
            (header(5, 1), position(6.0)),
        ],
    );
    assert_eq!(s.address, Some((5, 1)));
    assert_eq!(s.local_ned.unwrap().1.x_north_m, 6.0);
}

#[test]
fn telemetry_with_nan_or_inf_is_dropped_and_counted() {
    let attitude = |roll: f32| {
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            roll,
            ..Default::default()
        })
    };
    let s = feed(
        None,
        &[
            (header(1, 1), autopilot_heartbeat()),
            (header(1, 1), position(3.0)),
            (header(1, 1), position(f32::NAN)),
            (header(1, 1), position(f32::INFINITY)),
            (header(1, 1), attitude(0.1)),
            (header(1, 1), attitude(f32::NAN)),
        ],
    );
    assert_eq!(s.local_ned.unwrap().1.x_north_m, 3.0);
    assert_eq!(s.attitude.unwrap().1[0], 0.1);
    assert_eq!(s.non_finite_dropped, 3);
}

#[test]
fn urls_are_checked_with_a_reason() {
    for ok in [
        "udpin:0.0.0.0:14540",
        "udpout:127.0.0.1:14550",
        "tcpout:localhost:5760",
        "serial:/dev/ttyAMA0:921600",
        "file:flight/link.tlog",
    ] {
        assert!(check_url(ok).is_ok(), "{ok}");
    }
    for (bad, needle) in [
        ("udp:1.2.3.4:5", "unknown scheme"),
        ("udpin:0.0.0.0", "PORT"),
        ("udpin:0.0.0.0:99999", "not a number"),
        ("serial:/dev/ttyS0:fast", "baud"),
        ("14550", "SCHEME"),
        ("file:", "missing file path"),
    ] {
        let e = check_url(bad).unwrap_err();
        assert!(e.0.contains(needle), "{bad}: {e}");
    }
}

#[test]
fn position_target_is_local_ned_with_the_position_only_mask() {
    let p = PositionEnu {
        x_east_m: 3.0,
        y_north_m: 4.0,
        z_up_m: 10.0,
    };
    let MavMessage::SET_POSITION_TARGET_LOCAL_NED(m) =
        position_target((1, 1), p.to_ned(), [0.0; 3], 0.0, 0)
    else {
        unreachable!()
    };
    assert_eq!((m.x, m.y, m.z), (4.0, 3.0, -10.0));
    assert_eq!(m.coordinate_frame, MavFrame::MAV_FRAME_LOCAL_NED);
    // 3576 plus the yaw bit cleared: position + yaw given.
    assert_eq!(m.type_mask.bits(), 3576 & !1024);
}

#[test]
fn a_moving_target_sends_its_velocity_in_ned_with_the_position_velocity_mask() {
    // 2 m/s east, 1 m/s north in ENU is vx (north) 1, vy (east) 2 in NED.
    let v = PositionEnu::from_xy(&Enu2::new(2.0, 1.0), 0.0).to_ned();
    let p = PositionNed {
        x_north_m: 4.0,
        y_east_m: 3.0,
        z_down_m: -10.0,
    };
    let MavMessage::SET_POSITION_TARGET_LOCAL_NED(m) =
        position_target((1, 1), p, [v.x_north_m, v.y_east_m, 0.0], 0.0, 0)
    else {
        unreachable!()
    };
    assert_eq!((m.vx, m.vy, m.vz), (1.0, 2.0, 0.0));
    // 3520 (position + velocity) with yaw given.
    assert_eq!(m.type_mask.bits(), 3520 & !1024);
}

#[test]
fn a_moving_setpoint_advances_with_time_and_stops_at_the_geofence() {
    let t0 = Instant::now();
    let s = StreamedTarget {
        position_ned: PositionEnu::from_xy(&Enu2::new(0.0, 0.0), 10.0).to_ned(),
        velocity_ned: [0.0, 5.0, 0.0],
        yaw_ned: 0.0,
        since: t0,
    };
    let fence = BoundsEnu {
        x_min_m: -10.0,
        x_max_m: 12.0,
        y_min_m: -10.0,
        y_max_m: 10.0,
    };
    let (p, v) = s.at(t0 + Duration::from_secs(2), Some(&fence));
    assert_eq!(p.to_enu().xy(), Enu2::new(10.0, 0.0));
    assert_eq!(v, [0.0, 5.0, 0.0]);
    let (p, v) = s.at(t0 + Duration::from_secs(3), Some(&fence));
    assert_eq!(
        p.to_enu().xy(),
        Enu2::new(12.0, 0.0),
        "stopped at the fence"
    );
    assert_eq!(v, [0.0; 3]);
}
