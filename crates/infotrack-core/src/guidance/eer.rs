//! Expected entropy reduction (the paper's eqs. 10, 11 and 13) and the waypoint that
//! maximises it (eq. 14).
//!
//! One planning cycle:
//! 1. N_H particles are taken from the filter (all of them, with their weights, when
//!    N_H = N; otherwise drawn uniformly with replacement, keeping their weights).
//! 2. Each is propagated K filter steps through the motion model with process noise:
//!    x^_j. Each yields N_M simulated measurements z_jm = x^_j + N(0, R).
//! 3. For a candidate waypoint c, a simulated measurement is received only if its particle
//!    lies inside the footprint of an agent at c and outside every occlusion (the paper's
//!    intent; the authors' code tested z_j against a footprint built around z_j, which
//!    always passes; through the detector, the whole tag: `World::is_wholly_visible`,
//!    the filter's model of the camera). A received z_jm gives the eq. 10 entropy;
//!    otherwise the posterior is the missed-detection one, whose likelihood is p_miss for
//!    particles in view from c and 1 elsewhere (negative information; with p_miss = 1
//!    this is exactly eq. 11).
//! 4. EER(c) = H_now - sum_jm alpha_jm H_jm(c), with alpha_jm proportional to
//!    w_j p(z_jm | x^_j): eq. 13's weighting, normalised so the weights form an
//!    expectation.
//!
//! Interpretation, documented: the transition density p(x^_i | x_j) inside the entropy
//! formulas is a Gaussian with covariance `guidance.entropy_kernel_cov_m2` (Q, as in the
//! authors' code) centred on the propagated particle x^_j, i.e. the K-step transition of
//! particle j approximated at its own propagated position. H_now uses the same kernel on
//! the current particles.
//!
//! Field-scale extension, documented where it departs from the paper ([`intercepts`],
//! `guidance.intercept_within_s`, off unless a config sets it): once the target has been
//! seen, a predicted particle beyond one horizon's reach is a candidate where the agent
//! meets it (never past where it leaves the roads), and EER judges what that candidate sees
//! when the agent gets there.
//!
//! The fast evaluation rests on one observation: the measured-branch entropies do not
//! depend on the candidate (the candidate only decides whether each is received), and the
//! missed-detection entropy depends on the candidate only through sums over the particles
//! in view. So the O(N_H^2) kernel sums are computed once per cycle and each candidate
//! costs O(N_H). [`evaluate_reference`] computes every posterior from scratch for tests.

use rand::Rng;

mod commitment;
mod escape;
pub use commitment::{committed_choice, Centring};
pub use escape::{speed_away_mps, weigh_by_escape, DEFAULT_SEARCH_ESCAPE_FLOOR};

use super::entropy::{entropy_prior, exp_or_zero, log_sum_exp, log_transition_sums};
use super::view_heading::HeadingRule;
use crate::estimation::{road_following, ParticleFilter};
use crate::motion::{Histories, MotionError, MotionModel};
use crate::world::camera::View;
use crate::world::geometry::Enu2;
use crate::world::measurement::Gaussian2;
use crate::world::World;

/// `search_commitment` when a config leaves `guidance.search_commitment` out: the share
/// measured first outdoors (level with the argmax) and then on
/// every world (BENCHMARKS.md); not tuned per world.
pub const DEFAULT_SEARCH_COMMITMENT: f64 = 0.2;

/// `centring_share` when a config leaves `guidance.centring_share` out ([`Centring`]):
/// measured on the seven field worlds and the lab (BENCHMARKS.md);
/// not tuned per world.
pub const DEFAULT_CENTRING_SHARE: f64 = 0.02;

