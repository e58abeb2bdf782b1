//! The mock autopilot's behaviour as a pure state machine: messages in, messages out, and a
//! clock tick. No I/O: the server in `server.rs` moves the bytes.
//!
//! What it imitates (see ../shared/reference/autopilots.md): HEARTBEAT with the flavour's
//! autopilot type and mode encoding; telemetry streams at default rates, changed by
//! MAV_CMD_SET_MESSAGE_INTERVAL; arming refused without a position estimate; PX4's refusal of
//! OFFBOARD without a recent setpoint stream and its offboard-loss failsafe (COM_OF_LOSS_T,
//! COM_OBL_RC_ACT, back to OFFBOARD when setpoints resume); ArduPilot's GUIDED takeoff (a
//! position target before the altitude is reached cancels it) and GCS failsafe
//! (FS_GCS_ENABLE, FS_GCS_TIMEOUT, heartbeats from MAV_GCS_SYSID only); a kinematic
//! multicopter limited by the flavour's speed and acceleration parameters; the parameter
//! protocol with each firmware's value encoding.

use std::collections::BTreeMap;

use mavlink::dialects::ardupilotmega::*;
use mavlink::MavHeader;

use super::params::ParamTable;
use super::vehicle::{Command, KinematicState, Limits, Response};
use infotrack_core::rng::CoreRng;
use infotrack_link::modes::{Flavor, Mode};
use infotrack_link::params_file::{decode_wire, encode_wire, mav_param_type_of};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// How the mock is set up.
#[derive(Debug, Clone)]
pub struct MockConfig {
    /// Firmware to imitate.
    pub flavor: Flavor,
    /// Its system id.
    pub system_id: u8,
    /// Its component id (1, the autopilot).
    pub component_id: u8,
    /// Latitude of the local origin, degrees.
    pub origin_lat_deg: f64,
    /// Longitude of the local origin, degrees.
    pub origin_lon_deg: f64,
    /// Altitude of the local origin above mean sea level, m.
    pub origin_alt_m: f64,
    /// Seconds after boot before the estimator has a position (arming refused before).
    pub estimator_ready_after_s: f64,
    /// ArduPilot: seconds after boot until its start-up completes ("ArduPilot Ready",
    /// ~2.2 s on the ArduCopter SITL build). Before, a mode change is accepted but reset
    /// to STABILIZE when the start-up completes, as ArduCopter does, and arming is refused
    /// ("Arm: System not initialised"). 0: ready at boot. PX4 ignores it.
    pub startup_s: f64,
    /// Parameter overrides applied over the flavour's defaults.
    pub param_overrides: Vec<(String, f64)>,
    /// An RC transmitter is on with its throttle centred. Without one (a companion-only
    /// flight, or RC lost), ArduCopter's pilot-controlled modes read the throttle at its
    /// minimum: in LOITER (and ALT_HOLD) the copter descends to the ground, as its SITL
    /// does ("SIM Hit ground at 2.5 m/s" after a switch to LOITER at 45 m).
    pub rc_throttle_centred: bool,
    /// Amplitude of a hover that never settles, m: the reported position circles the true
    /// one at 0.5 Hz, as a real position loop hunts (PX4 SIH never came closer than 0.08 m
    /// to a setpoint nor slower than 0.08 m/s). 0: the kinematic model's exact settling.
    pub hover_wander_m: f64,
    /// How the vehicle's position loop answers: [`Response::IDEAL`] (the default: exact,
    /// what the tests of the protocol and the modes need) or [`Response::sitl`] (as the
    /// flavour's SITL build measured: `infotrack mock`'s default).
    pub response: Response,
    /// Seconds after boot during which a failsafe holds the vehicle's mode: every
    /// MAV_CMD_DO_SET_MODE is answered TEMPORARILY_REJECTED, with a STATUSTEXT saying why.
    /// PX4 SIH did so while its "Failsafe: blind land" held (a sensor that had not
    /// reported yet). 0: no such failsafe.
    pub mode_locked_until_s: f64,
    /// Seed of the loop's wander.
    pub seed: u64,
}

