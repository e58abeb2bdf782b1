//! The `dataset` subcommand: noisy target tracks from the simulated scenario, to train a motion model on.

use std::path::PathBuf;

use anyhow::{bail, Result};

use infotrack::report;

use super::{load_config, numbers};

#[derive(clap::Args)]
pub struct DatasetArgs {
    /// Scenario file; without it, the embedded config/default.toml.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Seconds of target motion to record.
    #[arg(long, default_value_t = 1800.0, value_parser = numbers::seconds)]
    pub duration: f64,
    /// Seed (default: the config's `seed`).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output CSV file; the world it was recorded in (the signature a model trained on it
    /// is checked against) goes beside it as `<name>.world.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Write only the world file (`<out>.world.json`), for training on your own flight
    /// logs of that world.
    #[arg(long)]
    pub world_only: bool,
}

pub fn dataset(a: DatasetArgs) -> Result<()> {
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
