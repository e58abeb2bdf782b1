//! The daemon (`infotrack run`): the closed loop from camera to setpoints.
//!
//! Tasks: the vehicle link (heartbeat, telemetry reader, setpoint streamer at >= 10 Hz,
//! heartbeat watchdog), a supervisor loop here that feeds the vehicle's pose to the pipeline,
//! applies its commands inside the geofence, pauses commands while the link is lost, prints
//! the status line and stops on SIGINT/SIGTERM, the duration or a fault; and the pipeline
//! thread (camera, detector, particle filter with the DMMN, EER) off the reactor.
//!
//! On the embedded default the vehicle is an in-process mock autopilot reached through real
//! MAVLink over loopback UDP, and the camera is the synthetic one.
//!
//! With `daemon.camera` a capture source instead of `synthetic`, frames come from the
//! camera, each projected with the vehicle pose interpolated at its capture time, and there
//! is no simulated target.
//!
//! Every timer here, in the link and in the mock is on tokio's clock and the pipeline is
//! stepped by that clock (one blocking task per tick): on a runtime whose time is paused
//! ([`run_simulated`]) the whole daemon flies faster than real time through the same code.

pub mod engagement;
pub mod flight_log;
pub mod gcs_report;
pub mod pipeline;
pub mod pose_history;
pub mod recorder;
pub mod replay;
mod vehicle_speed;

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::Duration;
use tokio::time::Instant;

use thiserror::Error;

use crate::autopilot::link::{LinkConfig, LinkError, VehicleLink};
use crate::autopilot::modes::{Flavor, Mode};
use crate::autopilot::signing::SigningKey;
use crate::config::{Config, Engage};
use crate::frames::Enu2;
use crate::frames::PositionEnu;
use crate::metrics::RunSummary;
use crate::mock::server::{spawn, Faults, MockHandle};
use crate::mock::MockConfig;
use crate::vision::camera_model::VehiclePoseNed;
use pipeline::{Command, PipelineOutput, Ready, Shared, VehicleSnapshot};
use recorder::FlightRecorder;

/// Why the daemon stopped with an error.
#[derive(Debug, Error)]
pub enum DaemonError {
    /// The vehicle link failed.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The pipeline (camera, detector, model) could not start.
    #[error(transparent)]
    Pipeline(#[from] pipeline::PipelineError),
    /// The flight's records cannot be written where asked.
    #[error(transparent)]
    Records(#[from] recorder::RecorderError),
    /// SIGINT or SIGTERM before tracking began.
    #[error("stopped by a signal {0}")]
    Interrupted(&'static str),
    /// The pipeline thread could not be started.
    #[error("cannot start the pipeline thread: {0}")]
    PipelineThread(std::io::Error),
    /// The pipeline thread ended when it should not have.
    #[error("the pipeline thread died {0}")]
    PipelineDied(&'static str),
    /// The in-process mock autopilot could not be started.
    #[error("cannot start the mock autopilot: {0}")]
    MockStart(std::io::Error),
    /// `daemon.signing_key` could not be used.
    #[error("daemon.signing_key: {0}")]
    SigningKey(#[from] crate::autopilot::signing::SigningKeyError),
    /// Link faults were asked for with a real vehicle.
    #[error(
        "link faults can be injected only into the in-process mock (mock:px4, mock:ardupilot)"
    )]
    LinkFaultNeedsMock,
    /// The simulated clock was asked for with real hardware.
    #[error(
        "the simulated clock needs the in-process mock and the synthetic camera \
         (daemon.vehicle = \"{vehicle}\", daemon.camera = \"{camera}\"); fly real hardware with `infotrack run`"
    )]
    SimulatedClockNeedsSimulation {
        /// `daemon.vehicle`.
        vehicle: String,
        /// `daemon.camera`.
        camera: String,
    },
    /// `daemon.engage = "pilot"` with a vehicle that has no pilot.
    #[error(
        "daemon.engage = \"pilot\" needs a vehicle with a pilot; the in-process mock \
         ({0}) has none: use daemon.engage = \"auto\" or a real vehicle (or a mock-autopilot a test drives)"
    )]
    PilotNeedsVehicle(String),
    /// `[world]` is set and the vehicle's origin cannot be checked against it.
    #[error(
        "world.origin: the vehicle reported no GPS_GLOBAL_ORIGIN within {0} s (no GPS fix or \
         no estimator origin yet?); infotrack flies a world on Earth only when it knows where \
         the vehicle's local frame is"
    )]
    NoVehicleOrigin(f64),
    /// The vehicle's origin is too far from the world's.
    #[error(
        "world.origin: the vehicle's local origin ({vehicle_lat:.7}, {vehicle_lon:.7}) is \
         {distance_m:.1} m from the world's ({world_lat:.7}, {world_lon:.7}), more than \
         world.origin_tolerance_m = {tolerance_m} m: too far for this world (the wrong world \
         file, or a vehicle that started its estimator elsewhere?). Within the tolerance \
         infotrack converts between the two frames"
    )]
    OriginTooFar {
        /// The vehicle's origin.
        vehicle_lat: f64,
        /// The vehicle's origin.
        vehicle_lon: f64,
        /// The world's origin.
        world_lat: f64,
        /// The world's origin.
        world_lon: f64,
        /// Between them, m.
        distance_m: f64,
        /// The tolerance, m.
        tolerance_m: f64,
    },
    /// The simulated-clock runtime could not be built.
    #[error("cannot build the simulated-clock runtime: {0}")]
    Runtime(std::io::Error),
}

