//! The vehicle link: MAVLink 2 to a PX4 or ArduPilot autopilot, on tokio.
//!
//! One connection shared by three tasks: a reader that keeps the vehicle's state current and
//! publishes events (acks, parameter values, status texts, mode changes), a 1 Hz HEARTBEAT
//! as MAV_TYPE_ONBOARD_CONTROLLER, and (once tracking starts) a setpoint streamer that sends
//! SET_POSITION_TARGET_LOCAL_NED at >= 10 Hz. Commands wait for their COMMAND_ACK with a
//! timeout and retries; a vehicle that never answers is an error, not a hang.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
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
use crate::frames::{yaw_enu_to_ned, Enu2, PositionEnu, PositionNed};
use crate::geodesy::WorldPlacement;
use crate::world::geometry::BoundsEnu;

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
    /// A setpoint with a NaN or infinite coordinate was asked for (never sent).
    #[error("setpoint with a non-finite position or velocity refused")]
    NonFiniteSetpoint,
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
    /// Attempts per command.
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
        }
    }
}

type SharedTlog = Option<Arc<super::tlog::Tlog>>;
type SharedState = Arc<Mutex<VehicleState>>;

/// The ICAO address the target estimate is reported under (`send_target_on_map`): in the
/// range ICAO leaves unassigned to aircraft (0xF00000 and up), so it is never a real one.
pub const TARGET_ICAO_ADDRESS: u32 = 0xF1_7A_60;

/// The newest STATUSTEXT waiting in `rx`, into `said` (events lost to a lagging receiver
/// are skipped).
fn latest_text(rx: &mut broadcast::Receiver<LinkEvent>, said: &mut Option<String>) {
    loop {
        match rx.try_recv() {
            Ok(LinkEvent::Text(t)) => *said = Some(t),
            Ok(_) | Err(broadcast::error::TryRecvError::Lagged(_)) => {}
            Err(_) => return,
        }
    }
}

/// The reader: every message into the tlog and the vehicle state; a dead stream reopened.
fn spawn_reader(
    conn: Arc<Connection>,
    tlog: SharedTlog,
    state: SharedState,
    events: broadcast::Sender<LinkEvent>,
    ids: Ids,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        loop {
            match conn.recv().await {
                Ok((h, m)) => {
                    if let Some(t) = &tlog {
                        t.record(&h, &m);
                    }
                    on_message(&state, &events, ids, &h, &m)
                }
                Err(e) if conn.reopens() && is_dead_stream(&e) => {
                    tracing::error!("link: {e}: the connection is gone; reopening");
                    conn.reopen(|| false).await;
                }
                Err(e) => {
                    tracing::debug!("link: receive error: {e}");
                    tokio::time::sleep(Duration::from_millis(5)).await;
                }
            }
        }
    })
}

/// Our heartbeat, once a second (unless paused by a test of the vehicle's failsafe).
fn spawn_heartbeat(
    conn: Arc<Connection>,
    tlog: SharedTlog,
    paused: Arc<AtomicBool>,
    header: MavHeader,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut t = tokio::time::interval(Duration::from_secs(1));
        loop {
            t.tick().await;
            if paused.load(Ordering::Relaxed) {
                continue;
            }
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            });
            if let Some(t) = &tlog {
                t.record(&header, &hb);
            }
            let _ = conn.send(&header, &hb).await;
        }
    })
}

/// Declares the vehicle lost when its heartbeat is older than `timeout`.
fn spawn_watchdog(
    state: SharedState,
    events: broadcast::Sender<LinkEvent>,
    timeout: Duration,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut t = tokio::time::interval(Duration::from_millis(100));
        loop {
            t.tick().await;
            let mut s = state.lock().expect("state poisoned");
            let stale = s.last_heartbeat.is_some_and(|h| h.elapsed() > timeout);
            if stale && !s.lost {
                s.lost = true;
                tracing::warn!("vehicle lost: no heartbeat for {timeout:?}");
                let _ = events.send(LinkEvent::VehicleLost);
            }
        }
    })
}