/// EER parameters (the configuration assembles them).
#[derive(Debug, Clone)]
pub struct EerParams {
    /// N_H.
    pub entropy_particles: usize,
    /// N_H while the belief is concentrated ([`belief_is_concentrated`]).
    pub entropy_particles_concentrated: usize,
    /// N_M.
    pub measurements_per_particle: usize,
    /// K.
    pub horizon_steps: usize,
    /// Reachable-candidate grid side.
    pub grid_side: usize,
    /// How far the agent can fly in K filter steps, metres: the half width of a square or
    /// the radius of a disc, as `reach_shape` says.
    pub reach_m: f64,
    /// The shape of the reachable region: the agent's speed limit's.
    pub reach_shape: ReachShape,
    /// Transition kernel of the entropy formulas.
    pub kernel: Gaussian2,
    /// p(no detection | in view).
    pub miss_probability: f64,
    /// Process noise added at each rollout step: N(0, 2Q).
    pub process_noise: Gaussian2,
    /// The filter period, s (one rollout step).
    pub step_s: f64,
    /// Far candidates as intercepts (see [`intercepts`]): a predicted particle beyond the
    /// reachable region becomes the point where the agent, flying at its top speed, meets
    /// it carried on at its own velocity, looked ahead by at most this long after the
    /// horizon; `None` keeps the paper's candidate, the predicted particle itself.
    pub intercept_within_s: Option<f64>,
    /// While searching ([`EerPlanner::set_searching`]), the share of the EER range below the
    /// best within which the candidate nearest the previous waypoint is kept
    /// ([`committed_choice`]); 0: no commitment (then [`Centring`] decides).
    pub search_commitment: f64,
    /// Without a previous waypoint to keep to, the share of the EER range below the best within which the candidate
    /// nearest the belief's predicted mean is taken ([`Centring`]); 0: exact ties only.
    pub centring_share: f64,
    /// While searching from a cue, never having seen the target
    /// ([`EerPlanner::weigh_escape`]), the weight in [0, 1] of a hypothesis that is not
    /// driving away from the agent relative to one driving away at the fastest speed
    /// ([`weigh_by_escape`]); 1: the paper's weights.
    pub search_escape_floor: f64,
}

/// Everything the evaluation needs, after the rollout: pure data.
#[derive(Debug, Clone, Default)]
pub struct EerInputs {
    /// Current positions of the N_H particles (for H_now).
    pub current: Vec<Enu2>,
    /// Their normalised weights.
    pub weights: Vec<f64>,
    /// Their positions after K predicted steps, x^_j.
    pub predicted: Vec<Enu2>,
    /// Simulated measurements, `N_M` per particle: `measurements[j * n_m + m]`.
    pub measurements: Vec<Enu2>,
    /// Expectation weights alpha_jm (sum to 1), same layout.
    pub alpha: Vec<f64>,
    /// N_M.
    pub n_m: usize,
    /// The velocity of each predicted particle over its whole kept track (the rollout's
    /// last K_in positions: one step's difference would be mostly the rollout's process
    /// noise), m/s, world ENU (zero when the track keeps a single position).
    pub velocity: Vec<Enu2>,
}

/// The result of one planning cycle.
#[derive(Debug, Clone)]
pub struct EerDecision {
    /// The chosen waypoint, world ENU, inside the geofence.
    pub waypoint_enu: Enu2,
    /// Its EER.
    pub eer: f64,
    /// Entropy of the current estimate.
    pub h_now: f64,
    /// Number of candidates evaluated (each view of a place counts once).
    pub candidates: usize,
    /// The heading (world ENU yaw, rad) of the chosen candidate's view: where the heading
    /// rule offers more than one view of a place (`informed`), the one to fly.
    pub view_yaw_enu_rad: f64,
}

/// The region the agent can reach within the horizon, as its speed limit shapes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ReachShape {
    /// A square of half width `reach` (a speed limit per axis: the paper's lab agent).
    #[default]
    Square,
    /// A disc of radius `reach` (a limit on the speed's norm: PX4, ArduCopter).
    Disc,
}

impl ReachShape {
    /// The farthest point of the region from its centre, in units of `reach`: a waypoint
    /// beyond it can only be a far predicted particle, not a reachable candidate.
    pub fn farthest_in_reaches(self) -> f64 {
        match self {
            ReachShape::Square => std::f64::consts::SQRT_2,
            ReachShape::Disc => 1.0,
        }
    }
}

/// Candidate waypoints: the predicted particles plus a grid of the points reachable within
/// K steps around the agent, all clamped to the geofence. For a disc, the grid's points
/// outside it are moved onto its rim along their direction, so the rim's directions stay
/// candidates.
pub fn candidates(
    inputs: &EerInputs,
    agent_enu: &Enu2,
    reach_m: f64,
    reach_shape: ReachShape,
    grid_side: usize,
    world: &World,
) -> Vec<Enu2> {
    let mut out = Vec::with_capacity(inputs.predicted.len() + grid_side * grid_side);
    out.extend(
        inputs
            .predicted
            .iter()
            .map(|p| world.workspace_enu.clamp(p)),
    );
    let step = if grid_side > 1 {
        2.0 * reach_m / (grid_side - 1) as f64
    } else {
        0.0
    };
    let origin = if grid_side > 1 {
        agent_enu - Enu2::repeat(reach_m)
    } else {
        *agent_enu
    };
    for iy in 0..grid_side {
        for ix in 0..grid_side {
            let mut offset = origin + Enu2::new(ix as f64 * step, iy as f64 * step) - agent_enu;
            if reach_shape == ReachShape::Disc && offset.norm() > reach_m {
                offset *= reach_m / offset.norm();
            }
            out.push(world.workspace_enu.clamp(&(agent_enu + offset)));
        }
    }
    out
}

