//! `infotrack run`: the daemon, and what it leaves behind (table, logs, plots).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use infotrack::autopilot::modes::Mode;
use infotrack::config::Config;
use infotrack::daemon::{self, flight_log, DaemonReport, RunOptions};
use infotrack::report;

use super::flight_figures::{percentile, Resources};
use super::flight_folder::FlightFolder;

/// Arguments of `infotrack run`.
#[derive(clap::Args)]
pub struct RunArgs {
    /// Configuration file; without it, the embedded config/default.toml (simulated target,
    /// synthetic camera, in-process mock PX4).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Seconds infotrack has the vehicle for, from its own take-off's end or from the
    /// pilot's hand-over (default: the config's timing.duration_s); the metrics count from
    /// there too; 0: until SIGINT/SIGTERM.
    #[arg(long, value_parser = super::numbers::seconds)]
    duration: Option<f64>,
    /// Folder for the logs (per-step CSV, MAVLink .tlog, plots, summary JSON), written as
    /// the flight goes; an existing one is overwritten (scripts, tests).
    #[arg(long, conflicts_with = "log_dir")]
    out: Option<PathBuf>,
    /// Keep every flight: its logs go into a new folder `<UTC date-time>-<seed>` under this
    /// one, never overwritten (the field; the systemd unit).
    #[arg(long)]
    log_dir: Option<PathBuf>,
    /// Seed (default: the config's `seed`).
    #[arg(long)]
    seed: Option<u64>,
    /// Write a visual record for Foxglove (MCAP) here as the flight goes: the world, the
    /// vehicle, the estimate, the measurements, the setpoints, the particles and the
    /// camera's frames (one a second).
    #[arg(long)]
    record: Option<PathBuf>,
    /// Motion model of the particle filter (default: the config's daemon.motion, `dmmn`).
    #[arg(long)]
    motion: Option<String>,
    /// The vehicle, overriding daemon.vehicle: mock:px4, mock:ardupilot or a MAVLink URL.
    #[arg(long)]
    vehicle: Option<String>,
    /// No status line.
    #[arg(long)]
    quiet: bool,
    /// Inject a fault: KIND@START+DURATION in seconds after tracking starts, KIND one of
    /// camera-freeze, link-cut, loss=PERCENT (these two need the in-process mock),
    /// pipeline-panic (the tracker thread dies; the vehicle must end in hold). Repeatable.
    #[arg(long)]
    inject: Vec<daemon::ScheduledFault>,
    /// Fly a simulation (the synthetic camera's simulated target, a lab-scale world) on a
    /// vehicle that is not the in-process mock: a SITL autopilot. Refused without it.
    #[arg(long)]
    allow_simulation_on_vehicle: bool,
    /// Let infotrack arm and take off (daemon.engage = "auto") a vehicle that is not the
    /// in-process mock. Refused without it.
    #[arg(long)]
    allow_auto_engage: bool,
}