/// Command-line choices of one run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Seconds of tracking after takeoff.
    pub duration_s: f64,
    /// Seed of the simulated world, the filter and guidance.
    pub seed: u64,
    /// Motion model name for the filter (`dmmn`, `cv`).
    pub motion: String,
    /// Telemetry log to write, if any.
    pub tlog: Option<PathBuf>,
    /// Folder the flight's records (`steps.csv`, `flight.csv`, `summary.json`) are
    /// written into as the flight goes, if any.
    pub records_dir: Option<PathBuf>,
    /// Print the status line every second on stderr.
    pub status_line: bool,
    /// Faults to inject during the flight (tests, demonstrations).
    pub faults: Vec<ScheduledFault>,
}

/// A fault the daemon injects into its own loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// The camera delivers no frames.
    CameraFreeze,
    /// The MAVLink link is cut both ways (in-process mock only).
    LinkCut,
    /// This share of MAVLink messages is lost, percent (in-process mock only).
    PacketLoss(f64),
    /// The pipeline thread panics (a bug in the tracker, simulated): the supervisor must
    /// hold the vehicle.
    PipelinePanic,
}

/// A fault from `at_s` (seconds after tracking starts) for `duration_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScheduledFault {
    /// What.
    pub kind: FaultKind,
    /// When it starts, s after tracking starts.
    pub at_s: f64,
    /// How long it lasts, s.
    pub duration_s: f64,
}

impl FaultKind {
    /// The name `--inject` takes (`camera-freeze`, `link-cut`, `loss=30`).
    pub fn name(&self) -> String {
        match self {
            Self::CameraFreeze => "camera-freeze".into(),
            Self::LinkCut => "link-cut".into(),
            Self::PacketLoss(p) => format!("loss={p}"),
            Self::PipelinePanic => "pipeline-panic".into(),
        }
    }
}

/// A `--inject` value that is not a fault.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("`{0}`: expected KIND@START+DURATION (seconds), KIND one of camera-freeze, link-cut, loss=PERCENT, pipeline-panic; e.g. camera-freeze@20+5")]
pub struct BadFault(pub String);

impl std::str::FromStr for ScheduledFault {
    type Err = BadFault;

    /// `camera-freeze@20+5`, `link-cut@40+5`, `loss=30@10+5` (KIND@START+DURATION, seconds).
    fn from_str(s: &str) -> Result<Self, BadFault> {
        let usage = || BadFault(s.to_string());
        let (kind, when) = s.split_once('@').ok_or_else(usage)?;
        let (at, dur) = when.split_once('+').ok_or_else(usage)?;
        let at_s: f64 = at.parse().map_err(|_| usage())?;
        let duration_s: f64 = dur.parse().map_err(|_| usage())?;
        if !(at_s.is_finite() && at_s >= 0.0 && duration_s.is_finite() && duration_s > 0.0) {
            return Err(usage());
        }
        let kind = match kind {
            "camera-freeze" => FaultKind::CameraFreeze,
            "link-cut" => FaultKind::LinkCut,
            "pipeline-panic" => FaultKind::PipelinePanic,
            k => match k.strip_prefix("loss=").map(str::parse::<f64>) {
                Some(Ok(p)) if (0.0..=100.0).contains(&p) => FaultKind::PacketLoss(p),
                _ => return Err(usage()),
            },
        };
        Ok(Self {
            kind,
            at_s,
            duration_s,
        })
    }
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The requested duration elapsed.
    Duration,
    /// SIGINT or SIGTERM.
    Signal,
    /// An internal fault (the pipeline thread died).
    Fault,
}

