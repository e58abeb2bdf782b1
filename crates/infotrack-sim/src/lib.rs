//! The simulator: the simulated target, agent and sensors, the synthetic camera's
//! renderer, one simulated run and the Monte Carlo runner, and the reports they write.
#![deny(missing_docs)]

pub mod render;
pub mod report;
pub mod sim;
pub mod simulated;
