//! One closed-loop simulated run: target, agent, camera, estimator and guidance law, on a
//! fixed-step clock. Deterministic for its seed.

use thiserror::Error;

use crate::simulated::{AgentSim, AnalyticSensor, RenderedSensor, TargetSim, VisionSensor};
use infotrack_config::Config;
use infotrack_core::guidance::GuidanceKind;
use infotrack_core::metrics::{RunSummary, StepRecord};
use infotrack_core::rng::{stream_rng, Stream};
use infotrack_core::tracker::{
    Command, Decision, MonotonicClock, Sensor, TickError, TickInput, Tracker, TrackerError,
};
use infotrack_core::world::geometry::Enu2;
use infotrack_core::world::World;

pub use infotrack_core::tracker::{check_combination, EstimatorKind};

/// Why a run failed.
#[derive(Debug, Error)]
pub enum RunError {
    /// The tracker could not be built or failed.
    #[error(transparent)]
    Tracker(#[from] TrackerError),
    /// The vision pipeline failed (vision mode).
    #[error(transparent)]
    Vision(#[from] infotrack_vision::VisionError),
    /// No guidance law or no motion model was given.
    #[error("nothing to run: give at least one guidance law and one motion model")]
    NothingToRun,
    /// `target.trajectory` could not be read.
    #[error(transparent)]
    Config(#[from] infotrack_config::ConfigError),
}

impl From<TickError<infotrack_vision::VisionError>> for RunError {
    fn from(e: TickError<infotrack_vision::VisionError>) -> Self {
        match e {
            TickError::Sensor(v) => Self::Vision(v),
            TickError::Tracker(t) => Self::Tracker(t),
        }
    }
}

impl From<TickError<std::convert::Infallible>> for RunError {
    fn from(e: TickError<std::convert::Infallible>) -> Self {
        match e {
            TickError::Sensor(never) => match never {},
            TickError::Tracker(t) => Self::Tracker(t),
        }
    }
}

/// Which run this is.
#[derive(Debug, Clone)]
pub struct RunSpec {
    /// Guidance law.
    pub guidance: GuidanceKind,
    /// Estimator.
    pub estimator: EstimatorKind,
    /// User seed.
    pub seed: u64,
    /// Index of the run in the Monte Carlo batch.
    pub run_index: u64,
    /// Length, seconds.
    pub duration_s: f64,
    /// Times (s) at which to keep a copy of the particles for plots.
    pub snapshot_times_s: Vec<f64>,
    /// Measure through rendered frames, the detector and the projection instead of the
    /// analytic model.
    pub vision: bool,
    /// Keep every filter step's particles and view heading (for a visual record).
    pub trace: bool,
}

/// The particles and the camera's heading at one filter step, for a visual record.
#[derive(Debug, Clone)]
pub struct TraceFrame {
    /// Time, s.
    pub t_s: f64,
    /// The way the camera's view faced, world ENU, rad.
    pub view_yaw_enu_rad: f64,
    /// Particle positions, world ENU.
    pub particles_enu: Vec<Enu2>,
    /// Their weights.
    pub weights: Vec<f64>,
}

/// The particle set at one instant.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// Time, s.
    pub t_s: f64,
    /// Newest particle positions, world ENU.
    pub particles_enu: Vec<Enu2>,
}

/// Everything a run produced.
#[derive(Debug, Clone)]
pub struct RunOutput {
    /// One record per filter step.
    pub steps: Vec<StepRecord>,
    /// Aggregates.
    pub summary: RunSummary,
    /// Particle snapshots (empty for the Kalman estimator).
    pub snapshots: Vec<Snapshot>,
    /// Guidance decisions' compute times, ms.
    pub guidance_ms: Vec<f64>,
    /// Filter steps' compute times, ms.
    pub filter_ms: Vec<f64>,
    /// Frame statistics in vision mode.
    pub vision: Option<crate::simulated::VisionStats>,
    /// Every filter step's particles and view heading, when the spec asked for them.
    pub trace: Vec<TraceFrame>,
}

/// The simulated target's sensor: the analytic model or rendered frames.
trait SimSensor: Sensor {
    fn set_target(&mut self, target: &TargetSim);
}

impl SimSensor for AnalyticSensor<'_> {
    fn set_target(&mut self, target: &TargetSim) {
        AnalyticSensor::set_target(self, target.position_enu);
    }
}

impl SimSensor for RenderedSensor {
    fn set_target(&mut self, target: &TargetSim) {
        RenderedSensor::set_target(self, target.position_enu, target.heading_enu_rad);
    }
}

/// Runs one closed-loop simulation.
pub fn run_once(cfg: &Config, world: &World, spec: &RunSpec) -> Result<RunOutput, RunError> {
    check_combination(spec.guidance, &spec.estimator)?;
    let method = method_salt(spec.guidance, &spec.estimator);
    let mut rng_target = stream_rng(spec.seed, spec.run_index, Stream::Target, 0);
    let rng_meas = stream_rng(spec.seed, spec.run_index, Stream::Measurement, 0);
    let target = TargetSim::for_run(cfg, world, spec.run_index, &mut rng_target)?;
    // The tracker's model of its camera is the sensor's: whole tags only through the
    // detector.
    let margin_m = if spec.vision {
        cfg.vision.detection_margin_m()
    } else {
        0.0
    };
    let seen = world.clone().with_detection_margin(margin_m);
    let mut params = cfg.tracker_params(spec.guidance, false);
    params.cue = params.cue.or(target.cue(cfg));
    let model = spec
        .estimator
        .build(&params.motion, &infotrack_dmmn::load_learned)
        .map_err(infotrack_core::tracker::TrackerError::from)?;
    let tracker = Tracker::new(
        params,
        seen,
        model,
        stream_rng(spec.seed, spec.run_index, Stream::Filter, method),
        stream_rng(spec.seed, spec.run_index, Stream::Guidance, method),
    )?;
    let sim = SimRun {
        target,
        rng_target,
        agent: AgentSim::new(cfg.agent.clone()),
        tracker,
    };
    if spec.vision {
        let mut sensor = RenderedSensor::new(VisionSensor::from_config(cfg)?, rng_meas);
        let mut out = sim.fly(cfg, world, spec, &mut sensor)?;
        out.vision = Some(sensor.camera.stats);
        Ok(out)
    } else {
        let mut sensor = AnalyticSensor::new(world, rng_meas);
        sim.fly(cfg, world, spec, &mut sensor)
    }
}

/// The simulator's sources and sinks around the tracker.
struct SimRun {
    target: TargetSim,
    rng_target: infotrack_core::rng::CoreRng,
    agent: AgentSim,
    tracker: Tracker,
}

impl SimRun {
    /// Ticks the physics for the run's duration: the target drives, the agent flies to the
    /// command in force, the tracker measures, estimates and decides.
    fn fly<S: SimSensor>(
        mut self,
        cfg: &Config,
        world: &World,
        spec: &RunSpec,
        sensor: &mut S,
    ) -> Result<RunOutput, RunError>
    where
        RunError: From<TickError<S::Error>>,
    {
        let clock = MonotonicClock::new();
        let dt_phys = 1.0 / cfg.timing.physics_hz;
        let n_phys = (spec.duration_s * cfg.timing.physics_hz).round() as u64;
        let mut setpoint =
            MovingSetpoint::fixed(self.agent.position_enu, self.agent.view_yaw_enu_rad);
        let mut rec = Recording::default();
        let mut snap_iter = spec.snapshot_times_s.iter().peekable();
        for tick in 1..=n_phys {
            let t_s = tick as f64 * dt_phys;
            if self.target.ended() {
                // A recorded track shorter than the run ends it.
                break;
            }
            self.target.step(&world.road, dt_phys, &mut self.rng_target);
            let (sp, ff) = setpoint.at(t_s, &world.workspace_enu);
            self.agent.step(&sp, &ff, dt_phys);
            self.agent.turn_toward(setpoint.view_yaw_enu_rad, dt_phys);
            sensor.set_target(&self.target);
            let input = TickInput {
                vehicle_enu: Some(self.agent.position_enu),
                view_yaw_enu_rad: self.agent.view_yaw_enu_rad,
                link_lost: false,
                truth_enu: Some(self.target.position_enu),
                truth_velocity_enu: self.target.velocity_enu,
            };
            let out = self.tracker.tick(&input, sensor, &clock)?;
            if let Some(step) = out.step {
                let pf = self.tracker.estimator().particle_filter();
                if spec.trace {
                    rec.note_trace(pf, out.t_s, self.agent.view_yaw_enu_rad);
                }
                rec.note_step(step, pf, out.t_s, &mut snap_iter);
            }
            if let Some(next) = rec.note_decision(out.decision, out.t_s) {
                setpoint = next;
            }
        }
        Ok(rec.into_output())
    }
}

/// What a run records as it flies: every filter step, the time each step and decision
/// took, and the particles at the snapshot times.
#[derive(Default)]
struct Recording {
    steps: Vec<StepRecord>,
    filter_ms: Vec<f64>,
    guidance_ms: Vec<f64>,
    snapshots: Vec<Snapshot>,
    trace: Vec<TraceFrame>,
}

impl Recording {
    /// The particles of `pf` (none for the Kalman filter) and the view's heading at `t_s`.
    fn note_trace(
        &mut self,
        pf: Option<&infotrack_core::estimation::ParticleFilter>,
        t_s: f64,
        view_yaw_enu_rad: f64,
    ) {
        self.trace.push(TraceFrame {
            t_s,
            view_yaw_enu_rad,
            particles_enu: pf.map(|p| p.particles()).unwrap_or_default(),
            weights: pf.map(|p| p.weights().to_vec()).unwrap_or_default(),
        });
    }