/// The setpoint stream: the current target every `period`, unless paused.
fn spawn_streamer(
    conn: Arc<Connection>,
    tlog: SharedTlog,
    streamer: Arc<Streamer>,
    state: SharedState,
    header: MavHeader,
    period: Duration,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut t = tokio::time::interval(period);
        t.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let start = Instant::now();
        loop {
            t.tick().await;
            if streamer.paused.load(Ordering::Relaxed) {
                continue;
            }
            let Some(target_sp) = *streamer.target_ned.lock().expect("streamer poisoned") else {
                continue;
            };
            let (p, v) = target_sp.at(Instant::now(), streamer.geofence_enu.as_ref());
            let p = world_to_vehicle_ned(streamer.placement().as_ref(), p);
            // No vehicle locked yet: a setpoint has nobody to go to.
            let Some(target) = state.lock().expect("state poisoned").address else {
                continue;
            };
            let m = position_target(
                target,
                p,
                v,
                target_sp.yaw_ned,
                start.elapsed().as_millis() as u32,
            );
            if let Some(t) = &tlog {
                t.record(&header, &m);
            }
            let _ = conn.send(&header, &m).await;
        }
    })
}

/// A MAVLink connection URL that is not one, and why.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{0}")]
pub struct BadUrl(pub String);

/// Checks a connection URL before handing it to the transport, for a clear error.
pub fn check_url(url: &str) -> Result<(), BadUrl> {
    url_reason(url).map_err(BadUrl)
}

fn url_reason(url: &str) -> Result<(), String> {
    let (scheme, rest) = url.split_once(':').ok_or_else(|| {
        "expected SCHEME:ADDRESS, e.g. udpin:0.0.0.0:14540 or serial:/dev/ttyAMA0:921600"
            .to_string()
    })?;
    let (a, b) = rest
        .rsplit_once(':')
        .ok_or_else(|| format!("`{rest}` needs a final `:PORT` (or `:BAUD` for serial)"))?;
    match scheme {
        "udpin" | "udpout" | "tcpin" | "tcpout" | "udpbcast" => {
            b.parse::<u16>()
                .map_err(|_| format!("port `{b}` is not a number 0-65535"))?;
            if a.is_empty() {
                return Err("missing host".into());
            }
        }
        "serial" => {
            b.parse::<u32>()
                .map_err(|_| format!("baud rate `{b}` is not a number"))?;
            if a.is_empty() {
                return Err("missing serial device path".into());
            }
        }
        other => {
            return Err(format!(
                "unknown scheme `{other}` (udpin, udpout, tcpin, tcpout, serial)"
            ))
        }
    }
    Ok(())
}

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
    pub global_origin: Option<crate::geodesy::GeodeticWgs84>,
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
}

struct Streamer {
    /// In the world frame's NED axes (converted to the vehicle's frame when sent).
    target_ned: Mutex<Option<StreamedTarget>>,
    paused: AtomicBool,
    /// Where a moving setpoint stops (world ENU).
    geofence_enu: Option<BoundsEnu>,
    /// Where the vehicle's local frame lies in the world's; None: they are the same frame.
    placement: Mutex<Option<WorldPlacement>>,
}

impl Streamer {
    fn placement(&self) -> Option<WorldPlacement> {
        *self.placement.lock().expect("placement poisoned")
    }
}

/// A position in the world frame's NED axes, in the vehicle's local NED frame (the same
/// without a placement). Heights are not converted (see [`WorldPlacement`]).
fn world_to_vehicle_ned(placement: Option<&WorldPlacement>, p: PositionNed) -> PositionNed {
    match placement {
        None => p,
        Some(pl) => horizontally(p, |en| pl.world_to_vehicle_en_m(en)),
    }
}

/// The inverse of [`world_to_vehicle_ned`]: the vehicle's local NED in the world's axes.
fn vehicle_to_world_ned(placement: Option<&WorldPlacement>, p: PositionNed) -> PositionNed {
    match placement {
        None => p,
        Some(pl) => horizontally(p, |en| pl.vehicle_to_world_en_m(en)),
    }
}

/// `p` with its (east, north) mapped by `f` and its height kept.
fn horizontally(p: PositionNed, f: impl Fn([f64; 2]) -> [f64; 2]) -> PositionNed {
    let [e, n] = f([p.y_east_m, p.x_north_m]);
    PositionNed {
        x_north_m: n,
        y_east_m: e,
        z_down_m: p.z_down_m,
    }
}

