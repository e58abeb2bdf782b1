//! The flight's records on disk as the flight goes: `steps.csv` and `flight.csv` a row per
//! filter step, buffered and flushed at least once a second (so a SIGKILL, an abort or a
//! power cut loses at most the last second), fsync'd when the tracking state changes and at
//! the end; `summary.json` rewritten (atomically) every few seconds with the metrics so far
//! and `"partial": true` until the clean end rewrites it. Only whole rows reach the files: a
//! write that fails (a full disk) is cut back to the last whole row, reported once, and the
//! flight goes on; the run then ends with an error and its summary says the records stopped.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::flight_log;
use super::flight_log::FlightRecord;
use crate::metrics::{RunSummary, StepRecord};
use crate::tracker::TrackState;

/// Longest a complete record waits in memory before it is written.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);
/// How often `summary.json` is rewritten during the flight.
pub const SUMMARY_EVERY: Duration = Duration::from_secs(5);

/// Writes a flight's records into its folder as they come.
pub struct FlightRecorder {
    dir: PathBuf,
    steps: Option<RecordFile>,
    flight: Option<RecordFile>,
    last_flush: Instant,
    last_summary: Instant,
    last_state: Option<TrackState>,
    /// The first write error, if any (the files stop there).
    failed: Option<String>,
}

/// A record folder that cannot be opened.
#[derive(Debug, thiserror::Error)]
#[error("cannot write the flight's records in {path}: {source}")]
pub struct RecorderError {
    /// The folder or file.
    pub path: String,
    /// Why.
    pub source: std::io::Error,
}

/// A file that takes whole records only: rows are buffered in memory and written together;
/// a write that fails part-way is cut back to the end of the last whole row.
pub struct RecordFile {
    file: File,
    buf: Vec<u8>,
    /// Bytes of whole rows on disk.
    committed: u64,
}

impl RecordFile {
    /// Rows beyond this many bytes in memory are written at once.
    const BUFFER: usize = 64 * 1024;

    fn new(file: File) -> Self {
        Self {
            file,
            buf: Vec::with_capacity(Self::BUFFER),
            committed: 0,
        }
    }

    /// Adds whole rows (ending in a newline); writes them if the buffer is full.
    pub fn push(&mut self, rows: &[u8]) -> std::io::Result<()> {
        self.buf.extend_from_slice(rows);
        if self.buf.len() >= Self::BUFFER {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes what is buffered; on failure the file is cut back to its last whole row.
    pub fn flush(&mut self) -> std::io::Result<()> {
        if self.buf.is_empty() {
            return Ok(());
        }
        match self.file.write_all(&self.buf) {
            Ok(()) => {
                self.committed += self.buf.len() as u64;
                self.buf.clear();
                Ok(())
            }
            Err(e) => {
                // Shrinking needs no space: the partial row goes, the whole ones stay.
                let _ = self.file.set_len(self.committed);
                self.buf.clear();
                Err(e)
            }
        }
    }

    /// Flushes and asks the disk to keep it.
    pub fn sync(&mut self) -> std::io::Result<()> {
        self.flush()?;
        self.file.sync_data()
    }
}

fn create(path: &Path) -> Result<RecordFile, RecorderError> {
    File::create(path)
        .map(RecordFile::new)
        .map_err(|source| RecorderError {
            path: path.display().to_string(),
            source,
        })
}

/// A folder of its own for a flight under `log_dir`: `<UTC date-time>-<seed>` (with `-2`,
/// `-3`, ... if that exists), never an existing one.
pub fn flight_folder(log_dir: &Path, seed: u64) -> Result<PathBuf, RecorderError> {
    let stamp: String = humantime::format_rfc3339_seconds(std::time::SystemTime::now())
        .to_string()
        .chars()
        .filter(|c| !matches!(c, '-' | ':'))
        .collect();
    let err = |source| RecorderError {
        path: log_dir.display().to_string(),
        source,
    };
    std::fs::create_dir_all(log_dir).map_err(err)?;
    for k in 1.. {
        let name = match k {
            1 => format!("{stamp}-{seed}"),
            _ => format!("{stamp}-{seed}-{k}"),
        };
        let dir = log_dir.join(name);
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(err(e)),
        }
    }
    unreachable!("an unbounded range ends only by returning")
}

impl FlightRecorder {
    /// Opens `steps.csv` and `flight.csv` in `dir` (created if needed) and writes their
    /// headers.
    pub fn open(dir: &Path, seed: u64, motion: &str) -> Result<Self, RecorderError> {
        std::fs::create_dir_all(dir).map_err(|source| RecorderError {
            path: dir.display().to_string(),
            source,
        })?;
        let mut steps = create(&dir.join("steps.csv"))?;
        let mut flight = create(&dir.join("flight.csv"))?;
        let header = |w: &mut RecordFile, text: &str, name: &str| {
            w.push(text.as_bytes())
                .and_then(|()| w.flush())
                .map_err(|source| RecorderError {
                    path: dir.join(name).display().to_string(),
                    source,
                })
        };
        header(
            &mut steps,
            &format!("{}\n", crate::metrics::csv::HEADER),
            "steps.csv",
        )?;
        header(
            &mut flight,
            &flight_log::preamble(seed, motion),
            "flight.csv",
        )?;
        Ok(Self {
            dir: dir.to_path_buf(),
            steps: Some(steps),
            flight: Some(flight),
            last_flush: Instant::now(),
            last_summary: Instant::now(),
            last_state: None,
            failed: None,
        })
    }

