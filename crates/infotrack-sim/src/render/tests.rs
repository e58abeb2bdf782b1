use super::*;
use infotrack_vision::camera_model::{CameraMount, Intrinsics};

fn scene() -> SceneEnu {
    SceneEnu {
        target: Some(TargetAppearance {
            position_enu_m: [1.0, 2.0],
            heading_enu_rad: 0.4,
            tag: TagBitmap::tag36h11(3).unwrap(),
            tag_size_m: 0.5,
        }),
        occluders: vec![],
        ground_seed: 9,
    }
}

fn pose() -> VehiclePoseNed {
    VehiclePoseNed {
        position_ned_m: [2.0, 1.0, -5.0],
        roll_rad: 0.0,
        pitch_rad: 0.0,
        yaw_rad: 0.0,
    }
}

#[test]
fn the_inlined_floor_is_floor() {
    for x in [
        -3.5,
        -3.0,
        -2.999_999,
        -0.5,
        -1e-300,
        -0.0,
        0.0,
        1e-300,
        0.5,
        2.0,
        2.5,
        1e15 + 0.5,
        -1e15 - 0.5,
    ] {
        assert_eq!(floor_fast(x), x.floor(), "{x}");
    }
}

/// Seen from 45 m a pixel spans 5 cm of textured ground: without an edge in view it is
/// the mean of its corners, which differs from the supersampled mean by under a grey
/// level; with the tag in view its pixels are still supersampled.
#[test]
fn from_high_up_smooth_ground_is_not_supersampled_but_the_tag_is() {
    // 5 cm pixels at 45 m, as a 1280 px, 70 degree camera has (a narrower view keeps
    // the test small).
    let cam = CameraModel {
        intrinsics: Intrinsics::ideal(320, 180, 2.0 * (320.0 * 0.05 / 2.0 / 45.0f64).atan()),
        mount: CameraMount::nadir(),
    };
    let high = VehiclePoseNed {
        position_ned_m: [0.0, 0.0, -45.0],
        ..pose()
    };
    let bare = SceneEnu {
        target: None,
        ..scene()
    };
    let sample = ray_sampler(&cam, &high, &bare);
    let corners = corner_radiance(
        &cam,
        &high,
        &bare,
        320,
        180,
        PixelRect::full(320, 180),
        &sample,
    );
    assert!(corners.edgy.iter().all(|e| !e), "no edge in a bare field");
    let img = render(&cam, &high, &bare, &RenderOptions::default(), 0);
    let mut worst: f64 = 0.0;
    for v in (0..180).step_by(7) {
        for u in (0..320).step_by(11) {
            let mut acc = 0.0;
            for k in 0..16 {
                acc += sample(
                    u as f64 + (k % 4) as f64 / 4.0 - 0.375,
                    v as f64 + (k / 4) as f64 / 4.0 - 0.375,
                );
            }
            worst = worst.max((img.data[v * 320 + u] as f64 - acc / 16.0).abs());
        }
    }
    assert!(
        worst < 1.6,
        "worst pixel {worst} grey levels from its 4x4 mean"
    );
    let tagged = SceneEnu {
        target: Some(TargetAppearance {
            position_enu_m: [0.0, 0.0],
            tag_size_m: 1.2,
            ..scene().target.unwrap()
        }),
        ..scene()
    };
    let sample = ray_sampler(&cam, &high, &tagged);
    let corners = corner_radiance(
        &cam,
        &high,
        &tagged,
        320,
        180,
        PixelRect::full(320, 180),
        &sample,
    );
    assert!(corners.edgy_at(160, 90), "the tag's block has an edge");
    assert!(
        !corners.edgy_at(10, 10),
        "a far corner of the frame has none"
    );
}

