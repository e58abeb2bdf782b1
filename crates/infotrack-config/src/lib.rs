//! The TOML configuration: one struct per table, a doc comment on every field, and
//! validation at load time so that a bad file fails before anything runs.
//!
//! Unknown keys are errors (`deny_unknown_fields`): a misspelt key must not silently
//! fall back to a default.
#![deny(missing_docs)]

mod assemble;
pub mod bounds;
pub mod recorded_track;
mod validate;
pub mod world_file;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use infotrack_core::estimation::sections::{FilterConfig, KalmanConfig};
pub use infotrack_core::guidance::sections::GuidanceConfig;
pub use infotrack_core::guidance::LawnConfig;
pub use infotrack_core::motion::sections::MotionConfig;
pub use infotrack_core::tracker::sections::{AcquisitionConfig, TimingConfig};
pub use infotrack_core::world::geometry::BoundsEnu;
pub use infotrack_core::world::road::{EdgeConfig, NodeConfig, RoadConfig};
pub use infotrack_core::world::sections::{CameraConfig, MeasurementConfig, OcclusionConfig};

/// Why a configuration could not be loaded.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file is not one to read: a device, a FIFO, too large, not text.
    #[error("config file {path}: {source}")]
    File {
        /// The file.
        path: PathBuf,
        /// Why.
        source: infotrack_files::BoundedReadError,
    },
    /// The file is not valid TOML, has an unknown key or a value of the wrong type.
    #[error("config file {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message, which names the key and the line.
        message: String,
    },
    /// A value is out of range or inconsistent with another.
    #[error("config key `{key}` = {value}: {reason}")]
    Invalid {
        /// Dotted path of the key, e.g. `filter.particles`.
        key: String,
        /// The offending value as written.
        value: String,
        /// What is wrong with it.
        reason: String,
    },
}

/// The whole configuration of a scenario and of the algorithms that run on it.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Human-readable scenario name, printed in reports.
    pub name: String,
    /// Seed of every random choice when the command line gives none.
    pub seed: u64,
    /// Workspace: where particles live and the geofence the agent may fly in.
    pub workspace_enu: BoundsEnu,
    /// The target's road network (a Markov chain over nodes joined by straight edges).
    pub road: RoadConfig,
    /// Regions where the target cannot be seen (a union of polygons).
    #[serde(default)]
    pub occlusions: Vec<OcclusionConfig>,
    /// The simulated target vehicle.
    pub target: TargetConfig,
    /// The simulated agent (multicopter).
    pub agent: AgentConfig,
    /// The downward camera.
    pub camera: CameraConfig,
    /// The measurement model z = x + N(0, R).
    pub measurement: MeasurementConfig,
    /// Loop rates and run length.
    pub timing: TimingConfig,
    /// The particle filter.
    pub filter: FilterConfig,
    /// Motion models the particle filter can predict with.
    pub motion: MotionConfig,
    /// The constant-velocity Kalman filter (estimation baseline and KF guidance).
    pub kalman: KalmanConfig,
    /// Guidance laws.
    pub guidance: GuidanceConfig,
    /// The synthetic camera and detector of the simulator's vision mode (`sim --vision`).
    #[serde(default)]
    pub vision: VisionSimConfig,
    /// The daemon (`infotrack run`): vehicle link, camera, rates and failsafes.
    #[serde(default)]
    pub daemon: DaemonConfig,
    /// Where the operator says the target is when tracking starts (optional).
    #[serde(default)]
    pub acquisition: Option<AcquisitionConfig>,
    /// Where the world is on Earth; without it the world is only ENU metres about the
    /// vehicle's local origin, wherever that is.
    #[serde(default)]
    pub world: Option<WorldConfig>,
}

