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

pub mod flight_log;
pub mod pipeline;
pub mod pose_history;
pub mod replay;

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::Duration;
use tokio::time::Instant;

use thiserror::Error;

use crate::autopilot::frames::PositionEnu;
use crate::autopilot::link::{LinkConfig, LinkError, VehicleLink};
use crate::autopilot::modes::{Flavor, Mode};
use crate::autopilot::signing::SigningKey;
use crate::config::Config;
use crate::metrics::RunSummary;
use crate::mock::server::{spawn, Faults, MockHandle};
use crate::mock::MockConfig;
use crate::vision::camera_model::VehiclePoseNed;
use pipeline::{Command, PipelineOutput, Ready, Shared, VehicleSnapshot};

/// Why the daemon stopped with an error.
#[derive(Debug, Error)]
pub enum DaemonError {
    /// A setting or input is wrong.
    #[error("{0}")]
    Setup(String),
    /// The vehicle link failed.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// SIGINT or SIGTERM before tracking began.
    #[error("stopped by a signal {0}")]
    Interrupted(&'static str),
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
        }
    }
}

impl std::str::FromStr for ScheduledFault {
    type Err = String;

    /// `camera-freeze@20+5`, `link-cut@40+5`, `loss=30@10+5` (KIND@START+DURATION, seconds).
    fn from_str(s: &str) -> Result<Self, String> {
        let usage = || {
            format!("`{s}`: expected KIND@START+DURATION (seconds), KIND one of camera-freeze, link-cut, loss=PERCENT; e.g. camera-freeze@20+5")
        };
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
    /// Mode changes the vehicle made by itself (failsafes).
    pub unexpected_mode_changes: Vec<(Mode, Mode)>,
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
        .map_err(|e| DaemonError::Setup(format!("no free UDP port on loopback: {e}")))
}

/// Starts the in-process mock for `mock:px4` / `mock:ardupilot`, with the agent's speed and
/// acceleration limits as its parameters; returns it and the URL to reach it.
async fn start_mock(cfg: &Config, flavor: Flavor) -> Result<(MockHandle, String), DaemonError> {
    let port = free_udp_port()?;
    let mut mc = MockConfig::new(flavor);
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
        ],
    };
    let mock = spawn(&format!("udpin:127.0.0.1:{port}"), mc, Faults::default())
        .await
        .map_err(|e| DaemonError::Setup(format!("cannot start the mock autopilot: {e}")))?;
    Ok((mock, format!("udpout:127.0.0.1:{port}")))
}

