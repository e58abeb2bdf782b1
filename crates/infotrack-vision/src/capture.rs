//! Camera capture through OpenCV's VideoCapture: a V4L2 device (index or path), a GStreamer
//! pipeline, a video file or an image sequence. Each frame gets a capture time. A reader
//! thread owns the capture (OpenCV blocks), so that a camera that stops delivering is
//! noticed by a timeout on the consumer's side, reported, and reopened.

use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use opencv::core::Mat;
use opencv::prelude::*;
use opencv::videoio::{self, VideoCapture};

use super::cv_io::gray_from_mat;
use super::image::Frame;
use super::VisionError;

pub use crate::capture_source::{CaptureConfig, CaptureSource};

fn open(src: &CaptureSource, cfg: &CaptureConfig) -> Result<VideoCapture, VisionError> {
    let err = |m: String| VisionError::Camera {
        camera: cfg.source.clone(),
        message: m,
    };
    let cap = match src {
        CaptureSource::DeviceIndex(i) => VideoCapture::new(*i, videoio::CAP_V4L2),
        CaptureSource::DevicePath(p) => {
            VideoCapture::from_file(&p.display().to_string(), videoio::CAP_V4L2)
        }
        CaptureSource::Gstreamer(p) => VideoCapture::from_file(p, videoio::CAP_GSTREAMER),
        CaptureSource::File(p) => {
            let name = p.display().to_string();
            if !name.contains('%') && !p.is_file() {
                return Err(err("no such file".into()));
            }
            VideoCapture::from_file(&name, videoio::CAP_ANY)
        }
    }
    .map_err(|e| err(e.to_string()))?;
    let mut cap = cap;
    if !cap.is_opened().unwrap_or(false) {
        return Err(err("OpenCV could not open it".into()));
    }
    if src.is_live() {
        // Requests; the driver picks the nearest mode it has.
        if cfg.width_px > 0 {
            let _ = cap.set(videoio::CAP_PROP_FRAME_WIDTH, cfg.width_px as f64);
        }
        if cfg.height_px > 0 {
            let _ = cap.set(videoio::CAP_PROP_FRAME_HEIGHT, cfg.height_px as f64);
        }
        if cfg.fps > 0.0 {
            let _ = cap.set(videoio::CAP_PROP_FPS, cfg.fps);
        }
    }
    Ok(cap)
}

/// What the reader thread sends.
#[derive(Debug)]
pub enum CaptureEvent {
    /// A frame.
    Frame(Frame),
    /// A file or sequence ended.
    Ended,
    /// The camera failed and is being reopened.
    Reopening(String),
}

/// A camera read by its own thread.
pub struct Camera {
    cfg: CaptureConfig,
    rx: Receiver<CaptureEvent>,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// Stalls seen (timeouts), for reports.
    pub stalls: u64,
    ended: bool,
    /// Frames a file's header declares (none for live sources or when it does not say).
    declared_frames: Option<u64>,
}

impl Camera {
    /// Opens the source (an error here if it cannot be opened at all) and starts reading.
    pub fn open(cfg: CaptureConfig) -> Result<Self, VisionError> {
        cfg.validate()?;
        let src = CaptureSource::parse(&cfg.source)?;
        let cap = open(&src, &cfg)?;
        let declared_frames = (!src.is_live())
            .then(|| cap.get(videoio::CAP_PROP_FRAME_COUNT).unwrap_or(0.0))
            .filter(|n| n.is_finite() && *n >= 1.0)
            .map(|n| n as u64);
        let (tx, rx) = mpsc::sync_channel(4);
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let thread = {
            let cfg = cfg.clone();
            let stop = stop.clone();
            std::thread::Builder::new()
                .name("camera".into())
                .spawn(move || reader(cap, src, cfg, tx, &stop))
                .map_err(|e| VisionError::Camera {
                    camera: "camera thread".into(),
                    message: e.to_string(),
                })?
        };
        Ok(Self {
            cfg,
            rx,
            stop,
            thread: Some(thread),
            stalls: 0,
            ended: false,
            declared_frames,
        })
    }

