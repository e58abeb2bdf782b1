//! Camera calibration from chessboard views with OpenCV (`infotrack calibrate`): corners
//! found and refined to sub-pixel, `calibrateCamera` (k1, k2, p1, p2; k3 fixed at 0, which
//! a handful of views cannot pin down), each view's reprojection error, and views whose
//! error is far above the others' reported as outliers and left out of a second pass.

use opencv::core::{self, Mat, Point2f, Point3f, Size, TermCriteria, Vector};
use opencv::prelude::*;
use opencv::{calib3d, imgproc};

use super::camera_model::Intrinsics;
use super::cv_io::mat_from_gray;
use super::image::GrayImage;
use super::VisionError;

/// A chessboard: inner corners per row and per column, and the side of one square.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Board {
    /// Inner corners along a row (the board's columns minus one).
    pub cols: u32,
    /// Inner corners along a column.
    pub rows: u32,
    /// Side of one square, m.
    pub square_m: f64,
}

impl Board {
    /// A board from `COLSxROWS` inner corners (e.g. `9x6`) and a square side in metres.
    pub fn parse(corners: &str, square_m: f64) -> Result<Self, VisionError> {
        let bad = |why: &str| {
            VisionError::Config(format!(
                "--board `{corners}`: {why} (COLSxROWS inner corners, e.g. 9x6)"
            ))
        };
        let (c, r) = corners
            .split_once(['x', 'X'])
            .ok_or_else(|| bad("no `x`"))?;
        let cols: u32 = c.trim().parse().map_err(|_| bad("COLS is not a number"))?;
        let rows: u32 = r.trim().parse().map_err(|_| bad("ROWS is not a number"))?;
        if !(2..=100).contains(&cols) || !(2..=100).contains(&rows) {
            return Err(bad("each must be 2-100"));
        }
        if !(square_m.is_finite() && square_m > 0.0 && square_m <= 10.0) {
            return Err(VisionError::Config(format!(
                "--square-m {square_m}: must be a side in metres, above 0 and at most 10"
            )));
        }
        Ok(Self {
            cols,
            rows,
            square_m,
        })
    }

    /// The inner corners on the board's plane (z = 0), row by row, m: OpenCV's order.
    fn object_points(&self) -> Vector<Point3f> {
        let mut v = Vector::new();
        for r in 0..self.rows {
            for c in 0..self.cols {
                v.push(Point3f::new(
                    (c as f64 * self.square_m) as f32,
                    (r as f64 * self.square_m) as f32,
                    0.0,
                ));
            }
        }
        v
    }
}

/// One view's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewReport {
    /// The file (or frame) name.
    pub name: String,
    /// RMS reprojection error with the final calibration, px; `None`: no board found.
    pub error_px: Option<f64>,
    /// Left out of the final calibration: its error was far above the others'.
    pub outlier: bool,
}

/// A calibration and how well it fits.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The camera.
    pub intrinsics: Intrinsics,
    /// RMS reprojection error over the views used, px.
    pub rms_px: f64,
    /// Every view, in the order given.
    pub views: Vec<ViewReport>,
}

/// Fewest views with the board found that make a calibration.
pub const MIN_VIEWS: usize = 3;

/// A view is an outlier when its error exceeds this many times the median (and 0.5 px).
const OUTLIER_FACTOR: f64 = 3.0;

fn cv(what: &str) -> impl FnOnce(opencv::Error) -> VisionError + '_ {
    move |e| VisionError::OpenCv(format!("{what}: {e}"))
}

