//! A scenario: the tables of a configuration the core is built from (world, filter,
//! motion, guidance, rates, cue), and each component's parameters assembled from them.
//! The application's configuration adds its own tables (vehicle, camera, daemon) and hands
//! the core a [`Scenario`] of the rest; the core never sees the application's `Config`.

use crate::estimation::sections::{FilterConfig, KalmanConfig};
use crate::estimation::{FilterParams, KalmanParams};
use crate::guidance::ambush::{AmbushParams, DEFAULT_AMBUSH_WINDOW_S};
use crate::guidance::eer::{
    DEFAULT_CENTRING_SHARE, DEFAULT_SEARCH_COMMITMENT, DEFAULT_SEARCH_ESCAPE_FLOOR,
};
use crate::guidance::sections::GuidanceConfig;
use crate::guidance::{EerParams, GuidanceKind, HeadingRule, ReachShape, ViewHeading};
use crate::motion::sections::MotionConfig;
use crate::motion::MotionParams;
use crate::tracker::sections::{AcquisitionConfig, TimingConfig};
use crate::tracker::{Failsafe, Rates, TrackerParams, DEFAULT_CUE_MIN_SPEED_SHARE};
use crate::world::camera::Footprint;
use crate::world::geometry::BoundsEnu;
use crate::world::geometry::{Enu2, PolygonEnu};
use crate::world::measurement::{Gaussian2, MeasurementModel};
use crate::world::road::RoadConfig;
use crate::world::road::RoadNetwork;
use crate::world::sections::{CameraConfig, MeasurementConfig, OcclusionConfig};
use crate::world::signature::{road_graph_sha256, SpeedEnvelope, WorldSignature};
use crate::world::World;

/// The assembly methods of a configuration type that has `fn scenario(&self) -> Scenario`:
/// every component's parameters as its [`Scenario`] assembles them, so that the
/// application's configuration and the core's test configurations read alike.
#[macro_export]
macro_rules! assembled_from_scenario {
    () => {
        /// See [`Scenario::world`]($crate::scenario::Scenario::world).
        pub fn world(&self) -> $crate::world::World {
            self.scenario().world()
        }

        /// See [`Scenario::road_network`]($crate::scenario::Scenario::road_network).
        pub fn road_network(&self) -> $crate::world::road::RoadNetwork {
            self.scenario().road_network()
        }

        /// See [`Scenario::footprint`]($crate::scenario::Scenario::footprint).
        pub fn footprint(&self) -> $crate::world::camera::Footprint {
            self.scenario().footprint()
        }

        /// See [`Scenario::world_seen_by_detector`]($crate::scenario::Scenario::world_seen_by_detector).
        pub fn world_seen_by_detector(&self) -> $crate::world::World {
            self.scenario().world_seen_by_detector()
        }

        /// See [`Scenario::occlusion_polygons`]($crate::scenario::Scenario::occlusion_polygons).
        pub fn occlusion_polygons(&self) -> Vec<$crate::world::geometry::PolygonEnu> {
            self.scenario().occlusion_polygons()
        }

        /// See [`Scenario::filter_params`]($crate::scenario::Scenario::filter_params).
        pub fn filter_params(&self) -> $crate::estimation::FilterParams {
            self.scenario().filter_params()
        }

        /// See [`Scenario::road_sigma_m`]($crate::scenario::Scenario::road_sigma_m).
        pub fn road_sigma_m(&self) -> Option<f64> {
            self.scenario().road_sigma_m()
        }

        /// See [`Scenario::cue_region`]($crate::scenario::Scenario::cue_region).
        pub fn cue_region(&self) -> Option<($crate::world::geometry::Enu2, f64)> {
            self.scenario().cue_region()
        }

        /// See [`Scenario::cue_speeds_mps`]($crate::scenario::Scenario::cue_speeds_mps).
        pub fn cue_speeds_mps(&self) -> std::ops::RangeInclusive<f64> {
            self.scenario().cue_speeds_mps()
        }

        /// See [`Scenario::eer_params`]($crate::scenario::Scenario::eer_params).
        pub fn eer_params(&self) -> $crate::guidance::EerParams {
            self.scenario().eer_params()
        }

        /// See [`Scenario::ambush_params`]($crate::scenario::Scenario::ambush_params).
        pub fn ambush_params(&self) -> $crate::guidance::ambush::AmbushParams {
            self.scenario().ambush_params()
        }

        /// See [`Scenario::kalman_params`]($crate::scenario::Scenario::kalman_params).
        pub fn kalman_params(&self) -> $crate::estimation::KalmanParams {
            self.scenario().kalman_params()
        }

        /// See [`Scenario::motion_params`]($crate::scenario::Scenario::motion_params).
        pub fn motion_params(&self) -> $crate::motion::MotionParams {
            self.scenario().motion_params()
        }

        /// See [`Scenario::world_signature`]($crate::scenario::Scenario::world_signature).
        pub fn world_signature(&self) -> $crate::world::signature::WorldSignature {
            self.scenario().world_signature()
        }

        /// See [`Scenario::rates`]($crate::scenario::Scenario::rates).
        pub fn rates(&self) -> $crate::tracker::Rates {
            self.scenario().rates()
        }

        /// See [`Scenario::heading_rule`]($crate::scenario::Scenario::heading_rule).
        pub fn heading_rule(&self) -> $crate::guidance::HeadingRule {
            self.scenario().heading_rule()
        }

        /// See [`Scenario::tracker_params`]($crate::scenario::Scenario::tracker_params).
        pub fn tracker_params(
            &self,
            guidance: $crate::guidance::GuidanceKind,
            failsafe: bool,
        ) -> $crate::tracker::TrackerParams {
            self.scenario().tracker_params(guidance, failsafe)
        }
    };
}

