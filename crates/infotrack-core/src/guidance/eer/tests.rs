use crate::testing::Config;
use rand::{Rng, SeedableRng};

use super::*;
use crate::estimation::RouteStart;
use crate::guidance::ViewHeading;
use crate::motion::ConstantVelocity;
use crate::rng::CoreRng;

fn random_inputs(rng: &mut CoreRng, n: usize, n_m: usize, world: &World) -> EerInputs {
    let mut inp = EerInputs {
        n_m,
        ..Default::default()
    };
    for _ in 0..n {
        // Around both occlusions and the open floor, so every branch is exercised.
        let c = Enu2::new(rng.gen_range(-2.0..1.0), rng.gen_range(-1.0..1.5));
        inp.current.push(c);
        inp.predicted
            .push(c + Enu2::new(rng.gen_range(-0.3..0.3), rng.gen_range(-0.3..0.3)));
        inp.weights.push(rng.gen_range(0.1..1.0));
    }
    let s: f64 = inp.weights.iter().sum();
    inp.weights.iter_mut().for_each(|w| *w /= s);
    for j in 0..n {
        for _ in 0..n_m {
            let z = world.measurement.measure(&inp.predicted[j], rng);
            inp.measurements.push(z);
            inp.alpha.push(inp.weights[j] * rng.gen_range(0.5..1.5));
        }
    }
    let s: f64 = inp.alpha.iter().sum();
    inp.alpha.iter_mut().for_each(|a| *a /= s);
    inp
}

/// A belief of `n` equally weighted particles at rest, particle `k` where `place(k, rng)`
/// puts it, now and at the horizon's end, each with one simulated measurement.
fn still_belief(
    n: usize,
    world: &World,
    rng: &mut CoreRng,
    mut place: impl FnMut(usize, &mut CoreRng) -> Enu2,
) -> EerInputs {
    let mut inp = EerInputs {
        n_m: 1,
        ..Default::default()
    };
    for k in 0..n {
        let p = place(k, rng);
        inp.current.push(p);
        inp.predicted.push(p);
        inp.velocity.push(Enu2::zeros());
        inp.weights.push(1.0 / n as f64);
        inp.measurements.push(world.measurement.measure(&p, rng));
        inp.alpha.push(1.0 / n as f64);
    }
    inp
}

#[test]
fn fast_eer_equals_reference_on_random_inputs() {
    let mut c = Config::default_lab();
    // A wide kernel and a moderate miss probability keep every term well away from
    // underflow in the reference's linear-domain arithmetic.
    c.guidance.entropy_kernel_cov_m2 = [[0.05, 0.01], [0.01, 0.04]];
    let kernel = Gaussian2::new(c.guidance.entropy_kernel_cov_m2);
    let mut rng = CoreRng::seed_from_u64(9);
    // The analytic sensor's world, and the detector's (whole tags: a margin inside the view
    // and around the occlusions).
    let worlds = [c.world(), c.world_seen_by_detector()];
    let trials = [(12, 1, 1e-3), (9, 3, 0.2), (15, 2, 1.0), (6, 1, 1e-10)];
    for (trial, (world, &(n, n_m, p_miss))) in worlds
        .iter()
        .flat_map(|w| trials.iter().map(move |t| (w, t)))
        .enumerate()
    {
        let inp = random_inputs(&mut rng, n, n_m, world);
        let agent = Enu2::new(-0.5, 0.4);
        let cands = candidates(&inp, &agent, 1.2, ReachShape::Square, 5, world);
        let mut scratch = EerScratch::default();
        let (h_fast, fast) = evaluate_fast(&inp, &cands, world, &kernel, p_miss, &mut scratch);
        let (h_ref, reference) = evaluate_reference(&inp, &cands, world, &kernel, p_miss);
        assert!(
            (h_fast - h_ref).abs() < 1e-9,
            "trial {trial}: {h_fast} vs {h_ref}"
        );
        let mut differing = 0;
        for (a, b) in fast.iter().zip(&reference) {
            assert!(
                (a - b).abs() < 1e-9,
                "trial {trial}: fast {a} vs reference {b}"
            );
            if (a - fast[0]).abs() > 1e-6 {
                differing += 1;
            }
        }
        assert!(differing > 0, "trial {trial}: candidates must not all tie");
    }
}

