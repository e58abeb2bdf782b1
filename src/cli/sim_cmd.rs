//! The `sim` subcommand: Monte Carlo runs of guidance laws and motion models on the simulator, or one closed-loop flight on the mock.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use infotrack::guidance::GuidanceKind;
use infotrack::report;
use infotrack::sim::{EstimatorKind, MonteCarlo};

use super::{load_config, numbers, run_cmd};

#[derive(clap::Args)]
pub struct SimArgs {
    /// Scenario file; without it, the embedded config/default.toml (the paper's lab scenario).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Runs per guidance x motion combination (default 10; with --closed-loop, 1).
    #[arg(long, value_parser = numbers::runs)]
    pub runs: Option<u64>,
    /// Seed of every random choice (default: the config's `seed`).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Seconds per run (default: the config's timing.duration_s, 90 s in the paper's scenario).
    #[arg(long, value_parser = numbers::seconds)]
    pub duration: Option<f64>,
    /// Guidance laws, comma-separated, of eer, pfwm, lawn, kf, truth (default
    /// eer,pfwm,lawn,kf; with --closed-loop only eer flies).
    #[arg(long, value_delimiter = ',')]
    pub guidance: Vec<String>,
    /// Motion models / estimators, comma-separated, of cv, dmmn, kf (default cv; with
    /// --closed-loop one of cv, dmmn, default the config's daemon.motion).
    #[arg(long, value_delimiter = ',')]
    pub motion: Vec<String>,
    /// Write the summary as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write per-step CSV logs of every run and PNG plots here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Run only shard K of N (`K/N`): the runs whose index is K modulo N, for a campaign
    /// split into independent jobs (a Slurm array); `infotrack merge` joins the shards'
    /// `--json` files into the campaign's results.
    #[arg(long)]
    pub shard: Option<infotrack::sim::monte_carlo::Shard>,
    /// A visual record for Foxglove (MCAP): the world, the drone, the target, the estimate,
    /// the setpoints and the particles over time. Monte Carlo: a folder, one
    /// `<guidance>_<motion>_run000.mcap` per combination (its first run); `--closed-loop`:
    /// the file, with the camera's frames too.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Worker threads (default: one per core).
    #[arg(long, value_parser = numbers::threads)]
    pub threads: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Measure through rendered camera frames, the AprilTag detector and the ground
    /// projection instead of the analytic measurement model (slower: one frame per filter
    /// step).
    #[arg(long)]
    pub vision: bool,
    /// Fly the full daemon instead (`infotrack run`: synthetic camera, detector, filter, EER,
    /// real MAVLink to the in-process mock autopilot) on a simulated clock, faster than real
    /// time; prints the daemon's table. One run, EER guidance.
    #[arg(long)]
    pub closed_loop: bool,
}

