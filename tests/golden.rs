//! Behaviour unchanged, proven: the outputs recorded with the code before the one-tracker
//! redesign (`tests/fixtures/golden/`, recorded by the commands they name) are reproduced
//! by today's binary. Per-run metrics must agree to 1e-9 (the simulated runs are
//! deterministic for their seed, so in practice they agree to the last bit).
//!
//! The fixtures are re-recorded on purpose, by `scripts/record-golden.py`, only when a
//! change of behaviour is meant (the commit that does it says which rows moved and why): a
//! new DMMN graph whose outputs differ by float32 rounding, a new EER transit, a belief
//! re-spread that repeats. Rows a change does not touch must not move; git's history of
//! `tests/fixtures/golden/` holds each re-recording.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

const METRICS: [&str; 4] = [
    "tracking_error_m",
    "estimation_error_m",
    "cov_det",
    "fov_percent",
];

fn fixture(name: &str) -> Value {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/golden")
        .join(name);
    serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap()
}

fn infotrack(args: &[&str]) -> (String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    );
    assert!(
        o.status.success(),
        "infotrack {args:?} failed\n{out}\n{err}"
    );
    (out, err)
}

fn assert_metrics_equal(what: &str, golden: &Value, got: &Value) {
    for k in METRICS {
        let (g, n) = (golden[k].as_f64().unwrap(), got[k].as_f64().unwrap());
        assert!(
            (g - n).abs() <= 1e-9 || (g.is_nan() && n.is_nan()),
            "{what}: {k} was {g} when recorded, now {n}"
        );
    }
}

/// Runs `args` with `--json` and compares every combination's per-run metrics.
fn check_sim(fixture_name: &str, args: &[&str]) {
    let golden = fixture(fixture_name);
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("r.json");
    let mut all: Vec<&str> = args.to_vec();
    all.extend(["--quiet", "--json", json.to_str().unwrap()]);
    infotrack(&all);
    let got: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(got["refused"], golden["refused"]);
    let (g_res, n_res) = (
        golden["results"].as_array().unwrap(),
        got["results"].as_array().unwrap(),
    );
    assert_eq!(g_res.len(), n_res.len(), "combinations");
    for (g, n) in g_res.iter().zip(n_res) {
        let combo = format!("{}/{}", g["guidance"], g["motion"]);
        assert_eq!(
            (&g["guidance"], &g["motion"]),
            (&n["guidance"], &n["motion"])
        );
        let (gr, nr) = (
            g["per_run"].as_array().unwrap(),
            n["per_run"].as_array().unwrap(),
        );
        assert_eq!(gr.len(), nr.len(), "{combo}: runs");
        for (i, (a, b)) in gr.iter().zip(nr).enumerate() {
            assert_metrics_equal(&format!("{combo} run {i}"), a, b);
        }
        if let Some(v) = g.get("vision") {
            assert_eq!(v, &n["vision"], "{combo}: frame statistics");
        }
    }
}

#[test]
fn sim_reproduces_the_recorded_monte_carlo() {
    check_sim(
        "sim.json",
        &[
            "sim",
            "--runs",
            "3",
            "--duration",
            "30",
            "--seed",
            "7",
            "--guidance",
            "eer,pfwm,lawn,kf,truth",
            "--motion",
            "cv,dmmn,kf",
        ],
    );
}

#[test]
fn sim_vision_reproduces_the_recorded_runs() {
    check_sim(
        "sim_vision.json",
        &[
            "sim",
            "--vision",
            "--runs",
            "2",
            "--duration",
            "30",
            "--seed",
            "7",
            "--guidance",
            "eer",
            "--motion",
            "dmmn",
        ],
    );
}

#[test]
fn closed_loop_reproduces_the_recorded_flights() {
    let golden = fixture("closed_loop.json");
    for run in golden["runs"].as_array().unwrap() {
        let seed = run["seed"].as_u64().unwrap().to_string();
        let dir = tempfile::tempdir().unwrap();
        let (stdout, _) = infotrack(&[
            "sim",
            "--closed-loop",
            "--seed",
            &seed,
            "--duration",
            "30",
            "--out",
            dir.path().to_str().unwrap(),
        ]);
        let summary: Value = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join("summary.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(
            summary["partial"], false,
            "a flight to its clean end is whole"
        );
        assert_metrics_equal(
            &format!("closed loop seed {seed}"),
            &run["metrics"],
            &summary,
        );
        // The printed digits too (the metric columns; latency is the machine's).
        let printed = |row: &str| -> Vec<String> {
            row.split('|')
                .skip(1)
                .take(5)
                .map(|c| c.trim().to_string())
                .collect()
        };
        let row = stdout
            .lines()
            .skip_while(|l| !l.starts_with("|---"))
            .nth(1)
            .unwrap_or_else(|| panic!("no results row in\n{stdout}"));
        assert_eq!(
            printed(row),
            printed(run["table_row"].as_str().unwrap()),
            "seed {seed}"
        );
    }
}