    /// The first write error, if the records stopped.
    pub fn failure(&self) -> Option<&str> {
        self.failed.as_deref()
    }

    /// Appends one record; flushes when a second has passed since the last flush, fsyncs
    /// when the tracking state changed, and rewrites the summary every few seconds from
    /// `all` (every record so far, this one included).
    pub fn record(&mut self, r: &FlightRecord, all: &[FlightRecord]) {
        let row_steps = crate::metrics::csv::render_row(&r.step);
        let row_flight = flight_log::render_row(r);
        self.write(|s, f| {
            s.push(row_steps.as_bytes())?;
            f.push(row_flight.as_bytes())
        });
        let phase_change = self.last_state.is_some_and(|s| s != r.state);
        self.last_state = Some(r.state);
        if phase_change {
            self.sync();
        } else if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.flush();
        }
        if self.last_summary.elapsed() >= SUMMARY_EVERY {
            self.last_summary = Instant::now();
            let steps: Vec<StepRecord> = all.iter().map(|r| r.step.clone()).collect();
            self.write_summary(&RunSummary::from_steps(&steps, &[], &[]));
        }
    }

    /// Flushes and fsyncs both files (the end of the flight, a change of phase).
    pub fn sync(&mut self) {
        self.flush();
        self.write(|s, f| {
            s.sync()?;
            f.sync()
        });
    }

    /// `summary.json`, replaced atomically (written beside it, then renamed).
    pub fn write_summary(&mut self, summary: &RunSummary) {
        if self.failed.is_some() {
            return;
        }
        // The rename makes the replacement atomic for a killed process; no fsync here (it
        // would stall the pipeline thread every few seconds): the files are fsync'd at
        // changes of phase and at the end.
        let tmp = self.dir.join(".summary.json.tmp");
        let result = summary_json(summary, Some("the flight is still going on"))
            .map_err(std::io::Error::other)
            .and_then(|bytes| {
                let mut f = File::create(&tmp)?;
                f.write_all(&bytes)
            })
            .and_then(|()| std::fs::rename(&tmp, self.dir.join("summary.json")));
        if let Err(e) = result {
            self.fail(format!("summary.json: {e}"));
        }
    }

    fn flush(&mut self) {
        self.last_flush = Instant::now();
        self.write(|s, f| {
            s.flush()?;
            f.flush()
        });
    }

