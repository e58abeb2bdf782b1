use super::*;
use crate::guidance::ViewHeading;
use crate::rng::{stream_rng, Stream};
use crate::testing::Config;

/// A sensor that sees the target wherever it is told it is, always from where the vehicle
/// is (or delivers no frame while frozen).
struct Scripted {
    z: Option<Enu2>,
    frozen: bool,
    calls: usize,
}

impl Sensor for Scripted {
    type Error = std::convert::Infallible;
    fn observe(&mut self, _t: f64, v: &View, _p: &Prior) -> Result<Observation, Self::Error> {
        self.calls += 1;
        Ok(if self.frozen {
            Observation::NoFrame
        } else {
            Observation::Frame {
                taken_from: *v,
                z: self.z,
            }
        })
    }
}

fn tracker(c: &Config, guidance: GuidanceKind, failsafe: bool) -> Tracker {
    tracker_with(c, guidance, failsafe, "cv", 1)
}

/// A tracker on `c` with the motion model named `motion`, its random streams drawn from
/// `seed`.
fn tracker_with(
    c: &Config,
    guidance: GuidanceKind,
    failsafe: bool,
    motion: &str,
    seed: u64,
) -> Tracker {
    let params = c.tracker_params(guidance, failsafe);
    let model = EstimatorKind::parse(motion)
        .unwrap()
        .build(&params.motion, &crate::motion::no_learned_model)
        .unwrap();
    Tracker::new(
        params,
        c.world(),
        model,
        stream_rng(seed, 0, Stream::Filter, 0),
        stream_rng(seed, 0, Stream::Guidance, 0),
    )
    .unwrap()
}

/// `config/NAME` as shipped.
fn shipped_config(name: &str) -> Config {
    Config::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("config")
            .join(name),
    )
    .unwrap()
}

/// `config/outdoor.toml` as shipped.
fn outdoor_config() -> Config {
    shipped_config("outdoor.toml")
}

fn input(v: Enu2) -> TickInput {
    TickInput {
        vehicle_enu: Some(v),
        view_yaw_enu_rad: crate::world::camera::NORTH_VIEW_YAW_ENU_RAD,
        link_lost: false,
        truth_enu: Some(Enu2::new(0.5, 0.5)),
        truth_velocity_enu: Enu2::zeros(),
    }
}

#[test]
fn one_second_of_lab_ticks_gives_three_steps_and_one_decision_inside_the_fence() {
    let c = Config::default_lab();
    let mut t = tracker(&c, GuidanceKind::Pfwm, false);
    let mut s = Scripted {
        z: Some(Enu2::new(0.5, 0.5)),
        frozen: false,
        calls: 0,
    };
    let ticks = c.timing.physics_hz as usize;
    let mut steps = 0;
    let mut decisions = Vec::new();
    for _ in 0..ticks {
        let out = t.tick(&input(Enu2::zeros()), &mut s, &FrozenClock).unwrap();
        steps += out.step.is_some() as usize;
        decisions.extend(out.decision);
    }
    assert_eq!(steps, c.timing.filter_hz as usize);
    assert_eq!(s.calls, steps);
    assert_eq!(decisions.len(), c.timing.guidance_hz as usize);
    let Decision::Command {
        command: Command::GoTo {
            position_enu: w, ..
        },
        ..
    } = decisions[0]
    else {
        panic!("{:?}", decisions[0])
    };
    assert!(c.workspace_enu.contains(&w));
    // PFWM flies to the estimate, which the measurements pulled toward (0.5, 0.5).
    assert!((w - Enu2::new(0.5, 0.5)).norm() < 0.3, "{w}");
}

#[test]
fn no_vehicle_position_means_no_step_until_one_arrives_then_catch_up() {
    let c = Config::default_lab();
    let mut t = tracker(&c, GuidanceKind::Pfwm, false);
    let mut s = Scripted {
        z: None,
        frozen: false,
        calls: 0,
    };
    let none = TickInput {
        vehicle_enu: None,
        ..input(Enu2::zeros())
    };
    for _ in 0..50 {
        let out = t.tick(&none, &mut s, &FrozenClock).unwrap();
        assert!(out.step.is_none() && out.decision.is_none());
    }
    assert_eq!(s.calls, 0);
    let out = t.tick(&input(Enu2::zeros()), &mut s, &FrozenClock).unwrap();
    assert!(out.step.is_some() && out.decision.is_some());
}

