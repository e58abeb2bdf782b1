//! Constant-velocity tracks through junctions: a track whose next straight step leaves its
//! road is put on one of the roads it can take within that step. The particle filter applies
//! it to its belief at each step without a measurement, and EER's rollout to its predicted
//! tracks at each of its steps, so the planner predicts as the filter does.

use rand::Rng;

use crate::motion::Histories;
use crate::world::geometry::Enu2;
use crate::world::road::RoadPieces;
use crate::world::World;

/// Track `i`'s velocity over its whole kept history, m/s, world ENU (zero for a track of one
/// position, a zero period or a non-finite difference).
pub fn track_velocity(histories: &Histories, i: usize, dt_s: f64) -> Enu2 {
    let k = histories.k_in();
    if k < 2 || dt_s <= 0.0 {
        return Enu2::zeros();
    }
    let v = (histories.newest(i) - histories.at(i, 0)) / ((k - 1) as f64 * dt_s);
    if v.x.is_finite() && v.y.is_finite() {
        v
    } else {
        Enu2::zeros()
    }
}

/// Track `i` becomes a straight track along one of `roads`, ending at a point drawn on them
/// (by weighted length), at a speed drawn from `speeds_mps`; false (unchanged) when there is
/// no road.
pub fn straight_track_on_roads<R: Rng + ?Sized>(
    histories: &mut Histories,
    i: usize,
    roads: &RoadPieces,
    speeds_mps: std::ops::RangeInclusive<f64>,
    dt_s: f64,
    rng: &mut R,
) -> bool {
    let Some((p, dir)) = roads.sample(rng) else {
        return false;
    };
    let speed = rng.gen_range(speeds_mps);
    straighten(histories, i, &p, &(dir * speed * dt_s));
    true
}

/// Track `i` becomes straight, ending at `newest` after steps of `v_step` (m per step).
fn straighten(histories: &mut Histories, i: usize, newest: &Enu2, v_step: &Enu2) {
    let k = histories.k_in();
    let tr = histories.track_mut(i);
    for t in 0..k {
        let q = newest - v_step * (k - 1 - t) as f64;
        tr[2 * t] = q.x;
        tr[2 * t + 1] = q.y;
    }
}

/// Re-routes track `i` if its next straight step (at its track velocity, over `dt_s`) leaves
/// its road at a junction, or reaches a node whose ways on include the turn back: it is put
/// on one of the roads it can take within that step, the turns drawn by their graph
/// probabilities, the turn back included (the road network is a Markov chain over nodes, so
/// a car at a node with a two-way street turns back along it with that edge's probability,
/// as the simulated car does), keeping its speed (a turn back slows it: [`slow_a_turn_back`]). A track whose step runs off the end of a
/// road with no way on but back (a dead end, or a U-turn edge at it) turns back along it. A
/// track whose step stays on its road (one piece ahead and no turn back in reach, or two with
/// the straight-on step within `on_road_m` of a road: a bend it follows anyway) is left
/// alone; a track more than [`STRAY_ON_ROAD_TOLERANCES`] times `on_road_m` off every road,
/// now and after its step, is put on the one piece ahead.
/// True when the track was re-routed.
///
/// Never drawing the turn back where another way on is in reach, the belief went on while
/// the car turned back, and was lost for good where it did (random-11, random-2:
/// BENCHMARKS.md; without the searching and road-placement rules the same change measured
/// level or worse). It costs field-ring 8.5 points: where the car turns back under an occlusion the
/// belief now splits between its exits, and EER's search chooses between them worse than the
/// re-spread corrected the old, wrong belief (BENCHMARKS.md).
pub fn reroute_track<R: Rng + ?Sized>(
    histories: &mut Histories,
    i: usize,
    world: &World,
    dt_s: f64,
    on_road_m: f64,
    rng: &mut R,
) -> bool {
    let before = track_velocity(histories, i, dt_s);
    let rerouted = put_on_the_road_ahead(histories, i, world, dt_s, on_road_m, rng);
    if rerouted {
        slow_a_turn_back(histories, i, &before, dt_s, rng);
    }
    rerouted
}

/// How many of [`reroute_track`]'s `on_road_m` a track must be off every road, now and after
/// its step, to be put back on the one piece of road ahead: 6, i.e. three road sigmas where
/// `on_road_m` is half a sigma (the filter and EER's rollout), where the road constraint has
/// all but ruled the track out (a weight of exp(-4.5) = 0.011) and the simulated car seldom
/// is (its 99th percentile off the centre line is 10.5-13.2 m against 11.1 m). With 1 (put
/// back from half a sigma) the belief lost its spread across the road: outdoors the tracking
/// error rose from 7.5 to 10.6 m and, flying to the true car, the estimate's from 3.44 to
/// 4.20 m (BENCHMARKS.md).
pub const STRAY_ON_ROAD_TOLERANCES: f64 = 6.0;

