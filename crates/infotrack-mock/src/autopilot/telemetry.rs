//! What the mock sends unasked: its heartbeat and telemetry streams.

use super::*;

impl MockAutopilot {
    /// This vehicle's HEARTBEAT.
    pub fn heartbeat(&self) -> MavMessage {
        let mut base = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if self.armed {
            base |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        if matches!(self.mode, Mode::Offboard | Mode::Guided) {
            base |= MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED;
        }
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: self.mode.custom_mode(self.cfg.flavor).unwrap_or(0),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: match self.cfg.flavor {
                Flavor::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
                Flavor::ArduPilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            },
            base_mode: base,
            system_status: if self.armed {
                MavState::MAV_STATE_ACTIVE
            } else {
                MavState::MAV_STATE_STANDBY
            },
            mavlink_version: 3,
        })
    }

    pub(super) fn time_boot_ms(&self) -> u32 {
        ((self.now_s - self.boot_s) * 1e3) as u32
    }

    pub(super) fn telemetry(&self, id: u32) -> Option<MavMessage> {
        let s = &self.state;
        let t = self.time_boot_ms();
        // LOCAL_POSITION_NED stays at zero on ArduPilot until the EKF has an origin.
        let has_origin = self.estimator_ready();
        Some(match id {
            0 => self.heartbeat(),
            1 => self.sys_status(),
            stock::HOME_POSITION_ID | stock::GPS_GLOBAL_ORIGIN_ID => {
                return self.origin_message(id)
            }
            30 => {
                let (roll, pitch) = s.attitude(self.yaw_ned_rad);
                MavMessage::ATTITUDE(ATTITUDE_DATA {
                    time_boot_ms: t,
                    roll: roll as f32,
                    pitch: pitch as f32,
                    yaw: self.yaw_ned_rad as f32,
                    ..Default::default()
                })
            }
            32 => {
                if !has_origin {
                    return Some(MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                        time_boot_ms: t,
                        ..Default::default()
                    }));
                }
                let (dp, dv) = self.hover_wander();
                MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                    time_boot_ms: t,
                    x: (s.pos_ned_m[0] + dp[0]) as f32,
                    y: (s.pos_ned_m[1] + dp[1]) as f32,
                    z: s.pos_ned_m[2] as f32,
                    vx: (s.vel_ned_mps[0] + dv[0]) as f32,
                    vy: (s.vel_ned_mps[1] + dv[1]) as f32,
                    vz: s.vel_ned_mps[2] as f32,
                })
            }
            33 => {
                let (lat, lon) = self.latlon();
                let hdg = (self.yaw_ned_rad.to_degrees().rem_euclid(360.0) * 100.0) as u16;
                MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                    time_boot_ms: t,
                    lat: (lat * 1e7) as i32,
                    lon: (lon * 1e7) as i32,
                    alt: ((self.cfg.origin_alt_m - s.pos_ned_m[2]) * 1e3) as i32,
                    relative_alt: (-s.pos_ned_m[2] * 1e3) as i32,
                    vx: (s.vel_ned_mps[0] * 100.0) as i16,
                    vy: (s.vel_ned_mps[1] * 100.0) as i16,
                    vz: (s.vel_ned_mps[2] * 100.0) as i16,
                    hdg,
                })
            }
            245 => MavMessage::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
                vtol_state: MavVtolState::MAV_VTOL_STATE_UNDEFINED,
                landed_state: if !self.armed || s.altitude_m() < 0.05 {
                    MavLandedState::MAV_LANDED_STATE_ON_GROUND
                } else if self.mode == Mode::Land {
                    MavLandedState::MAV_LANDED_STATE_LANDING
                } else {
                    MavLandedState::MAV_LANDED_STATE_IN_AIR
                },
            }),
            _ => return None,
        })
    }

    /// Latitude and longitude (degrees, WGS84) of the current position: the local NED
    /// position about the configured origin, exactly (`geodesy`).
    pub fn latlon(&self) -> (f64, f64) {
        // The local NED frame's origin in WGS84, as the firmware's estimator keeps it.
        let origin = infotrack_core::geodesy::GeodeticWgs84 {
            lat_deg: self.cfg.origin_lat_deg,
            lon_deg: self.cfg.origin_lon_deg,
            alt_m: self.cfg.origin_alt_m,
        };
        let p = self.state.pos_ned_m;
        let here = origin.offset_by_enu([p[1], p[0], -p[2]]);
        (here.lat_deg, here.lon_deg)
    }
}
