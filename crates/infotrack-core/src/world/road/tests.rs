//! The road network's unit tests.

use super::*;
use crate::testing::Config;
use rand::SeedableRng;

/// The road network of a shipped config, given its text and its path.
fn road_of(toml: &str, path: &str) -> RoadNetwork {
    let cfg = Config::from_toml_str(toml, std::path::Path::new(path)).unwrap();
    RoadNetwork::from_config(&cfg.road).unwrap()
}

fn outdoor_road() -> RoadNetwork {
    road_of(
        include_str!("../../../../../config/outdoor.toml"),
        "config/outdoor.toml",
    )
}

#[test]
fn the_road_one_may_drive_a_heading_is_told_from_the_nearest_road() {
    // Outdoor: 0 (0,0) -> 1 (600,0) is one-way east; 6 <-> 1 runs both ways on x = 600.
    let road = outdoor_road();
    let p = Enu2::new(300.0, 2.0);
    let (any, east) = road.distances_to_roads(&p, &Enu2::new(1.0, 0.0));
    assert!(
        (any - 2.0).abs() < 1e-9 && (east - 2.0).abs() < 1e-9,
        "{any} {east}"
    );
    // Westward, the nearest road one may drive that way is elsewhere (farther).
    let (any, west) = road.distances_to_roads(&p, &Enu2::new(-1.0, 0.0));
    assert!((any - 2.0).abs() < 1e-9 && west > 100.0, "{any} {west}");
    // Within 60 degrees of the road's direction counts as along it; beyond, not.
    let h = |deg: f64| Enu2::new(deg.to_radians().cos(), deg.to_radians().sin());
    assert!(road.distances_to_roads(&p, &h(55.0)).1 < 3.0);
    assert!(road.distances_to_roads(&p, &h(65.0)).1 > 100.0);
    // A two-way road is along either way.
    let q = Enu2::new(601.0, 200.0);
    for dir in [Enu2::new(0.0, 1.0), Enu2::new(0.0, -1.0)] {
        let (any, along) = road.distances_to_roads(&q, &dir);
        assert!((any - 1.0).abs() < 1e-9 && (along - 1.0).abs() < 1e-9);
    }
}

/// A region holding road gives that road only; one holding none gives the whole
/// network (a target on the roads is somewhere on them), as does no region.
#[test]
fn roads_within_a_region_fall_back_to_the_whole_network_only_where_it_holds_none() {
    let road = outdoor_road();
    let all = road.roads_within(None).length_m();
    let near_start = Some((Enu2::new(100.0, 0.0), 50.0));
    let within = road.roads_within_or_all(near_start).length_m();
    assert!(within > 0.0 && within < all, "{within} of {all}");
    assert!((within - road.length_within(near_start)).abs() < 1e-9);
    // Far outside the network: no road there, so all of it.
    let empty = Some((Enu2::new(-5000.0, -5000.0), 10.0));
    assert_eq!(road.roads_within(empty).length_m(), 0.0);
    assert!((road.roads_within_or_all(empty).length_m() - all).abs() < 1e-9);
    assert!((road.roads_within_or_all(None).length_m() - all).abs() < 1e-9);
}

#[test]
fn reachable_roads_lie_ahead_within_the_distance_band_split_by_the_turns() {
    // Outdoor: 0 (0,0) -> 1 (600,0), then 1 -> 2 east with p 0.6, 1 -> 6 north with 0.4.
    let road = outdoor_road();
    let from = Enu2::new(550.0, 1.0);
    let heading = Some(Enu2::new(10.0, 0.0));
    let r = road.reachable_from(&from, heading, (80.0, 120.0));
    let pieces: Vec<_> = r.pieces().map(|(p, w)| (*p, w)).collect();
    assert_eq!(pieces.len(), 2, "{pieces:?}");
    let east = pieces.iter().find(|(p, _)| p.0.y.abs() < 1e-9).unwrap();
    let north = pieces
        .iter()
        .find(|(p, _)| (p.0.x - 600.0).abs() < 1e-9)
        .unwrap();
    // 50 m to the junction, then 30..70 m along each branch.
    assert!((east.0 .0.x - 630.0).abs() < 1e-6 && (east.0 .1.x - 670.0).abs() < 1e-6);
    assert!((north.0 .0.y - 30.0).abs() < 1e-6 && (north.0 .1.y - 70.0).abs() < 1e-6);
    assert!((east.1 - 0.6).abs() < 1e-12 && (north.1 - 0.4).abs() < 1e-12);
    // Nothing behind, and the total is weighted: 40 m x (0.6 + 0.4).
    assert!((r.length_m() - 40.0).abs() < 1e-6);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut on_east = 0;
    for _ in 0..4000 {
        let (p, dir) = r.sample(&mut rng).unwrap();
        assert!(p.x >= 600.0 - 1e-9, "behind the junction: {p:?}");
        if p.y.abs() < 1e-9 {
            on_east += 1;
            assert!((dir - Enu2::new(1.0, 0.0)).norm() < 1e-9);
        } else {
            assert!((dir - Enu2::new(0.0, 1.0)).norm() < 1e-9);
        }
    }
    let share = on_east as f64 / 4000.0;
    assert!((share - 0.6).abs() < 0.03, "east share {share}");
}

