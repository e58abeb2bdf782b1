//! Output of the benchmark: the console table, the JSON summary, per-step CSV logs and plots.

pub mod bars;
pub mod csv;
pub mod markdown;
pub mod plots;
pub mod record;
pub mod table;

use std::path::{Path, PathBuf};

use thiserror::Error;

/// Why a report could not be written.
#[derive(Debug, Error)]
pub enum ReportError {
    /// A file or directory could not be written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A plot could not be drawn.
    #[error("cannot draw plot {path}: {message}")]
    Plot {
        /// The file.
        path: PathBuf,
        /// What the plotting library said.
        message: String,
    },
    /// JSON serialisation failed.
    #[error("cannot serialise JSON for {path}: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The serialiser's error.
        source: serde_json::Error,
    },
}

/// Writes `value` as pretty JSON to `path`.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), ReportError> {
    let text = serde_json::to_string_pretty(value).map_err(|source| ReportError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    write_file(path, text.as_bytes())
}

/// Writes bytes to `path`, creating its parent directory.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|source| ReportError::Io {
            path: parent.to_path_buf(),
            source,
        })?;
    }
    whole_file(path, |tmp| {
        std::fs::write(tmp, bytes).map_err(|source| ReportError::Io {
            path: path.to_path_buf(),
            source,
        })
    })
}

/// Writes `path` whole or not at all: `write` fills a temporary file beside it (same
/// extension, so that a plot backend picks the same format), which is renamed over `path`
/// only when the write succeeded, and removed when it failed (a full disk leaves no
/// truncated file, no 0-byte PNG).
pub fn whole_file(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), ReportError>,
) -> Result<(), ReportError> {
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let tmp = path.with_file_name(format!(".partial-{name}"));
    let done = write(&tmp).and_then(|()| {
        std::fs::File::open(&tmp)
            .and_then(|f| f.sync_all())
            .and_then(|()| std::fs::rename(&tmp, path))
            .map_err(|source| ReportError::Io {
                path: path.to_path_buf(),
                source,
            })
    });
    if done.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    done
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_written_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("scene.png");
        // A write that fails half-way (a full disk): nothing is left, not even a 0-byte file.
        let failed = whole_file(&png, |tmp| {
            std::fs::write(tmp, b"half a picture").unwrap();
            Err(ReportError::Io {
                path: tmp.to_path_buf(),
                source: std::io::Error::other("No space left on device"),
            })
        });
        assert!(failed.is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        // An earlier whole file stays as it was when its replacement fails.
        write_file(&png, b"whole").unwrap();
        let _ = whole_file(&png, |_| {
            Err(ReportError::Io {
                path: png.clone(),
                source: std::io::Error::other("No space left on device"),
            })
        });
        assert_eq!(std::fs::read(&png).unwrap(), b"whole");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_plot_on_a_full_disk_leaves_no_file() {
        // A plot whose file cannot be created leaves nothing behind.
        let steps = Vec::new();
        let path = std::path::Path::new("/proc/no-such-folder/estimation_error.png");
        assert!(plots::estimation_error(path, "t", &steps).is_err());
        assert!(!path.exists());
    }
}
