//! The ambush's unit tests.

use rand::SeedableRng;

use super::*;
use crate::rng::CoreRng;
use crate::testing::Config;

/// `config/outdoor.toml` as shipped: 0 (0,0) -> 1 (600,0) one-way east, 1 -> 2 (1200,0)
/// with p 0.6 and 1 -> 6 (600,400) north with 0.4; 5 (0,800) -> 0 south; the warehouse
/// covers node 1.
fn outdoor_world() -> World {
    Config::from_toml_str(
        include_str!("../../../../../config/outdoor.toml"),
        std::path::Path::new("config/outdoor.toml"),
    )
    .unwrap()
    .world()
}

fn params() -> AmbushParams {
    AmbushParams {
        window_s: 30.0,
        after_s: 40.0,
        hypotheses: 256,
        step_s: 1.0,
        flight_s: 90.0,
    }
}

/// Hypotheses spread along a road segment, all driving the same way at `speed`.
fn along(from: Enu2, to: Enu2, n: usize, speed: f64, weight: f64) -> Vec<Hypothesis> {
    let dir = (to - from) / (to - from).norm();
    (0..n)
        .map(|k| Hypothesis {
            position_enu: from + (to - from) * (k as f64 + 0.5) / n as f64,
            velocity_enu: dir * speed,
            weight: weight / n as f64,
        })
        .collect()
}

/// Every hypothesis on the south road 5 -> 0 (x = 0) between y = 600 and 400, driving
/// south at 10 m/s.
fn southbound() -> Vec<Hypothesis> {
    along(Enu2::new(0.0, 600.0), Enu2::new(0.0, 400.0), 50, 10.0, 1.0)
}

/// [`choose`] on the outdoor world for a drone at `agent` flying at 16 m/s with EER's
/// commitment share, its random draws seeded by `seed`.
fn pick(
    params: &AmbushParams,
    belief: &[Hypothesis],
    agent: Enu2,
    previous: Option<Enu2>,
    seed: u64,
) -> Option<AmbushPoint> {
    let mut rng = CoreRng::seed_from_u64(seed);
    choose(
        params,
        belief,
        &outdoor_world(),
        &agent,
        16.0,
        previous,
        0.2,
        &mut rng,
    )
}

/// Where the drone is in most of these tests: east of the south road, north of node 0.
fn agent() -> Enu2 {
    Enu2::new(300.0, 200.0)
}

#[test]
fn the_drone_waits_ahead_of_the_hypotheses_on_their_road_not_behind_them() {
    // They all pass x = 0 below y = 400 (and the road 0 -> 1 after node 0) within the
    // window; nothing comes back north of y = 600.
    for seed in 0..5 {
        let p = pick(&params(), &southbound(), agent(), None, seed).expect("a waiting point");
        let on_their_way = (p.point_enu.x.abs() < 1.0 && p.point_enu.y < 400.0)
            || (p.point_enu.y.abs() < 1.0 && p.point_enu.x < 600.0);
        assert!(on_their_way, "seed {seed}: {p:?}");
        assert!(p.score > 0.0 && p.score.is_finite(), "{p:?}");
    }
}

#[test]
fn a_point_the_drone_cannot_reach_within_the_routes_scores_nothing() {
    // A drone 10 km away: every point is more than `flight_s` of flight away.
    let far = Enu2::new(10_000.0, 10_000.0);
    assert_eq!(pick(&params(), &southbound(), far, None, 1), None);
}

#[test]
fn off_without_weight_or_speed_there_is_no_point() {
    let off = AmbushParams {
        window_s: 0.0,
        ..params()
    };
    assert_eq!(pick(&off, &southbound(), agent(), None, 2), None);
    let weightless: Vec<Hypothesis> = southbound()
        .iter()
        .map(|h| Hypothesis { weight: 0.0, ..*h })
        .collect();
    assert_eq!(pick(&params(), &weightless, agent(), None, 2), None);
    let mut rng = CoreRng::seed_from_u64(2);
    let world = outdoor_world();
    let standing = choose(
        &params(),
        &southbound(),
        &world,
        &agent(),
        0.0,
        None,
        0.2,
        &mut rng,
    );
    assert_eq!(standing, None);
}

#[test]
fn the_previous_point_is_kept_within_the_share_and_left_when_it_sees_nothing() {
    let first = pick(&params(), &southbound(), agent(), None, 3).unwrap();
    // A point 2 m off the best one scores as it does, and is kept.
    let beside = first.point_enu + Enu2::new(0.0, 2.0);
    let kept = pick(&params(), &southbound(), agent(), Some(beside), 4).unwrap();
    assert_eq!(kept.point_enu, beside);
    // A point no hypothesis passes (behind them, north on the road 5 -> 0) is left.
    let behind = Enu2::new(0.0, 790.0);
    let left = pick(&params(), &southbound(), agent(), Some(behind), 5).unwrap();
    assert_ne!(left.point_enu, behind);
    assert!(left.score > 0.0);
}
