use std::path::Path;

use super::*;

fn load_modified(edit: impl Fn(&mut toml::Table)) -> Result<Config, ConfigError> {
    let mut table: toml::Table = toml::from_str(DEFAULT_TOML).unwrap();
    edit(&mut table);
    let text = toml::to_string(&table).unwrap();
    Config::from_toml_str(&text, Path::new("test.toml"))
}

fn expect_invalid(err: ConfigError, key_part: &str) {
    match err {
        ConfigError::Invalid { key, .. } => {
            assert!(
                key.contains(key_part),
                "error names `{key}`, expected `{key_part}`"
            )
        }
        other => panic!("expected Invalid naming {key_part}, got {other}"),
    }
}

fn tbl<'a>(t: &'a mut toml::Table, k: &str) -> &'a mut toml::Table {
    t.get_mut(k).unwrap().as_table_mut().unwrap()
}

#[test]
fn embedded_default_is_valid_and_matches_the_paper() {
    let c = Config::default_lab();
    assert_eq!(c.filter.particles, 500);
    assert_eq!(c.guidance.entropy_particles, 25);
    assert_eq!(c.guidance.horizon_steps, 4);
    assert_eq!(c.filter.history_len, 10);
    assert_eq!(c.filter.resample_threshold, 0.99);
    assert_eq!(c.filter.reseed_threshold, 0.4);
    assert_eq!(c.occlusions.len(), 2);
    // Footprint side as in the authors' code: tan(35 deg) * 1.2 m.
    let side = 2.0 * c.agent.altitude_m * (0.5 * c.camera.fov_x_rad).tan();
    assert!(
        (side - 35f64.to_radians().tan() * 1.2).abs() < 1e-6,
        "{side}"
    );
}

#[test]
fn outdoor_config_is_valid() {
    let p = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("config/outdoor.toml");
    let c = Config::load(&p).unwrap();
    assert!(c.workspace_enu.width_m() > 1000.0);
    assert!(c.agent.altitude_m >= 30.0);
}

#[test]
fn unknown_key_is_an_error_naming_it() {
    let err = load_modified(|t| {
        tbl(t, "filter").insert("particals".into(), toml::Value::Integer(3));
    })
    .unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("particals"), "{msg}");
}

#[test]
fn zero_or_negative_particle_count_is_refused() {
    let err = load_modified(|t| {
        tbl(t, "filter").insert("particles".into(), toml::Value::Integer(0));
    })
    .unwrap_err();
    expect_invalid(err, "filter.particles");
    let err = load_modified(|t| {
        tbl(t, "filter").insert("particles".into(), toml::Value::Integer(-5));
    })
    .unwrap_err();
    assert!(err.to_string().contains("particles"), "{err}");
}

#[test]
fn transition_row_not_summing_to_one_is_refused() {
    let err = load_modified(|t| {
        let road = tbl(t, "road");
        let edges = road.get_mut("edges").unwrap().as_array_mut().unwrap();
        edges[0]
            .as_table_mut()
            .unwrap()
            .insert("p".into(), toml::Value::Float(0.5));
    })
    .unwrap_err();
    expect_invalid(err, "from = 1");
}

#[test]
fn edge_to_missing_node_is_refused() {
    let err = load_modified(|t| {
        let road = tbl(t, "road");
        let edges = road.get_mut("edges").unwrap().as_array_mut().unwrap();
        edges[2]
            .as_table_mut()
            .unwrap()
            .insert("to".into(), toml::Value::Integer(42));
    })
    .unwrap_err();
    expect_invalid(err, "road.edges[2].to");
}

#[test]
fn occlusion_outside_workspace_is_refused() {
    let err = load_modified(|t| {
        let occ = t.get_mut("occlusions").unwrap().as_array_mut().unwrap();
        let v: toml::Value =
            toml::Value::try_from(vec![[10.0, 10.0], [11.0, 10.0], [11.0, 11.0]]).unwrap();
        occ[0]
            .as_table_mut()
            .unwrap()
            .insert("vertices_enu_m".into(), v);
    })
    .unwrap_err();
    expect_invalid(err, "occlusions[0]");
}