/// How an agent at `agent_enu` flying at `speed_mps` meets a far predicted particle: the
/// time after the horizon's end (`horizon_s`) at which it reaches the particle carried on
/// at its velocity, at most `within_s`. The smallest `lead >= 0` with
/// `|p + v lead - a| <= speed (horizon + lead)`; `within_s` when the particle outruns the
/// agent.
pub fn intercept_lead_s(
    agent_enu: &Enu2,
    predicted_enu: &Enu2,
    velocity_enu: &Enu2,
    speed_mps: f64,
    horizon_s: f64,
    within_s: f64,
) -> f64 {
    let d = predicted_enu - agent_enu;
    let reach_now = speed_mps * horizon_s;
    if d.norm_squared() <= reach_now * reach_now {
        return 0.0;
    }
    // (v.v - s^2) t^2 + 2 (d.v - s^2 H) t + (d.d - s^2 H^2) = 0: with |v| < s the product
    // of the roots is negative (the constant is positive here), one root is positive.
    let s2 = speed_mps * speed_mps;
    let a = velocity_enu.norm_squared() - s2;
    let b = 2.0 * (d.dot(velocity_enu) - s2 * horizon_s);
    let c = d.norm_squared() - reach_now * reach_now;
    if a >= 0.0 {
        return within_s;
    }
    let lead = (b + (b * b - 4.0 * a * c).sqrt()) / (-2.0 * a);
    if lead.is_finite() {
        lead.clamp(0.0, within_s)
    } else {
        within_s
    }
}

/// Far candidates as intercepts: each predicted particle (candidates `0..N_H`, see
/// [`candidates`]) beyond the reachable region's farthest point is moved to where the agent
/// meets it ([`intercept_lead_s`]), or where it leaves the roads if sooner
/// ([`lead_on_the_roads`]), clamped to the geofence; returns each candidate's lead
/// (zero for the reachable ones), for [`evaluate_fast_led`]. A field-scale extension of
/// the paper's candidate set: there a far predicted particle is where the target will be
/// at the horizon's end, and by the time the agent gets there the target has driven on (a
/// car at 10 m/s, 200 m away, is 130 m further when a 15 m/s drone arrives). The planner
/// uses them only once the target has been seen ([`EerPlanner::use_intercepts`]): the
/// intercepts of a cue's belief, spread both ways along the roads, pull the search back and
/// forth (BENCHMARKS.md).
#[allow(clippy::too_many_arguments)]
pub fn intercepts(
    inputs: &EerInputs,
    candidates: &mut [Enu2],
    agent_enu: &Enu2,
    speed_mps: f64,
    horizon_s: f64,
    farthest_m: f64,
    within_s: f64,
    world: &World,
) -> Vec<f64> {
    let mut leads = vec![0.0; candidates.len()];
    let on_road_m = world.footprint.quarter_view_m();
    for (j, p) in inputs.predicted.iter().enumerate() {
        if (p - agent_enu).norm() <= farthest_m {
            continue;
        }
        let lead = intercept_lead_s(
            agent_enu,
            p,
            &inputs.velocity[j],
            speed_mps,
            horizon_s,
            within_s,
        );
        let lead = lead_on_the_roads(inputs, j, lead, world, on_road_m);
        leads[j] = lead;
        candidates[j] = world.workspace_enu.clamp(&led(inputs, j, lead));
    }
    leads
}

/// Steps in which [`lead_on_the_roads`] follows a particle carried straight on, s.
const LEAD_STEP_S: f64 = 0.5;

