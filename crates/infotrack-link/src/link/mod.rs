//! The vehicle link: MAVLink 2 to a PX4 or ArduPilot autopilot, on tokio.
//!
//! One connection shared by three tasks: a reader that keeps the vehicle's state current and
//! publishes events (acks, parameter values, status texts, mode changes), a 1 Hz HEARTBEAT
//! as MAV_TYPE_ONBOARD_CONTROLLER, and (once tracking starts) a setpoint streamer that sends
//! SET_POSITION_TARGET_LOCAL_NED at >= 10 Hz. Commands wait for their COMMAND_ACK with a
//! timeout and retries; a vehicle that never answers is an error, not a hang.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use parking_lot::Mutex;
use std::time::Duration;
use tokio::time::Instant;

use super::connection::{is_dead_stream, Connection};

use mavlink::dialects::ardupilotmega::*;
use mavlink::MavHeader;
use thiserror::Error;
use tokio::sync::broadcast;
use tokio::task::JoinHandle;

use super::modes::{Flavor, Mode};
use super::params_file::{decode_wire, encode_wire, ParamType};
use super::params_file::{mav_param_type_of, param_type_of};
use super::signing::SigningKey;
use infotrack_core::frames::{yaw_enu_to_ned, yaw_ned_to_enu, Enu2, PositionEnu, PositionNed};
use infotrack_core::geodesy::WorldPlacement;
use infotrack_core::world::geometry::BoundsEnu;

mod flight;
mod inbound;
mod params;
pub mod plausible;
mod stream;
mod tasks;
mod url;

pub use inbound::fuzz;
use inbound::{on_message, Ids};
pub use params::ParamList;
pub use stream::SetpointStats;
use stream::{
    position_target, vehicle_to_world_ned, world_to_vehicle_ned, StreamedTarget, Streamer,
};
use tasks::{spawn_heartbeat, spawn_reader, spawn_streamer, spawn_watchdog};
pub use url::{check_url, BadUrl};

