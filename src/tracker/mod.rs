//! The one tracker loop: the multi-rate tick that the simulator (`infotrack sim`, analytic
//! and `--vision`), the closed loop (`sim --closed-loop`), the daemon (`infotrack run`) and
//! `infotrack replay` all run.
//!
//! At each physics tick the caller says what it knows ([`TickInput`]: the vehicle's
//! position, whether its link is alive, the truth where a simulator has it) and lends a
//! [`Sensor`]; the tracker decides what is due ([`Schedule`]), asks the sensor for an
//! observation at a filter step, steps the estimator, keeps the tracking state (seen, lost,
//! camera lost, link lost) and, at a guidance step, decides what the vehicle should do. It
//! returns what happened ([`TickOutput`]); where its commands go and where its inputs come
//! from is the caller's business. Pure and synchronous: no I/O, no clock of its own (one is
//! passed in to time the work), every random draw from the generators it was given.

pub mod clock;
pub mod estimator;
pub mod ports;
pub mod schedule;

pub use clock::{Clock, FrozenClock, MonotonicClock};
pub use estimator::{Estimator, EstimatorKind, UnknownEstimator};
pub use ports::{
    Command, Decision, Observation, Prior, Sensor, StepOutcome, TickInput, TickOutput, TrackState,
};
pub use schedule::{Due, Rates, Schedule};

use crate::estimation::{
    FilterError, FilterParams, KalmanFilter, KalmanParams, ParticleFilter, RouteStart,
};
use crate::frames::Enu2;
use crate::guidance::{EerParams, EerPlanner, GuidanceKind, LawnConfig, LawnmowerPath, ReachShape};
use crate::metrics::StepRecord;
use crate::motion::{self, MotionError, MotionParams};
use crate::rng::CoreRng;
use crate::world::World;

/// How far back the measured track reaches for the target's last seen velocity, s.
const MEASURED_TRACK_S: f64 = 3.0;

/// How far back the target's cruising speed (the fastest it was measured driving over
/// [`MEASURED_TRACK_S`]) is remembered, s.
const CRUISE_WINDOW_S: f64 = 20.0;

/// The most empty frames a re-spread weighs its routes with (at 3 Hz, 22 minutes); older
/// ones are let go, which only forgets what they ruled out.
const MAX_EMPTY_FRAMES: usize = 4096;

/// What to do while the target is lost.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LostFallback {
    /// Keep the guidance law (EER searches by itself).
    Eer,
    /// Sweep the lawnmower path.
    Lawn,
    /// Stay where the vehicle is.
    Hold,
}

/// A fallback name that names none.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` (expected eer, lawn or hold)")]
pub struct UnknownFallback(pub String);

impl std::str::FromStr for LostFallback {
    type Err = UnknownFallback;
    fn from_str(s: &str) -> Result<Self, UnknownFallback> {
        match s {
            "eer" => Ok(Self::Eer),
            "lawn" => Ok(Self::Lawn),
            "hold" => Ok(Self::Hold),
            other => Err(UnknownFallback(other.to_string())),
        }
    }
}

/// The failsafes of a vehicle in flight (the daemon's; the simulator flies without them:
/// its sensor never fails and a failure is an error).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Failsafe {
    /// The target counts as lost after this long without a measurement, s.
    pub target_lost_after_s: f64,
    /// What to fly while it is lost.
    pub fallback: LostFallback,
    /// No frame for this long: hold, s.
    pub camera_timeout_s: f64,
    /// A decision that takes longer than this (caller's clock) is not applied, ms.
    pub guidance_budget_ms: f64,
}

