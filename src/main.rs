//! The `infotrack` command line.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};

use infotrack::config::Config;
use infotrack::guidance::GuidanceKind;
use infotrack::report;
use infotrack::sim::{EstimatorKind, MonteCarlo};

#[derive(Parser)]
#[command(
    name = "infotrack",
    version = concat!(env!("CARGO_PKG_VERSION"), " (commit ", env!("INFOTRACK_COMMIT"), ")"),
    about = "Find and follow a hidden moving ground target from a drone"
)]
struct Cli {
    /// Log filter (tracing syntax), e.g. `warn`, `infotrack=debug`; without it, the
    /// `RUST_LOG` environment variable, else `warn`.
    #[arg(long, global = true)]
    log: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Monte Carlo benchmark of guidance laws and motion models on the simulator.
    Sim(SimArgs),
    /// Time the core (PF step, EER cycle) on one thread and print a table.
    Bench(BenchArgs),
    /// Record noisy target positions from the simulated scenario, as a flight-log CSV, to
    /// train a motion model on (training/train_dmmn.py).
    Dataset(DatasetArgs),
    /// Run the SITL-free mock autopilot (PX4 or ArduPilot flavour) on a MAVLink transport
    /// until interrupted.
    MockAutopilot(MockArgs),
    /// Compare a parameter file with a vehicle (`check`), write it (`apply`), or save the
    /// vehicle's parameters into one (`save`).
    Params(ParamsArgs),
    /// Detect AprilTags (tag36h11) in an image, a folder of images, or a video.
    Detect(DetectArgs),
    /// The daemon: camera -> detector -> particle filter -> EER -> setpoints over MAVLink.
    /// The embedded default flies the simulated scenario through the mock autopilot.
    Run(run_cmd::RunArgs),
    /// Re-run estimation and guidance on a recorded `infotrack run` flight and compare.
    Replay(run_cmd::ReplayArgs),
    /// Print a configuration with every key filled in (defaults included), as TOML: what a
    /// config file means. `docs/config.md` lists every key.
    Config(ConfigArgs),
    /// Calibrate a camera from chessboard views (a folder or a live camera) into the OpenCV
    /// YAML that `daemon.calibration` reads.
    Calibrate(calibrate::CalibrateArgs),
    /// Print the shell completion script for SHELL (bash, zsh, fish, elvish, powershell),
    /// e.g. `infotrack completions bash > /etc/bash_completion.d/infotrack`.
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff), e.g. `infotrack man > /usr/local/share/man/man1/infotrack.1`.
    Man,
}

#[derive(clap::Args)]
struct ConfigArgs {
    /// Configuration file; without it, the embedded config/default.toml.
    #[arg(long)]
    config: Option<PathBuf>,
}

#[derive(clap::Args)]
struct DetectArgs {
    /// An image file, a folder of images (sorted by name), or a video file.
    path: PathBuf,
    /// Print exactly {"detections": [{"frame", "id", "center_px", "corners_px"}]} (OpenCV
    /// pixel convention, corners in the tag's own order).
    #[arg(long)]
    json: bool,
    /// Project each tag to the ground for the camera pose in this TOML file (calibration
    /// file, vehicle pose, optional mount); adds ground_enu_m and its covariance.
    #[arg(long)]
    pose: Option<PathBuf>,
    /// Write each frame with its detections drawn into this folder.
    #[arg(long)]
    annotate: Option<PathBuf>,
    /// Only these tag ids (comma-separated; default all).
    #[arg(long, value_delimiter = ',')]
    ids: Vec<u32>,
}

#[derive(clap::Args)]
struct MockArgs {
    /// px4 or ardupilot.
    #[arg(long)]
    flavor: String,
    /// Where to listen or connect: udpin:HOST:PORT, tcpin:HOST:PORT, serial:PATH:BAUD, or
    /// `pty` for a pseudo-terminal null modem whose other end is printed for the companion.
    #[arg(long, default_value = "udpin:127.0.0.1:14550")]
    listen: String,
    /// Start from the flavour's defaults with this parameter file applied.
    #[arg(long)]
    params: Option<PathBuf>,
    /// Drop this share of messages in both directions, percent.
    #[arg(long, default_value_t = 0.0, value_parser = numbers::percent)]
    loss: f64,
    /// One-way latency added to every message, milliseconds.
    #[arg(long, default_value_t = 0.0, value_parser = numbers::millis)]
    delay_ms: f64,
    /// Deliver this share of messages twice, percent.
    #[arg(long, default_value_t = 0.0, value_parser = numbers::percent)]
    duplicate: f64,
    /// Hold back this share of messages so that later ones overtake them, percent.
    #[arg(long, default_value_t = 0.0, value_parser = numbers::percent)]
    reorder: f64,
    /// MAVLink 2 signing key file (64 hex digits): sign everything and refuse unsigned
    /// frames.
    #[arg(long)]
    signing_key: Option<PathBuf>,
    /// Seed of the fault draws and of the vehicle's wander.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// How the vehicle answers targets: `sitl` (as the flavour's SITL build measured:
    /// PX4 SIH's slow, wandering loop; ArduCopter's steady one) or `ideal` (exactly).
    #[arg(long, default_value = "sitl", value_parser = ["sitl", "ideal"])]
    response: String,
    /// Seconds after start before arming is allowed (the estimator settling).
    #[arg(long, default_value_t = 0.0, value_parser = numbers::seconds)]
    estimator_ready_after: f64,
}

