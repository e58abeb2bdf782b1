//! The daemon's pipeline thread: the simulated world (target on its roads), the camera
//! (rendered from the vehicle's reported pose), the detector, the particle filter with the
//! DMMN, and EER guidance, one physics tick per message from the supervisor (which ticks on
//! the runtime's clock: wall-clock or simulated). It runs on its own OS thread so that the
//! DMMN, the filter and EER never block the async reactor; it talks to the async side only
//! through [`Shared`] and the tick channels.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

use crate::config::Config;
use crate::estimation::{FilterParams, ParticleFilter};
use crate::guidance::{EerParams, EerPlanner, LawnmowerPath};
use crate::metrics::StepRecord;
use crate::motion;
use crate::rng::{stream_rng, Stream};
use crate::sim::target::TargetSim;
use crate::sim::vision_sensor::{VisionSensor, VisionStats};
use crate::vision::camera_model::{CameraModel, CameraMount, VehiclePoseNed};
use crate::vision::capture::{Camera, CaptureConfig};
use crate::vision::detector::{AprilTagDetector, RoiPx, RoiSearch};
use crate::vision::projection::{measure_tag, ProjectionNoise};
use crate::world::geometry::Enu2;
use crate::world::World;

/// The vehicle as the link last reported it.
#[derive(Debug, Clone, Copy)]
pub struct VehicleSnapshot {
    /// Pose from LOCAL_POSITION_NED and ATTITUDE.
    pub pose: VehiclePoseNed,
    /// No heartbeat for the link's timeout.
    pub link_lost: bool,
    /// The flight mode the vehicle last reported.
    pub mode: Option<crate::autopilot::modes::Mode>,
}

/// What the pipeline asks the vehicle to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Fly to this point, world ENU, at the agent's altitude.
    GoTo(Enu2),
    /// Stay where it is (target-lost fallback `hold`).
    HoldHere,
}

/// Tracking state, for the status line and the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackState {
    /// Seen within the target-lost time.
    Tracking,
    /// Not seen for longer: the fallback is flying.
    Lost,
    /// No fresh vehicle state: no new commands.
    LinkLost,
    /// No camera frames for the camera timeout: hold and report.
    CameraLost,
}

impl TrackState {
    /// Lower-case name.
    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Tracking => "tracking",
            Self::Lost => "lost",
            Self::LinkLost => "link-lost",
            Self::CameraLost => "camera-lost",
        }
    }
}

/// What the status line shows.
#[derive(Debug, Clone, Copy)]
pub struct Status {
    /// Seconds since tracking started.
    pub t_s: f64,
    /// Whether the last frame had the target.
    pub seen: bool,
    /// Effective sample size after the last update.
    pub n_eff: f64,
    /// Entropy of the estimate at the last guidance decision.
    pub entropy: f64,
    /// Tracking state.
    pub state: TrackState,
}

/// State shared between the pipeline thread and the async side.
pub struct Shared {
    /// Latest vehicle state (written by the async side).
    pub vehicle: Mutex<Option<VehicleSnapshot>>,
    /// Latest command (written by the pipeline).
    pub command: Mutex<Option<Command>>,
    /// Status line.
    pub status: Mutex<Option<Status>>,
    /// Ask the pipeline to finish.
    pub stop: AtomicBool,
    /// Injected faults in force, `+`-joined (written by the supervisor, logged per step).
    pub faults: Mutex<String>,
    /// The camera delivers nothing while set (fault injection: a frozen camera).
    pub camera_frozen: AtomicBool,
    /// Recent vehicle poses by arrival time (written by the async side), for frames from a
    /// real camera.
    pub poses: Mutex<super::pose_history::PoseHistory>,
}

impl Shared {
    /// Empty shared state.
    pub fn new() -> Arc<Self> {
        Arc::new(Self {
            vehicle: Mutex::new(None),
            command: Mutex::new(None),
            status: Mutex::new(None),
            stop: AtomicBool::new(false),
            faults: Mutex::new(String::new()),
            camera_frozen: AtomicBool::new(false),
            poses: Mutex::new(super::pose_history::PoseHistory::new(Duration::from_secs(
                2,
            ))),
        })
    }
}

