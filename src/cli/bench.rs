//! Timings of the core (`infotrack bench`): the particle filter step and the EER cycle, on
//! the paper's scenario, single-threaded. The criterion benches in `benches/` time the same
//! fixtures (`benches/fixtures/mod.rs`).

use std::time::Instant;

use serde::Serialize;

use infotrack::config::Config;
use infotrack::dmmn::Dmmn;
use infotrack::metrics::median;

#[path = "../../benches/fixtures/mod.rs"]
mod fixtures;
use fixtures::{EerFixture, PfFixture};

fn time_median(reps: usize, mut f: impl FnMut()) -> f64 {
    let mut t = Vec::with_capacity(reps);
    for _ in 0..reps {
        let s = Instant::now();
        f();
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    median(&t)
}

/// PF step medians.
#[derive(Debug, Clone, Serialize)]
pub struct PfTimes {
    /// N = 500, ms.
    pub n500: f64,
    /// N = 5000, ms.
    pub n5000: f64,
}

/// EER cycle medians (motion-model calls excluded).
#[derive(Debug, Clone, Serialize)]
pub struct EerTimes {
    /// N_H = 25, ms.
    pub nh25: f64,
    /// N_H = 100, ms.
    pub nh100: f64,
    /// N_H = 500, ms.
    pub nh500: f64,
}

/// Rollout medians (the motion-model part of the cycle, constant-velocity model).
#[derive(Debug, Clone, Serialize)]
pub struct RolloutTimes {
    /// N_H = 25, ms.
    pub nh25: f64,
    /// N_H = 100, ms.
    pub nh100: f64,
    /// N_H = 500, ms.
    pub nh500: f64,
}

/// Timings with the learned model (`None` in the report when it could not be loaded).
#[derive(Debug, Clone, Serialize)]
pub struct DmmnTimes {
    /// Model file.
    pub model: String,
    /// Its parameter count.
    pub parameters: u64,
    /// One inference at batch 500, ms.
    pub infer_batch500_ms: f64,
    /// One inference at batch 25, ms.
    pub infer_batch25_ms: f64,
    /// One inference at batch 1, ms.
    pub infer_batch1_ms: f64,
    /// PF step with the DMMN at N = 500, ms.
    pub pf_step_n500_ms: f64,
    /// EER rollout with the DMMN, N_H = 500, K = 4, ms.
    pub eer_rollout_nh500_ms: f64,
}

/// This core's single-thread f32 matrix-multiply rate on the DMMN's own feed-forward shapes
/// at batch 500 (500 x 10 tokens of width 5, a hidden layer of 50): [5000 x 5] x [5 x 50]
/// then [5000 x 50] x [50 x 5], with nalgebra (the `matrixmultiply` kernels), GFLOP/s. The
/// model's FLOP count per batch comes from `training/count_flops.py`; the two together say
/// how close an inference is to what this machine can do (BENCHMARKS.md).
pub fn gemm_gflops(repetitions: usize) -> f64 {
    use nalgebra::DMatrix;
    let (tokens, width, hidden) = (5000, 5, 50);
    let x = DMatrix::<f32>::from_fn(tokens, width, |i, j| ((i * 7 + j) % 13) as f32 * 0.1);
    let w1 = DMatrix::<f32>::from_fn(width, hidden, |i, j| ((i + 3 * j) % 5) as f32 * 0.2);
    let w2 = DMatrix::<f32>::from_fn(hidden, width, |i, j| ((2 * i + j) % 7) as f32 * 0.1);
    let mut h = DMatrix::<f32>::zeros(tokens, hidden);
    let mut y = DMatrix::<f32>::zeros(tokens, width);
    let ms = time_median(repetitions.min(200), || {
        x.mul_to(&w1, &mut h);
        h.mul_to(&w2, &mut y);
        std::hint::black_box(&y);
    });
    let flop = 2.0 * (tokens * width * hidden) as f64 * 2.0;
    flop / (ms * 1e-3) / 1e9
}

/// What `infotrack bench` measures.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// PF step, ms.
    pub pf_step_ms: PfTimes,
    /// EER cycle without the motion model, ms.
    pub eer_cycle_ms: EerTimes,
    /// Candidates per EER cycle at N_H = 500.
    pub eer_candidates: usize,
    /// The K-step rollout with the constant-velocity model, ms.
    pub eer_rollout_cv_ms: RolloutTimes,
    /// Repetitions per median.
    pub repetitions: usize,
    /// The learned model's timings.
    pub dmmn: Option<DmmnTimes>,
    /// Why the learned model's timings are missing, if they are.
    pub dmmn_skipped: Option<String>,
    /// Single-thread GEMM rate on the DMMN's shapes, GFLOP/s ([`gemm_gflops`]).
    pub gemm_gflops: f64,
}

