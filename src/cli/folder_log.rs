//! The daemon's log in its flight folder: a tracing writer that copies each formatted line
//! into `daemon.log` while a flight folder is open, and writes nothing otherwise.

use std::fs::File;
use std::io::Write;
use std::path::Path;

use parking_lot::Mutex;
use tracing_subscriber::fmt::MakeWriter;

/// The open `daemon.log`, if a flight folder is being written.
static SINK: Mutex<Option<File>> = Mutex::new(None);

/// Starts copying the log into `path` (created or truncated).
pub fn start(path: &Path) -> std::io::Result<()> {
    *SINK.lock() = Some(File::create(path)?);
    Ok(())
}

/// Stops copying, after flushing what was written.
pub fn stop() {
    if let Some(mut f) = SINK.lock().take() {
        let _ = f.flush();
    }
}

/// The tracing layer's writer factory ([`MakeWriter`]).
pub struct FolderLog;

/// One event's writer: each formatted line arrives in one `write`.
pub struct FolderLogWriter;

impl Write for FolderLogWriter {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        if let Some(f) = SINK.lock().as_mut() {
            // A log line that cannot be written (a full disk) must not stop the flight;
            // the flight's records report the disk themselves.
            let _ = f.write_all(bytes);
        }
        Ok(bytes.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(f) = SINK.lock().as_mut() {
            let _ = f.flush();
        }
        Ok(())
    }
}

impl<'a> MakeWriter<'a> for FolderLog {
    type Writer = FolderLogWriter;

    fn make_writer(&'a self) -> Self::Writer {
        FolderLogWriter
    }
}
