//! A null-modem cable made of two pseudo-terminals, so that the serial transport is
//! exercised end to end with no hardware: the mock opens one end as `serial:PATH:BAUD`,
//! the companion the other, and a bridge thread copies bytes between the two pty masters
//! (what `socat -d -d pty,raw,echo=0 pty,raw,echo=0` does). The bridge can also put bytes
//! of its own on the line, for tests of a receiver that must skip junk (ArduPilot writes
//! its boot text on its first serial port).

use std::ffi::CStr;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use parking_lot::Mutex;
use std::thread::JoinHandle;

use thiserror::Error;

/// Why the null modem could not be set up.
#[derive(Debug, Error)]
#[error("pseudo-terminal: {what}: {source}")]
pub struct NullModemError {
    what: &'static str,
    #[source]
    source: std::io::Error,
}

fn os_err(what: &'static str) -> NullModemError {
    NullModemError {
        what,
        source: std::io::Error::last_os_error(),
    }
}

/// One pty pair: the master (kept by the bridge) and the slave's path. The slave is kept
/// open too, so that the master does not report a hang-up while no one has the path open.
struct Pty {
    master: OwnedFd,
    _slave: OwnedFd,
    path: String,
}

fn open_pty() -> Result<Pty, NullModemError> {
    let mut master: libc::c_int = -1;
    let mut slave: libc::c_int = -1;
    let mut name = [0 as libc::c_char; 128];
    // SAFETY: openpty writes two fds and a NUL-terminated name (at most 128 bytes on
    // glibc's ptys, "/dev/pts/N") into the buffers we own.
    let rc = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            name.as_mut_ptr(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    if rc != 0 {
        return Err(os_err("openpty"));
    }
    // SAFETY: openpty succeeded, so both are fresh fds that we now own.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    // SAFETY: `name` was NUL-terminated by openpty.
    let path = unsafe { CStr::from_ptr(name.as_ptr()) }
        .to_string_lossy()
        .into_owned();
    // Raw line discipline from the start: with the default (echo, canonical) bytes sent
    // before the serial port is opened would be echoed back or held for a newline.
    set_raw(slave.as_raw_fd())?;
    set_raw(master.as_raw_fd())?;
    set_nonblocking(master.as_raw_fd())?;
    Ok(Pty {
        master,
        _slave: slave,
        path,
    })
}

fn set_raw(fd: RawFd) -> Result<(), NullModemError> {
    // SAFETY: termios is plain data; tcgetattr fills it for a valid fd.
    unsafe {
        let mut t: libc::termios = std::mem::zeroed();
        if libc::tcgetattr(fd, &mut t) != 0 {
            return Err(os_err("tcgetattr"));
        }
        libc::cfmakeraw(&mut t);
        if libc::tcsetattr(fd, libc::TCSANOW, &t) != 0 {
            return Err(os_err("tcsetattr"));
        }
    }
    Ok(())
}

fn set_nonblocking(fd: RawFd) -> Result<(), NullModemError> {
    // SAFETY: fcntl on a valid fd with integer flags.
    unsafe {
        let flags = libc::fcntl(fd, libc::F_GETFL);
        if flags < 0 || libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK) != 0 {
            return Err(os_err("fcntl O_NONBLOCK"));
        }
    }
    Ok(())
}

/// Bytes waiting to be put on the line by the bridge, per direction.
#[derive(Default)]
struct Injected {
    to_vehicle: Vec<u8>,
    to_companion: Vec<u8>,
}

/// Two connected serial ports on pseudo-terminals. Dropping it stops the bridge.
pub struct NullModem {
    vehicle_path: String,
    companion_path: String,
    stop: Arc<AtomicBool>,
    injected: Arc<Mutex<Injected>>,
    bridge: Option<JoinHandle<()>>,
}

impl NullModem {
    /// Opens two pty pairs and starts the bridge thread.
    pub fn new() -> Result<Self, NullModemError> {
        let vehicle = open_pty()?;
        let companion = open_pty()?;
        let stop = Arc::new(AtomicBool::new(false));
        let injected = Arc::new(Mutex::new(Injected::default()));
        let vehicle_path = vehicle.path.clone();
        let companion_path = companion.path.clone();
        let bridge = {
            let stop = stop.clone();
            let injected = injected.clone();
            std::thread::Builder::new()
                .name("null-modem".into())
                .spawn(move || bridge(vehicle, companion, &stop, &injected))
                .map_err(|source| NullModemError {
                    what: "bridge thread",
                    source,
                })?
        };
        Ok(Self {
            vehicle_path,
            companion_path,
            stop,
            injected,
            bridge: Some(bridge),
        })
    }

