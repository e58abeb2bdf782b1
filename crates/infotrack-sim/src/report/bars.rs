//! The metrics bar chart of a campaign (like the paper's bar figure): one panel per metric,
//! one bar per guidance law and motion model (the mean over runs), its whisker the 95 %
//! bootstrap interval of that mean, and marks over the laws EER differs from. It is drawn
//! from a campaign's `results.json`, so that `sim --out` and `infotrack report` draw the
//! same figure from the same numbers.

use std::path::Path;

use plotters::prelude::*;
use serde_json::Value;

use super::table::significance_marks;
use super::ReportError;
use crate::sim::monte_carlo::PAIRED_METRICS;

/// The panels' titles and axis labels, with units, in the order of [`PAIRED_METRICS`].
const PANEL_LABELS: [&str; 4] = [
    "tracking error (m)",
    "estimation error (m)",
    "det of covariance (m^4)",
    "target in view, %FOV (% of steps)",
];

/// What the bar chart shows, read from a campaign's results.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricsFigure {
    /// First title line: the scenario, n, seed and run length.
    pub title: String,
    /// The bars' names, `law/motion`.
    pub laws: Vec<String>,
    /// One panel per metric.
    pub panels: Vec<Panel>,
}

/// One metric's panel.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Title and y-axis label, with the unit.
    pub label: &'static str,
    /// One bar per law, in the order of [`MetricsFigure::laws`].
    pub bars: Vec<Bar>,
}

/// One law's bar.
#[derive(Debug, Clone, PartialEq)]
pub struct Bar {
    /// The mean over runs.
    pub mean: f64,
    /// The 95 % bootstrap interval of the mean, when there were two runs or more.
    pub ci95: Option<[f64; 2]>,
    /// `*`, `**` or `***` when EER differs from this law (paired, Holm-corrected).
    pub marks: &'static str,
}

