//! The Monte Carlo benchmark: guidance x estimator combinations, many runs each, in
//! parallel, aggregated into the paper's metrics with Welch t-tests of EER against each
//! baseline.

use std::collections::BTreeMap;

use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;

use super::run::{check_combination, run_once, EstimatorKind, RunError, RunOutput, RunSpec};
use infotrack_config::Config;
use infotrack_core::guidance::GuidanceKind;
use infotrack_core::metrics::{
    mean_sd, median, welch_t_test, MeanSd, RunSummary, SearchSummary, WelchResult,
};

/// What to run.
#[derive(Debug, Clone)]
pub struct MonteCarlo {
    /// Guidance laws.
    pub guidance: Vec<GuidanceKind>,
    /// Estimators.
    pub estimators: Vec<EstimatorKind>,
    /// Runs per combination.
    pub runs: u64,
    /// User seed.
    pub seed: u64,
    /// Run length, s.
    pub duration_s: f64,
    /// Keep every run's step records (for CSV logs and plots).
    pub keep_outputs: bool,
    /// Show a progress bar on stderr.
    pub progress: bool,
    /// Measure through rendered frames and the real detector (`sim --vision`).
    pub vision: bool,
    /// Keep run 0's particles at every filter step (`sim --record`); needs `keep_outputs`.
    pub trace_first_run: bool,
    /// Run only this shard's runs (`sim --shard K/N`); `None`: all of them.
    pub shard: Option<Shard>,
}

/// One of N independent parts of a campaign: the runs whose index is K modulo N. Every run
/// draws from its own seeded streams, so a run is the same in whichever shard it runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct Shard {
    /// K, from 0.
    pub index: u64,
    /// N.
    pub count: u64,
}

impl Shard {
    /// Whether run `r` is this shard's.
    pub fn has(&self, r: u64) -> bool {
        r % self.count == self.index
    }
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `K/N`, 0 <= K < N.
    fn from_str(text: &str) -> Result<Self, String> {
        let bad = || format!("`{text}`: a shard is K/N with 0 <= K < N, e.g. 0/4");
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let (index, count) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }
}

/// How the camera frames went in vision mode, summed over runs.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct VisionSummary {
    /// Frames rendered and searched.
    pub frames: u64,
    /// Frames in which the target's tag was found.
    pub detections: u64,
    /// Detections found in the region of interest around the filter's prediction.
    pub roi_hits: u64,
}

/// A median, as the JSON schema wants it.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Median {
    /// The median.
    pub median: f64,
}

/// p-values of Welch t-tests of EER against this combination, per metric.
#[derive(Debug, Clone, Serialize)]
pub struct VersusEer {
    /// On tracking error.
    pub tracking_error_m: Option<WelchResult>,
    /// On estimation error.
    pub estimation_error_m: Option<WelchResult>,
    /// On det of the covariance.
    pub cov_det: Option<WelchResult>,
    /// On %FOV.
    pub fov_percent: Option<WelchResult>,
}

/// EER against this combination on the same seeds (run i of both chased the same target
/// with the same noise): the paired tests per metric, EER minus this law.
#[derive(Debug, Clone, Serialize)]
pub struct PairedVsEer {
    /// Pairs (runs of both).
    pub n: usize,
    /// Per metric, in the order of [`PAIRED_METRICS`].
    pub metrics: Vec<PairedMetric>,
}

/// One metric's paired comparison.
#[derive(Debug, Clone, Serialize)]
pub struct PairedMetric {
    /// The metric's name in the per-run summaries.
    pub metric: &'static str,
    /// Paired t-test of EER minus this law: mean difference, its 95 % CI, Cohen's d_z.
    pub t_test: Option<infotrack_core::metrics::paired::PairedT>,
    /// Wilcoxon signed-rank test of the same pairs.
    pub wilcoxon: Option<infotrack_core::metrics::paired::Wilcoxon>,
    /// The Wilcoxon p-value after Holm's correction over every law and metric compared with
    /// EER in this campaign.
    pub wilcoxon_p_holm: Option<f64>,
    /// The 95 % BCa bootstrap interval of the mean difference (seeded by the campaign's
    /// seed).
    pub mean_diff_ci95_bootstrap: Option<[f64; 2]>,
}

/// A per-run metric.
pub type RunMetric = fn(&RunSummary) -> f64;