#[test]
fn failsafes_lose_the_target_then_the_camera_then_hold() {
    let mut c = Config::default_lab();
    c.daemon.target_lost_fallback = "hold".into();
    let mut t = tracker(&c, GuidanceKind::Eer, true);
    let mut s = Scripted {
        z: None,
        frozen: false,
        calls: 0,
    };
    let mut states = Vec::new();
    let mut last = None;
    let n = (c.timing.physics_hz * (c.daemon.target_lost_after_s + 1.0)) as usize;
    for _ in 0..n {
        let out = t.tick(&input(Enu2::zeros()), &mut s, &FrozenClock).unwrap();
        if let Some(st) = out.step {
            states.push(st.state);
        }
        if let Some(d) = out.decision {
            last = Some(d);
        }
    }
    assert_eq!(states[0], TrackState::Tracking);
    assert_eq!(*states.last().unwrap(), TrackState::Lost);
    assert!(matches!(
        last,
        Some(Decision::Command {
            command: Command::HoldHere,
            ..
        })
    ));
    // Frozen camera: camera-lost once the timeout passes, reported once.
    s.frozen = true;
    let mut lost_now = 0;
    for _ in 0..(c.timing.physics_hz * (c.daemon.camera_timeout_s + 1.0)) as usize {
        let out = t.tick(&input(Enu2::zeros()), &mut s, &FrozenClock).unwrap();
        if let Some(st) = out.step {
            assert!(!st.frame);
            lost_now += st.camera_lost_now as usize;
        }
    }
    assert_eq!(t.state(), TrackState::CameraLost);
    assert_eq!(lost_now, 1);
    // Link lost: from the filter step that sees it (the state changes at filter steps), no
    // decision at all.
    let lost_link = TickInput {
        link_lost: true,
        ..input(Enu2::zeros())
    };
    let mut seen_lost = false;
    let mut decisions_after = 0;
    for _ in 0..(2.0 * c.timing.physics_hz) as usize {
        let out = t.tick(&lost_link, &mut s, &FrozenClock).unwrap();
        if seen_lost {
            decisions_after += out.decision.is_some() as usize;
        }
        seen_lost |= out.step.is_some_and(|st| st.state == TrackState::LinkLost);
    }
    assert!(seen_lost);
    assert_eq!(decisions_after, 0);
}

#[test]
fn truth_guidance_without_truth_is_an_error_not_a_guess() {
    let c = Config::default_lab();
    let mut t = tracker(&c, GuidanceKind::Truth, false);
    let mut s = Scripted {
        z: None,
        frozen: false,
        calls: 0,
    };
    let blind = TickInput {
        truth_enu: None,
        ..input(Enu2::zeros())
    };
    let err = (0..100)
        .find_map(|_| t.tick(&blind, &mut s, &FrozenClock).err())
        .expect("a decision falls due within 100 ticks");
    assert!(err.to_string().contains("truth"), "{err}");
}

#[test]
fn eer_with_a_kalman_estimator_is_refused_with_a_reason() {
    let c = Config::default_lab();
    let err = Tracker::new(
        c.tracker_params(GuidanceKind::Eer, false),
        c.world(),
        EstimatorModel::Kalman,
        stream_rng(1, 0, Stream::Filter, 0),
        stream_rng(1, 0, Stream::Guidance, 0),
    )
    .err()
    .unwrap();
    let msg = err.to_string();
    assert!(msg.contains("eer") && msg.contains("particle"), "{msg}");
}

/// The prior from a cue is drawn by traffic, not by length: at outdoor's node 1 (600, 0)
/// the car goes on east with p 0.6 and turns north with p 0.4, so within 100 m of it the
/// road on east holds 1.5 times the particles that drive north; with `acquisition.prior =
/// "length"`, as many.
#[test]
fn the_prior_from_a_cue_follows_the_traffic_at_a_fork() {
    let east_over_north = |prior| {
        let mut c = outdoor_config();
        c.acquisition = Some(crate::tracker::sections::AcquisitionConfig {
            cue_enu_m: Some([600.0, 0.0]),
            cue_radius_m: 100.0,
            min_speed_mps: None,
            prior,
        });
        let (mut east, mut north) = (0usize, 0usize);
        for seed in 1..=4 {
            let t = tracker_with(&c, GuidanceKind::Eer, false, "cv", seed);
            let h = t.estimator().particle_filter().unwrap().histories();
            let k = h.k_in();
            for i in 0..h.len() {
                let (p, v) = (h.at(i, k - 1), h.at(i, k - 1) - h.at(i, k - 2));
                if p.x > 600.5 && v.x > 0.0 {
                    east += 1;
                } else if (p.x - 600.0).abs() < 0.5 && v.y > 0.0 {
                    north += 1;
                }
            }
        }
        (
            east as f64 / north as f64,
            format!("east {east}, north {north}"),
        )
    };
    let (by_traffic, counts) = east_over_north(None);
    assert!((1.3..=1.7).contains(&by_traffic), "{counts}");
    let (by_length, counts) = east_over_north(Some(RoadWeighting::Length));
    assert!((0.85..=1.15).contains(&by_length), "{counts}");
}

