//! Criterion benches of the core: PF step at N = 500 and 5000, EER cycle (motion model
//! excluded) at N_H = 25, 100, 500 with K = 4. `infotrack bench` times the same fixtures.
//! The ambush's choice of a waiting point on the outdoor world (1000 hypotheses spread over
//! its roads; `guidance::ambush`), one decision's extra work while it is in force.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
mod fixtures;
use fixtures::{EerFixture, PfFixture};

fn pf_step(c: &mut Criterion) {
    let mut g = c.benchmark_group("pf_step_cv");
    for n in [500usize, 5000] {
        let mut f = PfFixture::new(n, 1);
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| f.step())
        });
    }
    g.finish();
}

fn eer_cycle(c: &mut Criterion) {
    let mut g = c.benchmark_group("eer_cycle_k4");
    for n_h in [25usize, 100, 500] {
        let mut f = EerFixture::new(500, n_h, 1);
        g.bench_with_input(BenchmarkId::new("decide", n_h), &n_h, |b, _| {
            b.iter(|| f.decide())
        });
        g.bench_with_input(BenchmarkId::new("rollout_cv", n_h), &n_h, |b, _| {
            b.iter(|| f.prepare())
        });
    }
    g.finish();
}

fn ambush_choice(c: &mut Criterion) {
    use infotrack::config::Config;
    use infotrack::guidance::ambush::{choose, AmbushParams, Hypothesis, DEFAULT_AMBUSH_WINDOW_S};
    use rand::SeedableRng;
    let world = Config::from_toml_str(
        include_str!("../config/outdoor.toml"),
        std::path::Path::new("config/outdoor.toml"),
    )
    .expect("config/outdoor.toml")
    .world();
    // 1000 hypotheses on the roads, each driving along its road at 10 m/s.
    let mut rng = infotrack::rng::CoreRng::seed_from_u64(1);
    let pieces = world.road.roads_within(None);
    let belief: Vec<Hypothesis> = (0..1000)
        .filter_map(|_| pieces.sample(&mut rng))
        .map(|(p, dir)| Hypothesis {
            position_enu: p,
            velocity_enu: dir * 10.0,
            weight: 1.0,
        })
        .collect();
    let params = AmbushParams::new(DEFAULT_AMBUSH_WINDOW_S);
    let agent = infotrack::frames::Enu2::new(300.0, 200.0);
    c.bench_function("ambush_choose_outdoor_1000", |b| {
        b.iter(|| choose(&params, &belief, &world, &agent, 16.0, None, 0.2, &mut rng))
    });
}

criterion_group!(benches, pf_step, eer_cycle, ambush_choice);
criterion_main!(benches);