/// The metrics compared in pairs.
pub const PAIRED_METRICS: [(&str, RunMetric); 4] = [
    ("tracking_error_m", |s| s.tracking_error_m),
    ("estimation_error_m", |s| s.estimation_error_m),
    ("cov_det", |s| s.cov_det),
    ("fov_percent", |s| s.fov_percent),
];

/// Aggregates of one guidance x estimator combination.
#[derive(Debug, Clone, Serialize)]
pub struct ComboResult {
    /// Guidance law.
    pub guidance: String,
    /// Motion model / estimator.
    pub motion: String,
    /// Number of runs.
    pub runs: usize,
    /// The campaign index of each run, in the order of `per_run` (0, 1, ... unless a shard
    /// ran only some).
    pub run_indices: Vec<u64>,
    /// Tracking error, m: mean and sd over runs of each run's mean.
    pub tracking_error_m: MeanSd,
    /// Estimation error, m.
    pub estimation_error_m: MeanSd,
    /// det of the covariance, m^4.
    pub cov_det: MeanSd,
    /// %FOV.
    pub fov_percent: MeanSd,
    /// Per metric of [`PAIRED_METRICS`], the 95 % BCa bootstrap interval of its mean over
    /// the runs (seeded by the campaign's seed); absent for fewer than two runs.
    pub ci95_bootstrap: BTreeMap<String, [f64; 2]>,
    /// Median filter step time over all steps of all runs, ms.
    pub filter_step_ms: Median,
    /// Median guidance step time, ms.
    pub guidance_step_ms: Median,
    /// Welch t-test of EER (same estimator) against this combination; absent for EER itself
    /// or when EER was not run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub welch_vs_eer: Option<VersusEer>,
    /// EER against this combination on the same seeds: paired tests with Holm's correction;
    /// absent for EER itself or when EER was not run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paired_vs_eer: Option<PairedVsEer>,
    /// Frame statistics (vision mode only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vision: Option<VisionSummary>,
    /// The search apart from the tracking: runs that never saw the target, the median
    /// time of the first sighting, and the tracking error after it.
    pub search: SearchSummary,
    /// Per-run summaries.
    pub per_run: Vec<RunSummary>,
}

/// The whole benchmark's result.
#[derive(Debug, Clone, Serialize)]
pub struct MonteCarloResult {
    /// One entry per combination that ran.
    pub results: Vec<ComboResult>,
    /// Combinations refused, with the reason.
    pub refused: Vec<String>,
    /// Seed used.
    pub seed: u64,
    /// Scenario name.
    pub scenario: String,
    /// Run length, s.
    pub duration_s: f64,
    /// Every run's output, by (guidance, motion), when asked to keep them.
    #[serde(skip)]
    pub outputs: BTreeMap<(String, String), Vec<RunOutput>>,
}

impl MonteCarlo {
    /// Runs the benchmark. Combinations that make no sense are refused with their reason
    /// (listed in the result); it is an error only if nothing is left to run.
    pub fn run(&self, cfg: &Config) -> Result<MonteCarloResult, RunError> {
        let world = cfg.world();
        let mut combos = Vec::new();
        let mut refused = Vec::new();
        let mut first_err = None;
        for g in &self.guidance {
            for e in &self.estimators {
                match check_combination(*g, e) {
                    Ok(()) => combos.push((*g, e.clone())),
                    Err(err) => {
                        refused.push(err.to_string());
                        first_err.get_or_insert(err);
                    }
                }
            }
        }
        if combos.is_empty() {
            return Err(first_err.map_or(RunError::NothingToRun, RunError::from));
        }
        let shard = self.shard;
        let runs: Vec<u64> = (0..self.runs)
            .filter(|r| shard.map_or(true, |s| s.has(*r)))
            .collect();
        let jobs: Vec<(usize, u64)> = (0..combos.len())
            .flat_map(|c| runs.iter().map(move |r| (c, *r)))
            .collect();
        let bar = progress_bar(self.progress, jobs.len());
        let snapshot_times: Vec<f64> = [1.0 / 6.0, 0.5, 5.0 / 6.0]
            .iter()
            .map(|f| f * self.duration_s)
            .collect();
        let outputs: Vec<Result<RunOutput, RunError>> = jobs
            .par_iter()
            .map(|&(c, r)| {
                let (g, e) = &combos[c];
                let spec = RunSpec {
                    guidance: *g,
                    estimator: e.clone(),
                    seed: self.seed,
                    run_index: r,
                    duration_s: self.duration_s,
                    snapshot_times_s: snapshot_times.clone(),
                    vision: self.vision,
                    trace: self.trace_first_run && r == 0,
                };
                let out = run_once(cfg, &world, &spec);
                bar.inc(1);
                out
            })
            .collect();
        bar.finish_and_clear();

        let mut by_combo: Vec<Vec<RunOutput>> = vec![Vec::new(); combos.len()];
        for ((c, _), out) in jobs.iter().zip(outputs) {
            by_combo[*c].push(out?);
        }
        let mut results: Vec<ComboResult> = combos
            .iter()
            .zip(&by_combo)
            .map(|((g, e), outs)| aggregate(*g, e, outs, &runs))
            .collect();
        compare(&mut results, self.seed);
        let mut outputs_map = BTreeMap::new();
        if self.keep_outputs {
            for ((g, e), outs) in combos.iter().zip(by_combo) {
                outputs_map.insert((g.to_string(), e.name().to_string()), outs);
            }
        }
        Ok(MonteCarloResult {
            results,
            refused,
            seed: self.seed,
            scenario: cfg.name.clone(),
            duration_s: self.duration_s,
            outputs: outputs_map,
        })
    }
}

