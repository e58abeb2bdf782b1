//! Waiting where a long-lost target will drive by (an ambush on the road graph).
//!
//! Why: once the search has gone long without a sighting, the belief is spread over the
//! road graph, and EER (a view judged 2 s ahead) chases the nearest compact front of
//! hypotheses, which drives nearly as fast as the drone and is seldom caught (random-1:
//! after a wrong first branch the drone flew 400 m up it in 30 s while the belief's mean
//! moved the other way; first sightings at 129-199 s or never). A drone that waits at rest
//! where many hypotheses will pass sees the car drive through its view and, from rest,
//! can keep it there: a car entering at the view's edge at 12 m/s is held by a drone that
//! accelerates at 4 m/s^2 along it, where a head-on pass at speed loses it.
//!
//! So: hypotheses drawn from the belief by weight drive on along the roads at their own
//! speed for `flight_s + window_s`; each candidate point along the roads (one view radius
//! apart) scores the share of them that pass within the view's inscribed radius of it, not
//! under an occlusion, in the `window_s` after the drone can be there, divided by that
//! flight plus the wait: a rate, so that a far point is worth its flight (a window from now
//! instead kept the drone at the nearest hub for minutes, BENCHMARKS.md). Pure and
//! seeded.

use rand::Rng;

use crate::world::geometry::Enu2;
use crate::world::World;

/// `guidance.ambush_window_s` when a config leaves it out, s: how long a waiting point is
/// judged over once the drone is there (the one value measured, BENCHMARKS.md).
pub const DEFAULT_AMBUSH_WINDOW_S: f64 = 30.0;

/// How long the target must have been unseen (since the start, or since its last
/// measurement) before the drone waits for it, s. Before it EER's search decides: at 20 s
/// the ambush took random-1's drone off the branch the car was on (BENCHMARKS.md).
pub const AMBUSH_AFTER_S: f64 = 40.0;

/// The ambush's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmbushParams {
    /// How long a waiting point is judged over once the drone can be there, s; 0: off.
    pub window_s: f64,
    /// Unseen for this long (since the start or the last measurement) before it applies, s.
    pub after_s: f64,
    /// Hypotheses drawn from the belief.
    pub hypotheses: usize,
    /// Sample period along the routes, s.
    pub step_s: f64,
    /// The longest flight to a waiting point judged, s (the routes are driven this long
    /// beyond the window).
    pub flight_s: f64,
}

impl AmbushParams {
    /// The shipped ambush judged over `window_s`: 256 hypotheses sampled every second,
    /// waiting points up to 90 s of flight away.
    pub fn new(window_s: f64) -> Self {
        Self {
            window_s,
            after_s: AMBUSH_AFTER_S,
            hypotheses: 256,
            step_s: 1.0,
            flight_s: 90.0,
        }
    }

    /// Whether it is on.
    pub fn is_on(&self) -> bool {
        self.window_s > 0.0 && self.hypotheses > 0 && self.step_s > 0.0
    }
}

/// One hypothesis of the belief: position, velocity (world ENU) and weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hypothesis {
    /// Position, world ENU, m.
    pub position_enu: Enu2,
    /// Velocity, world ENU, m/s.
    pub velocity_enu: Enu2,
    /// Weight (any scale).
    pub weight: f64,
}

/// A scored waiting point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmbushPoint {
    /// Where to wait, world ENU.
    pub point_enu: Enu2,
    /// The share of the drawn hypotheses it sees in its window, per second of the flight
    /// there and the wait.
    pub score: f64,
}

