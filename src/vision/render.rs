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
        // Beyond the circle around the whole tag (white border included) nothing is on it:
        // skips the rotation for nearly every ground point of the frame.
        let half_outer_m =
            0.5 * self.tag_size_m * self.tag.size as f64 / self.tag.black_cells() as f64;
        if dx * dx + dy * dy > 2.0 * half_outer_m * half_outer_m * (1.0 + 1e-9) {
            return None;
        }
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

/// `x.floor()` for |x| < 2^63, inlined: without SSE4.1 in the baseline target `floor` is a
/// libm call, and the renderer makes millions per frame.
#[inline]
fn floor_fast(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// Smooth value noise in [0, 1) on a grid of `cell` metres.
fn value_noise(x: f64, y: f64, cell: f64, seed: u64) -> f64 {
    let (gx, gy) = (x / cell, y / cell);
    let (ix, iy) = (floor_fast(gx), floor_fast(gy));
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

/// The ground point, world ENU, seen along the ray through pixel coordinates (u, v) (pixel
/// centres at integers); None for a ray that does not reach the ground.
fn ground_caster<'a>(
    cam: &'a CameraModel,
    pose: &VehiclePoseNed,
) -> impl Fn(f64, f64) -> Option<[f64; 2]> + Sync + 'a {
    let (c, r_nc) = cam.camera_in_ned(pose);
    move |u: f64, v: f64| {
        let (x, y) = cam.intrinsics.unproject(u, v);
        let d = r_nc * nalgebra::Vector3::new(x, y, 1.0);
        if d.z <= 1e-9 || c.z >= 0.0 {
            return None;
        }
        let t = -c.z / d.z;
        // NED ground point -> ENU.
        Some([c.y + t * d.y, c.x + t * d.x])
    }
}

/// Radiance along the ray through pixel coordinates (u, v) (pixel centres at integers).
fn ray_sampler<'a>(
    cam: &'a CameraModel,
    pose: &VehiclePoseNed,
    scene: &'a SceneEnu,
) -> impl Fn(f64, f64) -> f64 + Sync + 'a {
    let cast = ground_caster(cam, pose);
    move |u: f64, v: f64| cast(u, v).map_or(SKY, |g| radiance(scene, g[0], g[1]))
}