#[test]
fn the_prior_is_on_the_roads_within_the_cue() {
    let mut c = outdoor_config();
    let (cue, r) = (Enu2::new(600.0, 200.0), 120.0);
    c.acquisition = Some(crate::tracker::sections::AcquisitionConfig {
        cue_enu_m: Some([cue.x, cue.y]),
        cue_radius_m: r,
        min_speed_mps: None,
        prior: None,
    });
    let t = tracker(&c, GuidanceKind::Eer, false);
    let pf = t.estimator().particle_filter().unwrap();
    let road = &t.world().road;
    for p in pf.particles() {
        assert!(road.distance_to_roads(&p) < 1e-6, "{p} is off the roads");
        assert!((p - cue).norm() <= r + 1e-6, "{p} is outside the cue");
    }
    // Each particle moves along its road at a speed from half the largest (the default
    // `acquisition.min_speed_mps`) to the largest.
    let v_max = c.motion.cv_max_speed_mps;
    let speeds = |t: &Tracker| {
        let h = t.estimator().particle_filter().unwrap().histories();
        let k = h.k_in();
        (0..h.len())
            .map(|i| (h.at(i, k - 1) - h.at(i, k - 2)).norm() * c.timing.filter_hz)
            .collect::<Vec<_>>()
    };
    for v in speeds(&t) {
        assert!((0.5 * v_max - 1e-6..=v_max + 1e-6).contains(&v), "{v} m/s");
    }
    // An operator who expects a standing target sets 0: speeds from 0.
    c.acquisition.as_mut().unwrap().min_speed_mps = Some(0.0);
    let slow = speeds(&tracker(&c, GuidanceKind::Eer, false))
        .into_iter()
        .filter(|v| *v < 0.5 * v_max)
        .count();
    assert!(
        slow > 300 && slow < 700,
        "{slow} of 1000 below half the largest speed"
    );
    // Without a cue, the whole network: no particle off the roads either.
    c.acquisition = None;
    let t = tracker(&c, GuidanceKind::Eer, false);
    let pf = t.estimator().particle_filter().unwrap();
    let far = pf
        .particles()
        .iter()
        .filter(|p| (*p - cue).norm() > r)
        .count();
    assert!(
        far > pf.particles().len() / 2,
        "the prior should cover the whole network"
    );
    assert!(pf
        .particles()
        .iter()
        .all(|p| t.world().road.distance_to_roads(p) < 1e-6));
}

#[test]
fn eer_over_a_concentrated_belief_moves_with_the_target() {
    // A car driving east at 10 m/s, measured at every step: the setpoint carries its
    // velocity, so a vehicle following it does not trail by speed / gain.
    let c = outdoor_config();
    let mut t = tracker(&c, GuidanceKind::Pfwm, false);
    let mut last = None;
    let mut x = 20.0;
    let n = (c.timing.physics_hz * 10.0) as usize;
    for _ in 0..n {
        x += 10.0 / c.timing.physics_hz;
        let mut s = Scripted {
            z: Some(Enu2::new(x, 0.0)),
            frozen: false,
            calls: 0,
        };
        let out = t
            .tick(&input(Enu2::new(x, 0.0)), &mut s, &FrozenClock)
            .unwrap();
        if let Some(Decision::Command { command, .. }) = out.decision {
            last = Some(command);
        }
    }
    let Some(Command::GoTo { velocity_enu, .. }) = last else {
        panic!("{last:?}")
    };
    assert!(
        (velocity_enu - Enu2::new(10.0, 0.0)).norm() < 1.5,
        "{velocity_enu}"
    );
}

/// Following a car driving north (the road x = 1200 m): under `view_heading = "north"` every
/// command faces north; under `along_track` and `informed` the view turns its long side (the
/// image's width) along the car's track, north-south, whichever law plans (EER or the mean).
#[test]
fn the_view_heading_rule_turns_the_commands_view_along_the_track() {
    for (rule, law) in [
        (ViewHeading::North, GuidanceKind::Pfwm),
        (ViewHeading::AlongTrack, GuidanceKind::Pfwm),
        (ViewHeading::AlongTrack, GuidanceKind::Eer),
        // Over the car, both of informed's views hold the belief: the first, along it, stays.
        (ViewHeading::Informed, GuidanceKind::Pfwm),
        (ViewHeading::Informed, GuidanceKind::Eer),
    ] {
        let mut c = outdoor_config();
        c.guidance.view_heading = Some(rule);
        let mut t = tracker(&c, law, false);
        let mut yaws = Vec::new();
        let mut y = 100.0;
        for _ in 0..(c.timing.physics_hz * 10.0) as usize {
            y += 10.0 / c.timing.physics_hz;
            let mut s = Scripted {
                z: Some(Enu2::new(1200.0, y)),
                frozen: false,
                calls: 0,
            };
            let out = t
                .tick(&input(Enu2::new(1200.0, y - 3.0)), &mut s, &FrozenClock)
                .unwrap();
            if let Some(Decision::Command {
                command: Command::GoTo {
                    view_yaw_enu_rad, ..
                },
                ..
            }) = out.decision
            {
                yaws.push(view_yaw_enu_rad);
            }
        }
        assert!(yaws.len() >= 5, "{rule:?} {law}");
        let last = *yaws.last().unwrap();
        match rule {
            ViewHeading::North => assert!(yaws
                .iter()
                .all(|y| *y == crate::world::camera::NORTH_VIEW_YAW_ENU_RAD)),
            // The image's top east or west: its width north-south, along the road.
            ViewHeading::AlongTrack | ViewHeading::Informed => assert!(
                crate::frames::wrap_angle(2.0 * last).abs() < 0.3,
                "{law}: {yaws:?}"
            ),
        }
    }
}

