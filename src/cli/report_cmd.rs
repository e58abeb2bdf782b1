//! `infotrack report RESULTS.json`: a campaign's results as a Markdown report with its
//! bar chart, beside the results or in `--out`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use infotrack::report;

/// What `report` takes.
#[derive(clap::Args)]
pub struct ReportArgs {
    /// A campaign's `results.json` (from `sim --out DIR` or `sim --json FILE`).
    pub results: PathBuf,
    /// Folder for `report.md` and `metrics.png`; without it, the results' own folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Reads the results, draws the figure and writes the report; says where.
pub fn report(a: ReportArgs) -> Result<()> {
    let text = std::fs::read_to_string(&a.results)
        .with_context(|| format!("cannot read {}", a.results.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{} is not JSON", a.results.display()))?;
    let dir = a
        .out
        .clone()
        .unwrap_or_else(|| folder_of(&a.results).to_path_buf());
    write_report(&dir, &v, &a.results.display().to_string())?;
    let path = dir.join("report.md");
    println!(
        "wrote {} and {}",
        path.display(),
        dir.join("metrics.png").display()
    );
    Ok(())
}

/// A campaign's results (`what` names them in an error) as `metrics.png` and `report.md`
/// in `dir`.
pub fn write_report(dir: &Path, v: &serde_json::Value, what: &str) -> Result<()> {
    let figure = report::bars::MetricsFigure::from_results_json(v)
        .map_err(|e| anyhow::anyhow!("{what}: {e}"))?;
    report::bars::draw(&dir.join("metrics.png"), &figure)?;
    let md = report::markdown::render(v, Some("metrics.png"))
        .map_err(|e| anyhow::anyhow!("{what}: {e}"))?;
    report::write_file(&dir.join("report.md"), md.as_bytes())?;
    Ok(())
}

/// The folder a file is in (`.` for a bare name).
fn folder_of(file: &Path) -> &Path {
    file.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}
