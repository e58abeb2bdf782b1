//! `infotrack detect`: AprilTags in an image, a folder of images, or a video.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::Serialize;

use infotrack::vision::capture::{Camera, CaptureConfig};
use infotrack::vision::detector::{AprilTagDetector, DetectorConfig, TagDetector};
use infotrack::vision::image::GrayImage;
use infotrack::vision::projection::{measure_tag, ProjectionNoise};
use infotrack::vision::{cv_io, pose_file};

#[derive(Serialize)]
struct JsonDetection {
    frame: u64,
    id: u32,
    center_px: [f64; 2],
    corners_px: [[f64; 2]; 4],
    #[serde(skip_serializing_if = "Option::is_none")]
    ground_enu_m: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    covariance_enu_m2: Option<[[f64; 2]; 2]>,
}

const IMAGE_EXTENSIONS: [&str; 8] = ["png", "jpg", "jpeg", "bmp", "pgm", "ppm", "tif", "tiff"];

/// Whether `p` has an image file extension OpenCV reads.
pub fn is_image(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// The image files of a folder, sorted by name; none is an error.
pub fn image_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && is_image(p))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!(
            "{}: no image files ({})",
            dir.display(),
            IMAGE_EXTENSIONS.join(", ")
        );
    }
    Ok(files)
}

/// Calls `f` on every frame of `path`, in order. A file of a folder that cannot be read,
/// or a video that ends before the frame count its header declares, is a problem returned
/// (and the rest is still read); anything else stops with an error.
fn for_each_frame(
    path: &Path,
    mut f: impl FnMut(u64, &GrayImage) -> Result<()>,
) -> Result<Vec<String>> {
    if path.is_dir() {
        let files = image_files(path)?;
        let mut problems = Vec::new();
        for (i, p) in files.iter().enumerate() {
            match cv_io::read_image(p) {
                Ok(img) => f(i as u64, &img)?,
                Err(e) => {
                    eprintln!("error: frame {i}: {e}; going on with the next file");
                    problems.push(e.to_string());
                }
            }
        }
        return Ok(problems);
    }
    if !path.exists() {
        bail!("{}: no such file or folder", path.display());
    }
    if is_image(path) {
        f(0, &cv_io::read_image(path)?)?;
        return Ok(Vec::new());
    }
    let mut cam = Camera::open(CaptureConfig {
        source: path.display().to_string(),
        width_px: 0,
        height_px: 0,
        fps: 0.0,
        timeout_s: 10.0,
    })?;
    let mut n = 0;
    while let Some(frame) = cam.next_frame()? {
        f(frame.index, &frame.image)?;
        n += 1;
    }
    if n == 0 {
        bail!(
            "{}: no frames (not a video OpenCV can decode?)",
            path.display()
        );
    }
    match cam.declared_frames() {
        Some(declared) if n < declared => Ok(vec![format!(
            "{}: the video ended after {n} of the {declared} frames its header declares (truncated?)",
            path.display()
        )]),
        _ => Ok(Vec::new()),
    }
}

pub fn run(
    path: PathBuf,
    json: bool,
    pose: Option<PathBuf>,
    annotate: Option<PathBuf>,
    ids: Vec<u32>,
) -> Result<()> {
    let camera = pose.as_deref().map(pose_file::load).transpose()?;
    if let Some(dir) = &annotate {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let mut det = AprilTagDetector::new(DetectorConfig::default())?;
    let noise = ProjectionNoise::default();
    let mut all = Vec::new();
    let problems = for_each_frame(&path, |frame, img| {
        if let Some((cam, _)) = &camera {
            let (w, h) = (
                cam.intrinsics.width_px as usize,
                cam.intrinsics.height_px as usize,
            );
            if (img.width, img.height) != (w, h) {
                bail!(
                    "frame {frame} is {}x{} px but the calibration is for {w}x{h} px",
                    img.width,
                    img.height
                );
            }
        }
        let dets: Vec<_> = det
            .detect(img)?
            .into_iter()
            .filter(|d| ids.is_empty() || ids.contains(&d.id))
            .collect();
        if let Some(dir) = &annotate {
            cv_io::write_annotated(&dir.join(format!("frame_{frame:05}.png")), img, &dets)?;
        }
        for d in dets {
            let ground = camera
                .as_ref()
                .and_then(|(cam, pose)| measure_tag(cam, pose, &d, &noise));
            all.push(JsonDetection {
                frame,
                id: d.id,
                center_px: d.center_px,
                corners_px: d.corners_px,
                ground_enu_m: ground.map(|g| g.position_enu_m),
                covariance_enu_m2: ground.map(|g| g.covariance_enu_m2),
            });
        }
        Ok(())
    })?;
    if json {
        println!("{}", serde_json::json!({ "detections": all }));
    } else {
        for d in &all {
            print!(
                "frame {} id {} centre ({:.2}, {:.2}) px",
                d.frame, d.id, d.center_px[0], d.center_px[1]
            );
            if let Some(g) = d.ground_enu_m {
                print!(" ground ENU ({:.3}, {:.3}) m", g[0], g[1]);
            }
            println!();
        }
        println!("{} detection(s)", all.len());
    }
    if !problems.is_empty() {
        for p in &problems {
            eprintln!("error: {p}");
        }
        bail!(
            "{}: {} problem(s) reading the input (the detections above are from what could be read)",
            path.display(),
            problems.len()
        );
    }
    Ok(())
}