/// The vehicle's limits a scenario needs: where the camera flies and how far it can go.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleLimits {
    /// Flight altitude above the ground plane, m.
    pub altitude_m: f64,
    /// Horizontal speed limit, m/s.
    pub speed_limit_mps: f64,
    /// The shape of the region one guidance horizon reaches.
    pub reach_shape: ReachShape,
}

/// The core's tables of one configuration, borrowed.
#[derive(Debug, Clone, Copy)]
pub struct Scenario<'a> {
    /// The scenario's name (it identifies the world to a learned model).
    pub name: &'a str,
    /// The workspace (geofence), world ENU.
    pub workspace_enu: BoundsEnu,
    /// The road network's table.
    pub road: &'a RoadConfig,
    /// The occlusions.
    pub occlusions: &'a [OcclusionConfig],
    /// The camera's field of view.
    pub camera: &'a CameraConfig,
    /// The measurement noise.
    pub measurement: &'a MeasurementConfig,
    /// The loop rates.
    pub timing: &'a TimingConfig,
    /// The particle filter.
    pub filter: &'a FilterConfig,
    /// The motion models.
    pub motion: &'a MotionConfig,
    /// The Kalman filter.
    pub kalman: &'a KalmanConfig,
    /// The guidance laws.
    pub guidance: &'a GuidanceConfig,
    /// The operator's cue, if any.
    pub acquisition: Option<&'a AcquisitionConfig>,
    /// The vehicle's altitude and reach.
    pub vehicle: VehicleLimits,
    /// The failsafes a flight uses.
    pub failsafe: Failsafe,
    /// The target's speeds (they identify the world to a learned model).
    pub target_speed: SpeedEnvelope,
    /// How near an image edge or occlusion a detected tag's centre can be and the tag
    /// still be cut off, m (see [`World::with_detection_margin`]).
    pub detection_margin_m: f64,
}

