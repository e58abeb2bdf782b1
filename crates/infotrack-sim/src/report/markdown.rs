//! A campaign's `results.json` as a Markdown report: what ran (version, config, seed, n),
//! the metrics bar chart, each law's means with their 95 % bootstrap intervals, the search,
//! EER's paired comparison with every other law, and every run's figures by its seed.

use std::fmt::Write;

use serde_json::Value;

use super::table::{p_with_marks, significance_marks};
use crate::sim::monte_carlo::PAIRED_METRICS;

/// The metrics' column titles, with units, in the order of [`PAIRED_METRICS`].
const METRIC_TITLES: [&str; 4] = [
    "tracking error (m)",
    "estimation error (m)",
    "det of covariance (m^4)",
    "%FOV (%)",
];

/// The report; `figure` is the bar chart's file name relative to the report, if drawn.
pub fn render(v: &Value, figure: Option<&str>) -> Result<String, String> {
    let results = v["results"]
        .as_array()
        .ok_or("no \"results\" list: not a campaign's results.json")?;
    let mut s = String::new();
    header(&mut s, v, results);
    if let Some(f) = figure {
        let _ = writeln!(s, "![the metrics of every law]({f})\n");
    }
    means_table(&mut s, results);
    search_table(&mut s, results);
    paired_table(&mut s, results);
    runs_table(&mut s, v, results);
    method_notes(&mut s);
    Ok(s)
}

/// A number as the report prints it: four significant digits, `-` for none.
fn num(v: &Value) -> String {
    match v.as_f64() {
        Some(x) if x != 0.0 && (x.abs() >= 1e4 || x.abs() < 1e-3) => format!("{x:.3e}"),
        Some(x) => format!("{x:.4}"),
        None => "-".to_string(),
    }
}

fn interval(v: &Value) -> String {
    match (v[0].as_f64(), v[1].as_f64()) {
        (Some(_), Some(_)) => format!("[{}, {}]", num(&v[0]), num(&v[1])),
        _ => "-".to_string(),
    }
}

fn header(s: &mut String, v: &Value, results: &[Value]) {
    let runs = results
        .first()
        .map_or(0, |c| c["runs"].as_u64().unwrap_or(0));
    let laws: Vec<String> = results.iter().map(law).collect();
    let _ = writeln!(
        s,
        "# {}: {}\n",
        v["scenario"].as_str().unwrap_or("?"),
        laws.join(", ")
    );
    let _ = writeln!(s, "| | |\n|---|---|");
    let _ = writeln!(s, "| config | {} |", v["config"].as_str().unwrap_or("-"));
    let _ = writeln!(s, "| seed | {} |", v["seed"]);
    let _ = writeln!(s, "| runs per law | {runs}, on the same seeds (run i of every law chases the same target through the same noise) |");
    let _ = writeln!(s, "| run length | {} s |", v["duration_s"]);
    let _ = writeln!(
        s,
        "| infotrack | {} ({}) |\n",
        v["infotrack"]["version"].as_str().unwrap_or("?"),
        v["infotrack"]["commit"].as_str().unwrap_or("?")
    );
    if let Some(refused) = v["refused"].as_array().filter(|r| !r.is_empty()) {
        for why in refused {
            let _ = writeln!(s, "- refused: {}", why.as_str().unwrap_or("?"));
        }
        s.push('\n');
    }
}

fn law(c: &Value) -> String {
    format!(
        "{}/{}",
        c["guidance"].as_str().unwrap_or("?"),
        c["motion"].as_str().unwrap_or("?")
    )
}

