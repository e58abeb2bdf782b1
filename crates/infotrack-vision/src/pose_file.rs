//! The camera pose file of `infotrack detect --pose`: which calibration, where the vehicle
//! was, and how the camera is mounted, in TOML.
//!
//! ```toml
//! calibration = "camera.yaml"          # OpenCV calibration file, relative to this file
//! [pose]                                # the vehicle, local NED
//! position_ned_m = [0.0, 0.0, -10.0]
//! roll_rad = 0.0
//! pitch_rad = 0.0
//! yaw_rad = 0.0
//! [mount]                               # optional: tilt from nadir, body FRD
//! roll_rad = 0.0
//! pitch_rad = 0.0
//! yaw_rad = 0.0
//! offset_body_frd_m = [0.0, 0.0, 0.0]
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::camera_model::{CameraModel, CameraMount, VehiclePoseNed};
use super::cv_io::load_calibration;
use super::VisionError;

/// The camera's mount as written in a file: angles from the nadir mount.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MountFile {
    /// Extra roll, rad (body FRD).
    #[serde(default)]
    pub roll_rad: f64,
    /// Extra pitch, rad.
    #[serde(default)]
    pub pitch_rad: f64,
    /// Extra yaw, rad.
    #[serde(default)]
    pub yaw_rad: f64,
    /// Camera centre in body FRD, m.
    #[serde(default)]
    pub offset_body_frd_m: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseFile {
    calibration: PathBuf,
    pose: VehiclePoseNed,
    #[serde(default)]
    mount: MountFile,
}

/// Reads a pose file: the camera model and the vehicle pose.
pub fn load(path: &Path) -> Result<(CameraModel, VehiclePoseNed), VisionError> {
    let name = path.display().to_string();
    let text = infotrack_files::read_text(path, 1 << 20).map_err(|e| VisionError::Io {
        path: name.clone(),
        message: e.to_string(),
    })?;
    let f: PoseFile = toml::from_str(&text).map_err(|e| VisionError::Io {
        path: name.clone(),
        message: e.to_string(),
    })?;
    let p = &f.pose;
    let finite = p.position_ned_m.iter().all(|v| v.is_finite())
        && [p.roll_rad, p.pitch_rad, p.yaw_rad]
            .iter()
            .all(|v| v.is_finite());
    if !finite || p.altitude_m() <= 0.0 {
        return Err(VisionError::Io {
            path: name,
            message: "pose: position and angles must be finite, with the camera above the ground (position_ned_m[2] < 0)".into(),
        });
    }
    let calib = if f.calibration.is_relative() {
        path.parent().unwrap_or(Path::new(".")).join(&f.calibration)
    } else {
        f.calibration.clone()
    };
    let m = &f.mount;
    Ok((
        CameraModel {
            intrinsics: load_calibration(&calib)?,
            mount: CameraMount::from_angles(
                m.roll_rad,
                m.pitch_rad,
                m.yaw_rad,
                m.offset_body_frd_m,
            ),
        },
        f.pose,
    ))
}
