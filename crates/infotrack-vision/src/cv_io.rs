//! Everything that goes through OpenCV: image files, the calibration YAML that OpenCV's
//! calibration writes, annotated frames, and the solvePnP cross-check of a tag's pose.

use std::path::Path;

use opencv::core::{
    Mat, MatTraitConst, MatTraitConstManual, MatTraitManual, Point, Scalar, Vector,
};
use opencv::prelude::*;
use opencv::{calib3d, core, imgcodecs, imgproc};

use super::camera_model::{CameraModel, Intrinsics, VehiclePoseNed};
use super::detector::TagDetection;
use super::image::GrayImage;
use super::VisionError;

fn cv_err(what: impl Into<String>) -> impl FnOnce(opencv::Error) -> VisionError {
    let what = what.into();
    move |e| VisionError::OpenCv(format!("{what}: {e}"))
}

/// An 8-bit grey (or colour, converted) OpenCV matrix as a [`GrayImage`].
pub fn gray_from_mat(m: &Mat, origin: &str) -> Result<GrayImage, VisionError> {
    if m.empty() {
        return Err(VisionError::EmptyFrame {
            width: m.cols().max(0) as usize,
            height: m.rows().max(0) as usize,
        });
    }
    let gray = match m.channels() {
        1 => m.try_clone().map_err(cv_err(origin))?,
        3 | 4 => {
            let mut g = Mat::default();
            let code = if m.channels() == 3 {
                imgproc::COLOR_BGR2GRAY
            } else {
                imgproc::COLOR_BGRA2GRAY
            };
            imgproc::cvt_color(m, &mut g, code, 0).map_err(cv_err(origin))?;
            g
        }
        c => {
            return Err(VisionError::Corrupt {
                path: origin.to_string(),
                message: format!("{c} channels"),
            })
        }
    };
    if gray.depth() != core::CV_8U {
        return Err(VisionError::Corrupt {
            path: origin.to_string(),
            message: "not 8 bits per sample".into(),
        });
    }
    let gray = if gray.is_continuous() {
        gray
    } else {
        gray.try_clone().map_err(cv_err(origin))?
    };
    let data = gray.data_bytes().map_err(cv_err(origin))?.to_vec();
    GrayImage::new(gray.cols() as usize, gray.rows() as usize, data)
}

/// A [`GrayImage`] as an OpenCV matrix (CV_8UC1).
pub fn mat_from_gray(img: &GrayImage) -> Result<Mat, VisionError> {
    let mut m = Mat::new_rows_cols_with_default(
        img.height as i32,
        img.width as i32,
        core::CV_8UC1,
        Scalar::all(0.0),
    )
    .map_err(cv_err("allocating a frame"))?;
    m.data_bytes_mut()
        .map_err(cv_err("allocating a frame"))?
        .copy_from_slice(&img.data);
    Ok(m)
}

/// Reads an image file as grey.
pub fn read_image(path: &Path) -> Result<GrayImage, VisionError> {
    let name = path.display().to_string();
    if !path.is_file() {
        return Err(VisionError::Io {
            path: name,
            message: "no such file".into(),
        });
    }
    let m = imgcodecs::imread(&name, imgcodecs::IMREAD_GRAYSCALE).map_err(cv_err(&name))?;
    if m.empty() {
        return Err(VisionError::Corrupt {
            path: name,
            message: "not an image OpenCV can decode".into(),
        });
    }
    gray_from_mat(&m, &name)
}

/// Writes an image file (format from the extension; use .png for lossless).
pub fn write_image(path: &Path, img: &GrayImage) -> Result<(), VisionError> {
    write_mat(path, &mat_from_gray(img)?)
}

fn write_mat(path: &Path, m: &Mat) -> Result<(), VisionError> {
    let name = path.display().to_string();
    let ok = imgcodecs::imwrite(&name, m, &Vector::new()).map_err(cv_err(&name))?;
    if !ok {
        return Err(VisionError::Io {
            path: name,
            message: "OpenCV could not write it".into(),
        });
    }
    Ok(())
}