#[test]
fn a_reversal_is_left_out_unless_it_is_the_only_way_on() {
    // Outdoor: 2 m before node 6 (600, 400) driving north on 1 -> 6; from 6 the roads go
    // on north to 4 (p 0.7) or back south to 1 (p 0.3, a U-turn).
    let road = outdoor_road();
    let north = Enu2::new(0.0, 10.0);
    let ahead = road.reachable_from(&Enu2::new(600.0, 398.0), Some(north), (0.0, 5.0));
    let heads_south = |r: &RoadPieces| r.pieces().any(|((a, b), _)| b.y < a.y - 1e-9);
    assert!(heads_south(&ahead), "the graph allows the U-turn");
    // Node 6 has a way on besides the U-turn: no dead end.
    assert!(!road.heads_into_a_dead_end(&Enu2::new(600.0, 398.0), Some(north)));
    // Its complement: the U-turn alone, 3 m at p 0.3; nothing without a heading.
    let back_only = ahead.clone().split_reversals(&north).1;
    assert!(back_only.pieces().all(|((a, b), _)| b.y < a.y - 1e-9));
    assert!((back_only.length_m() - 0.3 * 3.0).abs() < 1e-6);
    assert_eq!(
        ahead
            .clone()
            .split_reversals(&Enu2::zeros())
            .1
            .pieces()
            .count(),
        0
    );
    let on = ahead.without_reversals(&north);
    assert!(!heads_south(&on));
    assert!(on.pieces().any(|((a, _), _)| a.y >= 400.0 - 1e-9));
    assert!(
        (on.length_m() - (2.0 + 0.7 * 3.0)).abs() < 1e-6,
        "{}",
        on.length_m()
    );
    // Every piece against the heading: nothing else is left, so they stay.
    let back = road.reachable_from(&Enu2::new(600.0, 200.0), Some(-north), (0.0, 5.0));
    let kept = back.length_m();
    assert!((back.without_reversals(&north).length_m() - kept).abs() < 1e-9);
    assert!(kept > 0.0);
}

#[test]
fn the_heading_picks_the_edge_and_a_crossing_road_is_not_taken() {
    // Outdoor has 6 -> 1 (south) and 1 -> 6 (north) on x = 600: the heading decides.
    let road = outdoor_road();
    let from = Enu2::new(600.0, 200.0);
    let north = road.reachable_from(&from, Some(Enu2::new(0.0, 10.0)), (10.0, 20.0));
    let south = road.reachable_from(&from, Some(Enu2::new(0.0, -10.0)), (10.0, 20.0));
    let first = |r: &RoadPieces| r.pieces().next().map(|(p, _)| *p).unwrap();
    assert!(first(&north).0.y > 200.0, "{:?}", first(&north));
    assert!(first(&south).0.y < 200.0, "{:?}", first(&south));
    // A point far off every road, heading north-east: still placed, never empty.
    let off = road.reachable_from(
        &Enu2::new(300.0, 400.0),
        Some(Enu2::new(1.0, 1.0)),
        (0.0, 5.0),
    );
    assert!(off.length_m() > 0.0);
}

fn rng() -> rand_chacha::ChaCha8Rng {
    rand_chacha::ChaCha8Rng::seed_from_u64(25)
}

