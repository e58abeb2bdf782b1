use crate::testing::Config;
use proptest::prelude::*;
use rand::SeedableRng;

use super::*;
use crate::estimation::road_following::TURN_BACK_MIN_SPEED_SHARE;
use crate::motion::ConstantVelocity;
use crate::rng::CoreRng;

fn setup(n: usize) -> (Config, World, ParticleFilter, CoreRng) {
    let mut c = Config::default_lab();
    c.filter.particles = n;
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(42);
    let pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    (c, world, pf, rng)
}

/// The outdoor world's config (`config/outdoor.toml`).
fn outdoor() -> Config {
    Config::from_toml_str(
        include_str!("../../../../../config/outdoor.toml"),
        std::path::Path::new("config/outdoor.toml"),
    )
    .unwrap()
}

/// `n` straight tracks of `k` positions, `dt_s` apart, along outdoor's y = 0, each ending at
/// `end_x` (m) and driving east at `speed_east(i)` m/s (negative: west).
fn tracks_along_y0(
    n: usize,
    k: usize,
    dt_s: f64,
    end_x: f64,
    speed_east: impl Fn(usize) -> f64,
) -> Histories {
    let mut h = Histories::new(n, k);
    for i in 0..n {
        let tr = h.track_mut(i);
        for t in 0..k {
            tr[2 * t] = end_x - (k - 1 - t) as f64 * speed_east(i) * dt_s;
            tr[2 * t + 1] = 0.0;
        }
    }
    h
}

/// `n` straight tracks of `k` positions driving north at `speed_mps`, each ending at `end`.
fn tracks_north(n: usize, k: usize, dt_s: f64, end: Enu2, speed_mps: f64) -> Histories {
    let mut h = Histories::new(n, k);
    for i in 0..n {
        let tr = h.track_mut(i);
        for t in 0..k {
            tr[2 * t] = end.x;
            tr[2 * t + 1] = end.y - (k - 1 - t) as f64 * speed_mps * dt_s;
        }
    }
    h
}

fn mass_inside(pf: &ParticleFilter, world: &World, agent: &Enu2) -> f64 {
    (0..pf.weights().len())
        .filter(|&i| world.is_wholly_visible(&View::north(*agent), &pf.particle(i)))
        .map(|i| pf.weights()[i])
        .sum()
}

/// A model that returns NaN for every other particle.
struct Broken;
impl MotionModel for Broken {
    fn name(&self) -> &str {
        "broken"
    }
    fn required_history_len(&self) -> Option<usize> {
        None
    }
    fn predict(&mut self, h: &Histories, out: &mut [Enu2]) -> Result<(), MotionError> {
        for (i, o) in out.iter_mut().enumerate() {
            *o = if i % 2 == 0 {
                Enu2::new(f64::NAN, 0.0)
            } else {
                h.newest(i)
            };
        }
        Ok(())
    }
}

#[test]
fn initial_particles_cover_the_workspace_with_equal_weights() {
    let (c, _, pf, _) = setup(2000);
    assert!((pf.weights().iter().sum::<f64>() - 1.0).abs() < 1e-12);
    let mean = pf.mean();
    let centre = c.workspace_enu.center();
    assert!((mean - centre).norm() < 0.1, "{mean} vs {centre}");
    // Uniform over 4 m x 3.2 m: variance w^2/12 and h^2/12.
    let cov = pf.covariance();
    assert!((cov[(0, 0)] - 16.0 / 12.0).abs() < 0.1, "{cov}");
    assert!((cov[(1, 1)] - 3.2 * 3.2 / 12.0).abs() < 0.1, "{cov}");
}

#[test]
fn negative_information_lowers_the_mass_inside_the_footprint() {
    let (c, world, mut pf, mut rng) = setup(2000);
    let agent = Enu2::new(-2.0, 1.5); // away from occlusions
    let before = mass_inside(&pf, &world, &agent);
    assert!(before > 0.01, "some particles start in view: {before}");
    let mut model = ConstantVelocity::new(0.0, c.filter_dt_s());
    pf.step(&mut model, None, &View::north(agent), &world, &mut rng)
        .unwrap();
    let after = mass_inside(&pf, &world, &agent);
    assert!(after < 0.2 * before, "before {before}, after {after}");
}

