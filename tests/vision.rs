//! The vision pipeline on rendered frames: corner accuracy against the rendering's ground
//! truth, projection accuracy, no false detections, occlusion, the region-of-interest
//! search, bad inputs, and a video written with OpenCV read back as a camera.

use infotrack::render::{render, RenderOptions, SceneEnu, TargetAppearance};
use infotrack::vision::camera_model::{CameraModel, CameraMount, Intrinsics, VehiclePoseNed};
use infotrack::vision::capture::{Camera, CaptureConfig};
use infotrack::vision::cv_io;
use infotrack::vision::detector::{
    AprilTagDetector, DetectorConfig, RoiPx, RoiSearch, SearchOutcome, TagDetection, TagDetector,
    MIN_DECIMATED_TAG_SIDE_PX,
};
use infotrack::vision::image::GrayImage;
use infotrack::vision::projection::{measure_tag, ProjectionNoise};
use infotrack::vision::tag_family::TagBitmap;
use infotrack::vision::VisionError;
use infotrack::world::geometry::{Enu2, PolygonEnu};
use rand::{Rng, SeedableRng};

fn camera(w: u32, h: u32) -> CameraModel {
    CameraModel {
        intrinsics: Intrinsics::ideal(w, h, 1.0),
        mount: CameraMount::nadir(),
    }
}

struct Shot {
    cam: CameraModel,
    pose: VehiclePoseNed,
    target: TargetAppearance,
}

/// A vehicle at `alt` with the given attitude, the target somewhere in the middle of its
/// view, a tag sized to ~70-110 px.
fn shot(rng: &mut impl Rng, alt: f64, max_tilt: f64, id: u32) -> Shot {
    let cam = camera(640, 480);
    let pose = VehiclePoseNed {
        position_ned_m: [rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0), -alt],
        roll_rad: rng.gen_range(-max_tilt..=max_tilt),
        pitch_rad: rng.gen_range(-max_tilt..=max_tilt),
        yaw_rad: rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI),
    };
    let u = rng.gen_range(200.0..440.0);
    let v = rng.gen_range(150.0..330.0);
    let ground = cam.pixel_to_ground_enu(u, v, &pose).unwrap();
    let target = TargetAppearance {
        position_enu_m: ground,
        heading_enu_rad: rng.gen_range(-3.1..3.1),
        tag: TagBitmap::tag36h11(id).unwrap(),
        tag_size_m: alt * 0.13,
    };
    Shot { cam, pose, target }
}

fn scene(t: &TargetAppearance, occluders: Vec<PolygonEnu>) -> SceneEnu {
    SceneEnu {
        target: Some(t.clone()),
        occluders,
        ground_seed: 77,
    }
}

fn truth_corners(s: &Shot) -> [[f64; 2]; 4] {
    s.target
        .corners_enu()
        .map(|c| s.cam.world_enu_to_pixel(c, 0.0, &s.pose).unwrap())
}

fn detector() -> AprilTagDetector {
    AprilTagDetector::new(DetectorConfig::default()).unwrap()
}