impl Scenario<'_> {
    /// The world: roads, occlusions, workspace, footprint at the agent's altitude, the
    /// measurement model.
    pub fn world(&self) -> World {
        World::new(
            self.workspace_enu,
            self.road_network(),
            self.occlusion_polygons(),
            self.footprint(),
            MeasurementModel::new(self.measurement.noise_cov_m2),
        )
    }

    /// The road network. A loaded config's roads were checked to form one (`validate`); a
    /// config changed in code since is checked again here, and one that no longer forms a
    /// network is a bug in that code.
    pub fn road_network(&self) -> RoadNetwork {
        match RoadNetwork::try_from(self.road) {
            Ok(road) => road,
            Err(e) => panic!("a config changed after it was validated: {e}"),
        }
    }

    /// The camera's footprint at the tracking altitude.
    pub fn footprint(&self) -> Footprint {
        Footprint::from_fov(
            self.vehicle.altitude_m,
            self.camera.fov_x_rad,
            self.camera.fov_y_rad,
        )
    }

    /// The world as a tracker measuring through the AprilTag detector sees it (rendered
    /// frames, a real camera): a missing detection is evidence only where the whole tag
    /// would be in the image (see [`World::is_wholly_visible`]). The analytic sensor sees
    /// a target whenever its centre is in view, and its tracker keeps [`Self::world`].
    pub fn world_seen_by_detector(&self) -> World {
        self.world().with_detection_margin(self.detection_margin_m)
    }

    /// The occlusions as polygons, world ENU.
    pub fn occlusion_polygons(&self) -> Vec<PolygonEnu> {
        self.occlusions
            .iter()
            .filter_map(|o| {
                // Validated at load: every polygon has at least three distinct vertices.
                PolygonEnu::new(
                    o.vertices_enu_m
                        .iter()
                        .map(|v| Enu2::new(v[0], v[1]))
                        .collect(),
                )
            })
            .collect()
    }

    /// The particle filter's parameters.
    pub fn filter_params(&self) -> FilterParams {
        let f = &self.filter;
        FilterParams {
            particles: f.particles,
            history_len: f.history_len,
            process_noise: twice(f.process_noise_cov_m2),
            resample_threshold: f.resample_threshold,
            reseed_threshold: f.reseed_threshold,
            roughening: f.roughening,
            miss_probability: f.miss_probability,
            max_outside_fraction: f.max_outside_fraction,
            init_speed_max_mps: self.motion.cv_max_speed_mps,
            dt_s: self.filter_dt_s(),
            redraw_on_roads: true,
            road_sigma_m: self.road_sigma_m(),
        }
    }

    /// The road constraint's sigma (`filter.road_sigma_m`, or three times the measurement
    /// noise's largest sigma); `None` when turned off with 0.
    pub fn road_sigma_m(&self) -> Option<f64> {
        let sigma = self.filter.road_sigma_m.unwrap_or_else(|| {
            let r = self.measurement.noise_cov_m2;
            3.0 * nalgebra::Matrix2::new(r[0][0], r[0][1], r[1][0], r[1][1])
                .symmetric_eigenvalues()
                .max()
                .max(0.0)
                .sqrt()
        });
        (sigma > 0.0).then_some(sigma)
    }

    /// The operator's cue as a region (centre, radius), world ENU; `None` without one, or
    /// when each run is cued where its recorded track starts ([`Self::cue_at_track_start`]).
    pub fn cue_region(&self) -> Option<(Enu2, f64)> {
        let a = self.acquisition?;
        let [x, y] = a.cue_enu_m?;
        Some((Enu2::new(x, y), a.cue_radius_m))
    }

    /// The cue's radius when each run is cued where its recorded track starts
    /// (`[acquisition]` without `cue_enu_m`): the cue is then `(track start, this radius)`.
    pub fn cue_at_track_start(&self) -> Option<f64> {
        let a = self.acquisition?;
        a.cue_enu_m.is_none().then_some(a.cue_radius_m)
    }

    /// The speeds the search from the cue gives its hypotheses before the first sighting,
    /// m/s: from `acquisition.min_speed_mps` (default half the motion model's largest speed)
    /// to the largest; without a cue, from 0.
    pub fn cue_speeds_mps(&self) -> std::ops::RangeInclusive<f64> {
        let v_max = self.motion.cv_max_speed_mps;
        let min = self.acquisition.map_or(0.0, |a| {
            a.min_speed_mps
                .unwrap_or(DEFAULT_CUE_MIN_SPEED_SHARE * v_max)
        });
        min.min(v_max)..=v_max
    }

    /// EER's parameters.
    pub fn eer_params(&self) -> EerParams {
        let g = &self.guidance;
        EerParams {
            entropy_particles: g.entropy_particles,
            entropy_particles_concentrated: g
                .entropy_particles_concentrated
                .unwrap_or(g.entropy_particles),
            measurements_per_particle: g.measurements_per_particle,
            horizon_steps: g.horizon_steps,
            grid_side: g.candidate_grid_side,
            reach_m: self.vehicle.speed_limit_mps * g.horizon_steps as f64 * self.filter_dt_s(),
            reach_shape: self.vehicle.reach_shape,
            kernel: Gaussian2::new(g.entropy_kernel_cov_m2),
            miss_probability: self.filter.miss_probability,
            process_noise: twice(self.filter.process_noise_cov_m2),
            step_s: self.filter_dt_s(),
            intercept_within_s: g.intercept_within_s,
            search_commitment: g.search_commitment.unwrap_or(DEFAULT_SEARCH_COMMITMENT),
            centring_share: g.centring_share.unwrap_or(DEFAULT_CENTRING_SHARE),
            search_escape_floor: g.search_escape_floor.unwrap_or(DEFAULT_SEARCH_ESCAPE_FLOOR),
        }
    }

    /// The ambush's parameters (`guidance.ambush_window_s`).
    pub fn ambush_params(&self) -> AmbushParams {
        AmbushParams::new(
            self.guidance
                .ambush_window_s
                .unwrap_or(DEFAULT_AMBUSH_WINDOW_S),
        )
    }

    /// The Kalman filter's parameters.
    pub fn kalman_params(&self) -> KalmanParams {
        KalmanParams {
            dt_s: self.filter_dt_s(),
            process_noise_diag: self.kalman.process_noise_diag,
            initial_cov_diag: self.kalman.initial_cov_diag,
            measurement_noise_cov_m2: self.measurement.noise_cov_m2,
            workspace_enu: self.workspace_enu,
        }
    }

    /// The motion models' parameters.
    pub fn motion_params(&self) -> MotionParams {
        MotionParams {
            dt_s: self.filter_dt_s(),
            history_len: self.filter.history_len,
            cv_max_speed_mps: self.motion.cv_max_speed_mps,
            dmmn_model: self.motion.dmmn_model.clone(),
            onnxruntime_library: self.motion.onnxruntime_library.clone(),
            world: Some(self.world_signature()),
            allow_model_from_other_world: self.motion.allow_model_from_other_world,
        }
    }

    /// What identifies this world to a learned motion model (recorded by `infotrack
    /// dataset`, checked when a model is loaded).
    pub fn world_signature(&self) -> WorldSignature {
        WorldSignature {
            name: self.name.to_string(),
            workspace_enu: self.workspace_enu,
            road_graph_sha256: road_graph_sha256(self.road),
            target_speed: self.target_speed,
            k_in: self.filter.history_len,
            dt_s: self.filter_dt_s(),
        }
    }

    /// The loop rates.
    pub fn rates(&self) -> Rates {
        Rates {
            physics_hz: self.timing.physics_hz,
            filter_hz: self.timing.filter_hz,
            guidance_hz: self.timing.guidance_hz,
        }
    }

    /// The daemon's failsafes.
    pub fn failsafe(&self) -> Failsafe {
        self.failsafe
    }

    /// Filter period dt = 1 / filter_hz, seconds.
    pub fn filter_dt_s(&self) -> f64 {
        1.0 / self.timing.filter_hz
    }

    /// Which way the view turns (`guidance.view_heading`; absent, `along_track` for a field
    /// flight from an operator's cue, `north` for the paper's lab, which has none): a hover
    /// within a quarter view of its setpoint keeps its heading.
    pub fn heading_rule(&self) -> HeadingRule {
        let default = if self.acquisition.is_some() {
            ViewHeading::AlongTrack
        } else {
            ViewHeading::North
        };
        HeadingRule {
            kind: self.guidance.view_heading.unwrap_or(default),
            settle_m: self.footprint().quarter_view_m(),
        }
    }

    /// Everything the tracker is built from, for a guidance law, with or without the
    /// daemon's failsafes.
    pub fn tracker_params(&self, guidance: GuidanceKind, failsafe: bool) -> TrackerParams {
        TrackerParams {
            rates: self.rates(),
            guidance,
            heading: self.heading_rule(),
            filter: self.filter_params(),
            kalman: self.kalman_params(),
            motion: self.motion_params(),
            eer: self.eer_params(),
            lawn: self.guidance.lawn.clone(),
            failsafe: failsafe.then_some(self.failsafe),
            cue: self.cue_region(),
            ambush: self.ambush_params(),
            cue_prior: self.acquisition.and_then(|a| a.prior).unwrap_or_default(),
            cue_speeds_mps: self.cue_speeds_mps(),
            respread_after_s: Some(self.failsafe.target_lost_after_s),
            injection_share: self.filter.hypothesis_injection,
        }
    }
}

/// N(0, 2Q): the paper's code adds twice the process noise after each prediction.
fn twice(q: [[f64; 2]; 2]) -> Gaussian2 {
    Gaussian2::new([
        [2.0 * q[0][0], 2.0 * q[0][1]],
        [2.0 * q[1][0], 2.0 * q[1][1]],
    ])
}