/// What a run produced.
pub struct DaemonReport {
    /// The pipeline's records and timings.
    pub output: PipelineOutput,
    /// Metrics over the filter steps (as `infotrack sim` computes them).
    pub summary: RunSummary,
    /// Why it ended.
    pub stopped_by: StopReason,
    /// The vehicle's mode after the clean stop.
    pub final_mode: Option<Mode>,
    /// Mode changes the vehicle made by itself once armed (failsafes, the pilot, a GCS).
    pub unexpected_mode_changes: Vec<(Mode, Mode)>,
    /// Mode changes the vehicle made by itself before it first armed (its start-up).
    pub mode_changes_before_arming: Vec<(Mode, Mode)>,
    /// Times the link lost the vehicle's heartbeat.
    pub link_losses: u32,
    /// Setpoints refused by the geofence check.
    pub geofence_refusals: u64,
    /// The firmware flown.
    pub flavor: Flavor,
    /// Where it was reached (`mock:px4 via udpout:...` or the URL).
    pub vehicle: String,
    /// The in-process mock, when the vehicle was one (for tests and fault injection).
    pub mock: Option<MockHandle>,
}

fn free_udp_port() -> Result<u16, DaemonError> {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .map_err(DaemonError::MockStart)
}

/// Starts the in-process mock for `mock:px4` / `mock:ardupilot`, with the agent's speed and
/// acceleration limits as its parameters and ArduPilot's lean limit as the shipped
/// parameter file sets it: a vehicle set up as the README says (a real one needs the same
/// parameters loaded before take-off); returns it and the URL to reach it.
async fn start_mock(cfg: &Config, flavor: Flavor) -> Result<(MockHandle, String), DaemonError> {
    let port = free_udp_port()?;
    let mut mc = MockConfig::new(flavor);
    mc.seed = cfg.seed;
    if cfg.daemon.mock_response == crate::config::MockResponse::Sitl {
        mc.answer_as_sitl();
    }
    let a = &cfg.agent;
    mc.param_overrides = match flavor {
        Flavor::Px4 => vec![
            ("MPC_XY_VEL_MAX".into(), a.speed_limit_mps),
            ("MPC_ACC_HOR".into(), a.accel_limit_mps2),
        ],
        // ArduPilot's are in cm/s and cm/s^2.
        Flavor::ArduPilot => vec![
            ("WPNAV_SPEED".into(), a.speed_limit_mps * 100.0),
            ("WPNAV_ACCEL".into(), a.accel_limit_mps2 * 100.0),
            // firmware-params/ardupilot-guided-tracking.parm: 45 degrees, in centidegrees.
            ("ANGLE_MAX".into(), 4500.0),
        ],
    };
    let mock = spawn(&format!("udpin:127.0.0.1:{port}"), mc, Faults::default())
        .await
        .map_err(DaemonError::MockStart)?;
    Ok((mock, format!("udpout:127.0.0.1:{port}")))
}

/// Resolves when SIGINT or SIGTERM arrives. The handlers are installed by this call, not at
/// the first poll, so that a signal during connection or takeoff is caught too (the default
/// action would kill the process with the vehicle in the air).
fn shutdown_signal() -> ShutdownSignal {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match (
            signal(SignalKind::terminate()),
            signal(SignalKind::interrupt()),
        ) {
            (Ok(mut term), Ok(mut int)) => Box::pin(async move {
                tokio::select! {
                    _ = term.recv() => {}
                    _ = int.recv() => {}
                }
            }),
            _ => Box::pin(std::future::pending()),
        }
    }
    #[cfg(not(unix))]
    {
        Box::pin(async {
            let _ = tokio::signal::ctrl_c().await;
        })
    }
}