#[test]
fn the_detector_margin_changes_what_a_candidate_sees() {
    // Particles in the band along the view's edge count as seen for the analytic sensor
    // and not through the detector: some candidate's EER differs.
    let mut c = Config::default_lab();
    c.guidance.entropy_kernel_cov_m2 = [[0.05, 0.01], [0.01, 0.04]];
    let kernel = Gaussian2::new(c.guidance.entropy_kernel_cov_m2);
    let (plain, seen) = (c.world(), c.world_seen_by_detector());
    let mut rng = CoreRng::seed_from_u64(9);
    let inp = random_inputs(&mut rng, 40, 1, &plain);
    let cands = candidates(
        &inp,
        &Enu2::new(-0.5, 0.4),
        1.2,
        ReachShape::Square,
        5,
        &plain,
    );
    let mut scratch = EerScratch::default();
    let (_, a) = evaluate_fast(&inp, &cands, &plain, &kernel, 1e-3, &mut scratch);
    let (_, b) = evaluate_fast(&inp, &cands, &seen, &kernel, 1e-3, &mut scratch);
    assert!(a.iter().zip(&b).any(|(x, y)| (x - y).abs() > 1e-6));
}

#[test]
fn eer_prefers_the_candidate_that_sees_the_particles() {
    let c = Config::default_lab();
    let world = c.world();
    let kernel = Gaussian2::new(c.guidance.entropy_kernel_cov_m2);
    let mut rng = CoreRng::seed_from_u64(2);
    // All mass in a 0.3 m cluster on open floor; one candidate over it, one far away.
    let inp = still_belief(30, &world, &mut rng, |_, rng| {
        Enu2::new(
            -2.2 + rng.gen_range(-0.15..0.15),
            1.3 + rng.gen_range(-0.15..0.15),
        )
    });
    let cands = [Enu2::new(-2.2, 1.3), Enu2::new(0.5, -1.0)];
    let (_, eer) = evaluate_fast(
        &inp,
        &cands,
        &world,
        &kernel,
        1e-10,
        &mut EerScratch::default(),
    );
    assert!(eer[0] > eer[1] + 0.1, "{eer:?}");
}

#[test]
fn occluded_particles_give_no_information() {
    let c = Config::default_lab();
    let world = c.world();
    let kernel = Gaussian2::new(c.guidance.entropy_kernel_cov_m2);
    let mut rng = CoreRng::seed_from_u64(3);
    // Every particle inside occlusion 1: no candidate can measure or miss them.
    let inp = still_belief(20, &world, &mut rng, |_, rng| {
        Enu2::new(
            -1.25 + rng.gen_range(-0.3..0.3),
            -0.6 + rng.gen_range(-0.3..0.3),
        )
    });
    let cands = [Enu2::new(-1.25, -0.6), Enu2::new(0.5, 1.5)];
    let (_, eer) = evaluate_fast(
        &inp,
        &cands,
        &world,
        &kernel,
        1e-10,
        &mut EerScratch::default(),
    );
    assert!((eer[0] - eer[1]).abs() < 1e-12, "{eer:?}");
}

#[test]
fn planner_waypoints_stay_inside_the_geofence_and_count_candidates() {
    let c = Config::default_lab();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(4);
    let pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let mut model = ConstantVelocity::new(0.7, c.filter_dt_s());
    let mut planner = EerPlanner::new(c.eer_params());
    for agent in [
        Enu2::new(0.9, 1.9),
        Enu2::new(-2.9, -1.1),
        Enu2::new(-1.0, 0.5),
    ] {
        let d = planner
            .plan(
                &pf,
                &mut model,
                &View::north(agent),
                &HeadingRule::north(),
                &world,
                &mut rng,
            )
            .unwrap();
        assert!(
            c.workspace_enu.contains(&d.waypoint_enu),
            "{}",
            d.waypoint_enu
        );
        assert_eq!(d.candidates, 25 + 16 * 16);
        assert!(d.eer.is_finite() && d.h_now.is_finite());
    }
}

#[test]
fn all_particles_used_when_n_h_equals_n() {
    let mut c = Config::default_lab();
    c.filter.particles = 40;
    c.guidance.entropy_particles = 40;
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(5);
    let pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    let mut model = ConstantVelocity::new(0.7, c.filter_dt_s());
    let mut planner = EerPlanner::new(c.eer_params());
    let inp = planner.prepare(&pf, &mut model, &world, &mut rng).unwrap();
    assert_eq!(inp.current, pf.particles());
    assert!((inp.alpha.iter().sum::<f64>() - 1.0).abs() < 1e-12);
}

