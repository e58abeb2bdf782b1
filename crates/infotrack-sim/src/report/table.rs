//! The console table of a Monte Carlo result.

use std::fmt::Write;

use crate::sim::monte_carlo::{ComboResult, PAIRED_METRICS};
use crate::sim::MonteCarloResult;

/// A p-value as the table prints it, with the usual marks: `*` < .05, `**` < .01,
/// `***` < .001.
pub fn p_with_marks(p: Option<f64>) -> String {
    match p {
        Some(p) if p < 0.001 => "<.001***".to_string(),
        Some(p) => format!("{p:.3}{}", significance_marks(p)),
        None => "-".to_string(),
    }
}

/// The marks of a p-value: `*` < .05, `**` < .01, `***` < .001, else nothing.
pub fn significance_marks(p: f64) -> &'static str {
    if p < 0.001 {
        "***"
    } else if p < 0.01 {
        "**"
    } else if p < 0.05 {
        "*"
    } else {
        ""
    }
}

/// Renders the results as a fixed-width table: per law, mean +- sd over runs of the per-run
/// means, median step times and EER's paired comparison with it; then each mean's
/// bootstrap interval, the search, and the paired differences in full.
pub fn render(r: &MonteCarloResult) -> String {
    let mut s = String::new();
    let runs = r.results.first().map_or(0, |c| c.runs);
    let _ = writeln!(
        s,
        "scenario {} | seed {} | {} s per run | n = {runs} runs per law, on the same seeds",
        r.scenario, r.seed, r.duration_s
    );
    let _ = writeln!(
        s,
        "{:<6} {:<6} {:>4}  {:>15}  {:>15}  {:>19}  {:>13}  {:>9} {:>9}  eer vs law, p: track/est/det/fov",
        "guid",
        "motion",
        "runs",
        "track err (m)",
        "est err (m)",
        "det(cov) (m^4)",
        "%FOV (%)",
        "filt ms",
        "guid ms",
    );
    for c in &r.results {
        let _ = writeln!(s, "{}", law_row(c));
    }
    let _ = writeln!(
        s,
        "(p: Wilcoxon signed-rank of EER against the law on the same seeds, Holm-corrected over every law and metric; * < .05, ** < .01, *** < .001)"
    );
    for c in &r.results {
        let _ = writeln!(s, "{}", interval_line(c));
    }
    for c in &r.results {
        let _ = writeln!(s, "{}", search_line(c));
    }
    for c in &r.results {
        if let Some(p) = &c.paired_vs_eer {
            let _ = writeln!(s, "{}", paired_line(c, p));
        }
    }
    for why in &r.refused {
        let _ = writeln!(s, "refused: {why}");
    }
    s
}

/// One law's row of the table.
fn law_row(c: &ComboResult) -> String {
    let pv = match &c.paired_vs_eer {
        Some(p) => p
            .metrics
            .iter()
            .map(|m| p_with_marks(m.wilcoxon_p_holm))
            .collect::<Vec<_>>()
            .join("/"),
        None => "-".into(),
    };
    format!(
        "{:<6} {:<6} {:>4}  {:>7.3} ± {:<5.3}  {:>7.3} ± {:<5.3}  {:>9.2e} ± {:<7.1e}  {:>5.1} ± {:<5.1}  {:>9.3} {:>9.3}  {}",
        c.guidance,
        c.motion,
        c.runs,
        c.tracking_error_m.mean,
        c.tracking_error_m.sd,
        c.estimation_error_m.mean,
        c.estimation_error_m.sd,
        c.cov_det.mean,
        c.cov_det.sd,
        c.fov_percent.mean,
        c.fov_percent.sd,
        c.filter_step_ms.median,
        c.guidance_step_ms.median,
        pv
    )
}

/// One law's 95 % bootstrap intervals of its metrics' means.
fn interval_line(c: &ComboResult) -> String {
    let units = ["m", "m", "m^4", "%"];
    let parts: Vec<String> = PAIRED_METRICS
        .iter()
        .zip(units)
        .map(|((metric, _), unit)| match c.ci95_bootstrap.get(*metric) {
            Some([lo, hi]) => format!("{metric} [{lo:.4}, {hi:.4}] {unit}"),
            None => format!("{metric} -"),
        })
        .collect();
    format!(
        "95 % CI of the mean {}/{} (BCa bootstrap over {} runs): {}",
        c.guidance,
        c.motion,
        c.runs,
        parts.join("; ")
    )
}

/// EER against one combination on the same seeds: per metric the mean difference (EER minus
/// the law) with its 95 % t interval and BCa bootstrap interval, d_z, and the Wilcoxon p
/// after Holm's correction.
fn paired_line(c: &ComboResult, p: &crate::sim::PairedVsEer) -> String {
    let parts: Vec<String> = p
        .metrics
        .iter()
        .map(|m| match (&m.t_test, m.wilcoxon_p_holm) {
            (Some(t), Some(holm)) => format!(
                "{} {:+.3} [{:+.3}, {:+.3}] boot {} d_z {:+.2} p_holm {:.3}{}",
                m.metric,
                t.mean_diff,
                t.ci95[0],
                t.ci95[1],
                m.mean_diff_ci95_bootstrap
                    .map_or("-".to_string(), |[lo, hi]| format!("[{lo:+.3}, {hi:+.3}]")),
                t.cohen_dz,
                holm,
                significance_marks(holm)
            ),
            _ => format!("{} -", m.metric),
        })
        .collect();
    format!(
        "paired eer - {}/{} (n {}, same seeds; 95 % t and bootstrap CI, Wilcoxon signed-rank, Holm over all): {}",
        c.guidance,
        c.motion,
        p.n,
        parts.join("; ")
    )
}

/// One combination's search apart from its tracking, under the table.
fn search_line(c: &ComboResult) -> String {
    let k = &c.search;
    let seen = c.runs - k.never_seen_runs;
    if seen == 0 {
        return format!(
            "search {}/{}: the target was never seen in {} runs",
            c.guidance, c.motion, c.runs
        );
    }
    let after = &k.tracking_error_after_first_sighting_m;
    format!(
        "search {}/{}: first sighting at {:.1} s (median of {seen} runs), never seen in {} of {}; tracking error after it {:.3} ± {:.3} m",
        c.guidance, c.motion, k.first_sighting_s_median, k.never_seen_runs, c.runs, after.mean, after.sd
    )
}