/// The longest lead up to `lead_s` over which particle `j`, carried straight on at its
/// velocity, stays on the roads (within `on_road_m` of one: the intercepts pass a quarter of
/// the footprint's smaller side, still in view of a camera looking at the road); `lead_s` in
/// a world without roads. Carried
/// straight on, a track that is about to turn or that drives into a dead end leaves the
/// road, and its intercept lay where no car can be: on field-hill the drone flew 120 m past
/// the spur's dead end while the car turned round in it, and lost it (BENCHMARKS.md). Cut at the road's end, the intercept is where the hypothesis can be
/// last seen on its road.
fn lead_on_the_roads(
    inputs: &EerInputs,
    j: usize,
    lead_s: f64,
    world: &World,
    on_road_m: f64,
) -> f64 {
    if lead_s <= 0.0 || world.road.nodes.is_empty() {
        return lead_s;
    }
    let mut on_road_s = 0.0;
    while on_road_s < lead_s {
        let next_s = (on_road_s + LEAD_STEP_S).min(lead_s);
        if world.road.distance_to_roads(&led(inputs, j, next_s)) > on_road_m {
            break;
        }
        on_road_s = next_s;
    }
    on_road_s
}

/// Entropy of the current estimate (eq. 7 form over the N_H current particles).
fn h_now(inputs: &EerInputs, kernel: &Gaussian2) -> f64 {
    let log_s = log_transition_sums(&inputs.current, &inputs.current, &inputs.weights, kernel);
    entropy_prior(&inputs.weights, &log_s)
}

/// Reusable workspace of the fast evaluation.
#[derive(Debug, Default, Clone)]
pub struct EerScratch {
    log_s: Vec<f64>,
    h_meas: Vec<f64>,
    alpha_h: Vec<f64>,
    alpha_particle: Vec<f64>,
    occluded: Vec<bool>,
    log_w: Vec<f64>,
    buf: Vec<f64>,
}

/// Eq. 10 entropy after measurement `z`, as [`super::entropy::entropy_measured`] computes it, with
/// log-weights precomputed and one exponential per particle.
fn entropy_measured_fast(
    z: &Enu2,
    points: &[Enu2],
    log_w: &[f64],
    log_s: &[f64],
    noise: &Gaussian2,
    buf: &mut [f64],
) -> f64 {
    let mut max = f64::NEG_INFINITY;
    for ((b, p), lw) in buf.iter_mut().zip(points).zip(log_w) {
        *b = noise.log_pdf(&(z - p)) + lw;
        max = max.max(*b);
    }
    let (mut sum, mut acc) = (0.0, 0.0);
    for ((b, lw), ls) in buf.iter().zip(log_w).zip(log_s) {
        let e = exp_or_zero(b - max);
        if e > 0.0 {
            sum += e;
            // log l_i + log S_i, with log l_i = b - log w_i.
            acc += e * (b - lw + ls);
        }
    }
    max + sum.ln() - acc / sum
}

/// The views of candidates seen facing north (the paper's constant heading).
pub fn north_views(candidates: &[Enu2]) -> Vec<View> {
    candidates.iter().map(|c| View::north(*c)).collect()
}

/// EER of every candidate, fast: O(N_H^2 N_M) once, then O(N_H) per candidate; each
/// candidate seen facing north. Returns `(h_now, eer per candidate)`.
pub fn evaluate_fast(
    inputs: &EerInputs,
    candidates: &[Enu2],
    world: &World,
    kernel: &Gaussian2,
    miss_probability: f64,
    scratch: &mut EerScratch,
) -> (f64, Vec<f64>) {
    evaluate_fast_led(
        inputs,
        &north_views(candidates),
        &[],
        world,
        kernel,
        miss_probability,
        scratch,
    )
}

/// Where particle `i` is `lead_s` after the horizon's end, carried on at its velocity.
fn led(inputs: &EerInputs, i: usize, lead_s: f64) -> Enu2 {
    if lead_s > 0.0 {
        inputs.predicted[i] + inputs.velocity[i] * lead_s
    } else {
        inputs.predicted[i]
    }
}

/// Into `scratch`: each measured branch's entropy (independent of the candidate), and per
/// particle the summed probability of its measurements and their probability-weighted
/// entropies; which particles may hide the tag. Needs `scratch.log_s`.
fn measured_branch_entropies(inputs: &EerInputs, world: &World, scratch: &mut EerScratch) {
    let (n, n_m, w) = (inputs.predicted.len(), inputs.n_m, &inputs.weights);
    // Measured-branch entropies: independent of the candidate. One exp per (z, particle)
    // pair: the exponentials of the log-sum-exp are the unnormalised posterior weights.
    scratch.log_w.clear();
    scratch.log_w.extend(w.iter().map(|w| w.ln()));
    scratch.h_meas.clear();
    scratch.alpha_h.clear();
    scratch.alpha_particle.clear();
    scratch.buf.resize(n, 0.0);
    for j in 0..n {
        let mut ap = 0.0;
        let mut ah = 0.0;
        for m in 0..n_m {
            let idx = j * n_m + m;
            let h = entropy_measured_fast(
                &inputs.measurements[idx],
                &inputs.predicted,
                &scratch.log_w,
                &scratch.log_s,
                &world.measurement.noise,
                &mut scratch.buf,
            );
            scratch.h_meas.push(h);
            ap += inputs.alpha[idx];
            ah += inputs.alpha[idx] * h;
        }
        scratch.alpha_particle.push(ap);
        scratch.alpha_h.push(ah);
    }
    scratch.occluded.clear();
    scratch
        .occluded
        .extend(inputs.predicted.iter().map(|p| world.may_hide_the_tag(p)));
}