/// Why a link operation failed.
#[derive(Debug, Error)]
pub enum LinkError {
    /// The connection URL is malformed or could not be opened.
    #[error("cannot open MAVLink connection `{url}`: {message}")]
    Connect {
        /// The URL.
        url: String,
        /// Why.
        message: String,
    },
    /// No HEARTBEAT from an autopilot in time.
    #[error("no autopilot heartbeat on `{url}` within {seconds} s{hint}")]
    NoVehicle {
        /// The URL.
        url: String,
        /// How long we waited.
        seconds: f64,
        /// What the link saw that explains it (a signing mismatch), as `; ...`, or empty.
        hint: String,
    },
    /// A command was never acknowledged.
    #[error("{command:?}: no COMMAND_ACK after {attempts} attempts{hint}")]
    NoAck {
        /// The command.
        command: MavCmd,
        /// Attempts made.
        attempts: u32,
        /// What the link saw that explains it (a signing mismatch), as `; ...`, or empty.
        hint: String,
    },
    /// The vehicle refused a command.
    #[error("{command:?} refused by the vehicle: {result:?}")]
    Refused {
        /// The command.
        command: MavCmd,
        /// The vehicle's answer.
        result: MavResult,
    },
    /// The vehicle kept refusing to arm until the takeoff's time was up.
    #[error("MAV_CMD_COMPONENT_ARM_DISARM refused by the vehicle for {seconds:.0} s; its last reason: {reason}")]
    NotReadyToArm {
        /// What the vehicle said last (its STATUSTEXT), or its COMMAND_ACK result.
        reason: String,
        /// How long arming was retried, s.
        seconds: f64,
    },
    /// The vehicle kept refusing a mode change as temporary until the time was up.
    #[error("MAV_CMD_DO_SET_MODE to {mode} refused by the vehicle for {seconds:.0} s; its last reason: {reason}")]
    ModeRejected {
        /// The mode asked for.
        mode: Mode,
        /// What the vehicle said last (its STATUSTEXT), or its COMMAND_ACK result.
        reason: String,
        /// How long the change was retried, s.
        seconds: f64,
    },
    /// The firmware has no such mode.
    #[error("{flavor} has no mode {mode:?}")]
    NoSuchMode {
        /// The firmware.
        flavor: Flavor,
        /// The mode.
        mode: Mode,
    },
    /// Something did not happen in time.
    #[error("timed out after {seconds} s waiting for {what}")]
    Timeout {
        /// What.
        what: String,
        /// How long.
        seconds: f64,
    },
    /// The takeoff stopped before its altitude: the vehicle disarmed or left the climb's
    /// mode.
    #[error("takeoff abandoned: {why}")]
    TakeoffAbandoned {
        /// What happened, with the vehicle's height, mode and last message.
        why: String,
    },
    /// A parameter is not on the vehicle.
    #[error("the vehicle has no parameter {0}")]
    NoSuchParam(String),
    /// A setpoint outside the geofence was asked for.
    #[error("setpoint ({x:.2}, {y:.2}) m ENU is outside the geofence")]
    OutsideGeofence {
        /// East, m.
        x: f64,
        /// North, m.
        y: f64,
    },
    /// A setpoint with a NaN or infinite coordinate or heading was asked for (never sent).
    #[error("setpoint with a non-finite position, velocity or yaw refused")]
    NonFiniteSetpoint,
    /// The hold's altitude correction is larger than a position loop's wander: the
    /// vehicle's state is not to be trusted, so the hold keeps its own altitude.
    #[error("an altitude correction of {0:.1} m is larger than a position loop's wander")]
    ImplausibleHold(f64),
    /// A command needs telemetry the vehicle has not sent yet.
    #[error("no {0} from the vehicle yet")]
    NoTelemetry(&'static str),
    /// Sending failed.
    #[error("MAVLink send failed: {0}")]
    Send(String),
}

/// Link settings.
#[derive(Debug, Clone)]
pub struct LinkConfig {
    /// `udpin:HOST:PORT`, `udpout:HOST:PORT`, `tcpin:`, `tcpout:`, `serial:PATH:BAUD`.
    pub url: String,
    /// Own system id.
    pub system_id: u8,
    /// Own component id (191: MAV_COMP_ID_ONBOARD_COMPUTER).
    pub component_id: u8,
    /// How long one command attempt waits for its ACK.
    pub ack_timeout: Duration,
    /// Attempts per command; also how many heartbeat periods (at least three) an accepted
    /// arm or mode change may take to show in the heartbeat on a lossy link.
    pub attempts: u32,
    /// Setpoint rate, Hz (PX4 needs > 2; use >= 10).
    pub setpoint_hz: f64,
    /// Where setpoints may go, world ENU (the geofence).
    pub geofence_enu: Option<BoundsEnu>,
    /// MAVLink 2 signing: when set, everything sent is signed and only frames signed with
    /// this key are accepted.
    pub signing_key: Option<SigningKey>,
    /// Signing link id (tells our streams apart from other signers with the same key).
    pub signing_link_id: u8,
    /// The vehicle counts as lost after this long without its heartbeat.
    pub heartbeat_timeout: Duration,
    /// Log every message sent and received to this telemetry log (.tlog).
    pub tlog: Option<std::path::PathBuf>,
    /// The vehicle's system and component id; `None`: the first autopilot heard. Either
    /// way the link locks onto one vehicle and ignores (and reports once) every other.
    pub vehicle: Option<(u8, u8)>,
    /// What the vehicle can fly: telemetry beyond it is dropped.
    pub envelope: plausible::Envelope,
}

impl LinkConfig {
    /// Defaults for `url`: system 1, component 191, 0.5 s ACK timeout, 5 attempts, 20 Hz.
    pub fn new(url: &str) -> Self {
        Self {
            url: url.to_string(),
            system_id: 1,
            component_id: 191,
            ack_timeout: Duration::from_millis(500),
            attempts: 5,
            setpoint_hz: 20.0,
            geofence_enu: None,
            signing_key: None,
            signing_link_id: 1,
            heartbeat_timeout: Duration::from_secs(3),
            tlog: None,
            vehicle: None,
            envelope: plausible::Envelope::default(),
        }
    }
}

type SharedState = Arc<Mutex<VehicleState>>;

/// The ICAO address the target estimate is reported under (`send_target_on_map`): in the
/// range ICAO leaves unassigned to aircraft (0xF00000 and up), so it is never a real one.
pub const TARGET_ICAO_ADDRESS: u32 = 0xF1_7A_60;

/// What the link saw, for waiters.
#[derive(Debug, Clone)]
pub enum LinkEvent {
    /// A COMMAND_ACK addressed to us (or to everyone).
    Ack {
        /// The command.
        command: MavCmd,
        /// The result.
        result: MavResult,
    },
    /// A PARAM_VALUE.
    Param {
        /// Name.
        name: String,
        /// Raw float as sent.
        wire: f32,
        /// Type.
        ty: Option<ParamType>,
        /// Index (65535 for an ArduPilot read by name).
        index: u16,
        /// Count.
        count: u16,
    },
    /// A STATUSTEXT.
    Text(String),
    /// The vehicle changed mode; `commanded` is false when we did not ask for it (a
    /// failsafe, the pilot).
    ModeChanged {
        /// Old mode.
        from: Mode,
        /// New mode.
        to: Mode,
        /// Whether this link asked for it.
        commanded: bool,
    },
    /// No heartbeat from the vehicle for the configured timeout.
    VehicleLost,
    /// Heartbeats again after [`LinkEvent::VehicleLost`].
    VehicleBack,
    /// The vehicle's boot clock went backwards: it rebooted (and is disarmed).
    VehicleRebooted,
    /// A GPS_GLOBAL_ORIGIN other than the one the world was placed with.
    OriginChanged,
}

/// The vehicle as the link last saw it.
#[derive(Debug, Clone, Default)]
pub struct VehicleState {
    /// Firmware, from its heartbeat.
    pub flavor: Option<Flavor>,
    /// Its system and component id.
    pub address: Option<(u8, u8)>,
    /// Time of its last heartbeat.
    pub last_heartbeat: Option<Instant>,
    /// Mode.
    pub mode: Option<Mode>,
    /// Armed.
    pub armed: bool,
    /// LOCAL_POSITION_NED (position, velocity) and when it arrived, in the vehicle's own
    /// local NED frame (`VehicleLink::local_ned_in_world` gives it in the world's).
    pub local_ned: Option<(Instant, PositionNed, [f32; 3])>,
    /// ATTITUDE roll, pitch, yaw (NED), rad, and when.
    pub attitude: Option<(Instant, [f32; 3])>,
    /// GLOBAL_POSITION_INT lat, lon (deg), relative altitude (m), and when.
    pub global: Option<(Instant, f64, f64, f64)>,
    /// GLOBAL_POSITION_INT's altitude above mean sea level minus its relative altitude: the
    /// height of the vehicle's home, m (AMSL).
    pub home_alt_amsl_m: Option<f64>,
    /// GPS_GLOBAL_ORIGIN: where the vehicle's local NED frame is on Earth (its estimator's
    /// origin). Heights are AMSL as the message gives them.
    pub global_origin: Option<infotrack_core::geodesy::GeodeticWgs84>,
    /// HOME_POSITION: home on Earth (heights AMSL) and in the vehicle's local NED frame.
    pub home_position: Option<(infotrack_core::geodesy::GeodeticWgs84, PositionNed)>,
    /// The origin the world was placed with ([`VehicleLink::place_in_world`]): fixed for
    /// the flight.
    pub origin_fixed: Option<infotrack_core::geodesy::GeodeticWgs84>,
    /// A GPS_GLOBAL_ORIGIN that differs from `origin_fixed`, once heard: the world would
    /// move under the vehicle, so the daemon holds.
    pub origin_changed: Option<infotrack_core::geodesy::GeodeticWgs84>,
    /// EXTENDED_SYS_STATE landed state and when.
    pub landed: Option<(Instant, MavLandedState)>,
    /// SYS_STATUS battery voltage (V) and when.
    pub battery_v: Option<(Instant, f64)>,
    /// Mode changes the link did not ask for once the vehicle had armed (failsafes, the
    /// pilot, a GCS), newest last.
    pub unexpected_mode_changes: Vec<(Mode, Mode)>,
    /// Mode changes the link did not ask for before the vehicle first armed: ArduCopter
    /// takes a mode set while it starts up and resets it to STABILIZE when its start-up
    /// completes ("ArduPilot Ready"; seen on the SITL build), a pilot choosing a mode on the
    /// ground. Reported apart from the failsafes.
    pub mode_changes_before_arming: Vec<(Mode, Mode)>,
    /// The vehicle has reported itself armed at least once.
    pub has_armed: bool,
    /// Mode changes the link did not ask for, all of them (the lists keep the first 64).
    pub own_mode_changes: u64,
    /// The mode the link last asked for.
    pub commanded_mode: Option<Mode>,
    /// No heartbeat for the configured timeout (cleared by the next one).
    pub lost: bool,
    /// Times the link saw the vehicle's boot clock restart.
    pub reboots: u32,
    /// Latest time_boot_ms seen in telemetry, ms.
    pub time_boot_ms: Option<u32>,
    /// Other autopilots heard (system, component) and ignored: the link is locked to
    /// `address`.
    pub ignored_autopilots: std::collections::BTreeSet<(u8, u8)>,
    /// Telemetry messages dropped for a NaN or infinite field.
    pub non_finite_dropped: u64,
    /// Telemetry messages dropped as beyond what the vehicle can have flown
    /// (`plausible.rs`).
    pub implausible_dropped: u64,
    /// The tracks telemetry is judged against.
    pub plausibility: Plausibility,
}

/// What telemetry is judged against: the envelope and the accepted tracks of the local and
/// the global position.
#[derive(Debug, Clone, Default)]
pub struct Plausibility {
    /// What the vehicle can do.
    pub envelope: plausible::Envelope,
    /// LOCAL_POSITION_NED's track (north, east; up).
    local: plausible::Track,
    /// GLOBAL_POSITION_INT's track, metres about `global_ref` and AMSL.
    global: plausible::Track,
    /// The height of home GLOBAL_POSITION_INT implies (AMSL minus relative), m.
    home: plausible::Track,
    /// The first accepted GLOBAL_POSITION_INT (lat, lon, deg): where its metres are taken.
    global_ref: Option<(f64, f64)>,
}

/// A running link to one vehicle.
pub struct VehicleLink {
    cfg: LinkConfig,
    conn: Arc<Connection>,
    state: Arc<Mutex<VehicleState>>,
    events: broadcast::Sender<LinkEvent>,
    heartbeat_paused: Arc<AtomicBool>,
    streamer: Arc<Streamer>,
    tlog: Option<Arc<super::tlog::Tlog>>,
    tasks: Vec<JoinHandle<()>>,
    /// When the link was opened (our uptime for time_boot_ms).
    started: Instant,
}

impl Drop for VehicleLink {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

impl VehicleLink {
    /// Opens the connection and starts the reader, heartbeat and (idle) setpoint tasks.
    pub async fn connect(cfg: LinkConfig) -> Result<Self, LinkError> {
        check_url(&cfg.url).map_err(|e| LinkError::Connect {
            url: cfg.url.clone(),
            message: e.0,
        })?;
        let tlog = match &cfg.tlog {
            Some(p) => Some(Arc::new(super::tlog::Tlog::create(p).map_err(|e| {
                LinkError::Connect {
                    url: cfg.url.clone(),
                    message: format!("cannot create the telemetry log {}: {e}", p.display()),
                }
            })?)),
            None => None,
        };
        let conn = Connection::open(
            &cfg.url,
            cfg.signing_key.clone().map(|k| (k, cfg.signing_link_id)),
        )
        .await
        .map_err(|e| LinkError::Connect {
            url: cfg.url.clone(),
            message: e.to_string(),
        })?
        .with_tlog(tlog.clone());
        let conn = Arc::new(conn);
        let state = Arc::new(Mutex::new(VehicleState {
            plausibility: Plausibility {
                envelope: cfg.envelope,
                ..Plausibility::default()
            },
            ..VehicleState::default()
        }));
        let (events, _) = broadcast::channel(1024);
        let header = MavHeader {
            system_id: cfg.system_id as u32,
            component_id: cfg.component_id,
            sequence: 0,
        };
        let heartbeat_paused = Arc::new(AtomicBool::new(false));
        let streamer = Arc::new(Streamer {
            target_ned: Mutex::new(None),
            geofence_enu: cfg.geofence_enu,
            paused: AtomicBool::new(false),
            placement: Mutex::new(None),
            sent: Mutex::new(SetpointStats::default()),
        });

        let me = (cfg.system_id, cfg.component_id);
        let reader = spawn_reader(
            conn.clone(),
            state.clone(),
            events.clone(),
            Ids {
                me,
                vehicle: cfg.vehicle,
            },
        );
        let heartbeat = spawn_heartbeat(conn.clone(), heartbeat_paused.clone(), header);
        let watchdog = spawn_watchdog(state.clone(), events.clone(), cfg.heartbeat_timeout);
        let period = Duration::from_secs_f64(1.0 / cfg.setpoint_hz.max(1.0));
        let stream = spawn_streamer(
            conn.clone(),
            streamer.clone(),
            state.clone(),
            header,
            period,
        );
        Ok(Self {
            cfg,
            conn,
            state,
            events,
            heartbeat_paused,
            streamer,
            tlog,
            tasks: vec![reader, heartbeat, watchdog, stream],
            started: Instant::now(),
        })
    }

