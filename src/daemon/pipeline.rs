//! The daemon's pipeline thread: the simulated world (target on its roads), the camera
//! (rendered from the vehicle's reported pose), the detector, the particle filter with the
//! DMMN, and EER guidance, one physics tick per message from the supervisor (which ticks on
//! the runtime's clock: wall-clock or simulated). It runs on its own OS thread so that the
//! DMMN, the filter and EER never block the async reactor; it talks to the async side only
//! through [`Shared`] and the tick channels.

use std::sync::atomic::AtomicBool;
use std::sync::{mpsc, Arc};

use parking_lot::Mutex;
use std::time::Duration;

use super::field_camera::FieldCamera;
pub use super::flight_log::FlightRecord;
use super::heading;
use super::sensor::{DaemonSensor, Frames};
use crate::config::Config;
use crate::guidance::GuidanceKind;
use crate::rng::{stream_rng, Stream};
pub use crate::tracker::{Command, TrackState};
use crate::tracker::{Decision, EstimatorKind, MonotonicClock, StepOutcome, TickInput, Tracker};
use crate::vision::camera_model::VehiclePoseNed;
use crate::vision::VisionStats;
use crate::world::camera::NORTH_VIEW_YAW_ENU_RAD;
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
    /// EER weighs 1 / 2^this of its hypotheses: lowered when decisions take most of their
    /// compute budget (a slow computer), 0 at full effort.
    pub effort_level: u8,
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
        self.to_pipeline.lock().clone()
    }

    /// What the pipeline said last.
    pub fn pipeline_view(&self) -> PipelineView {
        *self.from_pipeline.lock()
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
    /// The lowest effort EER planned with: it weighed 1 / 2^this of its hypotheses (0:
    /// always all of them).
    pub lowest_effort_level: u8,
}

/// Messages from the pipeline thread before it runs.
pub enum Ready {
    /// Built: model loaded, detector up.
    Ok,
    /// Could not start.
    Err(PipelineError),
}

/// The pipeline's state between ticks: the camera (with the simulated world of the
/// synthetic one), and the tracker.
struct Pipeline {
    shared: Arc<Shared>,
    world: World,
    physics_dt_s: f64,
    guidance_budget_ms: f64,
    camera_timeout_s: f64,
    sensor: DaemonSensor,
    tracker: Tracker,
    clock: MonotonicClock,
    out: PipelineOutput,
    last_pose: Option<VehiclePoseNed>,
    /// Detection plus filter time of the latest frame, ms.
    last_frame_ms: f64,
    /// Writes each record as it is made.
    recorder: Option<super::recorder::FlightRecorder>,
    /// The visual record, written as the flight goes.
    visual: Option<super::visual::VisualRecord>,
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
    /// The synthetic camera's world could not be built (its renderer, detector or target).
    #[error("{0}")]
    Synthetic(super::simulators::SimulatorError),
    /// The synthetic camera was asked for and the program provides none.
    #[error(
        "daemon.camera = \"synthetic\" needs the simulator, which this program does not provide"
    )]
    NoSynthetic,
}