/// A loop 0 -> 1 -> 2 with a gentle bend at 1 (14 degrees in, 11 out) and a chord 1 -> 5
/// north, 5 -> 0 back south-west: the geometry of the track jumps BENCHMARKS.md found.
fn bend_and_chord() -> RoadNetwork {
    network(
        &[
            (0, 0.0, 0.0),
            (1, 400.0, 100.0),
            (2, 900.0, 0.0),
            (5, 400.0, 500.0),
        ],
        &[
            (0, 1, 1.0),
            (1, 2, 0.6),
            (1, 5, 0.4),
            (2, 0, 1.0),
            (5, 0, 1.0),
        ],
    )
}

#[test]
fn a_heading_never_moves_a_point_to_a_far_road() {
    let road = bend_and_chord();
    // Where `drive` places a point with a heading, and its road's direction.
    let place = |x: f64, y: f64, heading: Enu2| {
        road.drive(&Enu2::new(x, y), Some(heading), &[0.0], &mut rng())
            .unwrap()[0]
    };
    // 10 m short of node 5 on 1 -> 5, standing (a car turning in place), its velocity's
    // noise pointing east, along 1 -> 2 390 m away: it stays on 1 -> 5.
    let (p, dir) = place(402.0, 490.0, Enu2::new(1.1, 0.6));
    assert!((p - Enu2::new(400.0, 490.0)).norm() < 1e-6, "{p:?}");
    assert!((dir - Enu2::new(0.0, 1.0)).norm() < 1e-9, "{dir:?}");
    // 58 m past the bend on 1 -> 2 heading east-north-east, closer in direction to 0 -> 1
    // than to 1 -> 2: it stays where it is, not at the bend behind it.
    let (p, _) = place(458.0, 93.0, Enu2::new(12.3, 2.0));
    assert!(
        p.x > 450.0 && (p - Enu2::new(458.0, 93.0)).norm() < 5.0,
        "{p:?}"
    );
    let ahead = road.reachable_from(
        &Enu2::new(458.0, 93.0),
        Some(Enu2::new(12.3, 2.0)),
        (0.0, 4.0),
    );
    assert!(ahead.pieces().all(|((a, _), _)| a.x > 450.0), "{ahead:?}");
    // Where two roads are about as near, the heading still chooses: at node 1, east is
    // 1 -> 2 and north 1 -> 5.
    let (_, east) = place(401.0, 101.0, Enu2::new(1.0, -0.2));
    let (_, north) = place(401.0, 101.0, Enu2::new(0.0, 1.0));
    assert!(east.x > 0.9 && north.y > 0.99, "{east:?} {north:?}");
}

#[test]
fn transitions_follow_their_probabilities() {
    let road = RoadNetwork::from_config(&Config::default_lab().road).unwrap();
    let a = road.nodes.iter().position(|n| n.id == 1).unwrap();
    let b = road.nodes.iter().position(|n| n.id == 2).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let n = 20_000;
    let to_b = (0..n)
        .filter(|_| road.sample_next(a, &mut rng) == b)
        .count();
    let share = to_b as f64 / n as f64;
    // 0.3 expected; 4 sigma of a binomial at n = 20000 is 0.013.
    assert!((share - 0.3).abs() < 0.013, "{share}");
}

#[test]
fn edges_connect_configured_nodes() {
    let road = RoadNetwork::from_config(&Config::default_lab().road).unwrap();
    assert_eq!(road.edges_enu().len(), 7);
    assert_eq!(road.nodes[road.start].id, 1);
}

fn distance_to_roads(road: &RoadNetwork, p: &Enu2) -> f64 {
    road.distance_to_roads(p)
}

