//! Tag detection behind one small trait, with the AprilRobotics C library (AprilTag 3,
//! through the `apriltag` crate, built from its bundled source) as the detector, and a
//! region-of-interest search around where the filter expects the target.
//!
//! Why this detector: measured on this kind of machine (one thread, noisy synthetic frames),
//! it gave 0.05 px median corner error at ~15 ms (640x480); OpenCV 4.6's aruco
//! (DICT_APRILTAG_36h11) was slower and 5x less accurate, and a pure-Rust port missed tags
//! at full resolution. Speed comes from the region of interest instead.

use crate::InvalidSetting;
use serde::{Deserialize, Serialize};

use super::image::{FrameSource, GrayImage};
use super::VisionError;

/// One detected tag, in OpenCV's pixel convention (pixel centres at integers).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TagDetection {
    /// Tag id.
    pub id: u32,
    /// Centre, px.
    pub center_px: [f64; 2],
    /// Corners in the tag's own order (the AprilTag library's p[0..3]), px.
    pub corners_px: [[f64; 2]; 4],
    /// Bits corrected while decoding.
    pub hamming: u32,
    /// The library's decision margin (higher: more confident).
    pub decision_margin: f64,
}

impl TagDetection {
    /// Mean side length, px.
    pub fn side_px(&self) -> f64 {
        (0..4)
            .map(|i| {
                let (a, b) = (self.corners_px[i], self.corners_px[(i + 1) % 4]);
                (a[0] - b[0]).hypot(a[1] - b[1])
            })
            .sum::<f64>()
            / 4.0
    }

    fn shifted(mut self, dx: f64, dy: f64) -> Self {
        self.center_px[0] += dx;
        self.center_px[1] += dy;
        for c in &mut self.corners_px {
            c[0] += dx;
            c[1] += dy;
        }
        self
    }
}

/// A tag detector.
pub trait TagDetector {
    /// Short name for reports.
    fn name(&self) -> &'static str;
    /// All tags of the configured family in the image.
    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, VisionError>;

    /// As [`TagDetector::detect`], but quads may be searched on the image decimated by
    /// `factor` when that is coarser than the configured decimation: for tags known to be
    /// large in the image, where the fine search costs time and finds nothing more. A detector
    /// without such a setting searches as `detect` does.
    fn detect_decimated(
        &mut self,
        image: &GrayImage,
        factor: f32,
    ) -> Result<Vec<TagDetection>, VisionError> {
        let _ = factor;
        self.detect(image)
    }
}

/// AprilTag detector settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DetectorConfig {
    /// Quad detection on an image decimated by this factor (decoding stays at full
    /// resolution and edges are refined on it, so accuracy is kept).
    pub decimation: f32,
    /// Gaussian blur before quad detection, px (0: none).
    pub quad_sigma: f32,
    /// Most bits corrected for a detection to count (0-2). More finds damaged tags and
    /// accepts more false ones.
    pub max_hamming: u32,
    /// Decision margin below which a detection is dropped.
    pub min_decision_margin: f64,
    /// Detector threads.
    pub threads: u8,
    /// The coarsest decimation the full-frame search may use when the tag is expected to be
    /// large in the image (at least 16 px per decimated pixel row of the tag's side): the
    /// full frame is where the time goes when the target is not where the filter predicts,
    /// and edges are refined at full resolution either way. 1 or the `decimation` turns this
    /// off.
    #[serde(default = "default_max_full_frame_decimation")]
    pub max_full_frame_decimation: f32,
}

fn default_max_full_frame_decimation() -> f32 {
    4.0
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            decimation: 2.0,
            quad_sigma: 0.0,
            max_hamming: 1,
            min_decision_margin: 30.0,
            threads: 1,
            max_full_frame_decimation: default_max_full_frame_decimation(),
        }
    }
}

impl DetectorConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        self.reason_invalid()
    }

    fn reason_invalid(&self) -> Result<(), InvalidSetting> {
        if !(self.decimation >= 1.0 && self.decimation <= 8.0) {
            return Err(InvalidSetting(format!(
                "decimation {} must be 1-8",
                self.decimation
            )));
        }
        if !(self.quad_sigma >= 0.0 && self.quad_sigma <= 5.0) {
            return Err(InvalidSetting(format!(
                "quad_sigma {} must be 0-5 px",
                self.quad_sigma
            )));
        }
        if self.max_hamming > 2 {
            return Err(InvalidSetting(format!(
                "max_hamming {} must be 0-2",
                self.max_hamming
            )));
        }
        if !(self.max_full_frame_decimation >= 1.0 && self.max_full_frame_decimation <= 8.0) {
            return Err(InvalidSetting(format!(
                "max_full_frame_decimation {} must be 1-8",
                self.max_full_frame_decimation
            )));
        }
        if self.threads == 0 {
            return Err(InvalidSetting("threads must be at least 1".into()));
        }
        Ok(())
    }
}

