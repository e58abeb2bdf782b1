//! What goes into the tracker at a tick and what comes out: the only contact between the
//! core loop and its sources (simulated target and sensor, rendered frames, a camera and
//! vehicle telemetry, a recorded log) and sinks (the agent simulator, the MAVLink link, a
//! comparison).

use nalgebra::Matrix2;

use crate::frames::Enu2;
use crate::metrics::StepRecord;
use crate::world::camera::View;

/// What the caller knows at a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickInput {
    /// Where the vehicle is, world ENU; `None` before its first reported position (the
    /// tick passes and what was due stays due).
    pub vehicle_enu: Option<Enu2>,
    /// Which way the camera's image faces now, world ENU yaw (rad; [`View::yaw_enu_rad`]):
    /// the vehicle's heading with the mount's yaw accounted for.
    pub view_yaw_enu_rad: f64,
    /// The vehicle's state is stale (no heartbeat): no decision is taken on it.
    pub link_lost: bool,
    /// The true target position, world ENU, where a simulator knows it (records and
    /// `truth` guidance); `None` in the field.
    pub truth_enu: Option<Enu2>,
    /// The true target's velocity, world ENU, m/s (zero where unknown).
    pub truth_velocity_enu: Enu2,
}

/// The filter's belief predicted to the next frame's time: where a sensor should look first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// Mean, world ENU.
    pub mean_enu: Enu2,
    /// Covariance, m^2.
    pub cov_m2: Matrix2<f64>,
}

/// What a sensor delivered at a filter step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Observation {
    /// A frame was taken from `taken_from`; `z` is the target's measured position, world
    /// ENU, or `None` when the frame did not show it (negative information).
    Frame {
        /// Where the camera was and which way its image faced when the frame was taken.
        taken_from: View,
        /// The measurement, if the target was seen.
        z: Option<Enu2>,
    },
    /// No frame (a frozen or lost camera): the filter predicts only.
    NoFrame,
}

/// A source of observations, asked once per filter step.
pub trait Sensor {
    /// Why an observation could not be made.
    type Error;

    /// The observation for the filter step at `t_s`, made from `view` (the vehicle's
    /// position and the camera's heading), looking first where `prior` says.
    fn observe(&mut self, t_s: f64, view: &View, prior: &Prior)
        -> Result<Observation, Self::Error>;
}

/// What the tracker asks the vehicle to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Fly a moving setpoint at the tracking altitude: at `position_enu` (inside the
    /// workspace) when the decision is taken, moving at `velocity_enu` from then on, the
    /// camera's image turned to face `view_yaw_enu_rad`; the
    /// velocity is also the autopilot's feed-forward, so that a vehicle following a moving
    /// target does not trail it by speed / position gain. Zero velocity: a fixed point. The
    /// sink stops the motion at the geofence.
    GoTo {
        /// Where the setpoint is at the decision, world ENU, m.
        position_enu: Enu2,
        /// How it moves, world ENU, m/s.
        velocity_enu: Enu2,
        /// Which way the camera's image should face, world ENU yaw (rad,
        /// [`View::yaw_enu_rad`]); the sink turns the vehicle (less the mount's yaw).
        view_yaw_enu_rad: f64,
    },
    /// Stay where it is.
    HoldHere,
}

impl Command {
    /// A fixed point, the view facing `view_yaw_enu_rad`.
    pub fn fixed(position_enu: Enu2, view_yaw_enu_rad: f64) -> Self {
        Self::GoTo {
            position_enu,
            velocity_enu: Enu2::zeros(),
            view_yaw_enu_rad,
        }
    }
}

/// Tracking state, for the status line, the log and the failsafes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackState {
    /// Seen within the target-lost time.
    Tracking,
    /// Not seen for longer: the fallback is flying.
    Lost,
    /// No fresh vehicle state: no new commands.
    LinkLost,
    /// No camera frames for the camera timeout: hold and report.
    CameraLost,
}

impl TrackState {
    /// Lower-case name.
    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Tracking => "tracking",
            Self::Lost => "lost",
            Self::LinkLost => "link-lost",
            Self::CameraLost => "camera-lost",
        }
    }
}

/// One filter step's outcome.
#[derive(Debug, Clone)]
pub struct StepOutcome {
    /// The simulator-compatible record (truth, vehicle, measurement, estimate, ...).
    pub record: StepRecord,
    /// Tracking state after the step.
    pub state: TrackState,
    /// Whether a frame was taken.
    pub frame: bool,
    /// The command in force after this step.
    pub command: Option<Command>,
    /// Entropy of the estimate at the latest EER decision (NaN before the first).
    pub entropy: f64,
    /// Time of the filter's prediction and update, ms (caller's clock).
    pub update_ms: f64,
    /// The filter failed at this step (only when failures are tolerated: the step is still
    /// recorded, with N_eff NaN).
    pub filter_error: Option<String>,
    /// The state changed to camera-lost at this step.
    pub camera_lost_now: bool,
}

/// One guidance decision's outcome.
#[derive(Debug, Clone, PartialEq)]
pub enum Decision {
    /// A new command, in force from now.
    Command {
        /// What to do.
        command: Command,
        /// Compute time of the decision, ms.
        compute_ms: f64,
    },
    /// The decision took longer than the budget and was not applied.
    Overrun {
        /// Its compute time, ms.
        compute_ms: f64,
    },
    /// The guidance law failed (only when failures are tolerated); the command in force
    /// stays.
    Failed {
        /// Why.
        reason: String,
        /// Compute time, ms.
        compute_ms: f64,
        /// It also took longer than the budget.
        over_budget: bool,
    },
}

/// What one tick produced.
#[derive(Debug, Clone, Default)]
pub struct TickOutput {
    /// Time of the tick since tracking began, s.
    pub t_s: f64,
    /// The filter step, if one ran.
    pub step: Option<StepOutcome>,
    /// The guidance decision, if one was taken.
    pub decision: Option<Decision>,
}