#[test]
fn points_on_the_roads_lie_on_an_edge_inside_the_region_in_its_direction() {
    let road = RoadNetwork::from_config(&Config::default_lab().road).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
    let region = (Enu2::new(0.35, 0.2), 0.5);
    for _ in 0..2000 {
        let (p, dir) = road.sample_on_roads(Some(region), &mut rng).unwrap();
        assert!(distance_to_roads(&road, &p) < 1e-9, "{p} is off the roads");
        assert!(
            (p - region.0).norm() <= region.1 + 1e-9,
            "{p} outside the region"
        );
        assert!((dir.norm() - 1.0).abs() < 1e-12);
    }
    // Within 0.5 m of (0.35, 0.2) only the edge 2 -> 3 (x = 0.35, northward) passes:
    // every direction drawn there is north.
    let (_, dir) = road.sample_on_roads(Some(region), &mut rng).unwrap();
    assert!((dir - Enu2::new(0.0, 1.0)).norm() < 1e-9, "{dir}");
    assert!((road.length_within(Some(region)) - 1.0).abs() < 1e-9);
    // No road far away.
    assert!(road
        .sample_on_roads(Some((Enu2::new(50.0, 50.0), 1.0)), &mut rng)
        .is_none());
}

#[test]
fn the_whole_network_is_drawn_by_length() {
    let road = RoadNetwork::from_config(&Config::default_lab().road).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let total = road.length_within(None);
    // Edge 2 -> 3 is 1.6 m of the network: its share of draws follows.
    let n = 20_000;
    let on_2_3 = (0..n)
        .filter(|_| {
            let (p, _) = road.sample_on_roads(None, &mut rng).unwrap();
            (p.x - 0.35).abs() < 1e-9 && p.y > -0.6 && p.y < 1.0
        })
        .count();
    let share = on_2_3 as f64 / n as f64;
    let expected = 1.6 / total;
    assert!((share - expected).abs() < 0.015, "{share} vs {expected}");
}

/// A fork: 0 -> 1 east, then at 1 an even choice of 2 (east, a dead end) or 3 (north,
/// a dead end).
fn fork() -> RoadNetwork {
    network(
        &[
            (0, 0.0, 0.0),
            (1, 100.0, 0.0),
            (2, 200.0, 0.0),
            (3, 100.0, 100.0),
        ],
        &[(0, 1, 1.0), (1, 2, 0.5), (1, 3, 0.5)],
    )
}

/// A network from `(id, x, y)` nodes and `(from, to, p)` edges, starting at node 0.
fn network(nodes: &[(u32, f64, f64)], edges: &[(u32, u32, f64)]) -> RoadNetwork {
    RoadNetwork::from_config(&RoadConfig {
        nodes: nodes
            .iter()
            .map(|&(id, x_m, y_m)| NodeConfig { id, x_m, y_m })
            .collect(),
        edges: edges
            .iter()
            .map(|&(from, to, p)| EdgeConfig { from, to, p })
            .collect(),
        start_node: 0,
    })
    .unwrap()
}

#[test]
fn a_route_is_driven_along_the_allowed_ways_and_takes_each_turn_by_its_probability() {
    let road = fork();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let from = Enu2::new(50.0, 1.0);
    let distances = [0.0, 25.0, 50.0, 80.0, 500.0];
    let mut east = 0;
    let n = 4000;
    for _ in 0..n {
        let route = road
            .drive(&from, Some(Enu2::new(1.0, 0.0)), &distances, &mut rng)
            .unwrap();
        let at: Vec<Enu2> = route.iter().map(|(p, _)| *p).collect();
        assert!((at[0] - Enu2::new(50.0, 0.0)).norm() < 1e-9, "{}", at[0]);
        assert!((at[1] - Enu2::new(75.0, 0.0)).norm() < 1e-9, "{}", at[1]);
        assert!((at[2] - Enu2::new(100.0, 0.0)).norm() < 1e-9, "{}", at[2]);
        assert!((route[1].1 - Enu2::new(1.0, 0.0)).norm() < 1e-9);
        // 30 m past the fork, on one branch or the other, heading along it; then
        // stopped at that branch's dead end.
        if (at[3] - Enu2::new(130.0, 0.0)).norm() < 1e-9 {
            east += 1;
            assert!((at[4] - Enu2::new(200.0, 0.0)).norm() < 1e-9, "{}", at[4]);
        } else {
            assert!((at[3] - Enu2::new(100.0, 30.0)).norm() < 1e-9, "{}", at[3]);
            assert!((route[3].1 - Enu2::new(0.0, 1.0)).norm() < 1e-9);
            assert!((at[4] - Enu2::new(100.0, 100.0)).norm() < 1e-9, "{}", at[4]);
        }
    }
    let share = east as f64 / n as f64;
    assert!((share - 0.5).abs() < 0.03, "{share}");
}

