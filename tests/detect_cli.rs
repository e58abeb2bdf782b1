//! `infotrack detect` as a user runs it: on rendered images written to disk.

use std::process::Command;

use infotrack::render::{render, RenderOptions, SceneEnu, TargetAppearance};
use infotrack::vision::camera_model::{CameraModel, CameraMount, Intrinsics, VehiclePoseNed};
use infotrack::vision::cv_io;
use infotrack::vision::tag_family::TagBitmap;

fn infotrack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_infotrack"))
}

struct Setup {
    cam: CameraModel,
    pose: VehiclePoseNed,
    target: TargetAppearance,
}

fn setup(id: u32) -> Setup {
    let mut intr = Intrinsics::ideal(640, 480, 1.0);
    intr.distortion = [-0.05, 0.01, 0.0, 0.0, 0.0];
    let cam = CameraModel {
        intrinsics: intr,
        mount: CameraMount::nadir(),
    };
    let pose = VehiclePoseNed {
        position_ned_m: [2.0, 1.0, -8.0],
        roll_rad: 0.05,
        pitch_rad: -0.08,
        yaw_rad: 0.7,
    };
    let ground = cam.pixel_to_ground_enu(350.0, 220.0, &pose).unwrap();
    Setup {
        target: TargetAppearance {
            position_enu_m: ground,
            heading_enu_rad: 1.1,
            tag: TagBitmap::tag36h11(id).unwrap(),
            tag_size_m: 1.0,
        },
        cam,
        pose,
    }
}

fn frame(s: &Setup) -> infotrack::vision::image::GrayImage {
    let scene = SceneEnu {
        target: Some(s.target.clone()),
        occluders: vec![],
        ground_seed: 3,
    };
    let opts = RenderOptions {
        noise_sigma: 2.0,
        ..Default::default()
    };
    render(&s.cam, &s.pose, &scene, &opts, 1)
}

#[test]
fn json_output_has_the_documented_shape_and_opencv_pixel_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let s = setup(3);
    let png = dir.path().join("shot.png");
    cv_io::write_image(&png, &frame(&s)).unwrap();
    let out = infotrack()
        .arg("detect")
        .arg(&png)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let obj = v.as_object().unwrap();
    assert_eq!(obj.keys().collect::<Vec<_>>(), vec!["detections"]);
    let dets = v["detections"].as_array().unwrap();
    assert_eq!(dets.len(), 1);
    let d = dets[0].as_object().unwrap();
    let mut keys: Vec<_> = d.keys().cloned().collect();
    keys.sort();
    assert_eq!(keys, vec!["center_px", "corners_px", "frame", "id"]);
    assert_eq!(d["frame"], 0);
    assert_eq!(d["id"], 3);
    let truth = s
        .target
        .corners_enu()
        .map(|c| s.cam.world_enu_to_pixel(c, 0.0, &s.pose).unwrap());
    for (i, t) in truth.iter().enumerate() {
        let c = &d["corners_px"][i];
        let (x, y) = (c[0].as_f64().unwrap(), c[1].as_f64().unwrap());
        assert!(
            (x - t[0]).hypot(y - t[1]) < 0.3,
            "corner {i}: ({x}, {y}) vs {t:?}"
        );
    }
}

