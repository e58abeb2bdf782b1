//! Criterion benches of the core: PF step at N = 500 and 5000, EER cycle (motion model
//! excluded) at N_H = 25, 100, 500 with K = 4. `infotrack bench` times the same fixtures.

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

criterion_group!(benches, pf_step, eer_cycle);
criterion_main!(benches);
