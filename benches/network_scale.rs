//! How the tracker's cost grows with the road network: one filter step and one guidance
//! decision (EER, 1000 particles, constant velocity, the settings of config/outdoor.toml) on
//! square grids of two-way streets 100 m apart with 10 to 5000 junctions, the target unseen
//! since the operator's cue at the grid's centre (the search, the costly case). The target
//! a real town asks for: at 1000 junctions a decision within 50 ms and a filter step within
//! 5 ms, medians on one thread.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};

use infotrack::config::{AcquisitionConfig, Config, EdgeConfig, NodeConfig, RoadConfig};
use infotrack::guidance::GuidanceKind;
use infotrack::motion::no_learned_model;
use infotrack::rng::{stream_rng, Stream};
use infotrack::tracker::{EstimatorKind, FrozenClock, Observation, TickInput, Tracker};
use infotrack::world::camera::{View, NORTH_VIEW_YAW_ENU_RAD};
use infotrack::world::geometry::{BoundsEnu, Enu2};

/// Street spacing of the grids, m.
const BLOCK_M: f64 = 100.0;

/// A `side` x `side` grid of two-way streets, every exit of a junction equally likely.
fn grid(side: usize) -> RoadConfig {
    let id = |i: usize, j: usize| (i * side + j) as u32;
    let nodes = (0..side * side)
        .map(|k| NodeConfig {
            id: k as u32,
            x_m: BLOCK_M * (k / side) as f64,
            y_m: BLOCK_M * (k % side) as f64,
        })
        .collect();
    let mut edges = Vec::new();
    for i in 0..side {
        for j in 0..side {
            let exits: Vec<(usize, usize)> = [(1, 0), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .map(|(di, dj)| (i as i64 + di, j as i64 + dj))
                .filter(|(a, b)| (0..side as i64).contains(a) && (0..side as i64).contains(b))
                .map(|(a, b)| (a as usize, b as usize))
                .collect();
            for (a, b) in &exits {
                edges.push(EdgeConfig {
                    from: id(i, j),
                    to: id(*a, *b),
                    p: 1.0 / exits.len() as f64,
                });
            }
        }
    }
    RoadConfig {
        nodes,
        edges,
        start_node: id(side / 2, side / 2),
    }
}

/// config/outdoor.toml's settings on a grid of about `junctions` junctions.
fn grid_config(junctions: usize) -> Config {
    let mut cfg = Config::from_toml_str(
        include_str!("../config/outdoor.toml"),
        std::path::Path::new("config/outdoor.toml"),
    )
    .expect("config/outdoor.toml");
    let side = (junctions as f64).sqrt().round().max(2.0) as usize;
    let far = BLOCK_M * (side - 1) as f64;
    cfg.road = grid(side);
    cfg.occlusions.clear();
    cfg.workspace_enu = BoundsEnu {
        x_min_m: -BLOCK_M,
        x_max_m: far + BLOCK_M,
        y_min_m: -BLOCK_M,
        y_max_m: far + BLOCK_M,
    };
    let centre = BLOCK_M * (side / 2) as f64;
    cfg.acquisition = Some(AcquisitionConfig {
        cue_enu_m: Some([centre, centre]),
        cue_radius_m: 150.0,
        min_speed_mps: None,
        prior: None,
    });
    cfg
}

/// East of the cue of [`grid_config`], m.
fn centre_east(cfg: &Config) -> f64 {
    cfg.acquisition
        .as_ref()
        .and_then(|a| a.cue_enu_m)
        .expect("grid_config sets a cue")[0]
}

/// A tracker on `cfg` that has searched for 20 s without seeing the target, the drone
/// over the cue; returns it and the time.
fn searching(cfg: &Config) -> (Tracker, f64) {
    let params = cfg.tracker_params(GuidanceKind::Eer, false);
    let model = EstimatorKind::parse("cv")
        .expect("cv")
        .build(&params.motion, &no_learned_model)
        .expect("cv builds");
    let mut t = Tracker::new(
        params,
        cfg.world(),
        model,
        stream_rng(1, 0, Stream::Filter, 0),
        stream_rng(1, 0, Stream::Guidance, 0),
    )
    .expect("the tracker builds");
    let over = Enu2::new(centre_east(cfg), 0.0);
    let dt = cfg.filter_dt_s();
    let mut t_s = 0.0;
    while t_s < 20.0 {
        t_s += dt;
        step_unseen(&mut t, t_s, over);
    }
    (t, t_s)
}

fn step_unseen(t: &mut Tracker, t_s: f64, over: Enu2) {
    let input = TickInput {
        vehicle_enu: Some(over),
        view_yaw_enu_rad: NORTH_VIEW_YAW_ENU_RAD,
        link_lost: false,
        truth_enu: None,
        truth_velocity_enu: Enu2::zeros(),
    };
    let frame = Observation::Frame {
        taken_from: View::north(over),
        z: None,
    };
    t.update(t_s, frame, &input, &FrozenClock)
        .expect("a filter step");
}

fn network_scale(c: &mut Criterion) {
    let mut g = c.benchmark_group("network_scale");
    g.sample_size(10);
    for junctions in [10usize, 100, 1000, 5000] {
        let cfg = grid_config(junctions);
        let n = cfg.road.nodes.len();
        let (mut tracker, mut t_s) = searching(&cfg);
        let over = Enu2::new(centre_east(&cfg), 0.0);
        let dt = cfg.filter_dt_s();
        g.bench_with_input(BenchmarkId::new("filter_step", n), &n, |b, _| {
            b.iter(|| {
                t_s += dt;
                step_unseen(&mut tracker, t_s, over)
            })
        });
        let view = View::north(over);
        g.bench_with_input(BenchmarkId::new("eer_decision", n), &n, |b, _| {
            b.iter(|| {
                t_s += 1.0;
                tracker
                    .decide(t_s, &view, None, &FrozenClock)
                    .expect("a decision")
            })
        });
    }
    g.finish();
}

criterion_group!(benches, network_scale);
criterion_main!(benches);