/// A waypoint beyond the reachable grid's corners (sqrt(2) x reach) is approached at the top
/// speed (reach / horizon) along the way; one within them, the grid's corner included, is a
/// fixed point, as before.
#[test]
fn a_far_waypoint_is_approached_at_top_speed_and_a_near_one_is_a_fixed_point() {
    let v = super::approach_velocity(
        &Enu2::new(0.0, 0.0),
        &Enu2::new(300.0, 400.0),
        2.0,
        30.0,
        ReachShape::Square,
    );
    assert!((v.norm() - 15.0).abs() < 1e-9, "{v}");
    assert!((v.x / v.norm() - 0.6).abs() < 1e-9 && (v.y / v.norm() - 0.8).abs() < 1e-9);
    let near = super::approach_velocity(
        &Enu2::new(0.0, 0.0),
        &Enu2::new(20.0, 0.0),
        2.0,
        30.0,
        ReachShape::Square,
    );
    assert_eq!(near, Enu2::zeros());
    let corner = super::approach_velocity(
        &Enu2::new(5.0, 5.0),
        &Enu2::new(35.0, 35.0),
        2.0,
        30.0,
        ReachShape::Square,
    );
    assert_eq!(corner, Enu2::zeros(), "the grid's corner is a fixed point");
    let just_beyond = super::approach_velocity(
        &Enu2::new(0.0, 0.0),
        &Enu2::new(43.0, 0.0),
        2.0,
        30.0,
        ReachShape::Square,
    );
    assert!((just_beyond.norm() - 15.0).abs() < 1e-9, "{just_beyond}");
}

/// With a disc of reach (a speed limit on the norm) the farthest candidate is on the rim:
/// a waypoint just beyond it, diagonal or not, is approached at top speed; one on it is a
/// fixed point.
#[test]
fn with_a_disc_of_reach_a_waypoint_beyond_the_rim_is_approached_at_top_speed() {
    let disc =
        |to: Enu2| super::approach_velocity(&Enu2::zeros(), &to, 2.0, 30.0, ReachShape::Disc);
    assert_eq!(
        disc(Enu2::new(30.0, 0.0)),
        Enu2::zeros(),
        "the rim is a fixed point"
    );
    let diagonal = disc(Enu2::new(22.0, 22.0));
    assert!((diagonal.norm() - 15.0).abs() < 1e-9, "{diagonal}");
    // The same diagonal point is inside the square's reach.
    let square = super::approach_velocity(
        &Enu2::zeros(),
        &Enu2::new(22.0, 22.0),
        2.0,
        30.0,
        ReachShape::Square,
    );
    assert_eq!(square, Enu2::zeros());
}

/// `config/field-grid.toml`, whose car drives east along y = 0 into a fork at (500, 0)
/// under an overpass: on east, or north to (500, 500).
fn field_grid() -> Config {
    shipped_config("field-grid.toml")
}

/// One filter step at `t_s` of a frame taken from `camera`, with or without the target.
fn frame(t: &mut Tracker, t_s: f64, camera: Enu2, z: Option<Enu2>) {
    let observation = Observation::Frame {
        taken_from: View::north(camera),
        z,
    };
    t.update(t_s, observation, &input(camera), &FrozenClock)
        .unwrap();
}

/// The car seen driving east at `speed` m/s up to (468, 0) at 14 s, its last 3 s at
/// `last_speed` m/s; returns the time of the last frame.
fn seen_driving_east(t: &mut Tracker, dt: f64, speed: f64, last_speed: f64) -> f64 {
    let mut t_s = 0.0;
    let mut x = 468.0 - 3.0 * last_speed - 11.0 * speed;
    while t_s < 14.0 - 1e-9 {
        t_s += dt;
        x += dt * if t_s > 11.0 { last_speed } else { speed };
        let car = Enu2::new(x, 0.0);
        frame(t, t_s, car, Some(car));
    }
    t_s
}

#[test]
fn the_re_spread_keeps_out_the_branch_the_camera_has_watched_empty() {
    let c = field_grid();
    let dt = 1.0 / c.timing.filter_hz;
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    let t_s = seen_driving_east(&mut t, dt, 12.0, 12.0);
    // Then nothing, the camera over the east exit of the fork, until after the re-spread
    // (`daemon.target_lost_after_s`, 10 s).
    let watched = Enu2::new(550.0, 0.0);
    unseen_until_after_the_re_spread(&mut t, &c, t_s, watched);
    let (north, east) = weights_past_the_fork(&t, 40.0, 530.0);
    // The car can be 60-190 m on; it drove through the watched view only on the east.
    assert!(north > 0.95 && east < 0.01, "north {north}, east {east}");
    let mean = t.estimator().mean();
    assert!((mean.x - 500.0).abs() < 5.0 && mean.y > 60.0, "{mean}");
}