#[derive(clap::Args)]
struct ParamsArgs {
    /// check (compare the file with the vehicle), apply (write it: all or nothing), or save
    /// (download every parameter of the vehicle into the file: a backup before apply).
    action: String,
    /// A QGroundControl .params or Mission Planner .parm/.param file.
    file: PathBuf,
    /// The vehicle: udpout:HOST:PORT, udpin:HOST:PORT, tcpout:..., serial:PATH:BAUD.
    #[arg(long)]
    connect: String,
    /// Seconds to wait for the vehicle's heartbeat.
    #[arg(long, default_value_t = 10.0, value_parser = numbers::timeout_seconds)]
    timeout: f64,
    /// MAVLink 2 signing key file (64 hex digits) for a vehicle with signing on.
    #[arg(long)]
    signing_key: Option<PathBuf>,
}

#[derive(clap::Args)]
struct DatasetArgs {
    /// Scenario file; without it, the embedded config/default.toml.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Seconds of target motion to record.
    #[arg(long, default_value_t = 1800.0, value_parser = numbers::seconds)]
    duration: f64,
    /// Seed (default: the config's `seed`).
    #[arg(long)]
    seed: Option<u64>,
    /// Output CSV file; the world it was recorded in (the signature a model trained on it
    /// is checked against) goes beside it as `<name>.world.json`.
    #[arg(long)]
    out: PathBuf,
    /// Write only the world file (`<out>.world.json`), for training on your own flight
    /// logs of that world.
    #[arg(long)]
    world_only: bool,
}

#[derive(clap::Args)]
struct SimArgs {
    /// Scenario file; without it, the embedded config/default.toml (the paper's lab scenario).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Runs per guidance x motion combination (default 10; with --closed-loop, 1).
    #[arg(long, value_parser = numbers::runs)]
    runs: Option<u64>,
    /// Seed of every random choice (default: the config's `seed`).
    #[arg(long)]
    seed: Option<u64>,
    /// Seconds per run (default: the config's timing.duration_s, 90 s in the paper's scenario).
    #[arg(long, value_parser = numbers::seconds)]
    duration: Option<f64>,
    /// Guidance laws, comma-separated, of eer, pfwm, lawn, kf, truth (default
    /// eer,pfwm,lawn,kf; with --closed-loop only eer flies).
    #[arg(long, value_delimiter = ',')]
    guidance: Vec<String>,
    /// Motion models / estimators, comma-separated, of cv, dmmn, kf (default cv; with
    /// --closed-loop one of cv, dmmn, default the config's daemon.motion).
    #[arg(long, value_delimiter = ',')]
    motion: Vec<String>,
    /// Write the summary as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write per-step CSV logs of every run and PNG plots here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Worker threads (default: one per core).
    #[arg(long, value_parser = numbers::threads)]
    threads: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Measure through rendered camera frames, the AprilTag detector and the ground
    /// projection instead of the analytic measurement model (slower: one frame per filter
    /// step).
    #[arg(long)]
    vision: bool,
    /// Fly the full daemon instead (`infotrack run`: synthetic camera, detector, filter, EER,
    /// real MAVLink to the in-process mock autopilot) on a simulated clock, faster than real
    /// time; prints the daemon's table. One run, EER guidance.
    #[arg(long)]
    closed_loop: bool,
}

