//! The particle filter of the paper (Section III-B) with the authors' resampling scheme
//! (thresholds a and b, roughening, re-seeding, uniform re-draw), implemented cleanly:
//! a resampled particle carries its whole history and the weights reset to 1/N (the
//! authors' code copied only the newest position and kept the old weights).

use std::collections::VecDeque;

use nalgebra::Matrix2;
use rand::Rng;
use rand_distr::{Distribution, Exp1, StandardNormal};
use thiserror::Error;

use super::road_following;
use crate::motion::{Histories, MotionError, MotionModel};
use crate::world::geometry::{BoundsEnu, Enu2};
use crate::world::measurement::Gaussian2;
use crate::world::road::RoadPieces;
use crate::world::World;

/// Why a filter step failed.
#[derive(Debug, Error)]
pub enum FilterError {
    /// The motion model failed.
    #[error(transparent)]
    Motion(#[from] MotionError),
}

/// Filter steps over which a track's heading is read for the road constraint.
const HEADING_STEPS: usize = 3;

/// How much farther than the nearest road a track driving a one-way road the wrong way
/// counts, in road sigmas (2: its weight falls by e^-2 a step against a track on the road).
const WRONG_WAY_SIGMAS: f64 = 2.0;

/// The filter's parameters (the configuration assembles them).
#[derive(Debug, Clone)]
pub struct FilterParams {
    /// N.
    pub particles: usize,
    /// K_in.
    pub history_len: usize,
    /// Noise added after each prediction: N(0, 2Q).
    pub process_noise: Gaussian2,
    /// a.
    pub resample_threshold: f64,
    /// b.
    pub reseed_threshold: f64,
    /// Roughening constant.
    pub roughening: f64,
    /// p(no detection | target in view).
    pub miss_probability: f64,
    /// Uniform re-draw when more than this share is outside the workspace.
    pub max_outside_fraction: f64,
    /// Largest speed of the straight tracks drawn at (re-)initialisation, m/s.
    pub init_speed_max_mps: f64,
    /// Filter period, s.
    pub dt_s: f64,
    /// When the filter must start over (weights degenerate without a measurement, or too
    /// many particles outside the workspace), it re-draws on the whole road network (the
    /// target is a vehicle on its roads) rather than over the workspace rectangle.
    pub redraw_on_roads: bool,
    /// The target drives on the roads: after each prediction a particle's weight is
    /// multiplied by exp(-d^2 / 2 sigma^2), d its distance to the nearest road, so that
    /// tracks that drive off the network (a constant-velocity track past a bend) fade;
    /// `None`: no such constraint.
    pub road_sigma_m: Option<f64>,
}

/// What the filter did to its particle set in one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResampleAction {
    /// Kept the weighted set.
    None,
    /// Multinomial resampling and roughening (N_eff < a N).
    Resampled,
    /// Re-seeded around the recent measurements (N_eff < b N with a measurement).
    Reseeded,
    /// More than the allowed share left the workspace: re-drawn uniformly.
    UniformRedraw,
    /// The weights were degenerate (all zero or not finite): re-seeded or re-drawn.
    Recovered,
}

/// The outcome of one step.
#[derive(Debug, Clone, Copy)]
pub struct StepReport {
    /// Whether a measurement was used.
    pub measured: bool,
    /// N_eff after the update and before any resampling.
    pub n_eff: f64,
    /// What was done to the set.
    pub action: ResampleAction,
    /// Predictions the motion model returned as NaN or infinite (replaced by the last
    /// position and counted; never taken in).
    pub nonfinite_predictions: usize,
}

/// Counters over the filter's life, for logs and reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FilterCounters {
    /// Steps run.
    pub steps: u64,
    /// Multinomial resamplings.
    pub resamples: u64,
    /// Re-seeds around measurements.
    pub reseeds: u64,
    /// Uniform re-draws after leaving the workspace.
    pub uniform_redraws: u64,
    /// Recoveries from degenerate weights.
    pub recoveries: u64,
    /// Non-finite model outputs rejected.
    pub nonfinite_predictions: u64,
}