/// ArduCopter SITL said "ArduPilot Ready" 2.2 s after its first heartbeat.
const ARDUCOPTER_SITL_STARTUP_S: f64 = 2.2;

impl MockConfig {
    /// Answers as the flavour's SITL build did: its measured position loop
    /// ([`Response::sitl`]) and, for ArduPilot, its 2.2 s start-up.
    pub fn answer_as_sitl(&mut self) {
        self.response = Response::sitl(self.flavor);
        if self.flavor == Flavor::ArduPilot {
            self.startup_s = ARDUCOPTER_SITL_STARTUP_S;
        }
    }

    /// Defaults for a flavour: system 1, component 1, an origin in Gainesville, estimator
    /// ready at once.
    pub fn new(flavor: Flavor) -> Self {
        Self {
            flavor,
            system_id: 1,
            component_id: 1,
            origin_lat_deg: 29.6436,
            origin_lon_deg: -82.3549,
            origin_alt_m: 30.0,
            estimator_ready_after_s: 0.0,
            startup_s: 0.0,
            param_overrides: Vec::new(),
            rc_throttle_centred: false,
            hover_wander_m: 0.0,
            response: Response::IDEAL,
            mode_locked_until_s: 0.0,
            seed: 1,
        }
    }
}

/// Something the vehicle did by itself, for tests and logs.
#[derive(Debug, Clone, PartialEq)]
pub enum MockEvent {
    /// A failsafe switched the mode.
    Failsafe {
        /// Why.
        reason: String,
        /// The mode it switched to.
        mode: Mode,
    },
    /// A takeoff was cancelled by an early position target (ArduPilot).
    TakeoffCancelled,
}

/// Message ids of the streamed telemetry.
const STREAMED: [u32; 8] = [0, 1, 30, 32, 33, 245, 242, 49];

/// The mock autopilot.
#[derive(Debug, Clone)]
pub struct MockAutopilot {
    cfg: MockConfig,
    params: ParamTable,
    mode: Mode,
    armed: bool,
    state: KinematicState,
    yaw_ned_rad: f64,
    /// The heading the last position target asked for, local NED yaw (rad); the vehicle
    /// turns to it at the firmware's auto yaw rate.
    yaw_target_ned_rad: f64,
    /// Target the vehicle flies to in the current mode, local NED.
    target_ned_m: Option<[f64; 3]>,
    /// Velocity of the last position + velocity target (feed-forward), NED, m/s.
    target_vel_ned_mps: [f64; 3],
    /// Time of the last valid offboard/guided position setpoint and its position.
    last_setpoint: Option<(f64, [f64; 3])>,
    /// PX4: the mode was left because the offboard stream stopped.
    offboard_lost: bool,
    /// ArduPilot: takeoff altitude while a GUIDED takeoff is climbing.
    takeoff_alt_m: Option<f64>,
    last_gcs_heartbeat_s: Option<f64>,
    gcs_failsafe: bool,
    /// Outside the geofence (the breach action fires once per breach).
    fence_breached: bool,
    /// Stream period per message id, s (0: off).
    intervals: BTreeMap<u32, f64>,
    next_due: BTreeMap<u32, f64>,
    boot_s: f64,
    /// ArduPilot's start-up has completed (`MockConfig::startup_s`).
    started_up: bool,
    now_s: f64,
    /// Time the kinematics were last advanced to.
    last_tick_s: f64,
    home_ned_m: [f64; 3],
    /// When the vehicle armed (its motors' spool-up counts from here).
    armed_at_s: f64,
    /// When a landing vehicle touched down (it disarms a moment later).
    touched_down_at_s: Option<f64>,
    /// Climbing out of a takeoff (until the target altitude is first reached).
    taking_off: bool,
    /// The position loop's wander: where the vehicle holds relative to its target, NED, m.
    wander_ned_m: [f64; 3],
    wander_rng: CoreRng,
    events: Vec<MockEvent>,
    /// Message sequence for STATUSTEXT ids.
    text_id: u16,
    /// SET_POSITION_TARGET_LOCAL_NED messages addressed to this vehicle, valid or not.
    setpoints_received: u64,
}