fn means_table(s: &mut String, results: &[Value]) {
    let _ = writeln!(
        s,
        "## Means over runs, with their 95 % bootstrap intervals\n"
    );
    let _ = writeln!(
        s,
        "| law | runs | {} | filter step (ms) | decision (ms) |",
        METRIC_TITLES.join(" | ")
    );
    let _ = writeln!(
        s,
        "|---|---:|{}---:|---:|",
        "---:|".repeat(METRIC_TITLES.len())
    );
    for c in results {
        let cells: Vec<String> = PAIRED_METRICS
            .iter()
            .map(|(m, _)| {
                format!(
                    "{} ± {} {}",
                    num(&c[*m]["mean"]),
                    num(&c[*m]["sd"]),
                    interval(&c["ci95_bootstrap"][*m])
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} |",
            law(c),
            c["runs"],
            cells.join(" | "),
            num(&c["filter_step_ms"]["median"]),
            num(&c["guidance_step_ms"]["median"])
        );
    }
    let _ = writeln!(s, "\nEach cell: mean ± sd over runs of each run's mean, then the 95 % BCa bootstrap interval of the mean. Step times are medians over every step.\n");
}

fn search_table(s: &mut String, results: &[Value]) {
    let _ = writeln!(s, "## The search\n");
    let _ = writeln!(
        s,
        "| law | never seen | first sighting (median, s) | tracking error after it (m) |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|");
    for c in results {
        let k = &c["search"];
        let _ = writeln!(
            s,
            "| {} | {} of {} | {} | {} ± {} |",
            law(c),
            k["never_seen_runs"],
            c["runs"],
            num(&k["first_sighting_s_median"]),
            num(&k["tracking_error_after_first_sighting_m"]["mean"]),
            num(&k["tracking_error_after_first_sighting_m"]["sd"])
        );
    }
    s.push('\n');
}

fn paired_table(s: &mut String, results: &[Value]) {
    let compared: Vec<&Value> = results
        .iter()
        .filter(|c| c["paired_vs_eer"].is_object())
        .collect();
    if compared.is_empty() {
        return;
    }
    let _ = writeln!(s, "## EER against each law, run by run\n");
    let _ = writeln!(s, "| law | metric | n | EER − law | 95 % CI (t) | 95 % CI (bootstrap) | d_z | Wilcoxon p | Holm p |");
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|");
    for c in compared {
        let p = &c["paired_vs_eer"];
        for (m, title) in p["metrics"]
            .as_array()
            .into_iter()
            .flatten()
            .zip(METRIC_TITLES)
        {
            let t = &m["t_test"];
            let holm = m["wilcoxon_p_holm"].as_f64();
            let _ = writeln!(
                s,
                "| {} | {title} | {} | {} | {} | {} | {} | {} | {} |",
                law(c),
                p["n"],
                num(&t["mean_diff"]),
                interval(&t["ci95"]),
                interval(&m["mean_diff_ci95_bootstrap"]),
                num(&t["cohen_dz"]),
                num(&m["wilcoxon"]["p_value"]),
                p_with_marks(holm)
            );
        }
    }
    let _ = writeln!(s, "\nHolm's correction runs over every law and metric in this table; {} marks p < .05, {} p < .01, {} p < .001.\n", significance_marks(0.04), significance_marks(0.009), significance_marks(0.0009));
}

fn runs_table(s: &mut String, v: &Value, results: &[Value]) {
    let _ = writeln!(s, "## Every run (%FOV, %)\n");
    let laws: Vec<String> = results.iter().map(law).collect();
    let _ = writeln!(s, "| run | seed | track | {} |", laws.join(" | "));
    let _ = writeln!(s, "|---:|---:|---|{}", "---:|".repeat(laws.len()));
    let n = results
        .iter()
        .map(|c| c["per_run"].as_array().map_or(0, Vec::len))
        .max()
        .unwrap_or(0);
    for i in 0..n {
        let first = &results[0]["per_run"][i];
        let cells: Vec<String> = results
            .iter()
            .map(|c| num(&c["per_run"][i]["fov_percent"]))
            .collect();
        let _ = writeln!(
            s,
            "| {i} | {} | {} | {} |",
            v["seed"],
            first["track"].as_str().unwrap_or("-"),
            cells.join(" | ")
        );
    }
    s.push('\n');
}

fn method_notes(s: &mut String) {
    let _ = writeln!(
        s,
        "## How to read this\n\n\
         - Each run's figure is a mean over its filter steps, and the table's mean is over \
         runs. **tracking error**: the horizontal distance from the drone to the target; \
         **estimation error**: the distance from the estimate to the target; **det of \
         covariance**: the determinant of the estimate's covariance (its spread); **%FOV**: \
         the share of filter steps with a measurement of the target.\n\
         - Every law flies the same runs: run i of each uses the same target and noise, so \
         laws are compared run by run (paired): the Wilcoxon signed-rank test, the paired \
         t-test's interval and Cohen's d_z (the mean difference over the differences' sd).\n\
         - The bootstrap intervals are BCa with 10 000 resamples, drawn from the campaign's \
         seed: the same results give the same intervals."
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_campaign_renders_every_law_its_intervals_and_its_runs() {
        let v = serde_json::json!({
            "scenario": "lab", "seed": 7, "duration_s": 30.0, "config": "config/default.toml",
            "infotrack": {"version": "0.2.0", "commit": "abc"},
            "results": [
                {"guidance": "eer", "motion": "cv", "runs": 2,
                 "fov_percent": {"mean": 80.0, "sd": 3.0},
                 "ci95_bootstrap": {"fov_percent": [77.0, 83.0]},
                 "search": {"never_seen_runs": 0},
                 "per_run": [{"fov_percent": 78.0}, {"fov_percent": 82.0}]},
                {"guidance": "lawn", "motion": "cv", "runs": 2,
                 "fov_percent": {"mean": 20.0, "sd": 3.0},
                 "search": {"never_seen_runs": 1},
                 "paired_vs_eer": {"n": 2, "metrics": [
                     {"t_test": {"mean_diff": -1.0}, "wilcoxon_p_holm": 0.002}]},
                 "per_run": [{"fov_percent": 18.0}, {"fov_percent": 22.0}]}
            ]
        });
        let md = render(&v, Some("metrics.png")).unwrap();
        assert!(md.starts_with("# lab: eer/cv, lawn/cv"), "{md}");
        assert!(md.contains("| seed | 7 |") && md.contains("0.2.0 (abc)"));
        assert!(md.contains("![the metrics of every law](metrics.png)"));
        assert!(md.contains("80.0000 ± 3.0000 [77.0000, 83.0000]"), "{md}");
        assert!(md.contains("| lawn/cv | 1 of 2 |"), "{md}");
        assert!(
            md.contains("| lawn/cv | tracking error (m) | 2 | -1.0000 |"),
            "{md}"
        );
        assert!(md.contains("0.002**"), "{md}");
        assert!(md.contains("| 1 | 7 | - | 82.0000 | 22.0000 |"), "{md}");
    }
}
