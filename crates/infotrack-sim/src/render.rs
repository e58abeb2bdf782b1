//! The synthetic camera: what the drone's camera sees for a vehicle pose and the true
//! target pose, rendered by casting each (supersampled) pixel's ray onto the ground plane
//! through the same intrinsics, distortion and mount the projection uses. A textured
//! ground, the target's tag drawn perspective-correct, occlusion regions drawn opaque over
//! everything, then exposure, blur and sensor noise.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use infotrack_core::rng::CoreRng;
use infotrack_core::world::geometry::{Enu2, PolygonEnu};
use infotrack_vision::camera_model::{CameraModel, VehiclePoseNed};
use infotrack_vision::image::{FrameSource, GrayImage, PixelRect};
use infotrack_vision::tag_family::TagBitmap;

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

    /// Half the side of the whole tag, white border included, m.
    fn half_outer_m(&self) -> f64 {
        0.5 * self.tag_size_m * self.tag.size as f64 / self.tag.black_cells() as f64
    }

    /// The radius of the circle around the whole tag, m: no ground point beyond it is on
    /// the tag ([`Self::sample`] says `None` there).
    pub fn reach_m(&self) -> f64 {
        std::f64::consts::SQRT_2 * self.half_outer_m() * (1.0 + 1e-6)
    }

    /// Whether an occluder covers the square around the whole tag (half side
    /// [`Self::reach_m`]): its canopy is drawn over every point of the tag, so no pixel shows
    /// any of it and the renderer treats the scene as one without the target.
    pub fn hidden_by(&self, occluders: &[PolygonEnu]) -> bool {
        let [x, y] = self.position_enu_m;
        let centre = Enu2::new(x, y);
        occluders
            .iter()
            .any(|o| o.contains_square(&centre, self.reach_m()))
    }

    /// Cell value under a world ENU ground point, if it falls on the tag.
    fn sample(&self, x: f64, y: f64) -> Option<u8> {
        let (dx, dy) = (x - self.position_enu_m[0], y - self.position_enu_m[1]);
        // Beyond the circle around the whole tag (white border included) nothing is on it:
        // skips the rotation for nearly every ground point of the frame.
        let half_outer_m = self.half_outer_m();
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
    render_region(cam, pose, scene, opts, noise_seed, PixelRect::full(w, h))
}

