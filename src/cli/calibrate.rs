//! `infotrack calibrate`: a camera calibration from chessboard views (a folder of images or
//! a live camera), written as the OpenCV YAML that `daemon.calibration` reads.

use std::path::Path;

use anyhow::{bail, Context, Result};
use infotrack::vision::calibration::{self, Board, Calibration};
use infotrack::vision::capture::{Camera, CaptureConfig};
use infotrack::vision::cv_io;
use infotrack::vision::image::GrayImage;

use super::detect::image_files;

pub use super::calibrate_args::CalibrateArgs;

/// Runs `infotrack calibrate`.
pub fn run(a: CalibrateArgs) -> Result<()> {
    let board = Board::parse(&a.board, a.square_m)?;
    let source = Path::new(&a.source);
    let views = if source.is_dir() {
        folder_views(source)?
    } else {
        camera_views(&a.source, a.frames, a.every_s)?
    };
    let cal = calibration::calibrate(&views, &board)?;
    print!("{}", report(&cal));
    cv_io::save_calibration(&a.out, &cal.intrinsics)
        .with_context(|| format!("cannot write {}", a.out.display()))?;
    println!("wrote {}", a.out.display());
    Ok(())
}

/// Every image of a folder, by name; one that cannot be read is reported and skipped.
fn folder_views(dir: &Path) -> Result<Vec<(String, GrayImage)>> {
    let files = image_files(dir)?;
    let mut views = Vec::new();
    for p in files {
        let name = p.file_name().map_or_else(
            || p.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        match cv_io::read_image(&p) {
            Ok(img) => views.push((name, img)),
            Err(e) => eprintln!("warning: {e}; left out"),
        }
    }
    Ok(views)
}

/// `frames` views from a camera, one every `every_s` seconds.
fn camera_views(source: &str, frames: usize, every_s: f64) -> Result<Vec<(String, GrayImage)>> {
    if !((1..=1000).contains(&frames) && every_s.is_finite() && every_s >= 0.0) {
        bail!("--frames must be 1-1000 and --every-s >= 0 (got {frames}, {every_s})");
    }
    let mut cam = Camera::open(CaptureConfig {
        source: source.to_string(),
        width_px: 0,
        height_px: 0,
        fps: 0.0,
        timeout_s: 5.0,
    })?;
    let mut views = Vec::new();
    let mut last: Option<f64> = None;
    while views.len() < frames {
        let Some(f) = cam.next_frame()? else {
            break;
        };
        if last.is_some_and(|t| f.capture_time_s - t < every_s) {
            continue;
        }
        last = Some(f.capture_time_s);
        eprintln!("view {} of {frames} (frame {})", views.len() + 1, f.index);
        views.push((format!("frame {}", f.index), f.image));
    }
    Ok(views)
}

/// The per-view table and the result.
fn report(c: &Calibration) -> String {
    use std::fmt::Write;
    let mut s = String::from("view                              error (px)\n");
    for v in &c.views {
        let e = match (v.error_px, v.outlier) {
            (None, _) => "board not found".to_string(),
            (Some(e), true) => format!("{e:.3}  OUTLIER, left out"),
            (Some(e), false) => format!("{e:.3}"),
        };
        let _ = writeln!(s, "{:<33} {e}", v.name);
    }
    let i = &c.intrinsics;
    let _ = writeln!(
        s,
        "reprojection error {:.3} px (RMS over the views used); {}x{} px, fx {:.2} fy {:.2} cx {:.2} cy {:.2}, distortion {:?}",
        c.rms_px, i.width_px, i.height_px, i.fx_px, i.fy_px, i.cx_px, i.cy_px, i.distortion
    );
    s
}
