//! Vision at field scale (`infotrack bench --vision-altitude`): how often the detector finds
//! a car's roof tag, and how far its ground projection lands from the truth, against the
//! drone's altitude, for field cameras (1280x720 and 1920x1080, 70 degrees horizontal) and
//! roof tags of 1.0-1.5 m. Frames are rendered as the simulator renders them (the default
//! `[vision]` noise and blur, tilt up to 0.1 rad, textured ground), the tag anywhere in the
//! central 80 % of the image; detection is the full-frame search the tracker falls back to
//! when its region of interest misses, told the tag's expected size.

use std::time::Instant;

use rand::{Rng, SeedableRng};
use serde::Serialize;

use infotrack::config::VisionSimConfig;
use infotrack::render::{render, RenderOptions, SceneEnu, TargetAppearance};
use infotrack::vision::camera_model::{CameraModel, CameraMount, Intrinsics, VehiclePoseNed};
use infotrack::vision::detector::{AprilTagDetector, RoiSearch};
use infotrack::vision::projection::measure_tag;
use infotrack::vision::tag_family::TagBitmap;
use infotrack::vision::VisionError;

/// One (camera, tag, altitude) cell.
#[derive(Debug, Clone, Serialize)]
pub struct AltitudeRow {
    /// Image width, px.
    pub width_px: u32,
    /// Image height, px.
    pub height_px: u32,
    /// Side of the tag's black square, m.
    pub tag_size_m: f64,
    /// Height above the ground, m.
    pub altitude_m: f64,
    /// The tag's side in the image, px.
    pub tag_side_px: f64,
    /// Frames rendered.
    pub frames: usize,
    /// Share of frames with the tag found, %.
    pub recall_percent: f64,
    /// Median distance of the projected tag centre from the truth, world ENU, m.
    pub ground_error_p50_m: f64,
    /// 90th percentile of that distance, m.
    pub ground_error_p90_m: f64,
    /// Median detection time, ms (one thread).
    pub detect_ms: f64,
}

/// Horizontal field of view of the field cameras, rad (70 degrees).
const FOV_X_RAD: f64 = 1.2217;

/// The cameras, tags and altitudes swept.
const CAMERAS: [(u32, u32); 2] = [(1280, 720), (1920, 1080)];
const TAGS_M: [f64; 3] = [1.0, 1.2, 1.5];
const ALTITUDES_M: [f64; 5] = [30.0, 45.0, 60.0, 75.0, 90.0];

fn percentile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// One cell: `frames` rendered frames, detected and projected.
fn cell(
    search: &mut RoiSearch<AprilTagDetector>,
    vision: &VisionSimConfig,
    (w, h): (u32, u32),
    tag_size_m: f64,
    altitude_m: f64,
    frames: usize,
    seed: u64,
) -> Result<AltitudeRow, VisionError> {
    let cam = CameraModel {
        intrinsics: Intrinsics::ideal(w, h, FOV_X_RAD),
        mount: CameraMount::nadir(),
    };
    let tag = TagBitmap::tag36h11(0)?;
    let opts = RenderOptions {
        supersample: vision.supersample,
        gain: 1.0,
        offset: 0.0,
        blur_sigma_px: vision.blur_sigma_px,
        noise_sigma: vision.noise_sigma,
    };
    let side_px = tag_size_m * cam.intrinsics.fx_px / altitude_m;
    let mut rng = infotrack::rng::CoreRng::seed_from_u64(seed);
    let (mut errors, mut times) = (Vec::new(), Vec::new());
    for k in 0..frames {
        let pose = VehiclePoseNed {
            position_ned_m: [0.0, 0.0, -altitude_m],
            roll_rad: rng.gen_range(-0.1..0.1),
            pitch_rad: rng.gen_range(-0.1..0.1),
            yaw_rad: rng.gen_range(-3.1..3.1),
        };
        let (u, v) = (
            rng.gen_range(0.1..0.9) * w as f64,
            rng.gen_range(0.1..0.9) * h as f64,
        );
        let Some(truth) = cam.pixel_to_ground_enu(u, v, &pose) else {
            continue;
        };
        let scene = SceneEnu {
            target: Some(TargetAppearance {
                position_enu_m: truth,
                heading_enu_rad: rng.gen_range(-3.1..3.1),
                tag: tag.clone(),
                tag_size_m,
            }),
            occluders: vec![],
            ground_seed: seed ^ k as u64,
        };
        let img = render(&cam, &pose, &scene, &opts, seed.wrapping_add(k as u64));
        let t = Instant::now();
        let (dets, _) = search.detect(&img, None, &[0], Some(side_px))?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        let measured = dets
            .first()
            .and_then(|d| measure_tag(&cam, &pose, d, &vision.projection));
        if let Some(m) = measured {
            errors.push((m.position_enu_m[0] - truth[0]).hypot(m.position_enu_m[1] - truth[1]));
        }
    }
    let found = errors.len();
    Ok(AltitudeRow {
        width_px: w,
        height_px: h,
        tag_size_m,
        altitude_m,
        tag_side_px: side_px,
        frames,
        recall_percent: 100.0 * found as f64 / frames.max(1) as f64,
        ground_error_p50_m: percentile(&mut errors, 0.5),
        ground_error_p90_m: percentile(&mut errors, 0.9),
        detect_ms: percentile(&mut times, 0.5),
    })
}

/// The whole sweep, `frames` frames per cell, with the simulator's default vision settings.
pub fn run(frames: usize, seed: u64) -> Result<Vec<AltitudeRow>, VisionError> {
    let vision = VisionSimConfig::default();
    let mut search = RoiSearch::new(AprilTagDetector::new(vision.detector.clone())?)
        .with_max_full_frame_decimation(vision.detector.max_full_frame_decimation);
    let mut rows = Vec::new();
    for (i, camera) in CAMERAS.into_iter().enumerate() {
        for (j, tag) in TAGS_M.into_iter().enumerate() {
            for (k, alt) in ALTITUDES_M.into_iter().enumerate() {
                let cell_seed = seed ^ ((i * 100 + j * 10 + k) as u64).wrapping_mul(0x9E37_79B9);
                rows.push(cell(
                    &mut search,
                    &vision,
                    camera,
                    tag,
                    alt,
                    frames,
                    cell_seed,
                )?);
            }
        }
    }
    Ok(rows)
}

/// The table.
pub fn render_table(rows: &[AltitudeRow]) -> String {
    let mut s = String::from(
        "| camera | tag (m) | altitude (m) | tag side (px) | frames | recall (%) | ground error p50 / p90 (m) | detection p50 (ms) |\n|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s += &format!(
            "| {}x{} | {:.1} | {:.0} | {:.1} | {} | {:.1} | {:.2} / {:.2} | {:.1} |\n",
            r.width_px,
            r.height_px,
            r.tag_size_m,
            r.altitude_m,
            r.tag_side_px,
            r.frames,
            r.recall_percent,
            r.ground_error_p50_m,
            r.ground_error_p90_m,
            r.detect_ms
        );
    }
    s
}