/// Where the world is on Earth (`[world]`). The world's roads, occlusions, geofence and cue
/// are ENU metres about `origin`. The vehicle's local frame has its own origin
/// (GPS_GLOBAL_ORIGIN: where its estimator started, usually where it was powered up);
/// infotrack reads it before commanding anything and converts every position and setpoint
/// between the two frames, horizontally (heights stay above the vehicle's own origin). A
/// vehicle without an origin, or one farther than `origin_tolerance_m` from `origin`, is
/// refused.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldConfig {
    /// The world ENU frame's origin: `{ lat_deg, lon_deg, alt_m }` (WGS84, height above
    /// the ellipsoid, m).
    pub origin: infotrack_core::geodesy::GeodeticWgs84,
    /// How far the vehicle's origin may be from `origin`, horizontally, m: beyond it the
    /// vehicle is refused as implausibly far (the wrong world file?).
    #[serde(default = "default_origin_tolerance_m")]
    pub origin_tolerance_m: f64,
    /// A GeoJSON file (WGS84, relative to the config file) with the world's roads,
    /// occlusions, geofence and cue, instead of writing them as ENU metres; see
    /// `config::world_file` and the README.
    #[serde(default)]
    pub geojson: Option<PathBuf>,
}

fn default_origin_tolerance_m() -> f64 {
    1000.0
}

/// The daemon's settings (`infotrack run`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DaemonConfig {
    /// The vehicle: `mock:px4` or `mock:ardupilot` (an in-process mock autopilot spoken to
    /// over MAVLink on loopback UDP), or a MAVLink URL (`udpin:0.0.0.0:14540`,
    /// `serial:/dev/ttyAMA0:921600`, ...).
    pub vehicle: String,
    /// The camera: `synthetic` (frames rendered from the simulated target on the simulated
    /// roads), or a capture source for a real camera: `v4l2:0`, `/dev/video0`,
    /// `gst:... ! appsink`, a video file or `dir/%04d.png`. With a real camera there is no
    /// simulated target and no ground truth.
    pub camera: String,
    /// OpenCV calibration file of the real camera (camera_matrix, distortion_coefficients,
    /// image_width, image_height); its size is requested from the camera.
    pub calibration: Option<PathBuf>,
    /// The camera's tilt from looking straight down with the image top to the nose: roll,
    /// pitch, yaw in body FRD, rad. The vehicle flies with its nose at minus this yaw from
    /// north, so that the image's axes lie along the world's as the tracker models them.
    pub camera_mount_rpy_rad: [f64; 3],
    /// Camera centre in body FRD, m.
    pub camera_offset_body_frd_m: [f64; 3],
    /// Frame rate requested from a real camera, Hz (0: its default).
    pub camera_fps: f64,
    /// Motion model of the particle filter (`dmmn`, `cv`); `--motion` overrides it.
    pub motion: String,
    /// The vehicle's MAVLink `[system id, component id]`; default: the first autopilot
    /// heard. Either way infotrack flies that one vehicle and ignores every other.
    pub vehicle_id: Option<[u8; 2]>,
    /// Own MAVLink system id.
    pub system_id: u8,
    /// Own MAVLink component id (191: onboard computer).
    pub component_id: u8,
    /// Setpoint stream rate, Hz (PX4 needs more than 2; at least 10).
    pub setpoint_hz: f64,
    /// Seconds to wait for the vehicle's heartbeat at start.
    pub connect_timeout_s: f64,
    /// Seconds allowed for the takeoff to reach the agent's altitude.
    pub takeoff_timeout_s: f64,
    /// Tracking begins once the vehicle is within this distance of the start point and
    /// slower than this many m/s; default: 1 % of the altitude, at least 0.05 m.
    pub start_tolerance_m: Option<f64>,
    /// A vehicle that stays within ten tolerances of the start point this long without
    /// settling (a real autopilot's position loop hunts by a few centimetres) begins
    /// tracking anyway, with a warning, s.
    pub start_settle_s: f64,
    /// The target counts as lost after this long without a measurement, s; the filter's
    /// belief is then spread again along the routes the target can have driven since it
    /// was last seen, less those the camera has looked at since (before it is first seen,
    /// with an `[acquisition]` cue: the routes from the cue's roads since the start), and
    /// again after each further such period while it stays unseen (half the belief kept).
    pub target_lost_after_s: f64,
    /// What to do while the target is lost: `eer` (keep the EER search), `lawn` (lawnmower
    /// sweep), `hold` (stay where the vehicle is).
    pub target_lost_fallback: String,
    /// A guidance decision that takes longer than this is not applied and is counted, ms.
    pub guidance_budget_ms: f64,
    /// No camera frame for this long: hold position and report, s.
    pub camera_timeout_s: f64,
    /// MAVLink 2 signing key file (64 hex digits); none: unsigned.
    pub signing_key: Option<PathBuf>,
    /// Who starts the flight: `auto` (infotrack arms, takes off and flies to the start
    /// point: the simulated default) or `pilot` (the pilot takes off and hands over by
    /// switching to OFFBOARD/GUIDED; infotrack never arms and lets go when the mode leaves).
    pub engage: Engage,
    /// How the in-process mock's vehicle (`mock:px4`, `mock:ardupilot`) answers targets:
    /// `ideal` (exactly, within the agent's speed and acceleration: the paper's simulated
    /// agent) or `sitl` (as the flavour's SITL build measured: PX4 SIH's slow loop that
    /// wanders by ~0.3 m, ArduCopter's steady one; see BENCHMARKS.md).
    pub mock_response: MockResponse,
}

