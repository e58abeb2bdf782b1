//! Reaching the vehicle and getting it airborne: connection, the world's origin, take-off
//! or the pilot's, and the start position.

use super::*;

/// Phase 2: starts the in-process mock if asked, opens the link and waits for the
/// vehicle's heartbeat.
pub(super) async fn connect(
    cfg: &Config,
    opts: &RunOptions,
    signal: &mut ShutdownSignal,
) -> Result<Vehicle, DaemonError> {
    let d = &cfg.daemon;
    let (mock, url) = match in_process_flavor(&d.vehicle) {
        Some(flavor) => {
            let start = opts
                .simulators
                .start_vehicle
                .as_ref()
                .ok_or(DaemonError::NoSimulator("the in-process mock autopilot"))?;
            let (m, u) = start(cfg, flavor).await.map_err(DaemonError::MockStart)?;
            (Some(m), u)
        }
        None => (None, d.vehicle.clone()),
    };
    if mock.is_none()
        && opts
            .faults
            .iter()
            .any(|f| !matches!(f.kind, FaultKind::CameraFreeze | FaultKind::PipelinePanic))
    {
        return Err(DaemonError::LinkFaultNeedsMock);
    }
    let mut lc = LinkConfig::new(&url);
    lc.system_id = d.system_id;
    lc.component_id = d.component_id;
    lc.setpoint_hz = d.setpoint_hz;
    lc.geofence_enu = Some(cfg.workspace_enu);
    lc.envelope = telemetry_envelope(cfg);
    lc.tlog = opts.tlog.clone();
    lc.vehicle = d.vehicle_id.map(|[s, c]| (s, c));
    lc.signing_key = d.signing_key.as_deref().map(SigningKey::load).transpose()?;
    let link = VehicleLink::connect(lc).await?;
    let flavor = wait_for_vehicle(&link, &url, d.connect_timeout_s, signal).await?;
    tracing::info!("vehicle ready: {flavor} on {url}");
    vehicle_speed::warn_if_slower_than_planned(cfg, &link, flavor).await;
    Ok(Vehicle {
        link,
        flavor,
        name: d.vehicle.clone(),
        url,
        mock,
    })
}

/// The flavour of an in-process mock vehicle name (`mock:px4`, `mock:ardupilot`).
fn in_process_flavor(vehicle: &str) -> Option<Flavor> {
    match vehicle {
        "mock:px4" => Some(Flavor::Px4),
        "mock:ardupilot" => Some(Flavor::ArduPilot),
        _ => None,
    }
}

/// What the vehicle can fly, from the agent's planned speed and the geofence's farthest
/// corner from the world's origin (the vehicle's own frame is within the world origin's
/// tolerance of it).
fn telemetry_envelope(cfg: &Config) -> crate::autopilot::link::plausible::Envelope {
    let w = &cfg.workspace_enu;
    let reach_m = [w.x_min_m, w.x_max_m]
        .iter()
        .flat_map(|x| [w.y_min_m, w.y_max_m].map(|y| x.hypot(y)))
        .fold(0.0, f64::max)
        + cfg.world.as_ref().map_or(0.0, |wc| wc.origin_tolerance_m);
    crate::autopilot::link::plausible::Envelope::for_vehicle(cfg.agent.speed_limit_mps, reach_m)
}