/// The car seen driving east into field-grid's fork at (500, 0), then measured for 4 s at
/// `(500 + creep_mps t, 3)`, 3 m up the north road, then unseen (the camera far off the
/// roads near the fork) until after the re-spread: the belief's weight on the north road
/// and on the east road beyond the fork.
fn re_spread_after_the_fork(creep_mps: f64) -> (f64, f64) {
    let c = field_grid();
    let dt = 1.0 / c.timing.filter_hz;
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    let mut t_s = seen_driving_east(&mut t, dt, 12.0, 12.0);
    let mut x = 468.0;
    while x < 500.0 {
        t_s += dt;
        x = (x + 12.0 * dt).min(500.0);
        let car = Enu2::new(x, 0.0);
        frame(&mut t, t_s, car, Some(car));
    }
    let stopped_s = t_s;
    while t_s < stopped_s + 4.0 {
        t_s += dt;
        let car = Enu2::new(500.0 + creep_mps * (t_s - stopped_s), 3.0);
        frame(&mut t, t_s, car, Some(car));
    }
    unseen_until_after_the_re_spread(&mut t, &c, t_s, Enu2::new(250.0, 250.0));
    weights_past_the_fork(&t, 5.0, 505.0)
}

/// Frames without the target from `camera`, from `t_s` until a second after the re-spread
/// is due (`daemon.target_lost_after_s`).
fn unseen_until_after_the_re_spread(t: &mut Tracker, c: &Config, mut t_s: f64, camera: Enu2) {
    let dt = 1.0 / c.timing.filter_hz;
    let lost_s = t_s;
    while t_s < lost_s + c.daemon.target_lost_after_s + 1.0 {
        t_s += dt;
        frame(t, t_s, camera, None);
    }
}

/// The belief's weight on field-grid's north road beyond `north_y` and on its east road
/// beyond `east_x`, past the fork at (500, 0).
fn weights_past_the_fork(t: &Tracker, north_y: f64, east_x: f64) -> (f64, f64) {
    let pf = t.estimator().particle_filter().unwrap();
    let (mut north, mut east) = (0.0, 0.0);
    for (p, w) in pf.particles().iter().zip(pf.weights()) {
        if p.y > north_y && (p.x - 500.0).abs() < 5.0 {
            north += w;
        } else if p.x > east_x && p.y.abs() < 5.0 {
            east += w;
        }
    }
    (north, east)
}

#[test]
fn a_car_seen_standing_is_re_spread_from_the_road_it_stands_on_not_its_noise_heading() {
    // Standing 3 m up the north road, its measurements creeping east at 0.3 m/s (noise: a
    // tenth of field-grid's largest hypothesis speed is 1.6 m/s): the routes start on the
    // road nearest where it was, north; taken from the creep's heading, every route went on
    // the road east (north 0.03, east 0.92).
    let (north, east) = re_spread_after_the_fork(0.3);
    assert!(north > 0.7 && east < 0.2, "north {north}, east {east}");
    // Both ways: measured driving east at 5 m/s from the same place, the heading counts and
    // the routes go east.
    let (north, east) = re_spread_after_the_fork(5.0);
    assert!(east > 0.9 && north < 0.05, "north {north}, east {east}");
}

/// The car seen cruising north at 10 m/s up outdoor's two-way street x = 600 to (600, 390),
/// 10 m short of its junction at (600, 400), then for its last 3 s moving `last_3s_m` (from
/// there); then unseen (the camera off every road) until after the re-spread: the belief's
/// weight on the street south of (600, 385).
fn re_spread_after_the_turn_back_street(last_3s_m: Enu2) -> f64 {
    let c = outdoor_config();
    let dt = 1.0 / c.timing.filter_hz;
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    let mut t_s = 0.0;
    while t_s < 12.0 - 1e-9 {
        t_s += dt;
        let car = Enu2::new(600.0, 390.0 - 10.0 * (12.0 - t_s));
        frame(&mut t, t_s, car, Some(car));
    }
    let slowed_s = t_s;
    while t_s < slowed_s + 3.0 - 1e-9 {
        t_s += dt;
        let car = Enu2::new(600.0, 390.0) + last_3s_m * ((t_s - slowed_s) / 3.0);
        frame(&mut t, t_s, car, Some(car));
    }
    unseen_until_after_the_re_spread(&mut t, &c, t_s, Enu2::new(1300.0, -150.0));
    let pf = t.estimator().particle_filter().unwrap();
    pf.particles()
        .iter()
        .zip(pf.weights())
        .filter(|(p, _)| (p.x - 600.0).abs() < 5.0 && p.y < 385.0)
        .map(|(_, w)| w)
        .sum()
}

#[test]
fn a_car_last_seen_slowed_far_below_its_cruise_is_re_spread_either_way_not_along_its_chord() {
    // Pulling out of a turn back: 5 m north-west in 3 s (1.7 m/s after 10) is the chord of
    // the turn, not the way it drives. Without a heading, half the routes take the street
    // south at once, half go on to the junction, where 0.3 turn back south: 0.65 south.
    // With the chord as the heading it would be north, 0.3 south.
    let south = re_spread_after_the_turn_back_street(Enu2::new(-3.0, 4.0));
    assert!(south > 0.5, "south {south}");
    // Both ways: measured still driving north at 9 m/s, the heading counts: only the turn
    // back at the junction (0.3) brings a route south.
    let south = re_spread_after_the_turn_back_street(Enu2::new(0.0, 27.0));
    assert!(south < 0.4, "south {south}");
}