    fn write(&mut self, op: impl FnOnce(&mut RecordFile, &mut RecordFile) -> std::io::Result<()>) {
        let (Some(s), Some(f)) = (self.steps.as_mut(), self.flight.as_mut()) else {
            return;
        };
        if let Err(e) = op(s, f) {
            self.fail(e.to_string());
        }
    }

    /// Stops writing after the first error: reported once, the flight goes on, and the
    /// files keep their whole rows.
    fn fail(&mut self, why: String) {
        tracing::error!(
            "flight records in {}: {why}; the flight goes on, its records stop here (disk full?)",
            self.dir.display()
        );
        self.failed = Some(why);
        self.steps = None;
        self.flight = None;
    }
}

/// `summary.json`: the run's metrics, and `"partial": true` with the reason while the
/// records are not those of a whole flight (still flying, killed, or stopped by an error).
pub fn summary_json(summary: &RunSummary, partial: Option<&str>) -> serde_json::Result<Vec<u8>> {
    let mut v = serde_json::to_value(summary)?;
    if let serde_json::Value::Object(m) = &mut v {
        m.insert("partial".into(), partial.is_some().into());
        if let Some(why) = partial {
            m.insert("partial_because".into(), why.into());
        }
    }
    serde_json::to_vec_pretty(&v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_flight_gets_a_new_folder_named_by_time_and_seed() {
        let root = tempfile::tempdir().unwrap();
        let a = flight_folder(root.path(), 7).unwrap();
        let b = flight_folder(root.path(), 7).unwrap();
        assert_ne!(a, b);
        let name = a.file_name().unwrap().to_str().unwrap().to_string();
        // e.g. 20261123T171502Z-7
        assert!(
            name.ends_with("Z-7") && name.len() == "20261123T171502Z-7".len(),
            "{name}"
        );
        assert!(b.to_str().unwrap().ends_with("-7-2") || b.to_str().unwrap().ends_with("Z-7"));
    }

    #[test]
    fn a_full_disk_is_reported_once_and_nothing_panics() {
        // /dev/full accepts the open and fails every write with ENOSPC.
        if !Path::new("/dev/full").exists() {
            panic!("this test needs /dev/full (Linux)");
        }
        let root = tempfile::tempdir().unwrap();
        let mut r = FlightRecorder::open(root.path(), 1, "cv").unwrap();
        r.steps = Some(RecordFile::new(File::create("/dev/full").unwrap()));
        r.write(|s, _| s.push(&[b'x'; 64]).and_then(|()| s.flush()));
        assert!(
            r.failure().unwrap().contains("No space left"),
            "{:?}",
            r.failure()
        );
        // Later writes are no-ops; the summary is not attempted.
        r.sync();
        r.write_summary(&RunSummary::from_steps(&[], &[], &[]));
        assert!(!root.path().join("summary.json").exists());
    }

    #[test]
    fn a_failed_write_leaves_only_whole_rows() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rows.csv");
        let mut f = RecordFile::new(File::create(&path).unwrap());
        f.push(b"a,1\n").unwrap();
        f.flush().unwrap();
        f.push(b"b,2\n").unwrap();
        // A write that fails part-way: the file is then as the last whole row left it.
        f.file = std::fs::OpenOptions::new().read(true).open(&path).unwrap();
        assert!(f.flush().is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "a,1\n");
    }

    #[test]
    fn the_summary_says_whether_it_is_partial() {
        let s = RunSummary::from_steps(&[], &[], &[]);
        let during: serde_json::Value =
            serde_json::from_slice(&summary_json(&s, Some("still flying")).unwrap()).unwrap();
        assert_eq!(during["partial"], true);
        assert_eq!(during["partial_because"], "still flying");
        let end: serde_json::Value =
            serde_json::from_slice(&summary_json(&s, None).unwrap()).unwrap();
        assert_eq!(end["partial"], false);
    }
}