#[test]
fn a_miss_through_the_detector_says_nothing_where_the_tag_could_be_cut_off() {
    // The lab's 0.1 m tag: a centre within 0.071 m of the view's edge may leave part of
    // the tag outside the image, and the detector misses it. Through the detector a frame
    // without a detection leaves such a particle's weight as it was; with the analytic
    // sensor's world (which sees every centre in view) it takes the miss probability.
    let agent = Enu2::new(-2.0, 1.5); // away from occlusions
    let (c, plain, pf, _) = setup(2000);
    let seen = c.world_seen_by_detector();
    assert!((seen.detection_margin_m - 0.1 / 2f64.sqrt()).abs() < 1e-12);
    let miss = c.filter_params().miss_probability;
    let (mut through_detector, mut analytic) = (pf.clone(), pf.clone());
    through_detector.update(None, &View::north(agent), &seen, false);
    analytic.update(None, &View::north(agent), &plain, false);
    let (mut band, mut inside) = (0, 0);
    for i in 0..pf.weights().len() {
        let p = pf.particle(i);
        let (d, a) = (through_detector.weights()[i], analytic.weights()[i]);
        if plain.is_visible(&View::north(agent), &p)
            && !seen.is_wholly_visible(&View::north(agent), &p)
        {
            band += 1;
            assert!((a - d * miss).abs() <= 1e-12 * d, "{p}: {d} vs {a}");
        } else {
            inside += usize::from(seen.is_wholly_visible(&View::north(agent), &p));
            assert_eq!(d, a, "{p}");
        }
    }
    assert!(
        band >= 10 && inside >= 10,
        "{band} in the band, {inside} inside"
    );
}

#[test]
fn negative_information_does_not_apply_inside_occlusions() {
    let (c, world, mut pf, mut rng) = setup(2000);
    // Footprint centred on occlusion 1: particles there are hidden, so not penalised.
    let agent = Enu2::new(-1.25, -0.6);
    let hidden_mass = |pf: &ParticleFilter| -> f64 {
        (0..pf.weights().len())
            .filter(|&i| world.is_occluded(&pf.particle(i)))
            .map(|i| pf.weights()[i])
            .sum()
    };
    let before = hidden_mass(&pf);
    let mut model = ConstantVelocity::new(0.0, c.filter_dt_s());
    pf.set_weights(&vec![1.0; 2000]);
    let _ = pf
        .step(&mut model, None, &View::north(agent), &world, &mut rng)
        .unwrap();
    let after = hidden_mass(&pf);
    // The footprint (0.84 m) lies inside the 1 m occlusion, so nothing is visible and the
    // hidden mass cannot drop by the miss probability.
    assert!(after > 0.5 * before, "{before} -> {after}");
}

#[test]
fn measurement_pulls_the_estimate_to_the_target() {
    let (c, world, mut pf, mut rng) = setup(500);
    let target = Enu2::new(0.35, -0.6);
    let mut model = ConstantVelocity::new(0.0, c.filter_dt_s());
    for _ in 0..6 {
        let z = world.measurement.measure(&target, &mut rng);
        pf.step(&mut model, Some(z), &View::north(target), &world, &mut rng)
            .unwrap();
    }
    // With a = 0.99 and b = 0.4 the filter often re-seeds around the newest measurement,
    // so the estimate is within a few measurement sigmas (0.1 m) of the truth, and tight.
    assert!((pf.mean() - target).norm() < 0.35, "{}", pf.mean());
    assert!(pf.covariance().determinant() < 1e-3);
}

#[test]
fn resampling_keeps_the_distribution() {
    let (_, _, mut pf, mut rng) = setup(20_000);
    // Weight particles by a bump: the weighted mean and covariance before resampling must
    // match the equally weighted ones after, within Monte Carlo error.
    let w: Vec<f64> = (0..20_000)
        .map(|i| {
            let p = pf.particle(i);
            (-(p - Enu2::new(-1.0, 0.5)).norm_squared() / 0.5).exp()
        })
        .collect();
    assert!(pf.set_weights(&w));
    let (m0, c0) = (pf.mean(), pf.covariance());
    pf.resample_multinomial(&mut rng);
    assert!(pf
        .weights()
        .iter()
        .all(|w| (*w - 1.0 / 20_000.0).abs() < 1e-15));
    let (m1, c1) = (pf.mean(), pf.covariance());
    // sd of the mean ~ sqrt(0.25 / 20000) = 0.0035 per axis; 5 sigma.
    assert!((m1 - m0).norm() < 0.02, "{m0} vs {m1}");
    assert!((c1 - c0).abs().max() < 0.02, "{c0} vs {c1}");
}

#[test]
fn resampling_copies_whole_histories() {
    let (_, _, mut pf, mut rng) = setup(50);
    let mut w = vec![0.0; 50];
    w[7] = 1.0;
    assert!(pf.set_weights(&w));
    let track = pf.histories().track(7).to_vec();
    pf.resample_multinomial(&mut rng);
    for i in 0..50 {
        assert_eq!(pf.histories().track(i), &track[..]);
    }
}

#[test]
fn nonfinite_model_outputs_are_never_taken_in() {
    let (_, world, mut pf, mut rng) = setup(100);
    let r = pf
        .step(
            &mut Broken,
            None,
            &View::north(Enu2::new(-2.0, 1.5)),
            &world,
            &mut rng,
        )
        .unwrap();
    assert_eq!(r.nonfinite_predictions, 50);
    assert!(pf
        .particles()
        .iter()
        .all(|p| p.x.is_finite() && p.y.is_finite()));
    assert_eq!(pf.counters().nonfinite_predictions, 50);
}

