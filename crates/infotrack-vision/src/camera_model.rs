//! The camera as geometry: OpenCV's pinhole + Brown-Conrady distortion model, the camera's
//! mount on the vehicle, and the rays between pixels and the ground.
//!
//! Frames, each named where used:
//! * camera (OpenCV): x right, y down, z along the optical axis; pixel centres at integers;
//! * body FRD: x forward, y right, z down;
//! * local NED: the autopilot's LOCAL_POSITION_NED frame, origin on the ground;
//! * world ENU: the tracker's world, `x_east = y_ned`, `y_north = x_ned`.

use crate::InvalidSetting;
use nalgebra::{Matrix3, Rotation3, Vector3};

pub use infotrack_core::frames::VehiclePoseNed;
use infotrack_core::frames::{PositionEnu, PositionNed};
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics and distortion, as OpenCV's calibration writes them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Image width, px.
    pub width_px: u32,
    /// Image height, px.
    pub height_px: u32,
    /// Focal length along x, px.
    pub fx_px: f64,
    /// Focal length along y, px.
    pub fy_px: f64,
    /// Principal point x, px (OpenCV convention: pixel centres at integers).
    pub cx_px: f64,
    /// Principal point y, px.
    pub cy_px: f64,
    /// Distortion k1, k2, p1, p2, k3 (OpenCV's order).
    pub distortion: [f64; 5],
}

impl Intrinsics {
    /// An ideal camera (no distortion, centred principal point) with horizontal field of
    /// view `hfov_rad` and square pixels.
    pub fn ideal(width_px: u32, height_px: u32, hfov_rad: f64) -> Self {
        let f = width_px as f64 / 2.0 / (hfov_rad / 2.0).tan();
        Self {
            width_px,
            height_px,
            fx_px: f,
            fy_px: f,
            cx_px: (width_px as f64 - 1.0) / 2.0,
            cy_px: (height_px as f64 - 1.0) / 2.0,
            distortion: [0.0; 5],
        }
    }

    /// Checks that the numbers describe a camera.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        self.reason_invalid()
    }

    fn reason_invalid(&self) -> Result<(), InvalidSetting> {
        if self.width_px == 0 || self.height_px == 0 {
            return Err(InvalidSetting(format!(
                "image size {}x{} px is empty",
                self.width_px, self.height_px
            )));
        }
        for (name, v) in [
            ("fx", self.fx_px),
            ("fy", self.fy_px),
            ("cx", self.cx_px),
            ("cy", self.cy_px),
        ] {
            if !v.is_finite() {
                return Err(InvalidSetting(format!("{name} = {v} is not finite")));
            }
        }
        if self.fx_px <= 0.0 || self.fy_px <= 0.0 {
            return Err(InvalidSetting(format!(
                "focal lengths must be positive (fx = {}, fy = {})",
                self.fx_px, self.fy_px
            )));
        }
        if self.distortion.iter().any(|d| !d.is_finite()) {
            return Err(InvalidSetting(format!(
                "distortion {:?} is not finite",
                self.distortion
            )));
        }
        Ok(())
    }

    /// Whether the lens model bends straight lines (any distortion coefficient set).
    pub fn has_distortion(&self) -> bool {
        self.distortion.iter().any(|&d| d != 0.0)
    }

    /// Normalized undistorted image coordinates -> distorted normalized coordinates.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Camera-frame point -> pixel (OpenCV convention). `None` behind the camera.
    pub fn project(&self, p_cam: &Vector3<f64>) -> Option<[f64; 2]> {
        if p_cam.z <= 1e-9 {
            return None;
        }
        let (x, y) = self.distort(p_cam.x / p_cam.z, p_cam.y / p_cam.z);
        Some([self.fx_px * x + self.cx_px, self.fy_px * y + self.cy_px])
    }

    /// Pixel -> normalized undistorted coordinates (the ray `(x, y, 1)` in the camera
    /// frame), by the fixed-point iteration OpenCV's undistortPoints uses.
    pub fn unproject(&self, u: f64, v: f64) -> (f64, f64) {
        let xd = (u - self.cx_px) / self.fx_px;
        let yd = (v - self.cy_px) / self.fy_px;
        if !self.has_distortion() {
            return (xd, yd);
        }
        let [k1, k2, p1, p2, k3] = self.distortion;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..20 {
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            x = (xd - dx) / radial;
            y = (yd - dy) / radial;
        }
        (x, y)
    }

    /// The camera matrix K.
    pub fn k(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.fx_px, 0.0, self.cx_px, 0.0, self.fy_px, self.cy_px, 0.0, 0.0, 1.0,
        )
    }
}