#[test]
fn corners_and_ground_positions_are_accurate_from_1_2_to_60_m() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut det = detector();
    let mut errors = Vec::new();
    let mut worst_ground = 0.0f64;
    let mut found = 0;
    let mut n = 0;
    let (mut coarse_errors, mut coarse_found, mut coarse_n) = (Vec::new(), 0, 0);
    for &alt in &[1.2, 3.0, 10.0, 30.0, 60.0] {
        for k in 0..6 {
            let s = shot(&mut rng, alt, 20f64.to_radians(), 3 + k);
            let img = render(
                &s.cam,
                &s.pose,
                &scene(&s.target, vec![]),
                &RenderOptions::default(),
                0,
            );
            n += 1;
            let truth = truth_corners(&s);
            // The coarse full-frame search (a tag of known size, decimated quads, corners
            // refined at full resolution) must be as good.
            let side = (truth[1][0] - truth[0][0]).hypot(truth[1][1] - truth[0][1]);
            let coarse = (side / MIN_DECIMATED_TAG_SIDE_PX).floor().min(4.0);
            if coarse > 2.0 {
                coarse_n += 1;
                if let Some(d) = det.detect_decimated(&img, coarse as f32).unwrap().first() {
                    coarse_found += 1;
                    for (c, t) in d.corners_px.iter().zip(truth.iter()) {
                        coarse_errors.push((c[0] - t[0]).hypot(c[1] - t[1]));
                    }
                }
            }
            let dets = det.detect(&img).unwrap();
            assert!(dets.len() <= 1, "{dets:?}");
            let Some(d) = dets.first() else { continue };
            found += 1;
            assert_eq!(d.id, 3 + k);
            for (c, t) in d.corners_px.iter().zip(truth.iter()) {
                errors.push((c[0] - t[0]).hypot(c[1] - t[1]));
            }
            let m = measure_tag(&s.cam, &s.pose, d, &ProjectionNoise::default()).unwrap();
            let e = (m.position_enu_m[0] - s.target.position_enu_m[0])
                .hypot(m.position_enu_m[1] - s.target.position_enu_m[1]);
            worst_ground = worst_ground.max(e / alt);
        }
    }
    errors.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let median = errors[errors.len() / 2];
    let max = *errors.last().unwrap();
    eprintln!(
        "detected {found}/{n}; corner error median {median:.4} px, max {max:.4} px; worst ground error {:.3}% of altitude",
        100.0 * worst_ground
    );
    assert_eq!(found, n, "every clean frame has its tag found");
    assert!(median <= 0.1, "median corner error {median} px");
    assert!(max <= 0.5, "max corner error {max} px");
    assert!(
        worst_ground <= 0.01,
        "ground error {}% of altitude",
        100.0 * worst_ground
    );
    coarse_errors.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let (cmed, cmax) = (
        coarse_errors[coarse_errors.len() / 2],
        *coarse_errors.last().unwrap(),
    );
    eprintln!("coarse full frame: found {coarse_found}/{coarse_n}; corner error median {cmed:.4} px, max {cmax:.4} px");
    assert!(
        coarse_n >= 20,
        "only {coarse_n} frames had a tag large enough"
    );
    assert_eq!(coarse_found, coarse_n, "the coarse search missed a tag");
    assert!(cmed <= 0.1, "coarse median corner error {cmed} px");
    assert!(cmax <= 0.5, "coarse max corner error {cmax} px");
}

#[test]
fn no_tag_no_detection_and_a_half_occluded_tag_is_not_reported() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut det = detector();
    for k in 0..5 {
        let s = shot(&mut rng, 10.0, 0.2, 1);
        let empty = SceneEnu {
            target: None,
            occluders: vec![PolygonEnu::square(
                Enu2::new(s.target.position_enu_m[0] + 3.0, s.target.position_enu_m[1]),
                2.0,
            )],
            ground_seed: k,
        };
        let opts = RenderOptions {
            noise_sigma: 3.0,
            ..Default::default()
        };
        let img = render(&s.cam, &s.pose, &empty, &opts, k);
        assert!(det.detect(&img).unwrap().is_empty(), "false detection");
        // An occluder covering the half of the tag east of its centre.
        let [x, y] = s.target.position_enu_m;
        let half = PolygonEnu::new(vec![
            Enu2::new(x, y - 5.0),
            Enu2::new(x + 5.0, y - 5.0),
            Enu2::new(x + 5.0, y + 5.0),
            Enu2::new(x, y + 5.0),
        ])
        .unwrap();
        let img = render(&s.cam, &s.pose, &scene(&s.target, vec![half]), &opts, k);
        assert!(
            det.detect(&img).unwrap().is_empty(),
            "half-hidden tag reported"
        );
        // Unhidden, the same frame has it.
        let img = render(&s.cam, &s.pose, &scene(&s.target, vec![]), &opts, k);
        assert_eq!(det.detect(&img).unwrap().len(), 1);
    }
}