/// Everything the tracker is built from: each component's own parameters.
#[derive(Debug, Clone)]
pub struct TrackerParams {
    /// Loop rates.
    pub rates: Rates,
    /// The guidance law.
    pub guidance: GuidanceKind,
    /// The particle filter.
    pub filter: FilterParams,
    /// The Kalman filter (the `kf` estimator and `kf` guidance).
    pub kalman: KalmanParams,
    /// The motion models.
    pub motion: MotionParams,
    /// EER.
    pub eer: EerParams,
    /// The lawnmower sweep (`lawn` guidance and the `lawn` fallback).
    pub lawn: LawnConfig,
    /// Failsafes; `None`: none, and any failure is an error.
    pub failsafe: Option<Failsafe>,
    /// The operator's cue (centre, radius, world ENU): the filter starts on the roads
    /// within it; `None`: on the whole road network.
    pub cue: Option<(Enu2, f64)>,
    /// After this long without a measurement, the belief is spread again along the roads
    /// that the target can have reached from where it was last seen (never seen, with a
    /// cue: since the start, from the cue's roads); `None`: never.
    pub respread_after_s: Option<f64>,
    /// Share of the particles replaced at each step without a measurement by hypotheses on
    /// the roads around the belief (0: none), for motion models that do not know the roads.
    pub injection_share: f64,
}

/// Why the tracker could not be built or could not go on.
#[derive(Debug, thiserror::Error)]
pub enum TrackerError {
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
    /// `truth` guidance without the truth.
    #[error("guidance `truth` needs the true target position, which only a simulator has")]
    NoTruth,
}

/// Why a tick failed: the sensor, or the tracker.
#[derive(Debug, thiserror::Error)]
pub enum TickError<E> {
    /// The sensor.
    #[error("sensor: {0}")]
    Sensor(E),
    /// The tracker.
    #[error(transparent)]
    Tracker(#[from] TrackerError),
}

/// Checks that a guidance law can run with an estimator.
pub fn check_combination(g: GuidanceKind, e: &EstimatorKind) -> Result<(), TrackerError> {
    if g.needs_particles() && *e == EstimatorKind::Kalman {
        return Err(TrackerError::Incompatible {
            guidance: g,
            motion: e.name().to_string(),
            reason: format!("{g} needs a particle set and `--motion kf` has none"),
        });
    }
    Ok(())
}

/// The tracker's state between ticks.
pub struct Tracker {
    params: TrackerParams,
    world: World,
    schedule: Schedule,
    estimator: Estimator,
    /// KF guidance always has a Kalman filter beside the estimator for its goal.
    side_kf: Option<KalmanFilter>,
    planner: EerPlanner,
    lawn: LawnmowerPath,
    rng_filter: CoreRng,
    rng_guidance: CoreRng,
    state: TrackState,
    last_measurement: Option<(f64, Enu2)>,
    last_seen_s: f64,
    last_frame_s: f64,
    command: Option<Command>,
    entropy: f64,
    last_eer: f64,
    /// The belief was spread again in the current spell without measurements.
    respread_done: bool,
    /// The estimate's speed at the last step with a measurement, m/s.
    last_seen_speed_mps: f64,
    /// The speeds measured over the last [`CRUISE_WINDOW_S`] (time, m/s), oldest first.
    recent_speeds: std::collections::VecDeque<(f64, f64)>,
    /// The estimate's velocity then, world ENU, m/s (which way the target was driving).
    last_seen_velocity_enu: Enu2,
    /// The measurements of the last [`MEASURED_TRACK_S`] seconds, oldest first.
    recent_measurements: std::collections::VecDeque<(f64, Enu2)>,
    /// The frames without the target since the last measurement (time, where the camera
    /// was, world ENU), oldest first, at most [`MAX_EMPTY_FRAMES`].
    empty_frames: std::collections::VecDeque<(f64, Enu2)>,
}

impl Tracker {
    /// Builds the estimator (drawing the initial particles from `rng_filter`) and the
    /// guidance; `rng_guidance` feeds EER's sampling.
    pub fn new(
        params: TrackerParams,
        world: World,
        estimator: &EstimatorKind,
        mut rng_filter: CoreRng,
        rng_guidance: CoreRng,
    ) -> Result<Self, TrackerError> {
        check_combination(params.guidance, estimator)?;
        let built = match estimator {
            EstimatorKind::Particle(name) => Estimator::Particle {
                pf: Box::new(ParticleFilter::on_roads(
                    params.filter.clone(),
                    &world,
                    params.cue,
                    &mut rng_filter,
                )),
                model: motion::build(name, &params.motion)?,
            },
            EstimatorKind::Kalman => {
                Estimator::Kalman(Box::new(KalmanFilter::new(params.kalman.clone())))
            }
        };
        let side_kf = (params.guidance == GuidanceKind::Kf && *estimator != EstimatorKind::Kalman)
            .then(|| KalmanFilter::new(params.kalman.clone()));
        Ok(Self {
            schedule: Schedule::new(params.rates),
            planner: EerPlanner::new(params.eer.clone()),
            lawn: LawnmowerPath::new(&params.lawn),
            params,
            world,
            estimator: built,
            side_kf,
            rng_filter,
            rng_guidance,
            state: TrackState::Tracking,
            last_measurement: None,
            last_seen_s: 0.0,
            last_frame_s: 0.0,
            command: None,
            entropy: f64::NAN,
            last_eer: f64::NAN,
            respread_done: false,
            last_seen_speed_mps: 0.0,
            recent_speeds: std::collections::VecDeque::new(),
            last_seen_velocity_enu: Enu2::zeros(),
            recent_measurements: std::collections::VecDeque::new(),
            empty_frames: std::collections::VecDeque::new(),
        })
    }

