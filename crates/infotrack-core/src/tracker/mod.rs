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
pub mod effort;
pub mod estimator;
pub mod ports;
pub mod schedule;
pub mod sections;

mod belief;
mod plan;
#[cfg(test)]
use plan::approach_velocity;

pub use clock::{Clock, FrozenClock, MonotonicClock};
pub use estimator::{Estimator, EstimatorKind, EstimatorModel, UnknownEstimator};
pub use ports::{
    Command, Decision, Observation, Prior, Sensor, StepOutcome, TickInput, TickOutput, TrackState,
};
pub use schedule::{Due, Rates, Schedule};

use crate::estimation::{
    FilterError, FilterParams, KalmanFilter, KalmanParams, ParticleFilter, RouteStart,
};
use crate::frames::Enu2;
use crate::guidance::{
    EerParams, EerPlanner, GuidanceKind, HeadingRule, LawnConfig, LawnmowerPath, ReachShape,
    ViewHeading,
};
use crate::metrics::StepRecord;
use crate::motion::{MotionError, MotionParams};
use crate::rng::CoreRng;
use crate::world::camera::View;
use crate::world::road::RoadWeighting;
use crate::world::World;

/// How far back the measured track reaches for the target's last seen velocity, s.
const MEASURED_TRACK_S: f64 = 3.0;

/// How far back the target's cruising speed (the fastest it was measured driving over
/// [`MEASURED_TRACK_S`]) is remembered, s.
const CRUISE_WINDOW_S: f64 = 20.0;

/// The share of the belief a repeated re-spread keeps on the filter's particles (the rest
/// goes on new routes, [`ParticleFilter::keep_part_of`]). Half, the one value measured
/// (BENCHMARKS.md): all routes lost resolution where the filter's
/// belief was right (field-eight -2.9 points).
const RESPREAD_KEEP_SHARE: f64 = 0.5;

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

/// The slowest speed of the search from a cue, as a share of the motion model's largest,
/// when a config leaves `acquisition.min_speed_mps` out. With speeds uniform from 0, half
/// the cue's belief was slower than half the largest speed and stayed
/// near the cue: EER, which values what it can see within its 2 s horizon, hovered over
/// the cue's junction while the car drove away (random-1 run 0: 107 m behind after 10 s)
/// and, chasing from behind, its sweep ruled out the slow hypotheses of the road it chased
/// until the unwatched road's full share looked likelier (it turned back 46 m behind the
/// car). A cued target is a moving car to be followed; one that is standing is in view
/// when the drone passes the cue, and an operator who expects a parked target sets the
/// key to 0. Sixteen random worlds' own seeds: mean FOV +3.1 points, the first sighting's
/// failures most (random-15 26.9 -> 46.3 %, random-16 33.3 -> 48.2 %); BENCHMARKS.md
/// BENCHMARKS.md.
pub const DEFAULT_CUE_MIN_SPEED_SHARE: f64 = 0.5;

/// Everything the tracker is built from: each component's own parameters.
#[derive(Debug, Clone)]
pub struct TrackerParams {
    /// Loop rates.
    pub rates: Rates,
    /// The guidance law.
    pub guidance: GuidanceKind,
    /// Which way every command turns the view (and EER judges its candidates at).
    pub heading: HeadingRule,
    /// The particle filter.
    pub filter: FilterParams,
    /// The Kalman filter (the `kf` estimator and `kf` guidance).
    pub kalman: KalmanParams,
    /// The motion models.
    pub motion: MotionParams,
    /// EER.
    pub eer: EerParams,
    /// Waiting where a long-lost target will pass ([`crate::guidance::ambush`]).
    pub ambush: crate::guidance::ambush::AmbushParams,
    /// The lawnmower sweep (`lawn` guidance and the `lawn` fallback).
    pub lawn: LawnConfig,
    /// Failsafes; `None`: none, and any failure is an error.
    pub failsafe: Option<Failsafe>,
    /// The operator's cue (centre, radius, world ENU): the filter starts on the roads
    /// within it; `None`: on the whole road network.
    pub cue: Option<(Enu2, f64)>,
    /// How the cue's belief is spread over its roads (the prior, and the re-spread until
    /// the first sighting): by traffic or by length.
    pub cue_prior: RoadWeighting,
    /// The speeds, m/s, of the hypotheses drawn before the first sighting: the prior from
    /// the cue and the re-spreads from its roads (without a cue, the lab's whole-network
    /// prior, from 0); see [`DEFAULT_CUE_MIN_SPEED_SHARE`].
    pub cue_speeds_mps: std::ops::RangeInclusive<f64>,
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
    check_needs(g, e.name(), *e == EstimatorKind::Kalman)
}