/// Per pixel of `judged` (row-major): whether its corners differ by more than a grey
/// level in a block with an edge, so that it and its neighbours are supersampled.
fn busy_pixels(corners: &Corners, judged: PixelRect) -> Vec<bool> {
    let corner = |u: usize, v: usize| corners.at(u, v);
    let jw = judged.width();
    (0..jw * judged.height())
        .map(|i| {
            let (u, v) = (judged.x0 + i % jw, judged.y0 + i / jw);
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
        .collect()
}

/// Renders the pixels of `region` only: exactly the pixels [`render`] draws there (the
/// blur's and the anti-aliasing's neighbourhoods and each row's noise stream are taken as
/// the whole frame has them), at the cost of the region and its margins.
pub fn render_region(
    cam: &CameraModel,
    pose: &VehiclePoseNed,
    scene: &SceneEnu,
    opts: &RenderOptions,
    noise_seed: u64,
    region: PixelRect,
) -> GrayImage {
    let (w, h) = (
        cam.intrinsics.width_px as usize,
        cam.intrinsics.height_px as usize,
    );
    let blur_radius = blur_radius_px(opts.blur_sigma_px);
    // Before the blur: the region and the blur's reach; whether a pixel is near an edge
    // looks at its 8 neighbours, whose corners lie one more pixel out.
    let drawn = region.grown(blur_radius, w, h);
    let judged = drawn.grown(1, w, h);
    let s = opts.supersample.max(1);
    let offsets: Vec<f64> = (0..s).map(|i| (i as f64 + 0.5) / s as f64 - 0.5).collect();
    let sample = ray_sampler(cam, pose, scene);
    // Adaptive anti-aliasing: radiance at every pixel corner first; a pixel whose corners
    // (or whose neighbours' corners) differ is supersampled, a smooth one is the mean of
    // its corners. The dilation catches a tag corner that pokes into a pixel without
    // covering any of its corners.
    let corners = corner_radiance(cam, pose, scene, w, h, judged, &sample);
    let corner = |u: usize, v: usize| corners.at(u, v);
    let jw = judged.width();
    let busy = busy_pixels(&corners, judged);
    let is_busy = |u: usize, v: usize| busy[(v - judged.y0) * jw + (u - judged.x0)];
    let mut img = vec![0f64; drawn.width() * drawn.height()];
    img.par_chunks_mut(drawn.width())
        .enumerate()
        .for_each(|(row_index, row)| {
            let v = drawn.y0 + row_index;
            for (k, px) in row.iter_mut().enumerate() {
                let u = drawn.x0 + k;
                let near_edge = s > 1
                    && (v.saturating_sub(1)..(v + 2).min(h))
                        .any(|vv| (u.saturating_sub(1)..(u + 2).min(w)).any(|uu| is_busy(uu, vv)));
                let value = if near_edge {
                    let mut acc = 0.0;
                    for &dv in &offsets {
                        for &du in &offsets {
                            acc += sample(u as f64 + du, v as f64 + dv);
                        }
                    }
                    acc / (s * s) as f64
                } else if s > 1 {
                    (corner(u, v) + corner(u + 1, v) + corner(u, v + 1) + corner(u + 1, v + 1))
                        / 4.0
                } else {
                    sample(u as f64, v as f64)
                };
                *px = value * opts.gain + opts.offset;
            }
        });
    let img = if blur_radius > 0 {
        gaussian_blur(&img, drawn, region, w, h, opts.blur_sigma_px)
    } else {
        img
    };
    GrayImage {
        width: region.width(),
        height: region.height(),
        data: quantise(&img, region, opts.noise_sigma, noise_seed),
    }
}

/// A synthetic frame rendered where it is looked at: a region of interest costs its own
/// pixels, the whole frame is rendered only when asked for (and then kept). Every pixel is
/// the one [`render`] draws there.
pub struct RenderedFrame<'a> {
    cam: &'a CameraModel,
    pose: &'a VehiclePoseNed,
    scene: &'a SceneEnu,
    opts: &'a RenderOptions,
    noise_seed: u64,
    whole: Option<GrayImage>,
    /// Time spent rendering so far (wall clock, for reports), ms.
    pub render_ms: f64,
}

impl<'a> RenderedFrame<'a> {
    /// The frame the camera sees from `pose`, nothing rendered yet.
    pub fn new(
        cam: &'a CameraModel,
        pose: &'a VehiclePoseNed,
        scene: &'a SceneEnu,
        opts: &'a RenderOptions,
        noise_seed: u64,
    ) -> Self {
        Self {
            cam,
            pose,
            scene,
            opts,
            noise_seed,
            whole: None,
            render_ms: 0.0,
        }
    }

    /// Whether no pixel of this frame can show the tag: the scene has none, an occluder
    /// hides it ([`TargetAppearance::hidden_by`], whatever the lens), or the square around
    /// the whole tag ([`TargetAppearance::reach_m`]) lies beyond one side of the frame by
    /// more than a block of the renderer's corner grid and a pixel (a tag that close to the
    /// frame still decides which of its blocks are evaluated exactly, and so the frame's last
    /// grey level). Then every pixel is the one a scene without the target gives (tested).
    /// The last is decided only for a lens without distortion, where the ground maps to the
    /// image by a homography: the square's corners all in front of the camera, their hull
    /// holds the projected tag. With distortion, `false` (the frame is searched as any
    /// other).
    pub fn holds_no_tag(&self) -> bool {
        let Some(t) = &self.scene.target else {
            return true;
        };
        if t.hidden_by(&self.scene.occluders) {
            return true;
        }
        if self.cam.intrinsics.has_distortion() {
            return false;
        }
        let r = t.reach_m();
        let [x, y] = t.position_enu_m;
        let mut corners = [[0.0; 2]; 4];
        for (k, (dx, dy)) in [(-r, -r), (r, -r), (r, r), (-r, r)].into_iter().enumerate() {
            match self
                .cam
                .world_enu_to_pixel([x + dx, y + dy], 0.0, self.pose)
            {
                Some(px) => corners[k] = px,
                None => return false,
            }
        }
        let (w, h) = self.size();
        let margin = (BLOCK_PX + 2) as f64;
        let all = |f: &dyn Fn(&[f64; 2]) -> bool| corners.iter().all(f);
        all(&|p| p[0] < -margin)
            || all(&|p| p[1] < -margin)
            || all(&|p| p[0] > w as f64 + margin)
            || all(&|p| p[1] > h as f64 + margin)
    }

    fn timed<T>(&mut self, f: impl FnOnce(&Self) -> T) -> T {
        let t0 = std::time::Instant::now();
        let out = f(self);
        self.render_ms += t0.elapsed().as_secs_f64() * 1e3;
        out
    }
}

impl FrameSource for RenderedFrame<'_> {
    fn size(&self) -> (usize, usize) {
        let i = &self.cam.intrinsics;
        (i.width_px as usize, i.height_px as usize)
    }

    fn crop(&mut self, x0: usize, y0: usize, w: usize, h: usize) -> GrayImage {
        if let Some(whole) = &self.whole {
            return whole.crop(x0, y0, w, h);
        }
        let (width, height) = self.size();
        let r = PixelRect::clipped(x0, y0, w, h, width, height);
        self.timed(|f| render_region(f.cam, f.pose, f.scene, f.opts, f.noise_seed, r))
    }

    fn holds_no_tag(&self) -> bool {
        RenderedFrame::holds_no_tag(self)
    }

    fn full(&mut self) -> &GrayImage {
        if self.whole.is_none() {
            let img = self.timed(|f| render(f.cam, f.pose, f.scene, f.opts, f.noise_seed));
            self.whole = Some(img);
        }
        self.whole.as_ref().expect("rendered above")
    }
}