    /// The world it tracks in.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The estimator.
    pub fn estimator(&self) -> &Estimator {
        &self.estimator
    }

    /// The filter's belief carried one filter period forward, to when the next frame is
    /// taken: the estimate moved by its velocity. Where the camera should look first: at
    /// field scale a 10 m/s car moves 3.3 m (about 70 px from 45 m) between frames, which
    /// put it at the edge of a search region centred on the last estimate. The spread is
    /// the estimate's own: adding the process noise too would widen the lab's regions past
    /// the size worth searching (its noise, 3 cm a step, is 23 px there), and what the
    /// search region needs is the systematic move, not the random one.
    pub fn prior(&self) -> Prior {
        let dt_s = self.params.filter.dt_s;
        Prior {
            mean_enu: self.estimator.mean() + self.estimator.velocity() * dt_s,
            cov_m2: self.estimator.covariance(),
        }
    }

    /// The command in force.
    pub fn command(&self) -> Option<Command> {
        self.command
    }

    /// The tracking state.
    pub fn state(&self) -> TrackState {
        self.state
    }

    /// One physics tick: a filter step and a guidance decision when due.
    pub fn tick<S: Sensor>(
        &mut self,
        input: &TickInput,
        sensor: &mut S,
        clock: &dyn Clock,
    ) -> Result<TickOutput, TickError<S::Error>> {
        let Some(vehicle_enu) = input.vehicle_enu else {
            // Nothing to act from yet: time passes, what is due stays due.
            return Ok(TickOutput {
                t_s: self.schedule.skip(),
                ..TickOutput::default()
            });
        };
        let due = self.schedule.advance();
        let mut out = TickOutput {
            t_s: due.t_s,
            ..TickOutput::default()
        };
        if due.filter {
            let observation = sensor
                .observe(due.t_s, &vehicle_enu, &self.prior())
                .map_err(TickError::Sensor)?;
            out.step = Some(self.update(due.t_s, observation, input, clock)?);
        }
        if due.guidance {
            let truth = input.truth_enu.map(|p| (p, input.truth_velocity_enu));
            out.decision = self.decide(due.t_s, &vehicle_enu, truth, clock)?;
        }
        Ok(out)
    }