/// Writes the frame with its detections drawn: corner 0 marked, outline, id at the centre.
pub fn write_annotated(
    path: &Path,
    img: &GrayImage,
    dets: &[TagDetection],
) -> Result<(), VisionError> {
    let gray = mat_from_gray(img)?;
    let mut bgr = Mat::default();
    imgproc::cvt_color(&gray, &mut bgr, imgproc::COLOR_GRAY2BGR, 0)
        .map_err(cv_err("annotating"))?;
    let pt = |p: [f64; 2]| Point::new(p[0].round() as i32, p[1].round() as i32);
    for d in dets {
        for i in 0..4 {
            imgproc::line(
                &mut bgr,
                pt(d.corners_px[i]),
                pt(d.corners_px[(i + 1) % 4]),
                Scalar::new(0.0, 255.0, 0.0, 0.0),
                2,
                imgproc::LINE_AA,
                0,
            )
            .map_err(cv_err("annotating"))?;
        }
        imgproc::circle(
            &mut bgr,
            pt(d.corners_px[0]),
            4,
            Scalar::new(0.0, 0.0, 255.0, 0.0),
            -1,
            imgproc::LINE_AA,
            0,
        )
        .map_err(cv_err("annotating"))?;
        imgproc::put_text(
            &mut bgr,
            &d.id.to_string(),
            pt(d.center_px),
            imgproc::FONT_HERSHEY_SIMPLEX,
            0.8,
            Scalar::new(255.0, 0.0, 0.0, 0.0),
            2,
            imgproc::LINE_AA,
            false,
        )
        .map_err(cv_err("annotating"))?;
    }
    write_mat(path, &bgr)
}

/// Reads the camera matrix, distortion and image size from the YAML (or XML) file that
/// OpenCV's calibration writes (`camera_matrix`, `distortion_coefficients`, `image_width`,
/// `image_height`).
pub fn load_calibration(path: &Path) -> Result<Intrinsics, VisionError> {
    let name = path.display().to_string();
    let bad = |message: String| VisionError::Calibration {
        path: name.clone(),
        message,
    };
    if !path.is_file() {
        return Err(bad("no such file".into()));
    }
    let fs = core::FileStorage::new(&name, core::FileStorage_Mode::READ as i32, "")
        .map_err(|e| bad(format!("not a file OpenCV can read: {e}")))?;
    if !fs.is_opened().unwrap_or(false) {
        return Err(bad("not a file OpenCV can read".into()));
    }
    let node = |key: &str| -> Result<core::FileNode, VisionError> {
        let n = fs.get(key).map_err(|e| bad(format!("{key}: {e}")))?;
        if n.is_none().unwrap_or(true) {
            return Err(bad(format!("missing key `{key}`")));
        }
        Ok(n)
    };
    let as_f64s = |key: &str, want: usize| -> Result<Vec<f64>, VisionError> {
        let m = node(key)?
            .mat()
            .map_err(|e| bad(format!("{key} is not a matrix: {e}")))?;
        let mut m64 = Mat::default();
        m.convert_to(&mut m64, core::CV_64F, 1.0, 0.0)
            .map_err(|e| bad(format!("{key}: {e}")))?;
        let v: Vec<f64> = m64
            .data_typed::<f64>()
            .map_err(|e| bad(format!("{key}: {e}")))?
            .to_vec();
        if v.len() < want {
            return Err(bad(format!(
                "{key} has {} numbers, expected {want}",
                v.len()
            )));
        }
        Ok(v)
    };
    let k = as_f64s("camera_matrix", 9)?;
    let d = as_f64s("distortion_coefficients", 4)?;
    let size = |key: &str| -> Result<u32, VisionError> {
        let v = node(key)?
            .to_i32()
            .map_err(|e| bad(format!("{key}: {e}")))?;
        u32::try_from(v)
            .ok()
            .filter(|&v| v > 0)
            .ok_or_else(|| bad(format!("{key} = {v} must be positive")))
    };
    let intr = Intrinsics {
        width_px: size("image_width")?,
        height_px: size("image_height")?,
        fx_px: k[0],
        fy_px: k[4],
        cx_px: k[2],
        cy_px: k[5],
        distortion: [d[0], d[1], d[2], d[3], d.get(4).copied().unwrap_or(0.0)],
    };
    intr.validate().map_err(|e| bad(e.0))?;
    Ok(intr)
}