/// Where the routes of [`ParticleFilter::spread_along_routes`] start.
#[derive(Debug, Clone, Copy)]
pub enum RouteStart<'a> {
    /// Where the target was last measured, with the way it was driving (world ENU); each
    /// route starts at its own draw of where the target was, the measurement give or take
    /// its noise.
    At(Enu2, Option<Enu2>),
    /// A point drawn on these roads by length for each route, driving along its road (the
    /// operator's cue before the target has been seen).
    On(&'a RoadPieces),
}

/// A particle filter whose particles each carry a history of their last K_in positions.
#[derive(Debug, Clone)]
pub struct ParticleFilter {
    params: FilterParams,
    workspace_enu: BoundsEnu,
    histories: Histories,
    weights: Vec<f64>,
    /// Recent measurements with the step they arrived at, for re-seeding.
    recent: VecDeque<(u64, Enu2)>,
    step_index: u64,
    counters: FilterCounters,
    // Scratch buffers reused across steps.
    predicted: Vec<Enu2>,
    resampled: Histories,
    indices: Vec<usize>,
}

impl ParticleFilter {
    /// A filter with particles drawn uniformly over the workspace.
    pub fn new<R: Rng + ?Sized>(
        params: FilterParams,
        workspace_enu: BoundsEnu,
        rng: &mut R,
    ) -> Self {
        let n = params.particles;
        let k = params.history_len;
        let mut pf = Self {
            histories: Histories::new(n, k),
            weights: vec![1.0 / n as f64; n],
            recent: VecDeque::with_capacity(k),
            step_index: 0,
            counters: FilterCounters::default(),
            predicted: vec![Enu2::zeros(); n],
            resampled: Histories::new(n, k),
            indices: Vec::with_capacity(n),
            params,
            workspace_enu,
        };
        pf.redraw_uniform(rng);
        pf
    }

    /// A filter with particles on the roads of `world` within `region` (a centre and a
    /// radius, world ENU; `None`: the whole network), each moving along its road's
    /// allowed direction at a speed drawn from [0, init_speed_max].
    pub fn on_roads<R: Rng + ?Sized>(
        params: FilterParams,
        world: &World,
        region: Option<(Enu2, f64)>,
        rng: &mut R,
    ) -> Self {
        let mut pf = Self::new(params, world.workspace_enu, rng);
        pf.spread_on_roads(world, region, rng);
        pf
    }