#[test]
fn footprint_larger_than_workspace_is_refused() {
    let err = load_modified(|t| {
        tbl(t, "agent").insert("altitude_m".into(), toml::Value::Float(50.0));
    })
    .unwrap_err();
    expect_invalid(err, "camera.fov_x_rad");
    assert!(err_string_contains_footprint(load_modified(|t| {
        tbl(t, "agent").insert("altitude_m".into(), toml::Value::Float(50.0));
    })));
}

fn err_string_contains_footprint(r: Result<Config, ConfigError>) -> bool {
    r.unwrap_err().to_string().contains("footprint")
}

#[test]
fn non_positive_definite_covariance_is_refused() {
    let err = load_modified(|t| {
        let v = toml::Value::try_from([[0.01, 0.2], [0.2, 0.01]]).unwrap();
        tbl(t, "measurement").insert("noise_cov_m2".into(), v);
    })
    .unwrap_err();
    expect_invalid(err, "measurement.noise_cov_m2");
}

#[test]
fn reseed_threshold_above_resample_threshold_is_refused() {
    let err = load_modified(|t| {
        tbl(t, "filter").insert("reseed_threshold".into(), toml::Value::Float(0.995));
    })
    .unwrap_err();
    expect_invalid(err, "filter.reseed_threshold");
}

#[test]
fn missing_file_names_the_path() {
    let err = Config::load(Path::new("/nonexistent/infotrack.toml")).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/infotrack.toml"));
}