#[test]
fn fast_measured_entropy_equals_the_plain_formula() {
    use crate::guidance::entropy::entropy_measured;
    let c = Config::default_lab();
    let world = c.world();
    let kernel = Gaussian2::new([[0.02, 0.0], [0.0, 0.02]]);
    let mut rng = CoreRng::seed_from_u64(11);
    let inp = random_inputs(&mut rng, 40, 1, &world);
    let log_s = log_transition_sums(&inp.predicted, &inp.predicted, &inp.weights, &kernel);
    let log_w: Vec<f64> = inp.weights.iter().map(|w| w.ln()).collect();
    let mut buf = vec![0.0; 40];
    for z in &inp.measurements {
        let a = entropy_measured(
            z,
            &inp.predicted,
            &inp.weights,
            &log_s,
            &world.measurement.noise,
        );
        let b = entropy_measured_fast(
            z,
            &inp.predicted,
            &log_w,
            &log_s,
            &world.measurement.noise,
            &mut buf,
        );
        assert!((a - b).abs() < 1e-10, "{a} vs {b}");
    }
}

/// A filter of 200 particles over the lab, with the weight either on the particles within
/// `radius_m` of the workspace's centre or spread over all of them.
fn lab_filter(c: &Config, radius_m: Option<f64>) -> ParticleFilter {
    let mut rng = CoreRng::seed_from_u64(21);
    let mut pf = ParticleFilter::new(c.filter_params(), c.workspace_enu, &mut rng);
    if let Some(r) = radius_m {
        let centre = c.workspace_enu.center();
        let w: Vec<f64> = (0..pf.weights().len())
            .map(|i| f64::from(u8::from((pf.particle(i) - centre).norm() <= r)))
            .collect();
        assert!(
            pf.set_weights(&w),
            "some particle within {r} m of the centre"
        );
    }
    pf
}

#[test]
fn a_belief_inside_one_view_is_concentrated_and_a_spread_one_is_not() {
    let mut c = Config::default_lab();
    c.filter.particles = 200;
    let world = c.world();
    let fp = world.footprint;
    assert!(belief_is_concentrated(
        &lab_filter(&c, Some(0.9 * world.footprint.quarter_view_m())),
        &world
    ));
    assert!(!belief_is_concentrated(
        &lab_filter(&c, Some(3.0 * fp.half_width_m.max(fp.half_height_m))),
        &world
    ));
    assert!(!belief_is_concentrated(&lab_filter(&c, None), &world));
}

#[test]
fn a_concentrated_belief_is_planned_with_the_concentrated_hypothesis_count() {
    let mut c = Config::default_lab();
    c.filter.particles = 200;
    c.guidance.entropy_particles = 200;
    c.guidance.entropy_particles_concentrated = Some(30);
    let world = c.world();
    let mut model = ConstantVelocity::new(0.7, c.filter_dt_s());
    let mut rng = CoreRng::seed_from_u64(4);
    let mut hypotheses = |planner: &mut EerPlanner, pf: &ParticleFilter| {
        planner
            .prepare(pf, &mut model, &world, &mut rng)
            .unwrap()
            .current
            .len()
    };
    let tight = lab_filter(&c, Some(0.9 * world.footprint.quarter_view_m()));
    let spread = lab_filter(&c, None);
    let mut planner = EerPlanner::new(c.eer_params());
    assert_eq!(hypotheses(&mut planner, &tight), 30);
    assert_eq!(hypotheses(&mut planner, &spread), 200);
    // Absent, the key means entropy_particles always.
    c.guidance.entropy_particles_concentrated = None;
    let mut planner = EerPlanner::new(c.eer_params());
    assert_eq!(hypotheses(&mut planner, &tight), 200);
}

/// A disc of reach keeps every grid candidate within the reach of the agent, with the rim's
/// diagonal directions still among them; a square's corners are sqrt(2) x reach away.
#[test]
fn a_disc_of_reach_keeps_the_grid_within_reach() {
    let c = Config::default_lab();
    let world = c.world();
    let inp = EerInputs::default();
    let agent = Enu2::new(0.0, 0.0);
    let reach = 0.5;
    let far = |cands: &[Enu2]| cands.iter().map(|p| (p - agent).norm()).fold(0.0, f64::max);
    let disc = candidates(&inp, &agent, reach, ReachShape::Disc, 5, &world);
    let square = candidates(&inp, &agent, reach, ReachShape::Square, 5, &world);
    assert_eq!(disc.len(), 25);
    assert!((far(&disc) - reach).abs() < 1e-12, "{}", far(&disc));
    assert!((far(&square) - std::f64::consts::SQRT_2 * reach).abs() < 1e-12);
    let diagonal = Enu2::new(reach, reach) / std::f64::consts::SQRT_2;
    assert!(disc.iter().any(|p| (p - diagonal).norm() < 1e-12));
}