/// How the in-process mock's vehicle answers (`daemon.mock_response`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MockResponse {
    /// Exactly, within the agent's limits.
    #[default]
    Ideal,
    /// As the flavour's SITL build did.
    Sitl,
}

/// Who starts and hands over the flight (`daemon.engage`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Engage {
    /// infotrack arms, takes off, flies to the start point and tracks.
    #[default]
    Auto,
    /// The pilot takes off with the RC; infotrack commands only while the pilot (or the
    /// GCS) has the vehicle in OFFBOARD (PX4) or GUIDED (ArduPilot).
    Pilot,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            vehicle: "mock:px4".into(),
            mock_response: MockResponse::Ideal,
            camera: "synthetic".into(),
            calibration: None,
            camera_mount_rpy_rad: [0.0; 3],
            camera_offset_body_frd_m: [0.0; 3],
            camera_fps: 0.0,
            motion: "dmmn".into(),
            vehicle_id: None,
            system_id: 1,
            component_id: 191,
            setpoint_hz: 20.0,
            connect_timeout_s: 10.0,
            takeoff_timeout_s: 30.0,
            start_tolerance_m: None,
            start_settle_s: 5.0,
            target_lost_after_s: 10.0,
            target_lost_fallback: "eer".into(),
            guidance_budget_ms: 300.0,
            camera_timeout_s: 1.0,
            signing_key: None,
            engage: Engage::Auto,
        }
    }
}

/// The simulator's vision mode: measurements come from rendered frames through the real
/// detector and projection instead of the analytic model.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VisionSimConfig {
    /// Rendered image width, px; the height follows from the fields of view with square
    /// pixels.
    pub image_width_px: u32,
    /// The target's tag36h11 id.
    pub tag_id: u32,
    /// Side of the tag's black square, m.
    pub tag_size_m: f64,
    /// Samples per pixel side when rendering (anti-aliasing).
    pub supersample: usize,
    /// Sensor noise, grey levels (one sigma).
    pub noise_sigma: f64,
    /// Optical blur, px (one sigma).
    pub blur_sigma_px: f64,
    /// The AprilTag detector's settings.
    pub detector: infotrack_vision::detector::DetectorConfig,
    /// Uncertainties behind each measurement's covariance.
    pub projection: infotrack_vision::projection::ProjectionNoise,
}