#[test]
fn a_car_last_seen_slowing_is_re_spread_up_to_its_cruising_speed() {
    let c = field_grid();
    let dt = 1.0 / c.timing.filter_hz;
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    seen_driving_east(&mut t, dt, 12.0, 4.0);
    let speeds = t.hypothesis_speeds();
    // From 0.7 x the last measured speed (4 m/s over the last 3 s) to 1.3 x the cruise.
    assert!((speeds.start() - 0.7 * 4.0).abs() < 0.3, "{speeds:?}");
    assert!((speeds.end() - 1.3 * 12.0).abs() < 0.5, "{speeds:?}");
    // Seen driving steadily: around that speed.
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    seen_driving_east(&mut t, dt, 12.0, 12.0);
    let speeds = t.hypothesis_speeds();
    assert!((speeds.start() - 0.7 * 12.0).abs() < 0.3, "{speeds:?}");
    assert!((speeds.end() - 1.3 * 12.0).abs() < 0.5, "{speeds:?}");
}

/// The belief's weight in the view of a camera at (220, 0) and beyond it along the road
/// 0 -> 1 of field-grid (y = 0, x > 251 m), after the target was never seen for `for_s`
/// seconds while the camera stayed at `camera`.
fn never_seen_while_watching(camera: Enu2, for_s: f64) -> (f64, f64) {
    let c = field_grid();
    let dt = 1.0 / c.timing.filter_hz;
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    let mut t_s = 0.0;
    while t_s < for_s {
        t_s += dt;
        frame(&mut t, t_s, camera, None);
    }
    let pf = t.estimator().particle_filter().unwrap();
    let view = Enu2::new(220.0, 0.0);
    let (mut in_view, mut beyond) = (0.0, 0.0);
    for (p, w) in pf.particles().iter().zip(pf.weights()) {
        if c.world().footprint.contains(&View::north(view), p) {
            in_view += w;
        } else if p.x > 251.0 && p.y.abs() < 5.0 {
            beyond += w;
        }
    }
    (in_view, beyond)
}

#[test]
fn before_the_first_sighting_the_re_spread_from_the_cue_keeps_out_what_was_watched_empty() {
    // field-grid's cue (40, 30), 150 m: the road east from node 0 up to x = 187 m and the
    // road south into node 0. A camera at (220, 0) watches x = 190-250 m of the road east
    // from the start: a car from the cue that is now beyond it drove through its view.
    // Just past the re-spread (`daemon.target_lost_after_s`, 10 s, from the start), and
    // 10 s later (meanwhile the particles drift and hypotheses are injected around them).
    let lost_s = field_grid().daemon.target_lost_after_s;
    for for_s in [lost_s + 1.0, 2.0 * lost_s + 1.0] {
        let (in_view, beyond) = never_seen_while_watching(Enu2::new(220.0, 0.0), for_s);
        // Looking elsewhere (off every road), nothing is ruled out.
        let (in_view_unwatched, beyond_unwatched) =
            never_seen_while_watching(Enu2::new(1100.0, -150.0), for_s);
        assert!(
            in_view < 0.01 && beyond < 0.01,
            "at {for_s} s: in view {in_view}, beyond {beyond}"
        );
        assert!(
            in_view_unwatched > 0.05 && beyond_unwatched > 0.05,
            "at {for_s} s, unwatched: in view {in_view_unwatched}, beyond {beyond_unwatched}"
        );
    }
}

#[test]
fn eer_searches_until_the_first_sighting_and_not_after_a_loss() {
    // Kept after a loss too, the commitment held the drone on a refuted
    // branch past covered junctions (BENCHMARKS.md).
    let c = field_grid();
    let dt = 1.0 / c.timing.filter_hz;
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    let elsewhere = Enu2::new(1100.0, -150.0);
    let mut t_s = 0.0;
    while t_s < 3.0 {
        t_s += dt;
        frame(&mut t, t_s, elsewhere, None);
    }
    let plan = |t: &mut Tracker, t_s: f64, at: Enu2| {
        t.decide(t_s, &View::north(at), None, &FrozenClock).unwrap();
    };
    plan(&mut t, t_s, elsewhere);
    assert!(t.planner.is_searching(), "never seen: searching");
    let mut t_s = seen_driving_east(&mut t, dt, 12.0, 12.0);
    plan(&mut t, t_s, Enu2::new(468.0, 0.0));
    assert!(!t.planner.is_searching(), "seen: tracking");
    // Unseen past the re-spread: the argmax still decides.
    let lost_s = t_s;
    while t_s < lost_s + 2.0 * c.daemon.target_lost_after_s {
        t_s += dt;
        frame(&mut t, t_s, elsewhere, None);
    }
    plan(&mut t, t_s, elsewhere);
    assert!(t.respreads_in_spell > 0);
    assert!(!t.planner.is_searching(), "lost: the argmax decides");
}