    /// One filter step with an observation, at `t_s`. Public for `infotrack replay`, which
    /// feeds a flight's recorded observations in their order.
    pub fn update(
        &mut self,
        t_s: f64,
        observation: Observation,
        input: &TickInput,
        clock: &dyn Clock,
    ) -> Result<StepOutcome, TrackerError> {
        let vehicle_enu = input.vehicle_enu.unwrap_or(Enu2::new(f64::NAN, f64::NAN));
        let (taken_from, z, frame) = match observation {
            Observation::Frame { taken_from_enu, z } => (taken_from_enu, z, true),
            Observation::NoFrame => (vehicle_enu, None, false),
        };
        if frame {
            self.last_frame_s = t_s;
        }
        if let Some(z) = z {
            self.remember_measurement(t_s, z);
            self.empty_frames.clear();
        } else if frame {
            if self.empty_frames.len() == MAX_EMPTY_FRAMES {
                self.empty_frames.pop_front();
            }
            self.empty_frames.push_back((t_s, taken_from));
        }
        let started = clock.now_s();
        let stepped = if frame {
            self.estimator
                .step(z, &taken_from, &self.world, &mut self.rng_filter)
        } else {
            self.estimator.step_blind(&mut self.rng_filter)
        };
        let update_ms = (clock.now_s() - started) * 1e3;
        let (n_eff, filter_error) = match stepped {
            Ok(n) => (n, None),
            Err(e) if self.params.failsafe.is_some() => (f64::NAN, Some(e.to_string())),
            Err(e) => return Err(e.into()),
        };
        if let Some(kf) = self.side_kf.as_mut() {
            kf.step(z);
        }
        if z.is_some() {
            self.last_seen_s = t_s;
            self.respread_done = false;
            self.last_seen_velocity_enu = self.measured_velocity();
            self.last_seen_speed_mps = self.last_seen_velocity_enu.norm();
            self.recent_speeds
                .push_back((t_s, self.last_seen_speed_mps));
            while self
                .recent_speeds
                .front()
                .is_some_and(|(t, _)| t_s - t > CRUISE_WINDOW_S)
            {
                self.recent_speeds.pop_front();
            }
        } else {
            self.respread_if_long_unseen(t_s);
            self.inject_where_it_can_be();
        }
        let before = self.state;
        self.state = self.next_state(t_s, input.link_lost);
        let truth = input.truth_enu.unwrap_or(Enu2::new(f64::NAN, f64::NAN));
        let record = StepRecord {
            t_s,
            target_enu: truth,
            agent_enu: taken_from,
            waypoint_enu: match self.command {
                Some(Command::GoTo { position_enu, .. }) => position_enu,
                _ => taken_from,
            },
            measurement_enu: z,
            estimate_enu: self.estimator.mean(),
            cov_m2: self.estimator.covariance(),
            n_eff,
            eer: self.last_eer,
            target_occluded: self.world.is_occluded(&truth),
            target_in_footprint: self.world.footprint.contains(&taken_from, &truth),
        };
        Ok(StepOutcome {
            record,
            state: self.state,
            frame,
            command: self.command,
            entropy: self.entropy,
            update_ms,
            filter_error,
            camera_lost_now: self.state == TrackState::CameraLost
                && before != TrackState::CameraLost,
        })
    }

    fn remember_measurement(&mut self, t_s: f64, z: Enu2) {
        self.last_measurement = Some((t_s, z));
        self.recent_measurements.push_back((t_s, z));
        while self
            .recent_measurements
            .front()
            .is_some_and(|(t, _)| t_s - t > MEASURED_TRACK_S)
        {
            self.recent_measurements.pop_front();
        }
    }

    /// The target's velocity as its measurements of the last [`MEASURED_TRACK_S`] seconds
    /// show it (first to last), when they span at least half that; else the estimate's.
    /// After a re-seed a particle filter's velocity starts again from zero, and the speed
    /// the re-spread bands are drawn with must not: measured motion is what the target did.
    fn measured_velocity(&self) -> Enu2 {
        match (
            self.recent_measurements.front(),
            self.recent_measurements.back(),
        ) {
            (Some((t0, z0)), Some((t1, z1))) if t1 - t0 >= 0.5 * MEASURED_TRACK_S => {
                (z1 - z0) / (t1 - t0)
            }
            _ => self.estimator.velocity(),
        }
    }

