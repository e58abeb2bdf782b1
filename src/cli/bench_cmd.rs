//! The `bench` subcommand: times the core, the detector and the DMMN.

use std::path::PathBuf;

use anyhow::{bail, Result};

use infotrack::report;

use super::{altitude_bench, bench, detect_bench, numbers};

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Repetitions per median.
    #[arg(long, default_value_t = 300, value_parser = numbers::repetitions)]
    pub repetitions: usize,
    /// Seed of the fixtures.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write the figures as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// The learned model to time (its rows are skipped, with the reason, if it does not load).
    #[arg(long, default_value = infotrack::dmmn::DEFAULT_MODEL_PATH)]
    pub model: PathBuf,
    /// Time tag detection instead (full frame vs region of interest, 640x480 and
    /// 1280x720); --repetitions is the number of frames per resolution.
    #[arg(long)]
    pub vision: bool,
    /// Measure vision at field scale instead: tag recall and ground error against altitude
    /// (30-90 m) for 1280x720 and 1920x1080 cameras and 1.0-1.5 m roof tags;
    /// --repetitions is the number of frames per cell.
    #[arg(long, conflicts_with = "vision")]
    pub vision_altitude: bool,
}

pub fn bench(a: BenchArgs) -> Result<()> {
    if a.repetitions == 0 {
        bail!("--repetitions must be at least 1");
    }
    if a.vision_altitude {
        let rows = altitude_bench::run(a.repetitions, a.seed)?;
        return print_bench(&altitude_bench::render_table(&rows), &rows, &a.json);
    }
    if a.vision {
        let rows = detect_bench::run(a.repetitions, a.seed)?;
        return print_bench(&detect_bench::render_table(&rows), &rows, &a.json);
    }
    let r = bench::run(a.repetitions, a.seed, &a.model);
    print_bench(&bench::render(&r), &r, &a.json)
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
