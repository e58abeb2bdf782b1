//! The simulator's camera in vision mode: each filter step renders what the drone's camera
//! sees, runs the real detector (searching around the filter's prediction first) and
//! projects the tag to the ground, in place of the analytic measurement model.
//!
//! The simulated agent flies level (no attitude model in the core simulator), so frames are
//! rendered at zero roll and pitch with the nose north; the vision tests cover tilted views.

use crate::render::{RenderOptions, RenderedFrame, SceneEnu, TargetAppearance};
use infotrack_config::Config;
use infotrack_core::frames::yaw_enu_to_ned;
use infotrack_core::world::camera::View;
use infotrack_core::world::geometry::{Enu2, PolygonEnu};
use infotrack_vision::camera_model::{CameraModel, CameraMount, Intrinsics, VehiclePoseNed};
use infotrack_vision::detector::{AprilTagDetector, RoiPx, RoiSearch, SearchOutcome};
use infotrack_vision::projection::{measure_tag, ProjectionNoise};
use infotrack_vision::tag_family::TagBitmap;
use infotrack_vision::VisionError;

pub use infotrack_vision::VisionStats;

/// Renders, detects and projects.
pub struct VisionSensor {
    cam: CameraModel,
    search: RoiSearch<AprilTagDetector>,
    opts: RenderOptions,
    noise: ProjectionNoise,
    tag: TagBitmap,
    tag_size_m: f64,
    occluders: Vec<PolygonEnu>,
    altitude_m: f64,
    /// What happened so far.
    pub stats: VisionStats,
    /// Time the last frame took to render (the camera's part, not the pipeline's), ms.
    pub last_render_ms: f64,
}

impl VisionSensor {
    /// The sensor the configuration describes.
    pub fn from_config(cfg: &Config) -> Result<Self, VisionError> {
        let v = &cfg.vision;
        let w = v.image_width_px;
        let ratio = (cfg.camera.fov_y_rad / 2.0).tan() / (cfg.camera.fov_x_rad / 2.0).tan();
        let h = ((w as f64 * ratio).round() as u32).max(16);
        let cam = CameraModel {
            intrinsics: Intrinsics::ideal(w, h, cfg.camera.fov_x_rad),
            mount: CameraMount::nadir(),
        };
        let occluders = cfg
            .occlusions
            .iter()
            .filter_map(|o| {
                PolygonEnu::new(
                    o.vertices_enu_m
                        .iter()
                        .map(|p| Enu2::new(p[0], p[1]))
                        .collect(),
                )
            })
            .collect();
        Ok(Self {
            cam,
            search: RoiSearch::new(AprilTagDetector::new(v.detector.clone())?)
                .with_max_full_frame_decimation(v.detector.max_full_frame_decimation),
            opts: RenderOptions {
                supersample: v.supersample,
                gain: 1.0,
                offset: 0.0,
                blur_sigma_px: v.blur_sigma_px,
                noise_sigma: v.noise_sigma,
            },
            noise: v.projection.clone(),
            tag: TagBitmap::tag36h11(v.tag_id)?,
            tag_size_m: v.tag_size_m,
            occluders,
            altitude_m: cfg.agent.altitude_m,
            stats: VisionStats::default(),
            last_render_ms: 0.0,
        })
    }

    /// The camera.
    pub fn camera(&self) -> &CameraModel {
        &self.cam
    }

    /// The camera's pose over `view` and the scene it sees with the target at `target_enu`.
    fn pose_and_scene(
        &self,
        view: &View,
        target_enu: &Enu2,
        target_heading_enu_rad: f64,
    ) -> (VehiclePoseNed, SceneEnu) {
        // The camera is mounted straight: the vehicle's nose is the image's top.
        let mut pose = VehiclePoseNed::level_above(&view.centre_enu, self.altitude_m);
        pose.yaw_rad = yaw_enu_to_ned(view.yaw_enu_rad);
        let scene = SceneEnu {
            target: Some(TargetAppearance {
                position_enu_m: [target_enu.x, target_enu.y],
                heading_enu_rad: target_heading_enu_rad,
                tag: self.tag.clone(),
                tag_size_m: self.tag_size_m,
            }),
            occluders: self.occluders.clone(),
            ground_seed: 17,
        };
        (pose, scene)
    }

    /// The whole frame [`Self::measure`] searches with the same arguments, every pixel
    /// rendered (for a visual record; the search renders only what it looks at).
    pub fn whole_frame(
        &self,
        view: &View,
        target_enu: &Enu2,
        target_heading_enu_rad: f64,
        frame_seed: u64,
    ) -> infotrack_vision::image::GrayImage {
        let (pose, scene) = self.pose_and_scene(view, target_enu, target_heading_enu_rad);
        crate::render::render(&self.cam, &pose, &scene, &self.opts, frame_seed)
    }