/// The setpoint being streamed: a point moving at a constant velocity from `since` on.
#[derive(Debug, Clone, Copy)]
struct StreamedTarget {
    position_ned: PositionNed,
    /// m/s, local NED.
    velocity_ned: [f64; 3],
    yaw_ned: f32,
    since: Instant,
}

impl StreamedTarget {
    /// Position and velocity at `now`; a setpoint that would leave the geofence stops at
    /// its edge with no velocity.
    fn at(&self, now: Instant, fence: Option<&BoundsEnu>) -> (PositionNed, [f64; 3]) {
        let dt = now.saturating_duration_since(self.since).as_secs_f64();
        let v = self.velocity_ned;
        let p = PositionNed {
            x_north_m: self.position_ned.x_north_m + v[0] * dt,
            y_east_m: self.position_ned.y_east_m + v[1] * dt,
            z_down_m: self.position_ned.z_down_m + v[2] * dt,
        };
        match fence {
            Some(f) if !f.contains(&p.to_enu().xy()) => {
                let e = p.to_enu();
                let c = f.clamp(&e.xy());
                (PositionEnu::from_xy(&c, e.z_up_m).to_ned(), [0.0; 3])
            }
            _ => (p, v),
        }
    }
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
        let conn = Connection::open(
            &cfg.url,
            cfg.signing_key.clone().map(|k| (k, cfg.signing_link_id)),
        )
        .await
        .map_err(|e| LinkError::Connect {
            url: cfg.url.clone(),
            message: e.to_string(),
        })?;
        let conn = Arc::new(conn);
        let tlog = match &cfg.tlog {
            Some(p) => Some(Arc::new(super::tlog::Tlog::create(p).map_err(|e| {
                LinkError::Connect {
                    url: cfg.url.clone(),
                    message: format!("cannot create the telemetry log {}: {e}", p.display()),
                }
            })?)),
            None => None,
        };
        let state = Arc::new(Mutex::new(VehicleState::default()));
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
        });

        let me = (cfg.system_id, cfg.component_id);
        let reader = spawn_reader(
            conn.clone(),
            tlog.clone(),
            state.clone(),
            events.clone(),
            Ids {
                me,
                vehicle: cfg.vehicle,
            },
        );
        let heartbeat =
            spawn_heartbeat(conn.clone(), tlog.clone(), heartbeat_paused.clone(), header);
        let watchdog = spawn_watchdog(state.clone(), events.clone(), cfg.heartbeat_timeout);
        let period = Duration::from_secs_f64(1.0 / cfg.setpoint_hz.max(1.0));
        let stream = spawn_streamer(
            conn.clone(),
            tlog.clone(),
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
        self.state.lock().expect("state poisoned").clone()
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
        if let Some(t) = &self.tlog {
            t.record(&self.header(), m);
        }
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
        at: crate::geodesy::GeodeticWgs84,
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

    /// MAV_CMD_DO_SET_MODE with the firmware's encoding; waits until the heartbeat shows it.
    pub async fn set_mode(&self, mode: Mode) -> Result<(), LinkError> {
        let flavor = self.flavor();
        let (p2, p3) = mode
            .do_set_mode_params(flavor)
            .ok_or(LinkError::NoSuchMode { flavor, mode })?;
        self.state.lock().expect("state poisoned").commanded_mode = Some(mode);
        self.command(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, p2, p3, 0.0, 0.0, 0.0, 0.0],
        )
        .await?;
        self.wait_for(
            |s| s.mode == Some(mode),
            &format!("mode {mode:?}"),
            Duration::from_secs(3),
        )
        .await
    }

    /// Arms (MAV_CMD_COMPONENT_ARM_DISARM, param1 = 1) and waits for the armed heartbeat.
    /// Arms, retrying while the vehicle refuses (an estimator still settling after boot:
    /// ArduCopter refuses for ~40 s with "Arm: Need Position Estimate") until `timeout`,
    /// saying each refusal's reason; the error carries the vehicle's last reason.
    pub async fn arm_when_ready(&self, timeout: Duration) -> Result<(), LinkError> {
        self.arm_in_mode_when_ready(None, timeout).await
    }

    /// [`Self::arm_when_ready`], entering `mode` again before each attempt when the vehicle
    /// is not in it: ArduCopter SITL drops a GUIDED set during its boot back to STABILIZE,
    /// and a takeoff from there is refused.
    pub async fn arm_in_mode_when_ready(
        &self,
        mode: Option<Mode>,
        timeout: Duration,
    ) -> Result<(), LinkError> {
        let until = Instant::now() + timeout;
        // One subscription for the whole wait: the vehicle's reason may come just before or
        // just after its COMMAND_ACK (the mock sends it after; the firmwares queue it).
        let mut texts = self.events();
        let mut said: Option<String> = None;
        loop {
            if let Some(m) = mode {
                if self.state().mode != Some(m) {
                    if let Err(e) = self.set_mode(m).await {
                        tracing::warn!("the vehicle refuses {m:?}: {e}; retrying");
                    }
                }
            }
            let refusal = match self.arm().await {
                Ok(()) => return Ok(()),
                Err(LinkError::Refused { result, .. }) => format!("{result:?}"),
                Err(e) => return Err(e),
            };
            // Time for a STATUSTEXT that follows the ACK.
            tokio::time::sleep(Duration::from_millis(200)).await;
            latest_text(&mut texts, &mut said);
            let reason = said.clone().unwrap_or(refusal);
            let left = until
                .saturating_duration_since(Instant::now())
                .as_secs_f64();
            if left <= 0.0 {
                return Err(LinkError::NotReadyToArm {
                    reason,
                    seconds: timeout.as_secs_f64(),
                });
            }
            tracing::warn!("the vehicle refuses to arm: {reason}; retrying ({left:.0} s left)");
            tokio::time::sleep(Duration::from_secs(2).min(Duration::from_secs_f64(left))).await;
            // A new attempt: only what the vehicle says from now on counts as its reason.
            latest_text(&mut texts, &mut None);
        }
    }

    /// Arms once.
    pub async fn arm(&self) -> Result<(), LinkError> {
        self.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await?;
        self.wait_for(|s| s.armed, "armed", Duration::from_secs(3))
            .await
    }

    /// Polls the state until `pred` holds.
    pub async fn wait_for(
        &self,
        pred: impl Fn(&VehicleState) -> bool,
        what: &str,
        timeout: Duration,
    ) -> Result<(), LinkError> {
        let until = Instant::now() + timeout;
        while !pred(&self.state()) {
            if Instant::now() > until {
                return Err(LinkError::Timeout {
                    what: what.to_string(),
                    seconds: timeout.as_secs_f64(),
                });
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
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
        if !(velocity_enu.x.is_finite() && velocity_enu.y.is_finite()) {
            return Err(LinkError::NonFiniteSetpoint);
        }
        let v = PositionEnu::from_xy(&velocity_enu, 0.0).to_ned();
        *self.streamer.target_ned.lock().expect("streamer poisoned") = Some(StreamedTarget {
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
        *self.streamer.placement.lock().expect("placement poisoned") = Some(placement);
    }

    /// Takes off to `altitude_m` above the origin and enters the tracking mode, as each
    /// firmware wants it:
    /// * PX4: stream setpoints (here, at altitude) for more than 1 s, then OFFBOARD, then arm;
    ///   the vehicle climbs to the setpoint.
    /// * ArduPilot: GUIDED, arm, MAV_CMD_NAV_TAKEOFF, wait for the altitude (a position
    ///   target sent earlier would cancel the takeoff), then stream setpoints.
    pub async fn take_off(&self, altitude_m: f64, timeout: Duration) -> Result<(), LinkError> {
        let here = self.position_enu().unwrap_or(PositionEnu {
            x_east_m: 0.0,
            y_north_m: 0.0,
            z_up_m: 0.0,
        });
        let above = PositionEnu {
            z_up_m: altitude_m,
            ..here
        };
        match self.flavor() {
            Flavor::Px4 => {
                self.set_setpoint(above, 0.0)?;
                tokio::time::sleep(Duration::from_millis(1200)).await;
                self.set_mode(Mode::Offboard).await?;
                self.arm_when_ready(timeout).await?;
            }
            Flavor::ArduPilot => {
                self.set_mode(Mode::Guided).await?;
                self.arm_in_mode_when_ready(Some(Mode::Guided), timeout)
                    .await?;
                if self.state().mode != Some(Mode::Guided) {
                    self.set_mode(Mode::Guided).await?;
                }
                self.command(
                    MavCmd::MAV_CMD_NAV_TAKEOFF,
                    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, altitude_m as f32],
                )
                .await?;
            }
        }
        let climb_mode = match self.flavor() {
            Flavor::Px4 => Mode::Offboard,
            Flavor::ArduPilot => Mode::Guided,
        };
        self.climb_to(altitude_m, climb_mode, timeout).await?;
        if self.flavor() == Flavor::ArduPilot {
            self.set_setpoint(above, 0.0)?;
        }
        Ok(())
    }

    /// Waits for the climb to 95 % of `altitude_m`. Gives up at once, saying why, when the
    /// vehicle disarms (its auto-disarm, the pilot's switch, a failsafe) or leaves
    /// `climb_mode` (the pilot or a GCS took it: never fought); on the timeout the error says
    /// how high it got, whether it was armed, its mode and its last STATUSTEXT.
    async fn climb_to(
        &self,
        altitude_m: f64,
        climb_mode: Mode,
        timeout: Duration,
    ) -> Result<(), LinkError> {
        let until = Instant::now() + timeout;
        let mut texts = self.events();
        let mut said: Option<String> = None;
        loop {
            let s = self.state();
            let up_m = s.local_ned.map(|(_, p, _)| -p.z_down_m);
            if up_m.is_some_and(|z| z >= 0.95 * altitude_m) {
                return Ok(());
            }
            latest_text(&mut texts, &mut said);
            let at = |s: &VehicleState| {
                let height = up_m.map_or("no local position".into(), |z| format!("{z:.2} m up"));
                let mode = s.mode.map_or("no mode".into(), |m| m.to_string());
                let text = said.as_deref().map_or(String::new(), |t| {
                    format!("; the vehicle's last message: \"{t}\"")
                });
                format!("{height}, {mode}{text}")
            };
            if !s.armed {
                return Err(LinkError::TakeoffAbandoned {
                    why: format!(
                        "the vehicle disarmed during the climb to {altitude_m} m ({})",
                        at(&s)
                    ),
                });
            }
            if s.mode.is_some_and(|m| m != climb_mode) {
                return Err(LinkError::TakeoffAbandoned {
                    why: format!(
                        "the vehicle left {climb_mode} during the climb to {altitude_m} m ({})",
                        at(&s)
                    ),
                });
            }
            if Instant::now() > until {
                return Err(LinkError::Timeout {
                    what: format!("altitude {altitude_m} m (armed, {})", at(&s)),
                    seconds: timeout.as_secs_f64(),
                });
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    /// Clean stop: hold position and altitude (PX4 AUTO.LOITER; ArduPilot BRAKE, else
    /// GUIDED at the current position: its LOITER descends without RC throttle) and stop
    /// streaming.
    pub async fn hold(&self) -> Result<(), LinkError> {
        let flavor = self.flavor();
        let r = self.set_mode(Mode::hold_for(flavor)).await;
        if r.is_err() && flavor == Flavor::ArduPilot {
            // BRAKE refused: GUIDED at the current position also holds altitude without RC.
            if let Some(p) = self.position_enu() {
                self.set_setpoint(p, 0.0)?;
                return self.set_mode(Mode::Guided).await;
            }
        }
        *self.streamer.target_ned.lock().expect("streamer poisoned") = None;
        r
    }

    /// Reads one parameter by name.
    pub async fn param_read(&self, name: &str) -> Result<(f64, ParamType), LinkError> {
        let (ts, tc) = self.target();
        let mut rx = self.events.subscribe();
        for _ in 0..self.cfg.attempts {
            self.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                param_index: -1,
                target_system: ts,
                target_component: tc,
                param_id: name.into(),
            }))
            .await?;
            if let Some((v, t)) = self.wait_param(&mut rx, name).await {
                return Ok((v, t));
            }
        }
        let hint = self.silence_hint();
        if !hint.is_empty() {
            // Not a missing parameter: the vehicle refuses to hear us.
            return Err(LinkError::Timeout {
                what: format!("the vehicle to answer for parameter {name}{hint}"),
                seconds: self.cfg.ack_timeout.as_secs_f64() * self.cfg.attempts as f64,
            });
        }
        Err(LinkError::NoSuchParam(name.to_string()))
    }

    /// Sets one parameter with the firmware's encoding and confirms the echoed value.
    pub async fn param_set(&self, name: &str, value: f64, ty: ParamType) -> Result<f64, LinkError> {
        let (ts, tc) = self.target();
        let flavor = self.flavor();
        let mut rx = self.events.subscribe();
        for _ in 0..self.cfg.attempts {
            self.send(&MavMessage::PARAM_SET(PARAM_SET_DATA {
                param_value: encode_wire(flavor, ty, value),
                target_system: ts,
                target_component: tc,
                param_id: name.into(),
                param_type: mav_param_type_of(ty),
            }))
            .await?;
            if let Some((v, _)) = self.wait_param(&mut rx, name).await {
                if (v - value).abs() <= 1e-6 * value.abs().max(1.0) {
                    return Ok(v);
                }
            }
        }
        Err(LinkError::Timeout {
            what: format!(
                "the vehicle to confirm {name} = {value}{}",
                self.silence_hint()
            ),
            seconds: self.cfg.ack_timeout.as_secs_f64() * self.cfg.attempts as f64,
        })
    }

    async fn wait_param(
        &self,
        rx: &mut broadcast::Receiver<LinkEvent>,
        name: &str,
    ) -> Option<(f64, ParamType)> {
        let flavor = self.flavor();
        let until = tokio::time::Instant::now() + self.cfg.ack_timeout;
        loop {
            match tokio::time::timeout_at(until, rx.recv()).await {
                Ok(Ok(LinkEvent::Param {
                    name: n,
                    wire,
                    ty: Some(t),
                    ..
                })) if n == name => {
                    return Some((decode_wire(flavor, t, wire), t));
                }
                Ok(Ok(_)) | Ok(Err(broadcast::error::RecvError::Lagged(_))) => continue,
                _ => return None,
            }
        }
    }
}

/// A local NED target: position and yaw, plus the velocity as feed-forward when it is not
/// zero. Masks: 2552 (position + yaw) and 2496 (position + velocity + yaw), which PX4's
/// offboard mode and ArduPilot's GUIDED both accept (3576 and 3520 with yaw ignored).
fn position_target(
    target: (u8, u8),
    p: PositionNed,
    v_ned: [f64; 3],
    yaw_ned: f32,
    time_boot_ms: u32,
) -> MavMessage {
    let mut mask = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
    if v_ned == [0.0; 3] {
        mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE;
    }
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms,
        x: p.x_north_m as f32,
        y: p.y_east_m as f32,
        z: p.z_down_m as f32,
        vx: v_ned[0] as f32,
        vy: v_ned[1] as f32,
        vz: v_ned[2] as f32,
        yaw: yaw_ned,
        type_mask: mask,
        target_system: target.0,
        target_component: target.1,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        ..Default::default()
    })
}