#[test]
fn the_tag_is_drawn_where_the_camera_model_projects_it() {
    let cam = CameraModel {
        intrinsics: Intrinsics::ideal(320, 240, 1.0),
        mount: CameraMount::nadir(),
    };
    let sc = scene();
    let img = render(&cam, &pose(), &sc, &RenderOptions::default(), 0);
    // The tag centre is the middle of its payload; the ring just inside each corner is
    // black, the white ring just outside is white.
    let t = sc.target.as_ref().unwrap();
    for corner in t.corners_enu() {
        let inward = [
            corner[0] + 0.1 * (t.position_enu_m[0] - corner[0]),
            corner[1] + 0.1 * (t.position_enu_m[1] - corner[1]),
        ];
        let outward = [
            corner[0] - 0.08 * (t.position_enu_m[0] - corner[0]),
            corner[1] - 0.08 * (t.position_enu_m[1] - corner[1]),
        ];
        let pi = cam.world_enu_to_pixel(inward, 0.0, &pose()).unwrap();
        let po = cam.world_enu_to_pixel(outward, 0.0, &pose()).unwrap();
        let at = |p: [f64; 2]| img.get(p[0].round() as usize, p[1].round() as usize);
        assert!(at(pi) < 60, "inside corner {corner:?}: {}", at(pi));
        assert!(at(po) > 190, "outside corner {corner:?}: {}", at(po));
    }
}

#[test]
fn rendering_is_deterministic_and_occluders_hide_the_tag() {
    let cam = CameraModel {
        intrinsics: Intrinsics::ideal(160, 120, 1.0),
        mount: CameraMount::nadir(),
    };
    let opts = RenderOptions {
        noise_sigma: 3.0,
        blur_sigma_px: 0.7,
        ..Default::default()
    };
    let a = render(&cam, &pose(), &scene(), &opts, 5);
    let b = render(&cam, &pose(), &scene(), &opts, 5);
    let c = render(&cam, &pose(), &scene(), &opts, 6);
    assert_eq!(a, b);
    assert_ne!(a, c);
    let mut hidden = scene();
    hidden.occluders = vec![PolygonEnu::square(Enu2::new(1.0, 2.0), 2.0)];
    let img = render(&cam, &pose(), &hidden, &RenderOptions::default(), 0);
    let p = cam.world_enu_to_pixel([1.0, 2.0], 0.0, &pose()).unwrap();
    let v = img.get(p[0] as usize, p[1] as usize);
    assert!((40..=60).contains(&v), "{v}");
}

#[test]
fn interpolated_corners_match_exact_ones() {
    // Low (the lab: blocks interpolated) and high (every block exact), level and tilted,
    // with an occluder's edge and the tag in view.
    for (alt, roll, pitch) in [
        (1.2, 0.0, 0.0),
        (1.2, 0.15, -0.1),
        (3.0, 0.0, 0.2),
        (45.0, 0.1, 0.0),
    ] {
        let cam = CameraModel {
            intrinsics: Intrinsics::ideal(640, 480, 1.0),
            mount: CameraMount::nadir(),
        };
        let pose = VehiclePoseNed {
            position_ned_m: [0.1, -0.2, -alt],
            roll_rad: roll,
            pitch_rad: pitch,
            yaw_rad: 0.7,
        };
        let ground = cam.pixel_to_ground_enu(300.0, 220.0, &pose).unwrap();
        let edge = cam.pixel_to_ground_enu(500.0, 120.0, &pose).unwrap();
        let scene = SceneEnu {
            target: Some(TargetAppearance {
                position_enu_m: ground,
                heading_enu_rad: 0.4,
                tag: TagBitmap::tag36h11(2).unwrap(),
                tag_size_m: 0.08 * alt,
            }),
            occluders: vec![PolygonEnu::square(Enu2::new(edge[0], edge[1]), 0.3 * alt)],
            ground_seed: 5,
        };
        let sample = ray_sampler(&cam, &pose, &scene);
        let Corners {
            values: fast,
            interpolated,
            ..
        } = corner_radiance(
            &cam,
            &pose,
            &scene,
            640,
            480,
            PixelRect::full(640, 480),
            &sample,
        );
        let share = interpolated as f64 / (641.0 * 481.0);
        eprintln!(
            "alt {alt} m, roll {roll}, pitch {pitch}: {:.0} % interpolated",
            100.0 * share
        );
        if alt < 2.0 {
            assert!(share > 0.5, "only {share} interpolated at {alt} m");
        } else if alt > 40.0 {
            assert_eq!(interpolated, 0, "blocks span metres at {alt} m: all exact");
        }
        let mut worst = 0.0f64;
        for v in 0..=480 {
            for u in 0..=640 {
                let e = sample(u as f64 - 0.5, v as f64 - 0.5);
                worst = worst.max((fast[v * 641 + u] - e).abs());
            }
        }
        eprintln!("  worst corner difference {worst:.4} grey levels");
        assert!(
            worst < 0.25,
            "alt {alt}: corner radiance off by {worst} grey levels"
        );
    }
}