fn aggregate(g: GuidanceKind, e: &EstimatorKind, outs: &[RunOutput], runs: &[u64]) -> ComboResult {
    let all = |f: fn(&RunOutput) -> &Vec<f64>| -> Vec<f64> {
        outs.iter().flat_map(|o| f(o).iter().copied()).collect()
    };
    let vision = outs.iter().filter_map(|o| o.vision).fold(None, |acc, v| {
        Some(VisionSummary::sum(acc, v.frames, v.detections, v.roi_hits))
    });
    ComboResult::from_runs(
        (g.to_string(), e.name().to_string()),
        outs.iter().map(|o| o.summary).collect(),
        runs.to_vec(),
        [
            median(&all(|o| &o.filter_ms)),
            median(&all(|o| &o.guidance_ms)),
        ],
        vision,
    )
}

impl VisionSummary {
    /// `acc` (none yet: zero) plus these counts.
    pub fn sum(acc: Option<Self>, frames: u64, detections: u64, roi_hits: u64) -> Self {
        let a = acc.unwrap_or(Self {
            frames: 0,
            detections: 0,
            roi_hits: 0,
        });
        Self {
            frames: a.frames + frames,
            detections: a.detections + detections,
            roi_hits: a.roi_hits + roi_hits,
        }
    }
}

impl ComboResult {
    /// One law and model's aggregates from its runs' summaries (`run_indices` names them),
    /// the medians of its filter and guidance step times, and its frame counts; the
    /// comparisons with EER are left to [`compare`].
    pub fn from_runs(
        (guidance, motion): (String, String),
        per_run: Vec<RunSummary>,
        run_indices: Vec<u64>,
        [filter_ms, guidance_ms]: [f64; 2],
        vision: Option<VisionSummary>,
    ) -> Self {
        let col = |f: fn(&RunSummary) -> f64| mean_sd(&per_run.iter().map(f).collect::<Vec<_>>());
        Self {
            guidance,
            motion,
            runs: per_run.len(),
            run_indices,
            tracking_error_m: col(|s| s.tracking_error_m),
            estimation_error_m: col(|s| s.estimation_error_m),
            cov_det: col(|s| s.cov_det),
            fov_percent: col(|s| s.fov_percent),
            ci95_bootstrap: BTreeMap::new(),
            filter_step_ms: Median { median: filter_ms },
            guidance_step_ms: Median {
                median: guidance_ms,
            },
            welch_vs_eer: None,
            paired_vs_eer: None,
            vision,
            search: SearchSummary::over(&per_run),
            per_run,
        }
    }
}

/// Every statistic that compares runs: each mean's bootstrap interval, and EER against
/// every other law (Welch, and paired with Holm's correction), from the campaign's seed.
pub fn compare(results: &mut [ComboResult], seed: u64) {
    add_bootstrap_intervals(results, seed);
    add_welch_tests(results);
    add_paired_tests(results, seed);
}

/// A progress bar over `jobs` runs, or a hidden one.
fn progress_bar(shown: bool, jobs: usize) -> ProgressBar {
    if !shown {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(jobs as u64);
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} {pos}/{len} runs {elapsed_precise} eta {eta}")
    {
        b.set_style(style);
    }
    b
}

