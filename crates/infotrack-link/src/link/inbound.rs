//! What the link reads: one dispatch over the vehicle's messages into the vehicle state.

use super::plausible;
use super::*;

/// Follows the vehicle's boot clock; a jump back by more than a second (more than any
/// reordering on a link) is a reboot.
fn boot_clock(s: &mut VehicleState, events: &broadcast::Sender<LinkEvent>, t_ms: u32) {
    if let Some(last) = s.time_boot_ms {
        if t_ms.saturating_add(1000) < last {
            s.reboots += 1;
            // At powers of two: spoofed boot times must not flood the log.
            if s.reboots.is_power_of_two() {
                tracing::warn!(
                    "vehicle rebooted (boot clock {last} ms -> {t_ms} ms; {} time(s) so far)",
                    s.reboots
                );
            }
            let _ = events.send(LinkEvent::VehicleRebooted);
            s.time_boot_ms = Some(t_ms);
            return;
        }
    }
    s.time_boot_ms = Some(s.time_boot_ms.map_or(t_ms, |l| l.max(t_ms)));
}

/// One received message into the vehicle state: only the locked vehicle's messages (any
/// autopilot's heartbeat, to lock onto one), only finite and plausible telemetry.
pub(super) fn on_message(
    state: &Mutex<VehicleState>,
    events: &broadcast::Sender<LinkEvent>,
    ids: Ids,
    h: &MavHeader,
    m: &MavMessage,
) {
    let now = Instant::now();
    let mut s = state.lock();
    let sender = (h.system_id as u8, h.component_id);
    let from_vehicle = s.address == Some(sender);
    if !from_vehicle && !matches!(m, MavMessage::HEARTBEAT(_)) {
        return;
    }
    if !admit_telemetry(&mut s, now, m) {
        return;
    }
    match m {
        MavMessage::HEARTBEAT(hb) => on_heartbeat(&mut s, events, ids, sender, hb, now),
        MavMessage::COMMAND_ACK(a) => on_ack(events, ids.me, a),
        MavMessage::PARAM_VALUE(p) => on_param_value(events, p),
        MavMessage::STATUSTEXT(t) => on_statustext(events, t),
        other => on_telemetry(&mut s, events, other, now),
    }
}

/// Whether `m` may update the state: NaN/infinite and implausible telemetry is dropped and
/// counted, said at powers of two.
fn admit_telemetry(s: &mut VehicleState, now: Instant, m: &MavMessage) -> bool {
    if non_finite_telemetry(m) {
        s.non_finite_dropped += 1;
        if s.non_finite_dropped.is_power_of_two() {
            tracing::warn!(
                "dropped {} telemetry message(s) with NaN or infinite fields so far (latest: {})",
                s.non_finite_dropped,
                mavlink::Message::message_name(m)
            );
        }
        return false;
    }
    if let Err(why) = plausible_telemetry(&mut s.plausibility, now, m) {
        s.implausible_dropped += 1;
        if s.implausible_dropped.is_power_of_two() {
            tracing::warn!(
                "dropped {} telemetry message(s) the vehicle cannot have flown so far (latest: {}, {})",
                s.implausible_dropped,
                mavlink::Message::message_name(m),
                why.0
            );
        }
        return false;
    }
    true
}

