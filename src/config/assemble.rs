//! The configuration assembles each core component's own parameters: the core never sees
//! the application's `Config`.

use super::{Config, SpeedLimitShape};
use crate::estimation::{FilterParams, KalmanParams};
use crate::guidance::ambush::{AmbushParams, DEFAULT_AMBUSH_WINDOW_S};
use crate::guidance::eer::{
    DEFAULT_CENTRING_SHARE, DEFAULT_SEARCH_COMMITMENT, DEFAULT_SEARCH_ESCAPE_FLOOR,
};
use crate::guidance::{EerParams, GuidanceKind, HeadingRule, ReachShape, ViewHeading};
use crate::motion::MotionParams;
use crate::tracker::{Failsafe, LostFallback, Rates, TrackerParams, DEFAULT_CUE_MIN_SPEED_SHARE};
use crate::world::camera::Footprint;
use crate::world::geometry::{Enu2, PolygonEnu};
use crate::world::measurement::{Gaussian2, MeasurementModel};
use crate::world::road::RoadNetwork;
use crate::world::signature::{road_graph_sha256, SpeedEnvelope, WorldSignature};
use crate::world::World;

impl Config {
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
        match RoadNetwork::try_from(&self.road) {
            Ok(road) => road,
            Err(e) => panic!("a config changed after it was validated: {e}"),
        }
    }

    /// The camera's footprint at the tracking altitude.
    pub fn footprint(&self) -> Footprint {
        Footprint::from_fov(
            self.agent.altitude_m,
            self.camera.fov_x_rad,
            self.camera.fov_y_rad,
        )
    }

    /// The world as a tracker measuring through the AprilTag detector sees it (rendered
    /// frames, a real camera): a missing detection is evidence only where the whole tag
    /// would be in the image (see [`World::is_wholly_visible`]). The analytic sensor sees
    /// a target whenever its centre is in view, and its tracker keeps [`Self::world`].
    pub fn world_seen_by_detector(&self) -> World {
        self.world()
            .with_detection_margin(self.vision.detection_margin_m())
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

    /// The operator's cue as a region (centre, radius), world ENU.
    pub fn cue_region(&self) -> Option<(Enu2, f64)> {
        self.acquisition
            .as_ref()
            .map(|a| (Enu2::new(a.cue_enu_m[0], a.cue_enu_m[1]), a.cue_radius_m))
    }

    /// The speeds the search from the cue gives its hypotheses before the first sighting,
    /// m/s: from `acquisition.min_speed_mps` (default half the motion model's largest speed)
    /// to the largest; without a cue, from 0.
    pub fn cue_speeds_mps(&self) -> std::ops::RangeInclusive<f64> {
        let v_max = self.motion.cv_max_speed_mps;
        let min = self.acquisition.as_ref().map_or(0.0, |a| {
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
            reach_m: self.agent.speed_limit_mps * g.horizon_steps as f64 * self.filter_dt_s(),
            reach_shape: match self.agent.speed_limit_shape {
                SpeedLimitShape::PerAxis => ReachShape::Square,
                SpeedLimitShape::Norm => ReachShape::Disc,
            },
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
            name: self.name.clone(),
            workspace_enu: self.workspace_enu,
            road_graph_sha256: road_graph_sha256(&self.road),
            target_speed: SpeedEnvelope {
                cruise_mps: self.target.cruise_speed_mps,
                max_mps: self.target.max_speed_mps,
            },
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
        let d = &self.daemon;
        Failsafe {
            target_lost_after_s: d.target_lost_after_s,
            // Validated at load to be one of eer, lawn, hold.
            fallback: d.target_lost_fallback.parse().unwrap_or(LostFallback::Eer),
            camera_timeout_s: d.camera_timeout_s,
            guidance_budget_ms: d.guidance_budget_ms,
        }
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
            failsafe: failsafe.then(|| self.failsafe()),
            cue: self.cue_region(),
            ambush: self.ambush_params(),
            cue_prior: self
                .acquisition
                .as_ref()
                .and_then(|a| a.prior)
                .unwrap_or_default(),
            cue_speeds_mps: self.cue_speeds_mps(),
            respread_after_s: Some(self.daemon.target_lost_after_s),
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
