//! Measuring the target with the drone's own downward camera: capture (OpenCV), AprilTag
//! detection with a region-of-interest search, pixel-to-ground projection with a
//! covariance, and a synthetic camera that renders what the camera would see so that the
//! simulator can run the whole loop through the real detector.
//!
//! The geometry (`camera_model`, `projection`), the detector and the capture settings are
//! pure Rust and the AprilTag C library; OpenCV is confined to `cv_io`, `capture`,
//! `calibration` and `pose_file`, behind the default feature `opencv`. A build without it
//! (for a board whose OpenCV is not at hand: the arm64 cross build) still detects tags in
//! rendered frames and flies the simulator; a real camera and calibration need it.
#![deny(missing_docs)]

#[cfg(feature = "opencv")]
pub mod calibration;
pub mod camera_model;
#[cfg(feature = "opencv")]
pub mod capture;
pub mod capture_source;
#[cfg(feature = "opencv")]
pub mod cv_io;

pub mod detector;
pub mod image;
#[cfg(feature = "opencv")]
pub mod pose_file;
pub mod projection;
pub mod tag_family;

use thiserror::Error;

/// A setting out of range, with what is wrong (the caller names the key).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{0}")]
pub struct InvalidSetting(pub String);

impl From<InvalidSetting> for VisionError {
    fn from(e: InvalidSetting) -> Self {
        Self::Config(e.0)
    }
}

/// Why a vision operation failed.
#[derive(Debug, Error)]
pub enum VisionError {
    /// A setting is out of range.
    #[error("vision config: {0}")]
    Config(String),
    /// A frame with no pixels.
    #[error("zero-size frame ({width}x{height} px)")]
    EmptyFrame {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
    /// A file could not be read or written.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        message: String,
    },
    /// A file is not a usable image.
    #[error("{path}: corrupt image: {message}")]
    Corrupt {
        /// The file.
        path: String,
        /// Why.
        message: String,
    },
    /// The calibration file is missing or incomplete.
    #[error("camera calibration {path}: {message}")]
    Calibration {
        /// The file.
        path: String,
        /// Why.
        message: String,
    },
    /// The camera could not be opened.
    #[error("camera `{camera}`: {message}")]
    Camera {
        /// The configured source.
        camera: String,
        /// Why.
        message: String,
    },
    /// The camera delivered nothing in time.
    #[error("camera `{camera}` delivered no frame for {seconds} s")]
    CameraStalled {
        /// The configured source.
        camera: String,
        /// The timeout.
        seconds: f64,
    },
    /// The detector library failed.
    #[error("tag detector: {0}")]
    Detector(String),
    /// An OpenCV call failed.
    #[error("OpenCV: {0}")]
    OpenCv(String),
}

/// Counts of how a camera's frames went (rendered or captured), for reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VisionStats {
    /// Frames looked at.
    pub frames: u64,
    /// Frames with the target's tag found.
    pub detections: u64,
    /// Of those, found in the region of interest.
    pub roi_hits: u64,
}