/// Renders the camera's view. `noise_seed` drives the sensor noise only.
// Slightly long: the per-row parallel loop keeps its sampling, noise and blur steps in
// one place so the pixel pipeline reads top to bottom.
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
    let s = opts.supersample.max(1);
    let offsets: Vec<f64> = (0..s).map(|i| (i as f64 + 0.5) / s as f64 - 0.5).collect();
    let sample = ray_sampler(cam, pose, scene);
    // Adaptive anti-aliasing: radiance at every pixel corner first; a pixel whose corners
    // (or whose neighbours' corners) differ is supersampled, a smooth one is the mean of
    // its corners. The dilation catches a tag corner that pokes into a pixel without
    // covering any of its corners.
    let corners = corner_radiance(cam, pose, scene, w, h, &sample);
    let corner = |u: usize, v: usize| corners.values[v * (w + 1) + u];
    let busy: Vec<bool> = (0..w * h)
        .map(|i| {
            let (u, v) = (i % w, i / w);
            // Smooth texture (no edge in the block) is not supersampled however much it
            // varies across a pixel: the mean of its corners is its pixel mean to a fraction
            // of a grey level, and seen from high up every pixel of it varies by more than one.
            if !corners.edgy_at(u, v) {
                return false;
            }
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

/// The ground point (world ENU) under a pixel corner and what is there (0 ground, 1 tag,
/// 2 + i occluder i); None: sky.
type Seen = Option<([f64; 2], u8)>;

/// Pixels per side of the blocks in which smooth ground is interpolated.
const BLOCK_PX: usize = 8;

/// The radiance at every pixel corner, and which blocks have an edge in them.
struct Corners {
    /// Radiance, (w + 1) x (h + 1), row-major.
    values: Vec<f64>,
    /// Per block of [`BLOCK_PX`] (row-major, `blocks_x` per row): something has an edge in
    /// it or next to it (an outline, the tag, a change of what is seen, the sky).
    edgy: Vec<bool>,
    /// Blocks per row.
    blocks_x: usize,
    /// Corners interpolated rather than evaluated (reported by the tests).
    #[cfg_attr(not(test), allow(dead_code))]
    interpolated: usize,
}

impl Corners {
    /// Whether pixel (u, v) lies in a block with an edge.
    fn edgy_at(&self, u: usize, v: usize) -> bool {
        self.edgy[(v / BLOCK_PX) * self.blocks_x + (u / BLOCK_PX).min(self.blocks_x - 1)]
    }
}

/// Longest ground side of a block that is interpolated, m: the ground texture's finest
/// scale is 0.23 m, over which a bilinear fit of 2 cm errs by ~0.1 grey level.
const SMOOTH_BLOCK_M: f64 = 0.02;

/// Radiance at every pixel corner ((w + 1) x (h + 1), row-major, corner (u, v) at pixel
/// coordinates (u - 0.5, v - 0.5)). Exact wherever something has an edge: blocks of
/// [`BLOCK_PX`] px crossed by an occluder's outline or covering the tag, blocks whose corners
/// see different things (ground, occluder, tag, sky), and blocks wider than
/// [`SMOOTH_BLOCK_M`] on the ground (high altitude: every block). Elsewhere the ground is
/// smooth at the block's scale and its corners are interpolated from the block's. The
/// result differs from evaluating every corner by well under a grey level (tested), at a
/// fraction of the cost when the camera is low.
// Long because it is the renderer's hot kernel: the block classification, the exact
// corners and the interpolated ones share local closures and buffers that would otherwise
// be passed around per pixel.
fn corner_radiance(
    cam: &CameraModel,
    pose: &VehiclePoseNed,
    scene: &SceneEnu,
    w: usize,
    h: usize,
    sample: &(impl Fn(f64, f64) -> f64 + Sync),
) -> Corners {
    let b = BLOCK_PX;
    let (nbx, nby) = (w.div_ceil(b), h.div_ceil(b));
    let xs: Vec<usize> = (0..=nbx).map(|i| (i * b).min(w)).collect();
    let ys: Vec<usize> = (0..=nby).map(|j| (j * b).min(h)).collect();
    let cast = ground_caster(cam, pose);
    // Ground point (world ENU) and what is there, at a pixel corner.
    let look = |u: usize, v: usize| -> Seen {
        let g = cast(u as f64 - 0.5, v as f64 - 0.5)?;
        let p = Enu2::new(g[0], g[1]);
        let class = if let Some(i) = scene.occluders.iter().position(|o| o.contains(&p)) {
            2 + i.min(250) as u8
        } else if scene
            .target
            .as_ref()
            .is_some_and(|t| t.sample(g[0], g[1]).is_some())
        {
            1
        } else {
            0
        };
        Some((g, class))
    };
    let coarse: Vec<(f64, Seen)> = (0..(nbx + 1) * (nby + 1))
        .into_par_iter()
        .map(|i| {
            let seen = look(xs[i % (nbx + 1)], ys[i / (nbx + 1)]);
            (seen.map_or(SKY, |(g, _)| radiance(scene, g[0], g[1])), seen)
        })
        .collect();
    let at = |i: usize, j: usize| &coarse[j * (nbx + 1) + i];
    // Per block: (has an edge, must be evaluated exactly).
    let (mut edgy, mut exact): (Vec<bool>, Vec<bool>) = (0..nbx * nby)
        .map(|k| {
            let (i, j) = (k % nbx, k / nbx);
            let q = [at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)];
            let Some(g) = q.iter().map(|x| x.1).collect::<Option<Vec<_>>>() else {
                return (true, true);
            };
            // Sides: top, bottom, left, right.
            let side = |a: usize, z: usize| (g[a].0[0] - g[z].0[0]).hypot(g[a].0[1] - g[z].0[1]);
            let edge = g.iter().any(|x| x.1 != g[0].1);
            let coarse = [(0, 1), (2, 3), (0, 2), (1, 3)]
                .iter()
                .any(|&(a, z)| side(a, z) > SMOOTH_BLOCK_M);
            (edge, edge || coarse)
        })
        .unzip();
    let mut mark = |px: [f64; 2], margin: usize| {
        if !(px[0] > -1.0 && px[1] > -1.0 && px[0] < w as f64 + 1.0 && px[1] < h as f64 + 1.0) {
            return;
        }
        let (bi, bj) = (
            ((px[0].max(0.0) as usize) / b).min(nbx - 1),
            ((px[1].max(0.0) as usize) / b).min(nby - 1),
        );
        for j in bj.saturating_sub(margin)..=(bj + margin).min(nby - 1) {
            for i in bi.saturating_sub(margin)..=(bi + margin).min(nbx - 1) {
                exact[j * nbx + i] = true;
                edgy[j * nbx + i] = true;
            }
        }
    };
    // Walk every outline on the ground in steps of under a quarter block.
    let height_m = (-cam.camera_in_ned(pose).0.z).max(1e-3);
    let step_m = 0.25 * b as f64 * height_m / cam.intrinsics.fx_px.max(cam.intrinsics.fy_px);
    let mut outline = |a: [f64; 2], z: [f64; 2]| {
        let n = (((z[0] - a[0]).hypot(z[1] - a[1]) / step_m).ceil() as usize).clamp(1, 100_000);
        for k in 0..=n {
            let f = k as f64 / n as f64;
            let p = [a[0] + f * (z[0] - a[0]), a[1] + f * (z[1] - a[1])];
            if let Some(px) = cam.world_enu_to_pixel(p, 0.0, pose) {
                mark(px, 1);
            }
        }
    };
    for o in &scene.occluders {
        let v = o.vertices();
        for k in 0..v.len() {
            let (a, z) = (v[k], v[(k + 1) % v.len()]);
            outline([a.x, a.y], [z.x, z.y]);
        }
    }
    if let Some(t) = &scene.target {
        // The whole tag (white border included): its cell edges are inside.
        let grow = t.tag.size as f64 / t.tag.black_cells() as f64;
        let k = t.corners_enu().map(|q| {
            [
                t.position_enu_m[0] + grow * (q[0] - t.position_enu_m[0]),
                t.position_enu_m[1] + grow * (q[1] - t.position_enu_m[1]),
            ]
        });
        let px: Vec<[f64; 2]> = k
            .iter()
            .filter_map(|q| cam.world_enu_to_pixel(*q, 0.0, pose))
            .collect();
        if px.len() < 4 {
            exact.iter_mut().for_each(|e| *e = true);
            edgy.iter_mut().for_each(|e| *e = true);
        } else {
            let lo = px
                .iter()
                .fold([f64::MAX; 2], |m, p| [m[0].min(p[0]), m[1].min(p[1])]);
            let hi = px
                .iter()
                .fold([f64::MIN; 2], |m, p| [m[0].max(p[0]), m[1].max(p[1])]);
            let (lo, hi) = (
                [lo[0].max(0.0), lo[1].max(0.0)],
                [hi[0].min(w as f64), hi[1].min(h as f64)],
            );
            let mut v = lo[1];
            while v <= hi[1] + b as f64 {
                let mut u = lo[0];
                while u <= hi[0] + b as f64 {
                    mark([u.min(w as f64), v.min(h as f64)], 1);
                    u += b as f64;
                }
                v += b as f64;
            }
        }
    }
    // Every corner of an exact block is evaluated; the others are interpolated within their
    // block (shared edges of smooth blocks agree: both interpolate linearly along them).
    let mut need = vec![false; (w + 1) * (h + 1)];
    for (k, _) in exact.iter().enumerate().filter(|(_, e)| **e) {
        let (i, j) = (k % nbx, k / nbx);
        for v in ys[j]..=ys[j + 1] {
            need[v * (w + 1) + xs[i]..=v * (w + 1) + xs[i + 1]]
                .iter_mut()
                .for_each(|n| *n = true);
        }
    }
    let interpolated = need.iter().filter(|n| !**n).count();
    let values = (0..(h + 1) * (w + 1))
        .into_par_iter()
        .map(|idx| {
            let (u, v) = (idx % (w + 1), idx / (w + 1));
            if need[idx] {
                return sample(u as f64 - 0.5, v as f64 - 0.5);
            }
            let (i, j) = ((u / b).min(nbx - 1), (v / b).min(nby - 1));
            let fx = (u - xs[i]) as f64 / (xs[i + 1] - xs[i]) as f64;
            let fy = (v - ys[j]) as f64 / (ys[j + 1] - ys[j]) as f64;
            let top = at(i, j).0 + fx * (at(i + 1, j).0 - at(i, j).0);
            let bottom = at(i, j + 1).0 + fx * (at(i + 1, j + 1).0 - at(i, j + 1).0);
            top + fy * (bottom - top)
        })
        .collect();
    Corners {
        values,
        edgy,
        blocks_x: nbx,
        interpolated,
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
        let corners = corner_radiance(&cam, &high, &bare, 320, 180, &sample);
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
        let corners = corner_radiance(&cam, &high, &tagged, 320, 180, &sample);
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
            } = corner_radiance(&cam, &pose, &scene, 640, 480, &sample);
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
}