    /// The end the autopilot (the mock) opens, e.g. `/dev/pts/3`.
    pub fn vehicle_path(&self) -> &str {
        &self.vehicle_path
    }

    /// The end the companion opens.
    pub fn companion_path(&self) -> &str {
        &self.companion_path
    }

    /// Puts `bytes` on the line toward the companion, between whole frames of the vehicle's.
    pub fn inject_to_companion(&self, bytes: &[u8]) {
        self.injected.lock().to_companion.extend_from_slice(bytes);
    }

    /// Puts `bytes` on the line toward the vehicle.
    pub fn inject_to_vehicle(&self, bytes: &[u8]) {
        self.injected.lock().to_vehicle.extend_from_slice(bytes);
    }
}

impl Drop for NullModem {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(b) = self.bridge.take() {
            let _ = b.join();
        }
    }
}

/// Reads what is there (non-blocking); `None` when nothing.
fn read_some(fd: RawFd, buf: &mut [u8]) -> Option<usize> {
    // SAFETY: reading into a buffer we own, of its length.
    let n = unsafe { libc::read(fd, buf.as_mut_ptr().cast(), buf.len()) };
    (n > 0).then_some(n as usize)
}

/// Writes all of `data`, waiting while the pty's buffer is full.
fn write_all(fd: RawFd, mut data: &[u8], stop: &AtomicBool) {
    while !data.is_empty() && !stop.load(Ordering::Relaxed) {
        // SAFETY: writing from a slice we own, of its length.
        let n = unsafe { libc::write(fd, data.as_ptr().cast(), data.len()) };
        if n > 0 {
            data = &data[n as usize..];
        } else {
            let err = std::io::Error::last_os_error();
            if err.kind() != std::io::ErrorKind::WouldBlock {
                // The reader went away; what was in flight is lost, as on a real cable.
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }
}

fn bridge(vehicle: Pty, companion: Pty, stop: &AtomicBool, injected: &Mutex<Injected>) {
    let (v, c) = (vehicle.master.as_raw_fd(), companion.master.as_raw_fd());
    let mut buf = [0u8; 4096];
    while !stop.load(Ordering::Relaxed) {
        let mut fds = [
            libc::pollfd {
                fd: v,
                events: libc::POLLIN,
                revents: 0,
            },
            libc::pollfd {
                fd: c,
                events: libc::POLLIN,
                revents: 0,
            },
        ];
        // SAFETY: two pollfd structs we own; 20 ms so that `stop` and injections are seen.
        unsafe { libc::poll(fds.as_mut_ptr(), 2, 20) };
        let (to_v, to_c) = {
            let mut inj = injected.lock();
            (
                std::mem::take(&mut inj.to_vehicle),
                std::mem::take(&mut inj.to_companion),
            )
        };
        write_all(v, &to_v, stop);
        write_all(c, &to_c, stop);
        while let Some(n) = read_some(v, &mut buf) {
            write_all(c, &buf[..n], stop);
        }
        while let Some(n) = read_some(c, &mut buf) {
            write_all(v, &buf[..n], stop);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read, Write};
    use std::time::{Duration, Instant};

    fn open(path: &str) -> std::fs::File {
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .unwrap();
        set_raw(f.as_raw_fd()).unwrap();
        set_nonblocking(f.as_raw_fd()).unwrap();
        f
    }

    fn read_n(f: &mut std::fs::File, n: usize) -> Vec<u8> {
        let mut got = Vec::new();
        let until = Instant::now() + Duration::from_secs(5);
        let mut buf = [0u8; 256];
        while got.len() < n && Instant::now() < until {
            match f.read(&mut buf) {
                Ok(k) if k > 0 => got.extend_from_slice(&buf[..k]),
                _ => std::thread::sleep(Duration::from_millis(2)),
            }
        }
        got
    }

    #[test]
    fn bytes_cross_both_ways_and_injections_arrive() {
        let nm = NullModem::new().unwrap();
        assert_ne!(nm.vehicle_path(), nm.companion_path());
        let mut veh = open(nm.vehicle_path());
        let mut comp = open(nm.companion_path());
        // Every byte value, including what a tty would otherwise treat as control.
        let all: Vec<u8> = (0..=255u8).collect();
        veh.write_all(&all).unwrap();
        assert_eq!(read_n(&mut comp, 256), all);
        comp.write_all(b"\x03\x11\x13\rhello\n").unwrap();
        assert_eq!(read_n(&mut veh, 9), b"\x03\x11\x13\rhello\n");
        nm.inject_to_companion(b"junk");
        assert_eq!(read_n(&mut comp, 4), b"junk");
        nm.inject_to_vehicle(b"boot");
        assert_eq!(read_n(&mut veh, 4), b"boot");
    }
}
