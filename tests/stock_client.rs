//! The mock as stock ground stations and SDKs use it: a plain MAVLink client (not infotrack's
//! link) sends what MAVProxy (ArduPilot) and MAVSDK (PX4) send on connection and during a
//! simple flight: heartbeats as a GCS, REQUEST_DATA_STREAM (ArduPilot), AUTOPILOT_VERSION,
//! HOME_POSITION / GPS_GLOBAL_ORIGIN, waiting for SYS_STATUS health, arm, take off (PX4 with
//! a NaN altitude, as MAVSDK's action.takeoff), a guided/offboard move, land, and the disarm
//! on touchdown with EXTENDED_SYS_STATE on the ground.
#![allow(deprecated)] // REQUEST_DATA_STREAM: deprecated in the XML, still what MAVProxy sends.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use infotrack::autopilot::modes::{Flavor, Mode};
use infotrack::mock::MockConfig;
use mavlink::dialects::ardupilotmega::*;
use mavlink::{AsyncMavConnection, MavHeader, Message};

mod common;
use common::{eventually, udp_mock};

const GCS: MavHeader = MavHeader {
    system_id: 255,
    component_id: 190,
    sequence: 0,
};

/// The newest message of each name the client heard from the vehicle.
type Heard = Arc<Mutex<HashMap<&'static str, MavMessage>>>;

struct Client {
    conn: Arc<mavlink::AsyncConnection<MavMessage>>,
    heard: Heard,
    acks: Arc<Mutex<Vec<(MavCmd, MavResult)>>>,
}

impl Client {
    async fn connect(port: u16) -> Self {
        let conn = Arc::new(
            mavlink::connect_async::<MavMessage>(&format!("udpout:127.0.0.1:{port}"))
                .await
                .unwrap(),
        );
        let heard: Heard = Arc::default();
        let acks: Arc<Mutex<Vec<(MavCmd, MavResult)>>> = Arc::default();
        {
            let (conn, heard, acks) = (conn.clone(), heard.clone(), acks.clone());
            tokio::spawn(async move {
                while let Ok((_, m)) = conn.recv().await {
                    if let MavMessage::COMMAND_ACK(a) = &m {
                        acks.lock().unwrap().push((a.command, a.result));
                    }
                    heard.lock().unwrap().insert(m.message_name(), m);
                }
            });
        }
        {
            let conn = conn.clone();
            tokio::spawn(async move {
                loop {
                    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                        mavtype: MavType::MAV_TYPE_GCS,
                        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                        ..Default::default()
                    });
                    let _ = conn.send(&GCS, &hb).await;
                    tokio::time::sleep(Duration::from_millis(500)).await;
                }
            });
        }
        Self { conn, heard, acks }
    }

    fn get(&self, name: &str) -> Option<MavMessage> {
        self.heard.lock().unwrap().get(name).cloned()
    }

    async fn send(&self, m: MavMessage) {
        self.conn.send(&GCS, &m).await.unwrap();
    }

    /// Sends a COMMAND_LONG and waits for its ACK.
    async fn command(&self, command: MavCmd, p: [f32; 7]) -> MavResult {
        self.acks.lock().unwrap().clear();
        let c = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
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
        });
        for _ in 0..5 {
            self.send(c.clone()).await;
            let got = eventually(0.5, || {
                self.acks.lock().unwrap().iter().any(|(c, _)| *c == command)
            })
            .await;
            if got {
                let acks = self.acks.lock().unwrap();
                return acks.iter().find(|(c, _)| *c == command).unwrap().1;
            }
        }
        panic!("no COMMAND_ACK for {command:?}");
    }

    async fn arm(&self) -> MavResult {
        self.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await
    }

    /// MAV_CMD_NAV_LAND, then waits for the disarm on the ground.
    async fn land_and_disarm(&self) {
        assert_eq!(
            self.command(MavCmd::MAV_CMD_NAV_LAND, [0.0; 7]).await,
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert!(
            eventually(20.0, || !self.armed() && self.on_ground()).await,
            "not disarmed on the ground; altitude {}",
            self.altitude_m()
        );
    }

    fn armed(&self) -> bool {
        matches!(self.get("HEARTBEAT"), Some(MavMessage::HEARTBEAT(h))
            if h.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED))
    }

    fn altitude_m(&self) -> f64 {
        match self.get("GLOBAL_POSITION_INT") {
            Some(MavMessage::GLOBAL_POSITION_INT(g)) => g.relative_alt as f64 / 1e3,
            _ => f64::NAN,
        }
    }

    fn healthy(&self) -> bool {
        matches!(self.get("SYS_STATUS"), Some(MavMessage::SYS_STATUS(s))
            if s.onboard_control_sensors_health.contains(
                MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_GPS | MavSysStatusSensor::MAV_SYS_STATUS_AHRS))
    }

    fn on_ground(&self) -> bool {
        matches!(self.get("EXTENDED_SYS_STATE"), Some(MavMessage::EXTENDED_SYS_STATE(e))
            if e.landed_state == MavLandedState::MAV_LANDED_STATE_ON_GROUND)
    }

    async fn set_mode(&self, flavor: Flavor, mode: Mode) -> MavResult {
        let (p2, p3) = mode.do_set_mode_params(flavor).unwrap();
        self.command(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, p2, p3, 0.0, 0.0, 0.0, 0.0],
        )
        .await
    }

    fn position_target(ned: [f32; 3]) -> MavMessage {
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

    fn north_m(&self) -> f64 {
        match self.get("LOCAL_POSITION_NED") {
            Some(MavMessage::LOCAL_POSITION_NED(p)) => p.x as f64,
            _ => f64::NAN,
        }
    }
}

