//! What the program plugs into the daemon for a simulated flight: the in-process vehicle
//! for `mock:` names and the world the synthetic camera looks at. The daemon imports
//! neither the mock autopilot nor the simulator; the program wires them in
//! (`infotrack::wiring`), and a daemon without them refuses `mock:` and `synthetic`.

use std::any::Any;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use crate::autopilot::modes::Flavor;
use crate::config::Config;
use crate::tracker::Prior;
use crate::vision::{VisionError, VisionStats};
use crate::world::camera::View;
use crate::world::geometry::Enu2;
use crate::world::World;

/// A vehicle simulated in the daemon's own process, reached over MAVLink like any other;
/// its link can be cut or degraded for fault injection.
pub trait InProcessVehicle: Send + Sync {
    /// Cuts the link both ways for `duration`.
    fn cut_link(&self, duration: Duration);
    /// Loses this share of messages, percent, drawn from `seed`.
    fn set_packet_loss(&self, percent: f64, seed: u64);
    /// The vehicle itself, for tests that look inside it.
    fn as_any(&self) -> &dyn Any;
}

/// The world the synthetic camera looks at: a simulated target on the roads and the frames
/// rendered of it, measured through the detector. Built and used on the pipeline's thread
/// (the detector may not move between threads).
pub trait SyntheticWorld {
    /// Moves the target one physics step of `dt_s` along `world`'s roads.
    fn step_target(&mut self, world: &World, dt_s: f64);
    /// Whether the target's recorded track has ended.
    fn target_ended(&self) -> bool;
    /// The cue (centre world ENU, radius m) where the target's recorded track starts, when
    /// the config leaves `acquisition.cue_enu_m` to the track.
    fn track_cue(&self) -> Option<(Enu2, f64)>;
    /// The target's position and velocity, world ENU.
    fn target_enu(&self) -> (Enu2, Enu2);
    /// Draws the next frame's noise seed (at every filter step, frozen camera or not).
    fn next_frame_seed(&mut self) -> u64;
    /// Renders the frame seen from `view` with `seed` and measures the tag in it.
    fn measure_with_seed(
        &mut self,
        view: &View,
        prior: &Prior,
        seed: u64,
    ) -> Result<Option<Enu2>, VisionError>;
    /// How the frames went.
    fn stats(&self) -> VisionStats;
    /// How long the last frame took to render, ms.
    fn last_render_ms(&self) -> f64;
    /// The last frame, every pixel rendered (for a visual record; the search renders only
    /// what it looks at).
    fn last_frame(&self) -> Option<crate::vision::image::GrayImage>;
}

/// Why a simulated part could not start.
pub type SimulatorError = Box<dyn std::error::Error + Send + Sync>;

/// A started in-process vehicle and the URL that reaches it.
pub type StartedVehicle = (Box<dyn InProcessVehicle>, String);

/// Starts the in-process vehicle of a flavour for a configuration.
pub type StartVehicle = Arc<
    dyn Fn(
            &Config,
            Flavor,
        ) -> Pin<Box<dyn Future<Output = Result<StartedVehicle, SimulatorError>> + Send>>
        + Send
        + Sync,
>;

/// Builds the synthetic camera's world for a configuration, its world and a seed.
pub type BuildSyntheticWorld = Arc<
    dyn Fn(&Config, &World, u64) -> Result<Box<dyn SyntheticWorld>, SimulatorError> + Send + Sync,
>;

/// The simulated parts a program hands the daemon; `None`: not available.
#[derive(Clone, Default)]
pub struct Simulators {
    /// For `daemon.vehicle = "mock:px4"` or `"mock:ardupilot"`.
    pub start_vehicle: Option<StartVehicle>,
    /// For `daemon.camera = "synthetic"`.
    pub synthetic_world: Option<BuildSyntheticWorld>,
}

impl std::fmt::Debug for Simulators {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulators")
            .field("start_vehicle", &self.start_vehicle.is_some())
            .field("synthetic_world", &self.synthetic_world.is_some())
            .finish()
    }
}