/// [`evaluate_fast`] with each candidate's view (where it is and which way the image faces
/// there) and a lead per candidate (`leads[c]`, s; empty: all zero): which
/// particles a candidate sees is judged where they will be when the agent gets there,
/// `lead` after the horizon's end ([`intercepts`]). Approximation, documented: the
/// measured-branch entropies and the kernel sums stay those at the horizon's end (a
/// belief carried along at its particles' velocities keeps its shape over the lead).
pub fn evaluate_fast_led(
    inputs: &EerInputs,
    candidates: &[View],
    leads: &[f64],
    world: &World,
    kernel: &Gaussian2,
    miss_probability: f64,
    scratch: &mut EerScratch,
) -> (f64, Vec<f64>) {
    let n = inputs.predicted.len();
    let h0 = h_now(inputs, kernel);
    let w = &inputs.weights;
    scratch.log_s = log_transition_sums(&inputs.predicted, &inputs.predicted, w, kernel);
    measured_branch_entropies(inputs, world, scratch);
    let log_s = &scratch.log_s;

    // Sums over all particles, to get the not-in-view sums by subtraction.
    let w_log_s_all: f64 = w.iter().zip(log_s).map(|(w, s)| w * s).sum();
    let log_miss = miss_probability.ln();
    // In view as the filter models the camera: the whole tag (World::is_wholly_visible).
    let (fp, inset) = (world.footprint, world.detection_margin_m);
    let eer = candidates
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let lead_s = leads.get(k).copied().unwrap_or(0.0);
            let (mut w_vis, mut wls_vis, mut p_vis, mut a_h_vis) = (0.0, 0.0, 0.0, 0.0);
            for i in 0..n {
                let in_view = if lead_s > 0.0 {
                    world.is_wholly_visible(c, &led(inputs, i, lead_s))
                } else {
                    !scratch.occluded[i] && fp.contains_inset(c, &inputs.predicted[i], inset)
                };
                if in_view {
                    w_vis += w[i];
                    wls_vis += w[i] * log_s[i];
                    p_vis += scratch.alpha_particle[i];
                    a_h_vis += scratch.alpha_h[i];
                }
            }
            // Missed detection from c: l_i = p_miss in view, 1 elsewhere.
            let w_out = (1.0 - w_vis).max(0.0);
            let z = w_out + miss_probability * w_vis;
            let h_miss = z.ln()
                - ((w_log_s_all - wls_vis) + miss_probability * (w_vis * log_miss + wls_vis)) / z;
            let expected = a_h_vis + (1.0 - p_vis).max(0.0) * h_miss;
            h0 - expected
        })
        .collect();
    (h0, eer)
}

/// EER of every candidate computed from scratch, the obviously-correct way: for each
/// candidate and each simulated measurement, build that posterior's likelihood vector and
/// evaluate the entropy formula with its double sum. O(C N_H N_M N_H^2): tests only.
pub fn evaluate_reference(
    inputs: &EerInputs,
    candidates: &[Enu2],
    world: &World,
    kernel: &Gaussian2,
    miss_probability: f64,
) -> (f64, Vec<f64>) {
    evaluate_reference_led(
        inputs,
        &north_views(candidates),
        &[],
        world,
        kernel,
        miss_probability,
    )
}

