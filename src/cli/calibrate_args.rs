//! `infotrack calibrate`'s arguments: part of the command line whether or not this build has
//! the OpenCV that the calibration itself needs.

use std::path::PathBuf;

/// `infotrack calibrate` arguments.
#[derive(clap::Args)]
pub struct CalibrateArgs {
    /// A folder of chessboard images (sorted by name), or a live camera (`v4l2:0`,
    /// `/dev/video0`, `gst:... ! appsink`) or video file to take `--frames` views from.
    pub source: String,
    /// Inner corners of the board, COLSxROWS (e.g. `9x6` for a board of 10 x 7 squares).
    #[arg(long)]
    pub board: String,
    /// Side of one square, m (measure the printed board).
    #[arg(long)]
    pub square_m: f64,
    /// The calibration file to write (OpenCV YAML: image_width, image_height,
    /// camera_matrix, distortion_coefficients).
    #[arg(long)]
    pub out: PathBuf,
    /// From a camera: views to take (move the board between them).
    #[arg(long, default_value_t = 20)]
    pub frames: usize,
    /// From a camera: seconds between two views.
    #[arg(long, default_value_t = 1.0, value_parser = super::numbers::seconds)]
    pub every_s: f64,
}