#[test]
fn folders_pose_projection_and_annotation() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    let s = setup(5);
    cv_io::write_image(&frames.join("a.png"), &frame(&s)).unwrap();
    cv_io::write_image(&frames.join("b.png"), &frame(&setup(6))).unwrap();
    std::fs::write(frames.join("notes.txt"), "not an image").unwrap();
    cv_io::save_calibration(&dir.path().join("camera.yaml"), &s.cam.intrinsics).unwrap();
    let pose = dir.path().join("pose.toml");
    std::fs::write(
        &pose,
        format!(
            "calibration = \"camera.yaml\"\n[pose]\nposition_ned_m = [{}, {}, {}]\nroll_rad = {}\npitch_rad = {}\nyaw_rad = {}\n",
            s.pose.position_ned_m[0],
            s.pose.position_ned_m[1],
            s.pose.position_ned_m[2],
            s.pose.roll_rad,
            s.pose.pitch_rad,
            s.pose.yaw_rad
        ),
    )
    .unwrap();
    let ann = dir.path().join("annotated");
    let out = infotrack()
        .arg("detect")
        .arg(&frames)
        .args(["--json", "--pose"])
        .arg(&pose)
        .arg("--annotate")
        .arg(&ann)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let dets = v["detections"].as_array().unwrap();
    assert_eq!(dets.len(), 2);
    assert_eq!(
        (dets[0]["frame"].as_u64(), dets[0]["id"].as_u64()),
        (Some(0), Some(5))
    );
    assert_eq!(
        (dets[1]["frame"].as_u64(), dets[1]["id"].as_u64()),
        (Some(1), Some(6))
    );
    let g = &dets[0]["ground_enu_m"];
    let (x, y) = (g[0].as_f64().unwrap(), g[1].as_f64().unwrap());
    let t = s.target.position_enu_m;
    // <= 1% of the 8 m altitude.
    assert!((x - t[0]).hypot(y - t[1]) < 0.08, "({x}, {y}) vs {t:?}");
    assert!(ann.join("frame_00000.png").is_file() && ann.join("frame_00001.png").is_file());
}

#[test]
fn bad_inputs_fail_with_the_file_named() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.jpg");
    std::fs::write(&bad, b"\xff\xd8\xff\xe0 truncated").unwrap();
    let out = infotrack().arg("detect").arg(&bad).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("broken.jpg") && err.contains("corrupt"),
        "{err}"
    );
    let pose = dir.path().join("pose.toml");
    std::fs::write(
        &pose,
        "calibration = \"missing.yaml\"\n[pose]\nposition_ned_m = [0.0, 0.0, -5.0]\nroll_rad = 0.0\npitch_rad = 0.0\nyaw_rad = 0.0\n",
    )
    .unwrap();
    let png = dir.path().join("x.png");
    cv_io::write_image(&png, &frame(&setup(1))).unwrap();
    let out = infotrack()
        .arg("detect")
        .arg(&png)
        .arg("--pose")
        .arg(&pose)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("missing.yaml") && err.contains("no such file"),
        "{err}"
    );
}

/// The fault campaign's rows: a folder with an unreadable file stopped at it and printed
/// nothing of the good ones; a truncated video gave half its frames silently. Now every good
/// frame is reported, each bad file is named, and the exit status says something failed.
#[test]
fn a_bad_file_in_a_folder_is_named_and_the_good_ones_still_count() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    cv_io::write_image(&frames.join("a.png"), &frame(&setup(5))).unwrap();
    std::fs::write(frames.join("b.png"), b"\x89PNG broken").unwrap();
    cv_io::write_image(&frames.join("c.png"), &frame(&setup(6))).unwrap();
    let out = infotrack()
        .arg("detect")
        .arg(&frames)
        .arg("--json")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("b.png") && err.contains("1 problem"), "{err}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let ids: Vec<u64> = v["detections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["id"].as_u64().unwrap())
        .collect();
    assert_eq!(ids, vec![5, 6]);
}

#[test]
fn a_video_cut_short_says_so() {
    use opencv::prelude::*;
    use opencv::videoio::VideoWriter;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flight.avi");
    let img = frame(&setup(3));
    let mut w = VideoWriter::new(
        &path.display().to_string(),
        VideoWriter::fourcc('F', 'F', 'V', '1').unwrap(),
        10.0,
        opencv::core::Size::new(640, 480),
        false,
    )
    .unwrap();
    assert!(w.is_opened().unwrap(), "OpenCV has no FFV1 writer");
    for _ in 0..20 {
        w.write(&cv_io::mat_from_gray(&img).unwrap()).unwrap();
    }
    w.release().unwrap();
    let whole = infotrack().arg("detect").arg(&path).output().unwrap();
    assert!(
        whole.status.success(),
        "{}",
        String::from_utf8_lossy(&whole.stderr)
    );
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let cut = infotrack().arg("detect").arg(&path).output().unwrap();
    let err = String::from_utf8_lossy(&cut.stderr);
    assert!(!cut.status.success(), "{err}");
    assert!(
        err.contains("ended after") && err.contains("of the 20 frames"),
        "{err}"
    );
}
