//! Per-step CSV logs of a run (the row format is the core's, `metrics::csv`).

use std::path::Path;

use super::{write_file, ReportError};
pub use infotrack_core::metrics::csv::{render, render_row, HEADER};
use infotrack_core::metrics::StepRecord;

/// Writes step records to `path`.
pub fn write(path: &Path, steps: &[StepRecord]) -> Result<(), ReportError> {
    write_file(path, render(steps).as_bytes())
}