    /// The speeds new hypotheses get: from 0.7 x the speed the target had when last seen
    /// to 1.3 x the fastest it was measured driving over the last [`CRUISE_WINDOW_S`] (a
    /// car keeps its speed through a junction it cannot be seen at, and one last seen
    /// slowing for a turn drives on at its cruising speed), or any speed the motion model
    /// allows when it was not moving or never seen.
    fn hypothesis_speeds(&self) -> std::ops::RangeInclusive<f64> {
        let v_max = self.params.filter.init_speed_max_mps;
        let s = self.last_seen_speed_mps;
        let cruise = self.recent_speeds.iter().map(|(_, v)| *v).fold(s, f64::max);
        if self.last_measurement.is_some() && cruise > 0.1 * v_max {
            (0.7 * s).min(v_max)..=(1.3 * cruise).min(v_max)
        } else {
            0.0..=v_max
        }
    }

    /// After `respread_after_s` without a measurement, once per such spell: the particles
    /// go back on the roads the target can have driven to since it was last seen, each on
    /// one route forward from the last measurement and weighted by the empty frames since
    /// ([`Self::respread_along_routes`]); never seen, each on a route from a point on the
    /// cue's roads, weighted by every empty frame since the start (before session 20 the
    /// cue's roads carried forward, which gave the roads the drone had flown along empty
    /// their share back: on field-eight the car was never found in 4 runs of 10); anywhere
    /// without a cue. A disc around the last measurement would put half the belief behind
    /// the target and on roads it cannot have reached; spreading over the reachable roads
    /// alone (before session 19) gave the branches the camera had already ruled out their
    /// share back (field-grid: the belief that had found the car turning north was split
    /// even again at the re-spread, and the drone flew east after it).
    fn respread_if_long_unseen(&mut self, t_s: f64) {
        let Some(after) = self.params.respread_after_s else {
            return;
        };
        if self.respread_done || t_s - self.last_seen_s <= after {
            return;
        }
        self.respread_done = true;
        if self.respread_along_routes(t_s) {
            return;
        }
        // No route to draw (no cue, or no road): the roads around where it can be.
        let speeds = self.hypothesis_speeds();
        let v_far = *speeds.end();
        let region = match self.last_measurement {
            Some((tm, zm)) => Some((zm, v_far * (t_s - tm))),
            None => self.params.cue.map(|(c, r)| (c, r + v_far * t_s)),
        };
        if let Estimator::Particle { pf, .. } = &mut self.estimator {
            pf.spread_on_roads_at(&self.world, region, speeds, &mut self.rng_filter);
        }
    }

    /// The re-spread along routes: every particle on a route the target can have driven
    /// since it was last measured (never seen: since the start, from a point on the cue's
    /// roads), weighted by the empty frames since (see
    /// [`ParticleFilter::spread_along_routes`]). False when it cannot be (never seen
    /// without a cue, no roads within it, or the Kalman filter).
    fn respread_along_routes(&mut self, t_s: f64) -> bool {
        let cue_roads;
        let (tm, start) = match (self.last_measurement, self.params.cue) {
            (Some((tm, zm)), _) => (tm, RouteStart::At(zm, Some(self.last_seen_velocity_enu))),
            (None, Some(cue)) => {
                cue_roads = self.world.road.roads_within(Some(cue));
                if cue_roads.length_m() <= 0.0 {
                    return false;
                }
                (0.0, RouteStart::On(&cue_roads))
            }
            _ => return false,
        };
        let speeds = self.hypothesis_speeds();
        let looked: Vec<(f64, Enu2)> = self
            .empty_frames
            .iter()
            .filter(|(t, _)| *t >= tm)
            .map(|(t, camera)| (t - tm, *camera))
            .collect();
        match &mut self.estimator {
            Estimator::Particle { pf, .. } => pf.spread_along_routes(
                &self.world,
                start,
                speeds,
                (t_s - tm).max(0.0),
                &looked,
                &mut self.rng_filter,
            ),
            Estimator::Kalman(_) => false,
        }
    }