#[derive(clap::Args)]
struct BenchArgs {
    /// Repetitions per median.
    #[arg(long, default_value_t = 300, value_parser = numbers::repetitions)]
    repetitions: usize,
    /// Seed of the fixtures.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also write the figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// The learned model to time (its rows are skipped, with the reason, if it does not load).
    #[arg(long, default_value = infotrack::motion::dmmn::DEFAULT_MODEL_PATH)]
    model: PathBuf,
    /// Time tag detection instead (full frame vs region of interest, 640x480 and
    /// 1280x720); --repetitions is the number of frames per resolution.
    #[arg(long)]
    vision: bool,
    /// Measure vision at field scale instead: tag recall and ground error against altitude
    /// (30-90 m) for 1280x720 and 1920x1080 cameras and 1.0-1.5 m roof tags;
    /// --repetitions is the number of frames per cell.
    #[arg(long, conflicts_with = "vision")]
    vision_altitude: bool,
}

mod cli;

use cli::{calibrate, detect, numbers, run_cmd};

/// Keeps freed heap memory in the process instead of handing it back to the kernel after
/// every frame. The renderer and the AprilTag detector allocate and free ~10 MB of image
/// buffers per frame; glibc's defaults return them (munmap, or trimming a thread's arena)
/// and the next frame faults every page in again, zeroed: ~2,500 page faults per frame,
/// a fifth of the simulated-clock closed loop's CPU time (issue 16, BENCHMARKS.md). The
/// cost is that the resident size stays at its peak, which a daemon reaches in its first
/// frames anyway. Only the allocator's thresholds change; what is computed is identical.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_memory() {
    // glibc's largest accepted mmap threshold (HEAP_MAX_SIZE / 2 on 64-bit).
    const MMAP_THRESHOLD_B: libc::c_int = 32 << 20;
    const TRIM_THRESHOLD_B: libc::c_int = 256 << 20;
    // SAFETY: mallopt only sets allocator parameters; it is called before any other
    // thread exists. A refusal (return 0) leaves glibc's defaults, which are correct too.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_B);
        libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD_B);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory() {}

fn main() -> ExitCode {
    keep_freed_memory();
    let cli = Cli::parse();
    let (filter, origin) = match &cli.log {
        Some(f) => (f.clone(), "--log"),
        None => match std::env::var("RUST_LOG") {
            Ok(f) if !f.trim().is_empty() => (f, "RUST_LOG"),
            _ => ("warn".to_string(), "the default"),
        },
    };
    let filter = tracing_subscriber::EnvFilter::try_new(&filter).unwrap_or_else(|_| {
        eprintln!("warning: {origin} `{filter}` is not a valid log filter; using `warn`");
        tracing_subscriber::EnvFilter::new("warn")
    });
    // Colour codes only on a terminal: a journal or a log file gets plain text.
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(ansi)
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        Command::Sim(a) => sim(a),
        Command::Run(a) => runtime().and_then(|rt| run_cmd::run(a, rt)),
        Command::Replay(a) => run_cmd::replay(a),
        Command::Bench(a) => bench(a),
        Command::Detect(a) => detect::run(a.path, a.json, a.pose, a.annotate, a.ids),
        Command::Dataset(a) => dataset(a),
        Command::MockAutopilot(a) => mock_autopilot(a),
        Command::Params(a) => params(a),
        Command::Calibrate(a) => calibrate::run(a),
        Command::Completions { shell } => {
            let mut cmd = <Cli as clap::CommandFactory>::command();
            clap_complete::generate(shell, &mut cmd, "infotrack", &mut std::io::stdout());
            Ok(())
        }
        Command::Man => {
            let cmd = <Cli as clap::CommandFactory>::command();
            clap_mangen::Man::new(cmd)
                .render(&mut std::io::stdout())
                .context("writing the manual page")
        }
        Command::Config(a) => load_config(a.config.as_deref()).and_then(|c| {
            print!("{}", toml::to_string(&c).context("the config as TOML")?);
            Ok(())
        }),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn load_config(path: Option<&Path>) -> Result<Config> {
    Ok(match path {
        Some(p) => Config::load(p)?,
        None => Config::default_lab(),
    })
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
        status_line: false,
        faults: Vec::new(),
        // The simulated clock refuses anything but the in-process mock.
        permits: Default::default(),
    };
    run_cmd::fly(&cfg, &opts, a.out.as_deref(), run_cmd::Clock::Simulated)
}

fn sim(a: SimArgs) -> Result<()> {
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
        keep_outputs: a.out.is_some(),
        progress: !a.quiet,
        vision: a.vision,
    };
    let result = mc.run(&cfg)?;
    print!("{}", report::table::render(&result));
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
    if let Some(p) = &a.json {
        report::write_json(p, &result)?;
        println!("wrote {}", p.display());
    }
    if let Some(dir) = &a.out {
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
        report::plots::metrics_bars(&dir.join("metrics.png"), &result)?;
        report::write_json(&dir.join("results.json"), &result)?;
        println!(
            "wrote per-step CSV logs, plots (metrics.png, */scene_run000.png, */estimation_error_run000.png) and results.json to {}",
            dir.display()
        );
    }
    Ok(())
}