impl Pipeline {
    fn build(start: Start, shared: Arc<Shared>) -> Result<Self, PipelineError> {
        let Start {
            cfg,
            motion_name,
            seed,
            synthetic,
            ..
        } = start;
        let world = cfg.world();
        let frames = if cfg.daemon.camera == "synthetic" {
            let build = synthetic.ok_or(PipelineError::NoSynthetic)?;
            Frames::Synthetic(build(&cfg, &world, seed).map_err(PipelineError::Synthetic)?)
        } else {
            Frames::Field(Box::new(FieldCamera::open(&cfg)?), VisionStats::default())
        };
        let mut params = cfg.tracker_params(GuidanceKind::Eer, true);
        if let Frames::Synthetic(scene) = &frames {
            params.cue = params.cue.or(scene.track_cue());
        }
        let model = EstimatorKind::parse(&motion_name)?
            .build(&params.motion, &infotrack_dmmn::load_learned)
            .map_err(crate::tracker::TrackerError::from)?;
        let tracker = Tracker::new(
            params,
            // Synthetic or real, the daemon's camera measures through the detector.
            cfg.world_seen_by_detector(),
            model,
            stream_rng(seed, 0, Stream::Filter, 0),
            stream_rng(seed, 0, Stream::Guidance, 0),
        )?;
        Ok(Self {
            sensor: DaemonSensor {
                shared: shared.clone(),
                frames,
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
            tracker,
            clock: MonotonicClock::new(),
            out: PipelineOutput::default(),
            last_pose: None,
            last_frame_ms: 0.0,
            recorder: None,
            visual: None,
        })
    }

    fn finish(mut self) -> PipelineOutput {
        if let Some(rec) = self.recorder.as_mut() {
            rec.sync();
            self.out.records_failure = rec.failure().map(str::to_string);
        }
        if let Some(v) = self.visual.as_mut() {
            v.finish();
            if let Some(why) = v.failure() {
                self.out.records_failure.get_or_insert(why.to_string());
            }
        }
        self.out.vision = self.sensor.stats();
        self.out.frames_missed = self.sensor.frames_missed;
        self.out
    }

    /// One physics tick: the simulated target moves; the tracker measures, estimates and
    /// decides when due; its outcome goes to the log, the status line and the supervisor.
    fn tick(&mut self) {
        // The simulated target moves (with the synthetic camera): the truth of the records.
        let truth = self.sensor.synthetic().map(|w| {
            w.step_target(&self.world, self.physics_dt_s);
            (w.target_ended(), w.target_enu())
        });
        if truth.is_some_and(|(ended, _)| ended) {
            self.shared
                .target_ended
                .store(true, std::sync::atomic::Ordering::Relaxed);
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
        let input = TickInput {
            vehicle_enu: self.last_pose.map(|p| p.position_enu()),
            view_yaw_enu_rad: self.last_pose.map_or(NORTH_VIEW_YAW_ENU_RAD, |p| {
                heading::view_yaw_enu_of_nose(p.yaw_rad, self.sensor.mount_yaw_rad)
            }),
            link_lost: snapshot.map_or(true, |s| s.link_lost),
            // No ground truth in the field.
            truth_enu: truth.map(|(_, (p, _))| p),
            truth_velocity_enu: truth.map_or(Enu2::zeros(), |(_, (_, v))| v),
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
        self.shared.from_pipeline.lock().status = Some(Status {
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
            effort_level: self.tracker.effort_level(),
        });
        self.out.lowest_effort_level = self
            .out
            .lowest_effort_level
            .max(self.tracker.effort_level());
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
        if let (Some(v), Some(last)) = (self.visual.as_mut(), self.out.records.last()) {
            v.note(last, &self.tracker, &self.sensor);
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
                self.shared.from_pipeline.lock().command = Some(command);
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
    /// The visual record, if asked for.
    pub visual: Option<super::visual::VisualRecord>,
    /// Builds the synthetic camera's world (the program's simulator), if it has one.
    pub synthetic: Option<super::simulators::BuildSyntheticWorld>,
}

/// Builds everything and reports on `ready`; then runs one physics tick for every message on
/// `ticks` and answers each on `done`, until `ticks` closes. The clock is the caller's: the
/// supervisor sends ticks on the runtime's clock, wall-clock in the field and simulated in
/// `infotrack sim --closed-loop`.
pub fn run(
    mut start: Start,
    shared: Arc<Shared>,
    ready: mpsc::Sender<Ready>,
    ticks: mpsc::Receiver<()>,
    done: mpsc::Sender<()>,
) -> PipelineOutput {
    let recorder = start.recorder.take();
    let visual = start.visual.take();
    let mut p = match Pipeline::build(start, shared) {
        Ok(p) => p,
        Err(e) => {
            let _ = ready.send(Ready::Err(e));
            return PipelineOutput::default();
        }
    };
    p.recorder = recorder;
    p.visual = visual;
    let _ = ready.send(Ready::Ok);
    while ticks.recv().is_ok() {
        p.tick();
        if done.send(()).is_err() {
            break;
        }
    }
    p.finish()
}