/// Where the camera sits on the vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraMount {
    /// Rotation taking camera-frame vectors to body FRD.
    pub body_from_camera: Rotation3<f64>,
    /// Camera centre in body FRD, m.
    pub offset_body_frd_m: Vector3<f64>,
}

impl CameraMount {
    /// Looking straight down, the top of the image toward the vehicle's nose: camera x is
    /// body right, camera y is body backward, camera z is body down.
    pub fn nadir() -> Self {
        let m = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        Self {
            body_from_camera: Rotation3::from_matrix_unchecked(m),
            offset_body_frd_m: Vector3::zeros(),
        }
    }

    /// The nadir mount turned by extra roll, pitch, yaw (rad, body FRD, applied after the
    /// nadir rotation), with an offset.
    pub fn from_angles(roll: f64, pitch: f64, yaw: f64, offset_body_frd_m: [f64; 3]) -> Self {
        let tilt = Rotation3::from_euler_angles(roll, pitch, yaw);
        Self {
            body_from_camera: tilt * Self::nadir().body_from_camera,
            offset_body_frd_m: Vector3::from(offset_body_frd_m),
        }
    }
}

/// Intrinsics and mount together: the whole camera.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraModel {
    /// Lens and sensor.
    pub intrinsics: Intrinsics,
    /// Mount on the vehicle.
    pub mount: CameraMount,
}

/// A point on the ground, world ENU, m.
pub type GroundEnu = [f64; 2];

impl CameraModel {
    /// Camera centre (local NED) and rotation taking camera vectors to local NED.
    pub fn camera_in_ned(&self, pose: &VehiclePoseNed) -> (Vector3<f64>, Rotation3<f64>) {
        let r_nb = pose.ned_from_body();
        let c = Vector3::from(pose.position_ned_m) + r_nb * self.mount.offset_body_frd_m;
        (c, r_nb * self.mount.body_from_camera)
    }

    /// Where the ray through pixel (u, v) meets the ground `z_ned = 0`, world ENU. `None`
    /// when the ray points at or above the horizon.
    pub fn pixel_to_ground_enu(&self, u: f64, v: f64, pose: &VehiclePoseNed) -> Option<GroundEnu> {
        let (c, r_nc) = self.camera_in_ned(pose);
        let (x, y) = self.intrinsics.unproject(u, v);
        let d = r_nc * Vector3::new(x, y, 1.0);
        if d.z <= 1e-9 || c.z >= 0.0 {
            return None;
        }
        let t = -c.z / d.z;
        let g = c + t * d;
        let g = PositionNed {
            x_north_m: g.x,
            y_east_m: g.y,
            z_down_m: g.z,
        }
        .to_enu();
        Some([g.x_east_m, g.y_north_m])
    }

    /// The pixel at which a world ENU point at height `z_up_m` appears, if in front of the
    /// camera (it may fall outside the image).
    pub fn world_enu_to_pixel(
        &self,
        p_enu: [f64; 2],
        z_up_m: f64,
        pose: &VehiclePoseNed,
    ) -> Option<[f64; 2]> {
        let (c, r_nc) = self.camera_in_ned(pose);
        let n = PositionEnu {
            x_east_m: p_enu[0],
            y_north_m: p_enu[1],
            z_up_m,
        }
        .to_ned();
        let p_ned = Vector3::new(n.x_north_m, n.y_east_m, n.z_down_m);
        self.intrinsics.project(&(r_nc.inverse() * (p_ned - c)))
    }

