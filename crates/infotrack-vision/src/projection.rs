//! From a detected tag to the measurement z_k the particle filter consumes: the ground point
//! under the tag's centre in world ENU, with a covariance propagated from pixel noise,
//! attitude and altitude uncertainty through the same ray-ground intersection.

use crate::InvalidSetting;
use serde::{Deserialize, Serialize};

use super::camera_model::{CameraModel, GroundEnu, VehiclePoseNed};
use super::detector::TagDetection;

/// Uncertainties that make up a measurement's covariance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProjectionNoise {
    /// Tag centre pixel noise (one sigma), px.
    pub pixel_sigma_px: f64,
    /// Roll and pitch uncertainty (one sigma), rad.
    pub tilt_sigma_rad: f64,
    /// Yaw uncertainty (one sigma), rad.
    pub yaw_sigma_rad: f64,
    /// Altitude uncertainty (one sigma), m.
    pub altitude_sigma_m: f64,
}

impl Default for ProjectionNoise {
    fn default() -> Self {
        Self {
            pixel_sigma_px: 0.5,
            tilt_sigma_rad: 0.01,
            yaw_sigma_rad: 0.02,
            altitude_sigma_m: 0.05,
        }
    }
}

impl ProjectionNoise {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        self.reason_invalid()
    }

    fn reason_invalid(&self) -> Result<(), InvalidSetting> {
        for (k, v) in [
            ("pixel_sigma_px", self.pixel_sigma_px),
            ("tilt_sigma_rad", self.tilt_sigma_rad),
            ("yaw_sigma_rad", self.yaw_sigma_rad),
            ("altitude_sigma_m", self.altitude_sigma_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(InvalidSetting(format!("{k} = {v} must be finite and >= 0")));
            }
        }
        if self.pixel_sigma_px == 0.0 {
            return Err(InvalidSetting(
                "pixel_sigma_px must be > 0 (a measurement is never exact)".into(),
            ));
        }
        Ok(())
    }
}

/// A target measurement in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GroundMeasurement {
    /// Target position, world ENU, m.
    pub position_enu_m: GroundEnu,
    /// Its covariance, world ENU, m^2.
    pub covariance_enu_m2: [[f64; 2]; 2],
}

/// Projects a pixel to the ground and propagates the uncertainties (numerical Jacobians of
/// the ray-ground intersection with respect to u, v, roll, pitch, yaw and altitude).
pub fn project_pixel(
    cam: &CameraModel,
    pose: &VehiclePoseNed,
    pixel: [f64; 2],
    noise: &ProjectionNoise,
) -> Option<GroundMeasurement> {
    let g0 = cam.pixel_to_ground_enu(pixel[0], pixel[1], pose)?;
    let mut cov = [[0.0; 2]; 2];
    let mut add = |g: Option<GroundEnu>, step: f64, sigma: f64| {
        if let Some(g) = g {
            let j = [(g[0] - g0[0]) / step, (g[1] - g0[1]) / step];
            for (a, ja) in j.iter().enumerate() {
                for (b, jb) in j.iter().enumerate() {
                    cov[a][b] += ja * jb * sigma * sigma;
                }
            }
        }
    };
    let (du, da, dz) = (0.25, 1e-5, 1e-3);
    let [u, v] = pixel;
    add(
        cam.pixel_to_ground_enu(u + du, v, pose),
        du,
        noise.pixel_sigma_px,
    );
    add(
        cam.pixel_to_ground_enu(u, v + du, pose),
        du,
        noise.pixel_sigma_px,
    );
    // Each pose uncertainty in turn: (perturbation, step, sigma).
    type Perturb = fn(&mut VehiclePoseNed, f64);
    let pose_terms: [(Perturb, f64, f64); 4] = [
        (|p, d| p.roll_rad += d, da, noise.tilt_sigma_rad),
        (|p, d| p.pitch_rad += d, da, noise.tilt_sigma_rad),
        (|p, d| p.yaw_rad += d, da, noise.yaw_sigma_rad),
        (|p, d| p.position_ned_m[2] -= d, dz, noise.altitude_sigma_m),
    ];
    for (perturb, step, sigma) in pose_terms {
        let mut p = *pose;
        perturb(&mut p, step);
        add(cam.pixel_to_ground_enu(u, v, &p), step, sigma);
    }
    Some(GroundMeasurement {
        position_enu_m: g0,
        covariance_enu_m2: cov,
    })
}

/// The measurement of a detected tag: its centre projected to the ground. (A tag lies flat
/// on the target; its centre is the target's reference point.)
pub fn measure_tag(
    cam: &CameraModel,
    pose: &VehiclePoseNed,
    det: &TagDetection,
    noise: &ProjectionNoise,
) -> Option<GroundMeasurement> {
    project_pixel(cam, pose, det.center_px, noise)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera_model::{CameraMount, Intrinsics};

    #[test]
    fn covariance_grows_with_altitude_and_tilt() {
        let cam = CameraModel {
            intrinsics: Intrinsics::ideal(640, 480, 1.0),
            mount: CameraMount::nadir(),
        };
        let noise = ProjectionNoise::default();
        let at = |alt: f64, roll: f64| {
            let pose = VehiclePoseNed {
                position_ned_m: [0.0, 0.0, -alt],
                roll_rad: roll,
                pitch_rad: 0.0,
                yaw_rad: 0.0,
            };
            project_pixel(&cam, &pose, [319.5, 239.5], &noise).unwrap()
        };
        let low = at(1.2, 0.0);
        let high = at(60.0, 0.0);
        let tilted = at(60.0, 0.3);
        assert!(low.position_enu_m[0].abs() < 1e-9);
        let tr = |m: &GroundMeasurement| m.covariance_enu_m2[0][0] + m.covariance_enu_m2[1][1];
        assert!(tr(&high) > 100.0 * tr(&low));
        assert!(tr(&tilted) > tr(&high));
        // Symmetric and positive definite.
        let c = tilted.covariance_enu_m2;
        assert!((c[0][1] - c[1][0]).abs() < 1e-12);
        assert!(c[0][0] > 0.0 && c[0][0] * c[1][1] - c[0][1] * c[1][0] > 0.0);
        // Pixel noise alone at nadir: sigma_ground = sigma_px * altitude / f.
        let quiet = ProjectionNoise {
            pixel_sigma_px: 1.0,
            tilt_sigma_rad: 0.0,
            yaw_sigma_rad: 0.0,
            altitude_sigma_m: 0.0,
        };
        let pose = VehiclePoseNed {
            position_ned_m: [0.0, 0.0, -10.0],
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: 0.0,
        };
        let m = project_pixel(&cam, &pose, [319.5, 239.5], &quiet).unwrap();
        let want = 10.0 / cam.intrinsics.fx_px;
        assert!((m.covariance_enu_m2[0][0].sqrt() - want).abs() < 1e-6 * want.max(1.0));
    }

    #[test]
    fn noise_settings_are_checked() {
        assert!(ProjectionNoise::default().validate().is_ok());
        let bad = ProjectionNoise {
            pixel_sigma_px: f64::NAN,
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().0.contains("pixel_sigma_px"));
    }
}
