//! The simulator (`infotrack sim`): one simulated run around the tracker, the Monte Carlo
//! benchmark that repeats it, and the data-set recorder. The simulated sources themselves
//! live in [`crate::simulated`], where the daemon uses them too.

pub mod dataset;
pub mod merge;
pub mod monte_carlo;
pub mod run;

pub use monte_carlo::{MonteCarlo, MonteCarloResult, PairedMetric, PairedVsEer};
pub use run::{check_combination, run_once, EstimatorKind, RunError, RunOutput, RunSpec};
