use super::*;
use infotrack_link::params_file::ParamType;

const GCS: MavHeader = MavHeader {
    system_id: 255,
    component_id: 191,
    sequence: 0,
};

fn cmd(command: MavCmd, p: [f32; 7]) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        command,
        target_system: 1,
        target_component: 1,
        confirmation: 0,
    })
}

fn ack_of(out: &[MavMessage]) -> MavResult {
    out.iter()
        .find_map(|m| match m {
            MavMessage::COMMAND_ACK(a) => Some(a.result),
            _ => None,
        })
        .expect("a COMMAND_ACK")
}

fn setpoint(ned: [f32; 3]) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        x: ned[0],
        y: ned[1],
        z: ned[2],
        type_mask: PositionTargetTypemask::from_bits_truncate(3576),
        target_system: 1,
        target_component: 1,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        ..Default::default()
    })
}

fn set_mode(m: &mut MockAutopilot, t: f64, mode: Mode) -> MavResult {
    let (p2, p3) = mode.do_set_mode_params(m.flavor()).unwrap();
    ack_of(&m.handle(
        t,
        &GCS,
        &cmd(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, p2, p3, 0.0, 0.0, 0.0, 0.0],
        ),
    ))
}

fn arm(m: &mut MockAutopilot, t: f64) -> MavResult {
    ack_of(&m.handle(
        t,
        &GCS,
        &cmd(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
    ))
}

/// Streams a setpoint at 20 Hz from t0 to t1 and ticks the vehicle.
fn stream(m: &mut MockAutopilot, t0: f64, t1: f64, sp: Option<[f32; 3]>) -> f64 {
    let mut t = t0;
    while t < t1 {
        t += 0.05;
        if let Some(p) = sp {
            m.handle(t, &GCS, &setpoint(p));
        }
        m.tick(t);
    }
    t
}

#[test]
fn px4_refuses_offboard_without_setpoints_then_flies_offboard() {
    let mut m = MockAutopilot::new(MockConfig::new(Flavor::Px4), 0.0);
    assert_eq!(
        set_mode(&mut m, 0.1, Mode::Offboard),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    let t = stream(&mut m, 0.1, 1.5, Some([5.0, 3.0, -10.0]));
    assert_eq!(
        set_mode(&mut m, t, Mode::Offboard),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(arm(&mut m, t), MavResult::MAV_RESULT_ACCEPTED);
    let t = stream(&mut m, t, t + 15.0, Some([5.0, 3.0, -10.0]));
    let p = m.position_ned_m();
    assert!(
        (p[0] - 5.0).abs() < 0.2 && (p[1] - 3.0).abs() < 0.2 && (p[2] + 10.0).abs() < 0.2,
        "{p:?} at {t}"
    );
}

#[test]
fn arming_is_refused_until_the_estimator_is_ready() {
    let mut cfg = MockConfig::new(Flavor::ArduPilot);
    cfg.estimator_ready_after_s = 5.0;
    let mut m = MockAutopilot::new(cfg, 0.0);
    assert_eq!(arm(&mut m, 1.0), MavResult::MAV_RESULT_FAILED);
    m.tick(6.0);
    assert_eq!(arm(&mut m, 6.0), MavResult::MAV_RESULT_ACCEPTED);
}

#[test]
fn a_failsafe_that_holds_the_mode_rejects_changes_temporarily_until_it_clears() {
    let mut cfg = MockConfig::new(Flavor::Px4);
    cfg.mode_locked_until_s = 4.0;
    let mut m = MockAutopilot::new(cfg, 0.0);
    let before = m.mode();
    let t = stream(&mut m, 0.0, 1.5, Some([0.0, 0.0, -5.0]));
    assert_eq!(
        set_mode(&mut m, t, Mode::Offboard),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert_eq!(m.mode(), before);
    let t = stream(&mut m, t, 4.5, Some([0.0, 0.0, -5.0]));
    assert_eq!(
        set_mode(&mut m, t, Mode::Offboard),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(m.mode(), Mode::Offboard);
}

#[test]
fn ardupilot_resets_a_mode_set_during_its_startup_and_refuses_to_arm_before() {
    let mut cfg = MockConfig::new(Flavor::ArduPilot);
    cfg.startup_s = 2.2;
    let mut m = MockAutopilot::new(cfg, 0.0);
    m.tick(0.5);
    assert_eq!(m.mode(), Mode::Stabilized);
    set_mode(&mut m, 1.0, Mode::Guided);
    assert_eq!(m.mode(), Mode::Guided);
    assert_eq!(arm(&mut m, 1.1), MavResult::MAV_RESULT_FAILED);
    let said = m.tick(2.3);
    assert_eq!(m.mode(), Mode::Stabilized);
    assert!(said.iter().any(
        |msg| matches!(msg, MavMessage::STATUSTEXT(t) if t.text.starts_with(b"ArduPilot Ready"))
    ));
    // Once started a mode sticks and arming goes on to the estimator's checks.
    set_mode(&mut m, 2.5, Mode::Guided);
    m.tick(5.0);
    assert_eq!(m.mode(), Mode::Guided);
    assert_eq!(arm(&mut m, 5.0), MavResult::MAV_RESULT_ACCEPTED);
}

#[test]
fn px4_offboard_loss_switches_to_the_configured_action_and_back() {
    let mut cfg = MockConfig::new(Flavor::Px4);
    cfg.param_overrides = vec![("COM_OBL_RC_ACT".into(), 5.0)];
    let mut m = MockAutopilot::new(cfg, 0.0);
    let t = stream(&mut m, 0.0, 1.5, Some([0.0, 0.0, -5.0]));
    set_mode(&mut m, t, Mode::Offboard);
    arm(&mut m, t);
    let t = stream(&mut m, t, t + 5.0, Some([0.0, 0.0, -5.0]));
    // Stream stops: after COM_OF_LOSS_T (1 s) the vehicle holds.
    let t = stream(&mut m, t, t + 0.8, None);
    assert_eq!(m.mode(), Mode::Offboard);
    let t = stream(&mut m, t, t + 0.5, None);
    assert_eq!(m.mode(), Mode::Hold);
    assert!(matches!(
        m.take_events().as_slice(),
        [MockEvent::Failsafe {
            mode: Mode::Hold,
            ..
        }]
    ));
    // Setpoints resume: back to OFFBOARD by itself.
    stream(&mut m, t, t + 0.2, Some([0.0, 0.0, -5.0]));
    assert_eq!(m.mode(), Mode::Offboard);
}

#[test]
fn ardupilot_position_target_during_takeoff_cancels_it() {
    let mut m = MockAutopilot::new(MockConfig::new(Flavor::ArduPilot), 0.0);
    set_mode(&mut m, 0.0, Mode::Guided);
    arm(&mut m, 0.0);
    let r = ack_of(&m.handle(
        0.0,
        &GCS,
        &cmd(
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0],
        ),
    ));
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    let t = stream(&mut m, 0.0, 1.0, None);
    m.handle(t, &GCS, &setpoint([10.0, 0.0, -10.0]));
    assert_eq!(m.take_events(), vec![MockEvent::TakeoffCancelled]);
    stream(&mut m, t, t + 10.0, None);
    assert!(m.position_ned_m()[2] > -0.1, "back on the ground");
}

#[test]
fn ardupilot_takeoff_then_guided_targets() {
    let mut m = MockAutopilot::new(MockConfig::new(Flavor::ArduPilot), 0.0);
    // Targets are ignored outside GUIDED.
    m.handle(0.0, &GCS, &setpoint([10.0, 0.0, -10.0]));
    set_mode(&mut m, 0.0, Mode::Guided);
    arm(&mut m, 0.0);
    m.handle(
        0.0,
        &GCS,
        &cmd(
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0],
        ),
    );
    let t = stream(&mut m, 0.0, 8.0, None);
    assert!(m.position_ned_m()[2] < -9.5);
    stream(&mut m, t, t + 12.0, Some([10.0, -5.0, -10.0]));
    let p = m.position_ned_m();
    assert!(
        (p[0] - 10.0).abs() < 0.3 && (p[1] + 5.0).abs() < 0.3,
        "{p:?}"
    );
}

/// A takeoff to a field altitude answers as SITL: ArduCopter SITL climbed to 45 m at
/// ~2.5 m/s (WPNAV_SPEED_UP), so each flavour's calibrated mock reaches 95 % of 45 m within
/// about 45 / 2.5 = 18 s of climbing (the firmware's climb limit; PX4's MPC_Z_VEL_MAX_UP is
/// 3 m/s), not at the slow rate the probe's 1.2 m takeoff shows.
#[test]
fn a_takeoff_to_a_field_altitude_climbs_at_the_firmwares_limit() {
    for flavor in [Flavor::ArduPilot, Flavor::Px4] {
        let mut cfg = MockConfig::new(flavor);
        cfg.answer_as_sitl();
        cfg.startup_s = 0.0;
        let mut m = MockAutopilot::new(cfg, 0.0);
        let up = [0.0, 0.0, -45.0];
        let t = match flavor {
            Flavor::Px4 => {
                let t = stream(&mut m, 0.0, 1.5, Some(up));
                set_mode(&mut m, t, Mode::Offboard);
                t
            }
            Flavor::ArduPilot => {
                set_mode(&mut m, 0.0, Mode::Guided);
                0.0
            }
        };
        assert_eq!(arm(&mut m, t), MavResult::MAV_RESULT_ACCEPTED, "{flavor:?}");
        if flavor == Flavor::ArduPilot {
            m.handle(
                t,
                &GCS,
                &cmd(
                    MavCmd::MAV_CMD_NAV_TAKEOFF,
                    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 45.0],
                ),
            );
        }
        let sp = (flavor == Flavor::Px4).then_some(up);
        let mut now = t;
        while -m.position_ned_m()[2] < 0.95 * 45.0 && now < t + 60.0 {
            now = stream(&mut m, now, now + 0.5, sp);
        }
        let took = now - t;
        assert!(
            (15.0..30.0).contains(&took),
            "{flavor:?}: 95 % of 45 m after {took:.1} s"
        );
    }
}

/// An ArduPilot mock with FS_GCS_ENABLE = 1, armed in GUIDED; its heartbeat, and the
/// companion's header (system 1, component 191), whose heartbeats the failsafe ignores.
fn armed_in_guided_with_gcs_failsafe() -> (MockAutopilot, MavMessage, MavHeader) {
    let mut cfg = MockConfig::new(Flavor::ArduPilot);
    cfg.param_overrides = vec![("FS_GCS_ENABLE".into(), 1.0)];
    let mut m = MockAutopilot::new(cfg, 0.0);
    set_mode(&mut m, 0.0, Mode::Guided);
    arm(&mut m, 0.0);
    let hb = m.heartbeat();
    let companion = MavHeader {
        system_id: 1,
        component_id: 191,
        sequence: 0,
    };
    (m, hb, companion)
}

/// As ArduCopter SITL did with FS_GCS_ENABLE = 1 from boot: no GCS ever heard, no GCS
/// failsafe (the companion flies on).
#[test]
fn ardupilot_gcs_failsafe_waits_for_a_gcs_to_be_heard() {
    let (mut m, hb, companion) = armed_in_guided_with_gcs_failsafe();
    let mut t = 0.0;
    while t < 30.0 {
        t += 0.5;
        m.handle(t, &companion, &hb);
        m.tick(t);
    }
    assert_eq!(m.mode(), Mode::Guided);
    assert!(m.take_events().is_empty());
}

#[test]
fn ardupilot_gcs_failsafe_counts_only_gcs_heartbeats() {
    let (mut m, hb, companion) = armed_in_guided_with_gcs_failsafe();
    let mut t = 0.0;
    while t < 4.0 {
        t += 0.5;
        m.handle(t, &GCS, &hb);
        m.handle(t, &companion, &hb);
        m.tick(t);
    }
    assert_eq!(m.mode(), Mode::Guided);
    // Only the companion's heartbeats from now on: they do not count.
    while t < 10.0 {
        t += 0.5;
        m.handle(t, &companion, &hb);
        m.tick(t);
    }
    // RTL; already over home on the ground, so it lands at once.
    let events = m.take_events();
    assert!(
        matches!(
            events.as_slice(),
            [MockEvent::Failsafe {
                mode: Mode::ReturnToLaunch,
                ..
            }]
        ),
        "{events:?}"
    );
    assert!(matches!(m.mode(), Mode::ReturnToLaunch | Mode::Land));
}

#[test]
fn set_message_interval_changes_the_stream() {
    let mut m = MockAutopilot::new(MockConfig::new(Flavor::ArduPilot), 0.0);
    let count = |m: &mut MockAutopilot, t0: f64| {
        let mut n = 0;
        let mut t = t0;
        for _ in 0..100 {
            t += 0.01;
            n += m
                .tick(t)
                .iter()
                .filter(|x| matches!(x, MavMessage::LOCAL_POSITION_NED(_)))
                .count();
        }
        n
    };
    assert_eq!(
        count(&mut m, 0.0),
        0,
        "ArduPilot streams nothing but HEARTBEAT until asked"
    );
    let r = ack_of(&m.handle(
        1.0,
        &GCS,
        &cmd(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [32.0, 50_000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
    ));
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    let n = count(&mut m, 1.0);
    assert!((19..=21).contains(&n), "20 Hz for 1 s: {n}");
}

#[test]
fn parameters_travel_with_each_firmwares_encoding() {
    let mut m = MockAutopilot::new(MockConfig::new(Flavor::Px4), 0.0);
    let set = MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: encode_wire(Flavor::Px4, ParamType::Int32, 5.0),
        target_system: 1,
        target_component: 1,
        param_id: "COM_OBL_RC_ACT".into(),
        param_type: MavParamType::MAV_PARAM_TYPE_INT32,
    });
    let out = m.handle(0.0, &GCS, &set);
    let MavMessage::PARAM_VALUE(v) = &out[0] else {
        panic!("{out:?}")
    };
    assert_eq!(v.param_value.to_bits(), 5);
    assert_eq!(m.params().get("COM_OBL_RC_ACT", -1.0), 5.0);
    let list = m.handle(
        0.0,
        &GCS,
        &MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 1,
        }),
    );
    assert_eq!(list.len(), m.params().len());
    let MavMessage::PARAM_VALUE(first) = &list[0] else {
        panic!()
    };
    assert_eq!(param_id_str(&first.param_id), "_HASH_CHECK");

    let mut a = MockAutopilot::new(MockConfig::new(Flavor::ArduPilot), 0.0);
    let read = MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
        param_index: -1,
        target_system: 1,
        target_component: 1,
        param_id: "WPNAV_SPEED".into(),
    });
    let out = a.handle(0.0, &GCS, &read);
    let MavMessage::PARAM_VALUE(v) = &out[0] else {
        panic!()
    };
    assert_eq!((v.param_value, v.param_index), (1000.0, u16::MAX));
}

