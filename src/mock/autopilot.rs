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
use crate::autopilot::modes::{Flavor, Mode};
use crate::autopilot::params_file::{decode_wire, encode_wire, mav_param_type_of};
use crate::rng::CoreRng;
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
    /// Seed of the loop's wander.
    pub seed: u64,
}

/// ArduCopter SITL said "ArduPilot Ready" 2.2 s after its first heartbeat (session 14).
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

    fn set_mode_internal(&mut self, mode: Mode) {
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
    fn hover_wander(&self) -> ([f64; 2], [f64; 2]) {
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
    fn disarm_after_touchdown(&mut self) {
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
    fn descend_without_throttle(&mut self) {
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
    fn advance_moving_target(&mut self, dt: f64) {
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
    /// target moved by the loop's wander, climbing at the takeoff rate until the target
    /// altitude is first reached.
    fn fly(&mut self, limits: &Limits, dt: f64) {
        let r = self.cfg.response;
        if self.now_s - self.armed_at_s < r.spool_up_s {
            return;
        }
        self.advance_wander(dt);
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
            taking_off: self.taking_off,
        };
        self.state.step(&cmd, limits, &r, dt);
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

    fn failsafe(&mut self, reason: &str, mode: Mode, out: &mut Vec<MavMessage>) {
        self.set_mode_internal(mode);
        self.events.push(MockEvent::Failsafe {
            reason: reason.to_string(),
            mode,
        });
        let text = format!("Failsafe: {reason}");
        out.push(self.statustext(MavSeverity::MAV_SEVERITY_CRITICAL, &text));
        out.push(self.heartbeat());
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

    fn addressed(&self, sys: u8, comp: u8) -> bool {
        (sys == 0 || sys == self.cfg.system_id) && (comp == 0 || comp == self.cfg.component_id)
    }

    fn param_value(&self, i: usize, by_name: bool) -> MavMessage {
        let p = self.params.by_index(i).expect("index checked");
        // ArduPilot answers a read by name with index 65535.
        let index = if by_name && self.cfg.flavor == Flavor::ArduPilot {
            u16::MAX
        } else {
            i as u16
        };
        MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: encode_wire(self.cfg.flavor, p.ty, p.value),
            param_count: self.params.len() as u16,
            param_index: index,
            param_id: p.name.as_str().into(),
            param_type: mav_param_type_of(p.ty),
        })
    }

    // Long because it is one dispatch over the COMMAND_LONG ids the firmware answers, one
    // short arm each, kept together so the table of supported commands reads at a glance.
    // MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES is deprecated but stock clients send it.
    #[allow(deprecated)]
    fn command(&mut self, from: &MavHeader, c: &COMMAND_LONG_DATA) -> Vec<MavMessage> {
        use MavResult::*;
        let mut out = Vec::new();
        let result = match c.command {
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL if !c.param1.is_finite() => {
                out.push(self.statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "SET_MESSAGE_INTERVAL: message id is not a number",
                ));
                MAV_RESULT_DENIED
            }
            // PX4 treats an interval that is neither below nor above zero (NaN compares
            // false both ways) as "the default rate"; ArduPilot casts it to an integer, so
            // the mock refuses it there.
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL
                if c.param2.is_nan() && self.cfg.flavor == Flavor::ArduPilot =>
            {
                out.push(self.statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "SET_MESSAGE_INTERVAL: interval is not a number",
                ));
                MAV_RESULT_DENIED
            }
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                let id = c.param1 as u32;
                if c.param2 < 0.0 {
                    self.intervals.insert(id, 0.0);
                } else if c.param2 > 0.0 {
                    self.intervals.insert(id, c.param2 as f64 / 1e6);
                }
                self.next_due.remove(&id);
                MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_DO_SET_MODE => {
                let mode = Mode::from_do_set_mode(self.cfg.flavor, c.param2, c.param3);
                if c.param1 as u32 & 1 == 0 || matches!(mode, Mode::Other(_)) {
                    MAV_RESULT_UNSUPPORTED
                } else if mode == Mode::Offboard && !self.setpoints_fresh() {
                    out.push(self.statustext(
                        MavSeverity::MAV_SEVERITY_WARNING,
                        "Offboard rejected: no recent setpoints",
                    ));
                    MAV_RESULT_TEMPORARILY_REJECTED
                } else {
                    self.offboard_lost = false;
                    self.set_mode_internal(mode);
                    MAV_RESULT_ACCEPTED
                }
            }
            // Both firmwares arm on exactly 1 and disarm on exactly 0; anything else (NaN
            // included) is refused rather than read as one of them.
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM if c.param1 != 0.0 && c.param1 != 1.0 => {
                out.push(self.statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("ARM_DISARM: param1 {} is neither 0 nor 1", c.param1),
                ));
                match self.cfg.flavor {
                    Flavor::Px4 => MAV_RESULT_DENIED,
                    Flavor::ArduPilot => MAV_RESULT_UNSUPPORTED,
                }
            }
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
                if c.param1 == 1.0 {
                    if self.armed {
                        MAV_RESULT_ACCEPTED
                    } else if !self.started_up {
                        out.push(self.statustext(
                            MavSeverity::MAV_SEVERITY_CRITICAL,
                            "Arm: System not initialised",
                        ));
                        MAV_RESULT_FAILED
                    } else if !self.estimator_ready() {
                        out.push(self.statustext(
                            MavSeverity::MAV_SEVERITY_CRITICAL,
                            "PreArm: no position estimate",
                        ));
                        match self.cfg.flavor {
                            Flavor::Px4 => MAV_RESULT_TEMPORARILY_REJECTED,
                            Flavor::ArduPilot => MAV_RESULT_FAILED,
                        }
                    } else if self.cfg.flavor == Flavor::Px4
                        && self.mode == Mode::Offboard
                        && !self.setpoints_fresh()
                    {
                        MAV_RESULT_TEMPORARILY_REJECTED
                    } else {
                        self.armed = true;
                        self.armed_at_s = self.now_s;
                        self.taking_off = true;
                        self.home_ned_m = self.state.pos_ned_m;
                        if self.mode == Mode::Offboard {
                            self.target_ned_m = self.last_setpoint.map(|(_, p)| p);
                        }
                        MAV_RESULT_ACCEPTED
                    }
                } else if self.state.altitude_m() > 0.2 && c.param2 != 21196.0 {
                    MAV_RESULT_TEMPORARILY_REJECTED
                } else {
                    self.armed = false;
                    MAV_RESULT_ACCEPTED
                }
            }
            MavCmd::MAV_CMD_REQUEST_MESSAGE => match self.requested_message(c.param1 as u32) {
                Some(m) => {
                    out.push(m);
                    MAV_RESULT_ACCEPTED
                }
                None => MAV_RESULT_UNSUPPORTED,
            },
            MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
                out.push(self.autopilot_version());
                MAV_RESULT_ACCEPTED
            }
            // Landing where it is (both: LAND mode), then disarming on the ground (tick).
            MavCmd::MAV_CMD_NAV_LAND if self.armed => {
                self.set_mode_internal(Mode::Land);
                MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_NAV_LAND => MAV_RESULT_FAILED,
            MavCmd::MAV_CMD_NAV_TAKEOFF => {
                // PX4 reads a NaN altitude (what MAVSDK's action.takeoff sends) as "the
                // configured take-off altitude", MIS_TAKEOFF_ALT above home.
                let alt = if c.param7.is_nan() && self.cfg.flavor == Flavor::Px4 {
                    self.params.get("MIS_TAKEOFF_ALT", 2.5) - self.home_ned_m[2]
                } else {
                    c.param7 as f64
                };
                if !self.armed || alt.is_nan() || alt <= 0.0 {
                    MAV_RESULT_FAILED
                } else {
                    match self.cfg.flavor {
                        Flavor::ArduPilot if self.mode == Mode::Guided => {
                            self.takeoff_alt_m = Some(alt);
                            let p = self.state.pos_ned_m;
                            self.target_ned_m = Some([p[0], p[1], -alt]);
                            MAV_RESULT_ACCEPTED
                        }
                        Flavor::ArduPilot => MAV_RESULT_FAILED,
                        Flavor::Px4 => {
                            self.set_mode_internal(Mode::Takeoff);
                            let p = self.state.pos_ned_m;
                            self.target_ned_m = Some([p[0], p[1], -alt]);
                            MAV_RESULT_ACCEPTED
                        }
                    }
                }
            }
            _ => MAV_RESULT_UNSUPPORTED,
        };
        out.insert(0, header_ack(c.command, result, from));
        out
    }

    fn setpoints_fresh(&self) -> bool {
        let timeout = match self.cfg.flavor {
            Flavor::Px4 => self.params.get("COM_OF_LOSS_T", 1.0),
            Flavor::ArduPilot => f64::INFINITY,
        };
        matches!(self.last_setpoint, Some((t, _)) if self.now_s - t <= timeout)
    }

    // BODY_NED and BODY_OFFSET_NED are deprecated in the MAVLink XML but are exactly the frame
    // numbers (8, 9) PX4 and ArduPilot accept.
    #[allow(deprecated)]
    fn setpoint(&mut self, sp: &SET_POSITION_TARGET_LOCAL_NED_DATA) -> Vec<MavMessage> {
        let mut out = Vec::new();
        let frame_ok = match self.cfg.flavor {
            Flavor::Px4 => matches!(
                sp.coordinate_frame,
                MavFrame::MAV_FRAME_LOCAL_NED | MavFrame::MAV_FRAME_BODY_NED
            ),
            Flavor::ArduPilot => matches!(
                sp.coordinate_frame,
                MavFrame::MAV_FRAME_LOCAL_NED
                    | MavFrame::MAV_FRAME_LOCAL_OFFSET_NED
                    | MavFrame::MAV_FRAME_BODY_NED
                    | MavFrame::MAV_FRAME_BODY_OFFSET_NED
            ),
        };
        let pos_ignored = sp.type_mask.intersects(
            PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE,
        );
        if !frame_ok || pos_ignored {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "position target ignored: unsupported frame or type_mask",
            ));
            return out;
        }
        if ![sp.x, sp.y, sp.z].iter().all(|v| v.is_finite()) {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "position target ignored: non-finite position",
            ));
            return out;
        }
        let target = [sp.x as f64, sp.y as f64, sp.z as f64];
        let vel_ignored = sp.type_mask.intersects(
            PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE,
        );
        let velocity = if vel_ignored {
            [0.0; 3]
        } else if [sp.vx, sp.vy, sp.vz].iter().all(|v| v.is_finite()) {
            [sp.vx as f64, sp.vy as f64, sp.vz as f64]
        } else {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "position target ignored: non-finite velocity",
            ));
            return out;
        };
        if !sp
            .type_mask
            .contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE)
            && sp.yaw.is_finite()
        {
            self.yaw_ned_rad = sp.yaw as f64;
        }
        match self.cfg.flavor {
            Flavor::Px4 => {
                self.last_setpoint = Some((self.now_s, target));
                if self.mode == Mode::Offboard {
                    self.target_ned_m = Some(target);
                    self.target_vel_ned_mps = velocity;
                } else if self.offboard_lost {
                    // PX4 goes back to OFFBOARD by itself when valid setpoints resume.
                    self.offboard_lost = false;
                    self.set_mode_internal(Mode::Offboard);
                    out.push(self.heartbeat());
                }
            }
            Flavor::ArduPilot => {
                if self.mode != Mode::Guided {
                    return out; // silently ignored unless GUIDED
                }
                if let Some(alt) = self.takeoff_alt_m {
                    if self.state.altitude_m() < 0.95 * alt {
                        // A position target during the climb cancels the takeoff.
                        self.takeoff_alt_m = None;
                        let p = self.state.pos_ned_m;
                        self.target_ned_m = Some([p[0], p[1], 0.0]);
                        self.events.push(MockEvent::TakeoffCancelled);
                        out.push(
                            self.statustext(MavSeverity::MAV_SEVERITY_WARNING, "Takeoff cancelled"),
                        );
                        return out;
                    }
                    self.takeoff_alt_m = None;
                }
                self.last_setpoint = Some((self.now_s, target));
                self.target_ned_m = Some(target);
                self.target_vel_ned_mps = velocity;
            }
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
            // field flight, session 12); a companion-only flight is not a lost GCS.
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

    /// The geofence from the flavour's parameters, around home: PX4 GF_MAX_HOR_DIST /
    /// GF_MAX_VER_DIST (0 = off) with GF_ACTION; ArduPilot FENCE_ENABLE, FENCE_TYPE (bit 0
    /// altitude, bit 1 circle), FENCE_RADIUS, FENCE_ALT_MAX with FENCE_ACTION.
    fn check_geofence(&mut self, out: &mut Vec<MavMessage>) {
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

    fn time_boot_ms(&self) -> u32 {
        ((self.now_s - self.boot_s) * 1e3) as u32
    }

    fn telemetry(&self, id: u32) -> Option<MavMessage> {
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
        let origin = crate::geodesy::GeodeticWgs84 {
            lat_deg: self.cfg.origin_lat_deg,
            lon_deg: self.cfg.origin_lon_deg,
            alt_m: self.cfg.origin_alt_m,
        };
        let p = self.state.pos_ned_m;
        let here = origin.offset_by_enu([p[1], p[0], -p[2]]);
        (here.lat_deg, here.lon_deg)
    }
}

mod pilot;
mod stock;

#[cfg(test)]
mod tests;