#[test]
fn all_particles_in_view_without_a_detection_stays_normalised() {
    let (c, world, mut pf, mut rng) = setup(200);
    // Put every particle under the camera, then report no detection repeatedly: every
    // weight is multiplied by the miss probability and must still normalise.
    let agent = Enu2::new(-2.0, 1.5);
    let target = agent;
    let mut model = ConstantVelocity::new(0.0, c.filter_dt_s());
    for _ in 0..5 {
        let z = world.measurement.measure(&target, &mut rng);
        pf.step(&mut model, Some(z), &View::north(agent), &world, &mut rng)
            .unwrap();
    }
    for _ in 0..20 {
        pf.step(&mut model, None, &View::north(agent), &world, &mut rng)
            .unwrap();
        let s: f64 = pf.weights().iter().sum();
        assert!((s - 1.0).abs() < 1e-9 && pf.weights().iter().all(|w| w.is_finite()));
    }
}

#[test]
fn a_far_measurement_reseeds_instead_of_underflowing() {
    let (c, world, mut pf, mut rng) = setup(300);
    let mut model = ConstantVelocity::new(0.0, c.filter_dt_s());
    let here = Enu2::new(-2.5, 1.8);
    for _ in 0..5 {
        let z = world.measurement.measure(&here, &mut rng);
        pf.step(&mut model, Some(z), &View::north(here), &world, &mut rng)
            .unwrap();
    }
    // The target jumps 4 m: every likelihood underflows in the linear domain.
    let there = Enu2::new(0.8, -1.0);
    let r = pf
        .step(
            &mut model,
            Some(there),
            &View::north(there),
            &world,
            &mut rng,
        )
        .unwrap();
    assert!(matches!(
        r.action,
        ResampleAction::Reseeded | ResampleAction::Recovered
    ));
    assert!(pf.weights().iter().all(|w| w.is_finite()));
}

#[test]
fn a_reseed_through_one_measurement_keeps_the_weighted_belief_of_the_velocity() {
    // Outdoor world: half the particles drive east at 12 m/s and carry all the weight,
    // half drive west; the target comes back into view at (400, 0) after a gap, so the
    // window holds that one measurement. The re-seeded tracks end at the measurement and
    // drive east at 12 m/s (not standing still).
    let c = outdoor();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(11);
    let mut pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let n = pf.weights().len();
    let k = c.filter.history_len;
    let dt = c.filter_dt_s();
    pf.histories = tracks_along_y0(n, k, dt, 380.0, |i| [12.0, -12.0][i % 2]);
    for (i, w) in pf.weights.iter_mut().enumerate() {
        *w = if i % 2 == 0 { 2.0 / n as f64 } else { 0.0 };
    }
    let z = Enu2::new(400.0, 0.0);
    pf.recent.push_back((pf.step_index, z));
    pf.reseed_around_measurements(&world, true, &mut rng);
    let mean_v = (0..n).map(|i| pf.track_velocity(i)).sum::<Enu2>() / n as f64;
    assert!(
        (mean_v - Enu2::new(12.0, 0.0)).norm() < 0.5,
        "mean velocity {mean_v:?}"
    );
    assert!((0..n).all(|i| (pf.particle(i) - z).norm() < 10.0));
    assert!((0..n).all(|i| pf.track_velocity(i).x > 6.0));
    // With two measurements in the window the tracks follow the measurements instead:
    // 3 m apart over one step, 9 m/s. (At the filter's first steps, as here, the slots
    // before its first step take the oldest measurement.)
    pf.step_index += 1;
    pf.recent
        .push_back((pf.step_index, z + Enu2::new(3.0, 0.0)));
    pf.reseed_around_measurements(&world, true, &mut rng);
    let last_step = (0..n)
        .map(|i| pf.histories.newest(i) - pf.histories.at(i, k - 2))
        .sum::<Enu2>()
        / n as f64;
    assert!((last_step.x - 3.0).abs() < 0.5, "last step {last_step:?}");
    let older = (0..n)
        .map(|i| pf.histories.at(i, k - 2) - pf.histories.at(i, 0))
        .sum::<Enu2>()
        / n as f64;
    assert!(older.norm() < 0.5, "slots before the newest: {older:?}");
    // A model that knows the roads (the DMMN) keeps the tracks through one measurement at
    // rest, as before.
    pf.recent.clear();
    pf.recent.push_back((pf.step_index, z));
    pf.reseed_around_measurements(&world, false, &mut rng);
    let at_rest = (0..n).map(|i| pf.track_velocity(i)).sum::<Enu2>() / n as f64;
    assert!(at_rest.norm() < 0.5, "mean velocity {at_rest:?}");
}