/// The results table of one daemon run.
pub fn table(r: &DaemonReport, motion: &str) -> String {
    let o = &r.output;
    let mut t = String::new();
    // A simulated target (the synthetic camera) makes it a closed loop with truth; a real
    // camera's flight has none, and its heading says so.
    let truth = o
        .records
        .iter()
        .any(|r| r.step.tracking_error_m().is_finite());
    let kind = if !truth && !o.records.is_empty() {
        "flight (real camera, no ground truth)"
    } else {
        "closed loop"
    };
    let _ = writeln!(
        t,
        "{kind} | {} vehicle at {} | motion {motion} | {} filter steps | stopped by {:?}",
        r.flavor,
        r.vehicle,
        o.records.len(),
        r.stopped_by
    );
    if truth {
        truth_rows(&mut t, r);
    } else {
        no_truth_rows(&mut t, r);
    }
    let pp = |v: &[f64]| format!("{:.1}/{:.1}", percentile(v, 0.5), percentile(v, 0.99));
    let _ = writeln!(
        t,
        "frame->setpoint parts p50/p99 (ms): detection {}, filter {}, guidance {}; {} setpoints streamed at {}",
        pp(&o.detect_ms),
        pp(&o.update_ms),
        pp(&o.guidance_ms),
        r.setpoints_sent,
        r.setpoint_rate_hz
            .map_or_else(|| "-".to_string(), |hz| format!("{hz:.1} Hz"))
    );
    if o.lowest_effort_level > 0 {
        let _ = writeln!(
            t,
            "guidance: too slow for its budget at times; EER planned with as few as 1/{} of its hypotheses",
            1u32 << o.lowest_effort_level
        );
    }
    let final_mode = r
        .final_mode
        .map_or_else(|| "an unknown mode".to_string(), |m| m.to_string());
    let list = |v: &[(Mode, Mode)]| {
        v.iter()
            .map(|(a, b)| format!("{a} -> {b}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut failsafes = if r.unexpected_mode_changes.is_empty() {
        "no mode change that infotrack did not command".to_string()
    } else {
        format!(
            "mode changes infotrack did not command (a failsafe, the pilot or a GCS): {}",
            list(&r.unexpected_mode_changes)
        )
    };
    if !r.mode_changes_before_arming.is_empty() {
        let _ = write!(
            failsafes,
            " (before arming the vehicle changed mode by itself: {}; ArduCopter resets a mode set during its start-up)",
            list(&r.mode_changes_before_arming)
        );
    }
    let _ = writeln!(
        t,
        "vehicle: ended in {final_mode}; {failsafes}; link lost {} time(s); {} setpoint(s) refused by the geofence; {} filter period(s) without a camera frame",
        r.link_losses, r.geofence_refusals, o.frames_missed
    );
    t
}

/// The metrics row of a flight with ground truth (a simulated target).
fn truth_rows(t: &mut String, r: &DaemonReport) {
    let (s, o) = (&r.summary, &r.output);
    let _ = writeln!(
        t,
        "| tracking error (m) | estimation error (m) | det(cov) (m^4) | %FOV | frames with tag | guidance overruns | frame->setpoint p50/p99 (ms) |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|---|");
    let _ = writeln!(
        t,
        "| {:.3} | {:.3} | {:.2e} | {:.1} | {}/{} | {} | {:.1} / {:.1} |",
        s.tracking_error_m,
        s.estimation_error_m,
        s.cov_det,
        s.fov_percent,
        o.vision.detections,
        o.vision.frames,
        o.guidance_overruns,
        percentile(&o.latency_ms, 0.5),
        percentile(&o.latency_ms, 0.99)
    );
}

/// The metrics row of a flight without ground truth (a real camera): what can be known
/// without it, the estimate's spread instead of its error.
fn no_truth_rows(t: &mut String, r: &DaemonReport) {
    let o = &r.output;
    let spread = super::flight_figures::estimate_spread_m(&o.records);
    let _ = writeln!(
        t,
        "| estimate spread p50/p99 (m, 1 sd along its widest axis) | det(cov) (m^4) | frames with tag | guidance overruns | frame->setpoint p50/p99 (ms) |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|");
    let _ = writeln!(
        t,
        "| {:.2} / {:.2} | {:.2e} | {}/{} | {} | {:.1} / {:.1} |",
        percentile(&spread, 0.5),
        percentile(&spread, 0.99),
        r.summary.cov_det,
        o.vision.detections,
        o.vision.frames,
        o.guidance_overruns,
        percentile(&o.latency_ms, 0.5),
        percentile(&o.latency_ms, 0.99)
    );
    let _ = writeln!(
        t,
        "(no ground truth: no tracking or estimation error, no %FOV)"
    );
}

/// Runs the daemon from the command line.
pub fn run(a: RunArgs, rt: tokio::runtime::Runtime) -> Result<()> {
    let mut cfg = match &a.config {
        Some(p) => Config::load(p)?,
        None => Config::default_lab(),
    };
    if let Some(v) = &a.vehicle {
        cfg.daemon.vehicle = v.clone();
        cfg.validate().with_context(|| format!("--vehicle `{v}`"))?;
    }
    let duration = a.duration.unwrap_or(cfg.timing.duration_s);
    if !(duration.is_finite() && duration >= 0.0) {
        bail!("--duration must be a number of seconds >= 0 (0: until stopped), got {duration}");
    }
    infotrack::config::bounds::check_duration("--duration", duration, cfg.timing.physics_hz)?;
    let duration = if duration == 0.0 {
        f64::INFINITY
    } else {
        duration
    };
    if let Some(m) = &a.motion {
        cfg.daemon.motion = m.clone();
        cfg.validate().with_context(|| format!("--motion `{m}`"))?;
    }
    let motion = cfg.daemon.motion.clone();
    let seed = a.seed.unwrap_or(cfg.seed);
    let out = match (&a.out, &a.log_dir) {
        (Some(dir), _) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            Some(dir.clone())
        }
        (None, Some(root)) => {
            let dir = infotrack::daemon::recorder::flight_folder(root, seed)?;
            println!("this flight's logs: {}", dir.display());
            Some(dir)
        }
        (None, None) => None,
    };
    let opts = RunOptions {
        duration_s: duration,
        seed,
        motion: motion.clone(),
        tlog: out.as_ref().map(|d| d.join("link.tlog")),
        records_dir: out.clone(),
        visual_record: a.record.clone(),
        status_line: !a.quiet,
        faults: a.inject.clone(),
        permits: daemon::VehiclePermits {
            simulation: a.allow_simulation_on_vehicle,
            auto_engage: a.allow_auto_engage,
        },
        simulators: infotrack::wiring::simulators(),
    };
    fly_into(
        &cfg,
        a.config.as_deref(),
        &opts,
        out.as_deref(),
        Clock::Wall(rt),
    )
}

/// [`fly`], with the flight folder `out` (if any) made to explain itself
/// ([`FlightFolder`]): marked failed, with the reason, when the flight fails. `source`: the
/// config file (`None`: the embedded default).
pub fn fly_into(
    cfg: &Config,
    source: Option<&std::path::Path>,
    opts: &RunOptions,
    out: Option<&std::path::Path>,
    clock: Clock,
) -> Result<()> {
    let Some(dir) = out else {
        return fly(cfg, opts, None, clock).map(|_| ());
    };
    let folder = FlightFolder::begin(dir, cfg, source, opts.seed)?;
    match fly(cfg, opts, Some(dir), clock) {
        Ok(report) => folder.flown(&report),
        Err(e) => {
            if let Err(also) = folder.failed(&format!("{e:#}")) {
                eprintln!("error: {also:#}");
            }
            Err(e)
        }
    }
}

/// Which clock a flight runs on.
pub enum Clock {
    /// Real time on this runtime: the field, and the README's main command.
    Wall(tokio::runtime::Runtime),
    /// Simulated time (`infotrack sim --closed-loop`): as fast as the CPU allows.
    Simulated,
}

/// Flies the daemon and prints the table; writes the logs and plots into `out`; the
/// daemon's report (an error when the flight failed or its records could not be written).
pub fn fly(
    cfg: &Config,
    opts: &RunOptions,
    out: Option<&std::path::Path>,
    clock: Clock,
) -> Result<DaemonReport> {
    let motion = opts.motion.clone();
    let cpu_before = cpu_seconds();
    let wall = std::time::Instant::now();
    let report = match clock {
        Clock::Wall(rt) => rt.block_on(daemon::run(cfg, opts))?,
        Clock::Simulated => daemon::run_simulated(cfg, opts)?,
    };
    let resources = Resources {
        cpu_s: cpu_seconds() - cpu_before,
        wall_s: wall.elapsed().as_secs_f64(),
        flown_s: report.output.records.last().map_or(0.0, |r| r.step.t_s),
        peak_rss_mb: peak_rss_mb(),
    };
    print!("{}", table(&report, &motion));
    println!("{}", resources.line());
    if let Some(dir) = out {
        write_flight_folder(dir, cfg, &report, &resources)?;
    }
    if let Some(record) = &opts.visual_record {
        println!("wrote the visual record {}", record.display());
    }
    if report.stopped_by == daemon::StopReason::OriginChanged {
        bail!(
            "the vehicle's GPS_GLOBAL_ORIGIN changed in flight, which would have moved the world \
             and its geofence: tracking stopped and the vehicle was put in hold"
        );
    }
    Ok(report)
}

/// The flight's plots and summary into `dir` (its records were written as it flew); an
/// error names what could not be written.
fn write_flight_folder(
    dir: &std::path::Path,
    cfg: &Config,
    report: &DaemonReport,
    resources: &Resources,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let steps: Vec<_> = report
        .output
        .records
        .iter()
        .map(|r| r.step.clone())
        .collect();
    // steps.csv and flight.csv were written as the flight went (daemon::recorder).
    if let Some(why) = &report.output.records_failure {
        eprintln!(
            "warning: the flight's records in {} stopped early: {why}",
            dir.display()
        );
    }
    // The flight is over and the vehicle holds: a write failing here (a full disk) is
    // said, and the files that made it stay.
    let world = cfg.world();
    let written = [
        report::plots::scene(
            &dir.join("scene.png"),
            &format!("{} | closed loop, {} guidance", cfg.name, "eer"),
            &world,
            &steps,
            &[],
        ),
        report::plots::estimation_error(
            &dir.join("estimation_error.png"),
            "closed loop: estimation error",
            &steps,
        ),
        final_summary(dir, report, resources),
    ];
    let failed: Vec<_> = written.into_iter().filter_map(Result::err).collect();
    for e in &failed {
        eprintln!("error: after the flight: {e:#}");
    }
    if let Some(why) = &report.output.records_failure {
        bail!(
            "the flight's records in {} stopped early ({why}); the vehicle was held as usual, \
             and summary.json says the records are partial",
            dir.display()
        );
    }
    if !failed.is_empty() {
        bail!(
            "{} of the flight's files could not be written in {} (see above)",
            failed.len(),
            dir.display()
        );
    }
    println!(
        "wrote steps.csv, flight.csv, link.tlog, scene.png, estimation_error.png, summary.json, config.toml, flight.json and daemon.log to {}",
        dir.display()
    );
    Ok(())
}

/// `summary.json` at the end: whole unless the records stopped early.
fn final_summary(
    dir: &std::path::Path,
    r: &DaemonReport,
    resources: &Resources,
) -> Result<(), report::ReportError> {
    let partial = r
        .output
        .records_failure
        .as_deref()
        .map(|why| format!("the records stopped early: {why}"));
    let path = dir.join("summary.json");
    let json_error = |source| report::ReportError::Json {
        path: path.clone(),
        source,
    };
    let bytes =
        daemon::recorder::summary_json(&r.summary, partial.as_deref()).map_err(json_error)?;
    let mut v: serde_json::Value = serde_json::from_slice(&bytes).map_err(json_error)?;
    v["flight"] = super::flight_figures::figures(r, resources);
    let bytes = serde_json::to_vec_pretty(&v).map_err(json_error)?;
    report::write_file(&path, &bytes)
}

/// This process's resource use so far, from the kernel (no /proc needed, so it also
/// works in a chroot or a bare container).
fn own_usage() -> Option<libc::rusage> {
    // SAFETY: getrusage fills the struct we own.
    unsafe {
        let mut u: libc::rusage = std::mem::zeroed();
        (libc::getrusage(libc::RUSAGE_SELF, &mut u) == 0).then_some(u)
    }
}

fn cpu_seconds() -> f64 {
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    own_usage().map_or(f64::NAN, |u| tv(u.ru_utime) + tv(u.ru_stime))
}

/// Peak resident memory, MB: Linux gives `ru_maxrss` in KiB.
fn peak_rss_mb() -> f64 {
    own_usage().map_or(f64::NAN, |u| u.ru_maxrss as f64 / 1024.0)
}

/// Arguments of `infotrack replay`.
#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The `--out` folder of an `infotrack run` (its flight.csv is read).
    dir: PathBuf,
    /// The configuration to replay with (default: the folder's config.toml, the flight's
    /// own; for a folder without one, the embedded config/default.toml).
    #[arg(long)]
    config: Option<PathBuf>,
}