    /// One frame from `view`: the measured target position (world ENU), if the tag was found.
    /// `predicted` is the filter's prior (mean and covariance, world ENU): the detector
    /// searches around it first.
    pub fn measure(
        &mut self,
        view: &View,
        target_enu: &Enu2,
        target_heading_enu_rad: f64,
        predicted: Option<(Enu2, nalgebra::Matrix2<f64>)>,
        frame_seed: u64,
    ) -> Result<Option<Enu2>, VisionError> {
        let (pose, scene) = self.pose_and_scene(view, target_enu, target_heading_enu_rad);
        let mut frame = RenderedFrame::new(&self.cam, &pose, &scene, &self.opts, frame_seed);
        self.stats.frames += 1;
        let side_px = self.tag_size_m * self.cam.intrinsics.fx_px / self.altitude_m;
        let px_per_m = self.cam.intrinsics.fx_px / self.altitude_m;
        let roi = predicted.and_then(|(p, cov)| {
            let px = self.cam.world_enu_to_pixel([p.x, p.y], 0.0, &pose)?;
            let sigma_m = cov.symmetric_eigenvalues().max().max(0.0).sqrt();
            self.cam
                .in_image(px)
                .then(|| RoiPx::around(px, side_px, sigma_m * px_per_m))
        });
        // The camera renders only what the search looks at: the region of interest, and the
        // whole frame only when the region holds no tag (the same pixels either way).
        let found = self
            .search
            .detect_in(&mut frame, roi, &[self.tag.id], Some(side_px));
        self.last_render_ms = frame.render_ms;
        let (dets, how) = found?;
        let Some(d) = dets.first() else {
            return Ok(None);
        };
        self.stats.detections += 1;
        if how == SearchOutcome::Roi {
            self.stats.roi_hits += 1;
        }
        Ok(measure_tag(&self.cam, &pose, d, &self.noise)
            .map(|m| Enu2::new(m.position_enu_m[0], m.position_enu_m[1])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_target_under_the_drone_is_measured_within_millimetres() {
        let cfg = Config::default_lab();
        let mut s = VisionSensor::from_config(&cfg).unwrap();
        // Clear of the lab's two occlusion squares.
        let agent = Enu2::new(-0.5, 1.3);
        let mut errs = Vec::new();
        for (i, (x, y, h)) in [(0.1, 0.05, 0.3), (-0.2, 0.1, 2.0), (0.25, -0.15, -1.0)]
            .into_iter()
            .enumerate()
        {
            let truth = agent + Enu2::new(x, y);
            let z = s
                .measure(&View::north(agent), &truth, h, None, i as u64)
                .unwrap()
                .expect("the tag is in view");
            errs.push((z - truth).norm());
        }
        // Outside the footprint: nothing.
        let far = agent + Enu2::new(1.5, 0.0);
        assert!(s
            .measure(&View::north(agent), &far, 0.0, None, 9)
            .unwrap()
            .is_none());
        assert!(errs.iter().all(|&e| e < 0.005), "{errs:?}");
        assert_eq!(s.stats.frames, 4);
        assert_eq!(s.stats.detections, 3);
    }

    /// What skipping a frame without the tag in view rests on (`RenderedFrame::holds_no_tag`):
    /// the detector finds no tag at all, of any id, in whole field frames of the ground and
    /// the occluders alone (the outdoor world's 1280 px camera at 45 m, over open road, the
    /// warehouse and the tree line).
    #[test]
    fn the_detector_finds_no_tag_in_field_frames_without_one() {
        let cfg = Config::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../..",
            "/config/outdoor.toml"
        )))
        .unwrap();
        let mut s = VisionSensor::from_config(&cfg).unwrap();
        let bare = SceneEnu {
            target: None,
            occluders: s.occluders.clone(),
            ground_seed: 17,
        };
        let side_px = s.tag_size_m * s.cam.intrinsics.fx_px / s.altitude_m;
        for (i, (x, y)) in [(300.0, 0.0), (600.0, 0.0), (1200.0, 380.0), (-50.0, 500.0)]
            .into_iter()
            .enumerate()
        {
            let pose = VehiclePoseNed::level_above(&Enu2::new(x, y), s.altitude_m);
            let img = crate::render::render(&s.cam, &pose, &bare, &s.opts, i as u64);
            let (found, _) = s
                .search
                .detect_in(&mut &img, None, &[], Some(side_px))
                .unwrap();
            assert!(found.is_empty(), "a tag found over ({x}, {y}): {found:?}");
        }
    }
}