/// A particle driving straight away from the agent is met where both have covered the
/// same time: lead = (D - s H) / (s - v); a parked one is met at its own position, lead =
/// (D - s H) / s; one within a horizon's reach needs none; one faster than the agent is
/// looked ahead by the cap.
#[test]
fn the_intercept_lead_is_when_the_agent_meets_the_particle() {
    let agent = Enu2::new(10.0, -5.0);
    let (s, h, d, v) = (15.0, 2.0, 200.0, 10.0);
    let away = Enu2::new(0.6, 0.8);
    let p = agent + away * d;
    let lead = intercept_lead_s(&agent, &p, &(away * v), s, h, 60.0);
    assert!((lead - (d - s * h) / (s - v)).abs() < 1e-9, "{lead}");
    // The meeting point is as far from the agent as it flies in horizon + lead.
    let met = p + away * v * lead;
    assert!(((met - agent).norm() - s * (h + lead)).abs() < 1e-9);
    let parked = intercept_lead_s(&agent, &p, &Enu2::zeros(), s, h, 60.0);
    assert!((parked - (d - s * h) / s).abs() < 1e-9, "{parked}");
    let towards = intercept_lead_s(&agent, &p, &(-away * v), s, h, 60.0);
    assert!((towards - (d - s * h) / (s + v)).abs() < 1e-9, "{towards}");
    let near = agent + away * (0.9 * s * h);
    assert_eq!(
        intercept_lead_s(&agent, &near, &(away * v), s, h, 60.0),
        0.0
    );
    assert_eq!(
        intercept_lead_s(&agent, &p, &(away * 20.0), s, h, 60.0),
        60.0
    );
    assert_eq!(intercept_lead_s(&agent, &p, &(away * v), s, h, 5.0), 5.0);
}

/// Random inputs with velocities: the fast evaluation with leads equals the reference's.
#[test]
fn fast_eer_with_leads_equals_reference() {
    let mut c = Config::default_lab();
    c.guidance.entropy_kernel_cov_m2 = [[0.05, 0.01], [0.01, 0.04]];
    for world in [c.world(), c.world_seen_by_detector()] {
        fast_eer_with_leads_equals_reference_in(&world, &c);
    }
}

fn fast_eer_with_leads_equals_reference_in(world: &World, c: &Config) {
    let kernel = Gaussian2::new(c.guidance.entropy_kernel_cov_m2);
    let mut rng = CoreRng::seed_from_u64(19);
    let mut inp = random_inputs(&mut rng, 14, 2, world);
    inp.velocity = (0..14)
        .map(|_| Enu2::new(rng.gen_range(-0.4..0.4), rng.gen_range(-0.4..0.4)))
        .collect();
    let agent = Enu2::new(-0.5, 0.4);
    let cands = candidates(&inp, &agent, 0.6, ReachShape::Square, 4, world);
    let leads: Vec<f64> = (0..cands.len()).map(|_| rng.gen_range(0.0..3.0)).collect();
    let mut scratch = EerScratch::default();
    let views = north_views(&cands);
    let (_, fast) = evaluate_fast_led(&inp, &views, &leads, world, &kernel, 0.1, &mut scratch);
    let (_, reference) = evaluate_reference_led(&inp, &views, &leads, world, &kernel, 0.1);
    for (a, b) in fast.iter().zip(&reference) {
        assert!((a - b).abs() < 1e-9, "fast {a} vs reference {b}");
    }
    // The leads matter: without them some candidate's EER differs.
    let (_, unled) = evaluate_fast(&inp, &cands, world, &kernel, 0.1, &mut scratch);
    assert!(fast.iter().zip(&unled).any(|(a, b)| (a - b).abs() > 1e-6));
}