    /// At each step without a measurement, for a motion model that does not know the roads
    /// (constant velocity, which drives straight on through a junction): once the target has
    /// been seen, the particles at a junction are re-routed onto the roads they can take
    /// (`ParticleFilter::reroute_at_junctions`: the belief itself, so what the agent has
    /// ruled out stays ruled out); before that, a share of the particles
    /// (`injection_share`) is replaced by hypotheses on the roads around the belief (within
    /// two standard deviations of its mean plus a second at the largest speed). A share of
    /// 0 turns both off.
    fn inject_where_it_can_be(&mut self) {
        let share = self.params.injection_share;
        let knows_roads = match &self.estimator {
            Estimator::Particle { model, .. } => model.knows_the_roads(),
            Estimator::Kalman(_) => true,
        };
        if share <= 0.0 || knows_roads {
            return;
        }
        let v_max = self.params.filter.init_speed_max_mps;
        let sd = self.estimator.largest_sd_m();
        let region = Some((self.estimator.mean(), 2.0 * sd + v_max));
        let speeds = self.hypothesis_speeds();
        let count = (share * self.params.filter.particles as f64).round() as usize;
        let seen = self.last_measurement.is_some();
        if let Estimator::Particle { pf, .. } = &mut self.estimator {
            if seen {
                pf.reroute_at_junctions(&self.world, &mut self.rng_filter);
            } else {
                pf.inject_on_roads(&self.world, region, count, speeds, &mut self.rng_filter);
            }
        }
    }

    fn next_state(&self, t_s: f64, link_lost: bool) -> TrackState {
        let Some(f) = self.params.failsafe else {
            return TrackState::Tracking;
        };
        if link_lost {
            TrackState::LinkLost
        } else if t_s - self.last_frame_s > f.camera_timeout_s {
            TrackState::CameraLost
        } else if t_s - self.last_seen_s > f.target_lost_after_s {
            TrackState::Lost
        } else {
            TrackState::Tracking
        }
    }

    /// One guidance decision at `t_s` for a vehicle at `vehicle_enu` (`truth`: the true
    /// target's position and velocity, world ENU, where a simulator knows them). `None`: no
    /// decision is taken on a stale vehicle state (link lost). Public for `infotrack
    /// replay`.
    pub fn decide(
        &mut self,
        t_s: f64,
        vehicle_enu: &Enu2,
        truth: Option<(Enu2, Enu2)>,
        clock: &dyn Clock,
    ) -> Result<Option<Decision>, TrackerError> {
        if self.state == TrackState::LinkLost {
            return Ok(None);
        }
        let started = clock.now_s();
        let decided = self.choose(t_s, vehicle_enu, truth);
        let compute_ms = (clock.now_s() - started) * 1e3;
        let failsafe = self.params.failsafe;
        let over_budget = failsafe.is_some_and(|f| compute_ms > f.guidance_budget_ms);
        let command = match decided {
            Ok(c) => c,
            Err(e) if failsafe.is_some() => {
                return Ok(Some(Decision::Failed {
                    reason: e.to_string(),
                    compute_ms,
                    over_budget,
                }))
            }
            Err(e) => return Err(e),
        };
        if over_budget {
            return Ok(Some(Decision::Overrun { compute_ms }));
        }
        let command = match command {
            Command::GoTo {
                position_enu,
                velocity_enu,
            } => Command::GoTo {
                position_enu: self.world.workspace_enu.clamp(&position_enu),
                velocity_enu,
            },
            hold => hold,
        };
        self.command = Some(command);
        Ok(Some(Decision::Command {
            command,
            compute_ms,
        }))
    }

