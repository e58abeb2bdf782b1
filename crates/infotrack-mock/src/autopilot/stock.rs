//! What stock clients (MAVProxy, MAVSDK, QGroundControl, Mission Planner) ask an autopilot
//! for on connection, answered as the real firmware does: REQUEST_DATA_STREAM (ArduPilot's
//! stream groups; PX4 does not implement it), AUTOPILOT_VERSION, SYS_STATUS sensor health
//! bits that turn healthy once the estimator is ready, HOME_POSITION and GPS_GLOBAL_ORIGIN.

// REQUEST_DATA_STREAM and MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES are deprecated in the
// MAVLink XML, yet MAVProxy, Mission Planner and MAVSDK still send them and the firmware
// answers: the mock must too.
#![allow(deprecated)]

use mavlink::dialects::ardupilotmega::*;

use super::{MockAutopilot, STREAMED};
use infotrack_link::modes::Flavor;

/// HOME_POSITION's message id.
pub const HOME_POSITION_ID: u32 = 242;
/// GPS_GLOBAL_ORIGIN's message id.
pub const GPS_GLOBAL_ORIGIN_ID: u32 = 49;
/// AUTOPILOT_VERSION's message id.
pub const AUTOPILOT_VERSION_ID: u32 = 148;

/// The messages of ArduPilot's stream groups that the mock produces (ArduCopter's
/// `GCS_MAVLINK_Copter` stream tables: SYS_STATUS and EXTENDED_SYS_STATE in
/// EXTENDED_STATUS, the positions in POSITION, ATTITUDE in EXTRA1).
fn stream_group(id: MavDataStream) -> &'static [u32] {
    match id {
        MavDataStream::MAV_DATA_STREAM_ALL => &[1, 245, 32, 33, 30],
        MavDataStream::MAV_DATA_STREAM_EXTENDED_STATUS => &[1, 245],
        MavDataStream::MAV_DATA_STREAM_POSITION => &[32, 33],
        MavDataStream::MAV_DATA_STREAM_EXTRA1 => &[30],
        _ => &[],
    }
}

/// The sensors SYS_STATUS reports: gyro, accelerometer, magnetometer, barometer, GPS,
/// angular rate and attitude control, position control, motor outputs, AHRS.
fn sensor_bits() -> MavSysStatusSensor {
    MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_MAG
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_GPS
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        | MavSysStatusSensor::MAV_SYS_STATUS_AHRS
}

impl MockAutopilot {
    /// REQUEST_DATA_STREAM: ArduPilot starts (rate > 0 and start) or stops a group; PX4
    /// ignores the message, as the firmware does.
    pub(super) fn request_data_stream(&mut self, r: &REQUEST_DATA_STREAM_DATA) {
        if self.cfg.flavor != Flavor::ArduPilot {
            return;
        }
        let period = if r.start_stop == 1 && r.req_message_rate > 0 {
            1.0 / r.req_message_rate as f64
        } else {
            0.0
        };
        for &id in stream_group(r.req_stream_id) {
            self.intervals.insert(id, period);
            self.next_due.remove(&id);
        }
    }

    /// MAV_CMD_REQUEST_MESSAGE: the one message asked for, if the mock has it.
    pub(super) fn requested_message(&self, id: u32) -> Option<MavMessage> {
        match id {
            AUTOPILOT_VERSION_ID => Some(self.autopilot_version()),
            HOME_POSITION_ID | GPS_GLOBAL_ORIGIN_ID => self.origin_message(id),
            _ if STREAMED.contains(&id) => self.telemetry(id),
            _ => None,
        }
    }

    /// AUTOPILOT_VERSION with the capabilities the link and stock clients look for.
    pub(super) fn autopilot_version(&self) -> MavMessage {
        let params = match self.cfg.flavor {
            Flavor::Px4 => MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
            Flavor::ArduPilot => MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
        };
        MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
            capabilities: params
                | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2
                | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MISSION_INT,
            // 1.15.0 release (major, minor, patch, FIRMWARE_VERSION_TYPE_OFFICIAL = 255).
            flight_sw_version: (1 << 24) | (15 << 16) | 255,
            uid: 0x1_0000 + self.cfg.system_id as u64,
            ..Default::default()
        })
    }

    /// HOME_POSITION or GPS_GLOBAL_ORIGIN, once the estimator has an origin (before that a
    /// real autopilot has neither).
    pub(super) fn origin_message(&self, id: u32) -> Option<MavMessage> {
        if !self.estimator_ready() {
            return None;
        }
        let lat = (self.cfg.origin_lat_deg * 1e7) as i32;
        let lon = (self.cfg.origin_lon_deg * 1e7) as i32;
        let alt = (self.cfg.origin_alt_m * 1e3) as i32;
        let t = self.time_boot_ms() as u64 * 1000;
        Some(match id {
            HOME_POSITION_ID => {
                let h = self.home_ned_m;
                MavMessage::HOME_POSITION(HOME_POSITION_DATA {
                    latitude: lat,
                    longitude: lon,
                    altitude: alt,
                    x: h[0] as f32,
                    y: h[1] as f32,
                    z: h[2] as f32,
                    q: [1.0, 0.0, 0.0, 0.0],
                    time_usec: t,
                    ..Default::default()
                })
            }
            _ => MavMessage::GPS_GLOBAL_ORIGIN(GPS_GLOBAL_ORIGIN_DATA {
                latitude: lat,
                longitude: lon,
                altitude: alt,
                time_usec: t,
            }),
        })
    }

    /// SYS_STATUS: every sensor present and enabled; healthy once the estimator is ready
    /// (a stock client's "ready to arm" waits for that).
    pub(super) fn sys_status(&self) -> MavMessage {
        let bits = sensor_bits();
        MavMessage::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_present: bits,
            onboard_control_sensors_enabled: bits,
            onboard_control_sensors_health: if self.estimator_ready() {
                bits
            } else {
                bits & !(MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_GPS
                    | MavSysStatusSensor::MAV_SYS_STATUS_AHRS)
            },
            voltage_battery: 16_000,
            current_battery: if self.armed { 1_500 } else { 50 },
            battery_remaining: 90,
            load: 300,
            ..Default::default()
        })
    }
}