fn header_ack(cmd: MavCmd, result: MavResult, to: &MavHeader) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command: cmd,
        result,
        progress: 0,
        result_param2: 0,
        target_system: to.system_id as u8,
        target_component: to.component_id,
    })
}

fn param_id_str(id: &mavlink::types::CharArray<16>) -> String {
    id.to_str().unwrap_or("").trim_end_matches('\0').to_string()
}

impl MockAutopilot {
    /// A vehicle on the ground at the origin, disarmed, booted at `now_s`.
    pub fn new(cfg: MockConfig, now_s: f64) -> Self {
        let mut params = ParamTable::defaults(cfg.flavor);
        for (name, v) in &cfg.param_overrides {
            params.set(name, *v);
        }
        let mode = match cfg.flavor {
            Flavor::Px4 => Mode::Position,
            Flavor::ArduPilot => Mode::Stabilized,
        };
        let mut intervals = BTreeMap::new();
        // Defaults seen on the onboard link (PX4) / after a companion asks (ArduPilot
        // streams only HEARTBEAT until asked).
        let rates: &[(u32, f64)] = match cfg.flavor {
            Flavor::Px4 => &[
                (0, 1.0),
                (30, 90.0),
                (33, 45.0),
                (32, 30.0),
                (1, 5.0),
                (245, 5.0),
            ],
            Flavor::ArduPilot => &[(0, 1.0)],
        };
        for &(id, hz) in rates {
            intervals.insert(id, 1.0 / hz);
        }
        Self {
            params,
            mode,
            armed: false,
            state: KinematicState::default(),
            yaw_ned_rad: 0.0,
            yaw_target_ned_rad: 0.0,
            target_ned_m: None,
            target_vel_ned_mps: [0.0; 3],
            last_setpoint: None,
            offboard_lost: false,
            takeoff_alt_m: None,
            last_gcs_heartbeat_s: None,
            gcs_failsafe: false,
            fence_breached: false,
            intervals,
            next_due: BTreeMap::new(),
            boot_s: now_s,
            started_up: cfg.flavor != Flavor::ArduPilot || cfg.startup_s <= 0.0,
            now_s,
            last_tick_s: now_s,
            home_ned_m: [0.0; 3],
            armed_at_s: now_s,
            touched_down_at_s: None,
            taking_off: false,
            wander_ned_m: [0.0; 3],
            wander_rng: CoreRng::seed_from_u64(cfg.seed),
            events: Vec::new(),
            text_id: 0,
            setpoints_received: 0,
            cfg,
        }
    }

    /// A power cycle at `now_s`: a fresh vehicle (disarmed, on the ground at home, default
    /// stream rates, boot clock restarted) that kept its parameters, as parameters live in
    /// the autopilot's flash.
    pub fn reboot(&mut self, now_s: f64) {
        let params = self.params.clone();
        *self = Self::new(self.cfg.clone(), now_s);
        self.params = params;
    }

    /// The flavour.
    pub fn flavor(&self) -> Flavor {
        self.cfg.flavor
    }

    /// Current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Whether armed.
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// Position, local NED, m.
    pub fn position_ned_m(&self) -> [f64; 3] {
        self.state.pos_ned_m
    }

    /// Parameters.
    pub fn params(&self) -> &ParamTable {
        &self.params
    }

    /// Events since the last call.
    pub fn take_events(&mut self) -> Vec<MockEvent> {
        std::mem::take(&mut self.events)
    }

    fn header(&self) -> MavHeader {
        MavHeader {
            system_id: self.cfg.system_id as u32,
            component_id: self.cfg.component_id,
            sequence: 0,
        }
    }

    /// The header the mock sends with.
    pub fn own_header(&self) -> MavHeader {
        self.header()
    }

