//! The daemon (`infotrack run`): the closed loop from camera to setpoints.
//!
//! Tasks: the vehicle link (heartbeat, telemetry reader, setpoint streamer at >= 10 Hz,
//! heartbeat watchdog), a supervisor loop (`supervisor.rs`) that feeds the vehicle's pose to
//! the pipeline, applies its commands inside the geofence, pauses commands while the link is
//! lost, prints the status line and stops on SIGINT/SIGTERM, the duration or a fault; and the
//! pipeline thread (camera, detector, particle filter with the DMMN, EER) off the reactor.
//! Getting the vehicle airborne is `airborne.rs`; the run's options and report `options.rs`.
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

mod airborne;
pub mod engagement;
mod field_camera;
pub mod flight_log;
pub mod gcs_report;
pub mod heading;
mod options;
pub mod permits;
pub mod pipeline;
pub mod pose_history;
pub mod recorder;
pub mod replay;
mod sensor;
pub mod simulators;
mod supervisor;
mod vehicle_speed;
pub mod visual;

use airborne::{check_world_origin, connect, launch};
pub use options::{
    BadFault, DaemonReport, FaultKind, RunOptions, ScheduledFault, StopReason, VehiclePermits,
};
pub use simulators::{InProcessVehicle, Simulators, SyntheticWorld};
use supervisor::{stop, track};

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
    /// The visual record cannot be written where asked.
    #[error(transparent)]
    VisualRecord(#[from] infotrack_record::RecordError),
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
    MockStart(simulators::SimulatorError),
    /// A simulated part was asked for that the program does not provide.
    #[error("this program does not provide {0}; use a real vehicle and camera")]
    NoSimulator(&'static str),
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
    /// The vehicle's origin does not agree with its own position messages.
    #[error(
        "world.origin: the vehicle's origin cannot be trusted: {0}. Nothing was commanded \
         (an origin spoofed on the link, or an estimator that has not settled)"
    )]
    OriginDisagrees(String),
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
    /// A simulation was asked to fly a vehicle that is not the in-process mock.
    #[error(
        "refusing to fly a simulation on `{vehicle}`, which is not the in-process mock: {what}. \
         Nothing was sent. Fly a real vehicle with a field config (--config, a real camera), \
         or pass --allow-simulation-on-vehicle to fly this simulation on a SITL autopilot on purpose"
    )]
    SimulationOnVehicle {
        /// `daemon.vehicle`.
        vehicle: String,
        /// What is simulated.
        what: String,
    },
    /// `daemon.engage = "auto"` on a vehicle that is not the in-process mock, not allowed.
    #[error(
        "refusing to arm and take off `{0}` by itself (daemon.engage = \"auto\"): nothing was \
         sent. Use daemon.engage = \"pilot\" (the pilot takes off and hands over), or pass \
         --allow-auto-engage to let infotrack arm and take off this vehicle"
    )]
    AutoEngageOnVehicle(String),
    /// The simulated-clock runtime could not be built.
    #[error("cannot build the simulated-clock runtime: {0}")]
    Runtime(std::io::Error),
}

/// The vehicle, once heard.
struct Vehicle {
    link: VehicleLink,
    flavor: Flavor,
    /// `daemon.vehicle` as configured.
    name: String,
    url: String,
    mock: Option<Box<dyn InProcessVehicle>>,
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
    permits::check(cfg, opts.permits)?;
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
    let visual = opts
        .visual_record
        .as_deref()
        .map(|p| visual::VisualRecord::create(p, &cfg.world()))
        .transpose()?;
    let thread = {
        let start = pipeline::Start {
            cfg: cfg.clone(),
            motion_name: opts.motion.clone(),
            seed: opts.seed,
            recorder,
            visual,
            synthetic: opts.simulators.synthetic_world.clone(),
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