    /// Whether a pixel lies inside the image (OpenCV convention: [-0.5, w - 0.5)).
    pub fn in_image(&self, px: [f64; 2]) -> bool {
        px[0] >= -0.5
            && px[1] >= -0.5
            && px[0] < self.intrinsics.width_px as f64 - 0.5
            && px[1] < self.intrinsics.height_px as f64 - 0.5
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(alt: f64, roll: f64, pitch: f64, yaw: f64) -> VehiclePoseNed {
        VehiclePoseNed {
            position_ned_m: [3.0, -2.0, -alt],
            roll_rad: roll,
            pitch_rad: pitch,
            yaw_rad: yaw,
        }
    }

    #[test]
    fn nadir_camera_sees_north_at_the_top_when_yaw_is_zero() {
        let cam = CameraModel {
            intrinsics: Intrinsics::ideal(640, 480, 1.0),
            mount: CameraMount::nadir(),
        };
        let p = pose(10.0, 0.0, 0.0, 0.0);
        // The image centre is straight below: NED (3, -2) is ENU (-2, 3).
        let g = cam.pixel_to_ground_enu(319.5, 239.5, &p).unwrap();
        assert!(
            (g[0] + 2.0).abs() < 1e-9 && (g[1] - 3.0).abs() < 1e-9,
            "{g:?}"
        );
        // Up in the image (smaller v) is north (the nose), right is east.
        let up = cam.pixel_to_ground_enu(319.5, 100.0, &p).unwrap();
        assert!(up[1] > 3.5 && (up[0] + 2.0).abs() < 1e-9, "{up:?}");
        let right = cam.pixel_to_ground_enu(500.0, 239.5, &p).unwrap();
        assert!(
            right[0] > -1.5 && (right[1] - 3.0).abs() < 1e-9,
            "{right:?}"
        );
        // Yawed to the east (pi/2): the top of the image is east.
        let p_e = pose(10.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let up_e = cam.pixel_to_ground_enu(319.5, 100.0, &p_e).unwrap();
        assert!(up_e[0] > -1.5 && (up_e[1] - 3.0).abs() < 1e-9, "{up_e:?}");
    }

    #[test]
    fn pixel_ground_pixel_round_trip_with_distortion_tilt_and_offset() {
        let mut intr = Intrinsics::ideal(1280, 720, 1.2);
        intr.distortion = [-0.28, 0.09, 0.0008, -0.0005, -0.012];
        intr.cx_px += 7.3;
        intr.cy_px -= 4.1;
        let cam = CameraModel {
            intrinsics: intr,
            mount: CameraMount::from_angles(0.05, -0.1, 0.02, [0.1, 0.0, 0.05]),
        };
        for &(alt, roll, pitch, yaw) in &[
            (1.2, 0.0, 0.0, 0.0),
            (10.0, 0.3, -0.2, 2.0),
            (60.0, -0.35, 0.35, -2.9),
        ] {
            let p = pose(alt, roll, pitch, yaw);
            for &(u, v) in &[(10.0, 10.0), (640.0, 360.0), (1200.0, 700.0), (77.7, 650.2)] {
                let g = cam.pixel_to_ground_enu(u, v, &p).unwrap();
                let back = cam.world_enu_to_pixel(g, 0.0, &p).unwrap();
                assert!(
                    (back[0] - u).abs() < 1e-6 && (back[1] - v).abs() < 1e-6,
                    "{u},{v} -> {g:?} -> {back:?}"
                );
            }
        }
    }

    #[test]
    fn undistortion_inverts_distortion() {
        let mut intr = Intrinsics::ideal(640, 480, 1.0);
        intr.distortion = [-0.3, 0.1, 0.001, 0.002, -0.02];
        for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.45, 0.33)] {
            let (xd, yd) = intr.distort(x, y);
            let (xu, yu) =
                intr.unproject(intr.fx_px * xd + intr.cx_px, intr.fy_px * yd + intr.cy_px);
            assert!((xu - x).abs() < 1e-9 && (yu - y).abs() < 1e-9);
        }
    }

    #[test]
    fn bad_intrinsics_are_refused() {
        let mut i = Intrinsics::ideal(640, 480, 1.0);
        i.fx_px = -1.0;
        assert!(i.validate().unwrap_err().0.contains("positive"));
        let mut i = Intrinsics::ideal(640, 480, 1.0);
        i.width_px = 0;
        assert!(i.validate().unwrap_err().0.contains("empty"));
        assert!(Intrinsics::ideal(640, 480, 1.0).validate().is_ok());
    }
}
