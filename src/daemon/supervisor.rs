//! The tracking phase: the supervisor loop between the vehicle link and the pipeline, and
//! the clean stop.

use super::*;

/// What the tracking phase counted.
pub(super) struct Tracked {
    stopped_by: StopReason,
    /// Whether infotrack had the vehicle at the end (then it holds it; else the pilot has it).
    engaged: bool,
    /// Seconds from the start of tracking to the first engagement (`None`: never engaged):
    /// the metrics count from there.
    engaged_after_s: Option<f64>,
    link_losses: u32,
    geofence_refusals: u64,
    ticker: tokio::task::JoinHandle<()>,
}

/// The supervisor's state during tracking.
struct Supervisor<'a> {
    cfg: &'a Config,
    opts: &'a RunOptions,
    vehicle: &'a Vehicle,
    shared: &'a std::sync::Arc<Shared>,
    applied: Option<Command>,
    geofence_refusals: u64,
    link_losses: u32,
    was_lost: bool,
    fault_active: Vec<bool>,
    last_status: Instant,
    gcs: gcs_report::GcsReporter,
    engagement: engagement::Engagement,
    /// The setpoint stream is paused (link lost, or released on ArduPilot).
    paused: bool,
    /// When infotrack first had the vehicle: `--duration` counts from there.
    engaged_at: Option<Instant>,
}

/// Phase 4: steps the pipeline on the runtime's clock and, every 20 ms, feeds it the
/// vehicle's state, applies its command, switches faults and prints the status line, until
/// the duration, a signal or a dead pipeline.
pub(super) async fn track(
    cfg: &Config,
    opts: &RunOptions,
    vehicle: &Vehicle,
    pipeline: &PipelineHandle,
    (ticks, done): TickChannels,
    signal: &mut ShutdownSignal,
) -> Tracked {
    let shared = &pipeline.shared;
    shared.to_pipeline.lock().vehicle = snapshot(&vehicle.link);
    let ticker = tokio::spawn(drive_pipeline(
        ticks,
        done,
        pipeline.physics_dt,
        shared.clone(),
    ));
    let began = Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(20));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut sup = Supervisor {
        cfg,
        opts,
        vehicle,
        shared,
        applied: None,
        geofence_refusals: 0,
        link_losses: 0,
        was_lost: false,
        fault_active: vec![false; opts.faults.len()],
        last_status: Instant::now(),
        gcs: gcs_report::GcsReporter::new(&cfg.daemon.target_lost_fallback),
        engagement: engagement::Engagement::new(cfg.daemon.engage, vehicle.flavor),
        paused: false,
        engaged_at: None,
    };
    // `auto` has the vehicle from the start of tracking (it took off itself).
    sup.engaged_at = sup.engagement.engaged().then_some(began);
    let (severity, text) = gcs_report::GcsReporter::started(&opts.motion);
    sup.tell_gcs(severity, &text).await;
    let stopped_by = loop {
        tokio::select! {
            _ = &mut *signal => break StopReason::Signal,
            _ = tick.tick() => {}
        }
        if let Some(why) = sup.reason_to_stop(pipeline, &ticker).await {
            break why;
        }
        sup.switch_faults(began.elapsed().as_secs_f64());
        let snap = sup.feed_vehicle_state();
        sup.follow_pilot().await;
        if sup.engaged_at.is_none() && sup.engagement.engaged() {
            sup.engaged_at = Some(Instant::now());
        }
        sup.apply_command(snap);
        sup.print_status();
        sup.report_to_gcs().await;
    };
    Tracked {
        stopped_by,
        engaged: sup.engagement.holds_at_stop()
            && (cfg.daemon.engage == Engage::Auto
                || vehicle.link.state().mode == Some(Mode::companion_for(vehicle.flavor))),
        engaged_after_s: sup
            .engaged_at
            .map(|t| t.duration_since(began).as_secs_f64()),
        link_losses: sup.link_losses,
        geofence_refusals: sup.geofence_refusals,
        ticker,
    }
}