#[test]
fn px4_geofence_breach_fires_gf_action_once() {
    let mut cfg = MockConfig::new(Flavor::Px4);
    cfg.param_overrides = vec![("GF_MAX_HOR_DIST".into(), 20.0), ("GF_ACTION".into(), 3.0)];
    let mut m = MockAutopilot::new(cfg, 0.0);
    let t = stream(&mut m, 0.0, 1.5, Some([0.0, 0.0, -5.0]));
    set_mode(&mut m, t, Mode::Offboard);
    arm(&mut m, t);
    // Inside the 20 m fence: nothing happens.
    let t = stream(&mut m, t, t + 10.0, Some([15.0, 0.0, -5.0]));
    assert_eq!(m.mode(), Mode::Offboard);
    assert!(m.take_events().is_empty());
    // A setpoint 40 m out: the vehicle crosses 20 m and returns (GF_ACTION 3).
    stream(&mut m, t, t + 15.0, Some([40.0, 0.0, -5.0]));
    let events = m.take_events();
    assert_eq!(
        events,
        vec![MockEvent::Failsafe {
            reason: "geofence breached".into(),
            mode: Mode::ReturnToLaunch
        }]
    );
    let p = m.position_ned_m();
    assert!(p[0].hypot(p[1]) < 21.0, "flew on past the fence: {p:?}");
}