    /// What the guidance law (or the failsafe in force) says, before the geofence.
    fn choose(
        &mut self,
        t_s: f64,
        vehicle_enu: &Enu2,
        truth: Option<(Enu2, Enu2)>,
    ) -> Result<Command, TrackerError> {
        if let Some(f) = self.params.failsafe {
            match (self.state, f.fallback) {
                (TrackState::CameraLost, _) | (TrackState::Lost, LostFallback::Hold) => {
                    return Ok(Command::HoldHere)
                }
                (TrackState::Lost, LostFallback::Lawn) => {
                    return Ok(Command::fixed(self.lawn.next_point()))
                }
                _ => {}
            }
        }
        Ok(match self.params.guidance {
            GuidanceKind::Eer => self.plan_eer(t_s, vehicle_enu)?,
            GuidanceKind::Pfwm => Command::GoTo {
                position_enu: self.estimator.mean(),
                velocity_enu: self.confident_velocity(),
            },
            GuidanceKind::Kf => match &self.side_kf {
                Some(k) => Command::GoTo {
                    position_enu: k.mean(),
                    velocity_enu: k.velocity(),
                },
                None => Command::GoTo {
                    position_enu: self.estimator.mean(),
                    velocity_enu: self.estimator.velocity(),
                },
            },
            GuidanceKind::Truth => {
                let (p, v) = truth.ok_or(TrackerError::NoTruth)?;
                Command::GoTo {
                    position_enu: p,
                    velocity_enu: v,
                }
            }
            GuidanceKind::Lawn => Command::fixed(match self.last_measurement {
                Some((tm, z)) if t_s - tm <= self.params.lawn.track_measurement_for_s => z,
                _ => self.lawn.next_point(),
            }),
        })
    }

    /// The estimate's velocity when the belief is concentrated enough to be over the
    /// target (its largest standard deviation within half the footprint's smaller side);
    /// zero while it is spread out, when a mean velocity means nothing.
    fn confident_velocity(&self) -> Enu2 {
        let fp = &self.world.footprint;
        if self.estimator.largest_sd_m() <= fp.quarter_view_m() {
            self.estimator.velocity()
        } else {
            Enu2::zeros()
        }
    }

    /// How long after the last measurement the belief stays local (the one that measurement
    /// left): the plan's horizon, or, if longer, the time the target, at the speed it was last
    /// seen at, takes to cross the camera's view along its shorter side. Until then the target
    /// may still be in or by the view it was lost from and EER's argmax follows it; after it,
    /// the belief may have split (an occluded junction) and EER keeps to one mode. With one
    /// horizon alone, the lab's closed loop lost 2.5 points of frames with the tag (seeds
    /// 1-16: a slow target hidden for seconds under a 1 m square, the argmax still the right
    /// move); with the crossing time it is level (BENCHMARKS.md "Field scale, part 27").
    fn local_for_s(&self, horizon_s: f64) -> f64 {
        let fp = self.world.footprint;
        let view_m = 2.0 * fp.half_width_m.min(fp.half_height_m);
        horizon_s.max(view_m / self.last_seen_speed_mps.max(1e-9))
    }

