//! A telemetry log (`.tlog`) of a MAVLink link, the format MAVProxy, QGroundControl and
//! pymavlink read: for every message, an 8-byte big-endian timestamp (microseconds since
//! the Unix epoch) followed by the MAVLink frame.
//!
//! Frames are written re-serialised from the parsed message and its header (system,
//! component, sequence as received); a signed frame is logged without its signature.

use parking_lot::Mutex;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MavHeader, MavlinkVersion};

/// An open telemetry log.
pub struct Tlog {
    out: Mutex<std::io::BufWriter<std::fs::File>>,
    /// The file, for the one error said when a write fails.
    path: String,
    /// A write failed (a full disk): said once, then the log is best effort.
    failed: AtomicBool,
    /// Wall-clock time at creation, µs since the Unix epoch.
    opened_unix_us: u64,
    /// The runtime's clock at creation: stamps advance with it, so a flight on the simulated
    /// clock gets the time stamps it would have had in real time.
    opened: tokio::time::Instant,
}

impl Tlog {
    /// Creates (truncates) the log file.
    pub fn create(path: &Path) -> std::io::Result<Self> {
        Ok(Self {
            out: Mutex::new(std::io::BufWriter::new(std::fs::File::create(path)?)),
            path: path.display().to_string(),
            failed: AtomicBool::new(false),
            opened_unix_us: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_micros() as u64)
                .unwrap_or(0),
            opened: tokio::time::Instant::now(),
        })
    }

    /// Appends one message.
    pub fn record(&self, header: &MavHeader, msg: &MavMessage) {
        let mut frame = Vec::with_capacity(300);
        if mavlink::write_versioned_msg(&mut frame, MavlinkVersion::V2, *header, msg).is_err() {
            return;
        }
        let us = self.opened_unix_us + self.opened.elapsed().as_micros() as u64;
        let mut out = self.out.lock();
        // A full disk must not stop the flight: said once, and the log goes on trying (the
        // buffer reaches the disk every ~8 KB, within a second at telemetry rates).
        let written = out
            .write_all(&us.to_be_bytes())
            .and_then(|()| out.write_all(&frame));
        if let Err(e) = written {
            if !self.failed.swap(true, Ordering::Relaxed) {
                tracing::error!(
                    "{}: {e}; the tlog misses messages from here (disk full?), the flight goes on",
                    self.path
                );
            }
        }
    }

    /// Flushes to disk.
    pub fn flush(&self) -> std::io::Result<()> {
        self.out.lock().flush()
    }
}

/// Reads a tlog back: (timestamp us, header, message) for every frame. A last frame cut
/// short (a kill or a full disk mid-write) ends the log; anything else that is not a frame
/// is an error naming its byte.
pub fn read(path: &Path) -> std::io::Result<Vec<(u64, MavHeader, MavMessage)>> {
    let bytes = std::fs::read(path)?;
    let bad = |at: usize, what: String| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{}: byte {at}: {what}", path.display()),
        )
    };
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        // Timestamp, then a MAVLink 2 frame: STX, len, incompat flags, ... payload, CRC,
        // and a 13-byte signature when flagged.
        if bytes.len() < at + 8 + 10 {
            tracing::warn!(
                "{}: the last frame is cut short at byte {at}",
                path.display()
            );
            break;
        }
        if bytes[at + 8] != 0xfd {
            return Err(bad(at, "not a timestamped MAVLink 2 frame".into()));
        }
        let ts = u64::from_be_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
        let f = at + 8;
        let len = 10 + bytes[f + 1] as usize + 2 + if bytes[f + 2] & 1 != 0 { 13 } else { 0 };
        let Some(frame) = bytes.get(f..f + len) else {
            tracing::warn!(
                "{}: the last frame is cut short at byte {at}",
                path.display()
            );
            break;
        };
        let mut reader = mavlink::MavlinkReader::new(frame);
        let (h, m) = reader
            .read_message::<MavMessage>(MavlinkVersion::V2)
            .map_err(|e| bad(at, e.to_string()))?;
        out.push((ts, h, m));
        at = f + len;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::*;

    #[test]
    fn messages_round_trip_through_a_tlog() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("link.tlog");
        let log = Tlog::create(&p).unwrap();
        let h = MavHeader {
            system_id: 1,
            component_id: 191,
            sequence: 42,
        };
        let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
            mavlink_version: 3,
            ..Default::default()
        });
        let pos = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            time_boot_ms: 1234,
            x: 1.5,
            y: -2.0,
            z: -10.0,
            ..Default::default()
        });
        log.record(&h, &hb);
        log.record(&h, &pos);
        log.flush().unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[0].1.sequence, 42);
        assert_eq!(back[1].2, pos);
        assert!(back[0].0 > 1_600_000_000_000_000, "a Unix time in us");

        // Cut anywhere inside the last record, the log reads up to the record before it;
        // garbage where a record should start is an error naming its byte.
        let bytes = std::fs::read(&p).unwrap();
        let first = 8 + mavlink_frame_len(&bytes[8..]);
        for cut in first..bytes.len() {
            std::fs::write(&p, &bytes[..cut]).unwrap();
            assert_eq!(read(&p).unwrap().len(), 1, "cut at {cut}");
        }
        let mut bad = bytes.clone();
        bad[first + 8] = 0x00;
        std::fs::write(&p, &bad).unwrap();
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains(&format!("byte {first}")), "{e}");
    }

    fn mavlink_frame_len(f: &[u8]) -> usize {
        12 + f[1] as usize + if f[2] & 1 != 0 { 13 } else { 0 }
    }
}