/// [`evaluate_reference`] with each candidate's view and lead, as [`evaluate_fast_led`]
/// takes them: tests only.
pub fn evaluate_reference_led(
    inputs: &EerInputs,
    candidates: &[View],
    leads: &[f64],
    world: &World,
    kernel: &Gaussian2,
    miss_probability: f64,
) -> (f64, Vec<f64>) {
    let n = inputs.predicted.len();
    let w = &inputs.weights;
    let trans = |x: &Enu2, c: &Enu2| kernel.pdf(&(x - c));
    let h0 = -(0..n)
        .map(|i| {
            let s: f64 = (0..n)
                .map(|j| trans(&inputs.current[i], &inputs.current[j]) * w[j])
                .sum();
            w[i] * s.ln()
        })
        .sum::<f64>();
    let eer = candidates
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let lead_s = leads.get(k).copied().unwrap_or(0.0);
            // The filter's model of the camera: through the detector, a tag is found (and
            // a miss is evidence) only when the whole tag is in view.
            let visible = |c: &View, i: usize| world.is_wholly_visible(c, &led(inputs, i, lead_s));
            let mut expected = 0.0;
            for j in 0..n {
                for m in 0..inputs.n_m {
                    let idx = j * inputs.n_m + m;
                    let lik: Vec<f64> = if visible(c, j) {
                        let z = inputs.measurements[idx];
                        (0..n)
                            .map(|i| world.measurement.noise.pdf(&(z - inputs.predicted[i])))
                            .collect()
                    } else {
                        (0..n)
                            .map(|i| if visible(c, i) { miss_probability } else { 1.0 })
                            .collect()
                    };
                    let norm: f64 = (0..n).map(|i| lik[i] * w[i]).sum();
                    let mut h = norm.ln();
                    for i in 0..n {
                        let s: f64 = (0..n)
                            .map(|l| trans(&inputs.predicted[i], &inputs.predicted[l]) * w[l])
                            .sum();
                        let post = lik[i] * w[i] / norm;
                        if post > 0.0 {
                            h -= post * (lik[i] * s).ln();
                        }
                    }
                    expected += inputs.alpha[idx] * h;
                }
            }
            h0 - expected
        })
        .collect();
    (h0, eer)
}

/// Whether the filter's belief fits in one view: its weighted standard deviation along each
/// world axis at most a quarter of the footprint's width along it (+-2 sigma in view at
/// once). Then EER's choice is where to put the footprint over one compact cluster, which
/// fewer hypotheses can show at a fraction of the cost; a spread or split belief (searching,
/// after an occluded junction) keeps `entropy_particles`, where every hypothesis paid
/// (BENCHMARKS.md).
pub fn belief_is_concentrated(pf: &ParticleFilter, world: &World) -> bool {
    let cov = pf.covariance();
    let fp = &world.footprint;
    // A NaN variance compares false: not concentrated, every hypothesis kept.
    cov[(0, 0)].sqrt() <= 0.5 * fp.half_width_m && cov[(1, 1)].sqrt() <= 0.5 * fp.half_height_m
}

/// The fewest hypotheses EER weighs when its effort is lowered for a slow computer.
pub const MIN_DEGRADED_HYPOTHESES: usize = 50;

/// The EER guidance law: owns its scratch buffers across cycles.
#[derive(Debug, Clone)]
pub struct EerPlanner {
    params: EerParams,
    indices: Vec<usize>,
    rollout: Histories,
    next: Vec<Enu2>,
    inputs: EerInputs,
    scratch: EerScratch,
    intercepts_on: bool,
    rollout_on_roads_m: Option<f64>,
    searching: bool,
    last_waypoint_enu: Option<Enu2>,
    escape_weighting: bool,
    /// The target's velocity, world ENU, m/s, while the vehicle rides along with it (the
    /// belief concentrated under the view): the candidates' views turn as the command will.
    over_target_velocity_enu: Option<Enu2>,
    /// The hypotheses weighed are N_H over this (1: all; the tracker raises it when
    /// decisions overrun their compute budget).
    effort_divisor: usize,
}

impl EerPlanner {
    /// Whether far candidates are intercepts (when `intercept_within_s` is set): the tracker
    /// turns them on once the target has been seen, so that the search from the cue stays
    /// the paper's.
    pub fn use_intercepts(&mut self, on: bool) {
        self.intercepts_on = on;
    }

    /// Whether the rollout's tracks are re-routed at junctions at each step
    /// ([`road_following::reroute_track`], with `on_road_m` its tolerance for a bend), as the
    /// filter re-routes its constant-velocity belief: the tracker turns it on when the filter
    /// does, so that EER plans with the prediction the filter makes. `None`: the motion
    /// model's rollout alone (the paper's).
    pub fn reroute_rollout(&mut self, on_road_m: Option<f64>) {
        self.rollout_on_roads_m = on_road_m;
    }