fn sim_closed_loop(a: SimArgs) -> Result<()> {
    let mut cfg = load_config(a.config.as_deref())?;
    if a.runs.is_some_and(|r| r != 1) {
        bail!("--closed-loop flies one run; drop --runs or set it to 1");
    }
    if a.guidance.iter().any(|g| g != "eer") {
        bail!("--closed-loop flies the daemon's EER guidance; --guidance can only be eer");
    }
    if a.vision || a.threads.is_some() || a.json.is_some() {
        bail!("--vision, --threads and --json do not apply to --closed-loop (it always measures through rendered frames; see --out for its logs)");
    }
    match a.motion.as_slice() {
        [] => {}
        [m] => {
            cfg.daemon.motion = m.clone();
            cfg.validate().with_context(|| format!("--motion `{m}`"))?;
        }
        _ => bail!("--closed-loop flies one motion model; give one --motion"),
    }
    let duration = a.duration.unwrap_or(cfg.timing.duration_s);
    if !(duration.is_finite() && duration > 0.0) {
        bail!("--duration must be a positive number of seconds, got {duration}");
    }
    infotrack::config::bounds::check_duration("--duration", duration, cfg.timing.physics_hz)?;
    if let Some(d) = &a.out {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    let opts = infotrack::daemon::RunOptions {
        duration_s: duration,
        seed: a.seed.unwrap_or(cfg.seed),
        motion: cfg.daemon.motion.clone(),
        tlog: a.out.as_ref().map(|d| d.join("link.tlog")),
        records_dir: a.out.clone(),
        visual_record: a.record.clone(),
        status_line: false,
        faults: Vec::new(),
        // The simulated clock refuses anything but the in-process mock.
        permits: Default::default(),
        simulators: infotrack::wiring::simulators(),
    };
    run_cmd::fly_into(
        &cfg,
        a.config.as_deref(),
        &opts,
        a.out.as_deref(),
        run_cmd::Clock::Simulated,
    )
}

pub fn sim(a: SimArgs) -> Result<()> {
    if a.closed_loop {
        return sim_closed_loop(a);
    }
    let cfg = load_config(a.config.as_deref())?;
    let runs = a.runs.unwrap_or(10);
    let guidance_names = if a.guidance.is_empty() {
        vec!["eer".to_string(), "pfwm".into(), "lawn".into(), "kf".into()]
    } else {
        a.guidance.clone()
    };
    let motion_names = if a.motion.is_empty() {
        vec!["cv".to_string()]
    } else {
        a.motion.clone()
    };
    if runs == 0 {
        bail!("--runs must be at least 1");
    }
    let duration = a.duration.unwrap_or(cfg.timing.duration_s);
    if !(duration.is_finite() && duration > 0.0) {
        bail!("--duration must be a positive number of seconds, got {duration}");
    }
    infotrack::config::bounds::check_duration("--duration", duration, cfg.timing.physics_hz)?;
    let guidance = guidance_names
        .iter()
        .map(|g| g.parse::<GuidanceKind>().map_err(anyhow::Error::msg))
        .collect::<Result<Vec<_>>>()
        .context("--guidance")?;
    let estimators = motion_names
        .iter()
        .map(|m| EstimatorKind::parse(m).map_err(anyhow::Error::msg))
        .collect::<Result<Vec<_>>>()
        .context("--motion")?;
    if let Some(t) = a.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t.max(1))
            .build_global()
            .context("--threads")?;
    }
    let mc = MonteCarlo {
        guidance,
        estimators,
        runs,
        seed: a.seed.unwrap_or(cfg.seed),
        duration_s: duration,
        keep_outputs: a.out.is_some() || a.record.is_some(),
        progress: !a.quiet,
        vision: a.vision,
        trace_first_run: a.record.is_some(),
        shard: a.shard,
    };
    let result = mc.run(&cfg)?;
    print!("{}", report::table::render(&result));
    print_vision(&result);
    let json = results_json(&result, &cfg, a.config.as_deref(), a.shard)?;
    if let Some(p) = &a.json {
        report::write_json(p, &json)?;
        println!("wrote {}", p.display());
    }
    if let Some(dir) = &a.out {
        write_outputs(dir, &cfg, &result, &json)?;
    }
    if let Some(dir) = &a.record {
        write_records(dir, &cfg, &result)?;
    }
    Ok(())
}