#[test]
fn ardupilot_fence_off_by_default_and_circle_when_enabled() {
    for (enable, want) in [(0.0, None), (1.0, Some(Mode::Brake))] {
        let mut cfg = MockConfig::new(Flavor::ArduPilot);
        cfg.param_overrides = vec![
            ("FENCE_ENABLE".into(), enable),
            ("FENCE_TYPE".into(), 2.0),
            ("FENCE_RADIUS".into(), 30.0),
            ("FENCE_ACTION".into(), 4.0),
        ];
        let mut m = MockAutopilot::new(cfg, 0.0);
        set_mode(&mut m, 0.1, Mode::Guided);
        arm(&mut m, 0.1);
        m.handle(
            0.2,
            &GCS,
            &cmd(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 5.0],
            ),
        );
        let t = stream(&mut m, 0.2, 6.0, None);
        stream(&mut m, t, t + 20.0, Some([0.0, 50.0, -5.0]));
        let fired: Vec<Mode> = m
            .take_events()
            .into_iter()
            .filter_map(|e| match e {
                MockEvent::Failsafe { mode, .. } => Some(mode),
                _ => None,
            })
            .collect();
        assert_eq!(
            fired,
            want.into_iter().collect::<Vec<_>>(),
            "FENCE_ENABLE {enable}"
        );
    }
}

