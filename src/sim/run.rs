//! One closed-loop simulated run: target, agent, camera, estimator and guidance law, on a
//! fixed-step clock. Deterministic for its seed.

use std::time::Instant;

use nalgebra::Matrix2;
use thiserror::Error;

use super::agent::AgentSim;
use super::target::TargetSim;
use crate::config::Config;
use crate::estimation::{FilterError, FilterParams, KalmanFilter, ParticleFilter};
use crate::guidance::{EerParams, EerPlanner, GuidanceKind, LawnmowerPath};
use crate::metrics::{RunSummary, StepRecord};
use crate::motion::{self, MotionError, MotionModel};
use crate::rng::{stream_rng, Stream};
use crate::world::geometry::Enu2;
use crate::world::World;

/// Why a run failed.
#[derive(Debug, Error)]
pub enum RunError {
    /// The guidance law and the estimator do not fit together.
    #[error("guidance `{guidance}` cannot run with motion `{motion}`: {reason}")]
    Incompatible {
        /// The guidance law.
        guidance: GuidanceKind,
        /// The motion model / estimator.
        motion: String,
        /// Why.
        reason: String,
    },
    /// The motion model could not be built or failed.
    #[error(transparent)]
    Motion(#[from] MotionError),
    /// The filter failed.
    #[error(transparent)]
    Filter(#[from] FilterError),
    /// The vision pipeline failed (vision mode).
    #[error(transparent)]
    Vision(#[from] crate::vision::VisionError),
}

/// What estimates the target: a particle filter with a motion model, or the Kalman filter.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EstimatorKind {
    /// Particle filter predicting with the named motion model (`cv`, ...).
    Particle(String),
    /// The constant-velocity Kalman filter (`--motion kf`).
    Kalman,
}

impl EstimatorKind {
    /// From a `--motion` name.
    pub fn parse(name: &str) -> Result<Self, String> {
        let name = name.trim();
        if name == "kf" {
            Ok(Self::Kalman)
        } else if motion::MODEL_NAMES.contains(&name) {
            Ok(Self::Particle(name.to_string()))
        } else {
            Err(format!(
                "unknown motion model `{name}` (expected one of kf, {})",
                motion::MODEL_NAMES.join(", ")
            ))
        }
    }

    /// The `--motion` name.
    pub fn name(&self) -> &str {
        match self {
            Self::Particle(m) => m,
            Self::Kalman => "kf",
        }
    }
}

/// Checks that a guidance law can run with an estimator.
pub fn check_combination(g: GuidanceKind, e: &EstimatorKind) -> Result<(), RunError> {
    if g.needs_particles() && *e == EstimatorKind::Kalman {
        return Err(RunError::Incompatible {
            guidance: g,
            motion: e.name().to_string(),
            reason: format!("{g} needs a particle set and `--motion kf` has none"),
        });
    }
    Ok(())
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
    pub vision: Option<super::vision_sensor::VisionStats>,
}

enum Estimator {
    Particle {
        pf: Box<ParticleFilter>,
        model: Box<dyn MotionModel>,
    },
    Kalman(Box<KalmanFilter>),
}

impl Estimator {
    fn mean(&self) -> Enu2 {
        match self {
            Self::Particle { pf, .. } => pf.mean(),
            Self::Kalman(kf) => kf.mean(),
        }
    }
    fn covariance(&self) -> Matrix2<f64> {
        match self {
            Self::Particle { pf, .. } => pf.covariance(),
            Self::Kalman(kf) => kf.covariance(),
        }
    }
}

/// Runs one closed-loop simulation.
pub fn run_once(cfg: &Config, world: &World, spec: &RunSpec) -> Result<RunOutput, RunError> {
    check_combination(spec.guidance, &spec.estimator)?;
    let method = method_salt(spec.guidance, &spec.estimator);
    let mut rng_target = stream_rng(spec.seed, spec.run_index, Stream::Target, 0);
    let mut rng_meas = stream_rng(spec.seed, spec.run_index, Stream::Measurement, 0);
    let mut rng_filter = stream_rng(spec.seed, spec.run_index, Stream::Filter, method);
    let mut rng_guid = stream_rng(spec.seed, spec.run_index, Stream::Guidance, method);

    let mut target = TargetSim::new(&world.road, cfg.target.clone(), &mut rng_target);
    let mut agent = AgentSim::new(cfg.agent.clone());
    let mut estimator = match &spec.estimator {
        EstimatorKind::Particle(name) => Estimator::Particle {
            pf: Box::new(ParticleFilter::new(
                FilterParams::from_config(cfg),
                world.workspace_enu,
                &mut rng_filter,
            )),
            model: motion::build(name, cfg)?,
        },
        EstimatorKind::Kalman => Estimator::Kalman(Box::new(KalmanFilter::from_config(cfg))),
    };
    // KF guidance always has a Kalman filter beside the estimator for its goal.
    let mut side_kf = (spec.guidance == GuidanceKind::Kf
        && spec.estimator != EstimatorKind::Kalman)
        .then(|| KalmanFilter::from_config(cfg));
    let mut planner = EerPlanner::new(EerParams::from_config(cfg));
    let mut sensor = if spec.vision {
        Some(super::vision_sensor::VisionSensor::from_config(cfg)?)
    } else {
        None
    };
    let mut lawn = LawnmowerPath::new(&cfg.guidance.lawn);

    let dt_phys = 1.0 / cfg.timing.physics_hz;
    let n_phys = (spec.duration_s * cfg.timing.physics_hz).round() as u64;
    let mut next_filter = 1u64;
    let mut next_guid = 1u64;
    let mut waypoint = agent.position_enu;
    let mut last_meas: Option<(f64, Enu2)> = None;
    let mut last_eer = f64::NAN;
    let mut steps = Vec::new();
    let mut filter_ms = Vec::new();
    let mut guidance_ms = Vec::new();
    let mut snapshots = Vec::new();
    let mut snap_iter = spec.snapshot_times_s.iter().peekable();

    for tick in 1..=n_phys {
        let t = tick as f64 * dt_phys;
        target.step(&world.road, dt_phys, &mut rng_target);
        agent.step(&waypoint, dt_phys);

        if t + 1e-9 >= next_filter as f64 / cfg.timing.filter_hz {
            next_filter += 1;
            let truth = target.position_enu;
            let z = match sensor.as_mut() {
                Some(s) => {
                    // The frame's noise comes from the measurement stream, like the
                    // analytic model's.
                    let frame_seed = rand::Rng::gen(&mut rng_meas);
                    s.measure(
                        &agent.position_enu,
                        &truth,
                        target.heading_enu_rad,
                        Some((estimator.mean(), estimator.covariance())),
                        frame_seed,
                    )?
                }
                None => {
                    let visible = world.is_visible(&agent.position_enu, &truth);
                    visible.then(|| world.measurement.measure(&truth, &mut rng_meas))
                }
            };
            if let Some(z) = z {
                last_meas = Some((t, z));
            }
            let started = Instant::now();
            let mut n_eff = f64::NAN;
            match &mut estimator {
                Estimator::Particle { pf, model } => {
                    let r = pf.step(
                        model.as_mut(),
                        z,
                        &agent.position_enu,
                        world,
                        &mut rng_filter,
                    )?;
                    n_eff = r.n_eff;
                }
                Estimator::Kalman(kf) => kf.step(z),
            }
            filter_ms.push(started.elapsed().as_secs_f64() * 1e3);
            if let Some(kf) = side_kf.as_mut() {
                kf.step(z);
            }
            let est = estimator.mean();
            let cov = estimator.covariance();
            steps.push(StepRecord {
                t_s: t,
                target_enu: truth,
                agent_enu: agent.position_enu,
                waypoint_enu: waypoint,
                measurement_enu: z,
                estimate_enu: est,
                cov_m2: cov,
                n_eff,
                eer: last_eer,
                target_occluded: world.is_occluded(&truth),
                target_in_footprint: world.footprint.contains(&agent.position_enu, &truth),
            });
            if let (Some(&&ts), Estimator::Particle { pf, .. }) = (snap_iter.peek(), &estimator) {
                if t + 1e-9 >= ts {
                    snap_iter.next();
                    snapshots.push(Snapshot {
                        t_s: t,
                        particles_enu: pf.particles(),
                    });
                }
            }
        }

        if t + 1e-9 >= next_guid as f64 / cfg.timing.guidance_hz {
            next_guid += 1;
            let started = Instant::now();
            let goal = match spec.guidance {
                GuidanceKind::Eer => {
                    let Estimator::Particle { pf, model } = &mut estimator else {
                        unreachable!("checked by check_combination")
                    };
                    let d = planner.plan(
                        pf,
                        model.as_mut(),
                        &agent.position_enu,
                        world,
                        &mut rng_guid,
                    )?;
                    last_eer = d.eer;
                    d.waypoint_enu
                }
                GuidanceKind::Pfwm => estimator.mean(),
                GuidanceKind::Kf => side_kf
                    .as_ref()
                    .map(|k| k.mean())
                    .unwrap_or_else(|| estimator.mean()),
                GuidanceKind::Truth => target.position_enu,
                GuidanceKind::Lawn => match last_meas {
                    Some((tm, z)) if t - tm <= cfg.guidance.lawn.track_measurement_for_s => z,
                    _ => lawn.next_point(),
                },
            };
            guidance_ms.push(started.elapsed().as_secs_f64() * 1e3);
            waypoint = world.workspace_enu.clamp(&goal);
        }
    }
    let summary = RunSummary::from_steps(&steps, &filter_ms, &guidance_ms);
    Ok(RunOutput {
        steps,
        summary,
        snapshots,
        guidance_ms,
        filter_ms,
        vision: sensor.map(|s| s.stats),
    })
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
        }
    }

    #[test]
    fn same_seed_same_run_different_seed_different_run() {
        let c = Config::default_lab();
        let w = World::from_config(&c);
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
        let w = World::from_config(&c);
        let a = run_once(&c, &w, &spec(GuidanceKind::Pfwm, "cv", 8)).unwrap();
        let b = run_once(&c, &w, &spec(GuidanceKind::Lawn, "kf", 8)).unwrap();
        for (x, y) in a.steps.iter().zip(&b.steps) {
            assert_eq!(x.target_enu, y.target_enu);
        }
    }

    #[test]
    fn eer_with_a_kalman_estimator_is_refused_with_a_reason() {
        let c = Config::default_lab();
        let w = World::from_config(&c);
        let err = run_once(&c, &w, &spec(GuidanceKind::Eer, "kf", 1))
            .err()
            .unwrap();
        let msg = err.to_string();
        assert!(msg.contains("eer") && msg.contains("particle"), "{msg}");
    }

    #[test]
    fn every_waypoint_is_inside_the_geofence() {
        let c = Config::default_lab();
        let w = World::from_config(&c);
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
        let w = World::from_config(&c);
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