#[test]
fn the_region_of_interest_finds_the_same_tag_and_falls_back_to_the_full_frame() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
    let s = shot(&mut rng, 5.0, 0.2, 9);
    let opts = RenderOptions {
        noise_sigma: 2.0,
        blur_sigma_px: 0.6,
        ..Default::default()
    };
    let img = render(&s.cam, &s.pose, &scene(&s.target, vec![]), &opts, 1);
    let mut search = RoiSearch::new(detector());
    let (full, how) = search.detect(&img, None, &[9], None).unwrap();
    assert_eq!(how, SearchOutcome::FullFrame);
    let center = s
        .cam
        .world_enu_to_pixel(s.target.position_enu_m, 0.0, &s.pose)
        .unwrap();
    // A prediction a few pixels off, as a filter's would be.
    let predicted = RoiPx::around([center[0] + 6.0, center[1] - 4.0], full[0].side_px(), 3.0);
    let (roi, how) = search.detect(&img, Some(predicted), &[9], None).unwrap();
    assert_eq!(how, SearchOutcome::Roi);
    for (a, b) in roi[0].corners_px.iter().zip(full[0].corners_px.iter()) {
        assert!((a[0] - b[0]).hypot(a[1] - b[1]) < 0.3, "{a:?} vs {b:?}");
    }
    // A prediction in the wrong place: the full frame still finds it.
    let wrong = RoiPx::around([40.0, 40.0], 60.0, 2.0);
    let (far, how) = search.detect(&img, Some(wrong), &[9], None).unwrap();
    assert_eq!(how, SearchOutcome::FullFrame);
    assert_eq!(far.len(), 1);
    // Another target id is not reported.
    assert!(search.detect(&img, None, &[10], None).unwrap().0.is_empty());
    // Knowing the tag's size, both searches may decimate coarsely (here the tag is ~90 px:
    // factor 4 allowed, 5 computed): same tag, same corners.
    let side = full[0].side_px();
    assert!(side >= 4.0 * MIN_DECIMATED_TAG_SIDE_PX, "{side} px");
    let mut coarse = RoiSearch::new(detector()).with_max_full_frame_decimation(4.0);
    for (roi, want) in [
        (Some(predicted), SearchOutcome::Roi),
        (Some(wrong), SearchOutcome::FullFrame),
    ] {
        let (d, how) = coarse.detect(&img, roi, &[9], Some(side)).unwrap();
        assert_eq!(how, want);
        for (a, b) in d[0].corners_px.iter().zip(full[0].corners_px.iter()) {
            assert!((a[0] - b[0]).hypot(a[1] - b[1]) < 0.3, "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn bad_inputs_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let corrupt = dir.path().join("frame.png");
    std::fs::write(&corrupt, b"\x89PNG\r\n\x1a\nnot really").unwrap();
    let e = cv_io::read_image(&corrupt).unwrap_err().to_string();
    assert!(e.contains("frame.png") && e.contains("corrupt"), "{e}");
    let e = cv_io::read_image(&dir.path().join("none.png"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("none.png") && e.contains("no such file"), "{e}");
    let empty = GrayImage {
        width: 0,
        height: 0,
        data: vec![],
    };
    assert!(matches!(
        detector().detect(&empty),
        Err(VisionError::EmptyFrame { .. })
    ));
    let e = cv_io::load_calibration(&dir.path().join("camera.yaml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("camera.yaml") && e.contains("no such file"),
        "{e}"
    );
    let partial = dir.path().join("partial.yaml");
    std::fs::write(
        &partial,
        "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n",
    )
    .unwrap();
    let e = cv_io::load_calibration(&partial).unwrap_err().to_string();
    assert!(e.contains("missing key `camera_matrix`"), "{e}");
}

#[test]
fn calibration_files_round_trip_through_opencv() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cam.yaml");
    let mut intr = Intrinsics::ideal(1280, 720, 1.1);
    intr.distortion = [-0.21, 0.05, 0.001, -0.002, 0.0];
    cv_io::save_calibration(&path, &intr).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.contains("camera_matrix") && text.contains("opencv-matrix"),
        "{text}"
    );
    assert_eq!(cv_io::load_calibration(&path).unwrap(), intr);
}

#[test]
fn pnp_cross_check_agrees_with_the_ray_projection() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    let mut det = detector();
    for _ in 0..4 {
        let s = shot(&mut rng, 3.0, 0.25, 0);
        let img = render(
            &s.cam,
            &s.pose,
            &scene(&s.target, vec![]),
            &RenderOptions::default(),
            0,
        );
        let d: TagDetection = det.detect(&img).unwrap().remove(0);
        let pnp = cv_io::tag_center_by_pnp(&s.cam, &s.pose, &d, s.target.tag_size_m).unwrap();
        let e = (pnp[0] - s.target.position_enu_m[0]).hypot(pnp[1] - s.target.position_enu_m[1]);
        assert!(e < 0.01 * 3.0, "PnP centre off by {e} m");
    }
}

#[test]
fn a_video_written_with_opencv_reads_back_with_the_same_detections() {
    use opencv::prelude::*;
    use opencv::videoio::VideoWriter;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flight.avi");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let mut det = detector();
    let frames: Vec<GrayImage> = (0..6)
        .map(|k| {
            let s = shot(&mut rng, 4.0, 0.2, k);
            let opts = RenderOptions {
                noise_sigma: 2.0,
                ..Default::default()
            };
            render(&s.cam, &s.pose, &scene(&s.target, vec![]), &opts, k as u64)
        })
        .collect();
    // FFV1 is lossless: what is read back is what was written.
    let fourcc = VideoWriter::fourcc('F', 'F', 'V', '1').unwrap();
    let mut w = VideoWriter::new(
        &path.display().to_string(),
        fourcc,
        10.0,
        opencv::core::Size::new(640, 480),
        false,
    )
    .unwrap();
    assert!(w.is_opened().unwrap(), "OpenCV has no FFV1 writer");
    for f in &frames {
        w.write(&cv_io::mat_from_gray(f).unwrap()).unwrap();
    }
    w.release().unwrap();

    let mut cam = Camera::open(CaptureConfig {
        source: path.display().to_string(),
        width_px: 0,
        height_px: 0,
        fps: 0.0,
        timeout_s: 5.0,
    })
    .unwrap();
    let mut n = 0;
    while let Some(frame) = cam.next_frame().unwrap() {
        let want = det.detect(&frames[n]).unwrap();
        let got = det.detect(&frame.image).unwrap();
        assert_eq!(got, want, "frame {n}");
        assert!(!got.is_empty());
        assert!(
            (frame.capture_time_s - n as f64 / 10.0).abs() < 1e-6,
            "{}",
            frame.capture_time_s
        );
        n += 1;
    }
    assert_eq!(n, frames.len());
}

#[test]
fn the_simulator_in_vision_mode_measures_through_rendered_frames() {
    use infotrack::config::Config;
    use infotrack::guidance::GuidanceKind;
    use infotrack::sim::run::{run_once, EstimatorKind, RunSpec};
    let cfg = Config::default_lab();
    let world = cfg.world();
    let spec = RunSpec {
        guidance: GuidanceKind::Truth,
        estimator: EstimatorKind::parse("cv").unwrap(),
        seed: 3,
        run_index: 0,
        duration_s: 20.0,
        snapshot_times_s: vec![],
        vision: true,
        trace: false,
    };
    let out = run_once(&cfg, &world, &spec).unwrap();
    let stats = out.vision.unwrap();
    assert_eq!(stats.frames as usize, out.steps.len());
    let mut measured = 0;
    for s in &out.steps {
        if let Some(z) = s.measurement_enu {
            measured += 1;
            // Detector + projection at 1.2 m: millimetres, far inside R's 0.1 m.
            assert!(
                (z - s.target_enu).norm() < 0.01,
                "t={} z={z:?} truth={:?}",
                s.t_s,
                s.target_enu
            );
            assert!(s.target_in_footprint);
        }
        if s.target_occluded {
            // The tag's centre is under canopy: at least half of it is hidden.
            assert!(
                s.measurement_enu.is_none(),
                "t={}: seen through the canopy",
                s.t_s
            );
        }
    }
    let visible = out
        .steps
        .iter()
        .filter(|s| s.target_in_footprint && !s.target_occluded)
        .count();
    eprintln!(
        "{measured} measurements, {visible} steps with the target visible, ROI hits {}",
        stats.roi_hits
    );
    assert_eq!(stats.detections, measured as u64);
    // Flying over the target, most visible steps give a measurement (a tag cut by the edge
    // of the image or of a canopy is the rest).
    assert!(
        measured as f64 >= 0.7 * visible as f64,
        "{measured} of {visible}"
    );
    assert!(out.summary.estimation_error_m.is_finite());
}