#[test]
fn reboot_keeps_parameters_and_forgets_the_flight() {
    let mut m = MockAutopilot::new(MockConfig::new(Flavor::Px4), 0.0);
    let t = stream(&mut m, 0.0, 1.5, Some([0.0, 0.0, -5.0]));
    set_mode(&mut m, t, Mode::Offboard);
    arm(&mut m, t);
    let t = stream(&mut m, t, t + 5.0, Some([0.0, 0.0, -5.0]));
    let value = 7.5;
    assert!(m.params.set("MPC_XY_CRUISE", value));
    m.reboot(t + 2.0);
    assert!(!m.armed());
    assert_eq!(m.mode(), Mode::Position);
    assert_eq!(m.position_ned_m(), [0.0; 3]);
    assert_eq!(m.params().get("MPC_XY_CRUISE", -1.0), value);
    // The boot clock restarts: telemetry time stamps start again from zero.
    let out = m.tick(t + 2.5);
    let boot_ms = out.iter().find_map(|x| match x {
        MavMessage::ATTITUDE(a) => Some(a.time_boot_ms),
        _ => None,
    });
    assert_eq!(boot_ms, Some(500));
}

/// Streams a target moving at `v_ned` (position + velocity mask 3520) at 20 Hz, as the link
/// does, and returns how far the vehicle trails it at the end.
fn follow_moving_target(m: &mut MockAutopilot, t0: f64, secs: f64, v_ned: [f32; 2]) -> f64 {
    let start = m.position_ned_m();
    let mut t = t0;
    let mut target = [0.0f32; 2];
    while t < t0 + secs {
        t += 0.05;
        let dt = (t - t0) as f32;
        target = [
            start[0] as f32 + v_ned[0] * dt,
            start[1] as f32 + v_ned[1] * dt,
        ];
        m.handle(
            t,
            &GCS,
            &MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
                x: target[0],
                y: target[1],
                z: -10.0,
                vx: v_ned[0],
                vy: v_ned[1],
                vz: 0.0,
                type_mask: PositionTargetTypemask::from_bits_truncate(3520),
                target_system: 1,
                target_component: 1,
                coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
                ..Default::default()
            }),
        );
        m.tick(t);
    }
    let p = m.position_ned_m();
    ((p[0] - target[0] as f64).powi(2) + (p[1] - target[1] as f64).powi(2)).sqrt()
}