fn ring_road() -> RoadNetwork {
    road_of(
        include_str!("../../../../../config/field-ring.toml"),
        "config/field-ring.toml",
    )
}

#[test]
fn a_track_past_a_junction_stays_beside_its_new_road_not_back_at_the_junction() {
    // field-ring: 3 (1300, 900) -> 4 (600, 1100) -> 5 (-100, 800) west-south-west, or on to
    // 6 (700, 500) south. A car that cut the corner at 4 is 29 m past it and 8 m beside the
    // road to 5, heading due west: 23 degrees off that road, 16 off 3 -> 4, whose end (node
    // 4) lies 29 m behind it.
    let road = ring_road();
    let p = Enu2::new(571.0, 1096.0);
    let west = Enu2::new(-12.0, 0.0);
    let ahead = road.reachable_from(&p, Some(west), (0.0, 4.0));
    assert!(ahead.length_m() > 0.0);
    for ((a, b), _) in ahead.pieces() {
        // On the road to 5, beside the car: not at node 4, and not south to 6.
        assert!((a - p).norm() < 15.0 && (b - p).norm() < 15.0, "{a} {b}");
        assert!(b.x < a.x, "{a} -> {b} does not head west");
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let route = road.drive(&p, Some(west), &[0.0, 50.0], &mut rng).unwrap();
    assert!((route[0].0 - p).norm() < 15.0, "{:?}", route[0]);
    assert!(route[1].0.x < p.x - 40.0, "{:?}", route[1]);
    // Short of node 4, 4 m beside 3 -> 4 and heading its way: it stays on 3 -> 4.
    let q = Enu2::new(650.0, 1090.0);
    let on = road.reachable_from(&q, Some(Enu2::new(-12.0, 3.0)), (0.0, 4.0));
    for ((a, b), _) in on.pieces() {
        assert!((a - q).norm() < 15.0 && b.x < a.x, "{a} -> {b}");
    }
    // A track that overshot node 4 heading north-west, where neither road out of 4 goes
    // (68 and 144 degrees off), is still put on the roads out of 4, by their probabilities.
    let past = Enu2::new(596.0, 1102.0);
    let out = road.reachable_from(&past, Some(Enu2::new(-8.0, 8.0)), (0.0, 4.0));
    assert_eq!(out.pieces().count(), 2);
    assert!(out
        .pieces()
        .all(|((a, _), _)| (a - Enu2::new(600.0, 1100.0)).norm() < 1e-6));
}

/// A crossing at (100, 0) of a two-way street (west 0 <-> crossing 1) with one-way roads
/// on east (to 2) and north (to 3): 0.2 back west, 0.3 east, 0.5 north.
fn crossing_with_a_two_way_street() -> RoadNetwork {
    network(
        &[
            (0, 0.0, 0.0),
            (1, 100.0, 0.0),
            (2, 200.0, 0.0),
            (3, 100.0, 100.0),
        ],
        &[(0, 1, 1.0), (1, 0, 0.2), (1, 2, 0.3), (1, 3, 0.5)],
    )
}

#[test]
fn a_route_without_a_heading_drives_a_two_way_street_either_way_and_a_one_way_its_way() {
    let road = crossing_with_a_two_way_street();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let n = 4000;
    // 30 m short of the crossing on the two-way street, 60 m on: straight back west to
    // (10, 0), or through the crossing and 30 m along one of its three ways on.
    let from = Enu2::new(70.0, 2.0);
    let (mut west, mut back, mut east, mut north) = (0, 0, 0, 0);
    for _ in 0..n {
        let route = road.drive(&from, None, &[0.0, 60.0], &mut rng).unwrap();
        assert!(
            (route[0].0 - Enu2::new(70.0, 0.0)).norm() < 1e-9,
            "{}",
            route[0].0
        );
        let p = route[1].0;
        if (p - Enu2::new(10.0, 0.0)).norm() < 1e-9 {
            west += 1;
        } else if (p - Enu2::new(70.0, 0.0)).norm() < 1e-9 {
            back += 1;
        } else if (p - Enu2::new(130.0, 0.0)).norm() < 1e-9 {
            east += 1;
        } else if (p - Enu2::new(100.0, 30.0)).norm() < 1e-9 {
            north += 1;
        } else {
            panic!("60 m on off every way: {p}");
        }
    }
    let share = |k: i32| k as f64 / n as f64;
    assert!((share(west) - 0.5).abs() < 0.03, "west {}", share(west));
    for (name, k, p) in [
        ("back", back, 0.1),
        ("east", east, 0.15),
        ("north", north, 0.25),
    ] {
        assert!((share(k) - p).abs() < 0.03, "{name} {}", share(k));
    }
    // On the one-way road east, every route drives east, 60 m on.
    for _ in 0..200 {
        let route = road
            .drive(&Enu2::new(120.0, 1.0), None, &[60.0], &mut rng)
            .unwrap();
        assert!(
            (route[0].0 - Enu2::new(180.0, 0.0)).norm() < 1e-9,
            "{}",
            route[0].0
        );
    }
}

#[test]
fn the_road_path_turns_at_the_junction_and_runs_either_way() {
    let road = outdoor_road();
    // East along 0 -> 1, then north up x = 600.
    let path = road
        .path_between(&Enu2::new(300.0, 5.0), &Enu2::new(603.0, 300.0))
        .unwrap();
    let want = [
        Enu2::new(300.0, 0.0),
        Enu2::new(600.0, 0.0),
        Enu2::new(600.0, 300.0),
    ];
    assert_eq!(path.points_enu().len(), 3, "{path:?}");
    for (p, w) in path.points_enu().iter().zip(want) {
        assert!((p - w).norm() < 1e-9, "{path:?}");
    }
    assert!((path.length_m() - 600.0).abs() < 1e-9);
    let (p, dir) = path.point_at(350.0);
    assert!(
        (p - Enu2::new(600.0, 50.0)).norm() < 1e-9 && (dir - Enu2::new(0.0, 1.0)).norm() < 1e-9
    );
    let (end, _) = path.point_at(1e6);
    assert!((end - want[2]).norm() < 1e-9, "clamped to the end: {end}");
    // 4 -> 5 is one-way west; the drone may fly it east: (300, 800) to (600, 700) is 300 m
    // east to node 4, then 100 m south, both against the car's directions.
    let back = road
        .path_between(&Enu2::new(300.0, 800.0), &Enu2::new(600.0, 700.0))
        .unwrap();
    assert!((back.length_m() - 400.0).abs() < 1e-9, "{back:?}");
    // Both ends on one road: straight along it, whichever way.
    for (a, b) in [(100.0, 400.0), (400.0, 100.0)] {
        let same = road
            .path_between(&Enu2::new(a, 3.0), &Enu2::new(b, -2.0))
            .unwrap();
        assert_eq!(same.points_enu().len(), 2, "{same:?}");
        assert!((same.length_m() - 300.0).abs() < 1e-9, "{same:?}");
    }
}

/// A loop with a fork: 0 -> 1 east, at 1 north to 2 with p 0.75 or south to 3 with p 0.25,
/// both back to 0. Every branch 100 m or so; the car drives it forever.
fn loop_with_a_fork() -> RoadNetwork {
    network(
        &[
            (0, 0.0, 0.0),
            (1, 100.0, 0.0),
            (2, 100.0, 100.0),
            (3, 100.0, -100.0),
        ],
        &[
            (0, 1, 1.0),
            (1, 2, 0.75),
            (1, 3, 0.25),
            (2, 0, 1.0),
            (3, 0, 1.0),
        ],
    )
}

/// The share of `n` points drawn from `pieces` that fall in the half plane y > 0.
fn share_north(pieces: &RoadPieces, n: usize, rng: &mut rand_chacha::ChaCha8Rng) -> f64 {
    let north = (0..n)
        .filter(|_| pieces.sample(rng).expect("a road").0.y > 1e-9)
        .count();
    north as f64 / n as f64
}

#[test]
fn traffic_follows_the_turn_probabilities_and_length_alone_does_not() {
    let road = loop_with_a_fork();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    // Within 60 m of the fork: 60 m of each branch up and down, 60 m of the road in.
    let region = Some((Enu2::new(100.0, 0.0), 60.0));
    // By traffic, the branch north carries 0.75 of what passes the fork, the south 0.25,
    // and the road in all of it: north 0.75 / (1 + 0.75 + 0.25) of the points.
    let by_traffic = share_north(&road.traffic_within(region), 20_000, &mut rng);
    assert!((by_traffic - 0.375).abs() < 0.015, "{by_traffic}");
    // By length, a third each.
    let by_length = share_north(&road.roads_within(region), 20_000, &mut rng);
    assert!((by_length - 1.0 / 3.0).abs() < 0.015, "{by_length}");
    // The return legs carry the same traffic as the branches they come from: far from
    // the fork, on 2 -> 0 (from (100, 100) to (0, 0)) against 3 -> 0.
    let w: Vec<f64> = road.traffic_within(None).pieces().map(|(_, w)| w).collect();
    // Segments in node order: 0->1, 1->2, 1->3, 2->0, 3->0.
    assert!((w[1] / w[2] - 3.0).abs() < 1e-6, "{w:?}");
    assert!((w[3] / w[4] - 3.0).abs() < 1e-6, "{w:?}");
    assert!((w[0] / (w[1] + w[2]) - 1.0).abs() < 1e-6, "{w:?}");
}

#[test]
fn on_a_ring_every_road_carries_the_same_traffic() {
    // A one-way ring of four: a periodic chain, for which plain power iteration would
    // never settle; the lazy chain does.
    let road = network(
        &[
            (0, 0.0, 0.0),
            (1, 100.0, 0.0),
            (2, 100.0, 100.0),
            (3, 0.0, 100.0),
        ],
        &[(0, 1, 1.0), (1, 2, 1.0), (2, 3, 1.0), (3, 0, 1.0)],
    );
    for (_, w) in road.traffic_within(None).pieces() {
        assert!((w - 1.0).abs() < 1e-9, "{w}");
    }
    // Outside every road: nothing.
    let far = road.traffic_within(Some((Enu2::new(1000.0, 1000.0), 10.0)));
    assert_eq!(far.length_m(), 0.0);
}

#[test]
fn a_road_config_naming_a_missing_node_is_an_error_not_a_panic() {
    let config = |to: u32, start_node: u32| RoadConfig {
        nodes: vec![
            NodeConfig {
                id: 0,
                x_m: 0.0,
                y_m: 0.0,
            },
            NodeConfig {
                id: 1,
                x_m: 10.0,
                y_m: 0.0,
            },
        ],
        edges: vec![
            EdgeConfig {
                from: 0,
                to,
                p: 1.0,
            },
            EdgeConfig {
                from: 1,
                to: 0,
                p: 1.0,
            },
        ],
        start_node,
    };
    let e = RoadNetwork::try_from(&config(7, 0)).unwrap_err();
    assert_eq!(
        e.to_string(),
        "road.edges[0].to names node 7, which is not one of road.nodes"
    );
    let e = RoadNetwork::try_from(&config(1, 9)).unwrap_err();
    assert!(
        e.to_string().starts_with("road.start_node names node 9"),
        "{e}"
    );
    assert_eq!(RoadNetwork::try_from(&config(1, 0)).unwrap().nodes.len(), 2);
}

/// A fork: 0 -> 1 (east), at 1 on east to 2 or north to 3, both on to 4; at 0 also a spur
/// south to 5. `p_east` is the probability of going on east at 1.
fn learning_fork(p_east: f64) -> RoadNetwork {
    let node = |id: u32, x_m: f64, y_m: f64| NodeConfig { id, x_m, y_m };
    let edge = |from: u32, to: u32, p: f64| EdgeConfig { from, to, p };
    RoadNetwork::from_config(&RoadConfig {
        nodes: vec![
            node(0, 0.0, 0.0),
            node(1, 200.0, 0.0),
            node(2, 400.0, 0.0),
            node(3, 200.0, 200.0),
            node(4, 400.0, 200.0),
            node(5, 0.0, -200.0),
        ],
        edges: vec![
            edge(0, 1, 0.5),
            edge(0, 5, 0.5),
            edge(1, 2, p_east),
            edge(1, 3, 1.0 - p_east),
            edge(2, 4, 1.0),
            edge(3, 4, 1.0),
        ],
        start_node: 0,
    })
    .unwrap()
}

/// Cars that drive the fork with `p_east`, sampled each second at 10 m/s with up to 3 m of
/// noise across and along, from 10 m past node 0.
fn learning_fork_tracks(p_east: f64, n: usize, seed: u64) -> Vec<Vec<(f64, Enu2)>> {
    let truth = learning_fork(p_east);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let distances: Vec<f64> = (0..44).map(|k| 10.0 * k as f64).collect();
    (0..n)
        .map(|_| {
            let route = truth
                .drive(
                    &Enu2::new(10.0, 0.0),
                    Some(Enu2::new(1.0, 0.0)),
                    &distances,
                    &mut rng,
                )
                .unwrap();
            route
                .iter()
                .enumerate()
                .map(|(k, (p, _))| {
                    let noise = Enu2::new(rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0));
                    (k as f64, p + noise)
                })
                .collect()
        })
        .collect()
}

