//! What infotrack refuses to do to a vehicle that is not the in-process mock unless the
//! operator says so: fly a simulation on it, or arm it and take off by itself.
//!
//! Why: `infotrack run --vehicle URL` without `--config` flies the embedded lab config: a
//! synthetic camera rendering a simulated car. On a real vehicle that is a take-off chasing a
//! car that does not exist. A SITL autopilot is the one legitimate use, and its tests say so.

use super::{DaemonError, VehiclePermits};
use crate::config::{Config, Engage};

/// A world whose geofence is no longer than this on either side is the lab's scale, m.
pub const LAB_SCALE_M: f64 = 20.0;

/// Whether `daemon.vehicle` is the in-process mock.
pub fn is_in_process_mock(vehicle: &str) -> bool {
    vehicle.starts_with("mock:")
}

/// What in `cfg` is simulated (empty: nothing), in the words the refusal uses.
pub fn simulated_parts(cfg: &Config) -> Vec<String> {
    let mut parts = Vec::new();
    if cfg.daemon.camera == "synthetic" {
        parts.push(
            "daemon.camera = \"synthetic\" (frames rendered from a simulated target)".to_string(),
        );
    }
    let w = &cfg.workspace_enu;
    let (east_m, north_m) = (w.x_max_m - w.x_min_m, w.y_max_m - w.y_min_m);
    if east_m.max(north_m) <= LAB_SCALE_M {
        parts.push(format!(
            "a lab-scale world (workspace_enu {east_m:.1} m x {north_m:.1} m, at most {LAB_SCALE_M} m a side)"
        ));
    }
    parts
}

/// Refuses, before anything is sent, a simulation or a self-started flight on a vehicle
/// that is not the in-process mock, unless `permits` allows it.
pub fn check(cfg: &Config, permits: VehiclePermits) -> Result<(), DaemonError> {
    let vehicle = &cfg.daemon.vehicle;
    if is_in_process_mock(vehicle) {
        return Ok(());
    }
    let simulated = simulated_parts(cfg);
    if !simulated.is_empty() && !permits.simulation {
        return Err(DaemonError::SimulationOnVehicle {
            vehicle: vehicle.clone(),
            what: simulated.join(" and "),
        });
    }
    if cfg.daemon.engage == Engage::Auto && !permits.auto_engage {
        return Err(DaemonError::AutoEngageOnVehicle(vehicle.clone()));
    }
    Ok(())
}