/// Each combination's first run as a visual record in `dir`.
fn write_records(
    dir: &std::path::Path,
    cfg: &infotrack::config::Config,
    result: &infotrack::sim::MonteCarloResult,
) -> Result<()> {
    let world = cfg.world();
    for ((g, m), outs) in &result.outputs {
        if let Some(first) = outs.first() {
            let path = dir.join(format!("{g}_{m}_run000.mcap"));
            report::record::write_run(&path, &world, first, cfg.agent.altitude_m)?;
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}

/// The results as JSON, each run named by what reproduces it: its index and seed (its random
/// streams are the seed's run-index streams) and, with recorded targets, its track; and the
/// whole by the program's version and commit and the config it ran.
fn results_json(
    result: &infotrack::sim::MonteCarloResult,
    cfg: &infotrack::config::Config,
    source: Option<&std::path::Path>,
    shard: Option<infotrack::sim::monte_carlo::Shard>,
) -> Result<serde_json::Value> {
    let mut v = serde_json::to_value(result).context("the results as JSON")?;
    // The world each run flew: its GeoJSON file, or the scenario whose config draws it.
    let world = cfg
        .world
        .as_ref()
        .and_then(|w| w.geojson.as_ref())
        .map_or_else(
            || format!("{} (drawn in the config)", cfg.name),
            |p| p.display().to_string(),
        );
    let tracks: Vec<String> = cfg
        .target
        .trajectory
        .as_ref()
        .map(|t| t.files().iter().map(|f| f.display().to_string()).collect())
        .unwrap_or_default();
    for combo in v["results"].as_array_mut().into_iter().flatten() {
        let indices: Vec<u64> = serde_json::from_value(combo["run_indices"].clone())
            .context("the results' run indices")?;
        for (run, &i) in combo["per_run"]
            .as_array_mut()
            .into_iter()
            .flatten()
            .zip(&indices)
        {
            let i = i as usize;
            run["run"] = i.into();
            run["seed"] = result.seed.into();
            run["world"] = world.clone().into();
            run["version"] = env!("CARGO_PKG_VERSION").into();
            if !tracks.is_empty() {
                run["track"] = tracks[i % tracks.len()].clone().into();
            }
        }
    }
    v["infotrack"] = serde_json::json!({
        "version": env!("CARGO_PKG_VERSION"),
        "commit": env!("INFOTRACK_COMMIT"),
    });
    v["config"] = super::flight_folder::source_name(source).into();
    if let Some(s) = shard {
        v["shard"] = serde_json::json!({"index": s.index, "count": s.count});
    }
    Ok(v)
}

/// Per law and model, how often the detector found the tag in the rendered frames.
fn print_vision(result: &infotrack::sim::MonteCarloResult) {
    for r in &result.results {
        if let Some(v) = r.vision {
            println!(
                "vision {}/{}: tag found in {}/{} frames ({:.1}%), {} of them in the region of interest",
                r.guidance,
                r.motion,
                v.detections,
                v.frames,
                100.0 * v.detections as f64 / v.frames.max(1) as f64,
                v.roi_hits
            );
        }
    }
}

/// The per-step CSV logs, the plots and `results.json` of a Monte Carlo run, into `dir`.
fn write_outputs(
    dir: &std::path::Path,
    cfg: &infotrack::config::Config,
    result: &infotrack::sim::MonteCarloResult,
    json: &serde_json::Value,
) -> Result<()> {
    let world = cfg.world();
    for ((g, m), outs) in &result.outputs {
        let sub = dir.join(format!("{g}_{m}"));
        for (r, out) in outs.iter().enumerate() {
            report::csv::write(&sub.join(format!("run{r:03}.csv")), &out.steps)?;
        }
        if let Some(first) = outs.first() {
            report::plots::scene(
                &sub.join("scene_run000.png"),
                &format!("{} | {g} guidance, {m} motion, run 0", cfg.name),
                &world,
                &first.steps,
                &first.snapshots,
            )?;
            report::plots::estimation_error(
                &sub.join("estimation_error_run000.png"),
                &format!("{g} guidance, {m} motion, run 0: estimation error"),
                &first.steps,
            )?;
        }
    }
    let figure =
        report::bars::MetricsFigure::from_results_json(json).map_err(anyhow::Error::msg)?;
    report::bars::draw(&dir.join("metrics.png"), &figure)?;
    report::write_json(&dir.join("results.json"), json)?;
    println!(
        "wrote per-step CSV logs, plots (metrics.png, */scene_run000.png, */estimation_error_run000.png) and results.json to {}",
        dir.display()
    );
    Ok(())
}
