//! An 8-bit grey image with its capture time: what the camera delivers and the detector
//! reads. Plain memory, no OpenCV, so that the core can render and test without it.

use super::VisionError;

/// An 8-bit single-channel image, row-major, no padding.
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Pixels, `width * height`, row-major.
    pub data: Vec<u8>,
}

impl GrayImage {
    /// Wraps pixels, checking the size.
    pub fn new(width: usize, height: usize, data: Vec<u8>) -> Result<Self, VisionError> {
        if width == 0 || height == 0 {
            return Err(VisionError::EmptyFrame { width, height });
        }
        if data.len() != width * height {
            return Err(VisionError::Config(format!(
                "image of {width}x{height} px needs {} bytes, got {}",
                width * height,
                data.len()
            )));
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Pixel (x, y).
    pub fn get(&self, x: usize, y: usize) -> u8 {
        self.data[y * self.width + x]
    }

    /// The rectangle `[x0, x0 + w) x [y0, y0 + h)`, clipped to the image.
    pub fn crop(&self, x0: usize, y0: usize, w: usize, h: usize) -> Self {
        let r = PixelRect::clipped(x0, y0, w, h, self.width, self.height);
        let mut data = Vec::with_capacity(r.width() * r.height());
        for y in r.y0..r.y1 {
            data.extend_from_slice(&self.data[y * self.width + r.x0..y * self.width + r.x1]);
        }
        Self {
            width: r.width(),
            height: r.height(),
            data,
        }
    }
}

/// A rectangle of pixels `[x0, x1) x [y0, y1)`, image coordinates (x right, y down).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelRect {
    /// First column.
    pub x0: usize,
    /// First row.
    pub y0: usize,
    /// One past the last column.
    pub x1: usize,
    /// One past the last row.
    pub y1: usize,
}

impl PixelRect {
    /// The whole of a `width` x `height` image.
    pub fn full(width: usize, height: usize) -> Self {
        Self {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }

    /// `[x0, x0 + w) x [y0, y0 + h)` clipped to a `width` x `height` image.
    pub fn clipped(x0: usize, y0: usize, w: usize, h: usize, width: usize, height: usize) -> Self {
        let (x1, y1) = ((x0 + w).min(width), (y0 + h).min(height));
        Self {
            x0: x0.min(x1),
            y0: y0.min(y1),
            x1,
            y1,
        }
    }

    /// Grown by `margin` on every side, within a `width` x `height` image.
    pub fn grown(&self, margin: usize, width: usize, height: usize) -> Self {
        Self {
            x0: self.x0.saturating_sub(margin),
            y0: self.y0.saturating_sub(margin),
            x1: (self.x1 + margin).min(width),
            y1: (self.y1 + margin).min(height),
        }
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.x1 - self.x0
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.y1 - self.y0
    }
}

/// Where a detector reads its pixels: a whole frame in memory, or a camera that makes
/// pixels only where asked (the synthetic camera renders a region of interest without the
/// rest of the frame). A crop is exactly the same pixels the whole frame has there.
pub trait FrameSource {
    /// The frame's size, px.
    fn size(&self) -> (usize, usize);
    /// The rectangle `[x0, x0 + w) x [y0, y0 + h)`, clipped to the frame.
    fn crop(&mut self, x0: usize, y0: usize, w: usize, h: usize) -> GrayImage;
    /// The whole frame.
    fn full(&mut self) -> &GrayImage;
    /// Whether the source knows that no tag is in the frame (a synthetic frame whose scene
    /// puts none in view), so that nothing need be searched. A camera never knows: `false`.
    fn holds_no_tag(&self) -> bool {
        false
    }
}

impl FrameSource for &GrayImage {
    fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }
    fn crop(&mut self, x0: usize, y0: usize, w: usize, h: usize) -> GrayImage {
        GrayImage::crop(self, x0, y0, w, h)
    }
    fn full(&mut self) -> &GrayImage {
        self
    }
}

/// A frame from a camera: the image and when it was captured.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Sequence number from the source, from 0.
    pub index: u64,
    /// Capture time, s, on the clock of whoever made the frame (the companion's monotonic
    /// clock for a live camera, the file's time line for a video).
    pub capture_time_s: f64,
    /// When the frame arrived from the driver, on the companion's monotonic clock: what
    /// the vehicle pose is looked up at.
    pub captured_at: std::time::Instant,
    /// The image.
    pub image: GrayImage,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_checked_and_crops_clip() {
        assert!(matches!(
            GrayImage::new(0, 10, vec![]),
            Err(VisionError::EmptyFrame { .. })
        ));
        assert!(GrayImage::new(2, 2, vec![0; 3]).is_err());
        let img = GrayImage::new(4, 3, (0..12).collect()).unwrap();
        let c = img.crop(2, 1, 10, 10);
        assert_eq!((c.width, c.height), (2, 2));
        assert_eq!(c.data, vec![6, 7, 10, 11]);
        assert_eq!(img.get(3, 2), 11);
    }
}