/// Writes intrinsics in OpenCV's calibration format.
pub fn save_calibration(path: &Path, intr: &Intrinsics) -> Result<(), VisionError> {
    let name = path.display().to_string();
    let mut fs = core::FileStorage::new(&name, core::FileStorage_Mode::WRITE as i32, "")
        .map_err(cv_err(&name))?;
    let k = Mat::from_slice_2d(&[
        [intr.fx_px, 0.0, intr.cx_px],
        [0.0, intr.fy_px, intr.cy_px],
        [0.0, 0.0, 1.0],
    ])
    .map_err(cv_err(&name))?;
    let d = Mat::from_slice_2d(&[intr.distortion]).map_err(cv_err(&name))?;
    fs.write_i32("image_width", intr.width_px as i32)
        .map_err(cv_err(&name))?;
    fs.write_i32("image_height", intr.height_px as i32)
        .map_err(cv_err(&name))?;
    fs.write_mat("camera_matrix", &k).map_err(cv_err(&name))?;
    fs.write_mat("distortion_coefficients", &d)
        .map_err(cv_err(&name))?;
    fs.release().map_err(cv_err(&name))?;
    Ok(())
}

/// The tag's centre from its four corners by solvePnP (IPPE for squares), world ENU, m: a
/// cross-check of the ray-ground projection when the tag is large in the image.
pub fn tag_center_by_pnp(
    cam: &CameraModel,
    pose: &VehiclePoseNed,
    det: &TagDetection,
    tag_size_m: f64,
) -> Result<[f64; 2], VisionError> {
    let h = tag_size_m / 2.0;
    // IPPE_SQUARE's object points, in the order of AprilTag's corners (p0 bottom-left,
    // counter-clockwise in the image): tag frame x right, y up, z out of the tag.
    let obj: Vector<core::Point3d> = Vector::from_iter([
        core::Point3d::new(-h, h, 0.0),
        core::Point3d::new(h, h, 0.0),
        core::Point3d::new(h, -h, 0.0),
        core::Point3d::new(-h, -h, 0.0),
    ]);
    let img: Vector<core::Point2d> = det
        .corners_px
        .iter()
        .map(|c| core::Point2d::new(c[0], c[1]))
        .collect();
    let i = &cam.intrinsics;
    let k = Mat::from_slice_2d(&[
        [i.fx_px, 0.0, i.cx_px],
        [0.0, i.fy_px, i.cy_px],
        [0.0, 0.0, 1.0],
    ])
    .map_err(cv_err("solvePnP"))?;
    let d = Mat::from_slice(&i.distortion).map_err(cv_err("solvePnP"))?;
    let (mut rvec, mut tvec) = (Mat::default(), Mat::default());
    let ok = calib3d::solve_pnp(
        &obj,
        &img,
        &k,
        &d,
        &mut rvec,
        &mut tvec,
        false,
        calib3d::SOLVEPNP_IPPE_SQUARE,
    )
    .map_err(cv_err("solvePnP"))?;
    if !ok {
        return Err(VisionError::OpenCv("solvePnP found no pose".into()));
    }
    let t: Vec<f64> = tvec
        .data_typed::<f64>()
        .map_err(cv_err("solvePnP"))?
        .to_vec();
    let (c, r_nc) = cam.camera_in_ned(pose);
    let p = c + r_nc * nalgebra::Vector3::new(t[0], t[1], t[2]);
    Ok([p.y, p.x])
}