/// The config a replay uses, and the line that says which.
fn replay_config(a: &ReplayArgs) -> Result<(Config, String)> {
    if let Some(p) = &a.config {
        return Ok((
            Config::load(p)?,
            format!("config: {} (--config)", p.display()),
        ));
    }
    let own = a.dir.join("config.toml");
    if own.exists() {
        let said = format!("config: {} (the flight's own)", own.display());
        return Ok((Config::load(&own)?, said));
    }
    Ok((
        Config::default_lab(),
        format!(
            "config: the embedded default (config/default.toml): {} has no config.toml; give the flight's with --config",
            a.dir.display()
        ),
    ))
}

/// A folder whose `flight.json` says the flight failed before it flew has nothing to
/// replay: say why it failed instead of what its empty records lack.
fn refuse_a_failed_start(dir: &std::path::Path) -> Result<()> {
    let Ok(text) = std::fs::read_to_string(dir.join("flight.json")) else {
        return Ok(());
    };
    let manifest: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not JSON", dir.join("flight.json").display()))?;
    if manifest["outcome"] == "failed" {
        bail!(
            "{} is a flight that failed before it flew ({}): nothing to replay",
            dir.display(),
            manifest["failure"].as_str().unwrap_or("no reason recorded")
        );
    }
    Ok(())
}