/// The slowest share of its speed a track keeps when it turns back ([`slow_a_turn_back`]).
pub const TURN_BACK_MIN_SPEED_SHARE: f64 = 0.4;

/// A track that [`reroute_track`] turned back (its velocity now against `before`) drives on
/// at a speed drawn from [`TURN_BACK_MIN_SPEED_SHARE`] to 1 of its own: no car turns round at
/// cruise speed (the simulated car stops to turn on the spot). Kept at full speed, the
/// turned-back hypotheses came out of a covered junction seconds before the car and were seen
/// absent there, and the belief gave the car's way up (field-eight's covered crossing;
/// BENCHMARKS.md). Its newest position stays; its history is made
/// straight at the new speed.
fn slow_a_turn_back<R: Rng + ?Sized>(
    histories: &mut Histories,
    i: usize,
    before: &Enu2,
    dt_s: f64,
    rng: &mut R,
) {
    let after = track_velocity(histories, i, dt_s);
    if after.dot(before) >= 0.0 {
        return;
    }
    let share = rng.gen_range(TURN_BACK_MIN_SPEED_SHARE..=1.0);
    let newest = histories.newest(i);
    straighten(histories, i, &newest, &(after * share * dt_s));
}

/// [`reroute_track`] before a turn back is slowed.
fn put_on_the_road_ahead<R: Rng + ?Sized>(
    histories: &mut Histories,
    i: usize,
    world: &World,
    dt_s: f64,
    on_road_m: f64,
    rng: &mut R,
) -> bool {
    if histories.k_in() < 2 || world.road.nodes.is_empty() {
        return false;
    }
    let p = histories.newest(i);
    let v = track_velocity(histories, i, dt_s);
    let speed = v.norm();
    let (in_reach, edge_enu) = world.road.reachable_along(&p, Some(v), (0.0, speed * dt_s));
    let all = in_reach.pieces().count();
    // The pieces that go the track's way ([`RoadPieces::split_reversals`]: all of them when
    // every one runs back), counted without splitting: this runs per particle per step, in
    // the filter and in EER's rollout, and only the branch taken below needs its pieces.
    let against_heading = in_reach.reversals(&v);
    let pieces = if against_heading == all {
        all
    } else {
        all - against_heading
    };
    // A turn back the graph allows at the node ahead, beside a way on: a piece against the
    // direction of the edge the track drives along (which it goes the way of). A track
    // facing against its edge (a slow one whose noise points back, or one off the road
    // facing a one-way street the wrong way) has no turn back to draw: it is re-routed as
    // before, by its own heading.
    let turn_back_in_reach = edge_enu.is_some_and(|d| {
        let turns_back = in_reach.reversals(&d);
        d.dot(&v) > 0.0 && turns_back > 0 && turns_back < all
    });
    let step_off_road_m = world.road.distance_to_roads(&(p + v * dt_s));
    let step_on_road = step_off_road_m <= on_road_m;
    // How far the track is off every road, asked once and only where one piece lies ahead
    // and the step leaves it: the dead end and the stray below both need it, and this runs
    // per particle per step.
    let off_road_m = (pieces == 1 && !step_on_road).then(|| world.road.distance_to_roads(&p));
    if let Some(off_road_m) = off_road_m {
        // A dead end: the track is on its road, the road ends within the step and the only
        // way on is back. Carried straight on, the belief ran off the road's end while the
        // car turned round in it, and EER sent the drone past the end (field-twin's
        // warehouse; BENCHMARKS.md). A track already off the road, or
        // at a junction whose other roads lie outside the step, is no dead end: told by the
        // graph, not by the pieces in reach (judged by the pieces in reach, tracks turned back
        // at field-ring's corners).
        if off_road_m <= on_road_m && world.road.heads_into_a_dead_end(&p, Some(v)) {
            let back = in_reach.split_reversals(&v).1;
            return straight_track_on_roads(histories, i, &back, speed..=speed, dt_s, rng);
        }
    }
    if turn_back_in_reach {
        return straight_track_on_roads(histories, i, &in_reach, speed..=speed, dt_s, rng);
    }
    // A track farther than STRAY_ON_ROAD_TOLERANCES tolerances off every road, whose next
    // step stays as far off, with one piece of road within the step ahead, is re-routed onto
    // that piece rather than counted as following its road: carried straight on it ran off
    // across the map, and EER's rollout, which has no road constraint to weigh it down,
    // judged the drone's candidates by hypotheses where no car can be (30-48 % of a 20 s
    // rollout near random-4's node 6; BENCHMARKS.md).
    let stray_m = STRAY_ON_ROAD_TOLERANCES * on_road_m;
    let strays_off_the_roads = off_road_m.is_some_and(|d| d > stray_m && step_off_road_m > stray_m);
    let follows_its_road = (pieces < 2 && !strays_off_the_roads) || (pieces == 2 && step_on_road);
    !follows_its_road && {
        let ahead = in_reach.without_reversals(&v);
        straight_track_on_roads(histories, i, &ahead, speed..=speed, dt_s, rng)
    }
}
