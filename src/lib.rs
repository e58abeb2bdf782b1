//! infotrack: find and follow a moving ground target that is often hidden.
//!
//! The program is a workspace of crates, one per concern (ARCHITECTURE.md draws the
//! graph); this crate is the flight daemon and the command line, and re-exports the
//! others under the names the subcommands and tests use:
//!
//! * [`world`], [`motion`], [`estimation`], [`guidance`], [`tracker`], [`metrics`],
//!   [`frames`], [`geodesy`], [`rng`]: the pure core (`infotrack-core`).
//! * [`dmmn`]: the learned motion model on ONNX Runtime (`infotrack-dmmn`).
//! * [`vision`]: camera model, AprilTag detector, capture (`infotrack-vision`).
//! * [`autopilot`]: the MAVLink vehicle link (`infotrack-link`).
//! * [`mock`]: the mock autopilot (`infotrack-mock`).
//! * [`config`], [`recorded_track`]: the configuration (`infotrack-config`).
//! * [`sim`], [`simulated`], [`render`], [`report`]: the simulator (`infotrack-sim`).
//! * [`bounded_file`]: bounded reads of user files (`infotrack-files`).
#![deny(missing_docs)]

pub mod daemon;
pub mod wiring;

pub use infotrack_config as config;
pub use infotrack_config::recorded_track;
pub use infotrack_core::{
    estimation, frames, geodesy, guidance, metrics, motion, rng, tracker, world,
};
pub use infotrack_dmmn as dmmn;
pub use infotrack_files as bounded_file;
pub use infotrack_link as autopilot;
pub use infotrack_mock as mock;
pub use infotrack_sim::{render, report, sim, simulated};
pub use infotrack_vision as vision;