/// Re-runs estimation and guidance on a recorded flight and compares.
pub fn replay(a: ReplayArgs) -> Result<()> {
    refuse_a_failed_start(&a.dir)?;
    let (cfg, which) = replay_config(&a)?;
    println!("{which}");
    let path = a.dir.join("flight.csv");
    /// A flight log is ~100 bytes a filter step: an hour at 10 Hz is ~4 MB.
    const MAX_FLIGHT_LOG_BYTES: u64 = 1 << 30;
    let text = infotrack::bounded_file::read_text(&path, MAX_FLIGHT_LOG_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let (seed, motion, steps) = flight_log::parse(&text, &path.display().to_string())?;
    let r = daemon::replay::replay(&cfg, &motion, seed, &steps)?;
    println!(
        "replayed {} filter steps of {} (seed {seed}, motion {motion})",
        r.steps,
        path.display()
    );
    println!(
        "estimates: largest difference from the flight {:.3e} m ({})",
        r.max_estimate_diff_m,
        if r.max_estimate_diff_m == 0.0 {
            "identical"
        } else {
            "NOT identical: different config, model or build?"
        }
    );
    println!(
        "guidance re-decided after each step: mean distance to the waypoint flown {:.3} m over {} steps",
        r.mean_waypoint_diff_m, r.waypoints_compared
    );
    if r.max_estimate_diff_m != 0.0 {
        bail!("the replayed estimates differ from the flight's");
    }
    Ok(())
}