/// As MAVProxy flies ArduCopter: streams by REQUEST_DATA_STREAM, GUIDED, arm, takeoff,
/// a move, LAND, disarmed on the ground.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mavproxy_style_client_flies_the_ardupilot_mock() {
    let (_mock, port) = udp_mock(MockConfig::new(Flavor::ArduPilot)).await;
    let c = Client::connect(port).await;
    assert!(eventually(5.0, || c.get("HEARTBEAT").is_some()).await);
    // ArduPilot streams nothing but HEARTBEAT until asked.
    tokio::time::sleep(Duration::from_millis(800)).await;
    assert!(c.get("GLOBAL_POSITION_INT").is_none(), "streamed unasked");
    c.send(MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
        req_message_rate: 4,
        target_system: 1,
        target_component: 1,
        req_stream_id: MavDataStream::MAV_DATA_STREAM_ALL,
        start_stop: 1,
    }))
    .await;
    assert!(eventually(3.0, || c.get("GLOBAL_POSITION_INT").is_some()).await);
    assert!(
        eventually(3.0, || c.healthy()).await,
        "SYS_STATUS never healthy"
    );
    assert_eq!(
        c.command(
            MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        )
        .await,
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(eventually(2.0, || c.get("AUTOPILOT_VERSION").is_some()).await);
    assert_eq!(
        c.command(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [49.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        )
        .await,
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(eventually(2.0, || c.get("GPS_GLOBAL_ORIGIN").is_some()).await);
    assert_eq!(
        c.set_mode(Flavor::ArduPilot, Mode::Guided).await,
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(c.arm().await, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(
        c.command(
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.0]
        )
        .await,
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(eventually(10.0, || (c.altitude_m() - 3.0).abs() < 0.3).await);
    for _ in 0..40 {
        c.send(Client::position_target([4.0, 0.0, -3.0])).await;
        tokio::time::sleep(Duration::from_millis(100)).await;
        if (c.north_m() - 4.0).abs() < 0.3 {
            break;
        }
    }
    assert!((c.north_m() - 4.0).abs() < 0.3, "north {}", c.north_m());
    c.land_and_disarm().await;
}

/// As MAVSDK flies PX4: AUTOPILOT_VERSION and HOME_POSITION by MAV_CMD_REQUEST_MESSAGE,
/// health, arm, action.takeoff (altitude NaN: MIS_TAKEOFF_ALT), OFFBOARD move, action.land.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mavsdk_style_client_flies_the_px4_mock() {
    let (_mock, port) = udp_mock(MockConfig::new(Flavor::Px4)).await;
    let c = Client::connect(port).await;
    assert!(eventually(5.0, || c.get("GLOBAL_POSITION_INT").is_some()).await);
    for id in [148.0, 242.0] {
        assert_eq!(
            c.command(
                MavCmd::MAV_CMD_REQUEST_MESSAGE,
                [id, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            )
            .await,
            MavResult::MAV_RESULT_ACCEPTED,
            "message {id}"
        );
    }
    assert!(
        eventually(2.0, || c.get("AUTOPILOT_VERSION").is_some()
            && c.get("HOME_POSITION").is_some())
        .await
    );
    assert!(
        eventually(3.0, || c.healthy()).await,
        "SYS_STATUS never healthy"
    );
    assert_eq!(c.arm().await, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(
        c.command(
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            [-1.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, f32::NAN]
        )
        .await,
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(
        eventually(10.0, || (c.altitude_m() - 2.5).abs() < 0.3).await,
        "altitude {}",
        c.altitude_m()
    );
    // Offboard: setpoints first, then the mode, as MAVSDK's offboard.start does.
    for _ in 0..10 {
        c.send(Client::position_target([0.0, 0.0, -2.5])).await;
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(
        c.set_mode(Flavor::Px4, Mode::Offboard).await,
        MavResult::MAV_RESULT_ACCEPTED
    );
    for _ in 0..60 {
        c.send(Client::position_target([4.0, 0.0, -2.5])).await;
        tokio::time::sleep(Duration::from_millis(100)).await;
        if (c.north_m() - 4.0).abs() < 0.3 {
            break;
        }
    }
    assert!((c.north_m() - 4.0).abs() < 0.3, "north {}", c.north_m());
    c.land_and_disarm().await;
}
