//! The console table of a Monte Carlo result.

use std::fmt::Write;

use crate::sim::monte_carlo::ComboResult;
use crate::sim::MonteCarloResult;
use infotrack_core::metrics::WelchResult;

fn p(w: &Option<WelchResult>) -> String {
    match w {
        Some(w) if w.p_value < 0.001 => "<.001".to_string(),
        Some(w) => format!("{:.3}", w.p_value),
        None => "-".to_string(),
    }
}

/// Renders the results as a fixed-width table: mean +- sd over runs of the per-run means,
/// median step times, and the Welch p-values of EER against each baseline.
pub fn render(r: &MonteCarloResult) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "scenario {} | seed {} | {} s per run",
        r.scenario, r.seed, r.duration_s
    );
    let _ = writeln!(
        s,
        "{:<6} {:<6} {:>4}  {:>15}  {:>15}  {:>19}  {:>13}  {:>9} {:>9}  p vs eer: track/est/det/fov",
        "guid",
        "motion",
        "runs",
        "track err (m)",
        "est err (m)",
        "det(cov) (m^4)",
        "%FOV",
        "filt ms",
        "guid ms",
    );
    for c in &r.results {
        let pv = match &c.welch_vs_eer {
            Some(v) => format!(
                "{}/{}/{}/{}",
                p(&v.tracking_error_m),
                p(&v.estimation_error_m),
                p(&v.cov_det),
                p(&v.fov_percent)
            ),
            None => "-".into(),
        };
        let _ = writeln!(
            s,
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
        );
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

/// EER against one combination on the same seeds: per metric the mean difference (EER minus
/// the law) with its 95 % CI, d_z, and the Wilcoxon p after Holm's correction.
fn paired_line(c: &ComboResult, p: &crate::sim::PairedVsEer) -> String {
    let parts: Vec<String> = p
        .metrics
        .iter()
        .map(|m| match (&m.t_test, m.wilcoxon_p_holm) {
            (Some(t), Some(holm)) => format!(
                "{} {:+.3} [{:+.3}, {:+.3}] d_z {:+.2} p_holm {:.3}",
                m.metric, t.mean_diff, t.ci95[0], t.ci95[1], t.cohen_dz, holm
            ),
            _ => format!("{} -", m.metric),
        })
        .collect();
    format!(
        "paired eer - {}/{} (n {}, same seeds; 95 % CI, Wilcoxon signed-rank, Holm over all): {}",
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