/// Follows the vehicle's boot clock; a jump back by more than a second (more than any
/// reordering on a link) is a reboot.
fn boot_clock(s: &mut VehicleState, events: &broadcast::Sender<LinkEvent>, t_ms: u32) {
    if let Some(last) = s.time_boot_ms {
        if t_ms.saturating_add(1000) < last {
            s.reboots += 1;
            tracing::warn!("vehicle rebooted (boot clock {last} ms -> {t_ms} ms)");
            let _ = events.send(LinkEvent::VehicleRebooted);
            s.time_boot_ms = Some(t_ms);
            return;
        }
    }
    s.time_boot_ms = Some(s.time_boot_ms.map_or(t_ms, |l| l.max(t_ms)));
}

// Long because it is one dispatch over the MAVLink messages the link reads, one short arm
// each, so what updates the vehicle state is in one place.
fn on_message(
    state: &Mutex<VehicleState>,
    events: &broadcast::Sender<LinkEvent>,
    ids: Ids,
    h: &MavHeader,
    m: &MavMessage,
) {
    let me = ids.me;
    let now = Instant::now();
    let mut s = state.lock().expect("state poisoned");
    let sender = (h.system_id as u8, h.component_id);
    let from_vehicle = s.address == Some(sender);
    if !from_vehicle && !matches!(m, MavMessage::HEARTBEAT(_)) {
        return;
    }
    if non_finite_telemetry(m) {
        s.non_finite_dropped += 1;
        if s.non_finite_dropped.is_power_of_two() {
            tracing::warn!(
                "dropped {} telemetry message(s) with NaN or infinite fields so far (latest: {})",
                s.non_finite_dropped,
                mavlink::Message::message_name(m)
            );
        }
        return;
    }
    match m {
        MavMessage::HEARTBEAT(hb) => {
            let flavor = match hb.autopilot {
                MavAutopilot::MAV_AUTOPILOT_PX4 => Flavor::Px4,
                MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Flavor::ArduPilot,
                _ => return, // a GCS, a camera, another companion
            };
            if !lock_onto(&mut s, ids.vehicle, sender) {
                return;
            }
            s.flavor = Some(flavor);
            s.last_heartbeat = Some(now);
            if s.lost {
                s.lost = false;
                tracing::info!("vehicle heartbeat back");
                let _ = events.send(LinkEvent::VehicleBack);
            }
            s.armed = hb
                .base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
            s.has_armed |= s.armed;
            let mode = Mode::from_custom_mode(flavor, hb.custom_mode);
            if let Some(old) = s.mode {
                if old != mode {
                    // A command explains one change: a later return to the same mode by
                    // the vehicle itself (PX4 back to OFFBOARD after a failsafe) is its own.
                    let commanded = s.commanded_mode == Some(mode);
                    if commanded {
                        s.commanded_mode = None;
                    } else if s.has_armed {
                        tracing::warn!(
                            "vehicle changed mode {old:?} -> {mode:?} by itself (failsafe?)"
                        );
                        s.unexpected_mode_changes.push((old, mode));
                    } else {
                        tracing::info!(
                            "vehicle changed mode {old:?} -> {mode:?} by itself before arming (its start-up, or the pilot on the ground)"
                        );
                        s.mode_changes_before_arming.push((old, mode));
                    }
                    let _ = events.send(LinkEvent::ModeChanged {
                        from: old,
                        to: mode,
                        commanded,
                    });
                }
            }
            s.mode = Some(mode);
        }
        MavMessage::COMMAND_ACK(a) => {
            // ACKs addressed to someone else are not ours.
            let ours = (a.target_system == 0 || a.target_system == me.0)
                && (a.target_component == 0 || a.target_component == me.1);
            if ours {
                let _ = events.send(LinkEvent::Ack {
                    command: a.command,
                    result: a.result,
                });
            }
        }
        MavMessage::LOCAL_POSITION_NED(p) => {
            boot_clock(&mut s, events, p.time_boot_ms);
            s.local_ned = Some((
                now,
                PositionNed {
                    x_north_m: p.x as f64,
                    y_east_m: p.y as f64,
                    z_down_m: p.z as f64,
                },
                [p.vx, p.vy, p.vz],
            ));
        }
        MavMessage::ATTITUDE(a) => {
            boot_clock(&mut s, events, a.time_boot_ms);
            s.attitude = Some((now, [a.roll, a.pitch, a.yaw]));
        }
        MavMessage::GLOBAL_POSITION_INT(g) => {
            s.global = Some((
                now,
                g.lat as f64 * 1e-7,
                g.lon as f64 * 1e-7,
                g.relative_alt as f64 * 1e-3,
            ));
            s.home_alt_amsl_m = Some((g.alt as f64 - g.relative_alt as f64) * 1e-3);
        }
        MavMessage::EXTENDED_SYS_STATE(e) => s.landed = Some((now, e.landed_state)),
        MavMessage::GPS_GLOBAL_ORIGIN(o) => {
            s.global_origin = Some(crate::geodesy::GeodeticWgs84 {
                lat_deg: o.latitude as f64 * 1e-7,
                lon_deg: o.longitude as f64 * 1e-7,
                alt_m: o.altitude as f64 * 1e-3,
            })
        }
        MavMessage::SYS_STATUS(st) => s.battery_v = Some((now, st.voltage_battery as f64 * 1e-3)),
        MavMessage::PARAM_VALUE(p) => {
            let _ = events.send(LinkEvent::Param {
                name: p
                    .param_id
                    .to_str()
                    .unwrap_or("")
                    .trim_end_matches('\0')
                    .to_string(),
                wire: p.param_value,
                ty: param_type_of(p.param_type),
                index: p.param_index,
                count: p.param_count,
            });
        }
        MavMessage::STATUSTEXT(t) => {
            let text = t
                .text
                .to_str()
                .unwrap_or("")
                .trim_end_matches('\0')
                .to_string();
            tracing::info!("vehicle: {text}");
            let _ = events.send(LinkEvent::Text(text));
        }
        _ => {}
    }
}