/// The AprilRobotics AprilTag 3 detector for tag36h11.
pub struct AprilTagDetector {
    inner: apriltag::Detector,
    cfg: DetectorConfig,
}

impl AprilTagDetector {
    /// A tag36h11 detector.
    pub fn new(cfg: DetectorConfig) -> Result<Self, VisionError> {
        cfg.validate()?;
        let mut inner = apriltag::Detector::builder()
            .add_family_bits(apriltag::Family::tag_36h11(), cfg.max_hamming as usize)
            .build()
            .map_err(|e| VisionError::Detector(e.to_string()))?;
        inner.set_decimation(cfg.decimation);
        inner.set_sigma(cfg.quad_sigma);
        inner.set_refine_edges(true);
        inner.set_thread_number(cfg.threads);
        Ok(Self { inner, cfg })
    }
}

impl TagDetector for AprilTagDetector {
    fn name(&self) -> &'static str {
        "apriltag3"
    }

    fn detect_decimated(
        &mut self,
        image: &GrayImage,
        factor: f32,
    ) -> Result<Vec<TagDetection>, VisionError> {
        let factor = factor.clamp(self.cfg.decimation, 8.0);
        self.inner.set_decimation(factor);
        let found = self.detect(image);
        self.inner.set_decimation(self.cfg.decimation);
        found
    }

    fn detect(&mut self, image: &GrayImage) -> Result<Vec<TagDetection>, VisionError> {
        if image.width == 0 || image.height == 0 {
            return Err(VisionError::EmptyFrame {
                width: image.width,
                height: image.height,
            });
        }
        let mut im = apriltag::Image::zeros_with_stride(image.width, image.height, image.width)
            .map_err(|e| VisionError::Detector(e.to_string()))?;
        im.as_slice_mut()[..image.data.len()].copy_from_slice(&image.data);
        let mut out: Vec<TagDetection> = self
            .inner
            .detect(&im)
            .into_iter()
            .filter(|d| {
                d.hamming() as u32 <= self.cfg.max_hamming
                    && d.decision_margin() as f64 >= self.cfg.min_decision_margin
            })
            .map(|d| {
                // The library puts pixel centres at +0.5; OpenCV at integers.
                let c = d.center();
                let k = d.corners();
                TagDetection {
                    id: d.id() as u32,
                    center_px: [c[0] - 0.5, c[1] - 0.5],
                    corners_px: k.map(|p| [p[0] - 0.5, p[1] - 0.5]),
                    hamming: d.hamming() as u32,
                    decision_margin: d.decision_margin() as f64,
                }
            })
            .collect();
        out.sort_by_key(|d| d.id);
        Ok(out)
    }
}

/// How a tracked detection was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum SearchOutcome {
    /// In the region of interest around the prediction.
    Roi,
    /// In the full frame (no prediction, or the region held no target tag).
    FullFrame,
    /// Not searched: the frame's source knew that no tag was in it (a synthetic frame; see
    /// [`FrameSource::holds_no_tag`]).
    NoTagInFrame,
}

/// A square region of interest, px (OpenCV convention).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoiPx {
    /// Where the tag's centre is expected.
    pub center_px: [f64; 2],
    /// Half the side of the square to search.
    pub half_px: f64,
}

impl RoiPx {
    /// The region a filter's prediction calls for: the expected tag side plus three standard
    /// deviations of the predicted position (`sigma_px`, its largest axis), at least 32 px.
    pub fn around(center_px: [f64; 2], tag_side_px: f64, sigma_px: f64) -> Self {
        Self {
            center_px,
            half_px: (tag_side_px + 3.0 * sigma_px).max(32.0),
        }
    }
}

/// Searches a region around the predicted target first, the full frame only when that fails.
pub struct RoiSearch<D: TagDetector> {
    /// The detector.
    pub detector: D,
    /// A region wider than this share of the image width is searched as the full frame
    /// (no saving left).
    pub max_roi_fraction: f64,
    /// Coarsest decimation of the searches for a tag of known size
    /// ([`DetectorConfig::max_full_frame_decimation`]); 1: never coarser than the detector's.
    pub max_full_frame_decimation: f32,
}

/// Decimated pixels the tag's side keeps in a coarse full-frame search: the 10-cell tag36h11
/// (with its white border) then has cells of at least 1.6 decimated px, which quad detection
/// finds reliably; corners are refined at full resolution.
pub const MIN_DECIMATED_TAG_SIDE_PX: f64 = 16.0;

impl<D: TagDetector> RoiSearch<D> {
    /// Wraps a detector.
    pub fn new(detector: D) -> Self {
        Self {
            detector,
            max_roi_fraction: 0.6,
            max_full_frame_decimation: 1.0,
        }
    }

    /// With the full-frame search allowed to decimate up to `factor` for large tags.
    pub fn with_max_full_frame_decimation(mut self, factor: f32) -> Self {
        self.max_full_frame_decimation = factor.max(1.0);
        self
    }

