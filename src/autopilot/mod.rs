//! Talking to a PX4 or ArduPilot vehicle over MAVLink: frames, modes, parameter files and
//! the vehicle link.

pub mod connection;
pub mod frames;
pub mod link;
pub mod modes;
pub mod params_file;
pub mod params_sync;
pub mod signing;
pub mod tlog;