/// Times the DMMN at `model_path`.
pub fn run_dmmn(
    model_path: &std::path::Path,
    repetitions: usize,
    seed: u64,
) -> Result<DmmnTimes, infotrack::motion::MotionError> {
    let mut cfg = Config::default_lab();
    cfg.motion.dmmn_model = model_path.to_path_buf();
    let load = || Dmmn::load(model_path, &cfg.motion_params());
    let mut m = load()?;
    let parameters = m.metadata().parameters;
    let reps = repetitions.min(200);
    let mut infer = |n: usize| {
        let f = PfFixture::new(n, seed);
        let input: Vec<f32> =
            f.pf.histories()
                .as_slice()
                .iter()
                .map(|v| *v as f32)
                .collect();
        time_median(reps, || {
            m.predict_raw(&input, n).expect("inference failed");
        })
    };
    let (b500, b25, b1) = (infer(500), infer(25), infer(1));
    let mut pf = PfFixture::with_model(500, seed, Box::new(load()?));
    let pf_ms = time_median(reps, || pf.step());
    let mut eer =
        EerFixture::with_fixture(PfFixture::with_model(500, seed, Box::new(load()?)), 500);
    let rollout = time_median(reps.min(100), || eer.prepare());
    Ok(DmmnTimes {
        model: model_path.display().to_string(),
        parameters,
        infer_batch500_ms: b500,
        infer_batch25_ms: b25,
        infer_batch1_ms: b1,
        pf_step_n500_ms: pf_ms,
        eer_rollout_nh500_ms: rollout,
    })
}

/// Runs the timings on the current thread; the DMMN rows use `model` when it loads.
pub fn run(repetitions: usize, seed: u64, model: &std::path::Path) -> BenchReport {
    let pf_time = |n: usize| {
        let mut f = PfFixture::new(n, seed);
        time_median(repetitions, || f.step())
    };
    let mut candidates = 0;
    let mut eer = |n_h: usize| {
        let mut f = EerFixture::new(500, n_h, seed);
        let reps = repetitions.min(200);
        let decide = time_median(reps, || {
            candidates = f.decide();
        });
        let prepare = time_median(reps, || f.prepare());
        (decide, prepare)
    };
    let (e25, r25) = eer(25);
    let (e100, r100) = eer(100);
    let (e500, r500) = eer(500);
    BenchReport {
        pf_step_ms: PfTimes {
            n500: pf_time(500),
            n5000: pf_time(5000),
        },
        eer_cycle_ms: EerTimes {
            nh25: e25,
            nh100: e100,
            nh500: e500,
        },
        eer_candidates: candidates,
        eer_rollout_cv_ms: RolloutTimes {
            nh25: r25,
            nh100: r100,
            nh500: r500,
        },
        repetitions,
        dmmn: None,
        dmmn_skipped: None,
        gemm_gflops: gemm_gflops(repetitions),
    }
    .with_dmmn(run_dmmn(model, repetitions, seed))
}

impl BenchReport {
    fn with_dmmn(mut self, r: Result<DmmnTimes, infotrack::motion::MotionError>) -> Self {
        match r {
            Ok(t) => self.dmmn = Some(t),
            Err(e) => self.dmmn_skipped = Some(e.to_string()),
        }
        self
    }
}

/// The report as a table, with the targets of the core issue beside the figures.
pub fn render(r: &BenchReport) -> String {
    let mut s = format!(
        "infotrack bench (one thread, medians of {} repetitions)\n\
         {:<44} {:>10} {:>12}\n\
         {:<44} {:>10.4} {:>12}\n\
         {:<44} {:>10.4} {:>12}\n\
         {:<44} {:>10.4} {:>12}\n\
         {:<44} {:>10.4} {:>12}\n\
         {:<44} {:>10.4} {:>12}\n\
         {:<44} {:>10.4} {:>12}\n\
         {:<44} {:>10.4} {:>12}\n\
         {:<44} {:>10.4} {:>12}\n\
         candidates per EER cycle (N_H = 500): {}\n",
        r.repetitions,
        "what",
        "ms",
        "target",
        "PF step, N = 500, constant velocity",
        r.pf_step_ms.n500,
        "<= 0.3",
        "PF step, N = 5000, constant velocity",
        r.pf_step_ms.n5000,
        "-",
        "EER cycle, N = 500, N_H = 25, K = 4",
        r.eer_cycle_ms.nh25,
        "-",
        "EER cycle, N = 500, N_H = 100, K = 4",
        r.eer_cycle_ms.nh100,
        "-",
        "EER cycle, N = N_H = 500, K = 4",
        r.eer_cycle_ms.nh500,
        "<= 10",
        "EER rollout (cv model), N_H = 25, K = 4",
        r.eer_rollout_cv_ms.nh25,
        "-",
        "EER rollout (cv model), N_H = 100, K = 4",
        r.eer_rollout_cv_ms.nh100,
        "-",
        "EER rollout (cv model), N_H = 500, K = 4",
        r.eer_rollout_cv_ms.nh500,
        "-",
        r.eer_candidates
    );
    match (&r.dmmn, &r.dmmn_skipped) {
        (Some(d), _) => {
            s += &format!(
                "DMMN {} ({} parameters), ONNX Runtime, one intra-op thread\n",
                d.model, d.parameters
            );
            for (what, v, target) in [
                ("DMMN inference, batch 500", d.infer_batch500_ms, "<= 0.3"),
                ("DMMN inference, batch 25", d.infer_batch25_ms, "-"),
                ("DMMN inference, batch 1", d.infer_batch1_ms, "-"),
                ("PF step, N = 500, DMMN", d.pf_step_n500_ms, "<= 0.5"),
                (
                    "EER rollout (DMMN), N_H = 500, K = 4",
                    d.eer_rollout_nh500_ms,
                    "<= 2",
                ),
            ] {
                s += &format!("{what:<44} {v:>10.4} {target:>12}\n");
            }
        }
        (None, Some(why)) => s += &format!("DMMN rows skipped: {why}\n"),
        (None, None) => {}
    }
    s += &format!(
        "f32 GEMM on the DMMN's feed-forward shapes at batch 500, one thread: {:.2} GFLOP/s\n",
        r.gemm_gflops
    );
    s
}