#[test]
fn history_length_mismatch_is_a_clear_error() {
    struct NeedsTen;
    impl MotionModel for NeedsTen {
        fn name(&self) -> &str {
            "needs-ten"
        }
        fn required_history_len(&self) -> Option<usize> {
            Some(12)
        }
        fn predict(&mut self, _: &Histories, _: &mut [Enu2]) -> Result<(), MotionError> {
            Ok(())
        }
    }
    let (_, world, mut pf, mut rng) = setup(10);
    let err = pf
        .step(
            &mut NeedsTen,
            None,
            &View::north(Enu2::zeros()),
            &world,
            &mut rng,
        )
        .unwrap_err();
    assert!(err.to_string().contains("12"), "{err}");
}

#[test]
fn same_seed_same_filter() {
    let run = || {
        let (c, world, mut pf, mut rng) = setup(300);
        let mut model = ConstantVelocity::new(0.7, c.filter_dt_s());
        for k in 0..30 {
            let t = Enu2::new(-1.0 + 0.03 * k as f64, 0.5);
            let z = (k % 3 == 0).then(|| world.measurement.measure(&t, &mut rng));
            pf.step(&mut model, z, &View::north(t), &world, &mut rng)
                .unwrap();
        }
        (pf.mean(), pf.covariance())
    };
    assert_eq!(run(), run());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Weights sum to one and stay finite under any sequence of updates.
    #[test]
    fn weights_stay_normalised_and_finite(
        seed in 0u64..1000,
        events in prop::collection::vec((any::<bool>(), -4.0f64..2.0, -2.0f64..3.0), 1..25),
    ) {
        let (c, world, mut pf, _) = setup(64);
        let mut rng = CoreRng::seed_from_u64(seed);
        let mut model = ConstantVelocity::new(0.7, c.filter_dt_s());
        for (measured, x, y) in events {
            let p = Enu2::new(x, y);
            let z = measured.then_some(p);
            pf.step(&mut model, z, &View::north(p), &world, &mut rng).unwrap();
            let s: f64 = pf.weights().iter().sum();
            prop_assert!((s - 1.0).abs() < 1e-9, "sum {}", s);
            prop_assert!(pf.weights().iter().all(|w| w.is_finite() && *w >= 0.0));
            prop_assert!(pf.particles().iter().all(|p| p.x.is_finite() && p.y.is_finite()));
        }
    }
}

#[test]
fn a_blind_step_predicts_without_negative_information() {
    let (c, world, mut pf, mut rng) = setup(2000);
    let mut model = ConstantVelocity::new(0.0, c.filter_dt_s());
    let agent = Enu2::new(-2.0, 1.5); // away from occlusions
    let before = mass_inside(&pf, &world, &agent);
    let weights = pf.weights().to_vec();
    let r = pf.step_blind(&mut model, &mut rng).unwrap();
    assert!(!r.measured);
    assert_eq!(pf.weights(), weights.as_slice(), "weights untouched");
    // Particles moved (prediction ran), but the footprint kept its share of the mass,
    // unlike a step with no measurement (negative information).
    let blind = mass_inside(&pf, &world, &agent);
    assert!((blind - before).abs() < 0.05, "{before} -> {blind}");
    pf.step(&mut model, None, &View::north(agent), &world, &mut rng)
        .unwrap();
    assert!(mass_inside(&pf, &world, &agent) < 0.5 * blind);
}

#[test]
fn particles_at_a_junction_are_rerouted_onto_its_branches_and_only_there() {
    // Outdoor world: every particle 2 m before node 1 (600, 0) driving east at 10 m/s;
    // one step (3.3 m) takes them through the junction: each is re-routed east (0.6) or
    // north (0.4), at its own speed, keeping its weight.
    let c = outdoor();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(5);
    let mut pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let n = pf.weights().len();
    let at = |x: f64| tracks_along_y0(n, c.filter.history_len, c.filter_dt_s(), x, |_| 10.0);
    pf.histories = at(598.0);
    pf.weights
        .iter_mut()
        .enumerate()
        .for_each(|(i, w)| *w = (1 + i % 3) as f64);
    let weights_before = pf.weights().to_vec();
    pf.reroute_at_junctions(&world, &mut rng);
    // They are spread over the step: 2 m before the junction, 1.33 m after it on each
    // branch; past the junction the branches share them as 0.4 to 0.6.
    let north = (0..n).filter(|&i| pf.particle(i).y > 1e-6).count();
    let east = (0..n)
        .filter(|&i| pf.particle(i).x > 600.0 && pf.particle(i).y.abs() < 1e-6)
        .count();
    let share = north as f64 / (north + east) as f64;
    assert!(
        north + east > n / 3,
        "particles past the junction: {}",
        north + east
    );
    assert!(
        (share - 0.4).abs() < 0.15,
        "north share {share} ({north} / {east})"
    );
    // Every particle is on the road, at its speed, with its weight.
    assert!((0..n).all(|i| world.road.distance_to_roads(&pf.particle(i)) < 1e-6));
    assert!((0..n).all(|i| (pf.track_velocity(i).norm() - 10.0).abs() < 1e-6));
    assert_eq!(pf.weights(), &weights_before[..]);
    // Mid-edge (far from any junction): the particles stay as they were.
    pf.histories = at(300.0);
    let before: Vec<Enu2> = (0..n).map(|i| pf.particle(i)).collect();
    pf.reroute_at_junctions(&world, &mut rng);
    assert!((0..n).all(|i| pf.particle(i) == before[i]));
}