    /// Starts over on the roads within `region` (see [`Self::on_roads`]); where no road
    /// lies in the region, on the whole network; without roads, over the workspace.
    pub fn spread_on_roads<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        region: Option<(Enu2, f64)>,
        rng: &mut R,
    ) {
        let speeds = 0.0..=self.params.init_speed_max_mps;
        self.spread_on_roads_at(world, region, speeds, rng);
    }

    /// [`Self::spread_on_roads`] with speeds drawn from `speeds_mps`.
    pub fn spread_on_roads_at<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        region: Option<(Enu2, f64)>,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) {
        let roads = world.road.roads_within_or_all(region);
        self.spread_on_pieces(&roads, speeds_mps, rng);
    }

    /// Starts over on `roads` (drawn by weighted length, moving along their direction at
    /// speeds from `speeds_mps`); over the workspace when they are empty.
    pub fn spread_on_pieces<R: Rng + ?Sized>(
        &mut self,
        roads: &RoadPieces,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) {
        if roads.length_m() <= 0.0 {
            self.redraw_uniform(rng);
            return;
        }
        for i in 0..self.weights.len() {
            self.seed_on_roads(i, roads, speeds_mps.clone(), rng);
        }
        let n = self.weights.len();
        self.weights.fill(1.0 / n as f64);
    }

    /// Starts over with every particle on a route the target can have driven from `start`
    /// (see [`RouteStart`]) for `driven_s` seconds at one speed drawn from
    /// `speeds_mps`, its turns drawn by their probabilities ([`crate::world::road::RoadNetwork::drive`]). A
    /// particle's history is its route's last positions; its weight is the likelihood along
    /// its route of the empty frames `looked` (seconds after the start, ascending, and where
    /// the camera was): `miss_probability` for each frame that would have seen it there.
    /// So what the camera has ruled out since the start stays ruled out, where spreading
    /// over the reachable roads would give it back its share. False (nothing changed)
    /// without roads.
    pub fn spread_along_routes<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        start: RouteStart<'_>,
        speeds_mps: std::ops::RangeInclusive<f64>,
        driven_s: f64,
        looked: &[(f64, Enu2)],
        rng: &mut R,
    ) -> bool {
        let n = self.weights.len();
        let k = self.params.history_len;
        if n == 0 || k == 0 || world.road.nodes.is_empty() {
            return false;
        }
        let dt = self.params.dt_s;
        // The frames' times, then the history's (oldest first), driven in time order.
        let mut times: Vec<f64> = looked.iter().map(|(t, _)| t.max(0.0)).collect();
        times.extend((0..k).map(|j| (driven_s - (k - 1 - j) as f64 * dt).max(0.0)));
        let mut order: Vec<usize> = (0..times.len()).collect();
        order.sort_by(|a, b| times[*a].total_cmp(&times[*b]));
        let ln_miss = self.params.miss_probability.ln();
        let mut log_w = vec![0.0; n];
        let mut at = vec![Enu2::zeros(); times.len()];
        for (i, lw) in log_w.iter_mut().enumerate() {
            let (from, heading) = match start {
                // Where the target was is the measurement give or take its noise: each
                // route starts at its own draw. From the measurement itself, every route
                // shared one start, and a car last measured a few metres short of an
                // occlusion left every route the first empty frame would have seen
                // refuted at 1e-6 except the fastest few: the re-spread put all the weight
                // on ~1 % of the routes, at the top speed, and ran ahead of the car
                // (BENCHMARKS "Field scale, part 22").
                RouteStart::At(z, heading) => (z + world.measurement.noise.sample(rng), heading),
                RouteStart::On(roads) => match roads.sample(rng) {
                    Some((p, dir)) => (p, Some(dir)),
                    None => return false,
                },
            };
            let speed = rng.gen_range(speeds_mps.clone());
            let distances: Vec<f64> = order.iter().map(|&j| speed * times[j]).collect();
            let Some(route) = world.road.drive(&from, heading, &distances, rng) else {
                return false;
            };
            for (&j, (p, _)) in order.iter().zip(route) {
                at[j] = p;
            }
            let seen = looked
                .iter()
                .zip(&at)
                .filter(|((_, camera), p)| world.is_wholly_visible(camera, p))
                .count();
            *lw = if seen == 0 {
                0.0
            } else {
                seen as f64 * ln_miss
            };
            let tr = self.histories.track_mut(i);
            for (j, p) in at[looked.len()..].iter().enumerate() {
                tr[2 * j] = p.x;
                tr[2 * j + 1] = p.y;
            }
        }
        let max = log_w.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        if max.is_finite() {
            for (w, lw) in self.weights.iter_mut().zip(&log_w) {
                *w = (lw - max).exp();
            }
        } else {
            self.weights.fill(1.0);
        }
        if !self.normalize() {
            self.weights.fill(1.0 / n as f64);
        }
        true
    }

    /// Re-routes in place every particle within a step of a junction: a constant-velocity
    /// particle drives straight on through a junction, off the road, where the road
    /// constraint kills it; so each one whose next step leaves its road is put on one of the
    /// roads it can take within that step (the turns drawn by their probabilities, never a
    /// U-turn back the way it came unless there is no other way on), keeping its speed
    /// and its weight. The belief then goes through a junction the way the target can,
    /// every branch in proportion (before session 23, 2 % of the particles per step became
    /// road-following clones: a corner kept ~2 % of the weight that reached it, the belief
    /// slowed from 14 to 5-8 m/s at corners and slow clusters sat at the roads' ends;
    /// BENCHMARKS.md "Field scale, part 21"). A particle whose step stays on its road (one
    /// piece ahead, or two with the straight-on step within half a road sigma of a road:
    /// a bend it follows anyway) is left alone. Nothing without roads.
    pub fn reroute_at_junctions<R: Rng + ?Sized>(&mut self, world: &World, rng: &mut R) {
        let dt = self.params.dt_s;
        let on_road_m = 0.5 * self.params.road_sigma_m.unwrap_or(0.0);
        for i in 0..self.weights.len() {
            road_following::reroute_track(&mut self.histories, i, world, dt, on_road_m, rng);
        }
    }

    /// An index drawn with probability proportional to its weight.
    fn draw_by_weight<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        let total: f64 = self.weights.iter().sum();
        let mut u = rng.gen_range(0.0..total.max(f64::MIN_POSITIVE));
        for (i, w) in self.weights.iter().enumerate() {
            if u < *w {
                return i;
            }
            u -= w;
        }
        self.weights.len() - 1
    }

    /// Weighted mean velocity, world ENU, m/s: each particle's motion over its last (up to)
    /// three filter periods, which averages out most of the process noise of single steps.
    pub fn mean_velocity(&self) -> Enu2 {
        let k = self.params.history_len;
        if k < 2 {
            return Enu2::zeros();
        }
        let span = (k - 1).min(3);
        let mut v = Enu2::zeros();
        for (i, w) in self.weights.iter().enumerate() {
            v += (self.histories.at(i, k - 1) - self.histories.at(i, k - 1 - span)) * *w;
        }
        v / (span as f64 * self.params.dt_s)
    }

    /// Replaces `count` particles drawn at random with new ones on the roads within
    /// `region` (see [`Self::on_roads`]), each given the mean weight: fresh hypotheses where
    /// the target can have gone, that the next frames confirm or rule out (sensor resetting,
    /// as in augmented Monte Carlo localisation).
    pub fn inject_on_roads<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        region: Option<(Enu2, f64)>,
        count: usize,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) {
        if count == 0 {
            return;
        }
        let roads = world.road.roads_within_or_all(region);
        self.inject_on_pieces(&roads, count, speeds_mps, rng);
    }

    /// Replaces `count` particles drawn at random by hypotheses on `roads` (see
    /// [`Self::spread_on_pieces`]) with the mean weight; nothing when `roads` is empty.
    pub fn inject_on_pieces<R: Rng + ?Sized>(
        &mut self,
        roads: &RoadPieces,
        count: usize,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) {
        let n = self.weights.len();
        if count == 0 || roads.length_m() <= 0.0 {
            return;
        }
        let w = 1.0 / n as f64;
        for _ in 0..count.min(n) {
            let i = rng.gen_range(0..n);
            if !self.seed_on_roads(i, roads, speeds_mps.clone(), rng) {
                return;
            }
            self.weights[i] = w;
        }
        self.normalize();
    }

    /// Particle `i` becomes a straight track along one of `roads`, ending at a point drawn
    /// on them, at a speed drawn from `speeds_mps`; false when there is no road.
    fn seed_on_roads<R: Rng + ?Sized>(
        &mut self,
        i: usize,
        roads: &RoadPieces,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) -> bool {
        let dt = self.params.dt_s;
        road_following::straight_track_on_roads(&mut self.histories, i, roads, speeds_mps, dt, rng)
    }

    /// Starts over with no information: on the roads or over the workspace (see
    /// [`FilterParams::redraw_on_roads`]).
    fn redraw<R: Rng + ?Sized>(&mut self, world: &World, rng: &mut R) {
        if self.params.redraw_on_roads {
            self.spread_on_roads(world, None, rng);
        } else {
            self.redraw_uniform(rng);
        }
    }

    /// The parameters.
    pub fn params(&self) -> &FilterParams {
        &self.params
    }

    /// Particle histories.
    pub fn histories(&self) -> &Histories {
        &self.histories
    }

    /// Normalised weights.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Counters over the filter's life.
    pub fn counters(&self) -> FilterCounters {
        self.counters
    }

    /// Newest position of particle `i`, world ENU.
    pub fn particle(&self, i: usize) -> Enu2 {
        self.histories.newest(i)
    }

    /// Newest positions of all particles.
    pub fn particles(&self) -> Vec<Enu2> {
        (0..self.weights.len()).map(|i| self.particle(i)).collect()
    }

    /// Effective sample size 1 / sum w^2.
    pub fn n_eff(&self) -> f64 {
        1.0 / self.weights.iter().map(|w| w * w).sum::<f64>()
    }

    /// Weighted mean of the newest positions (the PFWM goal and the estimate).
    pub fn mean(&self) -> Enu2 {
        let mut m = Enu2::zeros();
        for (i, w) in self.weights.iter().enumerate() {
            m += *w * self.particle(i);
        }
        m
    }

    /// Weighted covariance sum_i w_i (x_i - mu)(x_i - mu)^T of the newest positions.
    ///
    /// The paper's eq. 16 prints an outer product of two sums, which is zero by
    /// construction; this is the intended weighted covariance.
    pub fn covariance(&self) -> Matrix2<f64> {
        let mu = self.mean();
        let mut c = Matrix2::zeros();
        for (i, w) in self.weights.iter().enumerate() {
            let d = self.particle(i) - mu;
            c += *w * d * d.transpose();
        }
        c
    }

    /// One filter period: predict with `model`, update with `measurement` (or with negative
    /// information from the footprint of an agent at `agent_enu` when there is none), then
    /// resample as the thresholds say.
    pub fn step<R: Rng + ?Sized>(
        &mut self,
        model: &mut dyn MotionModel,
        measurement: Option<Enu2>,
        agent_enu: &Enu2,
        world: &World,
        rng: &mut R,
    ) -> Result<StepReport, FilterError> {
        self.step_index += 1;
        self.counters.steps += 1;
        let nonfinite = self.predict(model, rng)?;
        if let Some(z) = measurement {
            if self.recent.len() == self.params.history_len {
                self.recent.pop_front();
            }
            self.recent.push_back((self.step_index, z));
        }
        // A model that knows the roads drives its tracks their allowed way already.
        let headings = !model.knows_the_roads();
        self.update(measurement, agent_enu, world, headings);

        let action = if !self.normalize() {
            self.counters.recoveries += 1;
            if measurement.is_some() {
                tracing::warn!(
                    step = self.step_index,
                    "particle weights degenerate (all zero or not finite); re-seeding around the measurements"
                );
                self.reseed_around_measurements(world, headings, rng);
            } else {
                tracing::warn!(
                    step = self.step_index,
                    "particle weights degenerate (all zero or not finite) with no measurement; re-drawing uniformly"
                );
                self.redraw(world, rng);
            }
            ResampleAction::Recovered
        } else {
            ResampleAction::None
        };
        let n_eff = self.n_eff();
        let n = self.params.particles as f64;
        let action = if action != ResampleAction::None {
            action
        } else if self.outside_fraction() > self.params.max_outside_fraction {
            self.counters.uniform_redraws += 1;
            self.redraw(world, rng);
            ResampleAction::UniformRedraw
        } else if n_eff < self.params.resample_threshold * n {
            if measurement.is_some() && n_eff < self.params.reseed_threshold * n {
                self.counters.reseeds += 1;
                self.reseed_around_measurements(world, headings, rng);
                ResampleAction::Reseeded
            } else {
                self.counters.resamples += 1;
                self.resample_multinomial(rng);
                self.roughen(rng);
                ResampleAction::Resampled
            }
        } else {
            ResampleAction::None
        };
        Ok(StepReport {
            measured: measurement.is_some(),
            n_eff,
            action,
            nonfinite_predictions: nonfinite,
        })
    }

    /// One filter period in which the camera did not look (no frame: a frozen or lost
    /// camera): predict only. No negative information is applied and nothing is resampled,
    /// since no image ruled anything out.
    pub fn step_blind<R: Rng + ?Sized>(
        &mut self,
        model: &mut dyn MotionModel,
        rng: &mut R,
    ) -> Result<StepReport, FilterError> {
        self.step_index += 1;
        self.counters.steps += 1;
        let nonfinite = self.predict(model, rng)?;
        Ok(StepReport {
            measured: false,
            n_eff: self.n_eff(),
            action: ResampleAction::None,
            nonfinite_predictions: nonfinite,
        })
    }

    /// Prediction through the model, then N(0, 2Q). Returns how many outputs were rejected.
    fn predict<R: Rng + ?Sized>(
        &mut self,
        model: &mut dyn MotionModel,
        rng: &mut R,
    ) -> Result<usize, FilterError> {
        if let Some(k) = model.required_history_len() {
            if k != self.params.history_len {
                return Err(MotionError::HistoryLength {
                    model: model.name().to_string(),
                    expected: k,
                    got: self.params.history_len,
                }
                .into());
            }
        }
        model.predict(&self.histories, &mut self.predicted)?;
        let mut nonfinite = 0;
        for (i, p) in self.predicted.iter_mut().enumerate() {
            if !(p.x.is_finite() && p.y.is_finite()) {
                nonfinite += 1;
                *p = self.histories.newest(i);
            }
            *p += self.params.process_noise.sample(rng);
        }
        if nonfinite > 0 {
            self.counters.nonfinite_predictions += nonfinite as u64;
            tracing::warn!(
                model = model.name(),
                count = nonfinite,
                "motion model returned non-finite predictions; those particles held their last position"
            );
        }
        self.histories.push(&self.predicted);
        Ok(nonfinite)
    }

    /// The distance the road constraint weighs particle `i` by: to the nearest road, or,
    /// with `heading` (steps, noise) and for a track that clearly heads somewhere (its last
    /// `steps` steps longer than twice the process noise's random walk over them), to the
    /// nearest road it may drive that way, at most [`WRONG_WAY_SIGMAS`] road sigmas farther
    /// than the nearest road. An undirected distance keeps alive a constant-velocity track
    /// that drives on through a junction along a one-way road the wrong way (field-eight's
    /// crossing: every straight-on track ran up the one-way road in, and the belief never
    /// left it).
    fn road_distance(
        &self,
        i: usize,
        world: &World,
        sigma: f64,
        heading: Option<(usize, f64)>,
    ) -> f64 {
        let p = self.histories.newest(i);
        let Some((steps, noise_m)) = heading else {
            return world.road.distance_to_roads(&p);
        };
        let moved = p - self.histories.at(i, self.params.history_len - 1 - steps);
        // A NaN step (never expected: predictions are checked) reads as no heading.
        let heads_somewhere = moved.norm() > 2.0 * noise_m;
        if !heads_somewhere {
            return world.road.distance_to_roads(&p);
        }
        let (any, along) = world.road.distances_to_roads(&p, &moved.normalize());
        along.min(any + WRONG_WAY_SIGMAS * sigma)
    }

    /// The steps a track's heading is read over and the process noise's random walk over
    /// them (m), when headings are read and the history is long enough.
    fn heading_check(&self, headings: bool) -> Option<(usize, f64)> {
        let steps = HEADING_STEPS.min(self.params.history_len.saturating_sub(1));
        if !headings || steps == 0 {
            return None;
        }
        // The per-step noise is N(0, 2Q) (`process_noise`): a random walk over the steps.
        let per_step_m2 = self.params.process_noise.cov.symmetric_eigenvalues().max();
        Some((steps, (per_step_m2 * steps as f64).sqrt()))
    }

    /// Weighs the predicted particles: the road constraint (with the tracks' headings
    /// when `headings`, see [`Self::road_distance`]), then the measurement or its absence.
    fn update(
        &mut self,
        measurement: Option<Enu2>,
        agent_enu: &Enu2,
        world: &World,
        headings: bool,
    ) {
        if let Some(sigma) = self.params.road_sigma_m {
            let k = -0.5 / (sigma * sigma);
            let heading = self.heading_check(headings);
            for i in 0..self.weights.len() {
                let d = self.road_distance(i, world, sigma, heading);
                self.weights[i] *= (k * d * d).exp();
            }
        }
        match measurement {
            Some(z) => {
                // Log-domain with the maximum subtracted: a measurement far from every
                // particle must not underflow all weights to zero.
                let lls: Vec<f64> = (0..self.weights.len())
                    .map(|i| {
                        world
                            .measurement
                            .log_likelihood(&z, &self.histories.newest(i))
                    })
                    .collect();
                let max = lls.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                for (w, ll) in self.weights.iter_mut().zip(&lls) {
                    *w *= (ll - max).exp();
                }
            }
            None => {
                // Negative information: "not seen there" lowers the mass inside the view.
                // The paper applies it over the whole footprint; here only where the whole
                // tag would be in the image and clear of occlusions (the detector misses
                // a tag cut by the edge, and a miss there must not erase the truth).
                for i in 0..self.weights.len() {
                    if world.is_wholly_visible(agent_enu, &self.histories.newest(i)) {
                        self.weights[i] *= self.params.miss_probability;
                    }
                }
            }
        }
    }

    /// Normalises the weights; false when they cannot be (all zero, or not finite).
    fn normalize(&mut self) -> bool {
        let s: f64 = self.weights.iter().sum();
        if !(s.is_finite() && s > 0.0) || self.weights.iter().any(|w| !w.is_finite() || *w < 0.0) {
            return false;
        }
        let inv = 1.0 / s;
        self.weights.iter_mut().for_each(|w| *w *= inv);
        true
    }

    fn outside_fraction(&self) -> f64 {
        let n = self.weights.len();
        let outside = (0..n)
            .filter(|&i| !self.workspace_enu.contains(&self.histories.newest(i)))
            .count();
        outside as f64 / n as f64
    }

    /// Multinomial resampling in O(N): sorted uniforms from normalised exponential spacings,
    /// walked against the cumulative weights. Whole histories are copied; weights reset.
    fn resample_multinomial<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let n = self.weights.len();
        // u_(k) = S_k / S_{n+1} with S the partial sums of n+1 Exp(1) draws are the order
        // statistics of n uniforms.
        let mut spacings: Vec<f64> = (0..=n).map(|_| Exp1.sample(rng)).collect();
        let total: f64 = spacings.iter().sum();
        let mut acc = 0.0;
        for s in spacings.iter_mut() {
            acc += *s;
            *s = acc / total;
        }
        self.indices.clear();
        let mut cum = self.weights[0];
        let mut j = 0;
        for u in spacings.iter().take(n) {
            while *u > cum && j + 1 < n {
                j += 1;
                cum += self.weights[j];
            }
            self.indices.push(j);
        }
        self.histories
            .gather_into(&self.indices, &mut self.resampled);
        std::mem::swap(&mut self.histories, &mut self.resampled);
        self.weights.fill(1.0 / n as f64);
    }

    /// Gaussian jitter with sigma = c x per-axis spread x N^(-1/3); the whole track moves so
    /// the particle keeps the velocity its history encodes.
    fn roughen<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let n = self.weights.len();
        if self.params.roughening == 0.0 || n < 2 {
            return;
        }
        let (mut lo, mut hi) = (Enu2::repeat(f64::INFINITY), Enu2::repeat(f64::NEG_INFINITY));
        for i in 0..n {
            let p = self.histories.newest(i);
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
        let k = self.params.roughening * (n as f64).powf(-1.0 / 3.0);
        let mut sigma = (hi - lo) * k;
        if let Some(road) = self.params.road_sigma_m {
            // A cloud spread along a long road would get jitter across it as large as its
            // length allows, which the road constraint then punishes on the roads that run
            // across the larger spread: keep the jitter within the road's width.
            sigma = sigma.map(|s| s.min(0.5 * road));
        }
        for i in 0..n {
            let jitter = Enu2::new(
                sigma.x * rng.sample::<f64, _>(StandardNormal),
                sigma.y * rng.sample::<f64, _>(StandardNormal),
            );
            self.histories.translate(i, &jitter);
        }
    }

    /// Every particle, every history slot: a recent measurement + N(0, R), equal weights.
    ///
    /// Slot t of the history takes the newest measurement at or before that step within
    /// the window (the oldest one for earlier slots), so the seeded tracks follow what was
    /// actually seen. With one measurement in the window (the target has just come back
    /// into view) every slot would take it and every track would stand still: a car that
    /// drives out from under a bridge at 14 m/s was followed by a belief at rest, slow
    /// hypotheses under the bridge the camera cannot refute took the weight, and the car
    /// was lost for good (field-ring, BENCHMARKS.md "Field scale, part 21"). So, with
    /// `keep_velocity` (a motion model that does not know the roads: constant velocity, whose
    /// state the track's velocity is), each track through one measurement moves at the
    /// velocity of a particle drawn by weight, the prediction's own belief of how the target
    /// moves. The DMMN reads its motion from the history and the roads it learned; there the
    /// change measured neutral (lab closed loop, 16 seeds: +0.9 points, the config's seed
    /// -6.7) and it is left as it was.
    fn reseed_around_measurements<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        keep_velocity: bool,
        rng: &mut R,
    ) {
        let k = self.params.history_len;
        let n = self.weights.len();
        let now = self.step_index;
        let window_start = now.saturating_sub(k as u64 - 1);
        let in_window: Vec<(u64, Enu2)> = self
            .recent
            .iter()
            .filter(|(s, _)| *s >= window_start)
            .cloned()
            .collect();
        let Some(&(_, oldest)) = in_window.first() else {
            self.redraw(world, rng);
            return;
        };
        let slot_centre: Vec<Enu2> = (0..k)
            .map(|t| {
                // Slots before the filter's first step (a re-seed within its first k
                // steps) take the oldest measurement; this used to wrap around in u64 and
                // took the newest.
                (now + t as u64 + 1)
                    .checked_sub(k as u64)
                    .and_then(|step| in_window.iter().rev().find(|(s, _)| *s <= step))
                    .map(|(_, z)| *z)
                    .unwrap_or(oldest)
            })
            .collect();
        let dt = self.params.dt_s;
        let velocities = if keep_velocity && in_window.len() < 2 {
            self.velocities_drawn_by_weight(rng)
        } else {
            vec![Enu2::zeros(); n]
        };
        for (i, v) in velocities.iter().enumerate() {
            let tr = self.histories.track_mut(i);
            for (t, c) in slot_centre.iter().enumerate() {
                let p = world.measurement.measure(c, rng) - v * ((k - 1 - t) as f64 * dt);
                tr[2 * t] = p.x;
                tr[2 * t + 1] = p.y;
            }
        }
        self.weights.fill(1.0 / n as f64);
    }

    /// One velocity per particle (world ENU, m/s), each a particle's mean velocity over its
    /// history, the particle drawn by weight; each particle's own where the weights are
    /// degenerate (all zero or not finite: a recovery).
    fn velocities_drawn_by_weight<R: Rng + ?Sized>(&self, rng: &mut R) -> Vec<Enu2> {
        let by_weight =
            self.weights.iter().all(|w| w.is_finite()) && self.weights.iter().sum::<f64>() > 0.0;
        (0..self.weights.len())
            .map(|i| {
                let j = if by_weight {
                    self.draw_by_weight(rng)
                } else {
                    i
                };
                self.track_velocity(j)
            })
            .collect()
    }

    /// Track `i`'s mean velocity over its whole history, world ENU, m/s; zero when not
    /// finite or when the history holds one position.
    fn track_velocity(&self, i: usize) -> Enu2 {
        road_following::track_velocity(&self.histories, i, self.params.dt_s)
    }

    /// Uniform positions over the workspace, each with a straight track at a speed drawn
    /// from [0, init_speed_max] and a uniform heading; equal weights.
    fn redraw_uniform<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let ws = self.workspace_enu;
        let k = self.params.history_len;
        let n = self.weights.len();
        for i in 0..n {
            let p = Enu2::new(
                rng.gen_range(ws.x_min_m..=ws.x_max_m),
                rng.gen_range(ws.y_min_m..=ws.y_max_m),
            );
            let speed = rng.gen_range(0.0..=self.params.init_speed_max_mps);
            let heading = rng.gen_range(0.0..std::f64::consts::TAU);
            let v_step = Enu2::new(heading.cos(), heading.sin()) * speed * self.params.dt_s;
            let tr = self.histories.track_mut(i);
            for t in 0..k {
                let q = p - v_step * (k - 1 - t) as f64;
                tr[2 * t] = q.x;
                tr[2 * t + 1] = q.y;
            }
        }
        self.weights.fill(1.0 / n as f64);
    }

    /// Overwrites weights (tests and replay); they are normalised, and a degenerate set is
    /// refused.
    pub fn set_weights(&mut self, weights: &[f64]) -> bool {
        if weights.len() != self.weights.len() {
            return false;
        }
        let old = self.weights.clone();
        self.weights.copy_from_slice(weights);
        if self.normalize() {
            true
        } else {
            self.weights = old;
            false
        }
    }
}

#[cfg(test)]
mod tests;
