//! The console table of a Monte Carlo result.

use std::fmt::Write;

use crate::metrics::WelchResult;
use crate::sim::MonteCarloResult;

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
    for why in &r.refused {
        let _ = writeln!(s, "refused: {why}");
    }
    s
}