/// The region's grey levels to 8 bits, with sensor noise drawn from each row's own stream
/// (seeded by the row, consumed from the frame's first column): the same pixels whatever
/// the region and the thread count.
fn quantise(img: &[f64], region: PixelRect, noise_sigma: f64, noise_seed: u64) -> Vec<u8> {
    let to_u8 = |x: f64| x.round().clamp(0.0, 255.0) as u8;
    if noise_sigma <= 0.0 {
        return img.iter().map(|&x| to_u8(x)).collect();
    }
    let normal = Normal::new(0.0, noise_sigma).expect("sigma > 0");
    img.par_chunks(region.width())
        .enumerate()
        .flat_map_iter(|(row_index, row)| {
            let v = region.y0 + row_index;
            let mut rng = CoreRng::seed_from_u64(noise_seed ^ (v as u64).wrapping_mul(0x9E37_79B9));
            // The columns left of the region draw their noise too, so that each pixel gets
            // the draw the whole frame gives it.
            for _ in 0..region.x0 {
                let _: f64 = normal.sample(&mut rng);
            }
            row.iter()
                .map(|&x| to_u8(x + normal.sample(&mut rng)))
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The ground point (world ENU) under a pixel corner and what is there (0 ground, 1 tag,
/// 2 + i occluder i); None: sky.
type Seen = Option<([f64; 2], u8)>;

/// Pixels per side of the blocks in which smooth ground is interpolated.
const BLOCK_PX: usize = 8;

/// The radiance at the pixel corners of a rectangle of pixels, and which blocks of the
/// frame have an edge in them.
struct Corners {
    /// Radiance at corners `x0..=x1` x `y0..=y1` of the rectangle, row-major.
    values: Vec<f64>,
    /// The pixels whose corners `values` holds.
    pixels: PixelRect,
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
    /// Radiance at corner (u, v) (frame coordinates), which must be one of the rectangle's.
    fn at(&self, u: usize, v: usize) -> f64 {
        let stride = self.pixels.width() + 1;
        self.values[(v - self.pixels.y0) * stride + (u - self.pixels.x0)]
    }

    /// Whether pixel (u, v) lies in a block with an edge.
    fn edgy_at(&self, u: usize, v: usize) -> bool {
        self.edgy[(v / BLOCK_PX) * self.blocks_x + (u / BLOCK_PX).min(self.blocks_x - 1)]
    }
}

/// Longest ground side of a block that is interpolated, m: the ground texture's finest
/// scale is 0.23 m, over which a bilinear fit of 2 cm errs by ~0.1 grey level.
const SMOOTH_BLOCK_M: f64 = 0.02;

/// Radiance at the corners of the pixels in `pixels` (corner (u, v) at pixel coordinates
/// (u - 0.5, v - 0.5)). Exact wherever something has an edge: blocks of
/// [`BLOCK_PX`] px crossed by an occluder's outline or covering the tag, blocks whose corners
/// see different things (ground, occluder, tag, sky), and blocks wider than
/// [`SMOOTH_BLOCK_M`] on the ground (high altitude: every block). Elsewhere the ground is
/// smooth at the block's scale and its corners are interpolated from the block's. The
/// result differs from evaluating every corner by well under a grey level (tested), at a
/// fraction of the cost when the camera is low.
fn corner_radiance(
    cam: &CameraModel,
    pose: &VehiclePoseNed,
    scene: &SceneEnu,
    w: usize,
    h: usize,
    pixels: PixelRect,
    sample: &(impl Fn(f64, f64) -> f64 + Sync),
) -> Corners {
    let grid = BlockGrid::new(w, h);
    let coarse = coarse_corners(cam, pose, scene, &grid);
    let mut blocks = Blocks::classified(&grid, &coarse);
    blocks.mark_outlines(cam, pose, scene, &grid);
    blocks.mark_tag(cam, pose, scene, &grid);
    let (values, interpolated) = interpolate(&grid, &coarse, &blocks.exact, pixels, sample);
    Corners {
        values,
        pixels,
        edgy: blocks.edgy,
        blocks_x: grid.nbx,
        interpolated,
    }
}

/// The frame cut into blocks of [`BLOCK_PX`] px: their number along each side and the pixel
/// corners where they start (the last ones end at the frame's edge).
struct BlockGrid {
    w: usize,
    h: usize,
    nbx: usize,
    nby: usize,
    xs: Vec<usize>,
    ys: Vec<usize>,
}

impl BlockGrid {
    fn new(w: usize, h: usize) -> Self {
        let b = BLOCK_PX;
        let (nbx, nby) = (w.div_ceil(b), h.div_ceil(b));
        Self {
            w,
            h,
            nbx,
            nby,
            xs: (0..=nbx).map(|i| (i * b).min(w)).collect(),
            ys: (0..=nby).map(|j| (j * b).min(h)).collect(),
        }
    }
}

/// At each block corner: its radiance, and the ground point (world ENU) and what is there
/// (0 ground, 1 tag, 2 + i occluder i; `None`: sky).
fn coarse_corners(
    cam: &CameraModel,
    pose: &VehiclePoseNed,
    scene: &SceneEnu,
    grid: &BlockGrid,
) -> Vec<(f64, Seen)> {
    let cast = ground_caster(cam, pose);
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
    let nx = grid.nbx + 1;
    (0..nx * (grid.nby + 1))
        .into_par_iter()
        .map(|i| {
            let seen = look(grid.xs[i % nx], grid.ys[i / nx]);
            (seen.map_or(SKY, |(g, _)| radiance(scene, g[0], g[1])), seen)
        })
        .collect()
}

/// Per block: whether it has an edge, and whether its corners must be evaluated exactly.
struct Blocks {
    edgy: Vec<bool>,
    exact: Vec<bool>,
}

impl Blocks {
    /// From the block corners: an edge where the corners see different things (or sky), exact
    /// also where the block is wider than [`SMOOTH_BLOCK_M`] on the ground.
    fn classified(grid: &BlockGrid, coarse: &[(f64, Seen)]) -> Self {
        let at = |i: usize, j: usize| &coarse[j * (grid.nbx + 1) + i];
        let (edgy, exact) = (0..grid.nbx * grid.nby)
            .map(|k| {
                let (i, j) = (k % grid.nbx, k / grid.nbx);
                let q = [at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)];
                let Some(g) = q.iter().map(|x| x.1).collect::<Option<Vec<_>>>() else {
                    return (true, true);
                };
                // Sides: top, bottom, left, right.
                let side =
                    |a: usize, z: usize| (g[a].0[0] - g[z].0[0]).hypot(g[a].0[1] - g[z].0[1]);
                let edge = g.iter().any(|x| x.1 != g[0].1);
                let coarse = [(0, 1), (2, 3), (0, 2), (1, 3)]
                    .iter()
                    .any(|&(a, z)| side(a, z) > SMOOTH_BLOCK_M);
                (edge, edge || coarse)
            })
            .unzip();
        Self { edgy, exact }
    }

    /// Marks the block holding pixel `px` and those within `margin` blocks of it as edgy
    /// and exact.
    fn mark(&mut self, grid: &BlockGrid, px: [f64; 2], margin: usize) {
        let (w, h) = (grid.w as f64, grid.h as f64);
        if !(px[0] > -1.0 && px[1] > -1.0 && px[0] < w + 1.0 && px[1] < h + 1.0) {
            return;
        }
        let b = BLOCK_PX;
        let (bi, bj) = (
            ((px[0].max(0.0) as usize) / b).min(grid.nbx - 1),
            ((px[1].max(0.0) as usize) / b).min(grid.nby - 1),
        );
        for j in bj.saturating_sub(margin)..=(bj + margin).min(grid.nby - 1) {
            for i in bi.saturating_sub(margin)..=(bi + margin).min(grid.nbx - 1) {
                self.exact[j * grid.nbx + i] = true;
                self.edgy[j * grid.nbx + i] = true;
            }
        }
    }

    /// Every occluder's outline, walked on the ground in steps of under a quarter block.
    fn mark_outlines(
        &mut self,
        cam: &CameraModel,
        pose: &VehiclePoseNed,
        scene: &SceneEnu,
        grid: &BlockGrid,
    ) {
        let height_m = (-cam.camera_in_ned(pose).0.z).max(1e-3);
        let step_m =
            0.25 * BLOCK_PX as f64 * height_m / cam.intrinsics.fx_px.max(cam.intrinsics.fy_px);
        for o in &scene.occluders {
            let v = o.vertices();
            for k in 0..v.len() {
                let (a, z) = (v[k], v[(k + 1) % v.len()]);
                let n = (((z.x - a.x).hypot(z.y - a.y) / step_m).ceil() as usize).clamp(1, 100_000);
                for s in 0..=n {
                    let f = s as f64 / n as f64;
                    let p = [a.x + f * (z.x - a.x), a.y + f * (z.y - a.y)];
                    if let Some(px) = cam.world_enu_to_pixel(p, 0.0, pose) {
                        self.mark(grid, px, 1);
                    }
                }
            }
        }
    }

    /// The blocks the whole tag (white border included) covers; every block when the tag is
    /// partly behind the camera. A tag hidden under a canopy has no edge to show: its blocks
    /// stay as the bare scene's.
    fn mark_tag(
        &mut self,
        cam: &CameraModel,
        pose: &VehiclePoseNed,
        scene: &SceneEnu,
        grid: &BlockGrid,
    ) {
        let Some(t) = scene
            .target
            .as_ref()
            .filter(|t| !t.hidden_by(&scene.occluders))
        else {
            return;
        };
        let grow = t.tag.size as f64 / t.tag.black_cells() as f64;
        let px: Vec<[f64; 2]> = t
            .corners_enu()
            .iter()
            .map(|q| {
                [
                    t.position_enu_m[0] + grow * (q[0] - t.position_enu_m[0]),
                    t.position_enu_m[1] + grow * (q[1] - t.position_enu_m[1]),
                ]
            })
            .filter_map(|q| cam.world_enu_to_pixel(q, 0.0, pose))
            .collect();
        if px.len() < 4 {
            self.exact.iter_mut().for_each(|e| *e = true);
            self.edgy.iter_mut().for_each(|e| *e = true);
            return;
        }
        let lo = px
            .iter()
            .fold([f64::MAX; 2], |m, p| [m[0].min(p[0]), m[1].min(p[1])]);
        let hi = px
            .iter()
            .fold([f64::MIN; 2], |m, p| [m[0].max(p[0]), m[1].max(p[1])]);
        let (w, h, b) = (grid.w as f64, grid.h as f64, BLOCK_PX as f64);
        let (lo, hi) = (
            [lo[0].max(0.0), lo[1].max(0.0)],
            [hi[0].min(w), hi[1].min(h)],
        );
        let mut v = lo[1];
        while v <= hi[1] + b {
            let mut u = lo[0];
            while u <= hi[0] + b {
                self.mark(grid, [u.min(w), v.min(h)], 1);
                u += b;
            }
            v += b;
        }
    }
}

/// The radiance at every corner of `pixels`: sampled at the corners of exact blocks,
/// interpolated within the others (shared edges of smooth blocks agree: both interpolate
/// linearly along them); and how many were interpolated.
fn interpolate(
    grid: &BlockGrid,
    coarse: &[(f64, Seen)],
    exact: &[bool],
    pixels: PixelRect,
    sample: &(impl Fn(f64, f64) -> f64 + Sync),
) -> (Vec<f64>, usize) {
    let need = corners_to_sample(grid, exact, pixels);
    let interpolated = need.iter().filter(|n| !**n).count();
    let (b, nbx, nby) = (BLOCK_PX, grid.nbx, grid.nby);
    let (xs, ys) = (&grid.xs, &grid.ys);
    let at = |i: usize, j: usize| coarse[j * (nbx + 1) + i].0;
    let cw = pixels.width() + 1;
    let values = (0..cw * (pixels.height() + 1))
        .into_par_iter()
        .map(|idx| {
            let (u, v) = (pixels.x0 + idx % cw, pixels.y0 + idx / cw);
            if need[idx] {
                return sample(u as f64 - 0.5, v as f64 - 0.5);
            }
            let (i, j) = ((u / b).min(nbx - 1), (v / b).min(nby - 1));
            let fx = (u - xs[i]) as f64 / (xs[i + 1] - xs[i]) as f64;
            let fy = (v - ys[j]) as f64 / (ys[j + 1] - ys[j]) as f64;
            let top = at(i, j) + fx * (at(i + 1, j) - at(i, j));
            let bottom = at(i, j + 1) + fx * (at(i + 1, j + 1) - at(i, j + 1));
            top + fy * (bottom - top)
        })
        .collect();
    (values, interpolated)
}

/// Which corners of `pixels` (row-major) lie on an exact block and are sampled.
fn corners_to_sample(grid: &BlockGrid, exact: &[bool], pixels: PixelRect) -> Vec<bool> {
    let (cw, ch) = (pixels.width() + 1, pixels.height() + 1);
    let mut need = vec![false; cw * ch];
    for (k, _) in exact.iter().enumerate().filter(|(_, e)| **e) {
        let (i, j) = (k % grid.nbx, k / grid.nbx);
        let (u0, u1) = (grid.xs[i].max(pixels.x0), grid.xs[i + 1].min(pixels.x1));
        let (v0, v1) = (grid.ys[j].max(pixels.y0), grid.ys[j + 1].min(pixels.y1));
        if u0 > u1 || v0 > v1 {
            continue;
        }
        for v in v0..=v1 {
            let row = (v - pixels.y0) * cw;
            need[row + u0 - pixels.x0..=row + u1 - pixels.x0]
                .iter_mut()
                .for_each(|n| *n = true);
        }
    }
    need
}

/// How far the blur kernel reaches, px (0: no blur).
fn blur_radius_px(sigma_px: f64) -> usize {
    if sigma_px > 0.0 {
        (3.0 * sigma_px).ceil() as usize
    } else {
        0
    }
}

/// The separable Gaussian blur of the frame, at the pixels of `out` only, from the pixels
/// of `drawn` (which holds `out` and the kernel's reach around it, within the frame); the
/// frame's edges are extended as the whole frame's blur extends them.
fn gaussian_blur(
    img: &[f64],
    drawn: PixelRect,
    out: PixelRect,
    w: usize,
    h: usize,
    sigma: f64,
) -> Vec<f64> {
    let r = blur_radius_px(sigma) as isize;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f64 = k.iter().sum();
    let k: Vec<f64> = k.iter().map(|x| x / norm).collect();
    let clamp = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    let dw = drawn.width();
    let ow = out.width();
    // Along rows, for every drawn row, at the output's columns.
    let mut tmp = vec![0.0; ow * drawn.height()];
    tmp.par_chunks_mut(ow).enumerate().for_each(|(row, line)| {
        for (c, o) in line.iter_mut().enumerate() {
            let x = (out.x0 + c) as isize;
            *o = (-r..=r)
                .map(|i| k[(i + r) as usize] * img[row * dw + clamp(x + i, w) - drawn.x0])
                .sum();
        }
    });
    // Along columns, at the output's rows.
    let mut blurred = vec![0.0; ow * out.height()];
    blurred
        .par_chunks_mut(ow)
        .enumerate()
        .for_each(|(row, line)| {
            let y = (out.y0 + row) as isize;
            for (c, o) in line.iter_mut().enumerate() {
                *o = (-r..=r)
                    .map(|i| k[(i + r) as usize] * tmp[(clamp(y + i, h) - drawn.y0) * ow + c])
                    .sum();
            }
        });
    blurred
}

#[cfg(test)]
mod tests;