/// The board's inner corners in `img`, refined to sub-pixel; `None` when not found.
fn find_corners(img: &GrayImage, board: &Board) -> Result<Option<Vector<Point2f>>, VisionError> {
    let m = mat_from_gray(img)?;
    let mut corners = Vector::<Point2f>::new();
    let size = Size::new(board.cols as i32, board.rows as i32);
    let flags = calib3d::CALIB_CB_ADAPTIVE_THRESH | calib3d::CALIB_CB_NORMALIZE_IMAGE;
    let found = calib3d::find_chessboard_corners(&m, size, &mut corners, flags)
        .map_err(cv("findChessboardCorners"))?;
    if !found {
        return Ok(None);
    }
    let criteria = TermCriteria::new(
        core::TermCriteria_Type::COUNT as i32 + core::TermCriteria_Type::EPS as i32,
        30,
        1e-3,
    )
    .map_err(cv("TermCriteria"))?;
    imgproc::corner_sub_pix(
        &m,
        &mut corners,
        Size::new(11, 11),
        Size::new(-1, -1),
        criteria,
    )
    .map_err(cv("cornerSubPix"))?;
    Ok(Some(corners))
}

/// One `calibrateCamera` pass over `found` views: (K, distortion, per-view RMS error, RMS).
fn solve(
    board: &Board,
    found: &[&Vector<Point2f>],
    size: Size,
) -> Result<(Mat, Mat, Vec<f64>, f64), VisionError> {
    let object: Vector<Vector<Point3f>> = found.iter().map(|_| board.object_points()).collect();
    let image: Vector<Vector<Point2f>> = found.iter().map(|c| (*c).clone()).collect();
    let mut k = Mat::default();
    let mut d = Mat::default();
    let mut rvecs = Vector::<Mat>::new();
    let mut tvecs = Vector::<Mat>::new();
    let criteria = TermCriteria::new(
        core::TermCriteria_Type::COUNT as i32 + core::TermCriteria_Type::EPS as i32,
        100,
        f64::EPSILON,
    )
    .map_err(cv("TermCriteria"))?;
    let rms = calib3d::calibrate_camera(
        &object,
        &image,
        size,
        &mut k,
        &mut d,
        &mut rvecs,
        &mut tvecs,
        calib3d::CALIB_FIX_K3,
        criteria,
    )
    .map_err(cv("calibrateCamera"))?;
    let errors = errors_with(board, found, &k, &d)?;
    Ok((k, d, errors, rms))
}

fn intrinsics(k: &Mat, d: &Mat, size: Size) -> Result<Intrinsics, VisionError> {
    let at = |m: &Mat, r: i32, c: i32| -> Result<f64, VisionError> {
        m.at_2d::<f64>(r, c)
            .copied()
            .map_err(cv("calibration matrix"))
    };
    let mut dist = [0.0; 5];
    for (i, v) in dist.iter_mut().enumerate().take(d.total().min(5)) {
        *v = at(d, 0, i as i32)?;
    }
    Ok(Intrinsics {
        width_px: size.width as u32,
        height_px: size.height as u32,
        fx_px: at(k, 0, 0)?,
        fy_px: at(k, 1, 1)?,
        cx_px: at(k, 0, 2)?,
        cy_px: at(k, 1, 2)?,
        distortion: dist,
    })
}