/// One filter step of the daemon, beyond what the simulator records.
#[derive(Debug, Clone)]
pub struct FlightRecord {
    /// The simulator-compatible record (truth, vehicle position, measurement, estimate...).
    pub step: StepRecord,
    /// Vehicle pose at the frame.
    pub pose: VehiclePoseNed,
    /// Tracking state.
    pub state: TrackState,
    /// Whether a camera frame was taken at this step.
    pub frame: bool,
    /// The command in force after this step.
    pub command: Option<Command>,
    /// Entropy of the estimate at the latest EER decision (NaN before the first).
    pub entropy: f64,
    /// The flight mode the vehicle reported at this step.
    pub vehicle_mode: Option<crate::autopilot::modes::Mode>,
    /// Faults injected at this step (`camera-freeze`, `link-cut`, `loss=30`), `+`-joined;
    /// empty: none.
    pub faults: String,
}

/// What the pipeline produced.
#[derive(Debug, Default)]
pub struct PipelineOutput {
    /// One per filter step.
    pub records: Vec<FlightRecord>,
    /// Filter step times, ms.
    pub filter_ms: Vec<f64>,
    /// Guidance decision times, ms.
    pub guidance_ms: Vec<f64>,
    /// Of each filter step: detection and ground projection of the frame, ms.
    pub detect_ms: Vec<f64>,
    /// Of each filter step: the particle filter's prediction (DMMN) and update, ms.
    pub update_ms: Vec<f64>,
    /// Frame-to-command processing latency, ms, for every command: detection, projection and
    /// filter update of the latest frame plus the guidance decision (the wait between the
    /// frame and the next guidance tick is a matter of rates and is not included).
    pub latency_ms: Vec<f64>,
    /// Guidance decisions dropped for overrunning the budget.
    pub guidance_overruns: u64,
    /// Frame statistics.
    pub vision: VisionStats,
    /// Filter periods without a camera frame.
    pub frames_missed: u64,
}

/// Messages from the pipeline thread before it runs.
pub enum Ready {
    /// Built: model loaded, detector up.
    Ok,
    /// Could not start.
    Err(String),
}

/// A real camera: frames from capture, projected with the pose at their capture time.
struct FieldCamera {
    camera: Camera,
    model: CameraModel,
    search: RoiSearch<AprilTagDetector>,
    noise: ProjectionNoise,
    tag_ids: Vec<u32>,
    tag_size_m: f64,
}

impl FieldCamera {
    fn open(cfg: &Config) -> Result<Self, String> {
        let d = &cfg.daemon;
        let calib = d
            .calibration
            .as_deref()
            .ok_or("daemon.calibration is needed with a real camera")?;
        let intrinsics =
            crate::vision::cv_io::load_calibration(calib).map_err(|e| e.to_string())?;
        let [r, p, y] = d.camera_mount_rpy_rad;
        let camera = Camera::open(CaptureConfig {
            source: d.camera.clone(),
            width_px: intrinsics.width_px,
            height_px: intrinsics.height_px,
            fps: d.camera_fps,
            timeout_s: d.camera_timeout_s,
        })
        .map_err(|e| e.to_string())?;
        Ok(Self {
            camera,
            model: CameraModel {
                intrinsics,
                mount: CameraMount::from_angles(r, p, y, d.camera_offset_body_frd_m),
            },
            search: RoiSearch::new(
                AprilTagDetector::new(cfg.vision.detector.clone()).map_err(|e| e.to_string())?,
            )
            .with_max_full_frame_decimation(cfg.vision.detector.max_full_frame_decimation),
            noise: cfg.vision.projection.clone(),
            tag_ids: vec![cfg.vision.tag_id],
            tag_size_m: cfg.vision.tag_size_m,
        })
    }