/// The vehicle's state for the pipeline, its position in the world frame's NED axes.
fn snapshot(link: &VehicleLink) -> Option<VehicleSnapshot> {
    let (_, p, _) = link.local_ned_in_world()?;
    let s = link.state();
    let att = s.attitude.map(|(_, a)| a).unwrap_or([0.0; 3]);
    Some(VehicleSnapshot {
        pose: VehiclePoseNed {
            position_ned_m: [p.x_north_m, p.y_east_m, p.z_down_m],
            roll_rad: att[0] as f64,
            pitch_rad: att[1] as f64,
            yaw_rad: att[2] as f64,
        },
        link_lost: s.lost,
        mode: s.mode,
    })
}

/// Sends the pipeline thread one tick every `dt` on the runtime's clock and waits for each to
/// be done, until `shared.stop`. The wait is a blocking task: on a paused (simulated) clock
/// tokio does not advance time while one runs, so simulated time stands still while the
/// pipeline computes, exactly as if it were infinitely fast; on the wall clock the wait is off
/// the reactor and late ticks are caught up (the target moves with real time).
async fn drive_pipeline(
    ticks: mpsc::Sender<()>,
    done: mpsc::Receiver<()>,
    dt: Duration,
    shared: std::sync::Arc<Shared>,
) {
    let mut every = tokio::time::interval_at(Instant::now() + dt, dt);
    let mut ends = Some((ticks, done));
    while let Some((ticks, done)) = ends.take() {
        every.tick().await;
        if shared.stop.load(Ordering::Relaxed) {
            return;
        }
        ends = tokio::task::spawn_blocking(move || {
            ticks.send(()).ok()?;
            done.recv().ok()?;
            Some((ticks, done))
        })
        .await
        .ok()
        .flatten();
    }
    // The pipeline thread is gone (a panic): the supervisor notices this task has ended.
}

/// Runs the daemon: starts the pipeline (model, detector), connects to the vehicle, takes
/// off, tracks for `opts.duration_s` (or until SIGINT/SIGTERM), then holds.
pub async fn run(cfg: &Config, opts: &RunOptions) -> Result<DaemonReport, DaemonError> {
    // The pipeline first: a missing model or a bad detector setting is an error before
    // anything flies.
    if cfg.daemon.engage == Engage::Pilot && cfg.daemon.vehicle.starts_with("mock:") {
        return Err(DaemonError::PilotNeedsVehicle(cfg.daemon.vehicle.clone()));
    }
    let (pipeline, channels) = start_pipeline(cfg, opts).await?;
    let mut signal = shutdown_signal();
    let vehicle = connect(cfg, opts, &mut signal).await?;
    if let Some(w) = &cfg.world {
        if let Err(e) = check_world_origin(w, &vehicle.link, cfg.daemon.connect_timeout_s).await {
            pipeline.shared.stop.store(true, Ordering::Relaxed);
            vehicle.link.flush_tlog();
            return Err(e);
        }
    }
    let pilot = cfg.daemon.engage == Engage::Pilot;
    let launched: Result<(), DaemonError> = tokio::select! {
        r = launch(cfg, &vehicle.link) => r.map_err(DaemonError::from),
        _ = &mut signal => Err(DaemonError::Interrupted(if pilot {
            "while waiting for the pilot's takeoff; nothing was commanded"
        } else {
            "during takeoff, before tracking began; the vehicle was put in hold"
        })),
    };
    if let Err(e) = launched {
        pipeline.shared.stop.store(true, Ordering::Relaxed);
        drop(channels);
        // A takeoff that failed or was stopped half-way may have left the vehicle armed and
        // climbing; the pilot's takeoff is the pilot's.
        if !pilot {
            if let Err(h) = vehicle.link.hold().await {
                tracing::error!("could not put the vehicle in hold: {h}");
            }
        }
        vehicle.link.flush_tlog();
        return Err(e);
    }
    let tracked = track(cfg, opts, &vehicle, &pipeline, channels, &mut signal).await;
    stop(vehicle, pipeline, tracked).await
}

/// The pipeline thread and what it shares with the supervisor.
struct PipelineHandle {
    shared: std::sync::Arc<Shared>,
    thread: std::thread::JoinHandle<PipelineOutput>,
    physics_dt: Duration,
}

/// The channels that step the pipeline: one tick out, its end back.
type TickChannels = (mpsc::Sender<()>, mpsc::Receiver<()>);