/// Calibrates from named views of `board`; all views must have the same size.
pub fn calibrate(views: &[(String, GrayImage)], board: &Board) -> Result<Calibration, VisionError> {
    let Some((first_name, first)) = views.first() else {
        return Err(VisionError::Config("no views to calibrate from".into()));
    };
    let size = Size::new(first.width as i32, first.height as i32);
    let mut corners = Vec::with_capacity(views.len());
    for (name, img) in views {
        if (img.width, img.height) != (first.width, first.height) {
            return Err(VisionError::Config(format!(
                "{name} is {}x{} px but {first_name} is {}x{}: one camera, one size",
                img.width, img.height, first.width, first.height
            )));
        }
        corners.push(find_corners(img, board)?);
    }
    let found: Vec<usize> = (0..views.len()).filter(|&i| corners[i].is_some()).collect();
    if found.len() < MIN_VIEWS {
        return Err(VisionError::Config(format!(
            "the {}x{} board was found in {} of {} views; at least {MIN_VIEWS} are needed",
            board.cols,
            board.rows,
            found.len(),
            views.len()
        )));
    }
    let refs: Vec<&Vector<Point2f>> = found
        .iter()
        .map(|&i| corners[i].as_ref().expect("found"))
        .collect();
    let (mut k, mut d, errors, mut rms) = solve(board, &refs, size)?;
    let mut sorted = errors.clone();
    sorted.sort_by(f64::total_cmp);
    let limit = (OUTLIER_FACTOR * sorted[sorted.len() / 2]).max(0.5);
    let outlier: Vec<bool> = errors.iter().map(|e| *e > limit).collect();
    let kept: Vec<&Vector<Point2f>> = refs
        .iter()
        .zip(&outlier)
        .filter(|(_, o)| !**o)
        .map(|(c, _)| *c)
        .collect();
    let mut final_errors = errors;
    if kept.len() < refs.len() && kept.len() >= MIN_VIEWS {
        let (k2, d2, _, rms2) = solve(board, &kept, size)?;
        (k, d, rms) = (k2, d2, rms2);
        // Every view's error against the final calibration, outliers included.
        final_errors = errors_with(board, &refs, &k, &d)?;
    }
    let mut reports: Vec<ViewReport> = views
        .iter()
        .map(|(name, _)| ViewReport {
            name: name.clone(),
            error_px: None,
            outlier: false,
        })
        .collect();
    for (j, &i) in found.iter().enumerate() {
        reports[i].error_px = Some(final_errors[j]);
        reports[i].outlier = outlier[j] && kept.len() >= MIN_VIEWS;
    }
    Ok(Calibration {
        intrinsics: intrinsics(&k, &d, size)?,
        rms_px: rms,
        views: reports,
    })
}

/// Each view's RMS reprojection error for a camera (K, distortion): the view's pose by
/// solvePnP, then projection.
fn errors_with(
    board: &Board,
    found: &[&Vector<Point2f>],
    k: &Mat,
    d: &Mat,
) -> Result<Vec<f64>, VisionError> {
    let object = board.object_points();
    let mut errors = Vec::with_capacity(found.len());
    for seen in found {
        let mut rvec = Mat::default();
        let mut tvec = Mat::default();
        calib3d::solve_pnp_def(&object, *seen, k, d, &mut rvec, &mut tvec)
            .map_err(cv("solvePnP"))?;
        let mut projected = Vector::<Point2f>::new();
        calib3d::project_points_def(&object, &rvec, &tvec, k, d, &mut projected)
            .map_err(cv("projectPoints"))?;
        let sq: f64 = seen
            .iter()
            .zip(projected.iter())
            .map(|(a, b)| ((a.x - b.x) as f64).powi(2) + ((a.y - b.y) as f64).powi(2))
            .sum();
        errors.push((sq / seen.len() as f64).sqrt());
    }
    Ok(errors)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boards_parse_with_clear_errors() {
        let b = Board::parse("9x6", 0.025).unwrap();
        assert_eq!((b.cols, b.rows), (9, 6));
        for bad in ["9", "ax6", "9x1", "9x500"] {
            let e = Board::parse(bad, 0.025).unwrap_err().to_string();
            assert!(e.contains(bad) && e.contains("COLSxROWS"), "{e}");
        }
        assert!(Board::parse("9x6", 0.0)
            .unwrap_err()
            .to_string()
            .contains("--square-m"));
    }

    #[test]
    fn too_few_views_are_an_error_saying_how_many() {
        let blank = GrayImage::new(64, 48, vec![128; 64 * 48]).unwrap();
        let views = vec![
            ("a.png".to_string(), blank.clone()),
            ("b.png".into(), blank),
        ];
        let e = calibrate(&views, &Board::parse("4x3", 0.02).unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("found in 0 of 2 views"), "{e}");
    }
}
