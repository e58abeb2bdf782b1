//! Where a camera's frames come from and how it is asked for them: parsed and checked
//! without OpenCV, so that a configuration is validated by a build without it too.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::{InvalidSetting, VisionError};

/// Where frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum CaptureSource {
    /// A V4L2 device by index (`/dev/videoN`).
    DeviceIndex(i32),
    /// A V4L2 device by path.
    DevicePath(PathBuf),
    /// A GStreamer pipeline ending in `appsink`.
    Gstreamer(String),
    /// A video file, or an image sequence given as a printf pattern (`frames/%04d.png`).
    File(PathBuf),
}

impl CaptureSource {
    /// Parses `v4l2:0`, `/dev/video0`, `gst:PIPELINE`, or a file path / image pattern.
    pub fn parse(s: &str) -> Result<Self, VisionError> {
        let s = s.trim();
        if s.is_empty() {
            return Err(VisionError::Config("camera source is empty".into()));
        }
        if let Some(rest) = s.strip_prefix("v4l2:") {
            return rest.parse().map(Self::DeviceIndex).map_err(|_| {
                VisionError::Config(format!("`{s}`: expected v4l2:INDEX, e.g. v4l2:0"))
            });
        }
        if let Some(rest) = s.strip_prefix("gst:") {
            if !rest.contains("appsink") {
                return Err(VisionError::Config(format!(
                    "`{s}`: a GStreamer pipeline must end in appsink"
                )));
            }
            return Ok(Self::Gstreamer(rest.to_string()));
        }
        if s.starts_with("/dev/video") {
            return Ok(Self::DevicePath(s.into()));
        }
        Ok(Self::File(s.into()))
    }

    /// A live camera (not a file): it may stall, and is reopened when it does.
    pub fn is_live(&self) -> bool {
        !matches!(self, Self::File(_))
    }
}

/// Camera settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureConfig {
    /// `v4l2:0`, `/dev/video0`, `gst:... ! appsink`, a video file, or `dir/%04d.png`.
    pub source: String,
    /// Requested width, px (0: the camera's default).
    pub width_px: u32,
    /// Requested height, px (0: the camera's default).
    pub height_px: u32,
    /// Requested frame rate, Hz (0: the camera's default).
    pub fps: f64,
    /// A live camera that delivers nothing for this long is reported and reopened, s.
    pub timeout_s: f64,
}

impl CaptureConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        self.reason_invalid()
    }

    fn reason_invalid(&self) -> Result<(), InvalidSetting> {
        CaptureSource::parse(&self.source).map_err(|e| InvalidSetting(e.to_string()))?;
        if !(self.fps.is_finite() && self.fps >= 0.0) {
            return Err(InvalidSetting(format!("fps {} must be >= 0", self.fps)));
        }
        if !(self.timeout_s.is_finite() && self.timeout_s > 0.0) {
            return Err(InvalidSetting(format!(
                "timeout_s {} must be > 0",
                self.timeout_s
            )));
        }
        Ok(())
    }
}