    fn limits(&self) -> Limits {
        match self.cfg.flavor {
            Flavor::Px4 => Limits {
                xy_speed_mps: self.params.get("MPC_XY_VEL_MAX", 12.0),
                xy_accel_mps2: self.params.get("MPC_ACC_HOR", 3.0),
                climb_mps: self.params.get("MPC_Z_VEL_MAX_UP", 3.0),
                descend_mps: self.params.get("MPC_Z_VEL_MAX_DN", 1.5),
                max_tilt_rad: self.params.get("MPC_TILTMAX_AIR", 45.0).to_radians(),
            },
            // ArduPilot's speeds are in cm/s.
            Flavor::ArduPilot => Limits {
                xy_speed_mps: self.params.get("WPNAV_SPEED", 1000.0) / 100.0,
                xy_accel_mps2: self.params.get("WPNAV_ACCEL", 250.0) / 100.0,
                climb_mps: self.params.get("WPNAV_SPEED_UP", 250.0) / 100.0,
                descend_mps: self.params.get("WPNAV_SPEED_DN", 150.0) / 100.0,
                // Centidegrees.
                max_tilt_rad: (self.params.get("ANGLE_MAX", 3000.0) / 100.0).to_radians(),
            },
        }
    }

    /// ArduCopter's start-up completing: it says so and sets its initial mode, STABILIZE,
    /// over whatever mode was set during the start-up (the SITL build took GUIDED at 1.2 s
    /// and reported STABILIZE again at 2.2 s, with "ArduPilot Ready").
    fn complete_startup(&mut self, out: &mut Vec<MavMessage>) {
        if self.started_up || self.now_s - self.boot_s < self.cfg.startup_s {
            return;
        }
        self.started_up = true;
        self.set_mode_internal(Mode::Stabilized);
        out.push(self.statustext(MavSeverity::MAV_SEVERITY_INFO, "ArduPilot Ready"));
    }

    /// A failsafe still holds the mode ([`MockConfig::mode_locked_until_s`]).
    fn mode_locked(&self) -> bool {
        self.now_s - self.boot_s < self.cfg.mode_locked_until_s
    }

    fn estimator_ready(&self) -> bool {
        self.now_s - self.boot_s >= self.cfg.estimator_ready_after_s
    }

    fn statustext(&mut self, severity: MavSeverity, text: &str) -> MavMessage {
        self.text_id = self.text_id.wrapping_add(1);
        MavMessage::STATUSTEXT(STATUSTEXT_DATA {
            severity,
            text: text.into(),
            id: self.text_id,
            chunk_seq: 0,
        })
    }