impl VisionSimConfig {
    /// How near the edge of the image (or an occlusion) the tag's centre may be and the
    /// tag still be cut off, m: half its diagonal (the tag turns with the target).
    pub fn detection_margin_m(&self) -> f64 {
        self.tag_size_m * std::f64::consts::FRAC_1_SQRT_2
    }
}

impl Default for VisionSimConfig {
    fn default() -> Self {
        Self {
            image_width_px: 640,
            tag_id: 0,
            // The paper's lab: a 0.84 m footprint at 1.2 m; a 10 cm tag is ~75 px wide.
            tag_size_m: 0.1,
            supersample: 2,
            noise_sigma: 2.0,
            blur_sigma_px: 0.5,
            detector: Default::default(),
            projection: Default::default(),
        }
    }
}

/// The simulated target: a unicycle that drives along the road network.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetConfig {
    /// Speed when heading toward its goal, m/s.
    pub cruise_speed_mps: f64,
    /// Hard speed limit, m/s (the cruise speed is clipped to it).
    pub max_speed_mps: f64,
    /// Turn rate limit, rad/s.
    pub max_yaw_rate_radps: f64,
    /// Heading error above which the target stops and turns in place, radians.
    pub turn_in_place_above_rad: f64,
    /// Proportional heading gain, 1/s.
    pub heading_gain_per_s: f64,
    /// Distance to the current goal node at which the next goal is sampled, metres.
    pub goal_switch_radius_m: f64,
    /// Recorded tracks the target drives instead of the roads' Markov chain (the keys above
    /// are then unused): a file or a list of files, Monte Carlo run i taking track i mod n.
    /// CSV (`t_s,lon_deg,lat_deg`, or `t_s,x_m,y_m` in world ENU, with that header), GPX 1.1
    /// tracks with times, or SUMO FCD output written with `--fcd-output.geo` (`.xml`);
    /// interpolated in time. A run ends when its track does, if that is sooner. Absent: the
    /// simulated car.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<TrajectoryFiles>,
    /// In a SUMO FCD file with several vehicles, the one the target is; absent: the file's
    /// only vehicle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory_vehicle: Option<String>,
}

/// `target.trajectory`: one track file or several.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum TrajectoryFiles {
    /// One file.
    One(PathBuf),
    /// Several: run i takes file i mod n.
    Many(Vec<PathBuf>),
}

impl TrajectoryFiles {
    /// The files, in order.
    pub fn files(&self) -> Vec<&PathBuf> {
        match self {
            Self::One(p) => vec![p],
            Self::Many(v) => v.iter().collect(),
        }
    }

    /// The track files, to change (resolve or rewrite) their paths.
    pub fn files_mut(&mut self) -> Vec<&mut PathBuf> {
        match self {
            Self::One(p) => vec![p],
            Self::Many(v) => v.iter_mut().collect(),
        }
    }
}

/// The simulated agent: a multicopter at fixed altitude following position setpoints.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AgentConfig {
    /// Flight altitude above the ground plane, metres.
    pub altitude_m: f64,
    /// Start position `[x, y]` in the world ENU frame, metres.
    pub start_enu_m: [f64; 2],
    /// Proportional gain from position error to velocity command, 1/s.
    pub gain_per_s: f64,
    /// Horizontal speed limit, m/s: the simulator's agent applies it as
    /// `speed_limit_shape` says; in the closed loop it is the autopilot's own limit
    /// (MPC_XY_VEL_MAX, WPNAV_SPEED), which bounds the speed's norm.
    pub speed_limit_mps: f64,
    /// Acceleration limit (norm), m/s^2.
    pub accel_limit_mps2: f64,
    /// Position errors below this are treated as zero, metres.
    pub dead_zone_m: f64,
    /// How the simulator's agent limits its speed: `per_axis` (each of east and north
    /// within the limit, the paper's lab agent: a diagonal flies 1.41x faster and a
    /// saturated command turns toward the diagonal) or `norm` (the speed itself, as PX4 and
    /// ArduCopter do). Optional; `per_axis` when absent. EER's reachable candidates follow
    /// it: a square of half width `reach` for `per_axis`, a disc of that radius for `norm`.
    #[serde(default)]
    pub speed_limit_shape: SpeedLimitShape,
    /// How fast the simulator's agent turns to a new heading, rad/s (the mock autopilot turns
    /// at its firmware's own parameter: PX4 MPC_YAWRAUTO_MAX, ArduCopter ATC_SLEW_YAW).
    /// Optional; absent, 45 deg/s, PX4's MPC_YAWRAUTO_MAX default (ArduCopter's ATC_SLEW_YAW
    /// default is 60 deg/s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yaw_rate_limit_rad_s: Option<f64>,
}

