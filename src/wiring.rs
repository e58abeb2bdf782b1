//! The program's wiring of the simulated parts into the daemon: the in-process mock
//! autopilot for `mock:px4` / `mock:ardupilot` and the simulated world the synthetic
//! camera looks at. The daemon itself imports neither the mock nor the simulator.

use std::any::Any;
use std::sync::Arc;
use std::time::Duration;

use crate::autopilot::modes::Flavor;
use crate::config::{Config, MockResponse};
use crate::daemon::simulators::{SimulatorError, StartedVehicle};
use crate::daemon::{InProcessVehicle, Simulators, SyntheticWorld};
use crate::mock::server::{spawn, Faults, MockHandle};
use crate::mock::MockConfig;
use crate::rng::{stream_rng, CoreRng, Stream};
use crate::simulated::{RenderedSensor, TargetSim, VisionSensor};
use crate::tracker::Prior;
use crate::vision::{VisionError, VisionStats};
use crate::world::camera::View;
use crate::world::geometry::Enu2;
use crate::world::World;

/// Everything this program can simulate: what `infotrack run` and `sim --closed-loop` fly.
pub fn simulators() -> Simulators {
    Simulators {
        start_vehicle: Some(Arc::new(|cfg: &Config, flavor| {
            let cfg = cfg.clone();
            Box::pin(async move { start_mock(&cfg, flavor).await })
        })),
        synthetic_world: Some(Arc::new(|cfg: &Config, world: &World, seed| {
            Ok(Box::new(SimulatedScene::new(cfg, world, seed)?) as Box<dyn SyntheticWorld>)
        })),
    }
}

impl InProcessVehicle for MockHandle {
    fn cut_link(&self, duration: Duration) {
        MockHandle::cut_link(self, duration);
    }

    fn set_packet_loss(&self, percent: f64, seed: u64) {
        self.set_faults(Faults {
            loss_percent: percent,
            seed,
            ..Faults::default()
        });
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// A free UDP port on loopback for the mock.
fn free_udp_port() -> std::io::Result<u16> {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
}

/// Starts the in-process mock, with the agent's speed and acceleration limits as its
/// parameters and ArduPilot's lean limit as the shipped parameter file sets it: a vehicle
/// set up as the README says (a real one needs the same parameters loaded before
/// take-off); returns it and the URL to reach it.
async fn start_mock(cfg: &Config, flavor: Flavor) -> Result<StartedVehicle, SimulatorError> {
    let port = free_udp_port()?;
    let mut mc = MockConfig::new(flavor);
    mc.seed = cfg.seed;
    // A world placed on the globe ([world] origin) is flown where it is: the mock's local
    // origin is the world's, as a SITL started with its home there would have it.
    if let Some(w) = &cfg.world {
        mc.origin_lat_deg = w.origin.lat_deg;
        mc.origin_lon_deg = w.origin.lon_deg;
        mc.origin_alt_m = w.origin.alt_m;
    }
    if cfg.daemon.mock_response == MockResponse::Sitl {
        mc.answer_as_sitl();
    }
    let a = &cfg.agent;
    mc.param_overrides = match flavor {
        Flavor::Px4 => vec![
            ("MPC_XY_VEL_MAX".into(), a.speed_limit_mps),
            ("MPC_ACC_HOR".into(), a.accel_limit_mps2),
        ],
        // ArduPilot's are in cm/s and cm/s^2.
        Flavor::ArduPilot => vec![
            ("WPNAV_SPEED".into(), a.speed_limit_mps * 100.0),
            ("WPNAV_ACCEL".into(), a.accel_limit_mps2 * 100.0),
            // firmware-params/ardupilot-guided-tracking.parm: 45 degrees, in centidegrees.
            ("ANGLE_MAX".into(), 4500.0),
        ],
    };
    let mock = spawn(&format!("udpin:127.0.0.1:{port}"), mc, Faults::default()).await?;
    Ok((Box::new(mock), format!("udpout:127.0.0.1:{port}")))
}

/// The simulated target and the synthetic camera rendering it.
struct SimulatedScene {
    target: TargetSim,
    rng_target: CoreRng,
    camera: RenderedSensor,
    cue: Option<(Enu2, f64)>,
}

impl SimulatedScene {
    /// The daemon flies one run: the first recorded track, if any, else the simulated car;
    /// the target and the frames draw from the seed's own streams.
    fn new(cfg: &Config, world: &World, seed: u64) -> Result<Self, SimulatorError> {
        let mut rng_target = stream_rng(seed, 0, Stream::Target, 0);
        let rng_meas = stream_rng(seed, 0, Stream::Measurement, 0);
        let camera = RenderedSensor::new(VisionSensor::from_config(cfg)?, rng_meas);
        let target = TargetSim::for_run(cfg, world, 0, &mut rng_target)?;
        let mut scene = Self {
            cue: target.cue(cfg),
            target,
            rng_target,
            camera,
        };
        scene.show_target();
        Ok(scene)
    }

    fn show_target(&mut self) {
        self.camera
            .set_target(self.target.position_enu, self.target.heading_enu_rad);
    }
}

impl SyntheticWorld for SimulatedScene {
    fn step_target(&mut self, world: &World, dt_s: f64) {
        self.target.step(&world.road, dt_s, &mut self.rng_target);
        self.show_target();
    }

    fn target_ended(&self) -> bool {
        self.target.ended()
    }

    fn track_cue(&self) -> Option<(Enu2, f64)> {
        self.cue
    }

    fn target_enu(&self) -> (Enu2, Enu2) {
        (self.target.position_enu, self.target.velocity_enu)
    }

    fn next_frame_seed(&mut self) -> u64 {
        self.camera.next_frame_seed()
    }

    fn measure_with_seed(
        &mut self,
        view: &View,
        prior: &Prior,
        seed: u64,
    ) -> Result<Option<Enu2>, VisionError> {
        self.camera.measure_with_seed(view, prior, seed)
    }

    fn stats(&self) -> VisionStats {
        self.camera.camera.stats
    }

    fn last_render_ms(&self) -> f64 {
        self.camera.camera.last_render_ms
    }

    fn last_frame(&self) -> Option<crate::vision::image::GrayImage> {
        self.camera.last_frame()
    }
}
