//! Criterion benches of the synthetic camera at field scale (1280 x 720 px, 70 degrees, 45 m,
//! a 1.2 m tag and four occluders in view): the whole frame, as a frame without the tag in
//! its search region costs, and a 160 px region of interest around the tag, as a frame
//! found where the filter predicted costs (`render::render_region`).

use criterion::{criterion_group, criterion_main, Criterion};
use infotrack::render::{render, render_region, RenderOptions, SceneEnu, TargetAppearance};
use infotrack::vision::camera_model::{CameraModel, CameraMount, Intrinsics, VehiclePoseNed};
use infotrack::vision::image::PixelRect;
use infotrack::vision::tag_family::TagBitmap;
use infotrack::world::geometry::{Enu2, PolygonEnu};

fn field_frame() -> (CameraModel, VehiclePoseNed, SceneEnu, RenderOptions) {
    let cam = CameraModel {
        intrinsics: Intrinsics::ideal(1280, 720, 70f64.to_radians()),
        mount: CameraMount::nadir(),
    };
    let pose = VehiclePoseNed::level_above(&Enu2::new(10.0, 20.0), 45.0);
    let scene = SceneEnu {
        target: Some(TargetAppearance {
            position_enu_m: [12.0, 21.0],
            heading_enu_rad: 0.3,
            tag: TagBitmap::tag36h11(0).expect("tag 0 exists"),
            tag_size_m: 1.2,
        }),
        occluders: [(-15.0, 25.0), (30.0, 10.0), (0.0, 0.0), (35.0, 35.0)]
            .iter()
            .map(|&(x, y)| PolygonEnu::square(Enu2::new(x, y), 8.0))
            .collect(),
        ground_seed: 17,
    };
    // The simulator's defaults (`[vision]`).
    let opts = RenderOptions {
        supersample: 2,
        noise_sigma: 2.0,
        blur_sigma_px: 0.5,
        ..RenderOptions::default()
    };
    (cam, pose, scene, opts)
}

fn render_field(c: &mut Criterion) {
    let (cam, pose, scene, opts) = field_frame();
    let mut g = c.benchmark_group("render_1280x720_45m");
    g.sample_size(20);
    g.bench_function("whole_frame", |b| {
        b.iter(|| render(&cam, &pose, &scene, &opts, 3))
    });
    let tag_px = cam
        .world_enu_to_pixel([12.0, 21.0], 0.0, &pose)
        .expect("the tag is in view");
    let roi = PixelRect::clipped(
        (tag_px[0] - 80.0) as usize,
        (tag_px[1] - 80.0) as usize,
        160,
        160,
        1280,
        720,
    );
    g.bench_function("region_160px", |b| {
        b.iter(|| render_region(&cam, &pose, &scene, &opts, 3, roi))
    });
    g.finish();
}

criterion_group!(benches, render_field);
criterion_main!(benches);