    /// EER's waypoint is where to be at the end of the horizon; with the target's velocity
    /// (when the belief is concentrated) the setpoint moves so as to get there then, riding
    /// along with the target instead of trailing it.
    fn plan_eer(&mut self, t_s: f64, vehicle_enu: &Enu2) -> Result<Command, TrackerError> {
        let over_target_velocity_enu = self.confident_velocity();
        let horizon_s = self.params.eer.horizon_steps as f64 * self.params.filter.dt_s;
        // Searching: EER then keeps to one mode (BENCHMARKS.md "Field scale, parts 26-27").
        let searching = self.respread_done
            || is_searching(self.last_measurement, t_s, self.local_for_s(horizon_s));
        let Estimator::Particle { pf, model } = &mut self.estimator else {
            // Refused at construction by check_combination.
            return Err(TrackerError::Incompatible {
                guidance: GuidanceKind::Eer,
                motion: "kf".into(),
                reason: "eer needs a particle set".into(),
            });
        };
        self.planner.use_intercepts(self.last_measurement.is_some());
        self.planner.set_searching(searching);
        // EER plans with the prediction the filter makes: where the filter re-routes its
        // constant-velocity belief at junctions, so does the rollout. Straight on, the
        // predicted tracks ran off the road past every corner and EER sent the drone
        // there: it overshot the car's turns and chased from behind (BENCHMARKS.md "Field
        // scale, part 24").
        let reroutes = self.last_measurement.is_some()
            && self.params.injection_share > 0.0
            && !model.knows_the_roads();
        let on_road_m = 0.5 * self.params.filter.road_sigma_m.unwrap_or(0.0);
        self.planner.reroute_rollout(reroutes.then_some(on_road_m));
        let d = self.planner.plan(
            pf,
            model.as_mut(),
            vehicle_enu,
            &self.world,
            &mut self.rng_guidance,
        )?;
        self.entropy = d.h_now;
        self.last_eer = d.eer;
        let velocity_enu = if over_target_velocity_enu == Enu2::zeros() {
            approach_velocity(
                vehicle_enu,
                &d.waypoint_enu,
                horizon_s,
                self.params.eer.reach_m,
                self.params.eer.reach_shape,
            )
        } else {
            over_target_velocity_enu
        };
        Ok(Command::GoTo {
            position_enu: d.waypoint_enu - velocity_enu * horizon_s,
            velocity_enu,
        })
    }
}

/// Whether EER is searching at `t_s`: the target never seen, or unseen for longer than
/// `local_s` ([`Tracker::local_for_s`]), so that the belief may have split where it went out
/// of view (an occluded junction, a covered crossing). Tracking through a loss with the
/// paper's argmax, the plan flipped between a covered crossing's two exits from one plan to
/// the next and the drone saw neither (field-eight: 39 % of the time in view; BENCHMARKS.md
/// "Field scale, part 27").
fn is_searching(last_measurement: Option<(f64, Enu2)>, t_s: f64, local_s: f64) -> bool {
    last_measurement.map_or(true, |(seen_s, _)| t_s - seen_s > local_s)
}

/// The planned motion toward a waypoint beyond every candidate of the reachable region (a
/// square's corners lie at sqrt(2) x reach, a disc's rim at reach; beyond them a waypoint is
/// a far predicted particle) while the belief is
/// spread out: the agent's top speed along the way, so that the setpoint (`reach` short of
/// the waypoint, moving to it) carries the transit's speed as feed-forward instead of
/// trailing it by speed / position gain. Otherwise zero, a fixed point, which arrives
/// sooner than a setpoint that spreads the move over the horizon (that cost the lab's closed
/// loop 12-17 points of FOV). The threshold was `reach` at first; at the grid's corners the
/// transit cost the lab's closed loop 1.3 points over 16 seeds (BENCHMARKS "Field scale,
/// part 7").
fn approach_velocity(
    vehicle_enu: &Enu2,
    waypoint_enu: &Enu2,
    horizon_s: f64,
    reach_m: f64,
    reach_shape: ReachShape,
) -> Enu2 {
    let to_go = waypoint_enu - vehicle_enu;
    let distance = to_go.norm();
    // The tolerance keeps the region's own farthest candidates (a square's corners, a
    // disc's rim, exactly there before rounding) on the fixed-point side.
    let farthest_candidate_m = reach_shape.farthest_in_reaches() * reach_m + 1e-9;
    if distance <= farthest_candidate_m || horizon_s <= 0.0 {
        return Enu2::zeros();
    }
    to_go * (reach_m / distance / horizon_s)
}

#[cfg(test)]
mod tests;
