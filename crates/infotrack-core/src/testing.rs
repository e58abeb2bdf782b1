//! The shipped configurations' core tables, for tests: the core's own tests (and the
//! configuration's parity test) read the lab and the field worlds the program ships without
//! the application's configuration crate. Parsed from the files compiled in; no file is
//! read at run time and nothing is validated here (the configuration crate validates, and
//! its parity test checks that both assemble the same parameters).

use std::path::Path;

use serde::Deserialize;

use crate::estimation::sections::{FilterConfig, KalmanConfig};
use crate::guidance::sections::GuidanceConfig;
use crate::guidance::ReachShape;
use crate::motion::sections::MotionConfig;
use crate::scenario::{Scenario, VehicleLimits};
use crate::tracker::sections::{AcquisitionConfig, TimingConfig};
use crate::tracker::{Failsafe, LostFallback};
use crate::world::geometry::BoundsEnu;
use crate::world::road::RoadConfig;
use crate::world::sections::{CameraConfig, MeasurementConfig, OcclusionConfig};
use crate::world::signature::SpeedEnvelope;

/// The shipped configurations the tests read, by file name.
pub const SHIPPED: &[(&str, &str)] = &[
    ("default.toml", include_str!("../../../config/default.toml")),
    ("outdoor.toml", include_str!("../../../config/outdoor.toml")),
    (
        "field-grid.toml",
        include_str!("../../../config/field-grid.toml"),
    ),
    (
        "field-ring.toml",
        include_str!("../../../config/field-ring.toml"),
    ),
    (
        "field-twin.toml",
        include_str!("../../../config/field-twin.toml"),
    ),
];

/// A configuration's core tables, and the few values of the application's tables that the
/// core's parameters are assembled from (the vehicle's altitude and speed, the daemon's
/// failsafes, the tag's size).
#[derive(Debug, Clone, Deserialize)]
pub struct Config {
    /// The scenario's name.
    #[serde(default)]
    pub name: String,
    /// The workspace, world ENU.
    pub workspace_enu: BoundsEnu,
    /// The road network.
    pub road: RoadConfig,
    /// The occlusions.
    #[serde(default)]
    pub occlusions: Vec<OcclusionConfig>,
    /// The camera's field of view.
    pub camera: CameraConfig,
    /// The measurement noise.
    pub measurement: MeasurementConfig,
    /// The loop rates.
    pub timing: TimingConfig,
    /// The particle filter.
    pub filter: FilterConfig,
    /// The motion models.
    pub motion: MotionConfig,
    /// The Kalman filter.
    pub kalman: KalmanConfig,
    /// The guidance laws.
    pub guidance: GuidanceConfig,
    /// The operator's cue.
    #[serde(default)]
    pub acquisition: Option<AcquisitionConfig>,
    /// The agent's altitude and speed.
    pub agent: Agent,
    /// The target's speeds.
    pub target: Target,
    /// The daemon's failsafes.
    #[serde(default)]
    pub daemon: Daemon,
    /// The tag.
    #[serde(default)]
    pub vision: Vision,
}

/// `[agent]`: what the core's parameters use of it.
#[derive(Debug, Clone, Deserialize)]
pub struct Agent {
    /// Flight altitude, m.
    pub altitude_m: f64,
    /// Horizontal speed limit, m/s.
    pub speed_limit_mps: f64,
    /// `per_axis` (absent) or `norm`.
    #[serde(default)]
    pub speed_limit_shape: Option<String>,
}

/// `[target]`: the simulated car's speeds.
#[derive(Debug, Clone, Deserialize)]
pub struct Target {
    /// Cruise speed, m/s.
    pub cruise_speed_mps: f64,
    /// Top speed, m/s.
    pub max_speed_mps: f64,
}

/// `[daemon]`: the failsafes, with the application's defaults.
#[derive(Debug, Clone, Deserialize)]
#[serde(default)]
pub struct Daemon {
    /// Seconds without a detection before the target counts as lost.
    pub target_lost_after_s: f64,
    /// `eer`, `lawn` or `hold`.
    pub target_lost_fallback: String,
    /// Seconds without a frame before the camera counts as lost.
    pub camera_timeout_s: f64,
    /// A guidance decision's budget, ms.
    pub guidance_budget_ms: f64,
}

impl Default for Daemon {
    fn default() -> Self {
        Self {
            target_lost_after_s: 10.0,
            target_lost_fallback: "eer".into(),
            camera_timeout_s: 1.0,
            guidance_budget_ms: 300.0,
        }
    }
}

/// `[vision]`: the tag's size, with the application's default.
#[derive(Debug, Clone, Deserialize)]
#[serde(default)]
pub struct Vision {
    /// Side of the tag's black square, m.
    pub tag_size_m: f64,
}

impl Default for Vision {
    fn default() -> Self {
        Self { tag_size_m: 0.1 }
    }
}

impl Config {
    /// Parses a configuration's text (`_origin` only mirrors the application's signature).
    pub fn from_toml_str(text: &str, _origin: &Path) -> Result<Self, toml::de::Error> {
        toml::from_str(text)
    }

    /// The shipped configuration with `path`'s file name (one of [`SHIPPED`]).
    pub fn load(path: &Path) -> Result<Self, toml::de::Error> {
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let text = SHIPPED
            .iter()
            .find(|(file, _)| *file == name)
            .map(|(_, text)| *text)
            .unwrap_or_else(|| panic!("{name} is not among the configs compiled into the tests"));
        Self::from_toml_str(text, path)
    }

    /// The lab (`config/default.toml`).
    pub fn default_lab() -> Self {
        Self::load(Path::new("default.toml")).expect("config/default.toml parses")
    }

    /// The core's tables, as the application's configuration hands them over.
    pub fn scenario(&self) -> Scenario<'_> {
        let norm = self.agent.speed_limit_shape.as_deref() == Some("norm");
        Scenario {
            name: &self.name,
            workspace_enu: self.workspace_enu,
            road: &self.road,
            occlusions: &self.occlusions,
            camera: &self.camera,
            measurement: &self.measurement,
            timing: &self.timing,
            filter: &self.filter,
            motion: &self.motion,
            kalman: &self.kalman,
            guidance: &self.guidance,
            acquisition: self.acquisition.as_ref(),
            vehicle: VehicleLimits {
                altitude_m: self.agent.altitude_m,
                speed_limit_mps: self.agent.speed_limit_mps,
                reach_shape: if norm {
                    ReachShape::Disc
                } else {
                    ReachShape::Square
                },
            },
            failsafe: Failsafe {
                target_lost_after_s: self.daemon.target_lost_after_s,
                fallback: self
                    .daemon
                    .target_lost_fallback
                    .parse()
                    .unwrap_or(LostFallback::Eer),
                camera_timeout_s: self.daemon.camera_timeout_s,
                guidance_budget_ms: self.daemon.guidance_budget_ms,
            },
            target_speed: SpeedEnvelope {
                cruise_mps: self.target.cruise_speed_mps,
                max_mps: self.target.max_speed_mps,
            },
            detection_margin_m: self.vision.tag_size_m * std::f64::consts::FRAC_1_SQRT_2,
        }
    }

    crate::assembled_from_scenario!();

    /// See [`Scenario::filter_dt_s`].
    pub fn filter_dt_s(&self) -> f64 {
        self.scenario().filter_dt_s()
    }
}
