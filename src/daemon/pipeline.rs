//! The daemon's pipeline thread: the simulated world (target on its roads), the camera
//! (rendered from the vehicle's reported pose), the detector, the particle filter with the
//! DMMN, and EER guidance, one physics tick per message from the supervisor (which ticks on
//! the runtime's clock: wall-clock or simulated). It runs on its own OS thread so that the
//! DMMN, the filter and EER never block the async reactor; it talks to the async side only
//! through [`Shared`] and the tick channels.

use std::sync::atomic::AtomicBool;
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

pub use super::flight_log::FlightRecord;
use super::heading;
use crate::config::Config;
use crate::guidance::GuidanceKind;
use crate::rng::{stream_rng, Stream};
use crate::simulated::{RenderedSensor, TargetSim, VisionSensor, VisionStats};
pub use crate::tracker::{Command, TrackState};
use crate::tracker::{
    Decision, EstimatorKind, MonotonicClock, Observation, Prior, Sensor, StepOutcome, TickInput,
    Tracker,
};
use crate::vision::camera_model::{CameraModel, CameraMount, VehiclePoseNed};
use crate::vision::capture::{Camera, CaptureConfig};
use crate::vision::detector::{AprilTagDetector, RoiPx, RoiSearch};
use crate::vision::projection::{measure_tag, ProjectionNoise};
use crate::world::camera::{View, NORTH_VIEW_YAW_ENU_RAD};
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
    /// The estimate's uncertainty: one standard deviation along its widest axis, m.
    pub radius_m: f64,
    /// Whether the flight records stopped being written (a full disk; the reason is in the
    /// log).
    pub records_failed: bool,
    /// The target estimate, world ENU, m.
    pub estimate_enu: [f64; 2],
}

/// What the supervisor tells the pipeline, rewritten every 20 ms.
#[derive(Debug, Clone, Default)]
pub struct SupervisorView {
    /// The vehicle's latest state.
    pub vehicle: Option<VehicleSnapshot>,
    /// Injected faults in force, `+`-joined (logged per step).
    pub faults: String,
    /// The camera delivers nothing while set (fault injection: a frozen camera).
    pub camera_frozen: bool,
    /// The pipeline panics at its next tick (fault injection: a tracker bug).
    pub panic: bool,
}

/// What the pipeline tells the supervisor, rewritten at each filter step and decision.
#[derive(Debug, Clone, Copy, Default)]
pub struct PipelineView {
    /// The command in force.
    pub command: Option<Command>,
    /// What the status line shows.
    pub status: Option<Status>,
}

/// The meeting point of the pipeline thread and the async side: one small state struct in
/// each direction (the latest value wins), the pose history for frames from a real camera,
/// and the stop flag.
pub struct Shared {
    /// Supervisor -> pipeline.
    pub to_pipeline: Mutex<SupervisorView>,
    /// Pipeline -> supervisor.
    pub from_pipeline: Mutex<PipelineView>,
    /// Recent vehicle poses by arrival time (written by the async side).
    pub poses: Mutex<super::pose_history::PoseHistory>,
    /// Ask the pipeline to finish.
    pub stop: AtomicBool,
    /// The simulated target's recorded track has ended: so does the flight.
    pub target_ended: AtomicBool,
}

impl Shared {
    /// Empty shared state.
    pub fn new() -> Arc<Self> {
        Arc::new(Self {
            to_pipeline: Mutex::new(SupervisorView::default()),
            from_pipeline: Mutex::new(PipelineView::default()),
            poses: Mutex::new(super::pose_history::PoseHistory::new(Duration::from_secs(
                2,
            ))),
            stop: AtomicBool::new(false),
            target_ended: AtomicBool::new(false),
        })
    }

    /// What the supervisor said last.
    pub fn supervisor_view(&self) -> SupervisorView {
        self.to_pipeline.lock().expect("shared poisoned").clone()
    }

    /// What the pipeline said last.
    pub fn pipeline_view(&self) -> PipelineView {
        *self.from_pipeline.lock().expect("shared poisoned")
    }
}

