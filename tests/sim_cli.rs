//! `infotrack sim` and `infotrack bench` as a user runs them: real process, real files.

use std::path::{Path, PathBuf};
use std::process::Command;

fn infotrack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_infotrack"))
}

fn num(v: &serde_json::Value, path: &[&str]) -> f64 {
    let mut cur = v;
    for p in path {
        cur = &cur[*p];
    }
    cur.as_f64()
        .unwrap_or_else(|| panic!("{path:?} is not a number in {v}"))
}

/// A JSON file `infotrack` or a script wrote.
fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Runs `infotrack sim` with `args` plus `--json DIR/r.json --out DIR/out`; returns the
/// process output and the two paths.
fn sim_to_files(dir: &Path, args: &[&str]) -> (std::process::Output, PathBuf, PathBuf) {
    let json = dir.join("r.json");
    let out = dir.join("out");
    let o = infotrack()
        .arg("sim")
        .args(args)
        .arg("--json")
        .arg(&json)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    (o, json, out)
}

#[test]
fn sim_writes_the_json_schema_the_table_and_the_plots() {
    let dir = tempfile::tempdir().unwrap();
    let (o, json, out) = sim_to_files(
        dir.path(),
        &[
            "--runs",
            "2",
            "--duration",
            "15",
            "--quiet",
            "--seed",
            "3",
            "--guidance",
            "eer,pfwm,lawn,kf,truth",
            "--motion",
            "cv,kf",
        ],
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // The two particle-only laws are refused with kf, with the reason, and the rest run.
    assert!(
        stdout.contains("refused: guidance `eer` cannot run with motion `kf`"),
        "{stdout}"
    );
    let v = read_json(&json);
    let results = v["results"].as_array().unwrap();
    assert_eq!(results.len(), 8);
    for r in results {
        assert_eq!(r["runs"].as_u64(), Some(2));
        let g = r["guidance"].as_str().unwrap();
        let m = r["motion"].as_str().unwrap();
        assert!(["eer", "pfwm", "lawn", "kf", "truth"].contains(&g));
        assert!(["cv", "kf"].contains(&m));
        for key in [
            "tracking_error_m",
            "estimation_error_m",
            "cov_det",
            "fov_percent",
        ] {
            let mean = num(r, &[key, "mean"]);
            let sd = num(r, &[key, "sd"]);
            assert!(
                mean.is_finite() && mean >= 0.0 && sd.is_finite() && sd >= 0.0,
                "{g}/{m} {key}"
            );
        }
        assert!(num(r, &["fov_percent", "mean"]) <= 100.0);
        assert!(num(r, &["filter_step_ms", "median"]) >= 0.0);
        // The search apart from the tracking: never-seen runs are those whose first
        // sighting is null, and every sighting lies within the run.
        let per_run = r["per_run"].as_array().unwrap();
        let never = per_run
            .iter()
            .filter(|p| p["first_sighting_s"].is_null())
            .count();
        assert_eq!(
            r["search"]["never_seen_runs"].as_u64(),
            Some(never as u64),
            "{g}/{m}"
        );
        for p in per_run {
            if let Some(t) = p["first_sighting_s"].as_f64() {
                assert!((0.0..=15.0).contains(&t), "{g}/{m}: first sighting {t}");
                assert!(p["tracking_error_after_first_sighting_m"].as_f64().unwrap() >= 0.0);
            } else {
                assert!(p["tracking_error_after_first_sighting_m"].is_null());
            }
        }
        assert!(
            stdout
                .lines()
                .any(|l| l.starts_with(&format!("search {g}/{m}:"))),
            "search line {g}/{m}"
        );
        assert!(
            stdout
                .lines()
                .any(|l| l.starts_with(&format!("{g:<6} {m:<6}"))),
            "table row {g}/{m}"
        );
    }
    let eer = results.iter().find(|r| r["guidance"] == "eer").unwrap();
    assert!(num(eer, &["guidance_step_ms", "median"]) > 0.0);
    // Per-step CSV of each run, and the plots.
    let csv = std::fs::read_to_string(out.join("eer_cv/run001.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 45, "header + 15 s at 3 Hz");
    for png in [
        "metrics.png",
        "eer_cv/scene_run000.png",
        "truth_kf/estimation_error_run000.png",
    ] {
        let bytes = std::fs::read(out.join(png)).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{png}");
    }
}

/// `scripts/frame-causes.py` reads what `sim --out` writes: each method's "measured" share
/// is the sim's %FOV (equal-length runs: the pooled share is the mean of the runs'), and
/// the causes account for every step.
#[test]
fn frame_causes_reads_the_steps_sim_writes() {
    let dir = tempfile::tempdir().unwrap();
    let (o, json, out) = sim_to_files(
        dir.path(),
        &[
            "--runs",
            "3",
            "--duration",
            "30",
            "--quiet",
            "--seed",
            "4",
            "--guidance",
            "eer,lawn",
            "--motion",
            "cv",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/frame-causes.py");
    let o = Command::new("python3")
        .arg(&script)
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table = String::from_utf8(o.stdout).unwrap();
    let v = read_json(&json);
    for r in v["results"].as_array().unwrap() {
        let method = format!(
            "{}_{}",
            r["guidance"].as_str().unwrap(),
            r["motion"].as_str().unwrap()
        );
        let row = table
            .lines()
            .find(|l| l.split(" | ").next().is_some_and(|d| d.ends_with(&method)))
            .unwrap_or_else(|| panic!("no row for {method} in\n{table}"));
        let cells: Vec<f64> = row
            .split(" | ")
            .skip(1)
            .map(|c| c.parse().unwrap())
            .collect();
        assert_eq!(cells.len(), 7, "{row}");
        let fov = num(r, &["fov_percent", "mean"]);
        assert!(
            (cells[0] - fov).abs() <= 0.051,
            "{method}: measured {} against %FOV {fov}",
            cells[0]
        );
        let total: f64 = cells.iter().sum();
        assert!(
            (total - 100.0).abs() <= 0.4,
            "{method}: causes sum to {total}"
        );
    }
    // A directory without runs is named in the error.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let o = Command::new("python3")
        .arg(&script)
        .arg(&empty)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no run*.csv"));
}

#[test]
fn sim_is_deterministic_for_a_seed() {
    let dir = tempfile::tempdir().unwrap();
    let run = |seed: &str, name: &str| {
        let json = dir.path().join(name);
        let o = infotrack()
            .args([
                "sim",
                "--runs",
                "2",
                "--duration",
                "10",
                "--quiet",
                "--guidance",
                "eer,lawn",
                "--seed",
                seed,
            ])
            .arg("--json")
            .arg(&json)
            .output()
            .unwrap();
        assert!(o.status.success());
        let v = read_json(&json);
        // Everything but the wall-clock timings.
        v["results"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|r| {
                r["per_run"].as_array().unwrap().iter().flat_map(|p| {
                    [
                        "tracking_error_m",
                        "estimation_error_m",
                        "cov_det",
                        "fov_percent",
                    ]
                    .map(|k| p[k].as_f64().unwrap())
                })
            })
            .collect::<Vec<f64>>()
    };
    let a = run("5", "a.json");
    assert_eq!(a.len(), 2 * 2 * 4);
    assert_eq!(a, run("5", "b.json"));
    assert_ne!(a, run("6", "c.json"));
}

#[test]
fn bad_input_gives_a_clear_error_and_no_panic() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    let default =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/default.toml"))
            .unwrap();
    std::fs::write(&bad, default.replace("particles = 500", "particles = 0")).unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["sim".into(), "--config".into(), bad.display().to_string()],
            "filter.particles",
        ),
        (
            vec!["sim".into(), "--config".into(), "/no/such/file.toml".into()],
            "/no/such/file.toml",
        ),
        (
            vec!["sim".into(), "--guidance".into(), "eer,zigzag".into()],
            "zigzag",
        ),
        (vec!["sim".into(), "--motion".into(), "warp".into()], "warp"),
        (
            vec![
                "sim".into(),
                "--guidance".into(),
                "eer".into(),
                "--motion".into(),
                "kf".into(),
            ],
            "needs a particle set",
        ),
        (vec!["sim".into(), "--runs".into(), "0".into()], "--runs"),
    ];
    for (args, needle) in cases {
        let o = infotrack().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(
            stderr.contains(needle),
            "{args:?}: stderr lacks `{needle}`: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

#[test]
fn bench_prints_the_table_and_json() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("b.json");
    let o = infotrack()
        .args(["bench", "--repetitions", "3", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = read_json(&json);
    for k in [
        ["pf_step_ms", "n500"],
        ["pf_step_ms", "n5000"],
        ["eer_cycle_ms", "nh25"],
        ["eer_cycle_ms", "nh100"],
        ["eer_cycle_ms", "nh500"],
    ] {
        assert!(num(&v, &k) > 0.0, "{k:?}");
    }
    assert!(v["eer_candidates"].as_u64().unwrap() >= 256);
}

#[test]
fn sim_closed_loop_flies_the_daemon_on_the_simulated_clock() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("flight");
    let o = infotrack()
        .args(["sim", "--closed-loop", "--duration", "20", "--seed", "7"])
        .arg("--out")
        .arg(&out)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        stdout.contains("closed loop | px4 vehicle at mock:px4"),
        "{stdout}"
    );
    assert!(stdout.contains("stopped by Duration"), "{stdout}");
    // 20 s of flight: 60 filter steps at 3 Hz (the one at exactly 20 s may fall after the
    // stop). How much faster than real time it runs is a benchmark, not a test.
    assert!(
        stdout.contains("| 59 filter steps") || stdout.contains("| 60 filter steps"),
        "{stdout}"
    );
    for f in [
        "steps.csv",
        "flight.csv",
        "link.tlog",
        "scene.png",
        "summary.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    // Refusals name what is wrong.
    for (args, want) in [
        (vec!["--runs", "3"], "one run"),
        (vec!["--guidance", "pfwm"], "can only be eer"),
        (vec!["--motion", "kf"], "daemon.motion"),
        (vec!["--vision"], "do not apply"),
    ] {
        let o = infotrack()
            .args(["sim", "--closed-loop"])
            .args(&args)
            .output()
            .unwrap();
        assert!(!o.status.success());
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(e.contains(want), "{args:?}: {e}");
    }
}

/// As under systemd: `RUST_LOG` is honoured when `--log` is not given, and a log read from
/// a pipe (the journal) carries no colour codes; the run summary is in words.
#[test]
fn rust_log_is_honoured_and_piped_logs_are_plain_text() {
    let o = infotrack()
        .args(["sim", "--closed-loop", "--duration", "3", "--seed", "2"])
        .env("RUST_LOG", "info")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("INFO") && err.contains("infotrack: tracking started"),
        "RUST_LOG=info ignored:\n{err}"
    );
    assert!(
        !err.contains('\u{1b}'),
        "colour codes in a piped log:\n{err}"
    );
    assert!(
        out.contains("vehicle: ended in HOLD") && !out.contains("Some("),
        "{out}"
    );
    // --log wins over RUST_LOG; a bad filter is named with where it came from.
    let o = infotrack()
        .args(["sim", "--runs", "1", "--duration", "2", "--quiet"])
        .env("RUST_LOG", "not a [filter")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("RUST_LOG `not a [filter`"), "{err}");
    let o = infotrack()
        .args([
            "sim",
            "--runs",
            "1",
            "--duration",
            "2",
            "--quiet",
            "--log",
            "error",
        ])
        .env("RUST_LOG", "not a [filter")
        .output()
        .unwrap();
    assert!(!String::from_utf8_lossy(&o.stderr).contains("RUST_LOG"));
}

/// `infotrack sim` on `config` with the arguments `scripts/world-batch.py` passes (seed 2,
/// EER with CV, one thread), its `--json` written to `json` and returned.
fn sim_as_the_batch_does(
    config: &Path,
    runs: &str,
    duration_s: &str,
    json: &Path,
) -> serde_json::Value {
    let o = infotrack()
        .arg("sim")
        .arg("--config")
        .arg(config)
        .args(["--runs", runs, "--duration", duration_s, "--seed", "2"])
        .args([
            "--guidance",
            "eer",
            "--motion",
            "cv",
            "--quiet",
            "--threads",
            "1",
        ])
        .arg("--json")
        .arg(json)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    read_json(json)
}

/// `scripts/world-batch.py` flies every stand-in through `sim --json` and keeps its figures:
/// a world's row is what `infotrack sim` run by hand with the same arguments reports, the
/// table counts the worlds that meet both field-scale targets, a measurement compared
/// with itself differs by nothing, and a missing binary is named.
#[test]
fn world_batch_measures_the_stand_ins_as_sim_does() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let script = root.join("scripts/world-batch.py");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("batch");
    let o = Command::new("python3")
        .arg(&script)
        .args(["run", "--bin", env!("CARGO_BIN_EXE_infotrack"), "--out"])
        .arg(&out)
        .args(["--set", "stand-ins", "--runs", "2", "--duration", "40"])
        .args(["--seed", "2"])
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "{table}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let summary = read_json(&out.join("summary.json"));
    let worlds = summary["worlds"].as_object().unwrap();
    let stand_ins = std::fs::read_dir(root.join("config"))
        .unwrap()
        .filter(|e| {
            let name = e.as_ref().unwrap().file_name().into_string().unwrap();
            name.starts_with("field-") && name.ends_with(".toml")
        })
        .count();
    assert!(stand_ins >= 6, "{stand_ins} stand-ins");
    assert_eq!(worlds.len(), stand_ins, "{table}");

    // field-grid by hand, with the arguments the script passes.
    let by_hand = sim_as_the_batch_does(
        &root.join("config/field-grid.toml"),
        "2",
        "40",
        &dir.path().join("grid.json"),
    );
    let row = &by_hand["results"][0];
    let grid = &worlds["field-grid"];
    // Something to compare: the car seen in some runs but not in every step.
    let fov = num(row, &["fov_percent", "mean"]);
    assert!(fov > 0.0 && fov < 100.0, "field-grid %FOV {fov}");
    for key in ["fov_percent", "tracking_error_m"] {
        assert_eq!(
            num(row, &[key, "mean"]),
            num(grid, &[key]),
            "{key}: sim by hand against the batch"
        );
    }

    // The closing line counts the worlds meeting both targets (FOV >= 60 %, tracking <= 20 m).
    let both = worlds
        .values()
        .filter(|w| num(w, &["fov_percent"]) >= 60.0 && num(w, &["tracking_error_m"]) <= 20.0)
        .count();
    let expected = format!("both targets on {both} of {stand_ins}");
    assert!(table.contains(&expected), "{expected} not in\n{table}");

    // Compared with itself: no difference.
    let o = Command::new("python3")
        .arg(&script)
        .arg("compare")
        .arg(&out)
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let compared = String::from_utf8_lossy(&o.stdout);
    assert!(compared.contains("paired +0.00 points"), "{compared}");

    // A binary that is not there is named.
    let o = Command::new("python3")
        .arg(&script)
        .args(["run", "--bin", "no/such/infotrack", "--out"])
        .arg(dir.path().join("none"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--bin no/such/infotrack"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// `scripts/world-batch.py --key SECTION.KEY=VALUE` flies a copy of every world with the key
/// set: the copies are written beside the batch and hold the key under its section, the
/// batch's row for a world is what `infotrack sim` reports on that copy, and a key a world
/// already sets, or an argument that is not `SECTION.KEY=VALUE`, is refused by name.
#[test]
fn world_batch_flies_a_config_variant_from_a_key() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("informed");
    let batch = |out: &Path, key: &str| stand_in_batch(out, "20", &["--key", key]);
    let o = batch(&out, "guidance.view_heading=\"informed\"");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = read_json(&out.join("summary.json"));
    assert_eq!(summary["keys"][0], "guidance.view_heading=\"informed\"");
    let copy = out.join("worlds/field-grid.toml");
    let text = std::fs::read_to_string(&copy).unwrap();
    let table: toml::Table = text.parse().unwrap();
    assert_eq!(table["guidance"]["view_heading"].as_str(), Some("informed"));
    let grid = &summary["worlds"]["field-grid"];
    assert_eq!(grid["config"].as_str(), Some(copy.to_str().unwrap()));

    // The copy's row is what sim reports on the copy.
    let by_hand = sim_as_the_batch_does(&copy, "1", "20", &dir.path().join("by-hand.json"));
    assert_eq!(
        num(&by_hand["results"][0], &["tracking_error_m", "mean"]),
        num(grid, &["tracking_error_m"])
    );

    // A key the world sets already is refused, naming the key and the world.
    let err = refused(batch(&dir.path().join("twice"), "guidance.horizon_steps=3"));
    assert!(
        err.contains("guidance.horizon_steps") && err.contains("already sets it"),
        "{err}"
    );
    // Not SECTION.KEY=VALUE.
    let err = refused(batch(&dir.path().join("bad"), "informed"));
    assert!(err.contains("expected SECTION.KEY=VALUE"), "{err}");
}

/// `scripts/world-batch.py --scale SECTION.KEY=FACTOR` multiplies a number every world sets,
/// in copies it flies (a diagnostic of what a world's own setting decides), records the
/// factor in the summary, and refuses a key a world does not set and a factor that is no
/// number, naming what was wrong.
#[test]
fn world_batch_scales_a_number_every_world_sets() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let batch = |out: &Path, scale: &str| stand_in_batch(out, "5", &["--scale", scale]);
    let out = dir.path().join("agile");
    let o = batch(&out, "agent.accel_limit_mps2=2");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = read_json(&out.join("summary.json"));
    assert_eq!(summary["scales"][0], "agent.accel_limit_mps2=2");
    for world in ["field-grid", "field-town"] {
        let shipped: toml::Table =
            std::fs::read_to_string(root.join(format!("config/{world}.toml")))
                .unwrap()
                .parse()
                .unwrap();
        let copy = out.join(format!("worlds/{world}.toml"));
        let scaled: toml::Table = std::fs::read_to_string(&copy).unwrap().parse().unwrap();
        let accel = |t: &toml::Table| t["agent"]["accel_limit_mps2"].as_float().unwrap();
        assert_eq!(accel(&scaled), 2.0 * accel(&shipped), "{world}");
        // Nothing else in the world changed.
        let mut back = scaled.clone();
        back["agent"]
            .as_table_mut()
            .unwrap()
            .insert("accel_limit_mps2".into(), accel(&shipped).into());
        assert_eq!(back, shipped, "{world}");
        assert_eq!(
            summary["worlds"][world]["config"].as_str(),
            Some(copy.to_str().unwrap())
        );
    }

    // A key no world sets, and a factor that is not a number, are refused.
    let err = refused(batch(
        &dir.path().join("unset"),
        "guidance.search_commitment=2",
    ));
    assert!(
        err.contains("guidance.search_commitment") && err.contains("does not set it"),
        "{err}"
    );
    let err = refused(batch(
        &dir.path().join("nan"),
        "agent.accel_limit_mps2=fast",
    ));
    assert!(err.contains("expected SECTION.KEY=FACTOR"), "{err}");
    // A key the world sets to something other than one number (the start, a pair).
    let err = refused(batch(&dir.path().join("pair"), "agent.start_enu_m=2"));
    assert!(
        err.contains("agent.start_enu_m") && err.contains("not one number"),
        "{err}"
    );
}

/// The stderr of a run that must have failed (a batch refusing its arguments).
fn refused(o: std::process::Output) -> String {
    assert!(
        !o.status.success(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `scripts/world-batch.py run` on the stand-ins, one run of `duration_s` each on seed 2, with
/// `extra` arguments, into `out`.
fn stand_in_batch(out: &Path, duration_s: &str, extra: &[&str]) -> std::process::Output {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/world-batch.py");
    Command::new("python3")
        .arg(script)
        .args(["run", "--bin", env!("CARGO_BIN_EXE_infotrack"), "--out"])
        .arg(out)
        .args([
            "--set",
            "stand-ins",
            "--runs",
            "1",
            "--duration",
            duration_s,
        ])
        .args(["--seed", "2"])
        .args(extra)
        .output()
        .unwrap()
}

/// A recorded track (a car that stops at a light and turns where it likes) replaces the
/// simulated car, in `sim` and in the closed loop; each run ends when the track does.
#[test]
fn a_recorded_track_is_the_target_and_its_end_ends_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let mut rows = vec!["t_s,x_m,y_m".to_string()];
    // East along y = 0 at 10 m/s, 10 s stopped at x = 300, then north from x = 600: 110 s.
    let mut t = 0.0;
    for x in (0..=300).step_by(10).chain(std::iter::once(300)) {
        rows.push(format!("{t},{x},0"));
        t += if rows.len() == 32 { 10.0 } else { 1.0 };
    }
    for x in (310..=600).step_by(10) {
        rows.push(format!("{t},{x},0"));
        t += 1.0;
    }
    for y in (10..=400).step_by(10) {
        rows.push(format!("{t},600,{y}"));
        t += 1.0;
    }
    std::fs::write(dir.path().join("car.csv"), rows.join("\n") + "\n").unwrap();
    let outdoor = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/outdoor.toml");
    let text = std::fs::read_to_string(outdoor)
        .unwrap()
        .replace("[target]", "[target]\ntrajectory = \"car.csv\"");
    let cfg = dir.path().join("outdoor-car.toml");
    std::fs::write(&cfg, text).unwrap();
    let cfg = cfg.to_str().unwrap();
    let (o, _, out) = sim_to_files(
        dir.path(),
        &[
            "--config",
            cfg,
            "--runs",
            "2",
            "--guidance",
            "truth",
            "--motion",
            "cv",
            "--duration",
            "300",
            "--quiet",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let steps = std::fs::read_to_string(out.join("truth_cv/run001.csv")).unwrap();
    let last: Vec<f64> = steps
        .lines()
        .last()
        .unwrap()
        .split(',')
        .take(3)
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        (last[0] - 110.0).abs() < 0.5,
        "the run ends with the track: {last:?}"
    );
    assert!(
        (last[1] - 600.0).abs() < 1e-6 && (last[2] - 400.0).abs() < 1e-6,
        "{last:?}"
    );
    let cl = dir.path().join("cl");
    let o = infotrack()
        .args([
            "sim",
            "--closed-loop",
            "--config",
            cfg,
            "--motion",
            "cv",
            "--duration",
            "300",
            "--out",
        ])
        .arg(&cl)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("stopped by Duration"), "{stdout}");
    let flight = std::fs::read_to_string(cl.join("flight.csv")).unwrap();
    let (_, _, logged) = infotrack::daemon::flight_log::parse(&flight, "flight.csv").unwrap();
    let flown = logged.last().unwrap().t_s;
    assert!(
        (100.0..=112.0).contains(&flown),
        "the flight ends with the track: {flown} s"
    );
    // A track that leaves the workspace is refused at load, naming the file and the row.
    std::fs::write(
        dir.path().join("car.csv"),
        "t_s,x_m,y_m\n0,0,0\n60,0,1500\n",
    )
    .unwrap();
    let o = infotrack()
        .args(["sim", "--config", cfg, "--runs", "1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success()
            && err.contains("car.csv, line 3")
            && err.contains("outside the workspace"),
        "{err}"
    );
}

/// Without `acquisition.cue_enu_m` each run is cued where its recorded track starts: the
/// belief starts there, not at the config's cue 600 m away; without a track the key is needed.
#[test]
fn a_recorded_track_without_a_cue_is_cued_where_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let rows: Vec<String> = std::iter::once("t_s,x_m,y_m".to_string())
        .chain((0..=39).map(|i| format!("{i},600,{}", 400 - 10 * i)))
        .collect();
    std::fs::write(dir.path().join("car.csv"), rows.join("\n") + "\n").unwrap();
    let outdoor = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/outdoor.toml");
    let no_cue = std::fs::read_to_string(outdoor)
        .unwrap()
        .replace("cue_enu_m = [20.0, 10.0]\n", "");
    let cfg = dir.path().join("no-cue.toml");
    std::fs::write(&cfg, &no_cue).unwrap();
    let o = infotrack()
        .args(["sim", "--runs", "1", "--config"])
        .arg(&cfg)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success()
            && err.contains("acquisition.cue_enu_m")
            && err.contains("target.trajectory"),
        "{err}"
    );
    let text = no_cue.replace("[target]", "[target]\ntrajectory = \"car.csv\"");
    std::fs::write(&cfg, text).unwrap();
    let cfg = cfg.to_str().unwrap();
    let args = [
        "--config",
        cfg,
        "--runs",
        "1",
        "--guidance",
        "truth",
        "--motion",
        "cv",
        "--quiet",
    ];
    let (o, _, out) = sim_to_files(dir.path(), &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let steps = std::fs::read_to_string(out.join("truth_cv/run000.csv")).unwrap();
    let first: Vec<f64> = steps
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap_or(f64::NAN))
        .collect();
    let (ex, ey) = (first[10], first[11]);
    let from_start = (ex - 600.0).hypot(ey - 400.0);
    assert!(
        from_start < 150.0,
        "the belief starts at the track's start: ({ex}, {ey})"
    );
}

/// Laws compared on the same seeds are compared in pairs: per metric the mean difference with
/// its 95 % CI, d_z, the paired t and Wilcoxon tests, and Holm's correction, printed and in
/// the JSON.
#[test]
fn laws_on_the_same_seeds_are_compared_in_pairs() {
    let dir = tempfile::tempdir().unwrap();
    let (o, json, _) = sim_to_files(
        dir.path(),
        &[
            "--runs",
            "5",
            "--duration",
            "20",
            "--guidance",
            "eer,truth,lawn",
            "--motion",
            "cv",
            "--quiet",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("paired eer - truth/cv (n 5, same seeds"),
        "{stdout}"
    );
    assert!(
        stdout.contains("paired eer - lawn/cv (n 5, same seeds"),
        "{stdout}"
    );
    let v = read_json(&json);
    let results = v["results"].as_array().unwrap();
    let eer = results.iter().find(|r| r["guidance"] == "eer").unwrap();
    assert!(eer.get("paired_vs_eer").is_none());
    let mut holm = Vec::new();
    for r in results.iter().filter(|r| r["guidance"] != "eer") {
        let p = &r["paired_vs_eer"];
        assert_eq!(p["n"], 5);
        let metrics = p["metrics"].as_array().unwrap();
        assert_eq!(metrics.len(), 4);
        for m in metrics.iter().filter(|m| !m["wilcoxon"].is_null()) {
            let (raw, adjusted) = (
                num(m, &["wilcoxon", "p_value"]),
                num(m, &["wilcoxon_p_holm"]),
            );
            assert!(adjusted >= raw && adjusted <= 1.0, "{m}");
            holm.push(adjusted);
        }
    }
    assert!(!holm.is_empty());
}