#[test]
fn both_flavours_honour_the_velocity_feed_forward_of_a_moving_target() {
    for flavor in [Flavor::Px4, Flavor::ArduPilot] {
        let mut m = MockAutopilot::new(MockConfig::new(flavor), 0.0);
        let t = match flavor {
            Flavor::Px4 => {
                let t = stream(&mut m, 0.0, 1.5, Some([0.0, 0.0, -10.0]));
                set_mode(&mut m, t, Mode::Offboard);
                arm(&mut m, t);
                stream(&mut m, t, t + 15.0, Some([0.0, 0.0, -10.0]))
            }
            Flavor::ArduPilot => {
                set_mode(&mut m, 0.0, Mode::Guided);
                arm(&mut m, 0.0);
                m.handle(
                    0.0,
                    &GCS,
                    &cmd(
                        MavCmd::MAV_CMD_NAV_TAKEOFF,
                        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0],
                    ),
                );
                stream(&mut m, 0.0, 10.0, None)
            }
        };
        // 4 m/s north-east: with the feed-forward the vehicle rides on the target; the same
        // targets sent as position only leave it trailing by speed / gain.
        let trail = follow_moving_target(&mut m, t, 20.0, [4.0, 3.0]);
        assert!(trail < 0.5, "{flavor}: trails a moving target by {trail} m");
    }
}