/// What the pipeline produced.
#[derive(Debug, Default)]
pub struct PipelineOutput {
    /// One per filter step.
    pub records: Vec<FlightRecord>,
    /// Why the records on disk stopped early (a full disk), if they did.
    pub records_failure: Option<String>,
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
    Err(PipelineError),
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
    fn open(cfg: &Config) -> Result<Self, PipelineError> {
        let d = &cfg.daemon;
        let calib = d
            .calibration
            .as_deref()
            .ok_or(PipelineError::NoCalibration)?;
        let intrinsics = crate::vision::cv_io::load_calibration(calib)?;
        let [r, p, y] = d.camera_mount_rpy_rad;
        let camera = Camera::open(CaptureConfig {
            source: d.camera.clone(),
            width_px: intrinsics.width_px,
            height_px: intrinsics.height_px,
            fps: d.camera_fps,
            timeout_s: d.camera_timeout_s,
        })?;
        Ok(Self {
            camera,
            model: CameraModel {
                intrinsics,
                mount: CameraMount::from_angles(r, p, y, d.camera_offset_body_frd_m),
            },
            search: RoiSearch::new(AprilTagDetector::new(cfg.vision.detector.clone())?)
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
        prior: &Prior,
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
            .world_enu_to_pixel([prior.mean_enu.x, prior.mean_enu.y], 0.0, &pose)
            .filter(|px| self.model.in_image(*px))
            .map(|px| {
                let sigma_m = prior.cov_m2.symmetric_eigenvalues().max().max(0.0).sqrt();
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

/// The daemon's camera as the tracker sees it: the synthetic camera over the simulated
/// world, or a real one; either may be frozen by fault injection.
struct DaemonSensor {
    shared: Arc<Shared>,
    /// The synthetic camera (its frame seeds are drawn at every filter step, with or
    /// without a real camera, so that a flight's random streams do not depend on it).
    synthetic: RenderedSensor,
    field: Option<FieldCamera>,
    /// The camera's yaw on its mount (`daemon.camera_mount_rpy_rad`), rad: the view faces
    /// the nose's heading turned by it.
    mount_yaw_rad: f64,
    /// The vehicle's pose from telemetry at this tick.
    telemetry_pose: Option<VehiclePoseNed>,
    /// The camera is frozen (fault injection) at this tick.
    camera_frozen: bool,
    /// The pose of the last observation (the frame's, with a real camera).
    observed_pose: Option<VehiclePoseNed>,
    /// Detection and projection time of the last frame, ms (rendering excluded).
    detect_ms: f64,
    frames_missed: u64,
}

impl Sensor for DaemonSensor {
    type Error = std::convert::Infallible;

    fn observe(
        &mut self,
        _t_s: f64,
        view: &View,
        prior: &Prior,
    ) -> Result<Observation, Self::Error> {
        let started = Instant::now();
        let frame_seed = self.synthetic.next_frame_seed();
        self.observed_pose = self.telemetry_pose;
        let mut frozen = self.camera_frozen;
        let field_look = match self.field.as_mut() {
            Some(f) if !frozen => {
                let look = f.look(&self.shared, prior, &mut self.synthetic.camera.stats);
                if look.is_none() {
                    frozen = true;
                }
                look
            }
            _ => None,
        };
        let observation = if frozen {
            self.frames_missed += 1;
            Observation::NoFrame
        } else if let Some((pose, z)) = field_look {
            self.observed_pose = Some(pose);
            Observation::Frame {
                taken_from: View::new(
                    pose.position_enu(),
                    heading::view_yaw_enu_of_nose(pose.yaw_rad, self.mount_yaw_rad),
                ),
                z,
            }
        } else {
            let z = match self.synthetic.measure_with_seed(view, prior, frame_seed) {
                Ok(z) => z,
                Err(e) => {
                    tracing::warn!("camera frame dropped: {e}");
                    None
                }
            };
            Observation::Frame {
                taken_from: *view,
                z,
            }
        };
        // From the frame's capture (the end of its rendering) to its measurement.
        let render_ms = if self.field.is_some() {
            0.0
        } else {
            self.synthetic.camera.last_render_ms
        };
        self.detect_ms = started.elapsed().as_secs_f64() * 1e3 - render_ms;
        Ok(observation)
    }
}

/// The pipeline's state between ticks: the simulated target (on the synthetic camera), the
/// camera, and the tracker.
struct Pipeline {
    shared: Arc<Shared>,
    world: World,
    physics_dt_s: f64,
    guidance_budget_ms: f64,
    camera_timeout_s: f64,
    rng_target: crate::rng::CoreRng,
    target: TargetSim,
    sensor: DaemonSensor,
    tracker: Tracker,
    clock: MonotonicClock,
    out: PipelineOutput,
    last_pose: Option<VehiclePoseNed>,
    /// Detection plus filter time of the latest frame, ms.
    last_frame_ms: f64,
    /// Writes each record as it is made.
    recorder: Option<super::recorder::FlightRecorder>,
}

/// Why the pipeline could not start.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The motion model name.
    #[error("daemon.motion: {0}")]
    Motion(#[from] crate::tracker::UnknownEstimator),
    /// The tracker (its motion model).
    #[error(transparent)]
    Tracker(#[from] crate::tracker::TrackerError),
    /// The synthetic camera or the detector.
    #[error(transparent)]
    Vision(#[from] crate::vision::VisionError),
    /// The real camera: no calibration file.
    #[error("daemon.calibration is needed with a real camera")]
    NoCalibration,
    /// `target.trajectory` could not be read.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
}

impl Pipeline {
    fn build(
        cfg: Config,
        motion_name: &str,
        seed: u64,
        shared: Arc<Shared>,
    ) -> Result<Self, PipelineError> {
        let world = cfg.world();
        let mut rng_target = stream_rng(seed, 0, Stream::Target, 0);
        let rng_meas = stream_rng(seed, 0, Stream::Measurement, 0);
        let params = cfg.tracker_params(GuidanceKind::Eer, true);
        let model = EstimatorKind::parse(motion_name)?
            .build(&params.motion)
            .map_err(crate::tracker::TrackerError::from)?;
        let tracker = Tracker::new(
            params,
            // Synthetic or real, the daemon's camera measures through the detector.
            cfg.world_seen_by_detector(),
            model,
            stream_rng(seed, 0, Stream::Filter, 0),
            stream_rng(seed, 0, Stream::Guidance, 0),
        )?;
        let synthetic = RenderedSensor::new(VisionSensor::from_config(&cfg)?, rng_meas);
        // A real camera replaces the simulated world's synthetic one.
        let field = if cfg.daemon.camera == "synthetic" {
            None
        } else {
            Some(FieldCamera::open(&cfg)?)
        };
        // The daemon flies one run: the first recorded track, if any.
        let target = TargetSim::for_run(&cfg, &world, 0, &mut rng_target)?;
        Ok(Self {
            sensor: DaemonSensor {
                shared: shared.clone(),
                synthetic,
                field,
                mount_yaw_rad: cfg.daemon.camera_mount_rpy_rad[2],
                telemetry_pose: None,
                camera_frozen: false,
                observed_pose: None,
                detect_ms: 0.0,
                frames_missed: 0,
            },
            shared,
            world,
            physics_dt_s: 1.0 / cfg.timing.physics_hz,
            guidance_budget_ms: cfg.daemon.guidance_budget_ms,
            camera_timeout_s: cfg.daemon.camera_timeout_s,
            rng_target,
            target,
            tracker,
            clock: MonotonicClock::new(),
            out: PipelineOutput::default(),
            last_pose: None,
            last_frame_ms: 0.0,
            recorder: None,
        })
    }

    fn finish(mut self) -> PipelineOutput {
        if let Some(rec) = self.recorder.as_mut() {
            rec.sync();
            self.out.records_failure = rec.failure().map(str::to_string);
        }
        self.out.vision = self.sensor.synthetic.camera.stats;
        self.out.frames_missed = self.sensor.frames_missed;
        self.out
    }

    /// One physics tick: the simulated target moves; the tracker measures, estimates and
    /// decides when due; its outcome goes to the log, the status line and the supervisor.
    fn tick(&mut self) {
        let synthetic = self.sensor.field.is_none();
        if synthetic {
            self.target
                .step(&self.world.road, self.physics_dt_s, &mut self.rng_target);
            if self.target.ended() {
                self.shared
                    .target_ended
                    .store(true, std::sync::atomic::Ordering::Relaxed);
            }
        }
        let view = self.shared.supervisor_view();
        // Only ever set by `--inject pipeline-panic`, to prove the supervisor's hold.
        assert!(!view.panic, "injected fault: pipeline-panic");
        let snapshot = view.vehicle;
        self.sensor.camera_frozen = view.camera_frozen;
        if let Some(s) = snapshot.filter(|s| !s.link_lost) {
            self.last_pose = Some(s.pose);
        }
        self.sensor.telemetry_pose = self.last_pose;
        self.sensor
            .synthetic
            .set_target(self.target.position_enu, self.target.heading_enu_rad);
        let input = TickInput {
            vehicle_enu: self.last_pose.map(|p| p.position_enu()),
            view_yaw_enu_rad: self.last_pose.map_or(NORTH_VIEW_YAW_ENU_RAD, |p| {
                heading::view_yaw_enu_of_nose(p.yaw_rad, self.sensor.mount_yaw_rad)
            }),
            link_lost: snapshot.map_or(true, |s| s.link_lost),
            // No ground truth in the field.
            truth_enu: synthetic.then_some(self.target.position_enu),
            truth_velocity_enu: self.target.velocity_enu,
        };
        let out = match self.tracker.tick(&input, &mut self.sensor, &self.clock) {
            Ok(out) => out,
            Err(e) => {
                tracing::error!("tracker: {e}");
                return;
            }
        };
        if let Some(step) = out.step {
            self.record(step, snapshot.and_then(|s| s.mode), view.faults);
        }
        if let Some(decision) = out.decision {
            self.apply(decision);
        }
    }

    fn record(
        &mut self,
        step: StepOutcome,
        mode: Option<crate::autopilot::modes::Mode>,
        faults: String,
    ) {
        if let Some(e) = &step.filter_error {
            tracing::error!("filter step failed: {e}");
        }
        if step.camera_lost_now {
            tracing::error!(
                "camera: no frame for {} s; holding position",
                self.camera_timeout_s
            );
        }
        self.last_frame_ms = self.sensor.detect_ms + step.update_ms;
        self.out.filter_ms.push(self.last_frame_ms);
        self.out.detect_ms.push(self.sensor.detect_ms);
        self.out.update_ms.push(step.update_ms);
        self.shared
            .from_pipeline
            .lock()
            .expect("shared poisoned")
            .status = Some(Status {
            t_s: step.record.t_s,
            seen: step.record.measurement_enu.is_some(),
            n_eff: step.record.n_eff,
            entropy: step.entropy,
            state: step.state,
            radius_m: step
                .record
                .cov_m2
                .symmetric_eigenvalues()
                .max()
                .max(0.0)
                .sqrt(),
            records_failed: self
                .recorder
                .as_ref()
                .is_some_and(|r| r.failure().is_some()),
            estimate_enu: [step.record.estimate_enu.x, step.record.estimate_enu.y],
        });
        self.out.records.push(FlightRecord {
            pose: self
                .sensor
                .observed_pose
                .expect("a filter step runs only once the vehicle has a pose"),
            state: step.state,
            frame: step.frame,
            command: step.command,
            entropy: step.entropy,
            vehicle_mode: mode,
            faults,
            step: step.record,
        });
        if let (Some(rec), Some(last)) = (self.recorder.as_mut(), self.out.records.last()) {
            rec.record(last, &self.out.records);
        }
    }

    fn apply(&mut self, decision: Decision) {
        let budget = self.guidance_budget_ms;
        match decision {
            Decision::Command {
                command,
                compute_ms,
            } => {
                self.out.guidance_ms.push(compute_ms);
                self.out.latency_ms.push(self.last_frame_ms + compute_ms);
                self.shared
                    .from_pipeline
                    .lock()
                    .expect("shared poisoned")
                    .command = Some(command);
            }
            Decision::Overrun { compute_ms } => {
                self.out.guidance_ms.push(compute_ms);
                self.out.guidance_overruns += 1;
                tracing::warn!(
                    "guidance took {compute_ms:.0} ms (budget {budget} ms): decision skipped"
                );
            }
            Decision::Failed {
                reason,
                compute_ms,
                over_budget,
            } => {
                tracing::error!("guidance failed: {reason}");
                self.out.guidance_ms.push(compute_ms);
                if over_budget {
                    self.out.guidance_overruns += 1;
                    tracing::warn!(
                        "guidance took {compute_ms:.0} ms (budget {budget} ms): decision skipped"
                    );
                }
            }
        }
    }
}

/// What the pipeline thread is started with.
pub struct Start {
    /// The configuration.
    pub cfg: Config,
    /// Motion model of the filter.
    pub motion_name: String,
    /// Seed of every random stream.
    pub seed: u64,
    /// Where the records go as the flight goes, if anywhere.
    pub recorder: Option<super::recorder::FlightRecorder>,
}

/// Builds everything and reports on `ready`; then runs one physics tick for every message on
/// `ticks` and answers each on `done`, until `ticks` closes. The clock is the caller's: the
/// supervisor sends ticks on the runtime's clock, wall-clock in the field and simulated in
/// `infotrack sim --closed-loop`.
pub fn run(
    start: Start,
    shared: Arc<Shared>,
    ready: mpsc::Sender<Ready>,
    ticks: mpsc::Receiver<()>,
    done: mpsc::Sender<()>,
) -> PipelineOutput {
    let Start {
        cfg,
        motion_name,
        seed,
        recorder,
    } = start;
    let mut p = match Pipeline::build(cfg, &motion_name, seed, shared) {
        Ok(p) => p,
        Err(e) => {
            let _ = ready.send(Ready::Err(e));
            return PipelineOutput::default();
        }
    };
    p.recorder = recorder;
    let _ = ready.send(Ready::Ok);
    while ticks.recv().is_ok() {
        p.tick();
        if done.send(()).is_err() {
            break;
        }
    }
    p.finish()
}
