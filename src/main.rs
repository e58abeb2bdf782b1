//! The `infotrack` command line.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "infotrack",
    version = concat!(env!("CARGO_PKG_VERSION"), " (commit ", env!("INFOTRACK_COMMIT"), ")"),
    about = "Find and follow a hidden moving ground target from a drone"
)]
struct Cli {
    /// Log filter (tracing syntax), e.g. `warn`, `infotrack=debug`; without it, the
    /// `RUST_LOG` environment variable, else `warn` (`run`: its flight's story at `info` too,
    /// `warn,infotrack=info,infotrack_link=info`).
    #[arg(long, global = true)]
    log: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Monte Carlo benchmark of guidance laws and motion models on the simulator.
    Sim(SimArgs),
    /// Join a campaign's shards (`sim --shard K/N --json`) into its table and results.
    Merge(cli::merge_cmd::MergeArgs),
    /// A campaign's results.json (from `sim`) as a Markdown report with its bar chart.
    Report(cli::report_cmd::ReportArgs),
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
    /// config file means. `docs/src/config.md` lists every key.
    Config(ConfigArgs),
    /// Calibrate a camera from chessboard views (a folder or a live camera) into the OpenCV
    /// YAML that `daemon.calibration` reads.
    Calibrate(cli::calibrate_args::CalibrateArgs),
    /// Worlds from OpenStreetMap extracts (`world import`).
    World(cli::world_cmd::WorldArgs),
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

mod cli;

use cli::bench_cmd::{bench, BenchArgs};
use cli::dataset_cmd::{dataset, DatasetArgs};
use cli::mock_cmd::{mock_autopilot, MockArgs};
use cli::params_cmd::{params, ParamsArgs};
use cli::sim_cmd::{sim, SimArgs};
#[cfg(feature = "opencv")]
use cli::{calibrate, detect};
use cli::{load_config, run_cmd, runtime};

/// Keeps freed heap memory in the process instead of handing it back to the kernel after
/// every frame. The renderer and the AprilTag detector allocate and free ~10 MB of image
/// buffers per frame; glibc's defaults return them (munmap, or trimming a thread's arena)
/// and the next frame faults every page in again, zeroed: ~2,500 page faults per frame,
/// a fifth of the simulated-clock closed loop's CPU time (BENCHMARKS.md). The
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

/// The log on stderr (filtered by `--log`, else `RUST_LOG`, else `default`) and, while a
/// flight folder is open, its `daemon.log` (the same filter when one is given, else `info`:
/// a folder keeps the flight's story even when the terminal shows warnings only).
fn init_logging(log: Option<&str>, default: &str) {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    use tracing_subscriber::{EnvFilter, Layer};
    let given = match log {
        Some(f) => Some((f.to_string(), "--log")),
        None => match std::env::var("RUST_LOG") {
            Ok(f) if !f.trim().is_empty() => Some((f, "RUST_LOG")),
            _ => None,
        },
    };
    let parse = |default: &str| match &given {
        Some((f, origin)) => EnvFilter::try_new(f).unwrap_or_else(|_| {
            eprintln!("warning: {origin} `{f}` is not a valid log filter; using `{default}`");
            EnvFilter::new(default)
        }),
        None => EnvFilter::new(default),
    };
    // Colour codes only on a terminal: a journal or a log file gets plain text.
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let terminal = tracing_subscriber::fmt::layer()
        .with_ansi(ansi)
        .with_writer(std::io::stderr)
        .with_filter(parse(default));
    let folder = tracing_subscriber::fmt::layer()
        .with_ansi(false)
        .with_writer(cli::folder_log::FolderLog)
        .with_filter(
            EnvFilter::try_new(given.as_ref().map_or("info", |g| &g.0))
                .unwrap_or_else(|_| EnvFilter::new("info")),
        );
    tracing_subscriber::registry()
        .with(terminal)
        .with(folder)
        .init();
}

fn main() -> ExitCode {
    keep_freed_memory();
    let cli = Cli::parse();
    // A flight tells its story on the terminal as the GCS is told it; elsewhere, warnings.
    let default = match &cli.command {
        Command::Run(_) => "warn,infotrack=info,infotrack_link=info",
        _ => "warn",
    };
    init_logging(cli.log.as_deref(), default);
    let result = match cli.command {
        Command::Sim(a) => sim(a),
        Command::Run(a) => runtime().and_then(|rt| run_cmd::run(a, rt)),
        Command::Replay(a) => run_cmd::replay(a),
        Command::Report(a) => cli::report_cmd::report(a),
        Command::Merge(a) => cli::merge_cmd::merge(a),
        Command::Bench(a) => bench(a),
        #[cfg(feature = "opencv")]
        Command::Detect(a) => detect::run(a.path, a.json, a.pose, a.annotate, a.ids),
        #[cfg(not(feature = "opencv"))]
        Command::Detect(_) => Err(built_without_opencv("detect")),
        Command::Dataset(a) => dataset(a),
        Command::MockAutopilot(a) => mock_autopilot(a),
        Command::Params(a) => params(a),
        #[cfg(feature = "opencv")]
        Command::Calibrate(a) => calibrate::run(a),
        #[cfg(not(feature = "opencv"))]
        Command::Calibrate(_) => Err(built_without_opencv("calibrate")),
        Command::World(a) => cli::world_cmd::world(a),
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

/// What a subcommand that reads images or cameras says in a build without OpenCV.
#[cfg(not(feature = "opencv"))]
fn built_without_opencv(command: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "`infotrack {command}` reads images and cameras through OpenCV, and this infotrack was \
         built without it (its `opencv` feature); use a build with OpenCV"
    )
}
