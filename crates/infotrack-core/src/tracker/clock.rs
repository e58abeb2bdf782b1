//! The clock the tracker times its own work with, passed in by the caller (the core never
//! reads a clock of its own): compute times are reported, and the daemon's guidance budget
//! is checked against them.

/// A monotonic clock, seconds from an arbitrary origin.
pub trait Clock {
    /// Now, s.
    fn now_s(&self) -> f64;
}

/// The process's monotonic clock (`std::time::Instant`).
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    origin: std::time::Instant,
}

impl MonotonicClock {
    /// A clock whose origin is now.
    pub fn new() -> Self {
        Self {
            origin: std::time::Instant::now(),
        }
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for MonotonicClock {
    fn now_s(&self) -> f64 {
        self.origin.elapsed().as_secs_f64()
    }
}

/// A clock that never moves (tests, and callers that do not want compute times).
#[derive(Debug, Clone, Copy, Default)]
pub struct FrozenClock;

impl Clock for FrozenClock {
    fn now_s(&self) -> f64 {
        0.0
    }
}