/// The simulator's turn rate when `agent.yaw_rate_limit_rad_s` is absent, rad/s: PX4's
/// MPC_YAWRAUTO_MAX default, 45 deg/s.
pub const DEFAULT_YAW_RATE_LIMIT_RAD_S: f64 = std::f64::consts::FRAC_PI_4;

impl AgentConfig {
    /// The turn rate, rad/s (`yaw_rate_limit_rad_s` or its default).
    pub fn yaw_rate_limit_rad_s(&self) -> f64 {
        self.yaw_rate_limit_rad_s
            .unwrap_or(DEFAULT_YAW_RATE_LIMIT_RAD_S)
    }
}

/// How the simulator's agent limits its horizontal speed (`agent.speed_limit_shape`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpeedLimitShape {
    /// Each axis within the limit (the paper's lab agent).
    #[default]
    PerAxis,
    /// The speed's norm within the limit (the autopilots).
    Norm,
}

/// The lab scenario of the paper, compiled into the binary.
pub const DEFAULT_TOML: &str = include_str!("../../../config/default.toml");

impl Config {
    /// Loads and validates a configuration file. Relative paths in it (the calibration,
    /// the model, the ONNX Runtime library, the signing key) are taken from the config
    /// file's folder, so that `run --config /etc/infotrack/px4.toml` works from anywhere;
    /// a path found only from the current directory (how configs were read before) still
    /// works, with a warning.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        /// A config is a page or two of TOML; the largest shipped is ~10 kB.
        const MAX_CONFIG_BYTES: u64 = 1 << 20;
        let text = read_user_file(path, MAX_CONFIG_BYTES)?;
        let mut cfg = Self::from_toml_str(&text, path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        cfg.resolve_paths(base, path);
        // Tracks are read where the config's folder places them: checked here, after the
        // paths are resolved.
        let tracks = cfg.recorded_tracks()?;
        if !tracks.is_empty() {
            tracing::info!(
                "the target drives {} recorded track(s) (target.trajectory); the simulated car's keys of [target] are unused",
                tracks.len()
            );
        }
        Ok(cfg)
    }

    /// Makes the relative file paths of the config relative to `base` (its folder).
    fn resolve_paths(&mut self, base: &Path, origin: &Path) {
        let resolve = |key: &str, p: &mut PathBuf| {
            if p.is_absolute() {
                return;
            }
            let beside = base.join(&*p);
            if beside.exists() {
                *p = beside;
            } else if p.exists() {
                tracing::warn!(
                    "{}: {key} = {} is found from the current directory, not from the config's folder {}; write it relative to the config file",
                    origin.display(),
                    p.display(),
                    base.display()
                );
            } else {
                // Missing either way: name the config-relative place in later errors.
                *p = beside;
            }
        };
        if let Some(c) = self.daemon.calibration.as_mut() {
            resolve("daemon.calibration", c);
        }
        if let Some(k) = self.daemon.signing_key.as_mut() {
            resolve("daemon.signing_key", k);
        }
        // The default (the lab model) is not the config's to place: it stays where the
        // program finds it.
        if self.motion.dmmn_model != Path::new(infotrack_core::motion::DEFAULT_MODEL_PATH) {
            resolve("motion.dmmn_model", &mut self.motion.dmmn_model);
        }
        if let Some(l) = self.motion.onnxruntime_library.as_mut() {
            resolve("motion.onnxruntime_library", l);
        }
        if let Some(t) = self.target.trajectory.as_mut() {
            for f in t.files_mut() {
                resolve("target.trajectory", f);
            }
        }
    }