    /// The newest frame, if one came: its pose (at capture time) and the measurement.
    fn look(
        &mut self,
        shared: &Shared,
        prior: (Enu2, nalgebra::Matrix2<f64>),
        stats: &mut VisionStats,
    ) -> Option<(VehiclePoseNed, Option<Enu2>)> {
        let frame = self.camera.latest()?;
        stats.frames += 1;
        let pose = shared.poses.lock().expect("shared poisoned").at(
            // Capture stamps come from the capture thread on the wall clock, which is the
            // runtime's clock whenever a real camera flies.
            tokio::time::Instant::from_std(frame.captured_at),
            Duration::from_millis(100),
        );
        let Some(pose) = pose else {
            tracing::warn!(
                "frame {}: no vehicle pose at its capture time; skipped",
                frame.index
            );
            return None;
        };
        let i = &self.model.intrinsics;
        if (frame.image.width, frame.image.height) != (i.width_px as usize, i.height_px as usize) {
            tracing::error!(
                "frame {} is {}x{} px but the calibration is for {}x{} px; skipped",
                frame.index,
                frame.image.width,
                frame.image.height,
                i.width_px,
                i.height_px
            );
            return None;
        }
        let alt = pose.altitude_m().max(0.1);
        let side_px = self.tag_size_m * i.fx_px / alt;
        let roi = self
            .model
            .world_enu_to_pixel([prior.0.x, prior.0.y], 0.0, &pose)
            .filter(|px| self.model.in_image(*px))
            .map(|px| {
                let sigma_m = prior.1.symmetric_eigenvalues().max().max(0.0).sqrt();
                RoiPx::around(px, side_px, sigma_m * i.fx_px / alt)
            });
        let z = match self
            .search
            .detect(&frame.image, roi, &self.tag_ids, Some(side_px))
        {
            Ok((dets, how)) => dets.first().and_then(|d| {
                stats.detections += 1;
                if how == crate::vision::detector::SearchOutcome::Roi {
                    stats.roi_hits += 1;
                }
                measure_tag(&self.model, &pose, d, &self.noise)
                    .map(|m| Enu2::new(m.position_enu_m[0], m.position_enu_m[1]))
            }),
            Err(e) => {
                tracing::warn!("frame {}: {e}", frame.index);
                None
            }
        };
        Some((pose, z))
    }
}

/// The pipeline's state between ticks.
struct Pipeline {
    cfg: Config,
    shared: Arc<Shared>,
    world: World,
    rng_target: crate::rng::CoreRng,
    rng_meas: crate::rng::CoreRng,
    rng_filter: crate::rng::CoreRng,
    rng_guid: crate::rng::CoreRng,
    model: Box<dyn motion::MotionModel>,
    sensor: VisionSensor,
    field: Option<FieldCamera>,
    pf: ParticleFilter,
    planner: EerPlanner,
    lawn: LawnmowerPath,
    target: TargetSim,
    out: PipelineOutput,
    next_filter: u64,
    next_guid: u64,
    last_seen_s: f64,
    last_frame_s: f64,
    last_pose: Option<VehiclePoseNed>,
    last_frame_ms: f64,
    entropy: f64,
    last_eer: f64,
    command: Option<Command>,
    state: TrackState,
    tick: u64,
}

impl Pipeline {
    fn build(
        cfg: Config,
        motion_name: &str,
        seed: u64,
        shared: Arc<Shared>,
    ) -> Result<Self, String> {
        let world = World::from_config(&cfg);
        let mut rng_target = stream_rng(seed, 0, Stream::Target, 0);
        let rng_meas = stream_rng(seed, 0, Stream::Measurement, 0);
        let mut rng_filter = stream_rng(seed, 0, Stream::Filter, 0);
        let rng_guid = stream_rng(seed, 0, Stream::Guidance, 0);
        let model = motion::build(motion_name, &cfg).map_err(|e| e.to_string())?;
        let sensor = VisionSensor::from_config(&cfg).map_err(|e| e.to_string())?;
        // A real camera replaces the simulated world's synthetic one.
        let field = if cfg.daemon.camera == "synthetic" {
            None
        } else {
            Some(FieldCamera::open(&cfg)?)
        };
        let pf = ParticleFilter::new(
            FilterParams::from_config(&cfg),
            world.workspace_enu,
            &mut rng_filter,
        );
        let planner = EerPlanner::new(EerParams::from_config(&cfg));
        let lawn = LawnmowerPath::new(&cfg.guidance.lawn);
        let target = TargetSim::new(&world.road, cfg.target.clone(), &mut rng_target);
        Ok(Self {
            cfg,
            shared,
            world,
            rng_target,
            rng_meas,
            rng_filter,
            rng_guid,
            model,
            sensor,
            field,
            pf,
            planner,
            lawn,
            target,
            out: PipelineOutput::default(),
            next_filter: 1,
            next_guid: 1,
            last_seen_s: 0.0,
            last_frame_s: 0.0,
            last_pose: None,
            last_frame_ms: 0.0,
            entropy: f64::NAN,
            last_eer: f64::NAN,
            command: None,
            state: TrackState::Tracking,
            tick: 0,
        })
    }

