//! The command line's own code, one file per subcommand that needs more than a few lines:
//! binary-only, never imported by the library.

pub mod altitude_bench;
pub mod bench;
pub mod bench_cmd;
#[cfg(feature = "opencv")]
pub mod calibrate;
pub mod calibrate_args;
pub mod dataset_cmd;
#[cfg(feature = "opencv")]
pub mod detect;
pub mod detect_bench;
pub mod flight_figures;
pub mod flight_folder;
pub mod folder_log;
pub mod merge_cmd;
pub mod mock_cmd;
pub mod numbers;
pub mod params_cmd;
pub mod report_cmd;
pub mod run_cmd;
pub mod sim_cmd;
pub mod world_cmd;
pub mod world_learn;

use std::path::Path;

use anyhow::{Context, Result};

use infotrack::config::Config;

/// The configuration at `path`, or the embedded default (the lab).
pub fn load_config(path: Option<&Path>) -> Result<Config> {
    Ok(match path {
        Some(p) => Config::load(p)?,
        None => Config::default_lab(),
    })
}

/// The tokio runtime the link and the mock run on.
pub fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}
