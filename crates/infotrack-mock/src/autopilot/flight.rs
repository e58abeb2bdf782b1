//! How the mock flies: modes, the kinematic vehicle's step, hover wander, touchdown,
//! failsafes and the geofence.

use super::*;

impl MockAutopilot {
    pub(super) fn set_mode_internal(&mut self, mode: Mode) {
        self.mode = mode;
        self.target_vel_ned_mps = [0.0; 3];
        self.target_ned_m = match mode {
            // Stop where braking at the acceleration limit ends, as a multicopter's brake
            // and loiter do, rather than turning back to where the switch happened.
            Mode::Hold | Mode::Brake | Mode::Position => Some(self.stopping_point()),
            Mode::Land => Some([self.state.pos_ned_m[0], self.state.pos_ned_m[1], 0.5]),
            Mode::ReturnToLaunch => Some([
                self.home_ned_m[0],
                self.home_ned_m[1],
                self.state.pos_ned_m[2],
            ]),
            Mode::Offboard | Mode::Guided => self
                .last_setpoint
                .map(|(_, p)| p)
                .or(Some(self.state.pos_ned_m)),
            _ => self.target_ned_m,
        };
        if mode != Mode::Guided {
            self.takeoff_alt_m = None;
        }
    }

    /// The reported position's hunting around the true one (north, east) and its rate.
    pub(super) fn hover_wander(&self) -> ([f64; 2], [f64; 2]) {
        let a = self.cfg.hover_wander_m;
        if a == 0.0 || !self.armed {
            return ([0.0; 2], [0.0; 2]);
        }
        let w = std::f64::consts::TAU * 0.5;
        let (s, c) = (w * self.now_s).sin_cos();
        ([a * s, a * c], [a * w * c, -a * w * s])
    }

    /// A landing vehicle disarms once it has been on the ground for its land detector's
    /// delay (PX4's COM_DISARM_LAND, 2 s by default; ArduCopter ~1 s), and it reports
    /// itself ON_GROUND all that time: a ground station sees "landed" before "disarmed",
    /// as from the firmwares (MAVSDK reads the landed state when it sees the disarm).
    pub(super) fn disarm_after_touchdown(&mut self) {
        if !(self.armed && self.mode == Mode::Land && self.state.altitude_m() < 0.05) {
            self.touched_down_at_s = None;
            return;
        }
        let delay_s = match self.cfg.flavor {
            Flavor::Px4 => self.params.get("COM_DISARM_LAND", 2.0),
            Flavor::ArduPilot => 1.0,
        };
        let since = *self.touched_down_at_s.get_or_insert(self.now_s);
        if self.now_s - since >= delay_s {
            self.armed = false;
            self.touched_down_at_s = None;
        }
    }

    /// ArduCopter's LOITER with the throttle at its minimum (no RC) descends at the
    /// descent limit until it lands.
    pub(super) fn descend_without_throttle(&mut self) {
        if self.cfg.flavor == Flavor::ArduPilot
            && self.mode == Mode::Hold
            && !self.cfg.rc_throttle_centred
        {
            if let Some(t) = self.target_ned_m.as_mut() {
                t[2] = 0.0;
            }
        }
    }

    /// ArduPilot's GUIDED moves a position + velocity target along its velocity between
    /// messages (its position controller integrates the target); PX4 holds each target as
    /// sent until the next one.
    pub(super) fn advance_moving_target(&mut self, dt: f64) {
        if self.cfg.flavor != Flavor::ArduPilot {
            return;
        }
        if let Some(t) = self.target_ned_m.as_mut() {
            for (tk, vk) in t.iter_mut().zip(self.target_vel_ned_mps) {
                *tk += vk * dt;
            }
        }
    }

