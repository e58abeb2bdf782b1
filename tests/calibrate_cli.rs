//! `infotrack calibrate` on chessboard views rendered with a known camera: the intrinsics
//! come back within 1 %, a view taken with another camera is reported as an outlier, a
//! view without the board is named, and the file written is the one the daemon reads.

use std::path::Path;
use std::process::Command;

use infotrack::vision::cv_io;
use infotrack::vision::image::GrayImage;
use nalgebra::{Matrix3, Vector3};

/// The camera the views are rendered with (no distortion).
#[derive(Clone, Copy)]
struct Camera {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
}

const W: usize = 800;
const H: usize = 600;
/// A 9x6 inner-corner board: 10 x 7 squares of 30 mm, with a one-square white margin.
const SQUARE_M: f64 = 0.03;
const SQUARES: (f64, f64) = (10.0, 7.0);

/// World -> camera rotation for a camera at `eye` looking at `at`, rolled by `roll` rad.
fn look_at(eye: Vector3<f64>, at: Vector3<f64>, roll: f64) -> Matrix3<f64> {
    let z = (at - eye).normalize();
    let hint = if z.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let x0 = hint.cross(&z).normalize();
    let y0 = z.cross(&x0);
    let (s, c) = roll.sin_cos();
    let x = c * x0 + s * y0;
    let y = -s * x0 + c * y0;
    Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()])
}