    fn search(&mut self, image: &GrayImage, coarse: f32) -> Result<Vec<TagDetection>, VisionError> {
        if coarse > 1.0 {
            self.detector.detect_decimated(image, coarse)
        } else {
            self.detector.detect(image)
        }
    }

    /// Detections of `target_ids` (empty: any id), searching `roi` first, then the full
    /// frame; both coarsely when the tag is expected to be `tag_side_px` wide, so that quads
    /// are searched on an image decimated as far as the tag's size allows (at most
    /// `max_full_frame_decimation`).
    pub fn detect(
        &mut self,
        image: &GrayImage,
        roi: Option<RoiPx>,
        target_ids: &[u32],
        tag_side_px: Option<f64>,
    ) -> Result<(Vec<TagDetection>, SearchOutcome), VisionError> {
        self.detect_in(&mut &*image, roi, target_ids, tag_side_px)
    }

    /// [`Self::detect`] on a frame that makes its pixels where asked: the full frame is
    /// asked for only when the region of interest holds no target tag.
    pub fn detect_in(
        &mut self,
        frame: &mut impl FrameSource,
        roi: Option<RoiPx>,
        target_ids: &[u32],
        tag_side_px: Option<f64>,
    ) -> Result<(Vec<TagDetection>, SearchOutcome), VisionError> {
        if frame.holds_no_tag() {
            // A synthetic frame without the tag in view: the detector finds no tag on its
            // ground and occluders (tested), and rendering the whole frame to learn that was
            // most of a lost period's simulated cost.
            return Ok((Vec::new(), SearchOutcome::NoTagInFrame));
        }
        let wanted = |d: &TagDetection| target_ids.is_empty() || target_ids.contains(&d.id);
        let coarse = tag_side_px
            .map(|side| (side / MIN_DECIMATED_TAG_SIDE_PX).floor() as f32)
            .unwrap_or(1.0)
            .min(self.max_full_frame_decimation);
        let (width, height) = frame.size();
        let roi = roi.filter(|r| 2.0 * r.half_px <= self.max_roi_fraction * width as f64);
        if let Some(RoiPx {
            center_px: c,
            half_px: half,
        }) = roi
        {
            let x0 = (c[0] - half).floor().max(0.0);
            let y0 = (c[1] - half).floor().max(0.0);
            let x1 = (c[0] + half).ceil().min(width as f64);
            let y1 = (c[1] + half).ceil().min(height as f64);
            if x1 - x0 >= 16.0 && y1 - y0 >= 16.0 {
                let crop = frame.crop(
                    x0 as usize,
                    y0 as usize,
                    (x1 - x0) as usize,
                    (y1 - y0) as usize,
                );
                let found: Vec<TagDetection> = self
                    .search(&crop, coarse)?
                    .into_iter()
                    .filter(wanted)
                    .map(|d| d.shifted(x0, y0))
                    .collect();
                if !found.is_empty() {
                    return Ok((found, SearchOutcome::Roi));
                }
            }
        }
        let found = self
            .search(frame.full(), coarse)?
            .into_iter()
            .filter(wanted)
            .collect();
        Ok((found, SearchOutcome::FullFrame))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records the decimation of every search.
    #[derive(Default)]
    struct Recorder {
        calls: Vec<Option<f32>>,
    }

    impl TagDetector for Recorder {
        fn name(&self) -> &'static str {
            "recorder"
        }
        fn detect(&mut self, _: &GrayImage) -> Result<Vec<TagDetection>, VisionError> {
            self.calls.push(None);
            Ok(vec![])
        }
        fn detect_decimated(
            &mut self,
            _: &GrayImage,
            factor: f32,
        ) -> Result<Vec<TagDetection>, VisionError> {
            self.calls.push(Some(factor));
            Ok(vec![])
        }
    }

    #[test]
    fn the_coarse_factor_follows_the_tag_size_up_to_the_limit() {
        let img = GrayImage::new(640, 480, vec![0; 640 * 480]).unwrap();
        let roi = Some(RoiPx::around([320.0, 240.0], 75.0, 5.0));
        let mut s = RoiSearch::new(Recorder::default()).with_max_full_frame_decimation(4.0);
        // A 75 px tag: 75 / 16 = 4.7 -> 4, in the region and in the full frame.
        s.detect(&img, roi, &[0], Some(75.0)).unwrap();
        // A 40 px tag: 2; a 20 px tag: 1, the detector's own setting.
        s.detect(&img, None, &[0], Some(40.0)).unwrap();
        s.detect(&img, None, &[0], Some(20.0)).unwrap();
        // Size unknown: the detector's own setting.
        s.detect(&img, None, &[0], None).unwrap();
        assert_eq!(
            s.detector.calls,
            vec![Some(4.0), Some(4.0), Some(2.0), None, None]
        );
        // The limit at 1 turns it off.
        let mut off = RoiSearch::new(Recorder::default());
        off.detect(&img, None, &[0], Some(300.0)).unwrap();
        assert_eq!(off.detector.calls, vec![None]);
    }
}