    /// Advances the vehicle `dt` s: motionless while the motors spool up, then toward the
    /// target moved by the loop's wander (straight to it while taking off, until the target
    /// altitude is first reached).
    pub(super) fn fly(&mut self, limits: &Limits, dt: f64) {
        let r = self.cfg.response;
        if self.now_s - self.armed_at_s < r.spool_up_s {
            return;
        }
        self.advance_wander(dt);
        self.turn(dt);
        let target = self.target_ned_m.map(|t| {
            if self.taking_off {
                t
            } else {
                [
                    t[0] + self.wander_ned_m[0],
                    t[1] + self.wander_ned_m[1],
                    t[2] + self.wander_ned_m[2],
                ]
            }
        });
        if let Some(t) = self.target_ned_m {
            if self.taking_off && self.state.pos_ned_m[2] <= 0.95 * t[2].min(-0.1) {
                self.taking_off = false;
            }
        }
        let cmd = Command {
            target_ned_m: target,
            feed_forward_ned_mps: self.target_vel_ned_mps,
        };
        self.state.step(&cmd, limits, &r, dt);
    }

    /// Turns `dt` toward the asked heading the short way round at the firmware's auto yaw
    /// rate: PX4 MPC_YAWRAUTO_MAX (deg/s, default 45), ArduCopter ATC_SLEW_YAW (cdeg/s,
    /// default 6000). Both turn a position target's yaw at a limited rate, not at once.
    pub(super) fn turn(&mut self, dt: f64) {
        let rate_rad_s = match self.cfg.flavor {
            Flavor::Px4 => self.params.get("MPC_YAWRAUTO_MAX", 45.0).to_radians(),
            Flavor::ArduPilot => (self.params.get("ATC_SLEW_YAW", 6000.0) / 100.0).to_radians(),
        };
        let step = rate_rad_s.max(0.0) * dt;
        let to_go = infotrack_core::frames::wrap_angle(self.yaw_target_ned_rad - self.yaw_ned_rad);
        if to_go != 0.0 {
            self.yaw_ned_rad =
                infotrack_core::frames::wrap_angle(self.yaw_ned_rad + to_go.clamp(-step, step));
        }
    }

    /// One step of the wander's Gauss-Markov process (exact for any `dt`).
    fn advance_wander(&mut self, dt: f64) {
        let r = self.cfg.response;
        let decay = (-dt / r.wander_correlation_s.max(1e-3)).exp();
        let spread = (1.0 - decay * decay).sqrt();
        let sd = [
            r.wander_horizontal_m,
            r.wander_horizontal_m,
            r.wander_vertical_m,
        ];
        for (w, sd) in self.wander_ned_m.iter_mut().zip(sd) {
            let z: f64 = StandardNormal.sample(&mut self.wander_rng);
            *w = *w * decay + sd * spread * z;
        }
    }

    fn stopping_point(&self) -> [f64; 3] {
        let [x, y, z] = self.state.pos_ned_m;
        let [vx, vy, _] = self.state.vel_ned_mps;
        let a = self.limits().xy_accel_mps2.max(0.1);
        let speed = vx.hypot(vy);
        let k = speed / (2.0 * a);
        [x + vx * k, y + vy * k, z]
    }

    /// PX4's MAV_CMD_DO_CHANGE_ALTITUDE: its commander switches to AUTO.LOITER (accepted);
    /// its navigator moves the hold to `amsl_m` (param1, read as AMSL whatever param2's frame
    /// says; NaN keeps the altitude) only when the vehicle was armed and in AUTO.LOITER
    /// already, keeping the hold's point, and refuses a height beyond GF_MAX_VER_DIST with
    /// "Altitude change is outside geofence".
    pub(super) fn change_altitude_px4(&mut self, amsl_m: f64, out: &mut Vec<MavMessage>) {
        let applies = self.armed && self.mode == Mode::Hold;
        if self.mode != Mode::Hold {
            self.set_mode_internal(Mode::Hold);
        }
        if !applies || !amsl_m.is_finite() {
            return;
        }
        let z_down_m = self.cfg.origin_alt_m - amsl_m;
        let above_home_m = self.home_ned_m[2] - z_down_m;
        let max_v = self.params.get("GF_MAX_VER_DIST", 0.0);
        if max_v > 0.0 && above_home_m > max_v {
            let m = self.statustext(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                "Altitude change is outside geofence",
            );
            out.push(m);
            return;
        }
        if let Some(t) = &mut self.target_ned_m {
            t[2] = z_down_m;
        }
    }