    fn header(&self) -> MavHeader {
        MavHeader {
            system_id: self.cfg.system_id as u32,
            component_id: self.cfg.component_id,
            sequence: 0,
        }
    }

    /// A copy of the vehicle state.
    pub fn state(&self) -> VehicleState {
        self.state.lock().clone()
    }

    /// Subscribes to link events.
    pub fn events(&self) -> broadcast::Receiver<LinkEvent> {
        self.events.subscribe()
    }

    /// A signing mismatch seen on this link, in a sentence, if any (see
    /// [`Connection::signing_diagnosis`]).
    pub fn signing_diagnosis(&self) -> Option<String> {
        self.conn.signing_diagnosis()
    }

    /// Why the vehicle may be silent toward us, as `; <sentence>`, or empty.
    fn silence_hint(&self) -> String {
        self.signing_diagnosis()
            .map(|d| format!("; {d}"))
            .unwrap_or_default()
    }

    /// Waits for an autopilot's heartbeat; returns its flavour.
    pub async fn wait_vehicle(&self, timeout: Duration) -> Result<Flavor, LinkError> {
        let until = Instant::now() + timeout;
        loop {
            if let Some(f) = self.state().flavor {
                return Ok(f);
            }
            if Instant::now() > until {
                return Err(LinkError::NoVehicle {
                    url: self.cfg.url.clone(),
                    seconds: timeout.as_secs_f64(),
                    hint: self.silence_hint(),
                });
            }
            // udpout/tcpout peers learn our address from what we send.
            self.send(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                mavlink_version: 3,
                ..Default::default()
            }))
            .await
            .ok();
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// The vehicle's firmware (PX4 until a heartbeat has said otherwise).
    pub fn flavor(&self) -> Flavor {
        self.state().flavor.unwrap_or(Flavor::Px4)
    }