/// Turned views: the fast evaluation equals the reference's at any heading, and a turn
/// changes what a candidate sees.
#[test]
fn fast_eer_of_turned_views_equals_reference() {
    let c = Config::default_lab();
    let world = c.world_seen_by_detector();
    let kernel = Gaussian2::new(c.guidance.entropy_kernel_cov_m2);
    let mut rng = CoreRng::seed_from_u64(23);
    let inp = random_inputs(&mut rng, 14, 2, &world);
    let agent = Enu2::new(-0.5, 0.4);
    let cands = candidates(&inp, &agent, 0.6, ReachShape::Square, 4, &world);
    let views: Vec<View> = cands
        .iter()
        .map(|c| View::new(*c, rng.gen_range(-3.1..3.1)))
        .collect();
    let mut scratch = EerScratch::default();
    let (_, fast) = evaluate_fast_led(&inp, &views, &[], &world, &kernel, 0.1, &mut scratch);
    let (_, reference) = evaluate_reference_led(&inp, &views, &[], &world, &kernel, 0.1);
    for (a, b) in fast.iter().zip(&reference) {
        assert!((a - b).abs() < 1e-9, "fast {a} vs reference {b}");
    }
    let (_, north) = evaluate_fast(&inp, &cands, &world, &kernel, 0.1, &mut scratch);
    assert!(fast.iter().zip(&north).any(|(a, b)| (a - b).abs() > 1e-6));
}

/// A belief along a north-south road, 50 m long, under a 58 x 31 m view: turned with its
/// long side along the road the view holds all of it, facing north only the middle 31 m.
/// EER values the turned view more (what `view_heading = "along_track"` flies).
#[test]
fn eer_prefers_the_view_that_lies_along_the_belief() {
    let c =
        Config::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/outdoor.toml"))
            .unwrap();
    let mut world = c.world();
    world.occlusions.clear();
    assert!(world.footprint.half_width_m > 26.0 && world.footprint.half_height_m < 20.0);
    let kernel = Gaussian2::new(c.guidance.entropy_kernel_cov_m2);
    let mut rng = CoreRng::seed_from_u64(5);
    let centre = Enu2::new(100.0, 50.0);
    let n = 40;
    let inp = still_belief(n, &world, &mut rng, |k, rng| {
        centre + Enu2::new(rng.gen_range(-1.0..1.0), -25.0 + 50.0 * k as f64 / n as f64)
    });
    // Facing east (the width north-south, along the road), facing north (the paper's).
    let views = [View::new(centre, 0.0), View::north(centre)];
    let mut scratch = EerScratch::default();
    let (_, eer) = evaluate_fast_led(&inp, &views, &[], &world, &kernel, 1e-3, &mut scratch);
    assert!(eer[0] > eer[1] + 0.1, "{eer:?}");
}

/// At field scale, a car 300 m away driving on at 10 m/s: with intercepts the far
/// candidates are where a 15 m/s drone meets it, ahead of where the car is at the horizon's
/// end, and EER's waypoint is one of them; the paper's candidates are the particles where
/// they are then.
#[test]
fn far_candidates_are_where_the_agent_meets_the_particles() {
    let c = outdoor();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(23);
    let mut inp = EerInputs {
        n_m: 1,
        ..Default::default()
    };
    let east = Enu2::new(10.0, 0.0);
    for _ in 0..40 {
        let p = Enu2::new(300.0 + rng.gen_range(-5.0..5.0), rng.gen_range(-3.0..3.0));
        inp.current.push(p - east * 2.0);
        inp.predicted.push(p);
        inp.velocity.push(east);
        inp.weights.push(1.0 / 40.0);
        inp.measurements
            .push(world.measurement.measure(&p, &mut rng));
        inp.alpha.push(1.0 / 40.0);
    }
    let agent = Enu2::new(0.0, 0.0);
    let (s, h) = (15.0, 2.0);
    let mut cands = candidates(&inp, &agent, s * h, ReachShape::Disc, 8, &world);
    let paper = cands.clone();
    let leads = intercepts(&inp, &mut cands, &agent, s, h, s * h, 60.0, &world);
    // (300 - 30) / (15 - 10) = 54 s ahead: 540 m further east.
    for j in 0..40 {
        assert!((leads[j] - 54.0).abs() < 2.5, "{}", leads[j]);
        assert!((cands[j].x - paper[j].x - 10.0 * leads[j]).abs() < 1e-9);
    }
    assert!(leads[40..].iter().all(|l| *l == 0.0));
    let kernel = Gaussian2::new(c.guidance.entropy_kernel_cov_m2);
    let (_, eer) = evaluate_fast_led(
        &inp,
        &north_views(&cands),
        &leads,
        &world,
        &kernel,
        1e-6,
        &mut EerScratch::default(),
    );
    let best = (0..eer.len())
        .max_by(|a, b| eer[*a].total_cmp(&eer[*b]))
        .unwrap();
    assert!(
        best < 40 && cands[best].x > 800.0,
        "{best}: {}",
        cands[best]
    );
}