/// Resolves on SIGINT or SIGTERM.
type ShutdownSignal = std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>>;

/// Phase 1: builds the pipeline (model, detector, camera) on its own thread and waits until
/// it is ready.
async fn start_pipeline(
    cfg: &Config,
    opts: &RunOptions,
) -> Result<(PipelineHandle, TickChannels), DaemonError> {
    let shared = Shared::new();
    let (ready_tx, ready_rx) = mpsc::channel();
    let (tick_tx, tick_rx) = mpsc::channel();
    let (done_tx, done_rx) = mpsc::channel();
    let recorder = opts
        .records_dir
        .as_deref()
        .map(|d| FlightRecorder::open(d, opts.seed, &opts.motion))
        .transpose()?;
    let thread = {
        let start = pipeline::Start {
            cfg: cfg.clone(),
            motion_name: opts.motion.clone(),
            seed: opts.seed,
            recorder,
        };
        let shared = shared.clone();
        std::thread::Builder::new()
            .name("pipeline".into())
            .spawn(move || pipeline::run(start, shared, ready_tx, tick_rx, done_tx))
            .map_err(DaemonError::PipelineThread)?
    };
    let ready = tokio::task::spawn_blocking(move || ready_rx.recv())
        .await
        .map_err(|_| DaemonError::PipelineDied("at start"))?;
    match ready {
        Ok(Ready::Ok) => {}
        Ok(Ready::Err(e)) => return Err(DaemonError::Pipeline(e)),
        Err(_) => return Err(DaemonError::PipelineDied("at start")),
    }
    Ok((
        PipelineHandle {
            shared,
            thread,
            physics_dt: Duration::from_secs_f64(1.0 / cfg.timing.physics_hz),
        },
        (tick_tx, done_rx),
    ))
}

/// The vehicle, once heard.
struct Vehicle {
    link: VehicleLink,
    flavor: Flavor,
    /// `daemon.vehicle` as configured.
    name: String,
    url: String,
    mock: Option<MockHandle>,
}