    fn target(&self) -> (u8, u8) {
        self.state().address.unwrap_or((1, 1))
    }

    async fn send(&self, m: &MavMessage) -> Result<(), LinkError> {
        self.conn
            .send(&self.header(), m)
            .await
            .map(|_| ())
            .map_err(|e| LinkError::Send(e.to_string()))
    }

    /// A STATUSTEXT to the ground station (cut to MAVLink's 50 characters).
    pub async fn send_statustext(
        &self,
        severity: MavSeverity,
        text: &str,
    ) -> Result<(), LinkError> {
        let cut: String = text.chars().take(50).collect();
        self.send(&MavMessage::STATUSTEXT(STATUSTEXT_DATA {
            severity,
            text: cut.as_str().into(),
            ..Default::default()
        }))
        .await
    }

    /// A NAMED_VALUE_FLOAT (name cut to 10 characters), time-stamped with our uptime.
    pub async fn send_named_value(&self, name: &str, value: f32) -> Result<(), LinkError> {
        let cut: String = name.chars().take(10).collect();
        self.send(&MavMessage::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
            time_boot_ms: self.started.elapsed().as_millis() as u32,
            name: cut.as_str().into(),
            value,
        }))
        .await
    }

    /// The tracker's target estimate as an ADS-B traffic report (ADSB_VEHICLE, callsign
    /// `TARGET`, ICAO address [`TARGET_ICAO_ADDRESS`]): QGroundControl and Mission Planner
    /// draw ADS-B traffic on their maps, so the operator sees the estimate move there.
    /// `ground_alt_amsl_m`: the ground's height above mean sea level.
    pub async fn send_target_on_map(
        &self,
        at: infotrack_core::geodesy::GeodeticWgs84,
        ground_alt_amsl_m: f64,
    ) -> Result<(), LinkError> {
        if !(at.lat_deg.is_finite() && at.lon_deg.is_finite() && ground_alt_amsl_m.is_finite()) {
            return Err(LinkError::NonFiniteSetpoint);
        }
        self.send(&MavMessage::ADSB_VEHICLE(ADSB_VEHICLE_DATA {
            ICAO_address: TARGET_ICAO_ADDRESS,
            lat: (at.lat_deg * 1e7).round() as i32,
            lon: (at.lon_deg * 1e7).round() as i32,
            altitude_type: AdsbAltitudeType::ADSB_ALTITUDE_TYPE_GEOMETRIC,
            altitude: (ground_alt_amsl_m * 1e3).round() as i32,
            callsign: "TARGET".into(),
            emitter_type: AdsbEmitterType::ADSB_EMITTER_TYPE_SERVICE_SURFACE,
            tslc: 1,
            flags: AdsbFlags::ADSB_FLAGS_VALID_COORDS
                | AdsbFlags::ADSB_FLAGS_VALID_ALTITUDE
                | AdsbFlags::ADSB_FLAGS_VALID_CALLSIGN,
            ..Default::default()
        }))
        .await
    }