/// With the rollout re-routed at junctions (as the filter re-routes its constant-velocity
/// belief), the tracks that reach outdoor's junction at (600, 0) take its branches, east
/// (p 0.6) and north (p 0.4); without, they all drive straight on east.
#[test]
fn a_rerouted_rollout_takes_the_junctions_branches() {
    let c = outdoor();
    let world = c.world();
    let params = c.filter_params();
    let dt = params.dt_s;
    let mut rng = CoreRng::seed_from_u64(31);
    let mut pf = ParticleFilter::new(params, c.workspace_enu, &mut rng);
    // Every track on 0 -> 1, 10 m/s east, 10 m short of the junction after 3 s.
    let start = RouteStart::At(Enu2::new(560.0, 0.0), Some(Enu2::new(10.0, 0.0)));
    assert!(pf.spread_along_routes(&world, start, 10.0..=10.0, 3.0, &[], &mut rng));
    let mut eer = c.eer_params();
    // 4 s: 1 s to the junction, then 30 m along a branch (the rollout's noise is ~6 m).
    eer.horizon_steps = 12;
    let north_share = |on_road_m: Option<f64>| {
        let mut planner = EerPlanner::new(eer.clone());
        planner.reroute_rollout(on_road_m);
        let mut cv = ConstantVelocity::new(c.motion.cv_max_speed_mps, dt);
        let mut rng = CoreRng::seed_from_u64(32);
        let inp = planner.prepare(&pf, &mut cv, &world, &mut rng).unwrap();
        let north = inp.predicted.iter().filter(|p| p.y > 15.0).count();
        north as f64 / inp.predicted.len() as f64
    };
    // Straight on, only the rollout's noise reaches 15 m north.
    let straight = north_share(None);
    let share = north_share(Some(0.5 * c.filter_params().road_sigma_m.unwrap_or(0.0)));
    assert!(straight < 0.08, "north share, straight on: {straight}");
    // Re-routed: the north branch's share (0.4 of the tracks the junction re-routes; a track
    // the rollout's noise has carried within a metre of the east road already counts as on
    // it and drives on).
    assert!(
        share > straight + 0.1 && share < 0.45,
        "north share, re-routed: {share}"
    );
}

/// An intercept is never where no car can be: a far particle driving east toward outdoor's
/// corner at node 2 (1200, 0), where the road turns north, carried straight on for the full
/// lead would lie 50 m past the corner, off every road; its intercept is cut where it
/// leaves the road. A far particle mid-road keeps its whole lead.
#[test]
fn an_intercept_is_cut_where_its_particle_leaves_the_roads() {
    let c = outdoor();
    let world = c.world();
    let east = Enu2::new(10.0, 0.0);
    let inp = EerInputs {
        current: vec![Enu2::new(1130.0, 0.0), Enu2::new(700.0, 0.0)],
        weights: vec![0.5, 0.5],
        predicted: vec![Enu2::new(1150.0, 0.0), Enu2::new(720.0, 0.0)],
        velocity: vec![east, east],
        n_m: 1,
        ..Default::default()
    };
    let agent = Enu2::new(0.0, -50.0);
    let (speed, horizon_s, within_s) = (15.0, 2.0, 10.0);
    // Without roads' cut both would be led the full 10 s (each outruns the agent's reach
    // within the look-ahead): check the uncut lead first.
    for p in &inp.predicted {
        let uncut = intercept_lead_s(&agent, p, &east, speed, horizon_s, within_s);
        assert_eq!(uncut, within_s);
    }
    let mut cands = inp.predicted.clone();
    let leads = intercepts(
        &inp,
        &mut cands,
        &agent,
        speed,
        horizon_s,
        speed * horizon_s,
        within_s,
        &world,
    );
    let tolerance = world.footprint.quarter_view_m();
    // The corner-bound particle: cut to its last point near the road (5 s to the corner,
    // then at most the tolerance past it).
    assert!(
        leads[0] >= 5.0 && leads[0] < 5.0 + tolerance / 10.0 + 1e-9,
        "{}",
        leads[0]
    );
    assert!(
        world.road.distance_to_roads(&cands[0]) <= tolerance,
        "{}",
        cands[0]
    );
    // Mid-road: the whole look-ahead, 100 m further east on the same road.
    assert_eq!(leads[1], within_s);
    assert!(
        (cands[1] - Enu2::new(820.0, 0.0)).norm() < 1e-9,
        "{}",
        cands[1]
    );
}