    /// Whether the agent is searching (the tracker decides: until the target is first seen).
    /// The plan then keeps to its previous
    /// waypoint's mode unless another is clearly better ([`committed_choice`],
    /// `search_commitment`); otherwise the paper's argmax.
    pub fn set_searching(&mut self, on: bool) {
        self.searching = on;
    }

    /// Whether the agent is searching ([`Self::set_searching`]).
    pub fn is_searching(&self) -> bool {
        self.searching
    }

    /// Whether the plan weighs the hypotheses by how fast they drive away from the agent
    /// ([`weigh_by_escape`], `search_escape_floor`): the tracker turns it on while the search
    /// from a cue has not yet seen the target.
    pub fn weigh_escape(&mut self, on: bool) {
        self.escape_weighting = on;
    }

    /// A planner with these parameters.
    pub fn new(params: EerParams) -> Self {
        Self {
            params,
            indices: Vec::new(),
            rollout: Histories::new(0, 1),
            next: Vec::new(),
            inputs: EerInputs::default(),
            scratch: EerScratch::default(),
            intercepts_on: true,
            rollout_on_roads_m: None,
            searching: false,
            last_waypoint_enu: None,
            escape_weighting: false,
            over_target_velocity_enu: None,
            effort_divisor: 1,
        }
    }

    /// Weighs N_H / `divisor` hypotheses (never fewer than [`MIN_DEGRADED_HYPOTHESES`] or N_H
    /// itself): fewer on a computer too slow for the configured count.
    pub fn set_effort_divisor(&mut self, divisor: usize) {
        self.effort_divisor = divisor.max(1);
    }

    /// Whether the vehicle rides along with the target at this velocity (world ENU, m/s;
    /// `None`: it does not): the heading rule then turns every candidate's view for it.
    pub fn ride_along(&mut self, over_target_velocity_enu: Option<Enu2>) {
        self.over_target_velocity_enu = over_target_velocity_enu;
    }

    /// The parameters.
    pub fn params(&self) -> &EerParams {
        &self.params
    }

    /// Steps 1 and 2 of the cycle: subset, K-step rollout through `model`, simulated
    /// measurements. The motion-model calls all happen here.
    pub fn prepare<R: Rng + ?Sized>(
        &mut self,
        pf: &ParticleFilter,
        model: &mut dyn MotionModel,
        world: &World,
        rng: &mut R,
    ) -> Result<&EerInputs, MotionError> {
        let n = pf.weights().len();
        let (all, concentrated) = (
            self.params.entropy_particles,
            self.params.entropy_particles_concentrated,
        );
        // The belief's covariance is only worth its pass over the particles when the two
        // counts differ (unset in the config, they are equal).
        let n_h = if concentrated != all && belief_is_concentrated(pf, world) {
            concentrated
        } else {
            all
        };
        let n_h = (n_h / self.effort_divisor).max(n_h.min(MIN_DEGRADED_HYPOTHESES));
        self.indices.clear();
        if n_h >= n {
            self.indices.extend(0..n);
        } else {
            self.indices.extend((0..n_h).map(|_| rng.gen_range(0..n)));
        }
        let inp = &mut self.inputs;
        inp.current.clear();
        inp.weights.clear();
        for &i in &self.indices {
            inp.current.push(pf.particle(i));
            inp.weights.push(pf.weights()[i]);
        }
        let total: f64 = inp.weights.iter().sum();
        inp.weights.iter_mut().for_each(|w| *w /= total);

        pf.histories().gather_into(&self.indices, &mut self.rollout);
        self.next.resize(self.indices.len(), Enu2::zeros());
        for _ in 0..self.params.horizon_steps {
            if let Some(on_road_m) = self.rollout_on_roads_m {
                let dt = self.params.step_s;
                for i in 0..self.indices.len() {
                    road_following::reroute_track(&mut self.rollout, i, world, dt, on_road_m, rng);
                }
            }
            model.predict(&self.rollout, &mut self.next)?;
            for (i, p) in self.next.iter_mut().enumerate() {
                if !(p.x.is_finite() && p.y.is_finite()) {
                    *p = self.rollout.newest(i);
                }
                *p += self.params.process_noise.sample(rng);
            }
            self.rollout.push(&self.next);
        }
        inp.predicted.clear();
        inp.predicted
            .extend((0..self.indices.len()).map(|i| self.rollout.newest(i)));
        let step_s = self.params.step_s;
        inp.velocity.clear();
        inp.velocity.extend(
            (0..self.indices.len())
                .map(|i| road_following::track_velocity(&self.rollout, i, step_s)),
        );

        let n_m = self.params.measurements_per_particle;
        inp.n_m = n_m;
        inp.measurements.clear();
        let mut log_alpha = Vec::with_capacity(inp.predicted.len() * n_m);
        for (x, w) in inp.predicted.iter().zip(&inp.weights) {
            for _ in 0..n_m {
                let z = world.measurement.measure(x, rng);
                log_alpha.push(w.ln() + world.measurement.log_likelihood(&z, x));
                inp.measurements.push(z);
            }
        }
        let lse = log_sum_exp(log_alpha.iter().cloned());
        inp.alpha.clear();
        inp.alpha
            .extend(log_alpha.iter().map(|a| exp_or_zero(a - lse)));
        Ok(&self.inputs)
    }