impl Supervisor<'_> {
    /// Why tracking must stop now, if it must: infotrack has had the vehicle for the
    /// duration, the target's recorded
    /// track has ended, the pipeline died (a panic: nothing decides any more), or the
    /// vehicle's origin moved (the world and its geofence would move with it).
    async fn reason_to_stop(
        &mut self,
        pipeline: &PipelineHandle,
        ticker: &tokio::task::JoinHandle<()>,
    ) -> Option<StopReason> {
        // `--duration` is the time infotrack has had the vehicle for: from the pilot's
        // hand-over, or from the start of tracking after its own take-off.
        let engaged_for_s = self.engaged_at.map_or(0.0, |t| t.elapsed().as_secs_f64());
        if engaged_for_s >= self.opts.duration_s {
            return Some(StopReason::Duration);
        }
        if self.shared.target_ended.load(Ordering::Relaxed) {
            tracing::info!("the target's recorded track has ended: so does the flight");
            return Some(StopReason::Duration);
        }
        if pipeline.thread.is_finished() || ticker.is_finished() {
            // The pipeline died (a panic): nothing decides any more; hold.
            tracing::error!("the pipeline thread stopped; holding the vehicle");
            return Some(StopReason::Fault);
        }
        if let Some(o) = self.vehicle.link.state().origin_changed {
            let text = "infotrack: vehicle origin changed in flight; holding";
            eprintln!(
                "the vehicle's GPS_GLOBAL_ORIGIN changed in flight (now {:.7}, {:.7}): the world \
                 and its geofence would move; holding the vehicle",
                o.lat_deg, o.lon_deg
            );
            self.tell_gcs(
                mavlink::dialects::ardupilotmega::MavSeverity::MAV_SEVERITY_CRITICAL,
                text,
            )
            .await;
            return Some(StopReason::OriginChanged);
        }
        None
    }

    /// Starts and ends the scheduled faults.
    fn switch_faults(&mut self, now_s: f64) {
        let mock = self.vehicle.mock.as_ref();
        let mut toggled = false;
        for (f, active) in self.opts.faults.iter().zip(self.fault_active.iter_mut()) {
            let on = now_s >= f.at_s && now_s < f.at_s + f.duration_s;
            if on == *active {
                continue;
            }
            *active = on;
            toggled = true;
            tracing::warn!(
                "fault {} {}",
                f.kind.name(),
                if on { "begins" } else { "ends" }
            );
            match (f.kind, mock) {
                (FaultKind::PipelinePanic, _) if on => self.shared.to_pipeline.lock().panic = true,
                (FaultKind::CameraFreeze, _) => self.shared.to_pipeline.lock().camera_frozen = on,
                (FaultKind::LinkCut, Some(m)) if on => {
                    m.cut_link(Duration::from_secs_f64(f.duration_s))
                }
                (FaultKind::PacketLoss(p), Some(m)) => {
                    m.set_packet_loss(if on { p } else { 0.0 }, self.opts.seed)
                }
                _ => {}
            }
        }
        if toggled {
            let active: Vec<String> = self
                .opts
                .faults
                .iter()
                .zip(&self.fault_active)
                .filter(|(_, on)| **on)
                .map(|(f, _)| f.kind.name())
                .collect();
            self.shared.to_pipeline.lock().faults = active.join("+");
        }
    }

    /// Gives the pipeline the vehicle's latest state (and the pose history for a real
    /// camera); pauses setpoints while the link is lost.
    fn feed_vehicle_state(&mut self) -> Option<VehicleSnapshot> {
        let link = &self.vehicle.link;
        let snap = snapshot(link);
        self.shared.to_pipeline.lock().vehicle = snap;
        if let (Some(sn), Some((at, _, _))) = (snap, link.state().local_ned) {
            // Stamped with the telemetry's arrival, for frames from a real camera.
            self.shared.poses.lock().push(at, sn.pose);
        }
        let lost = link.state().lost;
        if lost != self.was_lost {
            if lost {
                self.link_losses += 1;
            }
            self.was_lost = lost;
        }
        snap
    }

    /// Who has the vehicle (`engagement`): says when infotrack gains or loses it, and while
    /// it does not have it streams what the firmware needs to let the pilot hand over (PX4:
    /// the vehicle's own position) or nothing (ArduPilot).
    async fn follow_pilot(&mut self) {
        let link = &self.vehicle.link;
        // What the firmware needs while the pilot has it: the vehicle where it is, nose
        // where it is.
        let yaw = link.heading_enu_rad();
        let mode = link.state().mode;
        match self.engagement.update(mode) {
            engagement::Change::Engaged => {
                // Send the tracker's current command at once.
                self.applied = None;
                self.tell_gcs(
                    mavlink::dialects::ardupilotmega::MavSeverity::MAV_SEVERITY_NOTICE,
                    "infotrack: engaged by the pilot, tracking",
                )
                .await;
            }
            engagement::Change::Released { to } => {
                let to = to.map_or("?".to_string(), |m| format!("{m:?}"));
                self.tell_gcs(
                    mavlink::dialects::ardupilotmega::MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("infotrack: released ({to}); pilot has it"),
                )
                .await;
            }
            engagement::Change::None => {}
        }
        let mut silent = false;
        if !self.engagement.engaged() {
            self.applied = None;
            silent = match self.engagement.idle_stream() {
                engagement::IdleStream::Silent => true,
                // Outside the geofence nothing can be streamed; OFFBOARD then cannot be
                // entered, which is what the fence is for.
                engagement::IdleStream::HoldHere => match link.position_enu() {
                    Some(here) => link.set_setpoint(here, yaw).is_err(),
                    None => true,
                },
            };
        }
        // Commands on stale state are worse than none: the vehicle's own failsafe acts.
        let paused = self.was_lost || silent;
        if paused != self.paused {
            link.pause_setpoints(paused);
            self.paused = paused;
        }
    }

    /// Sends the pipeline's newest command as a setpoint (inside the geofence).
    fn apply_command(&mut self, snap: Option<VehicleSnapshot>) {
        let cmd = self.shared.pipeline_view().command;
        if cmd == self.applied || self.was_lost || !self.engagement.engaged() {
            return;
        }
        if let Some(c) = cmd {
            let mount_yaw = self.cfg.daemon.camera_mount_rpy_rad[2];
            let target = match c {
                Command::GoTo {
                    position_enu,
                    velocity_enu,
                    view_yaw_enu_rad,
                } => Some((
                    position_enu,
                    velocity_enu,
                    heading::nose_yaw_enu_for_view(view_yaw_enu_rad, mount_yaw),
                )),
                // Where it is, nose where it is.
                Command::HoldHere => snap.map(|s| {
                    let yaw = crate::frames::yaw_ned_to_enu(s.pose.yaw_rad);
                    (s.pose.position_enu(), Enu2::zeros(), yaw)
                }),
            };
            if let Some((w, v, yaw)) = target {
                let p = PositionEnu::from_xy(&w, self.cfg.agent.altitude_m);
                if let Err(e) = self.vehicle.link.set_moving_setpoint(p, v, yaw) {
                    self.geofence_refusals += 1;
                    tracing::warn!("{e}");
                }
            }
        }
        self.applied = cmd;
    }

    /// Tells the ground station what changed, and the tracker's values once a second
    /// (`gcs_report`).
    async fn report_to_gcs(&mut self) {
        let Some(status) = self.shared.pipeline_view().status else {
            return;
        };
        if self.was_lost {
            return;
        }
        for (severity, text) in self.gcs.events(&status) {
            self.tell_gcs(severity, &text).await;
        }
        if let Some(values) = self.gcs.values_due(&status, Instant::now()) {
            for (name, value) in values {
                if let Err(e) = self.vehicle.link.send_named_value(name, value).await {
                    tracing::debug!("NAMED_VALUE_FLOAT {name}: {e}");
                }
            }
            self.put_target_on_map(status.estimate_enu).await;
        }
    }

    /// The estimate as ADS-B traffic on the GCS map: placed from the vehicle's own WGS84
    /// position by the estimate's world-ENU offset from the vehicle; on the ground (the
    /// vehicle's home height). Nothing until the vehicle reports a global position.
    async fn put_target_on_map(&self, estimate_enu: [f64; 2]) {
        let link = &self.vehicle.link;
        let s = link.state();
        let (Some((_, lat, lon, _)), Some(home_alt), Some(vehicle)) =
            (s.global, s.home_alt_amsl_m, link.position_enu())
        else {
            return;
        };
        let here = crate::geodesy::GeodeticWgs84 {
            lat_deg: lat,
            lon_deg: lon,
            alt_m: 0.0,
        };
        let target = here.offset_by_enu([
            estimate_enu[0] - vehicle.x_east_m,
            estimate_enu[1] - vehicle.y_north_m,
            0.0,
        ]);
        if let Err(e) = link.send_target_on_map(target, home_alt).await {
            tracing::debug!("ADSB_VEHICLE: {e}");
        }
    }

    /// One STATUSTEXT to the ground station (and the log).
    async fn tell_gcs(&self, severity: mavlink::dialects::ardupilotmega::MavSeverity, text: &str) {
        tell(&self.vehicle.link, severity, text).await;
    }

    /// The status line, once a second, when asked for: engagement, the target's state,
    /// the distance to the estimate and its spread, altitude, mode and the link.
    fn print_status(&mut self) {
        if !self.opts.status_line || self.last_status.elapsed() < Duration::from_secs(1) {
            return;
        }
        self.last_status = Instant::now();
        let Some(s) = self.shared.pipeline_view().status else {
            return;
        };
        let link = &self.vehicle.link;
        let vehicle = link.state();
        let mode = vehicle
            .mode
            .map_or_else(|| "?".into(), |m| format!("{m:?}"));
        // The link's own watchdog declares the vehicle lost after 3 s without a heartbeat.
        let link_state = match vehicle.last_heartbeat.map(|t| t.elapsed().as_secs_f64()) {
            Some(quiet_s) if quiet_s <= 3.0 => "ok".to_string(),
            Some(quiet_s) => format!("LOST ({quiet_s:.0} s without a heartbeat)"),
            None => "no heartbeat yet".to_string(),
        };
        let (distance, altitude) = link.position_enu().map_or((f64::NAN, f64::NAN), |p| {
            let d = (s.estimate_enu[0] - p.x_east_m).hypot(s.estimate_enu[1] - p.y_north_m);
            (d, p.z_up_m)
        });
        let engaged = if self.engagement.engaged() {
            "engaged"
        } else {
            "standby"
        };
        eprintln!(
            "t={:5.1}s {engaged} target={} ({}) estimate {distance:.0} m away, +-{:.0} m | alt {altitude:.1} m | mode {mode} | link {link_state}",
            s.t_s,
            s.state.as_str(),
            if s.seen { "in view" } else { "not in view" },
            s.radius_m,
        );
    }
}