/// Resolves when SIGINT or SIGTERM arrives. The handlers are installed by this call, not at
/// the first poll, so that a signal during connection or takeoff is caught too (the default
/// action would kill the process with the vehicle in the air).
fn shutdown_signal() -> std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>> {
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

fn snapshot(link: &VehicleLink) -> Option<VehicleSnapshot> {
    let s = link.state();
    let (_, p, _) = s.local_ned?;
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
    let d = cfg.daemon.clone();
    // The pipeline first: a missing model or a bad detector setting is an error before
    // anything flies.
    let shared = Shared::new();
    let (ready_tx, ready_rx) = mpsc::channel();
    let (tick_tx, tick_rx) = mpsc::channel();
    let (done_tx, done_rx) = mpsc::channel();
    let pipeline = {
        let (cfg, shared, motion, seed) =
            (cfg.clone(), shared.clone(), opts.motion.clone(), opts.seed);
        std::thread::Builder::new()
            .name("pipeline".into())
            .spawn(move || pipeline::run(cfg, motion, seed, shared, ready_tx, tick_rx, done_tx))
            .map_err(|e| DaemonError::Setup(format!("cannot start the pipeline thread: {e}")))?
    };
    let ready = tokio::task::spawn_blocking(move || ready_rx.recv())
        .await
        .map_err(|e| DaemonError::Setup(e.to_string()))?;
    match ready {
        Ok(Ready::Ok) => {}
        Ok(Ready::Err(e)) => return Err(DaemonError::Setup(e)),
        Err(_) => {
            return Err(DaemonError::Setup(
                "the pipeline thread died at start".into(),
            ))
        }
    }

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
            .any(|f| !matches!(f.kind, FaultKind::CameraFreeze))
    {
        return Err(DaemonError::Setup(
            "link faults can be injected only into the in-process mock (mock:px4, mock:ardupilot)"
                .into(),
        ));
    }
    let mut lc = LinkConfig::new(&url);
    lc.system_id = d.system_id;
    lc.component_id = d.component_id;
    lc.setpoint_hz = d.setpoint_hz;
    lc.geofence_enu = Some(cfg.workspace_enu);
    lc.tlog = opts.tlog.clone();
    lc.signing_key = d
        .signing_key
        .as_deref()
        .map(SigningKey::load)
        .transpose()
        .map_err(|e| DaemonError::Setup(e.to_string()))?;
    let mut signal = shutdown_signal();
    let link = VehicleLink::connect(lc).await?;
    let flavor = tokio::select! {
        f = link.wait_vehicle(Duration::from_secs_f64(d.connect_timeout_s)) => f?,
        _ = &mut signal => {
            return Err(DaemonError::Interrupted("while waiting for the vehicle; nothing was commanded"))
        }
    };
    tracing::info!("vehicle: {flavor} on {url}");
    let launch = async {
        link.request_telemetry().await?;
        link.take_off(
            cfg.agent.altitude_m,
            Duration::from_secs_f64(d.takeoff_timeout_s),
        )
        .await?;
        // Start where the simulator's agent starts (agent.start_enu_m), at the tracking
        // altitude, before tracking begins: the scenario's initial condition.
        let start = PositionEnu {
            x_east_m: cfg.agent.start_enu_m[0],
            y_north_m: cfg.agent.start_enu_m[1],
            z_up_m: cfg.agent.altitude_m,
        };
        link.set_setpoint(start, 0.0)?;
        let want = start.to_ned();
        // Not VehicleLink::wait_for: that polls every 20 ms, and the instant tracking begins
        // decides the simulated flights (and the recorded numbers of each seed).
        let until = Instant::now() + Duration::from_secs_f64(d.takeoff_timeout_s);
        loop {
            if let Some((_, p, v)) = link.state().local_ned {
                let off = (p.x_north_m - want.x_north_m)
                    .hypot(p.y_east_m - want.y_east_m)
                    .hypot(p.z_down_m - want.z_down_m);
                let speed = v.iter().map(|c| (*c as f64).powi(2)).sum::<f64>().sqrt();
                if off < 0.05 && speed < 0.05 {
                    return Ok(());
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
    };
    let launched: Result<(), DaemonError> = tokio::select! {
        r = launch => r.map_err(DaemonError::from),
        _ = &mut signal => Err(DaemonError::Interrupted(
            "during takeoff, before tracking began; the vehicle was put in hold",
        )),
    };
    if let Err(e) = launched {
        // A takeoff that failed or was stopped half-way may have left the vehicle armed and
        // climbing.
        shared.stop.store(true, Ordering::Relaxed);
        drop(tick_tx);
        if let Err(h) = link.hold().await {
            tracing::error!("could not put the vehicle in hold: {h}");
        }
        link.flush_tlog();
        return Err(e);
    }

    *shared.vehicle.lock().expect("shared poisoned") = snapshot(&link);
    let ticker = tokio::spawn(drive_pipeline(
        tick_tx,
        done_rx,
        Duration::from_secs_f64(1.0 / cfg.timing.physics_hz),
        shared.clone(),
    ));
    let began = Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(20));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut last_status = Instant::now();
    let mut applied: Option<Command> = None;
    let mut geofence_refusals = 0u64;
    let mut link_losses = 0u32;
    let mut was_lost = false;
    let mut fault_active = vec![false; opts.faults.len()];
    let stopped_by = loop {
        tokio::select! {
            _ = &mut signal => break StopReason::Signal,
            _ = tick.tick() => {}
        }
        if began.elapsed().as_secs_f64() >= opts.duration_s {
            break StopReason::Duration;
        }
        if pipeline.is_finished() || ticker.is_finished() {
            // The pipeline died (a panic): nothing decides any more; hold.
            tracing::error!("the pipeline thread stopped; holding the vehicle");
            break StopReason::Fault;
        }
        let now_s = began.elapsed().as_secs_f64();
        let mut toggled = false;
        for (f, active) in opts.faults.iter().zip(fault_active.iter_mut()) {
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
            match (f.kind, mock.as_ref()) {
                (FaultKind::CameraFreeze, _) => shared.camera_frozen.store(on, Ordering::Relaxed),
                (FaultKind::LinkCut, Some(m)) if on => {
                    m.cut_link(Duration::from_secs_f64(f.duration_s))
                }
                (FaultKind::PacketLoss(p), Some(m)) => m.set_faults(Faults {
                    loss_percent: if on { p } else { 0.0 },
                    seed: opts.seed,
                    ..Faults::default()
                }),
                _ => {}
            }
        }
        if toggled {
            let active: Vec<String> = opts
                .faults
                .iter()
                .zip(&fault_active)
                .filter(|(_, on)| **on)
                .map(|(f, _)| f.kind.name())
                .collect();
            *shared.faults.lock().expect("shared poisoned") = active.join("+");
        }
        let snap = snapshot(&link);
        *shared.vehicle.lock().expect("shared poisoned") = snap;
        if let (Some(sn), Some((at, _, _))) = (snap, link.state().local_ned) {
            // Stamped with the telemetry's arrival, for frames from a real camera.
            shared
                .poses
                .lock()
                .expect("shared poisoned")
                .push(at, sn.pose);
        }
        let lost = link.state().lost;
        if lost != was_lost {
            // Commands on stale state are worse than none: the vehicle's own failsafe acts.
            link.pause_setpoints(lost);
            if lost {
                link_losses += 1;
            }
            was_lost = lost;
        }
        let cmd = *shared.command.lock().expect("shared poisoned");
        if cmd != applied && !lost {
            if let Some(c) = cmd {
                let target = match c {
                    Command::GoTo(w) => Some(w),
                    Command::HoldHere => snap.map(|s| {
                        crate::world::geometry::Enu2::new(
                            s.pose.position_ned_m[1],
                            s.pose.position_ned_m[0],
                        )
                    }),
                };
                if let Some(w) = target {
                    let p = PositionEnu {
                        x_east_m: w.x,
                        y_north_m: w.y,
                        z_up_m: cfg.agent.altitude_m,
                    };
                    if let Err(e) = link.set_setpoint(p, 0.0) {
                        geofence_refusals += 1;
                        tracing::warn!("{e}");
                    }
                }
            }
            applied = cmd;
        }
        if opts.status_line && last_status.elapsed() >= Duration::from_secs(1) {
            last_status = Instant::now();
            let st = *shared.status.lock().expect("shared poisoned");
            let mode = link
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
    };

    shared.stop.store(true, Ordering::Relaxed);
    // The driver sees the stop at its next tick and closes the tick channel: the pipeline
    // thread then returns its output.
    let _ = ticker.await;
    let joined = tokio::task::spawn_blocking(move || pipeline.join()).await;
    // Clean stop, whatever happened to the pipeline: hold before exiting.
    let hold = link.hold().await;
    if let Err(e) = &hold {
        tracing::error!("could not put the vehicle in hold: {e}");
    }
    let output = joined
        .map_err(|e| DaemonError::Setup(e.to_string()))?
        .map_err(|_| {
            link.flush_tlog();
            DaemonError::Setup("the pipeline thread panicked (the vehicle was put in hold)".into())
        })?;
    let state = link.state();
    link.flush_tlog();
    let steps: Vec<_> = output.records.iter().map(|r| r.step.clone()).collect();
    let summary = RunSummary::from_steps(&steps, &output.filter_ms, &output.guidance_ms);
    Ok(DaemonReport {
        summary,
        stopped_by,
        final_mode: state.mode,
        unexpected_mode_changes: state.unexpected_mode_changes.clone(),
        link_losses,
        geofence_refusals,
        flavor,
        vehicle: if mock.is_some() {
            format!("{} via {url}", d.vehicle)
        } else {
            url.clone()
        },
        mock,
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
        return Err(DaemonError::Setup(format!(
            "the simulated clock needs the in-process mock and the synthetic camera \
             (daemon.vehicle = \"{}\", daemon.camera = \"{}\"); fly real hardware with `infotrack run`",
            cfg.daemon.vehicle, cfg.daemon.camera
        )));
    }
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .map_err(|e| {
            DaemonError::Setup(format!("cannot build the simulated-clock runtime: {e}"))
        })?;
    rt.block_on(run(cfg, opts))
}
