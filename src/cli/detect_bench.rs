//! Detection time per frame, full frame against the region-of-interest search, at 640x480
//! and 1280x720, one thread, on the same rendered frames (noise and blur on). Both use the
//! AprilTag C library: the full-frame row *is* the plain AprilTag 3 detection, so the ratio
//! is what the region of interest buys at the same recall.

use std::time::Instant;

use rand::{Rng, SeedableRng};
use serde::Serialize;

use infotrack::render::{render, RenderOptions, SceneEnu, TargetAppearance};
use infotrack::vision::camera_model::{CameraModel, CameraMount, Intrinsics, VehiclePoseNed};
use infotrack::vision::detector::{
    AprilTagDetector, DetectorConfig, RoiPx, RoiSearch, SearchOutcome,
};
use infotrack::vision::image::GrayImage;
use infotrack::vision::tag_family::TagBitmap;
use infotrack::vision::VisionError;

/// One resolution's numbers.
#[derive(Debug, Clone, Serialize)]
pub struct DetectBenchRow {
    /// Image width, px.
    pub width_px: u32,
    /// Image height, px.
    pub height_px: u32,
    /// Frames measured.
    pub frames: usize,
    /// Median full-frame detection time, ms.
    pub full_frame_ms: f64,
    /// Median full-frame detection time with the decimation the tag's known size allows
    /// (the fallback of the region-of-interest search), ms.
    pub coarse_ms: f64,
    /// Median time with the region of interest (falling back to the coarse full frame), ms.
    pub roi_ms: f64,
    /// Frames with the tag found, coarse full frame.
    pub coarse_found: usize,
    /// Frames with the tag found, full frame.
    pub full_frame_found: usize,
    /// Frames with the tag found, region of interest first.
    pub roi_found: usize,
    /// Of those, found inside the region.
    pub roi_hits: usize,
}

/// A tag ~60 px wide at either resolution, as a tracker keeps it.
const SIDE_PX: f64 = 60.0;

struct Case {
    img: GrayImage,
    roi: RoiPx,
}

fn cases(w: u32, h: u32, n: usize, seed: u64) -> Vec<Case> {
    let mut rng = infotrack::rng::CoreRng::seed_from_u64(seed);
    let cam = CameraModel {
        intrinsics: Intrinsics::ideal(w, h, 1.0),
        mount: CameraMount::nadir(),
    };
    let tag = TagBitmap::tag36h11(0).expect("id 0 exists");
    (0..n)
        .map(|k| {
            let alt = rng.gen_range(5.0..30.0);
            let pose = VehiclePoseNed {
                position_ned_m: [0.0, 0.0, -alt],
                roll_rad: rng.gen_range(-0.2..0.2),
                pitch_rad: rng.gen_range(-0.2..0.2),
                yaw_rad: rng.gen_range(-3.1..3.1),
            };
            let (u, v) = (
                rng.gen_range(0.25..0.75) * w as f64,
                rng.gen_range(0.25..0.75) * h as f64,
            );
            let ground = cam.pixel_to_ground_enu(u, v, &pose).expect("below horizon");
            let side_px = SIDE_PX;
            let tag_size_m = side_px * alt / cam.intrinsics.fx_px;
            let scene = SceneEnu {
                target: Some(TargetAppearance {
                    position_enu_m: ground,
                    heading_enu_rad: rng.gen_range(-3.1..3.1),
                    tag: tag.clone(),
                    tag_size_m,
                }),
                occluders: vec![],
                ground_seed: k as u64,
            };
            let opts = RenderOptions {
                supersample: 2,
                noise_sigma: 3.0,
                blur_sigma_px: 0.6,
                ..Default::default()
            };
            let img = render(&cam, &pose, &scene, &opts, k as u64);
            // The filter's prediction: off by a few pixels, with a 10 px sigma.
            let c = [u + rng.gen_range(-8.0..8.0), v + rng.gen_range(-8.0..8.0)];
            Case {
                img,
                roi: RoiPx::around(c, side_px, 10.0),
            }
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Runs the benchmark on `frames` frames per resolution.
pub fn run(frames: usize, seed: u64) -> Result<Vec<DetectBenchRow>, VisionError> {
    let cfg = DetectorConfig::default();
    let mut det = RoiSearch::new(AprilTagDetector::new(cfg.clone())?)
        .with_max_full_frame_decimation(cfg.max_full_frame_decimation);
    let mut rows = Vec::new();
    for (w, h) in [(640, 480), (1280, 720)] {
        let cs = cases(w, h, frames.max(1), seed);
        let (mut full_t, mut coarse_t, mut roi_t) = (Vec::new(), Vec::new(), Vec::new());
        let (mut full_found, mut coarse_found, mut roi_found, mut roi_hits) = (0, 0, 0, 0);
        for c in &cs {
            let t = Instant::now();
            let (d, _) = det.detect(&c.img, None, &[0], None)?;
            full_t.push(t.elapsed().as_secs_f64() * 1e3);
            full_found += usize::from(!d.is_empty());
            let t = Instant::now();
            let (d, _) = det.detect(&c.img, None, &[0], Some(SIDE_PX))?;
            coarse_t.push(t.elapsed().as_secs_f64() * 1e3);
            coarse_found += usize::from(!d.is_empty());
            let t = Instant::now();
            let (d, how) = det.detect(&c.img, Some(c.roi), &[0], Some(SIDE_PX))?;
            roi_t.push(t.elapsed().as_secs_f64() * 1e3);
            roi_found += usize::from(!d.is_empty());
            roi_hits += usize::from(how == SearchOutcome::Roi);
        }
        rows.push(DetectBenchRow {
            width_px: w,
            height_px: h,
            frames: cs.len(),
            full_frame_ms: median(full_t),
            coarse_ms: median(coarse_t),
            roi_ms: median(roi_t),
            full_frame_found: full_found,
            coarse_found,
            roi_found,
            roi_hits,
        });
    }
    Ok(rows)
}

/// The table.
pub fn render_table(rows: &[DetectBenchRow]) -> String {
    let mut s = String::from(
        "| resolution | frames | AprilTag 3 full frame (ms) | coarse full frame (ms) | ROI first (ms) | speed-up coarse / ROI | found full / coarse / ROI (in ROI) |\n|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s += &format!(
            "| {}x{} | {} | {:.2} | {:.2} | {:.2} | {:.1}x / {:.1}x | {} / {} / {} ({}) |\n",
            r.width_px,
            r.height_px,
            r.frames,
            r.full_frame_ms,
            r.coarse_ms,
            r.roi_ms,
            r.full_frame_ms / r.coarse_ms,
            r.full_frame_ms / r.roi_ms,
            r.full_frame_found,
            r.coarse_found,
            r.roi_found,
            r.roi_hits
        );
    }
    s
}