#[test]
fn turn_probabilities_learned_from_tracks_approach_the_cars_own() {
    let map = learning_fork(0.5);
    let tracks = learning_fork_tracks(0.8, 300, 5);
    let (counts, _) = map.count_turns(&tracks, 15.0);
    assert_eq!(counts.counts[1].iter().sum::<u32>(), 300, "{counts:?}");
    assert_eq!(counts.off_road_samples, 0);
    assert_eq!(counts.turn_backs, 0);
    let learned = map.learned_probabilities(&counts, 2.0);
    assert!((learned[1][0] - 0.8).abs() < 0.06, "{:?}", learned[1]);
    assert!((learned[1].iter().sum::<f64>() - 1.0).abs() < 1e-12);
    // Every car went on to 4 from 2 or 3: those have one exit and keep it.
    assert_eq!(learned[2], vec![1.0]);
    // No car was seen to choose at node 0 (every track starts past it): the map's.
    assert_eq!(counts.counts[0], vec![0, 0]);
    assert_eq!(learned[0], vec![0.5, 0.5]);
}

#[test]
fn few_tracks_move_the_maps_probabilities_only_by_what_they_show() {
    let map = learning_fork(0.5);
    let tracks = learning_fork_tracks(1.0, 2, 6);
    let (counts, _) = map.count_turns(&tracks, 15.0);
    let learned = map.learned_probabilities(&counts, 2.0);
    // Two cars east: (2 + 2 x 0.5) / (2 + 2) = 0.75; north keeps a quarter.
    assert_eq!(counts.counts[1], vec![2, 0]);
    assert!((learned[1][0] - 0.75).abs() < 1e-12 && (learned[1][1] - 0.25).abs() < 1e-12);
}