/// A region renders exactly the pixels the whole frame has there: with noise and blur on,
/// at the frame's edges and corners, across a tag's edge and an occluder's, high and low,
/// level and tilted.
#[test]
fn a_region_is_exactly_the_whole_frames_pixels_there() {
    let opts = RenderOptions {
        noise_sigma: 3.0,
        blur_sigma_px: 0.8,
        ..Default::default()
    };
    for (alt, roll) in [(5.0, 0.0), (45.0, 0.12)] {
        let cam = CameraModel {
            intrinsics: Intrinsics::ideal(320, 180, 1.0),
            mount: CameraMount::nadir(),
        };
        let pose = VehiclePoseNed {
            position_ned_m: [2.0, 1.0, -alt],
            roll_rad: roll,
            ..pose()
        };
        let tag_at = cam.pixel_to_ground_enu(150.0, 90.0, &pose).unwrap();
        let edge = cam.pixel_to_ground_enu(250.0, 40.0, &pose).unwrap();
        let scene = SceneEnu {
            target: Some(TargetAppearance {
                position_enu_m: tag_at,
                tag_size_m: 0.1 * alt,
                ..scene().target.unwrap()
            }),
            occluders: vec![PolygonEnu::square(Enu2::new(edge[0], edge[1]), 0.2 * alt)],
            ground_seed: 4,
        };
        let whole = render(&cam, &pose, &scene, &opts, 11);
        for (x0, y0, w, h) in [
            (130, 70, 40, 40),
            (0, 0, 17, 9),
            (300, 170, 30, 30),
            (230, 20, 45, 50),
            (0, 60, 320, 3),
        ] {
            let r = PixelRect::clipped(x0, y0, w, h, 320, 180);
            let part = render_region(&cam, &pose, &scene, &opts, 11, r);
            assert_eq!(part, whole.crop(x0, y0, w, h), "alt {alt}, region {r:?}");
        }
    }
}

