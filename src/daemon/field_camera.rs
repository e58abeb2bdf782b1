//! A real camera in the daemon: frames from capture, each projected with the vehicle's pose
//! at its capture time.

use std::time::Duration;

use super::pipeline::{PipelineError, Shared};
use crate::config::Config;
use crate::tracker::Prior;
#[cfg(feature = "opencv")]
use crate::vision::camera_model::CameraMount;
use crate::vision::camera_model::{CameraModel, VehiclePoseNed};
#[cfg(feature = "opencv")]
use crate::vision::capture::{Camera, CaptureConfig};
use crate::vision::detector::{AprilTagDetector, RoiPx, RoiSearch};
use crate::vision::projection::{measure_tag, ProjectionNoise};
use crate::vision::VisionStats;
use crate::world::geometry::Enu2;

/// A build without OpenCV has no capture: a camera that cannot be made.
#[cfg(not(feature = "opencv"))]
enum Camera {}

#[cfg(not(feature = "opencv"))]
impl Camera {
    fn latest(&mut self) -> Option<crate::vision::image::Frame> {
        match *self {}
    }
}

/// A real camera: frames from capture, projected with the pose at their capture time.
pub(super) struct FieldCamera {
    camera: Camera,
    model: CameraModel,
    search: RoiSearch<AprilTagDetector>,
    noise: ProjectionNoise,
    tag_ids: Vec<u32>,
    tag_size_m: f64,
    /// The newest frame searched (for a visual record).
    last_image: Option<crate::vision::image::GrayImage>,
}

impl FieldCamera {
    /// The newest frame searched, if any.
    pub(super) fn last_image(&self) -> Option<&crate::vision::image::GrayImage> {
        self.last_image.as_ref()
    }

    /// Without OpenCV there is no capture and no calibration file reader: a real camera is
    /// refused, naming it and why.
    #[cfg(not(feature = "opencv"))]
    pub(super) fn open(cfg: &Config) -> Result<Self, PipelineError> {
        Err(crate::vision::VisionError::Camera {
            camera: cfg.daemon.camera.clone(),
            message: "this infotrack was built without OpenCV (its `opencv` feature), which \
                      a real camera needs; it flies the synthetic camera only"
                .into(),
        }
        .into())
    }

    #[cfg(feature = "opencv")]
    pub(super) fn open(cfg: &Config) -> Result<Self, PipelineError> {
        let d = &cfg.daemon;
        let calib = d
            .calibration
            .as_deref()
            .ok_or(PipelineError::NoCalibration)?;
        let intrinsics = crate::vision::cv_io::load_calibration(calib)?;
        let [r, p, y] = d.camera_mount_rpy_rad;
        let camera = Camera::open(CaptureConfig {
            source: d.camera.clone(),
            width_px: intrinsics.width_px,
            height_px: intrinsics.height_px,
            fps: d.camera_fps,
            timeout_s: d.camera_timeout_s,
        })?;
        Ok(Self {
            camera,
            model: CameraModel {
                intrinsics,
                mount: CameraMount::from_angles(r, p, y, d.camera_offset_body_frd_m),
            },
            search: RoiSearch::new(AprilTagDetector::new(cfg.vision.detector.clone())?)
                .with_max_full_frame_decimation(cfg.vision.detector.max_full_frame_decimation),
            noise: cfg.vision.projection.clone(),
            tag_ids: vec![cfg.vision.tag_id],
            tag_size_m: cfg.vision.tag_size_m,
            last_image: None,
        })
    }

    /// The newest frame, if one came: its pose (at capture time) and the measurement.
    pub(super) fn look(
        &mut self,
        shared: &Shared,
        prior: &Prior,
        stats: &mut VisionStats,
    ) -> Option<(VehiclePoseNed, Option<Enu2>)> {
        let frame = self.camera.latest()?;
        stats.frames += 1;
        let pose = shared.poses.lock().at(
            // Capture stamps come from the capture thread on the wall clock, which is the
            // runtime's clock whenever a real camera flies.
            tokio::time::Instant::from_std(frame.captured_at),
            Duration::from_millis(100),
        );
        let Some(pose) = pose else {
            tracing::warn!(
                "frame {}: no vehicle pose at its capture time; skipped",
                frame.index
            );
            return None;
        };
        let i = &self.model.intrinsics;
        if (frame.image.width, frame.image.height) != (i.width_px as usize, i.height_px as usize) {
            tracing::error!(
                "frame {} is {}x{} px but the calibration is for {}x{} px; skipped",
                frame.index,
                frame.image.width,
                frame.image.height,
                i.width_px,
                i.height_px
            );
            return None;
        }
        let alt = pose.altitude_m().max(0.1);
        let side_px = self.tag_size_m * i.fx_px / alt;
        let roi = self
            .model
            .world_enu_to_pixel([prior.mean_enu.x, prior.mean_enu.y], 0.0, &pose)
            .filter(|px| self.model.in_image(*px))
            .map(|px| {
                let sigma_m = prior.cov_m2.symmetric_eigenvalues().max().max(0.0).sqrt();
                RoiPx::around(px, side_px, sigma_m * i.fx_px / alt)
            });
        let z = match self
            .search
            .detect(&frame.image, roi, &self.tag_ids, Some(side_px))
        {
            Ok((dets, how)) => dets.first().and_then(|d| {
                stats.detections += 1;
                if how == crate::vision::detector::SearchOutcome::Roi {
                    stats.roi_hits += 1;
                }
                measure_tag(&self.model, &pose, d, &self.noise)
                    .map(|m| Enu2::new(m.position_enu_m[0], m.position_enu_m[1]))
            }),
            Err(e) => {
                tracing::warn!("frame {}: {e}", frame.index);
                None
            }
        };
        self.last_image = Some(frame.image);
        Some((pose, z))
    }
}