    /// Handles one received message; returns the replies.
    // REQUEST_DATA_STREAM is deprecated but stock clients send it (see `stock`).
    #[allow(deprecated)]
    pub fn handle(&mut self, now_s: f64, from: &MavHeader, msg: &MavMessage) -> Vec<MavMessage> {
        self.now_s = self.now_s.max(now_s);
        let mut out = Vec::new();
        match msg {
            MavMessage::HEARTBEAT(_)
                if from.system_id as f64 == self.params.get("MAV_GCS_SYSID", 255.0) =>
            {
                self.last_gcs_heartbeat_s = Some(now_s);
            }
            MavMessage::COMMAND_LONG(c) if self.addressed(c.target_system, c.target_component) => {
                out.extend(self.command(from, c));
            }
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp)
                if self.addressed(sp.target_system, sp.target_component) =>
            {
                self.setpoints_received += 1;
                out.extend(self.setpoint(sp));
            }
            MavMessage::REQUEST_DATA_STREAM(r)
                if self.addressed(r.target_system, r.target_component) =>
            {
                self.request_data_stream(r);
            }
            MavMessage::PARAM_REQUEST_LIST(r)
                if self.addressed(r.target_system, r.target_component) =>
            {
                for i in 0..self.params.len() {
                    out.push(self.param_value(i, false));
                }
            }
            MavMessage::PARAM_REQUEST_READ(r)
                if self.addressed(r.target_system, r.target_component) =>
            {
                let by_name = r.param_index < 0;
                let idx = if by_name {
                    self.params
                        .by_name(&param_id_str(&r.param_id))
                        .map(|(i, _)| i)
                } else {
                    Some(r.param_index as usize).filter(|i| *i < self.params.len())
                };
                if let Some(i) = idx {
                    out.push(self.param_value(i, by_name));
                }
            }
            MavMessage::PARAM_SET(s) if self.addressed(s.target_system, s.target_component) => {
                let name = param_id_str(&s.param_id);
                if let Some((i, p)) = self.params.by_name(&name) {
                    let v = decode_wire(self.cfg.flavor, p.ty, s.param_value);
                    if self.params.set(&name, v) {
                        out.push(self.param_value(i, false));
                    } else {
                        out.push(self.statustext(
                            MavSeverity::MAV_SEVERITY_ERROR,
                            &format!("{name}: value {v} rejected"),
                        ));
                    }
                }
            }
            _ => {}
        }
        out
    }

    /// Advances the clock to `now_s`: failsafes, kinematics, due telemetry.
    pub fn tick(&mut self, now_s: f64) -> Vec<MavMessage> {
        let dt = (now_s - self.last_tick_s).max(0.0);
        self.last_tick_s = now_s;
        self.now_s = self.now_s.max(now_s);
        let mut out = Vec::new();
        self.complete_startup(&mut out);
        if self.armed {
            // PX4 offboard loss.
            if self.cfg.flavor == Flavor::Px4
                && self.mode == Mode::Offboard
                && !self.setpoints_fresh()
            {
                let action = self.params.get("COM_OBL_RC_ACT", 0.0) as i64;
                let mode = match action {
                    3 => Mode::ReturnToLaunch,
                    4 => Mode::Land,
                    1 => Mode::Altitude,
                    2 => Mode::Stabilized,
                    0 => Mode::Position,
                    _ => Mode::Hold,
                };
                self.offboard_lost = true;
                self.failsafe("offboard signal lost", mode, &mut out);
            }
            // ArduPilot GCS failsafe: only once a GCS has been heard. ArduCopter SITL with
            // FS_GCS_ENABLE = 1 from boot and no GCS flew GUIDED for 90 s without it (the
            // field flight); a companion-only flight is not a lost GCS.
            let fs = self.params.get("FS_GCS_ENABLE", 0.0) as i64;
            if self.cfg.flavor == Flavor::ArduPilot && fs != 0 && !self.gcs_failsafe {
                let timeout = self.params.get("FS_GCS_TIMEOUT", 5.0);
                if self
                    .last_gcs_heartbeat_s
                    .is_some_and(|last| now_s - last > timeout)
                {
                    self.gcs_failsafe = true;
                    let mode = match fs {
                        5 => Mode::Land,
                        7 => Mode::Brake,
                        _ => Mode::ReturnToLaunch,
                    };
                    self.failsafe("GCS heartbeat lost", mode, &mut out);
                }
            }
            if dt > 0.0 {
                let limits = self.limits();
                self.advance_moving_target(dt);
                self.descend_without_throttle();
                self.fly(&limits, dt);
            }
            self.check_geofence(&mut out);
            // RTL: over home, then land; landed: disarm.
            if self.mode == Mode::ReturnToLaunch {
                let p = self.state.pos_ned_m;
                if (p[0] - self.home_ned_m[0]).hypot(p[1] - self.home_ned_m[1]) < 0.5 {
                    self.set_mode_internal(Mode::Land);
                }
            }
            self.disarm_after_touchdown();
        }
        // Telemetry.
        for id in STREAMED {
            let period = self.intervals.get(&id).copied().unwrap_or(0.0);
            if period <= 0.0 {
                continue;
            }
            let due = *self.next_due.entry(id).or_insert(now_s);
            if now_s + 1e-9 >= due {
                self.next_due.insert(id, due.max(now_s - period) + period);
                if let Some(m) = self.telemetry(id) {
                    out.push(m);
                }
            }
        }
        out
    }
}

mod flight;
mod inbound;
mod pilot;
pub use pilot::PilotRefused;
mod stock;
mod telemetry;

#[cfg(test)]
mod tests;
