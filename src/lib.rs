//! infotrack: find and follow a moving ground target that is often hidden.
//!
//! The crate is split into a pure, synchronous, seed-deterministic core and the
//! programs built on it:
//!
//! * [`world`]: road network, occlusions, geofence, camera footprint, measurement model.
//! * [`estimation`]: the particle filter and the constant-velocity Kalman filter.
//! * [`motion`]: the motion models the particle filter predicts with.
//! * [`guidance`]: entropy, expected entropy reduction (EER) and the baseline guidance laws.
//! * [`sim`]: the target and agent simulators and one closed-loop simulated run.
//! * [`metrics`]: per-step and per-run metrics and the statistics that compare methods.
//! * [`report`]: tables, CSV logs, JSON and plots.
//! * [`config`]: the TOML configuration, validated at load time.
//! * [`autopilot`]: MAVLink frames, modes, parameter files and the vehicle link.
//! * [`mock`]: a SITL-free mock autopilot (PX4 and ArduPilot flavours).
//!
//! All frames are named: `_enu` is the world frame (x east, y north, metres), the
//! frame the paper's scenario is written in.
#![deny(missing_docs)]

pub mod autopilot;
pub mod bounded_file;
pub mod config;
pub mod daemon;
pub mod estimation;
pub mod frames;
pub mod geodesy;
pub mod guidance;
pub mod metrics;
pub mod mock;
pub mod motion;
pub mod recorded_track;
pub mod report;
pub mod rng;
pub mod sim;
pub mod simulated;
pub mod tracker;
pub mod vision;
pub mod world;