    fn finish(mut self) -> PipelineOutput {
        self.out.vision = self.sensor.stats;
        self.out
    }

    /// One physics tick: the target moves; a frame and a filter step, a guidance decision when due.
    fn tick(&mut self) {
        let Self {
            cfg,
            shared,
            world,
            rng_target,
            rng_meas,
            rng_filter,
            rng_guid,
            model,
            sensor,
            field,
            pf,
            planner,
            lawn,
            target,
            out,
            ..
        } = self;
        let d = &cfg.daemon;
        let dt = 1.0 / cfg.timing.physics_hz;
        self.tick += 1;
        let t = self.tick as f64 * dt;
        if field.is_none() {
            target.step(&world.road, dt, rng_target);
        }
        let snapshot = *shared.vehicle.lock().expect("shared poisoned");
        if let Some(s) = snapshot {
            if !s.link_lost {
                self.last_pose = Some(s.pose);
            }
        }
        let link_lost = snapshot.map_or(true, |s| s.link_lost);
        let Some(pose) = self.last_pose else { return };
        let agent = Enu2::new(pose.position_ned_m[1], pose.position_ned_m[0]);

        if t + 1e-9 >= self.next_filter as f64 / cfg.timing.filter_hz {
            self.next_filter += 1;
            // No ground truth in the field.
            let truth = if field.is_some() {
                Enu2::new(f64::NAN, f64::NAN)
            } else {
                target.position_enu
            };
            let started = Instant::now();
            let frame_seed = rand::Rng::gen(rng_meas);
            let mut frozen = shared.camera_frozen.load(Ordering::Relaxed);
            let mut pose = pose;
            let mut agent = agent;
            let field_z = match field.as_mut() {
                Some(f) if !frozen => {
                    match f.look(shared, (pf.mean(), pf.covariance()), &mut sensor.stats) {
                        Some((p, z)) => {
                            pose = p;
                            agent = Enu2::new(p.position_ned_m[1], p.position_ned_m[0]);
                            Some(z)
                        }
                        None => {
                            frozen = true;
                            None
                        }
                    }
                }
                _ => None,
            };
            let z = if frozen {
                out.frames_missed += 1;
                None
            } else if let Some(z) = field_z {
                self.last_frame_s = t;
                z
            } else {
                self.last_frame_s = t;
                match sensor.measure(
                    &agent,
                    &truth,
                    target.heading_enu_rad,
                    Some((pf.mean(), pf.covariance())),
                    frame_seed,
                ) {
                    Ok(z) => z,
                    Err(e) => {
                        tracing::warn!("camera frame dropped: {e}");
                        None
                    }
                }
            };
            let measured = Instant::now();
            // Without a frame nothing was looked at: predict only, no negative information.
            let stepped = if frozen {
                pf.step_blind(model.as_mut(), rng_filter)
            } else {
                pf.step(model.as_mut(), z, &agent, world, rng_filter)
            };
            let n_eff = match stepped {
                Ok(r) => r.n_eff,
                Err(e) => {
                    tracing::error!("filter step failed: {e}");
                    f64::NAN
                }
            };
            // From the frame's capture (the end of its rendering) to the updated filter.
            let render_ms = if field.is_some() {
                0.0
            } else {
                sensor.last_render_ms
            };
            self.last_frame_ms = started.elapsed().as_secs_f64() * 1e3 - render_ms;
            out.filter_ms.push(self.last_frame_ms);
            out.detect_ms
                .push((measured - started).as_secs_f64() * 1e3 - render_ms);
            out.update_ms.push(measured.elapsed().as_secs_f64() * 1e3);
            if z.is_some() {
                self.last_seen_s = t;
            }
            self.state = if link_lost {
                TrackState::LinkLost
            } else if t - self.last_frame_s > d.camera_timeout_s {
                if self.state != TrackState::CameraLost {
                    tracing::error!(
                        "camera: no frame for {} s; holding position",
                        d.camera_timeout_s
                    );
                }
                TrackState::CameraLost
            } else if t - self.last_seen_s > d.target_lost_after_s {
                TrackState::Lost
            } else {
                TrackState::Tracking
            };
            out.records.push(FlightRecord {
                step: StepRecord {
                    t_s: t,
                    target_enu: truth,
                    agent_enu: agent,
                    waypoint_enu: match self.command {
                        Some(Command::GoTo(w)) => w,
                        _ => agent,
                    },
                    measurement_enu: z,
                    estimate_enu: pf.mean(),
                    cov_m2: pf.covariance(),
                    n_eff,
                    eer: self.last_eer,
                    target_occluded: world.is_occluded(&truth),
                    target_in_footprint: world.footprint.contains(&agent, &truth),
                },
                pose,
                state: self.state,
                frame: !frozen,
                command: self.command,
                entropy: self.entropy,
                vehicle_mode: snapshot.and_then(|s| s.mode),
                faults: shared.faults.lock().expect("shared poisoned").clone(),
            });
            *shared.status.lock().expect("shared poisoned") = Some(Status {
                t_s: t,
                seen: z.is_some(),
                n_eff,
                entropy: self.entropy,
                state: self.state,
            });
        }

        if t + 1e-9 >= self.next_guid as f64 / cfg.timing.guidance_hz {
            self.next_guid += 1;
            if self.state == TrackState::LinkLost {
                // No commands decided on stale vehicle self.state.
                return;
            }
            let started = Instant::now();
            let fallback = self.state == TrackState::Lost;
            let decided = match (fallback, d.target_lost_fallback.as_str()) {
                _ if self.state == TrackState::CameraLost => Some(Command::HoldHere),
                (true, "hold") => Some(Command::HoldHere),
                (true, "lawn") => Some(Command::GoTo(lawn.next_point())),
                _ => match planner.plan(pf, model.as_mut(), &agent, world, rng_guid) {
                    Ok(dec) => {
                        self.entropy = dec.h_now;
                        self.last_eer = dec.eer;
                        Some(Command::GoTo(dec.waypoint_enu))
                    }
                    Err(e) => {
                        tracing::error!("guidance failed: {e}");
                        None
                    }
                },
            };
            let ms = started.elapsed().as_secs_f64() * 1e3;
            out.guidance_ms.push(ms);
            if ms > d.guidance_budget_ms {
                out.guidance_overruns += 1;
                tracing::warn!(
                    "guidance took {ms:.0} ms (budget {} ms): decision skipped",
                    d.guidance_budget_ms
                );
                return;
            }
            if let Some(c) = decided {
                let c = match c {
                    Command::GoTo(w) => Command::GoTo(world.workspace_enu.clamp(&w)),
                    h => h,
                };
                self.command = Some(c);
                out.latency_ms.push(self.last_frame_ms + ms);
                *shared.command.lock().expect("shared poisoned") = Some(c);
            }
        }
    }
}

/// Builds everything and reports on `ready`; then runs one physics tick for every message on
/// `ticks` and answers each on `done`, until `ticks` closes. The clock is the caller's: the
/// supervisor sends ticks on the runtime's clock, wall-clock in the field and simulated in
/// `infotrack sim --closed-loop`.
pub fn run(
    cfg: Config,
    motion_name: String,
    seed: u64,
    shared: Arc<Shared>,
    ready: mpsc::Sender<Ready>,
    ticks: mpsc::Receiver<()>,
    done: mpsc::Sender<()>,
) -> PipelineOutput {
    let mut p = match Pipeline::build(cfg, &motion_name, seed, shared) {
        Ok(p) => p,
        Err(e) => {
            let _ = ready.send(Ready::Err(e));
            return PipelineOutput::default();
        }
    };
    let _ = ready.send(Ready::Ok);
    while ticks.recv().is_ok() {
        p.tick();
        if done.send(()).is_err() {
            break;
        }
    }
    p.finish()
}
