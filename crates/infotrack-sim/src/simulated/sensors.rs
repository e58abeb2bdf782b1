//! The simulated sensors as the tracker sees them ([`Sensor`]): each is told where the true
//! target is before a tick, and draws its noise from the measurement stream it owns.

use rand::Rng;

use super::rendered_camera::VisionSensor;
use infotrack_core::frames::Enu2;
use infotrack_core::rng::CoreRng;
use infotrack_core::tracker::{Observation, Prior, Sensor};
use infotrack_core::world::camera::View;
use infotrack_core::world::World;
use infotrack_vision::VisionError;

/// The paper's sensor: the target is seen when it is inside the footprint and outside every
/// occlusion, and then measured as z = x + N(0, R).
pub struct AnalyticSensor<'w> {
    world: &'w World,
    rng: CoreRng,
    target_enu: Enu2,
}

impl<'w> AnalyticSensor<'w> {
    /// A sensor in `world`, with its noise from `rng`.
    pub fn new(world: &'w World, rng: CoreRng) -> Self {
        Self {
            world,
            rng,
            target_enu: Enu2::zeros(),
        }
    }

    /// Where the true target is now, world ENU.
    pub fn set_target(&mut self, target_enu: Enu2) {
        self.target_enu = target_enu;
    }
}

impl Sensor for AnalyticSensor<'_> {
    type Error = std::convert::Infallible;

    fn observe(
        &mut self,
        _t_s: f64,
        view: &View,
        _prior: &Prior,
    ) -> Result<Observation, Self::Error> {
        let visible = self.world.is_visible(view, &self.target_enu);
        let z = visible.then(|| {
            self.world
                .measurement
                .measure(&self.target_enu, &mut self.rng)
        });
        Ok(Observation::Frame {
            taken_from: *view,
            z,
        })
    }
}

/// Frames rendered by the synthetic camera from a level vehicle at the view's heading,
/// searched by the real
/// detector around the filter's prior, projected to the ground.
pub struct RenderedSensor {
    /// The camera, detector and projection (and their statistics).
    pub camera: VisionSensor,
    rng: CoreRng,
    target_enu: Enu2,
    target_heading_enu_rad: f64,
    /// What the last frame was taken with: view, target, heading, noise seed.
    last_frame: Option<(View, Enu2, f64, u64)>,
}

impl RenderedSensor {
    /// A sensor rendering with `camera`, each frame's noise seeded from `rng`.
    pub fn new(camera: VisionSensor, rng: CoreRng) -> Self {
        Self {
            camera,
            rng,
            target_enu: Enu2::zeros(),
            target_heading_enu_rad: 0.0,
            last_frame: None,
        }
    }

    /// The last frame, rendered whole (the measurement rendered only what it searched): the
    /// same pixels, for a visual record.
    pub fn last_frame(&self) -> Option<infotrack_vision::image::GrayImage> {
        let (view, target, heading, seed) = self.last_frame?;
        Some(self.camera.whole_frame(&view, &target, heading, seed))
    }

    /// Where the true target is now and where it heads, world ENU.
    pub fn set_target(&mut self, target_enu: Enu2, heading_enu_rad: f64) {
        self.target_enu = target_enu;
        self.target_heading_enu_rad = heading_enu_rad;
    }

    /// One frame's measurement from `view` with the frame noise seeded by
    /// `frame_seed` (drawn by the caller, who may need the draw even when it takes no frame).
    pub fn measure_with_seed(
        &mut self,
        view: &View,
        prior: &Prior,
        frame_seed: u64,
    ) -> Result<Option<Enu2>, VisionError> {
        self.last_frame = Some((
            *view,
            self.target_enu,
            self.target_heading_enu_rad,
            frame_seed,
        ));
        self.camera.measure(
            view,
            &self.target_enu,
            self.target_heading_enu_rad,
            Some((prior.mean_enu, prior.cov_m2)),
            frame_seed,
        )
    }

    /// The next frame seed from the sensor's own stream.
    pub fn next_frame_seed(&mut self) -> u64 {
        self.rng.gen()
    }
}

impl Sensor for RenderedSensor {
    type Error = VisionError;

    fn observe(
        &mut self,
        _t_s: f64,
        view: &View,
        prior: &Prior,
    ) -> Result<Observation, VisionError> {
        // The frame's noise comes from the measurement stream, like the analytic model's.
        let frame_seed = self.next_frame_seed();
        let z = self.measure_with_seed(view, prior, frame_seed)?;
        Ok(Observation::Frame {
            taken_from: *view,
            z,
        })
    }
}