/// One STATUSTEXT to the ground station, and the same words in the log (at `info`, or
/// `warn` and above as the STATUSTEXT's severity says): the terminal tells what the GCS is
/// told.
pub(super) async fn tell(
    link: &VehicleLink,
    severity: mavlink::dialects::ardupilotmega::MavSeverity,
    text: &str,
) {
    use mavlink::dialects::ardupilotmega::MavSeverity as S;
    match severity {
        S::MAV_SEVERITY_EMERGENCY
        | S::MAV_SEVERITY_ALERT
        | S::MAV_SEVERITY_CRITICAL
        | S::MAV_SEVERITY_ERROR => {
            tracing::error!("{text}")
        }
        S::MAV_SEVERITY_WARNING => tracing::warn!("{text}"),
        _ => tracing::info!("{text}"),
    }
    if let Err(e) = link.send_statustext(severity, text).await {
        tracing::debug!("STATUSTEXT `{text}`: {e}");
    }
}

/// Phase 5: stops the pipeline, holds the vehicle whatever happened, and reports.
pub(super) async fn stop(
    vehicle: Vehicle,
    pipeline: PipelineHandle,
    tracked: Tracked,
) -> Result<DaemonReport, DaemonError> {
    pipeline.shared.stop.store(true, Ordering::Relaxed);
    // The driver sees the stop at its next tick and closes the tick channel: the pipeline
    // thread then returns its output.
    let _ = tracked.ticker.await;
    let thread = pipeline.thread;
    let joined = tokio::task::spawn_blocking(move || thread.join()).await;
    // Clean stop, whatever happened to the pipeline: hold before exiting.
    // Clean stop: hold if infotrack has the vehicle; never change the pilot's mode.
    let link = &vehicle.link;
    let why = match tracked.stopped_by {
        StopReason::Duration => "duration",
        StopReason::Signal => "signal",
        StopReason::Fault => "fault",
        StopReason::OriginChanged => "origin changed",
    };
    let said = if tracked.engaged {
        match link.hold().await {
            Ok(()) => Some(gcs_report::GcsReporter::stopped(why)),
            Err(e) => {
                tracing::error!("could not put the vehicle in hold: {e}");
                None
            }
        }
    } else {
        link.pause_setpoints(true);
        Some(gcs_report::GcsReporter::stopped_released(why))
    };
    if let Some((severity, text)) = said {
        tell(link, severity, &text).await;
    }
    let output = match joined {
        Ok(Ok(output)) => output,
        _ => {
            link.flush_tlog();
            return Err(DaemonError::PipelineDied(
                "with a panic (the vehicle was put in hold)",
            ));
        }
    };
    let state = link.state();
    let setpoints = link.setpoint_stats();
    link.flush_tlog();
    // The metrics are those of the time infotrack had the vehicle (none if it never did).
    let from_s = tracked.engaged_after_s.unwrap_or(f64::INFINITY);
    let steps: Vec<_> = output
        .records
        .iter()
        .filter(|r| r.step.t_s >= from_s)
        .map(|r| r.step.clone())
        .collect();
    let summary = RunSummary::from_steps(&steps, &output.filter_ms, &output.guidance_ms);
    Ok(DaemonReport {
        summary,
        stopped_by: tracked.stopped_by,
        final_mode: state.mode,
        unexpected_mode_changes: state.unexpected_mode_changes.clone(),
        mode_changes_before_arming: state.mode_changes_before_arming.clone(),
        link_losses: tracked.link_losses,
        geofence_refusals: tracked.geofence_refusals,
        setpoints_sent: setpoints.sent,
        setpoint_rate_hz: setpoints.rate_hz(),
        flavor: vehicle.flavor,
        vehicle: match &vehicle.mock {
            Some(_) => format!("{} via {}", vehicle.name, vehicle.url),
            None => vehicle.url.clone(),
        },
        mock: vehicle.mock,
        output,
    })
}