#[test]
fn a_car_that_turns_back_on_a_two_way_street_is_counted_turning_back() {
    let node = |id: u32, x_m: f64| NodeConfig { id, x_m, y_m: 0.0 };
    let edge = |from: u32, to: u32| EdgeConfig { from, to, p: 1.0 };
    let map = RoadNetwork::from_config(&RoadConfig {
        nodes: vec![node(0, 0.0), node(1, 200.0)],
        edges: vec![edge(0, 1), edge(1, 0)],
        start_node: 0,
    })
    .unwrap();
    // East at 10 m/s to x = 190, back west to x = 20.
    let xs: Vec<f64> = (1..=19)
        .chain((2..19).rev())
        .map(|k| 10.0 * k as f64)
        .collect();
    let track: Vec<(f64, Enu2)> = xs
        .iter()
        .enumerate()
        .map(|(k, x)| (k as f64, Enu2::new(*x, 1.0)))
        .collect();
    let (counts, sequences) = map.count_turns(&[track], 15.0);
    assert_eq!(sequences, vec![vec![0, 1, 0]]);
    assert_eq!(counts.counts[1], vec![1]);
    assert_eq!(counts.turn_backs, 1);
}

#[test]
fn samples_far_from_every_road_are_not_matched_and_break_the_stretch() {
    let map = learning_fork(0.5);
    let mut track = learning_fork_tracks(1.0, 1, 7).remove(0);
    // Samples 10-14 jump 100 m south of the road (the recording lost its fix).
    for s in &mut track[10..15] {
        s.1.y -= 100.0;
    }
    let (counts, sequences) = map.count_turns(&[track], 15.0);
    assert!(counts.off_road_samples >= 4, "{counts:?}");
    assert_eq!(sequences.len(), 2, "{sequences:?}");
}