fn bench(a: BenchArgs) -> Result<()> {
    if a.repetitions == 0 {
        bail!("--repetitions must be at least 1");
    }
    if a.vision_altitude {
        let rows = cli::altitude_bench::run(a.repetitions, a.seed)?;
        return print_bench(&cli::altitude_bench::render_table(&rows), &rows, &a.json);
    }
    if a.vision {
        let rows = cli::detect_bench::run(a.repetitions, a.seed)?;
        return print_bench(&cli::detect_bench::render_table(&rows), &rows, &a.json);
    }
    let r = cli::bench::run(a.repetitions, a.seed, &a.model);
    print_bench(&cli::bench::render(&r), &r, &a.json)
}

/// Prints a benchmark's table and writes its figures as JSON when asked.
fn print_bench(table: &str, figures: &impl serde::Serialize, json: &Option<PathBuf>) -> Result<()> {
    print!("{table}");
    if let Some(p) = json {
        report::write_json(p, figures)?;
        println!("wrote {}", p.display());
    }
    Ok(())
}

fn dataset(a: DatasetArgs) -> Result<()> {
    let cfg = load_config(a.config.as_deref())?;
    if !(a.duration.is_finite() && a.duration > 0.0) {
        bail!(
            "--duration must be a positive number of seconds, got {}",
            a.duration
        );
    }
    infotrack::config::bounds::check_duration("--duration", a.duration, cfg.timing.physics_hz)?;
    let world = a.out.with_extension("world.json");
    report::write_json(&world, &cfg.world_signature())?;
    println!(
        "wrote the world of scenario {} to {}",
        cfg.name,
        world.display()
    );
    if a.world_only {
        return Ok(());
    }
    let steps = infotrack::sim::dataset::record(&cfg, a.seed.unwrap_or(cfg.seed), a.duration);
    report::csv::write(&a.out, &steps)?;
    println!(
        "wrote {} positions ({} s at {} Hz) of scenario {} to {}",
        steps.len(),
        a.duration,
        cfg.timing.filter_hz,
        cfg.name,
        a.out.display()
    );
    Ok(())
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

fn mock_autopilot(a: MockArgs) -> Result<()> {
    use infotrack::mock::{server, MockConfig};
    let flavor: infotrack::autopilot::modes::Flavor =
        a.flavor.parse().map_err(anyhow::Error::msg)?;
    if a.listen != "pty" {
        infotrack::autopilot::link::check_url(&a.listen)
            .map_err(|e| anyhow::anyhow!("--listen `{}`: {e}", a.listen))?;
    }
    for (name, v) in [
        ("--loss", a.loss),
        ("--duplicate", a.duplicate),
        ("--reorder", a.reorder),
    ] {
        if !(0.0..=100.0).contains(&v) {
            bail!("{name} must be a percentage 0-100, got {v}");
        }
    }
    if !(a.delay_ms.is_finite() && (0.0..=60_000.0).contains(&a.delay_ms)) {
        bail!("--delay-ms must be 0-60000, got {}", a.delay_ms);
    }
    let signing_key = a
        .signing_key
        .as_deref()
        .map(infotrack::autopilot::signing::SigningKey::load)
        .transpose()?;
    let mut cfg = MockConfig::new(flavor);
    cfg.estimator_ready_after_s = a.estimator_ready_after;
    cfg.seed = a.seed;
    if a.response == "sitl" {
        cfg.answer_as_sitl();
    }
    if let Some(path) = &a.params {
        let table = infotrack::mock::params::ParamTable::defaults(flavor);
        for p in infotrack::autopilot::params_file::read(path)? {
            if table.by_name(&p.name).is_none() {
                bail!(
                    "{}:{}: the {flavor} mock has no parameter {}",
                    path.display(),
                    p.line,
                    p.name
                );
            }
            cfg.param_overrides.push((p.name, p.value));
        }
    }
    runtime()?.block_on(async move {
        // The null modem must outlive the mock.
        let (_null_modem, listen, companion) = if a.listen == "pty" {
            let nm = infotrack::mock::null_modem::NullModem::new()?;
            let listen = format!("serial:{}:57600", nm.vehicle_path());
            let companion = format!("serial:{}:57600", nm.companion_path());
            (Some(nm), listen, companion)
        } else {
            (None, a.listen.clone(), a.listen.clone())
        };
        let opts = server::ServerOptions {
            faults: server::Faults {
                loss_percent: a.loss,
                delay: std::time::Duration::from_secs_f64(a.delay_ms / 1e3),
                duplicate_percent: a.duplicate,
                reorder_percent: a.reorder,
                seed: a.seed,
            },
            signing_key,
        };
        let _mock = server::spawn_with(&listen, cfg, opts)
            .await
            .with_context(|| format!("cannot open {listen}"))?;
        eprintln!("mock {flavor} autopilot on {listen} (Ctrl-C to stop)");
        if _null_modem.is_some() {
            // The companion's end, on stdout so that scripts can read it.
            println!("{companion}");
        }
        wait_for_signal().await;
        Ok(())
    })
}

async fn wait_for_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        let mut term = signal(SignalKind::terminate()).expect("SIGTERM handler");
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}

