//! The tag36h11 family's bit patterns, from the AprilTag C library itself, so that the
//! synthetic camera draws exactly the tags the detector decodes.

use super::VisionError;

/// Number of codes in tag36h11.
pub const TAG36H11_CODES: u32 = 587;

/// One tag as a square of cells, row-major from the top-left, 0 black and 255 white,
/// including its white outer ring. The detected corners are those of the black square
/// `border..size-border` (the "tag size" of AprilTag is that square's side).
#[derive(Debug, Clone, PartialEq)]
pub struct TagBitmap {
    /// Tag id.
    pub id: u32,
    /// Cells per side (10 for tag36h11).
    pub size: usize,
    /// Cells from the edge to the black square (1 for tag36h11).
    pub border: usize,
    /// Cell values, row-major.
    pub cells: Vec<u8>,
}

impl TagBitmap {
    /// The bitmap of tag36h11 `id`.
    pub fn tag36h11(id: u32) -> Result<Self, VisionError> {
        if id >= TAG36H11_CODES {
            return Err(VisionError::Config(format!(
                "tag id {id} is not in tag36h11 (0..{})",
                TAG36H11_CODES - 1
            )));
        }
        // SAFETY: the family and image are created and destroyed here; the image buffer is
        // read within its width x height with its stride.
        unsafe {
            let fam = apriltag_sys::tag36h11_create();
            if fam.is_null() {
                return Err(VisionError::Detector("tag36h11_create failed".into()));
            }
            let width_at_border = (*fam).width_at_border as usize;
            let im = apriltag_sys::apriltag_to_image(fam, id as i32);
            if im.is_null() {
                apriltag_sys::tag36h11_destroy(fam);
                return Err(VisionError::Detector("apriltag_to_image failed".into()));
            }
            let (w, h, stride) = (
                (*im).width as usize,
                (*im).height as usize,
                (*im).stride as usize,
            );
            let mut cells = Vec::with_capacity(w * h);
            for r in 0..h {
                let row = std::slice::from_raw_parts((*im).buf.add(r * stride), w);
                cells.extend_from_slice(row);
            }
            apriltag_sys::image_u8_destroy(im);
            apriltag_sys::tag36h11_destroy(fam);
            Ok(Self {
                id,
                size: w,
                border: (w - width_at_border) / 2,
                cells,
            })
        }
    }

    /// Cells per side of the black square.
    pub fn black_cells(&self) -> usize {
        self.size - 2 * self.border
    }

    /// Value at cell (col, row).
    pub fn cell(&self, col: usize, row: usize) -> u8 {
        self.cells[row * self.size + col]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tag36h11_has_a_white_ring_a_black_border_and_differing_payloads() {
        let t0 = TagBitmap::tag36h11(0).unwrap();
        assert_eq!((t0.size, t0.border, t0.black_cells()), (10, 1, 8));
        for i in 0..10 {
            assert_eq!(t0.cell(i, 0), 255);
            assert_eq!(t0.cell(0, i), 255);
            assert_eq!(t0.cell(9, i), 255);
        }
        for i in 1..9 {
            assert_eq!(t0.cell(i, 1), 0);
            assert_eq!(t0.cell(1, i), 0);
            assert_eq!(t0.cell(8, i), 0);
            assert_eq!(t0.cell(i, 8), 0);
        }
        let t1 = TagBitmap::tag36h11(1).unwrap();
        assert_ne!(t0.cells, t1.cells);
        assert!(TagBitmap::tag36h11(587)
            .unwrap_err()
            .to_string()
            .contains("tag36h11"));
    }
}