/// The board seen from `eye` (looking at the board's centre), 3x3 supersampled.
fn render(cam: Camera, eye: Vector3<f64>, roll: f64) -> GrayImage {
    let centre = Vector3::new(SQUARES.0 * SQUARE_M / 2.0, SQUARES.1 * SQUARE_M / 2.0, 0.0);
    let r = look_at(eye, centre, roll);
    let rt = r.transpose();
    let shade = |u: f64, v: f64| -> f64 {
        let d = rt * Vector3::new((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
        if d.z.abs() < 1e-12 {
            return 128.0;
        }
        let s = -eye.z / d.z;
        if s <= 0.0 {
            return 128.0;
        }
        let p = eye + s * d;
        let (bx, by) = (p.x / SQUARE_M, p.y / SQUARE_M);
        let inside = |v: f64, n: f64| (0.0..n).contains(&v);
        if inside(bx, SQUARES.0) && inside(by, SQUARES.1) {
            if (bx.floor() as i64 + by.floor() as i64) % 2 == 0 {
                20.0
            } else {
                235.0
            }
        } else if inside(bx + 1.0, SQUARES.0 + 2.0) && inside(by + 1.0, SQUARES.1 + 2.0) {
            235.0
        } else {
            110.0
        }
    };
    let mut data = vec![0u8; W * H];
    for v in 0..H {
        for u in 0..W {
            let mut sum = 0.0;
            for i in 0..3 {
                for j in 0..3 {
                    // Pixel centres at integers (OpenCV): samples at -1/3, 0, +1/3.
                    sum += shade(
                        u as f64 + (i as f64 - 1.0) / 3.0,
                        v as f64 + (j as f64 - 1.0) / 3.0,
                    );
                }
            }
            data[v * W + u] = (sum / 9.0).round() as u8;
        }
    }
    GrayImage::new(W, H, data).unwrap()
}

/// Views from around the board: azimuth all round, tilted 20-45 degrees, rolled.
fn write_views(dir: &Path, cam: Camera) {
    let centre = Vector3::new(0.15, 0.105, 0.0);
    for k in 0..12 {
        let az = (k as f64) * 30f64.to_radians();
        let tilt = (20.0 + 25.0 * ((k % 3) as f64 / 2.0)).to_radians();
        let dist = 0.55 + 0.05 * (k % 2) as f64;
        let eye =
            centre + dist * Vector3::new(tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos());
        let img = render(cam, eye, 0.3 * ((k % 4) as f64 - 1.5));
        cv_io::write_image(&dir.join(format!("view{k:02}.png")), &img).unwrap();
    }
}

#[test]
fn calibrate_recovers_a_known_camera_within_one_percent() {
    let truth = Camera {
        fx: 700.0,
        fy: 700.0,
        cx: 399.5,
        cy: 299.5,
    };
    let dir = tempfile::tempdir().unwrap();
    let views = dir.path().join("views");
    std::fs::create_dir(&views).unwrap();
    write_views(&views, truth);
    // A view from another camera (a zoomed lens): far off the others' fit.
    let other = Camera { fx: 980.0, ..truth };
    let img = render(other, Vector3::new(0.25, 0.02, 0.5), 0.2);
    cv_io::write_image(&views.join("view99-other-camera.png"), &img).unwrap();
    // A view without the board.
    let blank = GrayImage::new(W, H, vec![110; W * H]).unwrap();
    cv_io::write_image(&views.join("view98-no-board.png"), &blank).unwrap();

    let out_file = dir.path().join("camera.yaml");
    let out = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .arg("calibrate")
        .arg(&views)
        .args(["--board", "9x6", "--square-m", "0.03", "--out"])
        .arg(&out_file)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let all = format!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{all}");
    assert!(stdout.contains("reprojection error"), "{all}");
    let line = |name: &str| {
        stdout
            .lines()
            .find(|l| l.starts_with(name))
            .unwrap_or_else(|| panic!("no line for {name}: {all}"))
            .to_string()
    };
    assert!(
        line("view98-no-board.png").contains("board not found"),
        "{all}"
    );
    assert!(line("view99-other-camera.png").contains("OUTLIER"), "{all}");
    for k in 0..12 {
        let l = line(&format!("view{k:02}.png"));
        assert!(!l.contains("OUTLIER") && !l.contains("not found"), "{l}");
    }

    // The file is the daemon's calibration format.
    let got = cv_io::load_calibration(&out_file).unwrap();
    assert_eq!((got.width_px, got.height_px), (W as u32, H as u32));
    for (name, g, t) in [
        ("fx", got.fx_px, truth.fx),
        ("fy", got.fy_px, truth.fy),
        ("cx", got.cx_px, truth.cx),
        ("cy", got.cy_px, truth.cy),
    ] {
        assert!(
            ((g - t) / t).abs() < 0.01,
            "{name}: {g:.2} vs {t:.2}\n{all}"
        );
    }
    assert!(got.distortion.iter().all(|d| d.abs() < 0.05), "{all}");

    // The same views through the camera path (an image sequence is a capture source, as a
    // live camera is): --frames views, one every --every-s.
    let seq = views.join("view%02d.png");
    let out = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .arg("calibrate")
        .arg(&seq)
        .args(["--board", "9x6", "--square-m", "0.03", "--frames", "8"])
        .args(["--every-s", "0", "--out"])
        .arg(dir.path().join("live.yaml"))
        .output()
        .unwrap();
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{all}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let rows = stdout.lines().filter(|l| l.starts_with("frame ")).count();
    assert_eq!(rows, 8, "one table row per view taken: {all}");
    let live = cv_io::load_calibration(&dir.path().join("live.yaml")).unwrap();
    assert!(((live.fx_px - truth.fx) / truth.fx).abs() < 0.01, "{all}");
}

#[test]
fn calibrate_says_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_infotrack"))
            .arg("calibrate")
            .args(args)
            .output()
            .unwrap();
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let d = dir.path().to_str().unwrap();
    let out = dir.path().join("c.yaml");
    let out = out.to_str().unwrap();
    let e = run(&[d, "--board", "9by6", "--square-m", "0.03", "--out", out]);
    assert!(e.contains("--board `9by6`"), "{e}");
    let e = run(&[d, "--board", "9x6", "--square-m", "0.03", "--out", out]);
    assert!(e.contains("no image files"), "{e}");
    let blank = GrayImage::new(64, 48, vec![110; 64 * 48]).unwrap();
    cv_io::write_image(&dir.path().join("a.png"), &blank).unwrap();
    let e = run(&[d, "--board", "9x6", "--square-m", "0.03", "--out", out]);
    assert!(e.contains("found in 0 of 1 views"), "{e}");
}
