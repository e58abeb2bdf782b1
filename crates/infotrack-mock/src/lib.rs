//! A SITL-free mock autopilot, PX4 and ArduPilot flavours, that speaks real MAVLink: the
//! behaviour (`autopilot.rs`, pure) and the transport shell (`server.rs`).
#![deny(missing_docs)]

pub mod autopilot;
#[cfg(unix)]
pub mod null_modem;
pub mod params;
pub mod server;
pub mod vehicle;

pub use autopilot::{MockAutopilot, MockConfig, MockEvent};
