//! The synthetic camera: what the drone's camera sees for a vehicle pose and the true
//! target pose, rendered by casting each (supersampled) pixel's ray onto the ground plane
//! through the same intrinsics, distortion and mount the projection uses. A textured
//! ground, the target's tag drawn perspective-correct, occlusion regions drawn opaque over
//! everything, then exposure, blur and sensor noise.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::camera_model::{CameraModel, VehiclePoseNed};
use super::image::GrayImage;
use super::tag_family::TagBitmap;
use crate::rng::CoreRng;
use crate::world::geometry::{Enu2, PolygonEnu};

/// The target as the camera sees it: a tag lying flat on it.
#[derive(Debug, Clone)]
pub struct TargetAppearance {
    /// Tag centre, world ENU, m.
    pub position_enu_m: [f64; 2],
    /// Direction the top of the tag faces, world ENU, rad from east toward north.
    pub heading_enu_rad: f64,
    /// The tag's pattern.
    pub tag: TagBitmap,
    /// Side of the tag's black square, m.
    pub tag_size_m: f64,
}

impl TargetAppearance {
    /// The four corners of the tag's black square, world ENU, in the AprilTag library's
    /// order (p[0..3]: counter-clockwise in the image starting at the tag's bottom-left,
    /// which seen from above is: bottom-left, bottom-right, top-right, top-left).
    pub fn corners_enu(&self) -> [[f64; 2]; 4] {
        let h = self.tag_size_m / 2.0;
        let (s, c) = self.heading_enu_rad.sin_cos();
        // (right, forward) offsets -> ENU: forward = (c, s), right = (s, -c).
        let at = |r: f64, f: f64| {
            [
                self.position_enu_m[0] + r * s + f * c,
                self.position_enu_m[1] - r * c + f * s,
            ]
        };
        [at(-h, -h), at(h, -h), at(h, h), at(-h, h)]
    }

    /// Cell value under a world ENU ground point, if it falls on the tag.
    fn sample(&self, x: f64, y: f64) -> Option<u8> {
        let (dx, dy) = (x - self.position_enu_m[0], y - self.position_enu_m[1]);
        let (s, c) = self.heading_enu_rad.sin_cos();
        let forward = c * dx + s * dy;
        let right = s * dx - c * dy;
        let cell = self.tag_size_m / self.tag.black_cells() as f64;
        let half = self.tag.size as f64 / 2.0;
        let col = right / cell + half;
        let row = -forward / cell + half;
        let n = self.tag.size as f64;
        (col >= 0.0 && row >= 0.0 && col < n && row < n)
            .then(|| self.tag.cell(col as usize, row as usize))
    }
}

/// What is on the ground.
#[derive(Debug, Clone, Default)]
pub struct SceneEnu {
    /// The target, if it is in the world.
    pub target: Option<TargetAppearance>,
    /// Regions that hide whatever is under them (canopy, roofs), drawn opaque.
    pub occluders: Vec<PolygonEnu>,
    /// Seed of the ground texture.
    pub ground_seed: u64,
}

/// Image formation settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Samples per pixel side (anti-aliasing); 1 for none.
    pub supersample: usize,
    /// Exposure gain applied to the scene's radiance.
    pub gain: f64,
    /// Exposure offset, grey levels.
    pub offset: f64,
    /// Gaussian blur (defocus, motion), sigma in px; 0 for none.
    pub blur_sigma_px: f64,
    /// Sensor noise, sigma in grey levels; 0 for none.
    pub noise_sigma: f64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            supersample: 4,
            gain: 1.0,
            offset: 0.0,
            blur_sigma_px: 0.0,
            noise_sigma: 0.0,
        }
    }
}