#[test]
fn the_belief_is_spread_again_every_period_while_the_target_stays_unseen() {
    let c = field_grid();
    let dt = 1.0 / c.timing.filter_hz;
    let after = c.daemon.target_lost_after_s;
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    let mut t_s = seen_driving_east(&mut t, dt, 12.0, 12.0);
    let lost_s = t_s;
    assert_eq!(t.respreads_in_spell, 0);
    // The camera off every road: nothing is seen, nothing ruled out.
    let elsewhere = Enu2::new(1100.0, -150.0);
    for periods in 1..=3u32 {
        while t_s < lost_s + f64::from(periods) * after + 0.5 {
            t_s += dt;
            frame(&mut t, t_s, elsewhere, None);
        }
        assert_eq!(t.respreads_in_spell, periods, "at {t_s} s");
        let pf = t.estimator().particle_filter().unwrap();
        assert!((pf.weights().iter().sum::<f64>() - 1.0).abs() < 1e-9);
    }
    // Seen again: a new spell.
    t_s += dt;
    let car = Enu2::new(900.0, 0.0);
    frame(&mut t, t_s, car, Some(car));
    assert_eq!(t.respreads_in_spell, 0);
    assert_eq!(belief::respread_due_s(after, 0), after);
    assert_eq!(belief::respread_due_s(after, 2), 3.0 * after);
}

/// A far waypoint is flown to along the roads: outdoor's drone over the east road (0,0) ->
/// (600,0) at x = 100, the waypoint up the street x = 600 at (600, 120), 620 m by road and
/// 512 m straight (1.21 x). The setpoint is one reach ahead along the road, moving east at
/// top speed; off the roads by more than the view's shorter side, or where the roads wind
/// beyond 1.25 x the straight line, it is `None` (the caller flies straight).
#[test]
fn a_far_waypoint_is_flown_to_along_the_roads_unless_they_are_far_or_wind_away() {
    let c = outdoor_config();
    let t = tracker(&c, GuidanceKind::Eer, false);
    let reach = t.params.eer.reach_m;
    let horizon_s = t.params.eer.horizon_steps as f64 * t.params.filter.dt_s;
    let waypoint = Enu2::new(600.0, 120.0);
    let (setpoint, velocity) = t
        .along_the_roads(&Enu2::new(100.0, 10.0), &waypoint, horizon_s)
        .expect("near the roads, a 1.21 x road path");
    assert!(
        (setpoint - Enu2::new(100.0 + reach, 0.0)).norm() < 1e-9,
        "{setpoint}"
    );
    assert!(
        (velocity - Enu2::new(reach / horizon_s, 0.0)).norm() < 1e-9,
        "{velocity}"
    );
    // Straight, the drone would head north of east, off the road.
    let straight = super::approach_velocity(
        &Enu2::new(100.0, 10.0),
        &waypoint,
        horizon_s,
        reach,
        t.params.eer.reach_shape,
    );
    assert!(straight.y > 0.2 * straight.norm(), "{straight}");
    // 40 m off every road (the view's shorter side is ~31 m at 45 m): straight.
    assert!(t
        .along_the_roads(&Enu2::new(100.0, 40.0), &waypoint, horizon_s)
        .is_none());
    // From (300, 0) to (300, 790): either way round the roads is 1400 m, 1.77 x the
    // straight line: straight. And 1.44 x, to (600, 300) from (300, 10): straight too.
    for (from, to) in [
        ((300.0, 0.0), (300.0, 790.0)),
        ((300.0, 10.0), (600.0, 300.0)),
    ] {
        let (from, to) = (Enu2::new(from.0, from.1), Enu2::new(to.0, to.1));
        assert!(
            t.along_the_roads(&from, &to, horizon_s).is_none(),
            "{from} {to}"
        );
    }
}

/// After a loss the far waypoint is flown to along the roads too: field-grid's car seen
/// driving east to (468, 0), then unseen for 6 s with the camera elsewhere, its belief
/// (sd ~25 m) past the overpass at node 1 (500, 0), on the east and north roads out of
/// it. A drone 15 m north of the road at (250, 15), 250 m west, flies the road (y = 0)
/// east at top speed, where straight toward the node it would keep its 15 m offset and
/// see the road only at its view's edge (BENCHMARKS.md).
#[test]
fn after_a_loss_a_far_waypoint_is_flown_to_along_the_roads() {
    let c = field_grid();
    let dt = 1.0 / c.timing.filter_hz;
    let mut t = tracker(&c, GuidanceKind::Eer, false);
    let mut t_s = seen_driving_east(&mut t, dt, 12.0, 12.0);
    let elsewhere = Enu2::new(1100.0, -150.0);
    let lost_s = t_s;
    while t_s < lost_s + 6.0 {
        t_s += dt;
        frame(&mut t, t_s, elsewhere, None);
    }
    assert!(t.estimator.largest_sd_m() > t.world.footprint.quarter_view_m());
    let drone = Enu2::new(250.0, 15.0);
    let decision = t
        .decide(t_s, &View::north(drone), None, &FrozenClock)
        .unwrap();
    let Some(Decision::Command {
        command:
            Command::GoTo {
                position_enu,
                velocity_enu,
                ..
            },
        ..
    }) = decision
    else {
        panic!("{decision:?}");
    };
    let reach = t.params.eer.reach_m;
    assert!(
        (position_enu - Enu2::new(250.0 + reach, 0.0)).norm() < 1.0,
        "setpoint {position_enu}"
    );
    let horizon_s = t.params.eer.horizon_steps as f64 * t.params.filter.dt_s;
    assert!(
        (velocity_enu - Enu2::new(reach / horizon_s, 0.0)).norm() < 1e-6,
        "{velocity_enu}"
    );
}

