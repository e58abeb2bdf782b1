//! The tracker's core: pure, synchronous and seed-deterministic, with no I/O.
//!
//! * [`world`]: road network, occlusions, geofence, camera footprint, measurement model.
//! * [`motion`]: the motion-model trait the particle filter predicts with, and constant
//!   velocity (the learned model lives in `infotrack-dmmn`).
//! * [`estimation`]: the particle filter and the constant-velocity Kalman filter.
//! * [`guidance`]: entropy, expected entropy reduction (EER) and the baseline guidance laws.
//! * [`tracker`]: one loop of filter and guidance over sources and sinks it is handed.
//! * [`metrics`]: per-step and per-run metrics and the statistics that compare methods.
//! * [`frames`], [`geodesy`], [`rng`]: named frames, WGS84 conversions, seeded streams.
//!
//! All frames are named: `_enu` is the world frame (x east, y north, metres), the
//! frame the paper's scenario is written in.
#![deny(missing_docs)]

pub mod check;
pub mod estimation;
pub mod frames;
pub mod geodesy;
pub mod guidance;
pub mod metrics;
pub mod motion;
pub mod rng;
pub mod scenario;
#[cfg(any(test, feature = "testing"))]
pub mod testing;
pub mod tracker;
pub mod world;