#[test]
fn particles_at_a_junction_with_a_two_way_street_turn_back_by_its_probability() {
    // Outdoor: every particle 2 m before node 6 (600, 400) driving north at 10 m/s on the
    // two-way street 1 <-> 6; from 6 the car goes on north to 4 (p 0.7) or back south to 1
    // (p 0.3), as the simulated car does. Past the junction the belief takes both, the turn
    // back at its probability, slowed (a car turns round slower than it cruises: from
    // TURN_BACK_MIN_SPEED_SHARE of its speed to all of it); none is left driving north beyond
    // the step.
    let c = outdoor();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(11);
    let mut pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let (n, k, dt) = (pf.weights().len(), c.filter.history_len, c.filter_dt_s());
    pf.histories = tracks_north(n, k, dt, Enu2::new(600.0, 398.0), 10.0);
    let weights_before = pf.weights().to_vec();
    pf.reroute_at_junctions(&world, &mut rng);
    let heading = |i: usize| pf.track_velocity(i);
    let back = (0..n).filter(|&i| heading(i).y < 0.0).count();
    let on = (0..n)
        .filter(|&i| heading(i).y > 9.9 && pf.particle(i).y > 400.0 + 1e-9)
        .count();
    let share = back as f64 / (back + on) as f64;
    assert!(
        back + on > n / 3,
        "particles past the junction: {}",
        back + on
    );
    assert!(
        (share - 0.3).abs() < 0.1,
        "turned back {share} ({back} back, {on} on)"
    );
    for i in 0..n {
        let p = pf.particle(i);
        assert!(
            world.road.distance_to_roads(&p) < 1e-6,
            "off the road: {p:?}"
        );
        let speed = heading(i).norm();
        if heading(i).y < 0.0 {
            let slowest = TURN_BACK_MIN_SPEED_SHARE * 10.0;
            assert!(
                (slowest - 1e-6..=10.0 + 1e-6).contains(&speed),
                "turned back at {speed}"
            );
        } else {
            assert!(
                (speed - 10.0).abs() < 1e-6,
                "speed changed on the way on: {speed}"
            );
        }
        assert!(
            heading(i).x.abs() < 1e-6,
            "left the street: {:?}",
            heading(i)
        );
    }
    // The turn backs' speeds spread over the range rather than one value.
    let back_speeds: Vec<f64> = (0..n)
        .filter(|&i| heading(i).y < 0.0)
        .map(|i| heading(i).norm())
        .collect();
    let slowest = back_speeds.iter().cloned().fold(f64::INFINITY, f64::min);
    let fastest = back_speeds.iter().cloned().fold(0.0, f64::max);
    assert!(
        slowest < 5.0 && fastest > 9.0,
        "turn-back speeds {slowest}..{fastest}"
    );
    assert_eq!(pf.weights(), &weights_before[..]);
}

/// Outdoor's road 0 -> 1 (y = 0, x 0..600) is one-way east. Particles at x = 300 on it:
/// a third driving east at 10 m/s, a third west at 10 m/s, a third creeping west at
/// 0.3 m/s (a step well inside the process noise).
fn one_way_road_tracks() -> (Config, World, ParticleFilter) {
    let c = outdoor();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(8);
    let mut pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let n = pf.weights().len();
    let k = c.filter.history_len;
    let dt = c.filter_dt_s();
    pf.histories = tracks_along_y0(n, k, dt, 300.0, |i| [10.0, -10.0, -0.3][i % 3]);
    pf.set_weights(&vec![1.0; n]);
    (c, world, pf)
}

/// The mean weight of each third of [`one_way_road_tracks`] after one update with no
/// detection and nothing in view (`headings`: the motion model does not know the roads).
fn weights_by_track(pf: &mut ParticleFilter, world: &World, headings: bool) -> [f64; 3] {
    // Far from the road: the footprint holds no particle, only the road constraint acts.
    pf.update(
        None,
        &View::north(Enu2::new(1300.0, 900.0)),
        world,
        headings,
    );
    let (mut sums, mut counts) = ([0.0; 3], [0.0; 3]);
    for (i, w) in pf.weights().iter().enumerate() {
        sums[i % 3] += w;
        counts[i % 3] += 1.0;
    }
    [0, 1, 2].map(|k| sums[k] / counts[k])
}