/// The fault campaign's mock rows: ARM with param1 NaN and SET_MESSAGE_INTERVAL with NaN were
/// accepted, a NaN setpoint was "unsupported frame or type". Now refused with the reason.
#[test]
fn commands_with_non_finite_parameters_are_refused_with_the_reason() {
    let texts = |out: &[MavMessage]| -> String {
        out.iter()
            .filter_map(|m| match m {
                MavMessage::STATUSTEXT(t) => Some(t.text.to_str().unwrap_or("").to_string()),
                _ => None,
            })
            .collect()
    };
    for flavor in [Flavor::Px4, Flavor::ArduPilot] {
        let mut m = MockAutopilot::new(MockConfig::new(flavor), 0.0);
        m.tick(60.0);
        let arm_nan = cmd(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        let out = m.handle(60.0, &GCS, &arm_nan);
        assert_ne!(ack_of(&out), MavResult::MAV_RESULT_ACCEPTED, "{flavor:?}");
        assert!(texts(&out).contains("neither 0 nor 1"), "{}", texts(&out));
        assert!(!m.armed());
        let interval = cmd(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [f32::NAN, 1e5, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        let out = m.handle(60.0, &GCS, &interval);
        assert_eq!(ack_of(&out), MavResult::MAV_RESULT_DENIED, "{flavor:?}");
        assert!(texts(&out).contains("message id"), "{}", texts(&out));
        let out = m.handle(60.0, &GCS, &setpoint([f32::NAN, 0.0, -5.0]));
        assert!(
            texts(&out).contains("non-finite position"),
            "{}",
            texts(&out)
        );
        assert_eq!(
            arm(&mut m, 60.0),
            MavResult::MAV_RESULT_ACCEPTED,
            "{flavor:?}"
        );
    }
}

/// A landing vehicle disarms its land detector's delay after touching down (PX4 2 s,
/// ArduCopter ~1 s), not at the instant: a client that reads the landed state when it sees
/// the disarm reads ON_GROUND (MAVSDK's own test flight failed on the instant disarm when
/// the heartbeat overtook EXTENDED_SYS_STATE).
#[test]
fn a_landing_vehicle_disarms_a_moment_after_touchdown() {
    for (flavor, delay_s) in [(Flavor::Px4, 2.0), (Flavor::ArduPilot, 1.0)] {
        let mut m = MockAutopilot::new(MockConfig::new(flavor), 0.0);
        let mut t = stream(&mut m, 60.0, 61.5, Some([0.0, 0.0, -3.0]));
        let flying = if flavor == Flavor::Px4 {
            Mode::Offboard
        } else {
            Mode::Guided
        };
        set_mode(&mut m, t, flying);
        arm(&mut m, t);
        t = stream(&mut m, t, t + 10.0, Some([0.0, 0.0, -3.0]));
        assert!(m.position_ned_m()[2] < -2.5, "{flavor:?} did not climb");
        assert_eq!(
            set_mode(&mut m, t, Mode::Land),
            MavResult::MAV_RESULT_ACCEPTED
        );
        while m.position_ned_m()[2] < -0.05 && t < 200.0 {
            t = stream(&mut m, t, t + 0.05, None);
        }
        let touchdown = t;
        assert!(m.armed(), "{flavor:?} disarmed at the touchdown");
        t = stream(&mut m, t, touchdown + delay_s - 0.3, None);
        assert!(
            m.armed(),
            "{flavor:?} disarmed {:.2} s after touchdown",
            t - touchdown
        );
        stream(&mut m, t, touchdown + delay_s + 0.3, None);
        assert!(
            !m.armed(),
            "{flavor:?} still armed {:.2} s after touchdown",
            delay_s + 0.3
        );
    }
}

/// A position target's yaw is turned to at the firmware's auto yaw rate, not at once (PX4
/// MPC_YAWRAUTO_MAX 45 deg/s; ArduCopter ATC_SLEW_YAW 60 deg/s): the companion's model of
/// the camera's view must follow the heading the vehicle reports, not the one it asked for.
#[test]
fn a_setpoint_yaw_is_turned_to_at_the_auto_yaw_rate() {
    let mut m = MockAutopilot::new(MockConfig::new(Flavor::Px4), 0.0);
    let t = stream(&mut m, 0.1, 1.5, Some([0.0, 0.0, -10.0]));
    assert_eq!(
        set_mode(&mut m, t, Mode::Offboard),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(arm(&mut m, t), MavResult::MAV_RESULT_ACCEPTED);
    let mut t = stream(&mut m, t, t + 8.0, Some([0.0, 0.0, -10.0]));
    assert_eq!(m.yaw_ned_rad, 0.0);
    let turn = MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        z: -10.0,
        yaw: 1.5,
        // Position and yaw (3576 less YAW_IGNORE).
        type_mask: PositionTargetTypemask::from_bits_truncate(2552),
        target_system: 1,
        target_component: 1,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        ..Default::default()
    });
    let started = t;
    while t < started + 1.0 - 1e-9 {
        t += 0.05;
        m.handle(t, &GCS, &turn);
        m.tick(t);
    }
    let after_1s = m.yaw_ned_rad;
    assert!((after_1s - 45f64.to_radians()).abs() < 0.06, "{after_1s}");
    while t < started + 3.0 {
        t += 0.05;
        m.handle(t, &GCS, &turn);
        m.tick(t);
    }
    assert!((m.yaw_ned_rad - 1.5).abs() < 1e-6, "{}", m.yaw_ned_rad);
    // ArduCopter's slew: 60 deg/s, the short way round (0 to -2 rad: toward negative yaw).
    let mut a = MockAutopilot::new(MockConfig::new(Flavor::ArduPilot), 0.0);
    a.yaw_target_ned_rad = -2.0;
    a.turn(1.0);
    assert!(
        (a.yaw_ned_rad + 60f64.to_radians()).abs() < 1e-9,
        "{}",
        a.yaw_ned_rad
    );
}

/// PX4's MAV_CMD_DO_CHANGE_ALTITUDE (param1 AMSL): in AUTO.LOITER the hold moves to that
/// height over its own point; from another mode it only switches to AUTO.LOITER (PX4's
/// navigator applies the height only in a hold it is already in); beyond GF_MAX_VER_DIST
/// it is refused with PX4's message; ArduPilot's mock does not take it.
#[test]
fn px4_change_altitude_moves_a_hold_and_only_a_hold() {
    let mut cfg = MockConfig::new(Flavor::Px4);
    cfg.param_overrides = vec![("GF_MAX_VER_DIST".into(), 20.0)];
    let origin = cfg.origin_alt_m as f32;
    let mut m = MockAutopilot::new(cfg, 0.0);
    let t = stream(&mut m, 0.0, 1.5, Some([2.0, 1.0, -5.0]));
    set_mode(&mut m, t, Mode::Offboard);
    arm(&mut m, t);
    let t = stream(&mut m, t, t + 12.0, Some([2.0, 1.0, -5.0]));
    let change = |amsl: f32| {
        cmd(
            MavCmd::MAV_CMD_DO_CHANGE_ALTITUDE,
            [amsl, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    };
    // From OFFBOARD: a hold where it is, the height ignored.
    let out = m.handle(t, &GCS, &change(origin + 9.0));
    assert_eq!(ack_of(&out), MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(m.mode(), Mode::Hold);
    let t = stream(&mut m, t, t + 8.0, None);
    assert!(
        (m.position_ned_m()[2] + 5.0).abs() < 0.2,
        "{:?}",
        m.position_ned_m()
    );
    // In the hold: up to 9 m over the same point.
    let out = m.handle(t, &GCS, &change(origin + 9.0));
    assert_eq!(ack_of(&out), MavResult::MAV_RESULT_ACCEPTED);
    let t = stream(&mut m, t, t + 10.0, None);
    let p = m.position_ned_m();
    assert!(
        (p[2] + 9.0).abs() < 0.2 && (p[0] - 2.0).abs() < 0.3 && (p[1] - 1.0).abs() < 0.3,
        "{p:?}"
    );
    // Beyond the 20 m vertical fence: refused, the hold stays.
    let out = m.handle(t, &GCS, &change(origin + 25.0));
    let said: String = out
        .iter()
        .filter_map(|x| match x {
            MavMessage::STATUSTEXT(s) => Some(s.text.to_str().unwrap_or("").to_string()),
            _ => None,
        })
        .collect();
    assert!(said.contains("outside geofence"), "{said}");
    stream(&mut m, t, t + 5.0, None);
    assert!((m.position_ned_m()[2] + 9.0).abs() < 0.2);
    let mut ap = MockAutopilot::new(MockConfig::new(Flavor::ArduPilot), 0.0);
    let out = ap.handle(1.0, &GCS, &change(origin + 9.0));
    assert_eq!(ack_of(&out), MavResult::MAV_RESULT_UNSUPPORTED);
}