    /// The recorded tracks of `target.trajectory`, read and checked (none: the simulated
    /// car).
    pub fn recorded_tracks(
        &self,
    ) -> Result<Vec<std::sync::Arc<crate::recorded_track::RecordedTrack>>, ConfigError> {
        use crate::recorded_track::{load, TrackFrame};
        let Some(t) = &self.target.trajectory else {
            return Ok(Vec::new());
        };
        let frame = TrackFrame {
            origin: self.world.as_ref().map(|w| &w.origin),
            workspace: &self.workspace_enu,
            vehicle: self.target.trajectory_vehicle.as_deref(),
        };
        t.files()
            .into_iter()
            .map(|f| {
                load(f, &frame)
                    .map(std::sync::Arc::new)
                    .map_err(|e| ConfigError::Invalid {
                        key: "target.trajectory".into(),
                        value: f.display().to_string(),
                        reason: e.to_string(),
                    })
            })
            .collect()
    }

    /// Parses and validates TOML text; `origin` names the source in error messages.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Self, ConfigError> {
        let parse_error = |e: toml::de::Error| ConfigError::Parse {
            path: origin.to_path_buf(),
            message: e.to_string(),
        };
        let table: toml::Table = toml::from_str(text).map_err(parse_error)?;
        let has_world_file = table.get("world").and_then(|w| w.get("geojson")).is_some();
        let cfg: Config = if has_world_file {
            let mut table = table;
            let base = origin.parent().unwrap_or(Path::new("."));
            world_file::merge_world_file(&mut table, base, origin)?;
            Config::deserialize(toml::Value::Table(table)).map_err(parse_error)?
        } else {
            // From the text, so that errors name the line.
            toml::from_str(text).map_err(parse_error)?
        };
        cfg.validate()?;
        Ok(cfg)
    }

    /// The embedded default (the paper's lab scenario).
    pub fn default_lab() -> Self {
        Self::from_toml_str(DEFAULT_TOML, Path::new("<embedded config/default.toml>"))
            .expect("the embedded default config is valid (checked by a unit test)")
    }

    /// The start-point gate: distance (m) and speed (m/s) below which tracking begins.
    pub fn start_tolerance_m(&self) -> f64 {
        self.daemon
            .start_tolerance_m
            .unwrap_or((0.01 * self.agent.altitude_m).max(0.05))
    }

    /// Filter period dt = 1 / filter_hz, seconds.
    pub fn filter_dt_s(&self) -> f64 {
        1.0 / self.timing.filter_hz
    }

    /// Validates ranges and cross-references; the error names the key and the value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        validate::validate(self)
    }
}

#[cfg(test)]
mod tests;

/// Reads a file a config names (the config itself, a world): a regular file up to `limit`
/// bytes of UTF-8, else an error naming it.
pub(crate) fn read_user_file(path: &Path, limit: u64) -> Result<String, ConfigError> {
    use infotrack_files::{read_text, BoundedReadError};
    read_text(path, limit).map_err(|e| match e {
        BoundedReadError::Io(source) => ConfigError::Io {
            path: path.to_path_buf(),
            source,
        },
        source => ConfigError::File {
            path: path.to_path_buf(),
            source,
        },
    })
}

impl From<infotrack_core::check::InvalidValue> for ConfigError {
    fn from(e: infotrack_core::check::InvalidValue) -> Self {
        ConfigError::Invalid {
            key: e.key,
            value: e.value,
            reason: e.reason,
        }
    }
}