/// The link's message handling without a socket, for the fuzz tests (`tests/fuzz_mavlink.rs`):
/// messages go through the same `on_message` the reader task calls.
#[doc(hidden)]
pub mod fuzz {
    use super::*;

    /// A vehicle state fed directly.
    pub struct LinkUnderTest {
        state: Mutex<VehicleState>,
        events: broadcast::Sender<LinkEvent>,
    }

    impl LinkUnderTest {
        /// A link with our ids 1/191 and no configured vehicle.
        pub fn new() -> Self {
            Self {
                state: Mutex::new(VehicleState::default()),
                events: broadcast::channel(16).0,
            }
        }

        /// The state so far.
        pub fn state(&self) -> VehicleState {
            self.state.lock().expect("state poisoned").clone()
        }
    }

    impl Default for LinkUnderTest {
        fn default() -> Self {
            Self::new()
        }
    }

    /// One received message, as the reader task hands it over.
    pub fn feed(link: &mut LinkUnderTest, h: MavHeader, m: &MavMessage) {
        let ids = Ids {
            me: (1, 191),
            vehicle: None,
        };
        on_message(&link.state, &link.events, ids, &h, m);
    }
}

/// Our ids and the vehicle's, if configured.
#[derive(Debug, Clone, Copy)]
struct Ids {
    me: (u8, u8),
    vehicle: Option<(u8, u8)>,
}