#[test]
fn a_cue_outside_the_workspace_or_off_every_road_names_the_key() {
    let base = std::fs::read_to_string(
        std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .join("config/outdoor.toml"),
    )
    .unwrap();
    let base = base.split("[acquisition]").next().unwrap().to_string();
    let with = |cue: &str, r: &str| {
        format!("{base}\n[acquisition]\ncue_enu_m = {cue}\ncue_radius_m = {r}\n")
    };
    let load = |t: &str| Config::from_toml_str(t, std::path::Path::new("t.toml"));
    assert!(load(&with("[20.0, 10.0]", "150.0")).is_ok());
    let e = load(&with("[5000.0, 10.0]", "150.0"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("acquisition.cue_enu_m") && e.contains("workspace"),
        "{e}"
    );
    // (300, 400) is 300 m from the nearest road.
    let e = load(&with("[300.0, 400.0]", "100.0"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("acquisition.cue_enu_m") && e.contains("no road"),
        "{e}"
    );
    let e = load(&with("[20.0, 10.0]", "-1.0")).unwrap_err().to_string();
    assert!(e.contains("acquisition.cue_radius_m"), "{e}");
    // The search's slowest speed: optional, from 0 to the motion model's largest (14 m/s).
    let cued = |v: &str| format!("{}min_speed_mps = {v}\n", with("[20.0, 10.0]", "150.0"));
    let speeds = |t: &str| load(t).unwrap().cue_speeds_mps();
    assert_eq!(speeds(&with("[20.0, 10.0]", "150.0")), 7.0..=14.0);
    assert_eq!(speeds(&cued("0.0")), 0.0..=14.0);
    assert_eq!(
        speeds(&base),
        0.0..=14.0,
        "without a cue the lab's prior, from 0"
    );
    for bad in ["-1.0", "15.0", "nan"] {
        let e = load(&cued(bad)).unwrap_err().to_string();
        assert!(e.contains("acquisition.min_speed_mps"), "{bad}: {e}");
    }
    // The prior: by traffic unless the config says `length`; another name is refused
    // with the line, the key and the names it takes.
    let prior = |v: &str| format!("{}prior = \"{v}\"\n", with("[20.0, 10.0]", "150.0"));
    let assembled = |t: &str| {
        load(t)
            .unwrap()
            .tracker_params(infotrack_core::guidance::GuidanceKind::Eer, false)
            .cue_prior
    };
    use infotrack_core::world::road::RoadWeighting;
    assert_eq!(
        assembled(&with("[20.0, 10.0]", "150.0")),
        RoadWeighting::Traffic
    );
    assert_eq!(assembled(&prior("length")), RoadWeighting::Length);
    assert_eq!(assembled(&prior("traffic")), RoadWeighting::Traffic);
    let e = load(&prior("uniform")).unwrap_err().to_string();
    assert!(
        e.contains("prior = \"uniform\"") && e.contains("traffic") && e.contains("length"),
        "{e}"
    );
    // Unknown keys are errors there too.
    let e = load(&format!(
        "{}cue_height_m = 3.0\n",
        with("[20.0, 10.0]", "150.0")
    ))
    .unwrap_err()
    .to_string();
    assert!(e.contains("cue_height_m"), "{e}");
}

/// The values the fault campaign found aborting the process (allocation failures, a loop
/// that never ends, the broadcast id) are refused at load, each naming its key; the largest
/// shipped values load.
#[test]
fn sizes_and_rates_that_would_exhaust_the_companion_are_refused_naming_the_key() {
    use toml::Value::{Float, Integer};
    let cases: [(&str, &str, toml::Value); 12] = [
        ("filter", "particles", Integer(1_000_000_000)),
        ("filter", "history_len", Integer(100_000_000)),
        ("guidance", "candidate_grid_side", Integer(1_000_000)),
        ("guidance", "entropy_particles", Integer(1_000_000)),
        (
            "guidance",
            "entropy_particles_concentrated",
            Integer(1_000_000),
        ),
        ("guidance", "entropy_particles_concentrated", Integer(0)),
        ("guidance", "horizon_steps", Integer(100_000)),
        ("guidance", "measurements_per_particle", Integer(100_000)),
        ("timing", "physics_hz", Float(1e12)),
        ("timing", "duration_s", Float(1e9)),
        ("daemon", "system_id", Integer(0)),
        ("daemon", "component_id", Integer(0)),
    ];
    for (section, key, value) in cases {
        let err = load_modified(|t| {
            if !t.contains_key(section) {
                t.insert(section.into(), toml::Value::Table(Default::default()));
            }
            tbl(t, section).insert(key.into(), value.clone());
        })
        .unwrap_err();
        expect_invalid(err, &format!("{section}.{key}"));
    }
    // Each bound alone holds but particles x history is too much together.
    let err = load_modified(|t| {
        tbl(t, "filter").insert("particles".into(), Integer(100_000));
        tbl(t, "filter").insert("history_len".into(), Integer(200));
    })
    .unwrap_err();
    expect_invalid(err, "filter.particles");
    // A day at 1 kHz physics is too many ticks even though both are within their bounds.
    let err = load_modified(|t| {
        tbl(t, "timing").insert("physics_hz".into(), Float(1000.0));
        tbl(t, "timing").insert("duration_s".into(), Float(86_400.0));
    })
    .unwrap_err();
    expect_invalid(err, "timing.duration_s");
    for shipped in [
        "outdoor",
        "field-ring",
        "field-grid",
        "field-eight",
        "field-hill",
        "field-twin",
        "field-town",
        "px4",
        "ardupilot",
        "default",
    ] {
        let p = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .join(format!("config/{shipped}.toml"));
        Config::load(&p).unwrap_or_else(|e| panic!("{shipped}: {e}"));
    }
}

/// Paths in a config are taken from the config file's folder, whatever the current
/// directory (`run --config /etc/infotrack/config/px4.toml` under systemd); the default
/// model is left where the program finds it.
#[test]
fn relative_paths_resolve_from_the_config_file() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    let px4 = Config::load(&root.join("config/px4.toml")).unwrap();
    let cal = px4.daemon.calibration.unwrap();
    assert!(cal.is_file(), "{}", cal.display());
    assert!(cal.starts_with(root.join("config")), "{}", cal.display());
    assert!(
        px4.motion.dmmn_model.is_file(),
        "{}",
        px4.motion.dmmn_model.display()
    );
    // A copy elsewhere with its own calibration beside it.
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(root.join("config/px4.toml"), dir.path().join("px4.toml")).unwrap();
    std::fs::write(dir.path().join("camera-example.yaml"), "x").unwrap();
    let copy = Config::load(&dir.path().join("px4.toml")).unwrap();
    assert_eq!(
        copy.daemon.calibration.unwrap(),
        dir.path().join("camera-example.yaml")
    );
    let ring = Config::load(&root.join("config/field-ring.toml")).unwrap();
    assert_eq!(ring.motion.dmmn_model, Path::new("models/dmmn.onnx"));
}

/// `agent.speed_limit_shape` is optional (absent: the paper's per-axis agent and a square
/// reach), `norm` gives the autopilots' limit and a disc of reach, and a misspelt value is
/// an error naming the value and what is accepted.
#[test]
fn the_agent_speed_limit_shape_is_optional_and_a_bad_one_is_named() {
    use infotrack_core::guidance::ReachShape;
    let c = Config::default_lab();
    assert_eq!(c.agent.speed_limit_shape, SpeedLimitShape::PerAxis);
    assert_eq!(c.eer_params().reach_shape, ReachShape::Square);
    let norm = load_modified(|t| {
        tbl(t, "agent").insert("speed_limit_shape".into(), "norm".into());
    })
    .unwrap();
    assert_eq!(norm.agent.speed_limit_shape, SpeedLimitShape::Norm);
    assert_eq!(norm.eer_params().reach_shape, ReachShape::Disc);
    let msg = load_modified(|t| {
        tbl(t, "agent").insert("speed_limit_shape".into(), "round".into());
    })
    .unwrap_err()
    .to_string();
    assert!(
        msg.contains("round") && msg.contains("per_axis") && msg.contains("norm"),
        "{msg}"
    );
}

/// `guidance.search_commitment` (absent: 0.2), `guidance.centring_share` (absent: 0.02) and
/// `guidance.search_escape_floor` (absent: 0.3) are optional, a share in [0, 1] is passed to
/// EER as given, and one outside it (or NaN) is an error naming the key.
#[test]
fn the_eer_shares_are_optional_and_a_bad_one_is_named() {
    type Share = fn(&infotrack_core::guidance::eer::EerParams) -> f64;
    let keys: [(&str, f64, Share); 3] = [
        ("search_commitment", 0.2, |p| p.search_commitment),
        ("centring_share", 0.02, |p| p.centring_share),
        ("search_escape_floor", 0.3, |p| p.search_escape_floor),
    ];
    let c = Config::default_lab();
    assert_eq!(c.guidance.search_commitment, None);
    assert_eq!(c.guidance.centring_share, None);
    for (key, default, share_of) in keys {
        assert_eq!(share_of(&c.eer_params()), default, "{key}");
        for share in [0.0, 0.5, 1.0] {
            let set = load_modified(|t| {
                tbl(t, "guidance").insert(key.into(), share.into());
            })
            .unwrap();
            assert_eq!(share_of(&set.eer_params()), share, "{key}");
        }
        for bad in [-0.1, 1.5, f64::NAN] {
            let msg = load_modified(|t| {
                tbl(t, "guidance").insert(key.into(), bad.into());
            })
            .unwrap_err()
            .to_string();
            assert!(msg.contains(&format!("guidance.{key}")), "{msg}");
        }
    }
}

/// `guidance.intercept_within_s` is optional (absent: the paper's candidates), a lead is
/// passed to EER as given, and a lead of zero or less is an error naming the key.
#[test]
fn the_intercept_lead_is_optional_and_a_bad_one_is_named() {
    let c = Config::default_lab();
    assert_eq!(c.guidance.intercept_within_s, None);
    assert_eq!(c.eer_params().intercept_within_s, None);
    let set = load_modified(|t| {
        tbl(t, "guidance").insert("intercept_within_s".into(), 25.0.into());
    })
    .unwrap();
    assert_eq!(set.eer_params().intercept_within_s, Some(25.0));
    for bad in [0.0, -1.0] {
        let msg = load_modified(|t| {
            tbl(t, "guidance").insert("intercept_within_s".into(), bad.into());
        })
        .unwrap_err()
        .to_string();
        assert!(msg.contains("guidance.intercept_within_s"), "{msg}");
    }
}

/// `guidance.view_heading`: absent, the lab (no cue) keeps the paper's constant heading and
/// a flight from an operator's cue turns the view along the track; a value is kept; a
/// wrong one is refused naming the key and the names it takes.
#[test]
fn the_view_heading_defaults_by_the_cue_and_a_wrong_one_is_refused() {
    use infotrack_core::guidance::ViewHeading;
    assert_eq!(
        Config::default_lab().heading_rule().kind,
        ViewHeading::North
    );
    let outdoor = Config::load(
        &Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("config/outdoor.toml"),
    )
    .unwrap();
    assert!(outdoor.acquisition.is_some());
    assert_eq!(outdoor.heading_rule().kind, ViewHeading::AlongTrack);
    let mut north = outdoor.clone();
    north.guidance.view_heading = Some(ViewHeading::North);
    assert_eq!(north.heading_rule().kind, ViewHeading::North);
    let set = load_modified(|t| {
        tbl(t, "guidance").insert("view_heading".into(), "along_track".into());
    })
    .unwrap();
    assert_eq!(set.heading_rule().kind, ViewHeading::AlongTrack);
    let informed = load_modified(|t| {
        tbl(t, "guidance").insert("view_heading".into(), "informed".into());
    })
    .unwrap();
    assert_eq!(informed.heading_rule().kind, ViewHeading::Informed);
    let err = load_modified(|t| {
        tbl(t, "guidance").insert("view_heading".into(), "nose".into());
    })
    .unwrap_err()
    .to_string();
    // The parser's message: the line, the key, the value and the names it takes.
    assert!(
        err.contains("view_heading = \"nose\"")
            && err.contains("along_track")
            && err.contains("informed"),
        "{err}"
    );
}

/// `agent.yaw_rate_limit_rad_s` must be a positive number (a negative rate would turn the
/// agent backwards); absent, PX4's 45 deg/s.
#[test]
fn a_yaw_rate_limit_that_is_not_positive_is_refused() {
    assert_eq!(
        Config::default_lab().agent.yaw_rate_limit_rad_s(),
        DEFAULT_YAW_RATE_LIMIT_RAD_S
    );
    for bad in [-1.0, 0.0] {
        let err = load_modified(|t| {
            tbl(t, "agent").insert("yaw_rate_limit_rad_s".into(), bad.into());
        })
        .unwrap_err();
        expect_invalid(err, "agent.yaw_rate_limit_rad_s");
    }
    let ok = load_modified(|t| {
        tbl(t, "agent").insert("yaw_rate_limit_rad_s".into(), 1.0.into());
    })
    .unwrap();
    assert_eq!(ok.agent.yaw_rate_limit_rad_s(), 1.0);
}

/// `guidance.ambush_window_s` is optional (absent: 30 s, on), 0 turns the ambush off, and a
/// negative or non-finite window is an error naming the key.
#[test]
fn the_ambush_window_is_optional_and_a_bad_one_is_named() {
    let c = Config::default_lab();
    assert_eq!(c.guidance.ambush_window_s, None);
    let p = c.ambush_params();
    assert_eq!(
        p.window_s,
        infotrack_core::guidance::ambush::DEFAULT_AMBUSH_WINDOW_S
    );
    assert!(p.is_on());
    let off = load_modified(|t| {
        tbl(t, "guidance").insert("ambush_window_s".into(), 0.0.into());
    })
    .unwrap();
    assert!(!off.ambush_params().is_on());
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let msg = load_modified(|t| {
            tbl(t, "guidance").insert("ambush_window_s".into(), bad.into());
        })
        .unwrap_err()
        .to_string();
        assert!(msg.contains("guidance.ambush_window_s"), "{msg}");
    }
}