    /// Steps 3 and 4: candidates, EER of each (seen from where the vehicle will be, facing
    /// the way `heading` turns it there), argmax. No motion-model calls.
    pub fn decide(&mut self, agent: &View, heading: &HeadingRule, world: &World) -> EerDecision {
        let agent_enu = &agent.centre_enu;
        if self.escape_weighting {
            weigh_by_escape(&mut self.inputs, agent_enu, self.params.search_escape_floor);
        }
        let p = &self.params;
        let mut cands = candidates(
            &self.inputs,
            agent_enu,
            p.reach_m,
            p.reach_shape,
            p.grid_side,
            world,
        );
        let horizon_s = p.horizon_steps as f64 * p.step_s;
        let leads = match p.intercept_within_s {
            Some(within_s) if horizon_s > 0.0 && self.intercepts_on => intercepts(
                &self.inputs,
                &mut cands,
                agent_enu,
                p.reach_m / horizon_s,
                horizon_s,
                p.reach_shape.farthest_in_reaches() * p.reach_m,
                within_s,
                world,
            ),
            _ => Vec::new(),
        };
        // Every view of every place, each with its place and its lead.
        let over_target = self.over_target_velocity_enu;
        let (mut places, mut views, mut view_leads) = (Vec::new(), Vec::new(), Vec::new());
        for (k, c) in cands.iter().enumerate() {
            for view in heading.views_over(agent, c, over_target) {
                places.push(*c);
                views.push(view);
                view_leads.push(leads.get(k).copied().unwrap_or(0.0));
            }
        }
        let (h0, eer) = evaluate_fast_led(
            &self.inputs,
            &views,
            &view_leads,
            world,
            &p.kernel,
            p.miss_probability,
            &mut self.scratch,
        );
        // The commitment is to get the drone to the mode it chose. Once the vehicle sees its
        // previous waypoint it is there, and the argmax decides again ([`committed_choice`]).
        let previous = self
            .last_waypoint_enu
            .filter(|w| self.searching && !world.footprint.contains(agent, w));
        let mut predicted_mean = Enu2::zeros();
        for (p, w) in self.inputs.predicted.iter().zip(&self.inputs.weights) {
            predicted_mean += *w * p;
        }
        let centring = Centring {
            mean_enu: predicted_mean,
            share: p.centring_share,
        };
        let best = committed_choice(&eer, &places, previous, p.search_commitment, Some(centring));
        let view_yaw_enu_rad = best.map_or(agent.yaw_enu_rad, |i| views[i].yaw_enu_rad);
        let waypoint = match best {
            Some(i) => places[i],
            // Nothing to choose between (no candidate sees any particle): head for the
            // predicted mean, where the target most likely is.
            None => world.workspace_enu.clamp(&predicted_mean),
        };
        self.last_waypoint_enu = Some(waypoint);
        EerDecision {
            waypoint_enu: waypoint,
            eer: best.map_or_else(
                || eer.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
                |i| eer[i],
            ),
            h_now: h0,
            candidates: cands.len(),
            view_yaw_enu_rad,
        }
    }

    /// A whole cycle.
    pub fn plan<R: Rng + ?Sized>(
        &mut self,
        pf: &ParticleFilter,
        model: &mut dyn MotionModel,
        agent: &View,
        heading: &HeadingRule,
        world: &World,
        rng: &mut R,
    ) -> Result<EerDecision, MotionError> {
        self.prepare(pf, model, world, rng)?;
        Ok(self.decide(agent, heading, world))
    }

    /// The inputs of the last prepared cycle.
    pub fn inputs(&self) -> &EerInputs {
        &self.inputs
    }
}

#[cfg(test)]
mod tests;