#[test]
fn a_track_driving_a_one_way_road_the_wrong_way_fades() {
    let (c, world, mut pf) = one_way_road_tracks();
    let [east, west, creeping] = weights_by_track(&mut pf, &world, true);
    // On the road, the right way: untouched by the constraint (distance 0).
    assert!(
        east > 0.0 && (creeping - east).abs() < 1e-9 * east,
        "{east} {creeping}"
    );
    // The wrong way: as if two road sigmas off the road, e^-2 of the others.
    let expected = (-2.0f64).exp();
    assert!(
        (west / east - expected).abs() < 1e-9,
        "west/east {} (expected {expected})",
        west / east
    );
    // For a model that knows the roads (the DMMN), the nearest road whatever the heading.
    let (_, world, mut pf) = one_way_road_tracks();
    let [east, west, creeping] = weights_by_track(&mut pf, &world, false);
    assert_eq!((east, west), (creeping, creeping));
    // Without a road constraint nothing is weighed at all.
    let mut params = c.filter_params();
    params.road_sigma_m = None;
    let (_, world, mut pf) = one_way_road_tracks();
    pf.params = params;
    let [east, west, creeping] = weights_by_track(&mut pf, &world, true);
    assert_eq!((east, west), (creeping, creeping));
}

/// `config/field-grid.toml`: at node 1 (500, 0), under an overpass, a car driving east
/// turns north (to 500, 500) or goes on east (to 1000, 0), even odds.
fn field_grid() -> Config {
    Config::from_toml_str(
        include_str!("../../../../../config/field-grid.toml"),
        std::path::Path::new("config/field-grid.toml"),
    )
    .unwrap()
}

/// The weight on the northbound and on the eastbound branch after the fork at (500, 0).
fn branch_weights(pf: &ParticleFilter) -> (f64, f64) {
    let mut north_east = (0.0, 0.0);
    for (i, w) in pf.weights().iter().enumerate() {
        let p = pf.particle(i);
        if (p.x - 500.0).abs() < 1e-6 && p.y > 40.0 {
            north_east.0 += w;
        } else if p.y.abs() < 1e-6 && p.x > 530.0 {
            north_east.1 += w;
        }
    }
    north_east
}

/// field-grid's config and world, and a filter over its workspace drawn with `seed`.
fn field_grid_filter(seed: u64) -> (Config, World, ParticleFilter, CoreRng) {
    let c = field_grid();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(seed);
    let pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    (c, world, pf, rng)
}

#[test]
fn a_spread_along_routes_keeps_out_what_the_empty_frames_ruled_out() {
    let (c, world, mut pf, mut rng) = field_grid_filter(8);
    let start = RouteStart::At(Enu2::new(468.0, 0.0), Some(Enu2::new(12.0, 0.0)));
    // Ten seconds on at 8.4-15.6 m/s: 84-156 m of road, through the fork either way.
    assert!(pf.spread_along_routes(&world, start, 8.4..=15.6, 10.0, &[], &mut rng));
    let (north, east) = branch_weights(&pf);
    assert!(north > 0.4 && east > 0.4, "{north} {east}");
    let k = c.filter.history_len;
    for i in 0..pf.weights().len() {
        let p = pf.particle(i);
        assert!(world.road.distance_to_roads(&p) < 1e-6, "{p}");
        // The history is the route: its last step is one period at the particle's speed.
        let h = pf.histories();
        let step = (h.newest(i) - h.at(i, k - 2)).norm() / c.filter_params().dt_s;
        assert!((8.3..=15.7).contains(&step), "{step}");
    }
    // A camera over the east exit (550, 0) from 3 s on saw nothing: every eastbound route
    // drove through its view, no northbound one did.
    let looked: Vec<(f64, View)> = (9..=30)
        .map(|j| (j as f64 / 3.0, View::north(Enu2::new(550.0, 0.0))))
        .collect();
    assert!(pf.spread_along_routes(&world, start, 8.4..=15.6, 10.0, &looked, &mut rng));
    let (north, east) = branch_weights(&pf);
    assert!(north > 0.99 && east < 1e-3, "{north} {east}");
    assert!((pf.weights().iter().sum::<f64>() - 1.0).abs() < 1e-9);
}

