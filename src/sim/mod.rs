//! Simulators and the closed-loop run that the Monte Carlo benchmark repeats.

pub mod agent;
pub mod dataset;
pub mod monte_carlo;
pub mod run;
pub mod target;
pub mod vision_sensor;

pub use monte_carlo::{MonteCarlo, MonteCarloResult};
pub use run::{check_combination, run_once, EstimatorKind, RunError, RunOutput, RunSpec};