/// A number of the results, NaN where JSON has `null` (a mean of no samples).
fn number(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

impl MetricsFigure {
    /// The figure of a campaign's `results.json`; an error names what is missing.
    pub fn from_results_json(v: &Value) -> Result<Self, String> {
        let results = v["results"]
            .as_array()
            .ok_or("no \"results\" list: not a campaign's results.json")?;
        let runs = results
            .first()
            .and_then(|c| c["runs"].as_u64())
            .unwrap_or(0);
        let title = format!(
            "{}: bars are the mean over n = {runs} runs per law (the same seeds); seed {}, {} s runs",
            v["scenario"].as_str().unwrap_or("?"),
            v["seed"],
            v["duration_s"]
        );
        let mut laws = Vec::new();
        for (i, c) in results.iter().enumerate() {
            let (Some(g), Some(m)) = (c["guidance"].as_str(), c["motion"].as_str()) else {
                return Err(format!("results[{i}] has no \"guidance\" or \"motion\""));
            };
            laws.push(format!("{g}/{m}"));
        }
        let panels = PAIRED_METRICS
            .iter()
            .zip(PANEL_LABELS)
            .enumerate()
            .map(|(k, ((metric, _), label))| Panel {
                label,
                bars: results.iter().map(|c| bar_of(c, metric, k)).collect(),
            })
            .collect();
        Ok(Self {
            title,
            laws,
            panels,
        })
    }
}

/// One law's bar for `metric`, the `k`-th of the paired metrics.
fn bar_of(c: &Value, metric: &str, k: usize) -> Bar {
    let ci = &c["ci95_bootstrap"][metric];
    let ci95 = match (ci[0].as_f64(), ci[1].as_f64()) {
        (Some(lo), Some(hi)) => Some([lo, hi]),
        _ => None,
    };
    let p_holm = c["paired_vs_eer"]["metrics"][k]["wilcoxon_p_holm"].as_f64();
    Bar {
        mean: number(&c[metric]["mean"]),
        ci95,
        marks: p_holm.map_or("", significance_marks),
    }
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> ReportError {
    ReportError::Plot {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Draws the figure into `path` (PNG), creating its folder; written whole or not at all.
pub fn draw(path: &Path, figure: &MetricsFigure) -> Result<(), ReportError> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|source| ReportError::Io {
            path: parent.to_path_buf(),
            source,
        })?;
    }
    super::whole_file(path, |tmp| draw_into(tmp, figure))
}

fn draw_into(path: &Path, figure: &MetricsFigure) -> Result<(), ReportError> {
    let root = BitMapBackend::new(path, (1200, 840)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let body = root
        .titled(&figure.title, ("sans-serif", 18))
        .map_err(|e| plot_err(path, e))?
        .titled(
            "whiskers: 95 % BCa bootstrap interval of the mean;  marks: EER differs from the law \
             (paired Wilcoxon, Holm-corrected)  * p < .05  ** p < .01  *** p < .001",
            ("sans-serif", 15),
        )
        .map_err(|e| plot_err(path, e))?;
    for (area, panel) in body.split_evenly((2, 2)).iter().zip(&figure.panels) {
        draw_panel(area, panel, &figure.laws).map_err(|e| plot_err(path, e))?;
    }
    root.present().map_err(|e| plot_err(path, e))
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// The panel's y range: from 0 to a little above the highest whisker or bar.
fn panel_top(panel: &Panel) -> f64 {
    panel
        .bars
        .iter()
        .map(|b| b.ci95.map_or(b.mean, |ci| ci[1].max(b.mean)))
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .max(1e-9)
        * 1.2
}

fn draw_panel(area: &Area<'_>, panel: &Panel, laws: &[String]) -> Result<(), String> {
    let top = panel_top(panel);
    let n = panel.bars.len().max(1) as f64;
    let mut chart = ChartBuilder::on(area)
        .caption(panel.label, ("sans-serif", 17))
        .margin(10)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..(n - 0.5), 0.0..top)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_desc("guidance law / motion model")
        .y_desc(panel.label)
        .x_labels(panel.bars.len().max(1))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                laws.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .draw()
        .map_err(|e| e.to_string())?;
    let bars = panel
        .bars
        .iter()
        .enumerate()
        .filter(|(_, b)| b.mean.is_finite());
    chart
        .draw_series(bars.clone().map(|(i, b)| {
            let x = i as f64;
            Rectangle::new(
                [(x - 0.3, 0.0), (x + 0.3, b.mean.max(0.0))],
                BLUE.mix(0.6).filled(),
            )
        }))
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(bars.clone().filter_map(|(i, b)| {
            let [lo, hi] = b.ci95?;
            let x = i as f64;
            Some(PathElement::new(
                vec![(x, lo.max(0.0)), (x, hi)],
                BLACK.stroke_width(2),
            ))
        }))
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(bars.filter(|(_, b)| !b.marks.is_empty()).map(|(i, b)| {
            let y = b.ci95.map_or(b.mean, |ci| ci[1].max(b.mean)) + 0.04 * top;
            Text::new(
                b.marks,
                (i as f64 - 0.08, y),
                ("sans-serif", 20).into_font(),
            )
        }))
        .map_err(|e| e.to_string())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn results() -> Value {
        serde_json::json!({
            "scenario": "lab", "seed": 7, "duration_s": 30.0,
            "results": [
                {"guidance": "eer", "motion": "cv", "runs": 5,
                 "tracking_error_m": {"mean": 1.0, "sd": 0.1},
                 "estimation_error_m": {"mean": 0.5, "sd": 0.1},
                 "cov_det": {"mean": null, "sd": null},
                 "fov_percent": {"mean": 80.0, "sd": 3.0},
                 "ci95_bootstrap": {"fov_percent": [77.0, 83.0]}},
                {"guidance": "lawn", "motion": "cv", "runs": 5,
                 "tracking_error_m": {"mean": 3.0, "sd": 0.1},
                 "estimation_error_m": {"mean": 2.5, "sd": 0.1},
                 "cov_det": {"mean": 2.0, "sd": 0.1},
                 "fov_percent": {"mean": 20.0, "sd": 3.0},
                 "paired_vs_eer": {"metrics": [
                     {"wilcoxon_p_holm": 0.004}, {"wilcoxon_p_holm": 0.2},
                     {}, {"wilcoxon_p_holm": 0.0001}]}}
            ]
        })
    }

    #[test]
    fn the_figure_reads_means_intervals_and_marks_from_the_results() {
        let f = MetricsFigure::from_results_json(&results()).unwrap();
        assert_eq!(f.laws, ["eer/cv", "lawn/cv"]);
        assert!(f.title.contains("n = 5 runs") && f.title.contains("seed 7"));
        let fov = &f.panels[3];
        assert_eq!(fov.label, PANEL_LABELS[3]);
        assert_eq!(fov.bars[0].ci95, Some([77.0, 83.0]));
        assert_eq!((fov.bars[0].marks, fov.bars[1].marks), ("", "***"));
        assert_eq!(f.panels[0].bars[1].marks, "**");
        assert_eq!(f.panels[1].bars[1].marks, "");
        assert!(f.panels[2].bars[0].mean.is_nan());
    }

    #[test]
    fn a_file_that_is_not_a_campaign_is_refused_with_what_is_missing() {
        let e = MetricsFigure::from_results_json(&serde_json::json!({"runs": []})).unwrap_err();
        assert!(e.contains("\"results\""), "{e}");
        let e =
            MetricsFigure::from_results_json(&serde_json::json!({"results": [{}]})).unwrap_err();
        assert!(e.contains("results[0]"), "{e}");
    }
}