/// [`check_combination`] for an estimator by its name and whether it is the Kalman filter.
fn check_needs(g: GuidanceKind, name: &str, kalman: bool) -> Result<(), TrackerError> {
    if g.needs_particles() && kalman {
        return Err(TrackerError::Incompatible {
            guidance: g,
            motion: name.to_string(),
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
    /// How many of its hypotheses EER weighs under the compute budget.
    effort: effort::Effort,
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
    /// The view heading EER chose with its waypoint (world ENU yaw, rad), for the command
    /// to fly, when the heading rule lets EER choose (`informed`) and the waypoint is near
    /// enough to be seen as judged; `None` otherwise (the rule sets the heading).
    planned_view_yaw_enu_rad: Option<f64>,
    /// How many times the belief was spread again in the current spell without
    /// measurements.
    respreads_in_spell: u32,
    /// The ambush point in force ([`crate::guidance::ambush`]).
    ambush_point_enu: Option<Enu2>,
    /// The estimate's speed at the last step with a measurement, m/s.
    last_seen_speed_mps: f64,
    /// The speeds measured over the last [`CRUISE_WINDOW_S`] (time, m/s), oldest first.
    recent_speeds: std::collections::VecDeque<(f64, f64)>,
    /// The estimate's velocity then, world ENU, m/s (which way the target was driving).
    last_seen_velocity_enu: Enu2,
    /// The measurements of the last [`MEASURED_TRACK_S`] seconds, oldest first.
    recent_measurements: std::collections::VecDeque<(f64, Enu2)>,
    /// The frames without the target since the last measurement (time, the camera's view),
    /// oldest first, at most [`MAX_EMPTY_FRAMES`].
    empty_frames: std::collections::VecDeque<(f64, View)>,
}

impl Tracker {
    /// Builds the estimator around its ready model (drawing the initial particles from
    /// `rng_filter`) and the guidance; `rng_guidance` feeds EER's sampling. Reads no file:
    /// the caller builds the model ([`EstimatorKind::build`]).
    pub fn new(
        params: TrackerParams,
        world: World,
        estimator: EstimatorModel,
        mut rng_filter: CoreRng,
        rng_guidance: CoreRng,
    ) -> Result<Self, TrackerError> {
        let kalman = matches!(estimator, EstimatorModel::Kalman);
        check_needs(params.guidance, estimator.name(), kalman)?;
        let built = match estimator {
            EstimatorModel::Particle { model, .. } => Estimator::Particle {
                pf: Box::new(match params.cue {
                    Some(cue) => ParticleFilter::on_weighted_roads(
                        params.filter.clone(),
                        &world,
                        cue,
                        params.cue_prior,
                        params.cue_speeds_mps.clone(),
                        &mut rng_filter,
                    ),
                    None => ParticleFilter::on_roads(
                        params.filter.clone(),
                        &world,
                        None,
                        params.cue_speeds_mps.clone(),
                        &mut rng_filter,
                    ),
                }),
                model,
            },
            EstimatorModel::Kalman => {
                Estimator::Kalman(Box::new(KalmanFilter::new(params.kalman.clone())))
            }
        };
        let side_kf = (params.guidance == GuidanceKind::Kf && !kalman)
            .then(|| KalmanFilter::new(params.kalman.clone()));
        Ok(Self {
            schedule: Schedule::new(params.rates),
            planner: EerPlanner::new(params.eer.clone()),
            effort: effort::Effort::default(),
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
            planned_view_yaw_enu_rad: None,
            respreads_in_spell: 0,
            ambush_point_enu: None,
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

    /// How often the belief has been re-spread since the target was last seen.
    pub fn respreads_in_spell(&self) -> u32 {
        self.respreads_in_spell
    }

    /// The tracker's state.
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
        let Some(vehicle) = input
            .vehicle_enu
            .map(|p| View::new(p, input.view_yaw_enu_rad))
        else {
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
                .observe(due.t_s, &vehicle, &self.prior())
                .map_err(TickError::Sensor)?;
            out.step = Some(self.update(due.t_s, observation, input, clock)?);
        }
        if due.guidance {
            let truth = input.truth_enu.map(|p| (p, input.truth_velocity_enu));
            out.decision = self.decide(due.t_s, &vehicle, truth, clock)?;
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
            Observation::Frame { taken_from, z } => (taken_from, z, true),
            Observation::NoFrame => (View::new(vehicle_enu, input.view_yaw_enu_rad), None, false),
        };
        self.note_frame(t_s, frame, z, &taken_from);
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
            self.note_sighting(t_s);
        } else {
            self.respread_if_long_unseen(t_s);
            self.inject_where_it_can_be();
        }
        let before = self.state;
        self.state = self.next_state(t_s, input.link_lost);
        Ok(StepOutcome {
            record: self.record(t_s, input, &taken_from, z, n_eff),
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

    /// Remembers a frame: its time, and its measurement or where it saw nothing.
    fn note_frame(&mut self, t_s: f64, frame: bool, z: Option<Enu2>, taken_from: &View) {
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
            self.empty_frames.push_back((t_s, *taken_from));
        }
    }

    /// The target seen at `t_s`: the lost spell ends, and its measured speed joins the
    /// recent ones.
    fn note_sighting(&mut self, t_s: f64) {
        self.last_seen_s = t_s;
        self.respreads_in_spell = 0;
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
    }

    /// The step's record: truth (where a simulator has it), view, command, measurement and
    /// estimate.
    fn record(
        &self,
        t_s: f64,
        input: &TickInput,
        taken_from: &View,
        z: Option<Enu2>,
        n_eff: f64,
    ) -> StepRecord {
        let truth = input.truth_enu.unwrap_or(Enu2::new(f64::NAN, f64::NAN));
        StepRecord {
            t_s,
            target_enu: truth,
            agent_enu: taken_from.centre_enu,
            waypoint_enu: match self.command {
                Some(Command::GoTo { position_enu, .. }) => position_enu,
                _ => taken_from.centre_enu,
            },
            measurement_enu: z,
            estimate_enu: self.estimator.mean(),
            cov_m2: self.estimator.covariance(),
            n_eff,
            eer: self.last_eer,
            target_occluded: self.world.is_occluded(&truth),
            target_in_footprint: self.world.footprint.contains(taken_from, &truth),
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
}

#[cfg(test)]
mod tests;
