//! The world's tables of a configuration: occlusions, the camera's field of view, the
//! measurement noise.

use serde::{Deserialize, Serialize};

use crate::check::{covariance, invalid, Checked};
use crate::world::geometry::{BoundsEnu, Enu2, PolygonEnu};

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

impl BoundsEnu {
    /// Checks the table `workspace_enu` (the geofence): finite, with a positive extent.
    pub fn check_workspace(&self) -> Checked {
        for (k, v) in [
            ("workspace_enu.x_min_m", self.x_min_m),
            ("workspace_enu.x_max_m", self.x_max_m),
            ("workspace_enu.y_min_m", self.y_min_m),
            ("workspace_enu.y_max_m", self.y_max_m),
        ] {
            if !v.is_finite() {
                return Err(invalid(k, v, "must be finite"));
            }
        }
        if self.x_max_m <= self.x_min_m {
            return Err(invalid(
                "workspace_enu.x_max_m",
                self.x_max_m,
                "must be greater than workspace_enu.x_min_m",
            ));
        }
        if self.y_max_m <= self.y_min_m {
            return Err(invalid(
                "workspace_enu.y_max_m",
                self.y_max_m,
                "must be greater than workspace_enu.y_min_m",
            ));
        }
        Ok(())
    }
}

impl OcclusionConfig {
    /// Checks `occlusions[index]`: a polygon of at least three finite vertices, all inside
    /// the workspace `ws`, with an area.
    pub fn check(&self, index: usize, ws: &BoundsEnu) -> Checked {
        let key = format!("occlusions[{index}].vertices_enu_m");
        let verts: Vec<Enu2> = self
            .vertices_enu_m
            .iter()
            .map(|v| Enu2::new(v[0], v[1]))
            .collect();
        let poly = PolygonEnu::new(verts.clone()).ok_or_else(|| {
            invalid(
                &key,
                &self.vertices_enu_m,
                "an occlusion needs at least three finite vertices",
            )
        })?;
        if let Some(v) = verts.iter().find(|v| !ws.contains(v)) {
            return Err(invalid(
                &key,
                [v.x, v.y],
                "vertex lies outside the workspace (workspace_enu)",
            ));
        }
        if poly.area_m2() <= 0.0 {
            return Err(invalid(&key, &self.vertices_enu_m, "polygon has zero area"));
        }
        Ok(())
    }
}

impl CameraConfig {
    /// Checks `camera`: both fields of view in (0, pi), and a footprint at `altitude_m`
    /// (`agent.altitude_m`) smaller than the workspace `ws`, or there is nothing to search.
    pub fn check(&self, ws: &BoundsEnu, altitude_m: f64) -> Checked {
        for (k, v) in [
            ("camera.fov_x_rad", self.fov_x_rad),
            ("camera.fov_y_rad", self.fov_y_rad),
        ] {
            if !(v.is_finite() && v > 0.0 && v < std::f64::consts::PI) {
                return Err(invalid(k, v, "must lie in (0, pi) radians"));
            }
        }
        let fp_w = 2.0 * altitude_m * (0.5 * self.fov_x_rad).tan();
        let fp_h = 2.0 * altitude_m * (0.5 * self.fov_y_rad).tan();
        if fp_w >= ws.width_m() || fp_h >= ws.height_m() {
            return Err(invalid(
                "camera.fov_x_rad",
                self.fov_x_rad,
                &format!(
                    "camera footprint {fp_w:.2} m x {fp_h:.2} m at agent.altitude_m = {altitude_m} \
                     is not smaller than the workspace {:.2} m x {:.2} m: there would be nothing \
                     to search",
                    ws.width_m(),
                    ws.height_m()
                ),
            ));
        }
        Ok(())
    }
}

impl MeasurementConfig {
    /// Checks `measurement`: the noise is a covariance.
    pub fn check(&self) -> Checked {
        covariance("measurement.noise_cov_m2", &self.noise_cov_m2)
    }
}