/// The outdoor field world's config as shipped.
fn outdoor() -> Config {
    Config::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/outdoor.toml"
    )))
    .unwrap()
}

/// While searching, a plan keeps to its previous waypoint's mode when another is about as
/// good, and leaves it for one clearly better; once the target has been seen (not
/// searching) it takes the argmax, the paper's.
#[test]
fn a_search_keeps_to_its_mode_unless_another_is_clearly_better() {
    let c = outdoor();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(27);
    // Enough particles that each mode holds a few dozen, every one of them in EER, and
    // several simulated measurements each: EER's estimate with N_M = 1 moves by more than
    // the difference between two modes of about equal weight.
    let mut fp = c.filter_params();
    fp.particles = 2000;
    let speeds = 0.0..=fp.init_speed_max_mps;
    let mut pf = ParticleFilter::on_roads(fp, &world, None, speeds, &mut rng);
    let mut params = c.eer_params();
    params.entropy_particles = 2000;
    params.entropy_particles_concentrated = 2000;
    params.measurements_per_particle = 8;
    // Two modes on two east-west roads, as far from the agent, clear of every occlusion,
    // and the rest of the network (no view sees much of it).
    let (east, north) = (Enu2::new(450.0, 0.0), Enu2::new(150.0, 800.0));
    let agent = Enu2::new(300.0, 400.0);
    let ps = pf.particles();
    let in_east = |p: &Enu2| (p - east).norm() < 30.0;
    let in_north = |p: &Enu2| (p - north).norm() < 30.0;
    let n_east = ps.iter().filter(|p| in_east(p)).count() as f64;
    let n_north = ps.iter().filter(|p| in_north(p)).count() as f64;
    let n_rest = ps.len() as f64 - n_east - n_north;
    assert!(n_east >= 10.0 && n_north >= 10.0, "{n_east} {n_north}");
    // Each mode's share of the weight, whatever the number of particles drawn in it.
    let weigh = |share_east: f64, share_north: f64| -> Vec<f64> {
        let rest = (1.0 - share_east - share_north) / n_rest;
        ps.iter()
            .map(|p| {
                if in_east(p) {
                    share_east / n_east
                } else if in_north(p) {
                    share_north / n_north
                } else {
                    rest
                }
            })
            .collect()
    };
    let mut model = ConstantVelocity::new(c.motion.cv_max_speed_mps, c.filter_dt_s());
    let near = |d: &EerDecision, p: Enu2| (d.waypoint_enu - p).norm() < 60.0;
    let mut plan_from =
        |planner: &mut EerPlanner, pf: &mut ParticleFilter, shares: (f64, f64), agent: Enu2| {
            assert!(pf.set_weights(&weigh(shares.0, shares.1)));
            planner
                .plan(
                    pf,
                    &mut model,
                    &View::north(agent),
                    &HeadingRule::north(),
                    &world,
                    &mut rng,
                )
                .unwrap()
        };

    let mut searching = EerPlanner::new(params.clone());
    searching.set_searching(true);
    let d = plan_from(&mut searching, &mut pf, (0.5, 0.1), agent);
    assert!(near(&d, east), "{}", d.waypoint_enu);
    // North now holds a little more: the search stays east.
    let d = plan_from(&mut searching, &mut pf, (0.28, 0.32), agent);
    assert!(near(&d, east), "{}", d.waypoint_enu);
    // North clearly better: the search goes there.
    let d = plan_from(&mut searching, &mut pf, (0.1, 0.5), agent);
    assert!(near(&d, north), "{}", d.waypoint_enu);

    // Arrived over the east mode (its previous waypoint in view): the commitment has got
    // the drone there, and the argmax decides again: north, a little heavier.
    let mut arrived = EerPlanner::new(params.clone());
    arrived.set_searching(true);
    let d = plan_from(&mut arrived, &mut pf, (0.5, 0.1), agent);
    assert!(near(&d, east), "{}", d.waypoint_enu);
    let over_east = d.waypoint_enu;
    let d = plan_from(&mut arrived, &mut pf, (0.28, 0.32), over_east);
    assert!(near(&d, north), "{}", d.waypoint_enu);

    let mut seen = EerPlanner::new(params);
    seen.set_searching(false);
    let d = plan_from(&mut seen, &mut pf, (0.5, 0.1), agent);
    assert!(near(&d, east), "{}", d.waypoint_enu);
    let d = plan_from(&mut seen, &mut pf, (0.1, 0.5), agent);
    assert!(near(&d, north), "{}", d.waypoint_enu);
}

