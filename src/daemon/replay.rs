//! `infotrack replay`: re-runs estimation and guidance on a recorded flight log, with the
//! flight's seed, and compares with what was flown. The particle filter sees exactly the
//! inputs it saw in flight (frames taken or not, measurements, vehicle positions), in the
//! same order and with the same random stream, so its estimates must agree to the last bit;
//! guidance is re-decided after every filter step and compared with the command that was in
//! force (in flight it ran on its own clock, so this is a comparison, not a reproduction).

use serde::Serialize;

use super::flight_log::LoggedStep;
use super::heading::view_yaw_enu_of_nose;
use crate::config::Config;
use crate::guidance::GuidanceKind;
use crate::rng::{stream_rng, Stream};
use crate::tracker::{
    Command, Decision, EstimatorKind, FrozenClock, Observation, TickInput, Tracker, TrackerError,
    UnknownEstimator,
};
use crate::world::camera::View;
use crate::world::geometry::Enu2;

/// What the replay found.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayReport {
    /// Filter steps replayed.
    pub steps: usize,
    /// Largest distance between a replayed and a recorded estimate, m.
    pub max_estimate_diff_m: f64,
    /// Mean distance between the replayed EER waypoint and the waypoint in force, m.
    pub mean_waypoint_diff_m: f64,
    /// Steps with a recorded waypoint to compare with.
    pub waypoints_compared: usize,
    /// Replayed estimates, world ENU, one per step.
    #[serde(skip)]
    pub estimates_enu: Vec<Enu2>,
}

/// Why a replay failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The log's motion model is not one infotrack has.
    #[error(transparent)]
    Motion(#[from] UnknownEstimator),
    /// The tracker (its motion model, its filter).
    #[error(transparent)]
    Tracker(#[from] TrackerError),
}

/// Replays `steps` (from [`super::flight_log::parse`]) with the flight's `seed` and motion
/// model, through the same tracker the flight ran (without its failsafes: the flight's
/// frames, taken or not, are the log's).
pub fn replay(
    cfg: &Config,
    motion_name: &str,
    seed: u64,
    steps: &[LoggedStep],
) -> Result<ReplayReport, ReplayError> {
    // The streams the pipeline used, in the order it drew from them.
    let params = cfg.tracker_params(GuidanceKind::Eer, false);
    let model = EstimatorKind::parse(motion_name)?
        .build(&params.motion, &infotrack_dmmn::load_learned)
        .map_err(crate::tracker::TrackerError::from)?;
    let mut tracker = Tracker::new(
        params,
        cfg.world_seen_by_detector(),
        model,
        stream_rng(seed, 0, Stream::Filter, 0),
        stream_rng(seed, 0, Stream::Guidance, 0),
    )?;
    let mount_yaw_rad = cfg.daemon.camera_mount_rpy_rad[2];
    let mut max_diff: f64 = 0.0;
    let (mut wp_sum, mut wp_n) = (0.0, 0usize);
    let mut estimates = Vec::with_capacity(steps.len());
    for s in steps {
        // The camera's view as the flight had it: the logged heading turned by the mount.
        let view = View::new(
            s.vehicle_enu,
            view_yaw_enu_of_nose(s.vehicle_yaw_ned_rad, mount_yaw_rad),
        );
        let observation = if s.frame {
            Observation::Frame {
                taken_from: view,
                z: s.measurement_enu,
            }
        } else {
            Observation::NoFrame
        };
        let input = TickInput {
            vehicle_enu: Some(s.vehicle_enu),
            view_yaw_enu_rad: view.yaw_enu_rad,
            link_lost: false,
            truth_enu: None,
            truth_velocity_enu: Enu2::zeros(),
        };
        let step = tracker.update(s.t_s, observation, &input, &FrozenClock)?;
        let est = step.record.estimate_enu;
        max_diff = max_diff.max((est - s.estimate_enu).norm());
        estimates.push(est);
        if let Some(flown) = s.command_enu {
            let decided = tracker.decide(s.t_s, &view, None, &FrozenClock)?;
            if let Some(Decision::Command {
                command: Command::GoTo {
                    position_enu: w, ..
                },
                ..
            }) = decided
            {
                wp_sum += (w - flown).norm();
                wp_n += 1;
            }
        }
    }
    Ok(ReplayReport {
        steps: steps.len(),
        max_estimate_diff_m: max_diff,
        mean_waypoint_diff_m: if wp_n > 0 {
            wp_sum / wp_n as f64
        } else {
            f64::NAN
        },
        waypoints_compared: wp_n,
        estimates_enu: estimates,
    })
}