/// `infotrack params save FILE`: every parameter of the vehicle into FILE (a backup before
/// `apply`), in the format its extension names.
fn params_save(a: ParamsArgs) -> Result<()> {
    use infotrack::autopilot::{link, params_file, params_sync};
    let format = params_file::ParamFormat::from_path(&a.file).with_context(|| {
        format!(
            "{}: unknown parameter file type (expected .params, .parm or .param)",
            a.file.display()
        )
    })?;
    let key = a
        .signing_key
        .as_deref()
        .map(infotrack::autopilot::signing::SigningKey::load)
        .transpose()?;
    let text = runtime()?.block_on(async {
        let mut lc = link::LinkConfig::new(&a.connect);
        lc.signing_key = key;
        let l = link::VehicleLink::connect(lc).await?;
        l.wait_vehicle(std::time::Duration::from_secs_f64(a.timeout))
            .await?;
        let list = l.param_list(std::time::Duration::from_secs(2)).await;
        if !list.complete {
            bail!(
                "the vehicle sent {} parameters but not all it counts: nothing was saved (a lossy link? try again)",
                list.values.len()
            );
        }
        let address = l.state().address.unwrap_or((1, 1));
        println!("{} parameters of the {} vehicle", list.values.len(), l.flavor());
        Ok::<String, anyhow::Error>(params_sync::render_backup(&list, format, address))
    })?;
    infotrack::report::write_file(&a.file, text.as_bytes())?;
    println!("saved to {}", a.file.display());
    Ok(())
}

fn params(a: ParamsArgs) -> Result<()> {
    use infotrack::autopilot::{link, params_file, params_sync};
    let apply = match a.action.as_str() {
        "check" => false,
        "apply" => true,
        "save" => return params_save(a),
        other => bail!("unknown params action `{other}` (check, apply or save)"),
    };
    let file = params_file::read(&a.file)?;
    let key = a
        .signing_key
        .as_deref()
        .map(infotrack::autopilot::signing::SigningKey::load)
        .transpose()?;
    let file_name = a.file.display().to_string();
    let ok = runtime()?.block_on(async move {
        let mut lc = link::LinkConfig::new(&a.connect);
        lc.signing_key = key;
        let l = link::VehicleLink::connect(lc).await?;
        l.wait_vehicle(std::time::Duration::from_secs_f64(a.timeout))
            .await?;
        let rows = if apply {
            params_sync::apply(&l, &file).await
        } else {
            params_sync::check(&l, &file).await
        };
        print!("{}", params_sync::render(&rows));
        for line in params_sync::advice(&rows, l.flavor(), apply) {
            println!("{line}");
        }
        if let (false, Some(why)) = (params_sync::all_ok(&rows), l.signing_diagnosis()) {
            bail!("{file_name}: {why}");
        }
        use params_sync::ParamStatus;
        if let Some(failed) = rows.iter().find(|r| r.status == ParamStatus::Failed) {
            let count = |s: ParamStatus| rows.iter().filter(|r| r.status == s).count();
            bail!(
                "{file_name}: writing {} (line {}) failed midway: {} parameter(s) written before \
                 were set back to their earlier values{}; the rest were not written (see the table)",
                failed.name,
                failed.line,
                count(ParamStatus::RolledBack),
                match count(ParamStatus::RollbackFailed) {
                    0 => String::new(),
                    n => format!(", {n} could NOT be set back and hold the file's values"),
                }
            );
        }
        let untouched = rows.iter().any(|r| r.status == ParamStatus::NotWritten);
        if untouched {
            bail!(
                "{file_name}: nothing was written: the file is applied whole or not at all, and the vehicle lacks some of its parameters or cannot hold their values (see the table)"
            );
        }
        Ok::<bool, anyhow::Error>(params_sync::all_ok(&rows))
    })?;
    if !ok {
        bail!(
            "{}: the vehicle does not match the file (see the table)",
            a.file.display()
        );
    }
    Ok(())
}