/// EER's per-run summaries, by motion model: what every other law is compared with.
fn eer_runs_by_motion(results: &[ComboResult]) -> BTreeMap<String, Vec<RunSummary>> {
    results
        .iter()
        .filter(|r| r.guidance == "eer")
        .map(|r| (r.motion.clone(), r.per_run.clone()))
        .collect()
}

/// The resampling stream of one interval: the campaign's seed, the combination's place and
/// the metric's, so that each interval is reproducible and independent of the others.
fn statistics_rng(seed: u64, combo: usize, salt: usize) -> infotrack_core::rng::CoreRng {
    use infotrack_core::rng::{stream_rng, Stream};
    stream_rng(seed, combo as u64, Stream::Statistics, salt as u64)
}

/// Each combination's bootstrap intervals of its metrics' means over runs.
fn add_bootstrap_intervals(results: &mut [ComboResult], seed: u64) {
    use infotrack_core::metrics::bootstrap::{bca_mean_ci95, RESAMPLES};
    for (c, r) in results.iter_mut().enumerate() {
        for (k, (metric, f)) in PAIRED_METRICS.iter().enumerate() {
            let x: Vec<f64> = r.per_run.iter().map(f).collect();
            if let Some(ci) = bca_mean_ci95(&x, RESAMPLES, &mut statistics_rng(seed, c, k)) {
                r.ci95_bootstrap.insert(metric.to_string(), ci);
            }
        }
    }
}

/// Paired tests of EER against every other law with the same estimator (run i of both used
/// seed i's streams), the Wilcoxon p-values Holm-corrected over all of them.
fn add_paired_tests(results: &mut [ComboResult], seed: u64) {
    use infotrack_core::metrics::bootstrap::{bca_mean_ci95, RESAMPLES};
    use infotrack_core::metrics::paired::{holm, paired_t_test, wilcoxon_signed_rank};
    let eer_runs = eer_runs_by_motion(results);
    for (c, r) in results.iter_mut().enumerate() {
        if r.guidance == "eer" {
            continue;
        }
        let Some(eer) = eer_runs
            .get(&r.motion)
            .filter(|e| e.len() == r.per_run.len())
        else {
            continue;
        };
        let metrics = PAIRED_METRICS
            .iter()
            .enumerate()
            .map(|(k, (metric, f))| {
                let a: Vec<f64> = eer.iter().map(f).collect();
                let b: Vec<f64> = r.per_run.iter().map(f).collect();
                let d: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x - y).collect();
                let mut rng = statistics_rng(seed, c, PAIRED_METRICS.len() + k);
                PairedMetric {
                    metric,
                    t_test: paired_t_test(&a, &b),
                    wilcoxon: wilcoxon_signed_rank(&a, &b),
                    wilcoxon_p_holm: None,
                    mean_diff_ci95_bootstrap: bca_mean_ci95(&d, RESAMPLES, &mut rng),
                }
            })
            .collect();
        r.paired_vs_eer = Some(PairedVsEer {
            n: eer.len(),
            metrics,
        });
    }
    let family: Vec<&mut PairedMetric> = results
        .iter_mut()
        .filter_map(|r| r.paired_vs_eer.as_mut())
        .flat_map(|p| p.metrics.iter_mut())
        .filter(|m| m.wilcoxon.is_some())
        .collect();
    let p: Vec<f64> = family
        .iter()
        .filter_map(|m| m.wilcoxon.map(|w| w.p_value))
        .collect();
    for (m, adjusted) in family.into_iter().zip(holm(&p)) {
        m.wilcoxon_p_holm = Some(adjusted);
    }
}

/// Welch tests of EER against every other law with the same estimator.
fn add_welch_tests(results: &mut [ComboResult]) {
    let eer_runs = eer_runs_by_motion(results);
    for r in results.iter_mut().filter(|r| r.guidance != "eer") {
        if let Some(eer) = eer_runs.get(&r.motion) {
            let t = |f: fn(&RunSummary) -> f64| {
                let a: Vec<f64> = eer.iter().map(f).collect();
                let b: Vec<f64> = r.per_run.iter().map(f).collect();
                welch_t_test(&a, &b)
            };
            r.welch_vs_eer = Some(VersusEer {
                tracking_error_m: t(|s| s.tracking_error_m),
                estimation_error_m: t(|s| s.estimation_error_m),
                cov_det: t(|s| s.cov_det),
                fov_percent: t(|s| s.fov_percent),
            });
        }
    }
}
