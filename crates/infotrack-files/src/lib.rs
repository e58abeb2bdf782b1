//! Reading a user's file (a config, a parameter file, a world) without trusting it: only a
//! regular file, only up to a size, so that `/dev/zero`, a FIFO or a 50 MB file is a clear
//! error rather than a hang or a process that reads until memory runs out.
#![deny(missing_docs)]

use std::io::Read;
use std::path::Path;

use thiserror::Error;

/// Why a file was not read.
#[derive(Debug, Error)]
pub enum BoundedReadError {
    /// Opening or reading failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// Not a regular file (a device, a FIFO, a folder, a socket).
    #[error("not a regular file (a device, a FIFO or a folder): only a file can be read here")]
    NotRegular,
    /// Larger than the limit.
    #[error("larger than {limit} bytes: refused (the wrong file?)")]
    TooLarge {
        /// The limit, bytes.
        limit: u64,
    },
    /// Not UTF-8 text.
    #[error("not UTF-8 text")]
    NotText,
}

/// Reads `path` as UTF-8 text if it is a regular file of at most `limit` bytes.
pub fn read_text(path: &Path, limit: u64) -> Result<String, BoundedReadError> {
    let bytes = read_bytes(path, limit)?;
    String::from_utf8(bytes).map_err(|_| BoundedReadError::NotText)
}

/// Reads `path` if it is a regular file of at most `limit` bytes.
pub fn read_bytes(path: &Path, limit: u64) -> Result<Vec<u8>, BoundedReadError> {
    // The type is checked before opening: opening a FIFO for reading blocks until a writer
    // comes.
    if !std::fs::metadata(path)?.is_file() {
        return Err(BoundedReadError::NotRegular);
    }
    let file = std::fs::File::open(path)?;
    if file.metadata()?.len() > limit {
        return Err(BoundedReadError::TooLarge { limit });
    }
    // A file that grows while it is read is cut at the limit and refused.
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(BoundedReadError::TooLarge { limit });
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_folders_and_large_files_are_refused_small_files_read() {
        assert!(matches!(
            read_text(Path::new("/dev/zero"), 1024),
            Err(BoundedReadError::NotRegular)
        ));
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(
            read_text(dir.path(), 1024),
            Err(BoundedReadError::NotRegular)
        ));
        let big = dir.path().join("big.toml");
        std::fs::write(&big, vec![b'#'; 2048]).unwrap();
        assert!(matches!(
            read_text(&big, 1024),
            Err(BoundedReadError::TooLarge { limit: 1024 })
        ));
        assert_eq!(read_text(&big, 4096).unwrap().len(), 2048);
        let bin = dir.path().join("bin.toml");
        std::fs::write(&bin, [0xff, 0xfe, 0x00]).unwrap();
        assert!(matches!(
            read_text(&bin, 1024),
            Err(BoundedReadError::NotText)
        ));
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_refused_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        assert!(matches!(
            read_text(&fifo, 1024),
            Err(BoundedReadError::NotRegular)
        ));
    }
}
