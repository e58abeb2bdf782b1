//! The world's tables of a configuration: occlusions, the camera's field of view, the
//! measurement noise.

use serde::{Deserialize, Serialize};

/// One occlusion region.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcclusionConfig {
    /// Optional label (a building, a tree line).
    #[serde(default)]
    pub name: String,
    /// Polygon vertices `[x, y]` in the world ENU frame, metres, at least three.
    pub vertices_enu_m: Vec<[f64; 2]>,
}

/// The downward-looking camera.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    /// Full horizontal field of view, radians (footprint width = 2 h tan(fov_x / 2)).
    pub fov_x_rad: f64,
    /// Full vertical field of view, radians.
    pub fov_y_rad: f64,
}

/// The measurement model z = x + N(0, R).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementConfig {
    /// Measurement noise covariance R (2x2, row-major), square metres.
    pub noise_cov_m2: [[f64; 2]; 2],
}
