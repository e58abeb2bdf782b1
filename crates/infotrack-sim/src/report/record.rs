//! One simulated run as a visual record (MCAP for Foxglove, `infotrack-record`): the world,
//! and at every filter step the drone at its altitude, the target, the estimate, the
//! measurement, the setpoint and the particles.

use std::path::Path;

use crate::sim::run::RunOutput;
use infotrack_core::world::World;
use infotrack_record::{RecordError, RecordStep, Recorder};

/// Writes `out`, a run kept with its trace (`RunSpec::trace`), to `path`; the drone flew at
/// `altitude_m`. Times start at 0 (a simulation has no date).
pub fn write_run(
    path: &Path,
    world: &World,
    out: &RunOutput,
    altitude_m: f64,
) -> Result<(), RecordError> {
    let mut r = Recorder::create(path, world, 0)?;
    let mut trace = out.trace.iter().peekable();
    for s in &out.steps {
        let frame = trace.next_if(|f| (f.t_s - s.t_s).abs() < 1e-9);
        r.step(&RecordStep {
            t_s: s.t_s,
            drone_enu: s.agent_enu,
            drone_altitude_m: altitude_m,
            view_yaw_enu_rad: frame.map_or(std::f64::consts::FRAC_PI_2, |f| f.view_yaw_enu_rad),
            truth_enu: Some(s.target_enu),
            estimate_enu: s.estimate_enu,
            measurement_enu: s.measurement_enu,
            setpoint_enu: s.waypoint_enu,
        })?;
        if let Some(f) = frame.filter(|f| !f.particles_enu.is_empty()) {
            r.particles(f.t_s, &f.particles_enu, &f.weights)?;
        }
    }
    r.finish()
}
