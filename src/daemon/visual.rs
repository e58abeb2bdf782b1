//! The flight's visual record (`run --record FILE`, `sim --closed-loop --record FILE`): an
//! MCAP file for Foxglove written as the flight goes (`infotrack-record`): at every filter
//! step the vehicle at its altitude and heading, the estimate, the measurement, the
//! setpoint, the target when it is simulated, and the particles; the camera's newest frame
//! once a second. A write that fails stops the record, not the flight: it is said once,
//! and the run ends with the error, as a failure of the other records does.

use std::path::Path;

use super::flight_log::FlightRecord;
use super::heading;
use super::sensor::DaemonSensor;
use crate::tracker::Tracker;
use crate::world::World;
use infotrack_record::{RecordError, RecordStep, Recorder};

/// How often a camera frame goes into the record, s: a frame is a few hundred kB of PNG,
/// and one a second is enough to see what the camera saw.
pub const FRAME_EVERY_S: f64 = 1.0;

/// The visual record of a flight.
pub struct VisualRecord {
    recorder: Option<Recorder>,
    next_frame_t_s: f64,
    failure: Option<String>,
}

impl VisualRecord {
    /// Creates the file and writes the world into it; message times count from now.
    pub fn create(path: &Path, world: &World) -> Result<Self, RecordError> {
        let now_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        Ok(Self {
            recorder: Some(Recorder::create(path, world, now_ns)?),
            next_frame_t_s: 0.0,
            failure: None,
        })
    }

    /// The first write error, if any (the record stopped there).
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// One filter step of the flight.
    pub(super) fn note(&mut self, rec: &FlightRecord, tracker: &Tracker, sensor: &DaemonSensor) {
        let Some(r) = self.recorder.as_mut() else {
            return;
        };
        let result = write_step(r, rec, tracker, sensor, &mut self.next_frame_t_s);
        if let Err(e) = result {
            tracing::error!("{e}; the visual record stops here, the flight goes on");
            self.failure = Some(e.to_string());
            self.recorder = None;
        }
    }

    /// Writes the record's index and closes it.
    pub fn finish(&mut self) {
        if let Some(r) = self.recorder.take() {
            if let Err(e) = r.finish() {
                tracing::error!("{e}");
                self.failure.get_or_insert(e.to_string());
            }
        }
    }
}

/// A record dropped unfinished (a start that failed, a pipeline that died) is still
/// finished: its summary and index written, so that any MCAP reader opens what it holds.
impl Drop for VisualRecord {
    fn drop(&mut self) {
        self.finish();
    }
}

fn write_step(
    r: &mut Recorder,
    rec: &FlightRecord,
    tracker: &Tracker,
    sensor: &DaemonSensor,
    next_frame_t_s: &mut f64,
) -> Result<(), RecordError> {
    let s = &rec.step;
    r.step(&RecordStep {
        t_s: s.t_s,
        drone_enu: s.agent_enu,
        drone_altitude_m: rec.pose.altitude_m(),
        view_yaw_enu_rad: heading::view_yaw_enu_of_nose(rec.pose.yaw_rad, sensor.mount_yaw_rad),
        truth_enu: Some(s.target_enu).filter(|t| t.x.is_finite() && t.y.is_finite()),
        estimate_enu: s.estimate_enu,
        measurement_enu: s.measurement_enu,
        setpoint_enu: s.waypoint_enu,
    })?;
    if let Some(pf) = tracker.estimator().particle_filter() {
        r.particles(s.t_s, &pf.particles(), pf.weights())?;
    }
    if rec.frame && s.t_s + 1e-9 >= *next_frame_t_s {
        if let Some(image) = sensor.last_image() {
            *next_frame_t_s = s.t_s + FRAME_EVERY_S;
            r.frame(s.t_s, image.width as u32, image.height as u32, &image.data)?;
        }
    }
    Ok(())
}