    /// The next frame; `Ok(None)` at the end of a file; an error when nothing came within
    /// the timeout (the reader goes on trying to reopen a live camera).
    pub fn next_frame(&mut self) -> Result<Option<Frame>, VisionError> {
        let timeout = Duration::from_secs_f64(self.cfg.timeout_s);
        loop {
            match self.rx.recv_timeout(timeout) {
                Ok(CaptureEvent::Frame(f)) => return Ok(Some(f)),
                Ok(CaptureEvent::Ended) | Err(RecvTimeoutError::Disconnected) => {
                    self.ended = true;
                    return Ok(None);
                }
                Ok(CaptureEvent::Reopening(why)) => {
                    tracing::warn!("camera {}: {why}; reopening", self.cfg.source);
                }
                Err(RecvTimeoutError::Timeout) => {
                    self.stalls += 1;
                    return Err(VisionError::CameraStalled {
                        camera: self.cfg.source.clone(),
                        seconds: self.cfg.timeout_s,
                    });
                }
            }
        }
    }
}

impl Camera {
    /// The newest frame delivered since the last call, without waiting (older ones are
    /// dropped: the filter wants the freshest view). `Err(Ended)`-like end of a file is
    /// `Ok(None)` with `ended()` true.
    pub fn latest(&mut self) -> Option<Frame> {
        let mut newest = None;
        loop {
            match self.rx.try_recv() {
                Ok(CaptureEvent::Frame(f)) => newest = Some(f),
                Ok(CaptureEvent::Ended) | Err(mpsc::TryRecvError::Disconnected) => {
                    self.ended = true;
                    return newest;
                }
                Ok(CaptureEvent::Reopening(why)) => {
                    tracing::warn!("camera {}: {why}; reopening", self.cfg.source);
                }
                Err(mpsc::TryRecvError::Empty) => return newest,
            }
        }
    }

    /// Whether a file or sequence has ended.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// The frame count a video file's header declares, if it does.
    pub fn declared_frames(&self) -> Option<u64> {
        self.declared_frames
    }
}

impl Drop for Camera {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        // Unblock a reader waiting to hand over a frame.
        while self.rx.try_recv().is_ok() {}
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn reader(
    mut cap: VideoCapture,
    src: CaptureSource,
    cfg: CaptureConfig,
    tx: SyncSender<CaptureEvent>,
    stop: &std::sync::atomic::AtomicBool,
) {
    let start = Instant::now();
    let mut index = 0u64;
    let mut mat = Mat::default();
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        let got = cap.read(&mut mat).unwrap_or(false) && !mat.empty();
        let captured_at = Instant::now();
        if !got {
            if !src.is_live() {
                let _ = tx.send(CaptureEvent::Ended);
                return;
            }
            if tx.send(CaptureEvent::Reopening("no frame".into())).is_err() {
                return;
            }
            std::thread::sleep(Duration::from_millis(200));
            if let Ok(c) = open(&src, &cfg) {
                cap = c;
            }
            continue;
        }
        // Files carry their own time line; live frames are stamped on arrival.
        let t = if src.is_live() {
            start.elapsed().as_secs_f64()
        } else {
            cap.get(videoio::CAP_PROP_POS_MSEC).unwrap_or(0.0) / 1e3
        };
        let image = match gray_from_mat(&mat, &cfg.source) {
            Ok(i) => i,
            Err(e) => {
                tracing::warn!("camera {}: frame {index} dropped: {e}", cfg.source);
                continue;
            }
        };
        let frame = Frame {
            index,
            capture_time_s: t,
            captured_at,
            image,
        };
        index += 1;
        // Waits while the consumer is busy; the stop flag is checked between frames.
        if tx.send(CaptureEvent::Frame(frame)).is_err() {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_parse_with_clear_errors() {
        assert_eq!(
            CaptureSource::parse("v4l2:2").unwrap(),
            CaptureSource::DeviceIndex(2)
        );
        assert_eq!(
            CaptureSource::parse("/dev/video1").unwrap(),
            CaptureSource::DevicePath("/dev/video1".into())
        );
        assert!(matches!(
            CaptureSource::parse("gst:videotestsrc ! videoconvert ! appsink").unwrap(),
            CaptureSource::Gstreamer(_)
        ));
        assert!(CaptureSource::parse("v4l2:x")
            .unwrap_err()
            .to_string()
            .contains("v4l2:INDEX"));
        assert!(CaptureSource::parse("gst:videotestsrc")
            .unwrap_err()
            .to_string()
            .contains("appsink"));
        let cfg = CaptureConfig {
            source: "/nonexistent/video.avi".into(),
            width_px: 0,
            height_px: 0,
            fps: 0.0,
            timeout_s: 1.0,
        };
        let e = Camera::open(cfg).err().unwrap().to_string();
        assert!(
            e.contains("/nonexistent/video.avi") && e.contains("no such file"),
            "{e}"
        );
    }
}