/// Never seen from a cue, with the camera looking elsewhere: EER decides until the target
/// has been unseen for `AMBUSH_AFTER_S`, then the drone is sent to a point on the roads
/// (and, with `guidance.ambush_window_s = 0`, EER goes on deciding). field-grid flown at
/// half its altitude, so that its belief is spread over two views' lengths before then.
#[test]
fn a_long_unseen_target_is_waited_for_on_the_roads() {
    let after_s = crate::guidance::ambush::AMBUSH_AFTER_S;
    let elsewhere = Enu2::new(1100.0, -150.0);
    let unseen_for = |c: &Config, for_s: f64| {
        let dt = 1.0 / c.timing.filter_hz;
        let mut t = tracker(c, GuidanceKind::Eer, false);
        let mut t_s = 0.0;
        while t_s < for_s {
            t_s += dt;
            frame(&mut t, t_s, elsewhere, None);
        }
        t.decide(t_s, &View::north(elsewhere), None, &FrozenClock)
            .unwrap();
        t
    };
    let mut c = field_grid();
    c.agent.altitude_m *= 0.5;
    let fp = c.world().footprint;
    let two_views_m = 4.0 * fp.half_width_m.max(fp.half_height_m);
    let before = unseen_for(&c, after_s - 5.0);
    assert!(before.estimator().largest_sd_m() > two_views_m);
    assert_eq!(before.ambush_point_enu, None, "not unseen for long enough");
    let after = unseen_for(&c, after_s + 5.0);
    let point = after.ambush_point_enu.expect("an ambush point");
    assert!(c.world().road.distance_to_roads(&point) < 1e-6, "{point:?}");
    let Some(Command::GoTo { position_enu, .. }) = after.command() else {
        panic!("a go-to, got {:?}", after.command());
    };
    // The setpoint heads for the point (along the roads or straight).
    assert!((position_enu - point).norm() < (elsewhere - point).norm());
    let mut off = c.clone();
    off.guidance.ambush_window_s = Some(0.0);
    assert_eq!(unseen_for(&off, after_s + 5.0).ambush_point_enu, None);
}

/// A clock on which each reading is `step_s` after the last: every decision takes it.
struct SlowClock {
    now_s: std::cell::Cell<f64>,
    step_s: f64,
}

impl Clock for SlowClock {
    fn now_s(&self) -> f64 {
        let t = self.now_s.get() + self.step_s;
        self.now_s.set(t);
        t
    }
}

#[test]
fn decisions_that_take_most_of_their_budget_lower_eers_effort_and_still_fly() {
    let c = Config::default_lab();
    let mut t = tracker(&c, GuidanceKind::Eer, true);
    let budget_ms = c.daemon.guidance_budget_ms;
    // Each decision takes 90 % of the budget: slow, but within it.
    let clock = SlowClock {
        now_s: std::cell::Cell::new(0.0),
        step_s: 0.9 * budget_ms * 1e-3,
    };
    let view = View::north(Enu2::zeros());
    let mut commands = 0;
    for k in 0..5 {
        match t.decide(k as f64, &view, None, &clock).unwrap() {
            Some(Decision::Command { .. }) => commands += 1,
            other => panic!("decision {k}: {other:?}"),
        }
    }
    assert_eq!(commands, 5, "a slow decision within its budget still flies");
    assert_eq!(t.effort_level(), effort::MAX_LEVEL);
    // Quick decisions bring the effort back, a level per run of them.
    let quick = SlowClock {
        now_s: std::cell::Cell::new(0.0),
        step_s: 0.1 * budget_ms * 1e-3,
    };
    for k in 0..effort::QUICK_RUN {
        t.decide(10.0 + k as f64, &view, None, &quick).unwrap();
    }
    assert_eq!(t.effort_level(), effort::MAX_LEVEL - 1);
    // Without a budget (the simulator) the effort never changes.
    let mut sim = tracker(&c, GuidanceKind::Eer, false);
    for k in 0..5 {
        sim.decide(k as f64, &view, None, &clock).unwrap();
    }
    assert_eq!(sim.effort_level(), 0);
}