/// Smooth value noise in [0, 1) on a grid of `cell` metres.
fn value_noise(x: f64, y: f64, cell: f64, seed: u64) -> f64 {
    let (gx, gy) = (x / cell, y / cell);
    let (ix, iy) = (gx.floor(), gy.floor());
    let (fx, fy) = (gx - ix, gy - iy);
    let h = |i: f64, j: f64| {
        let mut z = (i as i64 as u64)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add((j as i64 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
            ^ seed;
        z = (z ^ (z >> 31)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 29;
        (z >> 11) as f64 / (1u64 << 53) as f64
    };
    let sx = fx * fx * (3.0 - 2.0 * fx);
    let sy = fy * fy * (3.0 - 2.0 * fy);
    let a = h(ix, iy) + sx * (h(ix + 1.0, iy) - h(ix, iy));
    let b = h(ix, iy + 1.0) + sx * (h(ix + 1.0, iy + 1.0) - h(ix, iy + 1.0));
    a + sy * (b - a)
}

/// Radiance (grey level before exposure) of the ground point (x, y) world ENU.
fn radiance(scene: &SceneEnu, x: f64, y: f64) -> f64 {
    let p = Enu2::new(x, y);
    if scene.occluders.iter().any(|o| o.contains(&p)) {
        // Canopy: dark and flat, opaque over the tag.
        return 45.0 + 10.0 * value_noise(x, y, 0.7, scene.ground_seed ^ 0x5555);
    }
    if let Some(t) = &scene.target {
        if let Some(v) = t.sample(x, y) {
            // Printed black is not 0, paper white is not 255.
            return 25.0 + v as f64 * (225.0 - 25.0) / 255.0;
        }
    }
    // Asphalt and grass: low-contrast texture at two scales.
    95.0 + 45.0 * value_noise(x, y, 1.3, scene.ground_seed)
        + 15.0 * value_noise(x, y, 0.23, scene.ground_seed ^ 0xABCD)
}

const SKY: f64 = 210.0;

/// Renders the camera's view. `noise_seed` drives the sensor noise only.
pub fn render(
    cam: &CameraModel,
    pose: &VehiclePoseNed,
    scene: &SceneEnu,
    opts: &RenderOptions,
    noise_seed: u64,
) -> GrayImage {
    let (w, h) = (
        cam.intrinsics.width_px as usize,
        cam.intrinsics.height_px as usize,
    );
    let (c, r_nc) = cam.camera_in_ned(pose);
    let s = opts.supersample.max(1);
    let offsets: Vec<f64> = (0..s).map(|i| (i as f64 + 0.5) / s as f64 - 0.5).collect();
    let sample = |u: f64, v: f64| -> f64 {
        let (x, y) = cam.intrinsics.unproject(u, v);
        let d = r_nc * nalgebra::Vector3::new(x, y, 1.0);
        if d.z <= 1e-9 || c.z >= 0.0 {
            SKY
        } else {
            let t = -c.z / d.z;
            // NED ground point -> ENU.
            radiance(scene, c.y + t * d.y, c.x + t * d.x)
        }
    };
    // Adaptive anti-aliasing: radiance at every pixel corner first; a pixel whose corners
    // (or whose neighbours' corners) differ is supersampled, a smooth one is the mean of
    // its corners. The dilation catches a tag corner that pokes into a pixel without
    // covering any of its corners.
    let corners: Vec<f64> = (0..(h + 1) * (w + 1))
        .into_par_iter()
        .map(|i| sample((i % (w + 1)) as f64 - 0.5, (i / (w + 1)) as f64 - 0.5))
        .collect();
    let corner = |u: usize, v: usize| corners[v * (w + 1) + u];
    let busy: Vec<bool> = (0..w * h)
        .map(|i| {
            let (u, v) = (i % w, i / w);
            let c = [
                corner(u, v),
                corner(u + 1, v),
                corner(u, v + 1),
                corner(u + 1, v + 1),
            ];
            let (lo, hi) = c
                .iter()
                .fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
            hi - lo > 1.0
        })
        .collect();
    let mut img = vec![0f64; w * h];
    img.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        for (u, px) in row.iter_mut().enumerate() {
            let near_edge = s > 1
                && (v.saturating_sub(1)..(v + 2).min(h))
                    .any(|vv| (u.saturating_sub(1)..(u + 2).min(w)).any(|uu| busy[vv * w + uu]));
            let value = if near_edge {
                let mut acc = 0.0;
                for &dv in &offsets {
                    for &du in &offsets {
                        acc += sample(u as f64 + du, v as f64 + dv);
                    }
                }
                acc / (s * s) as f64
            } else if s > 1 {
                (corner(u, v) + corner(u + 1, v) + corner(u, v + 1) + corner(u + 1, v + 1)) / 4.0
            } else {
                sample(u as f64, v as f64)
            };
            *px = value * opts.gain + opts.offset;
        }
    });
    if opts.blur_sigma_px > 0.0 {
        img = gaussian_blur(&img, w, h, opts.blur_sigma_px);
    }
    let data: Vec<u8> = if opts.noise_sigma > 0.0 {
        let normal = Normal::new(0.0, opts.noise_sigma).expect("sigma > 0");
        img.par_chunks(w)
            .enumerate()
            .flat_map_iter(|(v, row)| {
                // One stream per row: the same image whatever the thread count.
                let mut rng =
                    CoreRng::seed_from_u64(noise_seed ^ (v as u64).wrapping_mul(0x9E37_79B9));
                row.iter()
                    .map(|&x| (x + normal.sample(&mut rng)).round().clamp(0.0, 255.0) as u8)
                    .collect::<Vec<_>>()
            })
            .collect()
    } else {
        img.iter()
            .map(|&x| x.round().clamp(0.0, 255.0) as u8)
            .collect()
    };
    GrayImage {
        width: w,
        height: h,
        data,
    }
}

fn gaussian_blur(img: &[f64], w: usize, h: usize, sigma: f64) -> Vec<f64> {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f64 = k.iter().sum();
    let k: Vec<f64> = k.iter().map(|x| x / norm).collect();
    let clamp = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    let mut tmp = vec![0.0; w * h];
    tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            *out = (-r..=r)
                .map(|i| k[(i + r) as usize] * img[y * w + clamp(x as isize + i, w)])
                .sum();
        }
    });
    let mut out = vec![0.0; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            *o = (-r..=r)
                .map(|i| k[(i + r) as usize] * tmp[clamp(y as isize + i, h) * w + x])
                .sum();
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::camera_model::{CameraMount, Intrinsics};

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
}