#[test]
fn a_kept_share_gives_the_belief_before_the_re_spread_its_weight_back() {
    let (c, world, mut pf, mut rng) = field_grid_filter(9);
    // Before: the whole belief on the northbound branch (its weight there 1).
    let north = RouteStart::At(Enu2::new(500.0, 60.0), Some(Enu2::new(0.0, 12.0)));
    assert!(pf.spread_along_routes(&world, north, 10.0..=10.0, 1.0, &[], &mut rng));
    let before = pf.clone();
    assert!(branch_weights(&before).0 > 0.999);
    // The re-spread: every route east, past the fork.
    let east = RouteStart::At(Enu2::new(560.0, 0.0), Some(Enu2::new(12.0, 0.0)));
    assert!(pf.spread_along_routes(&world, east, 10.0..=10.0, 1.0, &[], &mut rng));
    assert!(branch_weights(&pf).1 > 0.999);
    // Refused, nothing changed: a share outside (0, 1), or filters of different sizes.
    let respread = pf.weights().to_vec();
    for share in [0.0, 1.0, f64::NAN, -0.5] {
        assert!(!pf.keep_part_of(&before, share, &mut rng), "{share}");
    }
    let mut other = ParticleFilter::new(
        FilterParams {
            particles: 10,
            ..c.filter_params()
        },
        c.workspace_enu,
        &mut rng,
    );
    assert!(!other.keep_part_of(&before, 0.5, &mut rng));
    assert_eq!(pf.weights(), &respread[..]);
    // Kept: a share of the particles back on their old tracks with that share of the weight.
    for share in [0.3, 0.5] {
        let mut mixed = pf.clone();
        assert!(mixed.keep_part_of(&before, share, &mut rng));
        let (n, e) = branch_weights(&mixed);
        assert!(
            (n - share).abs() < 1e-9 && (e - (1.0 - share)).abs() < 1e-9,
            "{n} {e}"
        );
        let back = (0..mixed.weights().len())
            .filter(|&i| mixed.histories().track(i) == before.histories().track(i))
            .count() as f64;
        let n_all = mixed.weights().len() as f64;
        assert!((back / n_all - share).abs() < 0.1, "{back} of {n_all}");
    }
}

/// The weighted share of the particles whose last step is slower than `mps`.
fn weight_slower_than(pf: &ParticleFilter, mps: f64, dt_s: f64) -> f64 {
    let h = pf.histories();
    let k = h.k_in();
    (0..pf.weights().len())
        .filter(|&i| (h.newest(i) - h.at(i, k - 2)).norm() / dt_s < mps)
        .map(|i| pf.weights()[i])
        .sum()
}

#[test]
fn a_spread_from_a_measurement_short_of_an_occlusion_keeps_the_slower_routes() {
    // field-grid's overpass covers x 470-530 on the road y = 0. The car was last measured
    // 4 m short of it, driving east; the camera over that point saw nothing a third of a
    // second later. At 7-13 m/s a car starting exactly at the measurement is still in view
    // then unless it drives faster than 12 m/s; one starting where the measurement's noise
    // (1 m) puts it may be under the overpass already at any of those speeds.
    let c = field_grid();
    let world = c.world();
    let dt = c.filter_params().dt_s;
    let mut rng = CoreRng::seed_from_u64(5);
    let mut pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let z = Enu2::new(466.0, 0.0);
    let start = RouteStart::At(z, Some(Enu2::new(10.0, 0.0)));
    // Two seconds on, every route is under the overpass, short of its junction at x = 500.
    let looked: Vec<(f64, View)> = (1..=6).map(|j| (j as f64 / 3.0, View::north(z))).collect();
    assert!(pf.spread_along_routes(&world, start, 7.0..=13.0, 2.0, &looked, &mut rng));
    let slower = weight_slower_than(&pf, 11.0, dt);
    assert!(slower > 0.2, "weight on routes under 11 m/s: {slower}");
    let n_eff = pf.n_eff();
    assert!(n_eff > 0.1 * pf.weights().len() as f64, "N_eff {n_eff}");
    // What the first frame saw stays ruled out: the history's fifth slot is where each
    // route was then (2 s driven, ten slots a third of a second apart, the first ones at
    // the start).
    let h = pf.histories();
    assert_eq!((h.k_in(), dt), (10, 1.0 / 3.0));
    let mut refuted = 0;
    for (i, w) in pf.weights().iter().enumerate() {
        if world.is_wholly_visible(&View::north(z), &h.at(i, 4)) {
            refuted += 1;
            assert!(*w < 1e-6, "{} {w}", h.at(i, 4));
        }
    }
    assert!(refuted > 100, "{refuted} routes in the first frame's view");
}