/// The core's tests read the shipped configurations through `infotrack_core::testing`
/// (without this crate); both must assemble the same world and tracker parameters.
#[test]
fn the_core_test_configs_assemble_what_the_application_config_does() {
    use infotrack_core::guidance::GuidanceKind;
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    for (file, text) in infotrack_core::testing::SHIPPED {
        // Parsed from the same text (loading would also resolve the file paths in it).
        let app = Config::from_toml_str(text, &root.join("config").join(file)).unwrap();
        let core = infotrack_core::testing::Config::from_toml_str(text, Path::new(file)).unwrap();
        assert_eq!(
            format!("{:?}", app.world()),
            format!("{:?}", core.world()),
            "{file}"
        );
        assert_eq!(
            format!("{:?}", app.world_seen_by_detector()),
            format!("{:?}", core.world_seen_by_detector()),
            "{file}"
        );
        for guidance in [GuidanceKind::Eer, GuidanceKind::Pfwm, GuidanceKind::Lawn] {
            for failsafe in [false, true] {
                let (a, c) = (
                    app.tracker_params(guidance, failsafe),
                    core.tracker_params(guidance, failsafe),
                );
                assert_eq!(format!("{a:?}"), format!("{c:?}"), "{file} {guidance:?}");
            }
        }
    }
}