    pub(super) fn failsafe(&mut self, reason: &str, mode: Mode, out: &mut Vec<MavMessage>) {
        self.set_mode_internal(mode);
        self.events.push(MockEvent::Failsafe {
            reason: reason.to_string(),
            mode,
        });
        let text = format!("Failsafe: {reason}");
        out.push(self.statustext(MavSeverity::MAV_SEVERITY_CRITICAL, &text));
        out.push(self.heartbeat());
    }

    /// The geofence from the flavour's parameters, around home: PX4 GF_MAX_HOR_DIST /
    /// GF_MAX_VER_DIST (0 = off) with GF_ACTION; ArduPilot FENCE_ENABLE, FENCE_TYPE (bit 0
    /// altitude, bit 1 circle), FENCE_RADIUS, FENCE_ALT_MAX with FENCE_ACTION.
    pub(super) fn check_geofence(&mut self, out: &mut Vec<MavMessage>) {
        let p = self.state.pos_ned_m;
        let horizontal = (p[0] - self.home_ned_m[0]).hypot(p[1] - self.home_ned_m[1]);
        let altitude = self.state.altitude_m();
        // A breach clears only once the vehicle is back inside by a margin (ArduPilot's
        // FENCE_MARGIN, 2 m), or braking at the edge would trigger it again and again.
        const MARGIN_M: f64 = 2.0;
        let beyond = |value: f64, limit: f64, margin: f64| limit > 0.0 && value > limit - margin;
        let (limits, action) = match self.cfg.flavor {
            Flavor::Px4 => {
                let max_h = self.params.get("GF_MAX_HOR_DIST", 0.0);
                let max_v = self.params.get("GF_MAX_VER_DIST", 0.0);
                let action = match self.params.get("GF_ACTION", 1.0) as i64 {
                    2 => Some(Mode::Hold),
                    3 => Some(Mode::ReturnToLaunch),
                    5 => Some(Mode::Land),
                    _ => None,
                };
                ([max_h, max_v], action)
            }
            Flavor::ArduPilot => {
                let on = self.params.get("FENCE_ENABLE", 0.0) as i64 == 1;
                let kinds = self.params.get("FENCE_TYPE", 7.0) as i64;
                let max_h = if on && kinds & 2 != 0 {
                    self.params.get("FENCE_RADIUS", 300.0)
                } else {
                    0.0
                };
                let max_v = if on && kinds & 1 != 0 {
                    self.params.get("FENCE_ALT_MAX", 100.0)
                } else {
                    0.0
                };
                let action = match self.params.get("FENCE_ACTION", 1.0) as i64 {
                    0 => None,
                    2 => Some(Mode::Land),
                    4 => Some(Mode::Brake),
                    _ => Some(Mode::ReturnToLaunch),
                };
                ([max_h, max_v], action)
            }
        };
        let outside = beyond(horizontal, limits[0], 0.0) || beyond(altitude, limits[1], 0.0);
        let near = beyond(horizontal, limits[0], MARGIN_M) || beyond(altitude, limits[1], MARGIN_M);
        if outside && !self.fence_breached {
            self.fence_breached = true;
            match action {
                Some(mode) => self.failsafe("geofence breached", mode, out),
                None => {
                    let m = self.statustext(MavSeverity::MAV_SEVERITY_WARNING, "Geofence breached");
                    out.push(m);
                }
            }
        } else if !near {
            self.fence_breached = false;
        }
    }
}