#[test]
fn particles_off_the_road_beside_one_piece_are_put_back_on_it() {
    // Outdoor world: every particle 20 m north of the y = 0 road mid-edge (x = 300, far from
    // any junction), driving east at 10 m/s. The one piece of road within its step is the
    // road's own: each is put on it, east at its speed, keeping its weight. Counted as
    // following its road, such a track ran on 20 m off it (BENCHMARKS.md).
    let c = outdoor();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(9);
    let mut pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let (n, k, dt) = (pf.weights().len(), c.filter.history_len, c.filter_dt_s());
    // Tracks along y0, moved `beside_m` north.
    let beside = |beside_m: f64| {
        let mut h = tracks_along_y0(n, k, dt, 300.0, |_| 10.0);
        for i in 0..n {
            let tr = h.track_mut(i);
            (0..k).for_each(|t| tr[2 * t + 1] = beside_m);
        }
        h
    };
    pf.histories = beside(20.0);
    let weights_before = pf.weights().to_vec();
    pf.reroute_at_junctions(&world, &mut rng);
    for i in 0..n {
        let p = pf.particle(i);
        assert!(
            p.y.abs() < 1e-6 && p.x > 299.0 && p.x < 305.0,
            "not on the road ahead: {p:?}"
        );
        let v = pf.track_velocity(i);
        assert!(
            (v - Enu2::new(10.0, 0.0)).norm() < 1e-6,
            "not east at 10 m/s: {v:?}"
        );
    }
    assert_eq!(pf.weights(), &weights_before[..]);
    // On the road, or 5 m beside it (within STRAY_ON_ROAD_TOLERANCES: a car off the
    // centre line), a track is left alone.
    for beside_m in [0.0, 5.0] {
        pf.histories = beside(beside_m);
        pf.reroute_at_junctions(&world, &mut rng);
        let at = Enu2::new(300.0, beside_m);
        assert!(
            (0..n).all(|i| (pf.particle(i) - at).norm() < 1e-9),
            "moved from {at:?}"
        );
    }
}

#[test]
fn particles_at_a_dead_end_turn_back_along_its_road() {
    // field-twin's spur runs north from node 4 (500, 70) to node 6 (500, 500), the warehouse,
    // and the only way on from 6 is back south. Every particle 2 m before the end driving
    // north at 15 m/s: one step (5 m) runs off the road's end; each turns back along the
    // spur, slowed to between TURN_BACK_MIN_SPEED_SHARE of its speed and all of it, keeping
    // its weight. Straight on, the belief left the road.
    let c = Config::from_toml_str(
        include_str!("../../../../../config/field-twin.toml"),
        std::path::Path::new("config/field-twin.toml"),
    )
    .unwrap();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(6);
    let mut pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let (n, k, dt) = (pf.weights().len(), c.filter.history_len, c.filter_dt_s());
    pf.histories = tracks_north(n, k, dt, Enu2::new(500.0, 498.0), 15.0);
    let weights_before = pf.weights().to_vec();
    pf.reroute_at_junctions(&world, &mut rng);
    for i in 0..n {
        let p = pf.particle(i);
        assert!(
            world.road.distance_to_roads(&p) < 1e-6,
            "off the road: {p:?}"
        );
        assert!(p.y <= 500.0 + 1e-9, "past the end: {p:?}");
        let v = pf.track_velocity(i);
        assert!(
            v.y < -TURN_BACK_MIN_SPEED_SHARE * 15.0 + 1e-6
                && v.y > -15.0 - 1e-6
                && v.x.abs() < 1e-6,
            "not turned back south: {v:?}"
        );
    }
    assert_eq!(pf.weights(), &weights_before[..]);
}

/// A frame without the target from a turned view (the nose east at field scale: the 58 m
/// width north-south) lowers exactly the particles inside that turned rectangle, not those
/// of the north view the paper's agent would have seen from the same place.
#[test]
fn negative_information_follows_the_views_heading() {
    let mut c = outdoor();
    c.filter.particles = 40_000;
    let mut world = c.world();
    world.occlusions.clear();
    let mut rng = CoreRng::seed_from_u64(8);
    let pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let centre = Enu2::new(300.0, 200.0);
    let turned = View::new(centre, 0.0);
    let north = View::north(centre);
    let (mut after_turned, mut after_north) = (pf.clone(), pf.clone());
    after_turned.update(None, &turned, &world, false);
    after_north.update(None, &north, &world, false);
    let miss = c.filter_params().miss_probability;
    let (mut only_turned, mut only_north) = (0, 0);
    for i in 0..pf.weights().len() {
        let p = pf.particle(i);
        let (in_turned, in_north) = (
            world.is_wholly_visible(&turned, &p),
            world.is_wholly_visible(&north, &p),
        );
        only_turned += usize::from(in_turned && !in_north);
        only_north += usize::from(in_north && !in_turned);
        let (t, n) = (after_turned.weights()[i], after_north.weights()[i]);
        let want = match (in_turned, in_north) {
            (true, false) => n * miss,
            (false, true) => n / miss,
            _ => n,
        };
        assert!(
            (t - want).abs() <= 1e-12 * want.abs().max(1e-300),
            "{p}: {t} vs {want}"
        );
        // A turned view reaches 29 m north and 15.5 m east, a north view the other way.
        if in_turned && !in_north {
            assert!(
                (p.y - centre.y).abs() > world.footprint.half_height_m,
                "{p}"
            );
        }
    }
    assert!(
        only_turned > 5 && only_north > 5,
        "{only_turned} {only_north}"
    );
}