/// A frame that says it holds no tag is, pixel for pixel, the frame of the scene without
/// the target (blur, noise and supersampling on, a tilted camera, the tag slid out across
/// each side of the frame past the margin); a tag whose border still reaches into the frame
/// is not skipped; a lens with distortion is never decided.
#[test]
fn a_frame_that_holds_no_tag_is_the_scene_without_the_target() {
    let cam = CameraModel {
        intrinsics: Intrinsics::ideal(160, 90, 1.2217),
        mount: CameraMount::nadir(),
    };
    let tilted = VehiclePoseNed {
        position_ned_m: [0.0, 0.0, -8.0],
        roll_rad: 0.05,
        pitch_rad: -0.08,
        yaw_rad: 0.7,
    };
    let opts = RenderOptions {
        supersample: 3,
        blur_sigma_px: 0.8,
        noise_sigma: 2.0,
        ..RenderOptions::default()
    };
    let bare = SceneEnu {
        target: None,
        ..scene()
    };
    let mut skipped = 0;
    let mut kept_with_tag_pixels = 0;
    for (dx, dy) in [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (0.7, 0.7)] {
        for step in 0..24 {
            let d = 3.0 + 0.25 * step as f64;
            let mut s = scene();
            // Pose NED [0, 0] is ENU [0, 0]; the tag slides out along (dx, dy).
            let at = [d * dx, d * dy];
            s.target.as_mut().unwrap().position_enu_m = at;
            let frame = RenderedFrame::new(&cam, &tilted, &s, &opts, 5);
            let with = render(&cam, &tilted, &s, &opts, 5);
            let without = render(&cam, &tilted, &bare, &opts, 5);
            if frame.holds_no_tag() {
                skipped += 1;
                let differ: Vec<usize> = (0..with.data.len())
                    .filter(|&i| with.data[i] != without.data[i])
                    .collect();
                let corners: Vec<_> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                    .iter()
                    .map(|(a, b)| {
                        let r = s.target.as_ref().unwrap().reach_m();
                        cam.world_enu_to_pixel([at[0] + a * r, at[1] + b * r], 0.0, &tilted)
                    })
                    .collect();
                assert!(
                    differ.is_empty(),
                    "skipped at {at:?}: {} pixels differ, first at ({}, {}); corners {corners:?}",
                    differ.len(),
                    differ.first().map_or(0, |i| i % 160),
                    differ.first().map_or(0, |i| i / 160)
                );
            } else if with.data != without.data {
                kept_with_tag_pixels += 1;
            }
        }
    }
    assert!(
        skipped >= 20,
        "the test must reach frames without the tag: {skipped}"
    );
    assert!(kept_with_tag_pixels >= 20, "{kept_with_tag_pixels}");
    let s = scene();
    assert!(RenderedFrame::new(&cam, &tilted, &bare, &opts, 5).holds_no_tag());
    let far = SceneEnu {
        target: s.target.clone().map(|t| TargetAppearance {
            position_enu_m: [40.0, 0.0],
            ..t
        }),
        ..scene()
    };
    assert!(RenderedFrame::new(&cam, &tilted, &far, &opts, 5).holds_no_tag());
    let mut bent = cam.clone();
    bent.intrinsics.distortion = [-0.1, 0.0, 0.0, 0.0, 0.0];
    assert!(!RenderedFrame::new(&bent, &tilted, &far, &opts, 5).holds_no_tag());
}

/// A tag under an occluder's canopy is not in the frame, whatever the lens: the frame says
/// so, and it is pixel for pixel the scene without the target; a canopy with a notch
/// reaching into the tag's square, or one smaller than the square, hides nothing.
#[test]
fn a_tag_under_a_canopy_holds_no_tag() {
    let mut bent = CameraModel {
        intrinsics: Intrinsics::ideal(120, 90, 1.0),
        mount: CameraMount::nadir(),
    };
    bent.intrinsics.distortion = [-0.1, 0.01, 0.0, 0.0, 0.0];
    let opts = RenderOptions {
        supersample: 3,
        blur_sigma_px: 0.6,
        noise_sigma: 1.0,
        ..RenderOptions::default()
    };
    // A canopy over the tag (at (1, 2), its square +-0.44 m) with a notch in its top edge.
    let canopy = |notch: Enu2| {
        PolygonEnu::new(vec![
            Enu2::new(0.0, 0.5),
            Enu2::new(2.2, 0.8),
            Enu2::new(2.2, 3.2),
            notch,
            Enu2::new(0.0, 3.5),
        ])
        .unwrap()
    };
    let above = pose();
    let covered = SceneEnu {
        occluders: vec![canopy(Enu2::new(1.6, 2.7))],
        ..scene()
    };
    assert!(RenderedFrame::new(&bent, &above, &covered, &opts, 3).holds_no_tag());
    let bare = SceneEnu {
        target: None,
        ..covered.clone()
    };
    assert!(
        render(&bent, &above, &covered, &opts, 3).data
            == render(&bent, &above, &bare, &opts, 3).data
    );
    let notched = SceneEnu {
        occluders: vec![canopy(Enu2::new(1.2, 2.1))],
        ..scene()
    };
    assert!(!RenderedFrame::new(&bent, &above, &notched, &opts, 3).holds_no_tag());
    let small = SceneEnu {
        occluders: vec![PolygonEnu::square(Enu2::new(1.0, 2.0), 0.8)],
        ..scene()
    };
    assert!(!RenderedFrame::new(&bent, &above, &small, &opts, 3).holds_no_tag());
    let small_bare = SceneEnu {
        target: None,
        ..small.clone()
    };
    assert!(
        render(&bent, &above, &small, &opts, 3).data
            != render(&bent, &above, &small_bare, &opts, 3).data,
        "the uncovered rim of the tag shows"
    );
}