    /// A filter step at `t_s`; the particles of `pf` when a snapshot is due.
    fn note_step(
        &mut self,
        step: infotrack_core::tracker::StepOutcome,
        pf: Option<&infotrack_core::estimation::ParticleFilter>,
        t_s: f64,
        snapshot_times_s: &mut std::iter::Peekable<std::slice::Iter<'_, f64>>,
    ) {
        self.filter_ms.push(step.update_ms);
        self.steps.push(step.record);
        if let (Some(&&ts), Some(pf)) = (snapshot_times_s.peek(), pf) {
            if t_s + 1e-9 >= ts {
                snapshot_times_s.next();
                self.snapshots.push(Snapshot {
                    t_s,
                    particles_enu: pf.particles(),
                });
            }
        }
    }

    /// A decision at `t_s`: the setpoint it gives the agent, if it commands one.
    fn note_decision(&mut self, decision: Option<Decision>, t_s: f64) -> Option<MovingSetpoint> {
        let Some(Decision::Command {
            command,
            compute_ms,
        }) = decision
        else {
            return None;
        };
        self.guidance_ms.push(compute_ms);
        match command {
            Command::GoTo {
                position_enu,
                velocity_enu,
                view_yaw_enu_rad,
            } => Some(MovingSetpoint {
                position_enu,
                velocity_enu,
                view_yaw_enu_rad,
                since_s: t_s,
            }),
            _ => None,
        }
    }