/// Phase 2: starts the in-process mock if asked, opens the link and waits for the
/// vehicle's heartbeat.
async fn connect(
    cfg: &Config,
    opts: &RunOptions,
    signal: &mut ShutdownSignal,
) -> Result<Vehicle, DaemonError> {
    let d = &cfg.daemon;
    let (mock, url) = match d.vehicle.as_str() {
        "mock:px4" => {
            let (m, u) = start_mock(cfg, Flavor::Px4).await?;
            (Some(m), u)
        }
        "mock:ardupilot" => {
            let (m, u) = start_mock(cfg, Flavor::ArduPilot).await?;
            (Some(m), u)
        }
        url => (None, url.to_string()),
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
    lc.tlog = opts.tlog.clone();
    lc.vehicle = d.vehicle_id.map(|[s, c]| (s, c));
    lc.signing_key = d.signing_key.as_deref().map(SigningKey::load).transpose()?;
    let link = VehicleLink::connect(lc).await?;
    let flavor = tokio::select! {
        f = link.wait_vehicle(Duration::from_secs_f64(d.connect_timeout_s)) => f?,
        _ = &mut *signal => {
            return Err(DaemonError::Interrupted("while waiting for the vehicle; nothing was commanded"))
        }
    };
    tracing::info!("vehicle: {flavor} on {url}");
    vehicle_speed::warn_if_slower_than_planned(cfg, &link, flavor).await;
    Ok(Vehicle {
        link,
        flavor,
        name: d.vehicle.clone(),
        url,
        mock,
    })
}

/// `[world]`: the vehicle's local origin (GPS_GLOBAL_ORIGIN, asked for once) must be known
/// and within the tolerance of the world's before anything is commanded; the link then
/// converts every position and setpoint between the vehicle's frame and the world's.
async fn check_world_origin(
    w: &crate::config::WorldConfig,
    link: &VehicleLink,
    timeout_s: f64,
) -> Result<(), DaemonError> {
    const GPS_GLOBAL_ORIGIN_ID: u32 = 49;
    if let Err(e) = link.request_message(GPS_GLOBAL_ORIGIN_ID).await {
        // Some firmware streams it without answering the request: wait for it anyway.
        tracing::warn!("asking for GPS_GLOBAL_ORIGIN: {e}");
    }
    let until = Instant::now() + Duration::from_secs_f64(timeout_s);
    let origin = loop {
        if let Some(o) = link.state().global_origin {
            break o;
        }
        if Instant::now() > until {
            return Err(DaemonError::NoVehicleOrigin(timeout_s));
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
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
         north of it): positions and setpoints are converted between the two frames"
    );
    link.place_in_world(placement);
    Ok(())
}

/// Phase 3: telemetry, then the takeoff: infotrack's own (`auto`) or the pilot's.
async fn launch(cfg: &Config, link: &VehicleLink) -> Result<(), LinkError> {
    link.request_telemetry().await?;
    match cfg.daemon.engage {
        Engage::Auto => take_off_to_start(cfg, link).await,
        Engage::Pilot => wait_for_pilot_takeoff(link).await,
    }
}

/// `daemon.engage = "pilot"`: waits, as long as it takes, until the pilot has the vehicle
/// armed and off the ground. Nothing is commanded.
async fn wait_for_pilot_takeoff(link: &VehicleLink) -> Result<(), LinkError> {
    /// Above this height over the origin a vehicle that reports no landed state is airborne.
    const AIRBORNE_M: f64 = 0.5;
    tracing::warn!("daemon.engage = pilot: waiting for the pilot to take off");
    let _ = link
        .send_statustext(
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
            tracing::warn!(
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
    link.set_setpoint(start, 0.0)?;
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

/// What the tracking phase counted.
struct Tracked {
    stopped_by: StopReason,
    /// Whether infotrack had the vehicle at the end (then it holds it; else the pilot has it).
    engaged: bool,
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
}

/// Phase 4: steps the pipeline on the runtime's clock and, every 20 ms, feeds it the
/// vehicle's state, applies its command, switches faults and prints the status line, until
/// the duration, a signal or a dead pipeline.
async fn track(
    cfg: &Config,
    opts: &RunOptions,
    vehicle: &Vehicle,
    pipeline: &PipelineHandle,
    (ticks, done): TickChannels,
    signal: &mut ShutdownSignal,
) -> Tracked {
    let shared = &pipeline.shared;
    shared.to_pipeline.lock().expect("shared poisoned").vehicle = snapshot(&vehicle.link);
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
    };
    let (severity, text) = gcs_report::GcsReporter::started(&opts.motion);
    sup.tell_gcs(severity, &text).await;
    let stopped_by = loop {
        tokio::select! {
            _ = &mut *signal => break StopReason::Signal,
            _ = tick.tick() => {}
        }
        if began.elapsed().as_secs_f64() >= opts.duration_s {
            break StopReason::Duration;
        }
        if pipeline.thread.is_finished() || ticker.is_finished() {
            // The pipeline died (a panic): nothing decides any more; hold.
            tracing::error!("the pipeline thread stopped; holding the vehicle");
            break StopReason::Fault;
        }
        sup.switch_faults(began.elapsed().as_secs_f64());
        let snap = sup.feed_vehicle_state();
        sup.follow_pilot().await;
        sup.apply_command(snap);
        sup.print_status();
        sup.report_to_gcs().await;
    };
    Tracked {
        stopped_by,
        engaged: sup.engagement.holds_at_stop()
            && (cfg.daemon.engage == Engage::Auto
                || vehicle.link.state().mode == Some(Mode::companion_for(vehicle.flavor))),
        link_losses: sup.link_losses,
        geofence_refusals: sup.geofence_refusals,
        ticker,
    }
}

impl Supervisor<'_> {
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
                (FaultKind::PipelinePanic, _) if on => {
                    self.shared
                        .to_pipeline
                        .lock()
                        .expect("shared poisoned")
                        .panic = true
                }
                (FaultKind::CameraFreeze, _) => {
                    self.shared
                        .to_pipeline
                        .lock()
                        .expect("shared poisoned")
                        .camera_frozen = on
                }
                (FaultKind::LinkCut, Some(m)) if on => {
                    m.cut_link(Duration::from_secs_f64(f.duration_s))
                }
                (FaultKind::PacketLoss(p), Some(m)) => m.set_faults(Faults {
                    loss_percent: if on { p } else { 0.0 },
                    seed: self.opts.seed,
                    ..Faults::default()
                }),
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
            self.shared
                .to_pipeline
                .lock()
                .expect("shared poisoned")
                .faults = active.join("+");
        }
    }

    /// Gives the pipeline the vehicle's latest state (and the pose history for a real
    /// camera); pauses setpoints while the link is lost.
    fn feed_vehicle_state(&mut self) -> Option<VehicleSnapshot> {
        let link = &self.vehicle.link;
        let snap = snapshot(link);
        self.shared
            .to_pipeline
            .lock()
            .expect("shared poisoned")
            .vehicle = snap;
        if let (Some(sn), Some((at, _, _))) = (snap, link.state().local_ned) {
            // Stamped with the telemetry's arrival, for frames from a real camera.
            self.shared
                .poses
                .lock()
                .expect("shared poisoned")
                .push(at, sn.pose);
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
                    Some(here) => link.set_setpoint(here, 0.0).is_err(),
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
            let target = match c {
                Command::GoTo {
                    position_enu,
                    velocity_enu,
                } => Some((position_enu, velocity_enu)),
                Command::HoldHere => snap.map(|s| (s.pose.position_enu(), Enu2::zeros())),
            };
            if let Some((w, v)) = target {
                let p = PositionEnu::from_xy(&w, self.cfg.agent.altitude_m);
                if let Err(e) = self.vehicle.link.set_moving_setpoint(p, v, 0.0) {
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
        tracing::info!("{text}");
        if let Err(e) = self.vehicle.link.send_statustext(severity, text).await {
            tracing::debug!("STATUSTEXT `{text}`: {e}");
        }
    }

    /// The status line, once a second, when asked for.
    fn print_status(&mut self) {
        if !self.opts.status_line || self.last_status.elapsed() < Duration::from_secs(1) {
            return;
        }
        self.last_status = Instant::now();
        let st = self.shared.pipeline_view().status;
        let mode = self
            .vehicle
            .link
            .state()
            .mode
            .map(|m| format!("{m:?}"))
            .unwrap_or_else(|| "?".into());
        if let Some(s) = st {
            eprintln!(
                "t={:5.1}s mode={mode} target={} N_eff={:6.1} H={:6.2} state={}",
                s.t_s,
                if s.seen { "seen" } else { "unseen" },
                s.n_eff,
                s.entropy,
                s.state.as_str()
            );
        }
    }
}

/// Phase 5: stops the pipeline, holds the vehicle whatever happened, and reports.
async fn stop(
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
        if let Err(e) = link.send_statustext(severity, &text).await {
            tracing::debug!("STATUSTEXT `{text}`: {e}");
        }
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
    link.flush_tlog();
    let steps: Vec<_> = output.records.iter().map(|r| r.step.clone()).collect();
    let summary = RunSummary::from_steps(&steps, &output.filter_ms, &output.guidance_ms);
    Ok(DaemonReport {
        summary,
        stopped_by: tracked.stopped_by,
        final_mode: state.mode,
        unexpected_mode_changes: state.unexpected_mode_changes.clone(),
        mode_changes_before_arming: state.mode_changes_before_arming.clone(),
        link_losses: tracked.link_losses,
        geofence_refusals: tracked.geofence_refusals,
        flavor: vehicle.flavor,
        vehicle: match &vehicle.mock {
            Some(_) => format!("{} via {}", vehicle.name, vehicle.url),
            None => vehicle.url.clone(),
        },
        mock: vehicle.mock,
        output,
    })
}

/// Runs the daemon on a simulated clock: a single-threaded runtime whose time is paused and
/// jumps to the next timer whenever every task waits (tokio's `start_paused`), with the
/// pipeline computing while time stands still. Through the same code as [`run`], real
/// MAVLink over loopback and rendered frames, but as fast as the CPU allows. Only for the
/// simulated world: a real camera or a real vehicle lives on the wall clock.
pub fn run_simulated(cfg: &Config, opts: &RunOptions) -> Result<DaemonReport, DaemonError> {
    if !cfg.daemon.vehicle.starts_with("mock:") || cfg.daemon.camera != "synthetic" {
        return Err(DaemonError::SimulatedClockNeedsSimulation {
            vehicle: cfg.daemon.vehicle.clone(),
            camera: cfg.daemon.camera.clone(),
        });
    }
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .map_err(DaemonError::Runtime)?;
    rt.block_on(run(cfg, opts))
}