/// An autopilot's heartbeat: locks onto the vehicle, follows its link, arming and mode.
fn on_heartbeat(
    s: &mut VehicleState,
    events: &broadcast::Sender<LinkEvent>,
    ids: Ids,
    sender: (u8, u8),
    hb: &HEARTBEAT_DATA,
    now: Instant,
) {
    let flavor = match hb.autopilot {
        MavAutopilot::MAV_AUTOPILOT_PX4 => Flavor::Px4,
        MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Flavor::ArduPilot,
        _ => return, // a GCS, a camera, another companion
    };
    if !lock_onto(s, ids.vehicle, sender) {
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
    if let Some(old) = s.mode.filter(|old| *old != mode) {
        // A command explains one change: a later return to the same mode by the vehicle
        // itself (PX4 back to OFFBOARD after a failsafe) is its own.
        let commanded = s.commanded_mode == Some(mode);
        if commanded {
            s.commanded_mode = None;
        } else {
            note_own_mode_change(s, old, mode);
        }
        let _ = events.send(LinkEvent::ModeChanged {
            from: old,
            to: mode,
            commanded,
        });
    }
    s.mode = Some(mode);
}

/// A COMMAND_ACK: ours (or everyone's) goes to the waiting command.
fn on_ack(events: &broadcast::Sender<LinkEvent>, me: (u8, u8), a: &COMMAND_ACK_DATA) {
    let ours = (a.target_system == 0 || a.target_system == me.0)
        && (a.target_component == 0 || a.target_component == me.1);
    if ours {
        let _ = events.send(LinkEvent::Ack {
            command: a.command,
            result: a.result,
        });
    }
}

/// A PARAM_VALUE, to whoever reads or sets parameters.
fn on_param_value(events: &broadcast::Sender<LinkEvent>, p: &PARAM_VALUE_DATA) {
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

/// A STATUSTEXT: logged and published.
fn on_statustext(events: &broadcast::Sender<LinkEvent>, t: &STATUSTEXT_DATA) {
    let text = t
        .text
        .to_str()
        .unwrap_or("")
        .trim_end_matches('\0')
        .to_string();
    tracing::info!("vehicle: {text}");
    let _ = events.send(LinkEvent::Text(text));
}

/// Position, attitude, origin, home, landed state and battery into the state.
fn on_telemetry(
    s: &mut VehicleState,
    events: &broadcast::Sender<LinkEvent>,
    m: &MavMessage,
    now: Instant,
) {
    let wgs84 = |lat_e7: i32, lon_e7: i32, alt_mm: i32| infotrack_core::geodesy::GeodeticWgs84 {
        lat_deg: lat_e7 as f64 * 1e-7,
        lon_deg: lon_e7 as f64 * 1e-7,
        alt_m: alt_mm as f64 * 1e-3,
    };
    match m {
        MavMessage::LOCAL_POSITION_NED(p) => {
            boot_clock(s, events, p.time_boot_ms);
            let position = PositionNed {
                x_north_m: p.x as f64,
                y_east_m: p.y as f64,
                z_down_m: p.z as f64,
            };
            s.local_ned = Some((now, position, [p.vx, p.vy, p.vz]));
        }
        MavMessage::ATTITUDE(a) => {
            boot_clock(s, events, a.time_boot_ms);
            s.attitude = Some((now, [a.roll, a.pitch, a.yaw]));
        }
        MavMessage::GLOBAL_POSITION_INT(g) => {
            let relative_m = g.relative_alt as f64 * 1e-3;
            s.global = Some((now, g.lat as f64 * 1e-7, g.lon as f64 * 1e-7, relative_m));
            s.home_alt_amsl_m = Some((g.alt as f64 - g.relative_alt as f64) * 1e-3);
        }
        MavMessage::EXTENDED_SYS_STATE(e) => s.landed = Some((now, e.landed_state)),
        MavMessage::GPS_GLOBAL_ORIGIN(o) => {
            on_origin(s, events, wgs84(o.latitude, o.longitude, o.altitude))
        }
        MavMessage::HOME_POSITION(hp) => {
            let local = PositionNed {
                x_north_m: hp.x as f64,
                y_east_m: hp.y as f64,
                z_down_m: hp.z as f64,
            };
            s.home_position = Some((wgs84(hp.latitude, hp.longitude, hp.altitude), local));
        }
        MavMessage::SYS_STATUS(st) => s.battery_v = Some((now, st.voltage_battery as f64 * 1e-3)),
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
            self.state.lock().clone()
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
pub(super) struct Ids {
    pub(super) me: (u8, u8),
    pub(super) vehicle: Option<(u8, u8)>,
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
    } else if s.ignored_autopilots.len() < MAX_LISTED && s.ignored_autopilots.insert(sender) {
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

/// Position, velocity, attitude and global position the vehicle can have flown: see
/// `plausible.rs`. Other messages pass.
fn plausible_telemetry(
    p: &mut super::Plausibility,
    now: Instant,
    m: &MavMessage,
) -> Result<(), plausible::Implausible> {
    let env = p.envelope;
    match m {
        MavMessage::LOCAL_POSITION_NED(l) => {
            let ned = [l.x as f64, l.y as f64, l.z as f64];
            plausible::local_in_world(&env, ned, [l.vx as f64, l.vy as f64, l.vz as f64])?;
            p.local.check(&env, now, [ned[0], ned[1]], -ned[2])
        }
        MavMessage::ATTITUDE(a) => plausible::attitude(
            [a.roll as f64, a.pitch as f64, a.yaw as f64],
            [a.rollspeed as f64, a.pitchspeed as f64, a.yawspeed as f64],
        ),
        MavMessage::GLOBAL_POSITION_INT(g) => {
            let (lat, lon) = (g.lat as f64 * 1e-7, g.lon as f64 * 1e-7);
            let relative_m = g.relative_alt as f64 * 1e-3;
            plausible::global_on_earth(&env, lat, lon, relative_m)?;
            let cm_per_s = [g.vx as f64, g.vy as f64, g.vz as f64];
            plausible::speed_in_envelope(&env, cm_per_s.map(|v| v * 1e-2))?;
            let (lat0, lon0) = *p.global_ref.get_or_insert((lat, lon));
            // Metres about the first fix: an equirectangular view is exact enough for the
            // tens of metres a glitch check needs.
            const M_PER_DEG: f64 = 111_320.0;
            let north_m = (lat - lat0) * M_PER_DEG;
            let east_m = (lon - lon0) * M_PER_DEG * lat0.to_radians().cos();
            let amsl_m = g.alt as f64 * 1e-3;
            plausible::amsl_on_earth(amsl_m)?;
            p.global.check(&env, now, [north_m, east_m], amsl_m)?;
            // Home's height (AMSL minus relative) moves only when home is set again.
            p.home.check(&env, now, [0.0, 0.0], amsl_m - relative_m)
        }
        _ => Ok(()),
    }
}

/// GPS_GLOBAL_ORIGIN: before the world is placed, the latest is kept (the daemon cross-checks
/// it); after, one that moves the origin by more than a metre is reported and kept apart: the
/// placement never moves in flight.
fn on_origin(
    s: &mut VehicleState,
    events: &broadcast::Sender<LinkEvent>,
    origin: infotrack_core::geodesy::GeodeticWgs84,
) {
    /// Re-sent origins differ by their 1e-7 degree rounding at most.
    const SAME_ORIGIN_M: f64 = 1.0;
    if !(origin.lat_deg.abs() <= 90.0 && origin.lon_deg.abs() <= 180.0) {
        return;
    }
    let Some(fixed) = s.origin_fixed else {
        s.global_origin = Some(origin);
        return;
    };
    let moved_m = fixed.horizontal_distance_m(&origin);
    if moved_m <= SAME_ORIGIN_M || s.origin_changed.is_some() {
        return;
    }
    tracing::error!(
        "the vehicle's GPS_GLOBAL_ORIGIN moved {moved_m:.1} m in flight (to {:.7}, {:.7}): \
         the world no longer lies where it was placed",
        origin.lat_deg,
        origin.lon_deg
    );
    s.origin_changed = Some(origin);
    let _ = events.send(LinkEvent::OriginChanged);
}

/// Mode changes, ignored autopilots and the like kept for the report: a spoofed heartbeat
/// with another mode every frame must neither flood the log nor grow memory without end.
const MAX_LISTED: usize = 64;

/// A mode change of an armed vehicle that the link did not ask for, said for what it most
/// likely is: a switch to the companion's mode is the pilot's (or a GCS's) hand-over, one
/// to return or land what a failsafe does (or the pilot), anything else the pilot's.
fn note_armed_mode_change(old: Mode, mode: Mode, n: u64) {
    match mode {
        Mode::Offboard | Mode::Guided => tracing::info!(
            "vehicle switched {old:?} -> {mode:?} by the pilot or a GCS: the hand-over to infotrack ({n} mode change(s) not commanded so far)"
        ),
        Mode::ReturnToLaunch | Mode::Land => tracing::warn!(
            "vehicle switched {old:?} -> {mode:?}, not commanded by infotrack: a failsafe or the pilot ({n} so far)"
        ),
        _ => tracing::info!(
            "vehicle switched {old:?} -> {mode:?} by the pilot or a GCS ({n} mode change(s) not commanded so far)"
        ),
    }
}

/// A mode change the link did not ask for: listed (up to [`MAX_LISTED`]) and logged at
/// powers of two.
fn note_own_mode_change(s: &mut VehicleState, old: Mode, mode: Mode) {
    let armed = s.has_armed;
    let list = if armed {
        &mut s.unexpected_mode_changes
    } else {
        &mut s.mode_changes_before_arming
    };
    if list.len() < MAX_LISTED {
        list.push((old, mode));
    }
    s.own_mode_changes += 1;
    if !s.own_mode_changes.is_power_of_two() {
        return;
    }
    let n = s.own_mode_changes;
    if armed {
        note_armed_mode_change(old, mode, n);
    } else {
        tracing::info!(
            "vehicle changed mode {old:?} -> {mode:?} by itself before arming (its start-up, or the pilot on the ground; {n} so far)"
        );
    }
}
