//! What a run is asked to do (options, scheduled faults) and what it reports.

use super::*;

/// Command-line choices of one run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Seconds of tracking after takeoff.
    pub duration_s: f64,
    /// Seed of the simulated world, the filter and guidance.
    pub seed: u64,
    /// Motion model name for the filter (`dmmn`, `cv`).
    pub motion: String,
    /// Telemetry log to write, if any.
    pub tlog: Option<PathBuf>,
    /// Folder the flight's records (`steps.csv`, `flight.csv`, `summary.json`) are
    /// written into as the flight goes, if any.
    pub records_dir: Option<PathBuf>,
    /// The visual record (MCAP for Foxglove) written as the flight goes, if any.
    pub visual_record: Option<PathBuf>,
    /// Print the status line every second on stderr.
    pub status_line: bool,
    /// Faults to inject during the flight (tests, demonstrations).
    pub faults: Vec<ScheduledFault>,
    /// What the operator explicitly allowed on a vehicle that is not the in-process mock.
    pub permits: VehiclePermits,
    /// The simulated parts the program provides (the in-process mock, the synthetic
    /// camera's world).
    pub simulators: Simulators,
}

/// What the operator must say explicitly before infotrack flies a vehicle that is not the
/// in-process mock (`mock:px4`, `mock:ardupilot`): both default to refused.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VehiclePermits {
    /// Fly a simulation (the synthetic camera and its simulated target, or a lab-scale
    /// world) on it: a SITL autopilot (`--allow-simulation-on-vehicle`).
    pub simulation: bool,
    /// Let infotrack arm it and take off by itself (`daemon.engage = "auto"`,
    /// `--allow-auto-engage`).
    pub auto_engage: bool,
}

/// A fault the daemon injects into its own loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// The camera delivers no frames.
    CameraFreeze,
    /// The MAVLink link is cut both ways (in-process mock only).
    LinkCut,
    /// This share of MAVLink messages is lost, percent (in-process mock only).
    PacketLoss(f64),
    /// The pipeline thread panics (a bug in the tracker, simulated): the supervisor must
    /// hold the vehicle.
    PipelinePanic,
}

/// A fault from `at_s` (seconds after tracking starts) for `duration_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScheduledFault {
    /// What.
    pub kind: FaultKind,
    /// When it starts, s after tracking starts.
    pub at_s: f64,
    /// How long it lasts, s.
    pub duration_s: f64,
}

impl FaultKind {
    /// The name `--inject` takes (`camera-freeze`, `link-cut`, `loss=30`).
    pub fn name(&self) -> String {
        match self {
            Self::CameraFreeze => "camera-freeze".into(),
            Self::LinkCut => "link-cut".into(),
            Self::PacketLoss(p) => format!("loss={p}"),
            Self::PipelinePanic => "pipeline-panic".into(),
        }
    }
}

/// A `--inject` value that is not a fault.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("`{0}`: expected KIND@START+DURATION (seconds), KIND one of camera-freeze, link-cut, loss=PERCENT, pipeline-panic; e.g. camera-freeze@20+5")]
pub struct BadFault(pub String);

impl std::str::FromStr for ScheduledFault {
    type Err = BadFault;

    /// `camera-freeze@20+5`, `link-cut@40+5`, `loss=30@10+5` (KIND@START+DURATION, seconds).
    fn from_str(s: &str) -> Result<Self, BadFault> {
        let usage = || BadFault(s.to_string());
        let (kind, when) = s.split_once('@').ok_or_else(usage)?;
        let (at, dur) = when.split_once('+').ok_or_else(usage)?;
        let at_s: f64 = at.parse().map_err(|_| usage())?;
        let duration_s: f64 = dur.parse().map_err(|_| usage())?;
        // Within a day: a fault's end (start + duration) becomes a `Duration`, which panics
        // on values like 1e300.
        let day_s = crate::config::bounds::MAX_DURATION_S;
        if !((0.0..=day_s).contains(&at_s) && duration_s > 0.0 && duration_s <= day_s) {
            return Err(usage());
        }
        let kind = match kind {
            "camera-freeze" => FaultKind::CameraFreeze,
            "link-cut" => FaultKind::LinkCut,
            "pipeline-panic" => FaultKind::PipelinePanic,
            k => match k.strip_prefix("loss=").map(str::parse::<f64>) {
                Some(Ok(p)) if (0.0..=100.0).contains(&p) => FaultKind::PacketLoss(p),
                _ => return Err(usage()),
            },
        };
        Ok(Self {
            kind,
            at_s,
            duration_s,
        })
    }
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The requested duration elapsed.
    Duration,
    /// SIGINT or SIGTERM.
    Signal,
    /// An internal fault (the pipeline thread died).
    Fault,
    /// The vehicle's GPS_GLOBAL_ORIGIN changed after the world was placed with it: the
    /// world, and the geofence, would no longer be where they are on Earth.
    OriginChanged,
}

/// What a run produced.
pub struct DaemonReport {
    /// The pipeline's records and timings.
    pub output: PipelineOutput,
    /// Metrics over the filter steps (as `infotrack sim` computes them).
    pub summary: RunSummary,
    /// Why it ended.
    pub stopped_by: StopReason,
    /// The vehicle's mode after the clean stop.
    pub final_mode: Option<Mode>,
    /// Mode changes the vehicle made by itself once armed (failsafes, the pilot, a GCS).
    pub unexpected_mode_changes: Vec<(Mode, Mode)>,
    /// Mode changes the vehicle made by itself before it first armed (its start-up).
    pub mode_changes_before_arming: Vec<(Mode, Mode)>,
    /// Times the link lost the vehicle's heartbeat.
    pub link_losses: u32,
    /// Setpoints refused by the geofence check.
    pub geofence_refusals: u64,
    /// Setpoints streamed to the vehicle.
    pub setpoints_sent: u64,
    /// Their rate between the first and the last, Hz (`None` before two).
    pub setpoint_rate_hz: Option<f64>,
    /// The firmware flown.
    pub flavor: Flavor,
    /// Where it was reached (`mock:px4 via udpout:...` or the URL).
    pub vehicle: String,
    /// The in-process vehicle, when the vehicle was one (for tests).
    pub mock: Option<Box<dyn InProcessVehicle>>,
}