    /// COMMAND_LONG with retries; Ok only for MAV_RESULT_ACCEPTED.
    pub async fn command(&self, command: MavCmd, p: [f32; 7]) -> Result<(), LinkError> {
        let (ts, tc) = self.target();
        let mut rx = self.events.subscribe();
        for attempt in 0..self.cfg.attempts {
            let m = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: p[0],
                param2: p[1],
                param3: p[2],
                param4: p[3],
                param5: p[4],
                param6: p[5],
                param7: p[6],
                command,
                target_system: ts,
                target_component: tc,
                confirmation: attempt.min(255) as u8,
            });
            self.send(&m).await?;
            let until = tokio::time::Instant::now() + self.cfg.ack_timeout;
            loop {
                match tokio::time::timeout_at(until, rx.recv()).await {
                    Ok(Ok(LinkEvent::Ack { command: c, result })) if c == command => {
                        return match result {
                            MavResult::MAV_RESULT_ACCEPTED => Ok(()),
                            MavResult::MAV_RESULT_IN_PROGRESS => continue,
                            r => Err(LinkError::Refused { command, result: r }),
                        };
                    }
                    Ok(Ok(_)) | Ok(Err(broadcast::error::RecvError::Lagged(_))) => continue,
                    Ok(Err(broadcast::error::RecvError::Closed)) | Err(_) => break,
                }
            }
        }
        Err(LinkError::NoAck {
            command,
            attempts: self.cfg.attempts,
            hint: self.silence_hint(),
        })
    }

    /// MAV_CMD_REQUEST_MESSAGE: the vehicle sends message `id` once.
    pub async fn request_message(&self, id: u32) -> Result<(), LinkError> {
        self.command(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [id as f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await
    }

    /// MAV_CMD_SET_MESSAGE_INTERVAL for message `id` at `hz`.
    pub async fn set_message_rate(&self, id: u32, hz: f64) -> Result<(), LinkError> {
        self.command(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [id as f32, (1e6 / hz) as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await
    }

    /// Asks for the telemetry the tracker reads: LOCAL_POSITION_NED and ATTITUDE at 30 Hz,
    /// GLOBAL_POSITION_INT at 10 Hz, EXTENDED_SYS_STATE and SYS_STATUS at 2 Hz.
    pub async fn request_telemetry(&self) -> Result<(), LinkError> {
        for (id, hz) in [(32, 30.0), (30, 30.0), (33, 10.0), (245, 2.0), (1, 2.0)] {
            self.set_message_rate(id, hz).await?;
        }
        Ok(())
    }

    /// Sets the position the streamer sends (world ENU, yaw ENU), refusing points outside the
    /// geofence. The stream starts with the first setpoint.
    pub fn set_setpoint(&self, p: PositionEnu, yaw_enu_rad: f64) -> Result<(), LinkError> {
        self.set_moving_setpoint(p, Enu2::zeros(), yaw_enu_rad)
    }

    /// Streams a setpoint that starts at `p` now and moves at `velocity_enu` (m/s,
    /// horizontal), sent as position + velocity (the velocity is the autopilot's
    /// feed-forward); it stops at the geofence's edge. A zero velocity sends position-only
    /// targets.
    pub fn set_moving_setpoint(
        &self,
        p: PositionEnu,
        velocity_enu: Enu2,
        yaw_enu_rad: f64,
    ) -> Result<(), LinkError> {
        if let Some(g) = &self.cfg.geofence_enu {
            if !g.contains(&p.xy()) {
                return Err(LinkError::OutsideGeofence {
                    x: p.x_east_m,
                    y: p.y_north_m,
                });
            }
        }
        let finite = [
            p.x_east_m,
            p.y_north_m,
            p.z_up_m,
            velocity_enu.x,
            velocity_enu.y,
            yaw_enu_rad,
        ]
        .iter()
        .all(|v| v.is_finite());
        if !finite {
            return Err(LinkError::NonFiniteSetpoint);
        }
        let v = PositionEnu::from_xy(&velocity_enu, 0.0).to_ned();
        *self.streamer.target_ned.lock() = Some(StreamedTarget {
            position_ned: p.to_ned(),
            velocity_ned: [v.x_north_m, v.y_east_m, 0.0],
            yaw_ned: yaw_enu_to_ned(yaw_enu_rad) as f32,
            since: Instant::now(),
        });
        Ok(())
    }

    /// Flushes the telemetry log, if any.
    pub fn flush_tlog(&self) {
        if let Some(t) = &self.tlog {
            if let Err(e) = t.flush() {
                tracing::warn!("telemetry log: {e}");
            }
        }
    }

    /// How the setpoint stream went so far.
    pub fn setpoint_stats(&self) -> SetpointStats {
        *self.streamer.sent.lock()
    }

    /// Pauses or resumes the setpoint stream (tests; a stalled companion).
    pub fn pause_setpoints(&self, paused: bool) {
        self.streamer.paused.store(paused, Ordering::Relaxed);
    }

    /// Pauses or resumes our heartbeat (tests; a stalled companion).
    pub fn pause_heartbeat(&self, paused: bool) {
        self.heartbeat_paused.store(paused, Ordering::Relaxed);
    }

    /// Current position, world ENU, if known.
    pub fn position_enu(&self) -> Option<PositionEnu> {
        self.local_ned_in_world().map(|(_, p, _)| p.to_enu())
    }

    /// LOCAL_POSITION_NED (when it arrived, position, velocity) with the position in the
    /// world frame's NED axes: the vehicle's local NED as it reports it, moved by the
    /// placement (unchanged without one). The velocity keeps its components.
    pub fn local_ned_in_world(&self) -> Option<(Instant, PositionNed, [f32; 3])> {
        let placement = self.streamer.placement();
        self.state()
            .local_ned
            .map(|(at, p, v)| (at, vehicle_to_world_ned(placement.as_ref(), p), v))
    }

    /// Anchors the vehicle's local frame in the world's (`[world] origin` and the vehicle's
    /// GPS_GLOBAL_ORIGIN): from now on positions read through [`Self::position_enu`] and
    /// [`Self::local_ned_in_world`] and every setpoint are converted between the two.
    pub fn place_in_world(&self, placement: WorldPlacement) {
        *self.streamer.placement.lock() = Some(placement);
        let mut s = self.state.lock();
        s.origin_fixed = s.global_origin;
    }
}

#[cfg(test)]
mod tests;