/// Whether an autopilot's heartbeat from `sender` is the vehicle's: the configured one, or
/// the first heard. Any other is ignored and reported once; a vehicle that reboots keeps its
/// ids and stays the vehicle.
fn lock_onto(s: &mut VehicleState, configured: Option<(u8, u8)>, sender: (u8, u8)) -> bool {
    /// MAV_COMP_ID_AUTOPILOT1: the flight controller itself.
    const AUTOPILOT: u8 = 1;
    let ours = match (s.address, configured) {
        (_, Some(wanted)) => wanted == sender,
        // Another component of the same system that calls itself an autopilot heard first
        // (a camera or gimbal manager): the flight controller's own component wins.
        (Some(locked), None) => locked == sender || (locked.0 == sender.0 && sender.1 == AUTOPILOT),
        (None, None) => true,
    };
    if ours {
        s.address = Some(sender);
    } else if s.ignored_autopilots.insert(sender) {
        let to = s.address.or(configured).expect("locked or configured");
        tracing::warn!(
            "ignoring the autopilot of system {} component {}: infotrack flies system {} component {} only",
            sender.0,
            sender.1,
            to.0,
            to.1
        );
    }
    ours
}

/// A position, velocity or attitude message with a NaN or infinite field: it must not
/// reach the vehicle state the tracker and the geofence read.
fn non_finite_telemetry(m: &MavMessage) -> bool {
    let bad = |v: &[f32]| v.iter().any(|x| !x.is_finite());
    match m {
        MavMessage::LOCAL_POSITION_NED(p) => bad(&[p.x, p.y, p.z, p.vx, p.vy, p.vz]),
        MavMessage::ATTITUDE(a) => bad(&[
            a.roll,
            a.pitch,
            a.yaw,
            a.rollspeed,
            a.pitchspeed,
            a.yawspeed,
        ]),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
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
        let s = state.lock().unwrap().clone();
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
        ] {
            assert!(check_url(ok).is_ok(), "{ok}");
        }
        for (bad, needle) in [
            ("udp:1.2.3.4:5", "unknown scheme"),
            ("udpin:0.0.0.0", "PORT"),
            ("udpin:0.0.0.0:99999", "not a number"),
            ("serial:/dev/ttyS0:fast", "baud"),
            ("14550", "SCHEME"),
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
}
