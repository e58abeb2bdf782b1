//! `infotrack report` on a campaign `infotrack sim` wrote, as a researcher runs it: the
//! intervals in the results, the Markdown report and its figure, and clear errors.

use std::path::Path;
use std::process::Command;

fn infotrack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_infotrack"))
}

fn run_ok(c: &mut Command) -> String {
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Width and height of a PNG, from its IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(
        &b[..8],
        b"\x89PNG\r\n\x1a\n",
        "{} is not a PNG",
        path.display()
    );
    let be = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    (be(16), be(20))
}

#[test]
fn a_campaign_carries_bootstrap_intervals_and_renders_as_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("results.json");
    let table = run_ok(
        infotrack()
            .args([
                "sim",
                "--runs",
                "8",
                "--duration",
                "20",
                "--guidance",
                "eer,lawn",
                "--quiet",
            ])
            .arg("--json")
            .arg(&json),
    );
    assert!(
        table.contains("n = 8 runs per law, on the same seeds"),
        "{table}"
    );
    assert!(
        table.contains("95 % CI of the mean lawn/cv (BCa bootstrap over 8 runs)"),
        "{table}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for c in v["results"].as_array().unwrap() {
        let mean = c["tracking_error_m"]["mean"].as_f64().unwrap();
        let ci = &c["ci95_bootstrap"]["tracking_error_m"];
        let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
        assert!(
            lo <= mean && mean <= hi,
            "{} [{lo}, {hi}] around {mean}",
            c["guidance"]
        );
    }
    let run = &v["results"][0]["per_run"][3];
    assert_eq!(
        (run["run"].as_u64(), run["seed"].as_u64()),
        (Some(3), Some(7)),
        "{run}"
    );
    assert_eq!(run["world"], "paper-lab (drawn in the config)");
    let lawn = &v["results"][1]["paired_vs_eer"]["metrics"][0];
    let diff = lawn["t_test"]["mean_diff"].as_f64().unwrap();
    let boot = &lawn["mean_diff_ci95_bootstrap"];
    assert!(
        boot[0].as_f64().unwrap() <= diff && diff <= boot[1].as_f64().unwrap(),
        "{lawn}"
    );

    let out = dir.path().join("report");
    let said = run_ok(infotrack().arg("report").arg(&json).arg("--out").arg(&out));
    assert!(said.contains("report.md"), "{said}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.starts_with("# paper-lab: eer/cv, lawn/cv"), "{md}");
    assert!(
        md.contains("![the metrics of every law](metrics.png)"),
        "{md}"
    );
    assert!(md.contains("| lawn/cv | %FOV (%) | 8 |"), "{md}");
    assert_eq!(
        md.matches("\n| 7 | 7 |").count(),
        1,
        "every run by its seed: {md}"
    );
    assert_eq!(png_size(&out.join("metrics.png")), (1200, 840));

    // The same results give the same report, beside them when no folder is given.
    run_ok(infotrack().arg("report").arg(&json));
    assert_eq!(
        std::fs::read_to_string(dir.path().join("report.md")).unwrap(),
        md
    );
}

#[test]
fn a_file_that_is_not_a_campaign_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    for (name, text, why) in [
        ("broken.json", "{\"results\": [", "is not JSON"),
        (
            "flight.json",
            "{\"version\": 1}",
            "not a campaign's results.json",
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let o = infotrack().arg("report").arg(&path).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert!(err.contains(name) && err.contains(why), "{err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let o = infotrack()
        .args(["report", "/nonexistent/results.json"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("cannot read /nonexistent/results.json"),
        "{err}"
    );
}