/// The best waiting point for an agent at `agent_enu` flying at `agent_speed_mps`;
/// `previous` is kept while its score is within `commitment_share` of the score range
/// below the best. `None` when off or nothing to draw from.
#[allow(clippy::too_many_arguments)]
pub fn choose<R: Rng + ?Sized>(
    params: &AmbushParams,
    belief: &[Hypothesis],
    world: &World,
    agent_enu: &Enu2,
    agent_speed_mps: f64,
    previous: Option<Enu2>,
    commitment_share: f64,
    rng: &mut R,
) -> Option<AmbushPoint> {
    if !params.is_on() || agent_speed_mps.is_nan() || agent_speed_mps <= 0.0 {
        return None;
    }
    let total: f64 = belief.iter().map(|h| h.weight.max(0.0)).sum();
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let k_max = ((params.window_s + params.flight_s) / params.step_s).ceil() as usize;
    let times: Vec<f64> = (0..=k_max).map(|k| k as f64 * params.step_s).collect();
    let routes = drawn_routes(params, belief, total, world, &times, rng)?;
    let fp = &world.footprint;
    let radius_m = fp.half_width_m.min(fp.half_height_m);
    let mut candidates = candidate_points(world, radius_m);
    if let Some(p) = previous {
        candidates.push(p);
    }
    let scored: Vec<AmbushPoint> = candidates
        .iter()
        .map(|c| AmbushPoint {
            point_enu: *c,
            score: score(
                c,
                agent_enu,
                agent_speed_mps,
                &routes,
                &times,
                radius_m,
                params,
            ),
        })
        .collect();
    let best = scored
        .iter()
        .map(|p| p.score)
        .fold(f64::NEG_INFINITY, f64::max);
    let worst = scored.iter().map(|p| p.score).fold(f64::INFINITY, f64::min);
    if best.is_nan() || best <= 0.0 {
        return None;
    }
    if let Some(prev) = previous {
        let kept = scored.last().copied().filter(|p| p.point_enu == prev);
        if let Some(k) = kept {
            if k.score >= best - commitment_share * (best - worst) {
                return Some(k);
            }
        }
    }
    scored.into_iter().find(|p| p.score >= best)
}

/// `params.hypotheses` hypotheses drawn from the belief (weights summing to `total`), each
/// driven along the roads at its speed: where it is at each of `times` (`None` where it may
/// be hidden). `None` when the roads cannot be driven from one.
fn drawn_routes<R: Rng + ?Sized>(
    params: &AmbushParams,
    belief: &[Hypothesis],
    total: f64,
    world: &World,
    times: &[f64],
    rng: &mut R,
) -> Option<Vec<Vec<Option<Enu2>>>> {
    let mut acc = 0.0;
    let cumulative: Vec<f64> = belief
        .iter()
        .map(|h| {
            acc += h.weight.max(0.0) / total;
            acc
        })
        .collect();
    let mut routes: Vec<Vec<Option<Enu2>>> = Vec::with_capacity(params.hypotheses);
    for _ in 0..params.hypotheses {
        let u: f64 = rng.gen();
        let h = belief[cumulative.partition_point(|c| *c < u).min(belief.len() - 1)];
        let speed = h.velocity_enu.norm();
        let heading = (speed > 0.5).then(|| h.velocity_enu / speed);
        let distances: Vec<f64> = times.iter().map(|t| speed * t).collect();
        let route = world
            .road
            .drive(&h.position_enu, heading, &distances, rng)?;
        routes.push(
            route
                .into_iter()
                .map(|(p, _)| (!world.may_hide_the_tag(&p)).then_some(p))
                .collect(),
        );
    }
    Some(routes)
}

/// Points along every road, one view radius apart, and every node.
fn candidate_points(world: &World, spacing_m: f64) -> Vec<Enu2> {
    let mut out = Vec::new();
    for (a, b) in world.road.edges_enu() {
        let len = (b - a).norm();
        let n = (len / spacing_m).floor() as usize;
        for k in 0..=n {
            out.push(a + (b - a) * (k as f64 * spacing_m / len.max(1e-9)).min(1.0));
        }
        out.push(b);
    }
    out
}

/// The share of the routes that pass within `radius_m` of `c` in the `window_s` after the
/// agent can be there, per second of the whole plan (the flight there and the wait).
fn score(
    c: &Enu2,
    agent_enu: &Enu2,
    speed_mps: f64,
    routes: &[Vec<Option<Enu2>>],
    times: &[f64],
    radius_m: f64,
    params: &AmbushParams,
) -> f64 {
    let arrive_s = (c - agent_enu).norm() / speed_mps;
    let k0 = times.partition_point(|t| *t < arrive_s);
    let k1 = times.partition_point(|t| *t <= arrive_s + params.window_s);
    if k1 > times.len() || k0 >= k1 || arrive_s + params.window_s > times[times.len() - 1] {
        return 0.0;
    }
    let r2 = radius_m * radius_m;
    let passes = routes
        .iter()
        .filter(|r| (k0..k1).any(|k| r[k].is_some_and(|p| (p - c).norm_squared() <= r2)))
        .count();
    passes as f64 / routes.len() as f64 / (arrive_s + params.window_s)
}

#[cfg(test)]
mod tests;