/// `[world]`: the vehicle's local origin (GPS_GLOBAL_ORIGIN) must be known, agree with
/// where the vehicle says it is (GLOBAL_POSITION_INT against the origin moved by
/// LOCAL_POSITION_NED; HOME_POSITION, when sent, likewise) and lie within the tolerance of
/// the world's before anything is commanded; the link then converts every position and
/// setpoint between the vehicle's frame and the world's. Why the cross-check: an origin
/// spoofed with the vehicle's ids during start-up would place the world, and the geofence
/// with it, hundreds of metres off.
pub(super) async fn check_world_origin(
    w: &crate::config::WorldConfig,
    link: &VehicleLink,
    timeout_s: f64,
) -> Result<(), DaemonError> {
    let until = Instant::now() + Duration::from_secs_f64(timeout_s);
    let mut disagreement = None;
    let mut asked: Option<Instant> = None;
    loop {
        if asked.map_or(true, |at| at.elapsed() >= Duration::from_secs(1)) {
            ask_for_origin(link).await;
            asked = Some(Instant::now());
        }
        match origin_agreement(&link.state()) {
            Some(Ok(origin)) => return place_world(w, link, origin),
            Some(Err(d)) => disagreement = Some(d),
            None => {}
        }
        if Instant::now() > until {
            return Err(disagreement.unwrap_or(DaemonError::NoVehicleOrigin(timeout_s)));
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Asks for GPS_GLOBAL_ORIGIN and HOME_POSITION (again: a spoofed one may have come last).
async fn ask_for_origin(link: &VehicleLink) {
    const GPS_GLOBAL_ORIGIN_ID: u32 = 49;
    const HOME_POSITION_ID: u32 = 242;
    for id in [GPS_GLOBAL_ORIGIN_ID, HOME_POSITION_ID] {
        if let Err(e) = link.request_message(id).await {
            // Some firmware streams them without answering the request: wait anyway.
            tracing::debug!("asking for message {id}: {e}");
        }
    }
}

/// The latest origin if it agrees with the vehicle's own position messages; `Err` says how
/// far off it is; `None`: not all of them have arrived yet.
fn origin_agreement(
    s: &crate::autopilot::link::VehicleState,
) -> Option<Result<crate::geodesy::GeodeticWgs84, DaemonError>> {
    /// GLOBAL_POSITION_INT and LOCAL_POSITION_NED come from one estimator: they agree to
    /// centimetres, and a vehicle on the ground moves by less than this between the two, m.
    const AGREE_M: f64 = 5.0;
    let origin = s.global_origin?;
    let (_, lat_deg, lon_deg, _) = s.global?;
    let (_, local, _) = s.local_ned?;
    let here = crate::geodesy::GeodeticWgs84 {
        lat_deg,
        lon_deg,
        alt_m: origin.alt_m,
    };
    let implied = origin.offset_by_enu([local.y_east_m, local.x_north_m, 0.0]);
    let off_m = implied.horizontal_distance_m(&here);
    if off_m > AGREE_M {
        return Some(Err(DaemonError::OriginDisagrees(format!(
            "GPS_GLOBAL_ORIGIN ({:.7}, {:.7}) moved by LOCAL_POSITION_NED lies {off_m:.1} m from \
             GLOBAL_POSITION_INT ({lat_deg:.7}, {lon_deg:.7})",
            origin.lat_deg, origin.lon_deg
        ))));
    }
    if let Some((home, home_local)) = s.home_position {
        let home_origin = home.offset_by_enu([-home_local.y_east_m, -home_local.x_north_m, 0.0]);
        let off_m = home_origin.horizontal_distance_m(&origin);
        if off_m > AGREE_M {
            return Some(Err(DaemonError::OriginDisagrees(format!(
                "GPS_GLOBAL_ORIGIN ({:.7}, {:.7}) lies {off_m:.1} m from the origin HOME_POSITION \
                 implies ({:.7}, {:.7})",
                origin.lat_deg, origin.lon_deg, home_origin.lat_deg, home_origin.lon_deg
            ))));
        }
    }
    Some(Ok(origin))
}

/// Places the world with the vehicle's checked origin, if it is within the tolerance.
fn place_world(
    w: &crate::config::WorldConfig,
    link: &VehicleLink,
    origin: crate::geodesy::GeodeticWgs84,
) -> Result<(), DaemonError> {
    let distance_m = w.origin.horizontal_distance_m(&origin);
    if distance_m > w.origin_tolerance_m {
        return Err(DaemonError::OriginTooFar {
            vehicle_lat: origin.lat_deg,
            vehicle_lon: origin.lon_deg,
            world_lat: w.origin.lat_deg,
            world_lon: w.origin.lon_deg,
            distance_m,
            tolerance_m: w.origin_tolerance_m,
        });
    }
    let placement = crate::geodesy::WorldPlacement::new(w.origin, origin);
    let [e, n] = placement.vehicle_origin_in_world_en_m();
    tracing::info!(
        "the vehicle's origin is {distance_m:.2} m from the world's ({e:.2} m east, {n:.2} m \
         north of it), and agrees with its GLOBAL_POSITION_INT: positions and setpoints are \
         converted between the two frames"
    );
    link.place_in_world(placement);
    Ok(())
}

/// Phase 3: telemetry, then the takeoff: infotrack's own (`auto`) or the pilot's.
pub(super) async fn launch(cfg: &Config, link: &VehicleLink) -> Result<(), LinkError> {
    link.request_telemetry().await?;
    match cfg.daemon.engage {
        Engage::Auto => take_off_to_start(cfg, link).await,
        Engage::Pilot => wait_for_pilot_takeoff(link).await,
    }
}

/// Waits for the vehicle's heartbeat, up to `timeout_s`, saying so every 5 s.
async fn wait_for_vehicle(
    link: &VehicleLink,
    url: &str,
    timeout_s: f64,
    signal: &mut ShutdownSignal,
) -> Result<Flavor, DaemonError> {
    tracing::info!("waiting for the vehicle at {url} (up to {timeout_s:.0} s)");
    let started = tokio::time::Instant::now();
    let wait = link.wait_vehicle(Duration::from_secs_f64(timeout_s));
    tokio::pin!(wait);
    let mut every =
        tokio::time::interval_at(started + Duration::from_secs(5), Duration::from_secs(5));
    loop {
        tokio::select! {
            f = &mut wait => return Ok(f?),
            _ = every.tick() => tracing::info!(
                "still waiting for the vehicle at {url} ({:.0} s)",
                started.elapsed().as_secs_f64()
            ),
            _ = &mut *signal => {
                return Err(DaemonError::Interrupted("while waiting for the vehicle; nothing was commanded"))
            }
        }
    }
}

/// `daemon.engage = "pilot"`: waits, as long as it takes, until the pilot has the vehicle
/// armed and off the ground. Nothing is commanded.
async fn wait_for_pilot_takeoff(link: &VehicleLink) -> Result<(), LinkError> {
    /// Above this height over the origin a vehicle that reports no landed state is airborne.
    const AIRBORNE_M: f64 = 0.5;
    supervisor::tell(
        link,
        mavlink::dialects::ardupilotmega::MavSeverity::MAV_SEVERITY_INFO,
        "infotrack: ready; waiting for the pilot's takeoff",
    )
    .await;
    loop {
        let s = link.state();
        let in_air = match s.landed {
            Some((_, l)) => {
                l == mavlink::dialects::ardupilotmega::MavLandedState::MAV_LANDED_STATE_IN_AIR
            }
            None => s
                .local_ned
                .is_some_and(|(_, p, _)| -p.z_down_m > AIRBORNE_M),
        };
        if s.armed && in_air {
            tracing::info!(
                "the pilot has the vehicle in the air; infotrack takes over when the mode is switched to {}",
                Mode::companion_for(link.flavor())
            );
            return Ok(());
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// `daemon.engage = "auto"`: takeoff to the tracking altitude, then the scenario's start
/// point (`agent.start_enu_m`, where the simulator's agent starts) before tracking begins.
async fn take_off_to_start(cfg: &Config, link: &VehicleLink) -> Result<(), LinkError> {
    let d = &cfg.daemon;
    link.take_off(
        cfg.agent.altitude_m,
        Duration::from_secs_f64(d.takeoff_timeout_s),
    )
    .await?;
    let start = PositionEnu {
        x_east_m: cfg.agent.start_enu_m[0],
        y_north_m: cfg.agent.start_enu_m[1],
        z_up_m: cfg.agent.altitude_m,
    };
    link.set_setpoint(start, heading::start_yaw_enu_rad(cfg))?;
    let want = start.to_ned();
    let tol = cfg.start_tolerance_m();
    let mut close_since: Option<Instant> = None;
    // Not VehicleLink::wait_for: that polls every 20 ms, and the instant tracking begins
    // decides the simulated flights (and the recorded numbers of each seed).
    let until = Instant::now() + Duration::from_secs_f64(d.takeoff_timeout_s);
    loop {
        if let Some((_, p, v)) = link.local_ned_in_world() {
            let off = (p.x_north_m - want.x_north_m)
                .hypot(p.y_east_m - want.y_east_m)
                .hypot(p.z_down_m - want.z_down_m);
            let speed = v.iter().map(|c| (*c as f64).powi(2)).sum::<f64>().sqrt();
            if off < tol && speed < tol {
                return Ok(());
            }
            if off < 10.0 * tol {
                let since = *close_since.get_or_insert_with(Instant::now);
                if since.elapsed().as_secs_f64() >= d.start_settle_s {
                    tracing::warn!(
                        "the vehicle hovers {off:.2} m from the start point at {speed:.2} m/s \
                         and does not settle within daemon.start_tolerance_m = {tol} m; \
                         tracking begins anyway"
                    );
                    return Ok(());
                }
            } else {
                close_since = None;
            }
        }
        if Instant::now() > until {
            return Err(LinkError::Timeout {
                what: format!(
                    "the vehicle to reach the start point agent.start_enu_m = {:?} \
                     (daemon.takeoff_timeout_s)",
                    cfg.agent.start_enu_m
                ),
                seconds: d.takeoff_timeout_s,
            });
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}