    fn into_output(self) -> RunOutput {
        let summary = RunSummary::from_steps(&self.steps, &self.filter_ms, &self.guidance_ms);
        RunOutput {
            steps: self.steps,
            summary,
            snapshots: self.snapshots,
            guidance_ms: self.guidance_ms,
            filter_ms: self.filter_ms,
            vision: None,
            trace: self.trace,
        }
    }
}

/// The agent's setpoint: a point moving at a constant velocity from a decision's time on,
/// stopped at the workspace's edge (the geofence), as the daemon streams it.
#[derive(Debug, Clone, Copy)]
struct MovingSetpoint {
    position_enu: Enu2,
    velocity_enu: Enu2,
    /// The heading the view turns to, world ENU, rad.
    view_yaw_enu_rad: f64,
    since_s: f64,
}

impl MovingSetpoint {
    fn fixed(position_enu: Enu2, view_yaw_enu_rad: f64) -> Self {
        Self {
            position_enu,
            velocity_enu: Enu2::zeros(),
            view_yaw_enu_rad,
            since_s: 0.0,
        }
    }

    /// The setpoint and the feed-forward at `t_s`.
    fn at(&self, t_s: f64, fence: &infotrack_core::world::geometry::BoundsEnu) -> (Enu2, Enu2) {
        let p = self.position_enu + self.velocity_enu * (t_s - self.since_s);
        if fence.contains(&p) {
            (p, self.velocity_enu)
        } else {
            (fence.clamp(&p), Enu2::zeros())
        }
    }
}

/// Distinct random streams per method, so methods do not share filter noise by accident
/// while every method of one run sees the same target route and measurement noise.
fn method_salt(g: GuidanceKind, e: &EstimatorKind) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in g.as_str().bytes().chain([b'/']).chain(e.name().bytes()) {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// A reproducible draw, used by tests to check determinism end to end.
pub fn fingerprint(out: &RunOutput) -> u64 {
    let mut h: u64 = 0;
    for s in &out.steps {
        for v in [
            s.estimate_enu.x,
            s.estimate_enu.y,
            s.agent_enu.x,
            s.agent_enu.y,
        ] {
            h = h.rotate_left(7) ^ v.to_bits();
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(g: GuidanceKind, m: &str, seed: u64) -> RunSpec {
        RunSpec {
            guidance: g,
            estimator: EstimatorKind::parse(m).unwrap(),
            seed,
            run_index: 0,
            duration_s: 20.0,
            snapshot_times_s: vec![5.0, 10.0],
            vision: false,
            trace: false,
        }
    }

    #[test]
    fn same_seed_same_run_different_seed_different_run() {
        let c = Config::default_lab();
        let w = c.world();
        let a = run_once(&c, &w, &spec(GuidanceKind::Eer, "cv", 3)).unwrap();
        let b = run_once(&c, &w, &spec(GuidanceKind::Eer, "cv", 3)).unwrap();
        let d = run_once(&c, &w, &spec(GuidanceKind::Eer, "cv", 4)).unwrap();
        assert_eq!(fingerprint(&a), fingerprint(&b));
        assert_ne!(fingerprint(&a), fingerprint(&d));
        assert_eq!(a.steps.len(), 60);
        assert_eq!(a.snapshots.len(), 2);
    }

    #[test]
    fn methods_of_one_run_see_the_same_target() {
        let c = Config::default_lab();
        let w = c.world();
        let a = run_once(&c, &w, &spec(GuidanceKind::Pfwm, "cv", 8)).unwrap();
        let b = run_once(&c, &w, &spec(GuidanceKind::Lawn, "kf", 8)).unwrap();
        for (x, y) in a.steps.iter().zip(&b.steps) {
            assert_eq!(x.target_enu, y.target_enu);
        }
    }

    #[test]
    fn eer_with_a_kalman_estimator_is_refused_with_a_reason() {
        let c = Config::default_lab();
        let w = c.world();
        let err = run_once(&c, &w, &spec(GuidanceKind::Eer, "kf", 1))
            .err()
            .unwrap();
        let msg = err.to_string();
        assert!(msg.contains("eer") && msg.contains("particle"), "{msg}");
    }

    #[test]
    fn every_waypoint_is_inside_the_geofence() {
        let c = Config::default_lab();
        let w = c.world();
        for g in GuidanceKind::ALL {
            let out = run_once(&c, &w, &spec(g, "cv", 2)).unwrap();
            assert!(
                out.steps
                    .iter()
                    .all(|s| c.workspace_enu.contains(&s.waypoint_enu)),
                "{g}"
            );
        }
    }

    #[test]
    fn truth_guidance_keeps_the_target_in_view_most_of_the_time() {
        let c = Config::default_lab();
        let w = c.world();
        let out = run_once(&c, &w, &spec(GuidanceKind::Truth, "cv", 6)).unwrap();
        // Following the true target, only occlusions and the lag hide it.
        assert!(
            out.summary.fov_percent > 40.0,
            "{}",
            out.summary.fov_percent
        );
        assert!(
            out.summary.tracking_error_m < 0.5,
            "{}",
            out.summary.tracking_error_m
        );
    }
}