#[test]
fn the_escape_weighting_applies_only_when_the_tracker_turns_it_on() {
    let c = outdoor();
    let world = c.world();
    let mut rng = CoreRng::seed_from_u64(5);
    let fp = c.filter_params();
    let speeds = 0.0..=fp.init_speed_max_mps;
    let pf = ParticleFilter::on_roads(fp, &world, None, speeds, &mut rng);
    let mut model = ConstantVelocity::new(c.motion.cv_max_speed_mps, c.filter_dt_s());
    let agent = Enu2::new(300.0, 400.0);
    let params = c.eer_params();
    assert_eq!(params.search_escape_floor, DEFAULT_SEARCH_ESCAPE_FLOOR);
    for on in [false, true] {
        let mut planner = EerPlanner::new(params.clone());
        planner.weigh_escape(on);
        let mut expected = planner
            .prepare(&pf, &mut model, &world, &mut CoreRng::seed_from_u64(9))
            .unwrap()
            .clone();
        if on {
            weigh_by_escape(&mut expected, &agent, params.search_escape_floor);
        }
        planner.decide(&View::north(agent), &HeadingRule::north(), &world);
        assert_eq!(planner.inputs().weights, expected.weights, "on = {on}");
        assert_eq!(planner.inputs().alpha, expected.alpha, "on = {on}");
    }
    // The weighting moved something: the hypotheses are not all equally escaping.
    let mut weighed = EerPlanner::new(params.clone());
    weighed.weigh_escape(true);
    let before = weighed
        .prepare(&pf, &mut model, &world, &mut CoreRng::seed_from_u64(9))
        .unwrap()
        .weights
        .clone();
    weighed.decide(&View::north(agent), &HeadingRule::north(), &world);
    assert_ne!(weighed.inputs().weights, before);
}

/// A belief split 40 m apart north and south of where the drone hovers facing north (a
/// covered junction's two exits): the 31 m side of the view north-south holds one exit at
/// most, the 58 m side both. `along_track` judges each candidate at the heading the way
/// there gives (over the middle, where it is: north, the long side east-west); `informed`
/// judges it a quarter turn from that too, flies the view over the middle with its long
/// side north-south, and that view's EER is the higher.
#[test]
fn informed_heading_turns_the_long_side_across_two_exits() {
    let c = outdoor();
    let mut world = c.world();
    world.occlusions.clear();
    let fp = world.footprint;
    assert!(fp.half_width_m - world.detection_margin_m > 22.0 && fp.half_height_m < 20.0);
    let mut rng = CoreRng::seed_from_u64(11);
    let centre = Enu2::new(300.0, 400.0);
    let inp = still_belief(40, &world, &mut rng, |k, rng| {
        let side = if k % 2 == 0 { 20.0 } else { -20.0 };
        centre + Enu2::new(rng.gen_range(-1.0..1.0), side + rng.gen_range(-1.0..1.0))
    });
    let agent = View::north(centre);
    // The reachable grid reduced to the drone's own place: the candidates are the two
    // exits' particles (flown to, the view's long side along the way there: one exit seen)
    // and the place between them.
    let mut params = c.eer_params();
    params.grid_side = 1;
    let decide = |kind: ViewHeading| {
        let mut planner = EerPlanner::new(params.clone());
        planner.inputs = inp.clone();
        let rule = HeadingRule {
            kind,
            settle_m: fp.quarter_view_m(),
        };
        planner.decide(&agent, &rule, &world)
    };
    let along = decide(ViewHeading::AlongTrack);
    let informed = decide(ViewHeading::Informed);
    // Along the track: one exit. Informed: over the middle, the image's top east or west
    // (its width north-south).
    assert!((along.waypoint_enu - centre).norm() > 15.0, "{along:?}");
    let yaw = informed.view_yaw_enu_rad;
    assert!(crate::frames::wrap_angle(2.0 * yaw).abs() < 1e-9, "{yaw}");
    assert_eq!(informed.waypoint_enu, centre);
    assert!(
        informed.eer > along.eer + 0.1,
        "{} {}",
        informed.eer,
        along.eer
    );
    // Each place counts once, whatever its number of views.
    assert_eq!(informed.candidates, along.candidates);
}
