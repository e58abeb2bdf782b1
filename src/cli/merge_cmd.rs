//! `infotrack merge SHARD.json...`: a campaign run as independent shards (`sim --shard K/N
//! --json`, a Slurm array) joined into the table, statistics and results of one run.

use std::path::PathBuf;

use anyhow::{Context, Result};

use infotrack::report;

/// What `merge` takes.
#[derive(clap::Args)]
pub struct MergeArgs {
    /// The shards' results (`sim --shard K/N --json FILE`), every K of one N once.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// Write the campaign's results JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write `results.json`, `metrics.png` and `report.md` into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Reads the shards, joins them, prints the table and writes what was asked for.
pub fn merge(a: MergeArgs) -> Result<()> {
    let mut shards = Vec::new();
    for p in &a.shards {
        let text =
            std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
        let v: serde_json::Value =
            serde_json::from_str(&text).with_context(|| format!("{} is not JSON", p.display()))?;
        shards.push((p.display().to_string(), v));
    }
    let (result, json) = infotrack::sim::merge::merge(&shards)?;
    print!("{}", report::table::render(&result));
    if let Some(p) = &a.json {
        report::write_json(p, &json)?;
        println!("wrote {}", p.display());
    }
    if let Some(dir) = &a.out {
        report::write_json(&dir.join("results.json"), &json)?;
        super::report_cmd::write_report(dir, &json, "the merged results")?;
        println!(
            "wrote results.json, metrics.png and report.md to {}",
            dir.display()
        );
    }
    Ok(())
}
