//! The daemon's camera as the tracker sees it: the synthetic camera over the simulated
//! world (which the program provides), or a real one; either may be frozen by fault
//! injection.

use std::sync::Arc;
use std::time::Instant;

use super::field_camera::FieldCamera;
use super::heading;
use super::pipeline::Shared;
use super::simulators::SyntheticWorld;
use crate::tracker::{Observation, Prior, Sensor};
use crate::vision::camera_model::VehiclePoseNed;
use crate::vision::VisionStats;
use crate::world::camera::View;

/// Where the daemon's frames come from.
pub(super) enum Frames {
    /// Rendered from the simulated world.
    Synthetic(Box<dyn SyntheticWorld>),
    /// A real camera, and how its frames went.
    Field(Box<FieldCamera>, VisionStats),
}

/// The camera the tracker measures through, with what the pipeline tells it each tick.
pub(super) struct DaemonSensor {
    pub(super) shared: Arc<Shared>,
    pub(super) frames: Frames,
    /// The camera's yaw on its mount (`daemon.camera_mount_rpy_rad`), rad: the view faces
    /// the nose's heading turned by it.
    pub(super) mount_yaw_rad: f64,
    /// The vehicle's pose from telemetry at this tick.
    pub(super) telemetry_pose: Option<VehiclePoseNed>,
    /// The camera is frozen (fault injection) at this tick.
    pub(super) camera_frozen: bool,
    /// The pose of the last observation (the frame's, with a real camera).
    pub(super) observed_pose: Option<VehiclePoseNed>,
    /// Detection and projection time of the last frame, ms (rendering excluded).
    pub(super) detect_ms: f64,
    pub(super) frames_missed: u64,
}

impl DaemonSensor {
    /// How the frames went.
    pub(super) fn stats(&self) -> VisionStats {
        match &self.frames {
            Frames::Synthetic(w) => w.stats(),
            Frames::Field(_, stats) => *stats,
        }
    }

    /// The newest frame, synthetic (rendered whole now) or real.
    pub(super) fn last_image(
        &self,
    ) -> Option<std::borrow::Cow<'_, crate::vision::image::GrayImage>> {
        match &self.frames {
            Frames::Synthetic(w) => w.last_frame().map(std::borrow::Cow::Owned),
            Frames::Field(camera, _) => camera.last_image().map(std::borrow::Cow::Borrowed),
        }
    }

    /// The synthetic camera's world, when the frames are rendered.
    pub(super) fn synthetic(&mut self) -> Option<&mut (dyn SyntheticWorld + 'static)> {
        match &mut self.frames {
            Frames::Synthetic(w) => Some(w.as_mut()),
            Frames::Field(..) => None,
        }
    }

    /// A real camera's newest frame: its view and measurement (`None`: no frame).
    fn look_field(&mut self, prior: &Prior) -> Option<Observation> {
        let Frames::Field(camera, stats) = &mut self.frames else {
            return None;
        };
        let (pose, z) = camera.look(&self.shared, prior, stats)?;
        self.observed_pose = Some(pose);
        Some(Observation::Frame {
            taken_from: View::new(
                pose.position_enu(),
                heading::view_yaw_enu_of_nose(pose.yaw_rad, self.mount_yaw_rad),
            ),
            z,
        })
    }
}

impl Sensor for DaemonSensor {
    type Error = std::convert::Infallible;

    fn observe(
        &mut self,
        _t_s: f64,
        view: &View,
        prior: &Prior,
    ) -> Result<Observation, Self::Error> {
        let started = Instant::now();
        // The synthetic camera's frame seed is drawn at every filter step, frozen or not,
        // so that a flight's random streams do not depend on the faults.
        let frame_seed = self.synthetic().map(|w| w.next_frame_seed());
        self.observed_pose = self.telemetry_pose;
        let observation = match (self.camera_frozen, frame_seed) {
            (true, _) => None,
            (false, None) => self.look_field(prior),
            (false, Some(seed)) => {
                let world = self.synthetic().expect("synthetic frames");
                let z = match world.measure_with_seed(view, prior, seed) {
                    Ok(z) => z,
                    Err(e) => {
                        tracing::warn!("camera frame dropped: {e}");
                        None
                    }
                };
                Some(Observation::Frame {
                    taken_from: *view,
                    z,
                })
            }
        };
        let observation = observation.unwrap_or_else(|| {
            self.frames_missed += 1;
            Observation::NoFrame
        });
        // From the frame's capture (the end of its rendering) to its measurement.
        let render_ms = match &self.frames {
            Frames::Synthetic(w) => w.last_render_ms(),
            Frames::Field(..) => 0.0,
        };
        self.detect_ms = started.elapsed().as_secs_f64() * 1e3 - render_ms;
        Ok(observation)
    }
}
