//! Talking to a PX4 or ArduPilot vehicle over MAVLink: modes, parameter files and
//! the vehicle link.
#![deny(missing_docs)]

pub mod connection;
pub mod link;
pub mod modes;
pub mod params_file;
pub mod params_sync;
pub mod signing;
pub mod tlog;
