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
use crate::world::camera::View;
use crate::world::geometry::{BoundsEnu, Enu2};
use crate::world::measurement::Gaussian2;
use crate::world::road::RoadPieces;
use crate::world::World;

mod resample;
mod spread;

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
    /// information from the footprint of `view` when there is none), then
    /// resample as the thresholds say.
    pub fn step<R: Rng + ?Sized>(
        &mut self,
        model: &mut dyn MotionModel,
        measurement: Option<Enu2>,
        view: &View,
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
        self.update(measurement, view, world, headings);

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
    fn update(&mut self, measurement: Option<Enu2>, view: &View, world: &World, headings: bool) {
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
                    if world.is_wholly_visible(view, &self.histories.newest(i)) {
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
