//! `infotrack replay`: re-runs estimation and guidance on a recorded flight log, with the
//! flight's seed, and compares with what was flown. The particle filter sees exactly the
//! inputs it saw in flight (frames taken or not, measurements, vehicle positions), in the
//! same order and with the same random stream, so its estimates must agree to the last bit;
//! guidance is re-decided after every filter step and compared with the command that was in
//! force (in flight it ran on its own clock, so this is a comparison, not a reproduction).

use serde::Serialize;

use super::flight_log::LoggedStep;
use crate::config::Config;
use crate::estimation::{FilterError, FilterParams, ParticleFilter};
use crate::guidance::{EerParams, EerPlanner};
use crate::motion::{self, MotionError};
use crate::rng::{stream_rng, Stream};
use crate::world::geometry::Enu2;
use crate::world::World;

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
    /// The motion model.
    #[error(transparent)]
    Motion(#[from] MotionError),
    /// The filter.
    #[error(transparent)]
    Filter(#[from] FilterError),
}

/// Replays `steps` (from [`super::flight_log::parse`]) with the flight's `seed` and motion
/// model.
pub fn replay(
    cfg: &Config,
    motion_name: &str,
    seed: u64,
    steps: &[LoggedStep],
) -> Result<ReplayReport, ReplayError> {
    let world = World::from_config(cfg);
    // The streams the pipeline used, in the order it drew from them.
    let mut rng_filter = stream_rng(seed, 0, Stream::Filter, 0);
    let mut rng_guid = stream_rng(seed, 0, Stream::Guidance, 0);
    let mut model = motion::build(motion_name, cfg)?;
    let mut pf = ParticleFilter::new(
        FilterParams::from_config(cfg),
        world.workspace_enu,
        &mut rng_filter,
    );
    let mut planner = EerPlanner::new(EerParams::from_config(cfg));
    let mut max_diff: f64 = 0.0;
    let (mut wp_sum, mut wp_n) = (0.0, 0usize);
    let mut estimates = Vec::with_capacity(steps.len());
    for s in steps {
        if s.frame {
            pf.step(
                model.as_mut(),
                s.measurement_enu,
                &s.vehicle_enu,
                &world,
                &mut rng_filter,
            )?;
        } else {
            pf.step_blind(model.as_mut(), &mut rng_filter)?;
        }
        let est = pf.mean();
        max_diff = max_diff.max((est - s.estimate_enu).norm());
        estimates.push(est);
        if let Some(flown) = s.command_enu {
            let d = planner.plan(&pf, model.as_mut(), &s.vehicle_enu, &world, &mut rng_guid)?;
            wp_sum += (d.waypoint_enu - flown).norm();
            wp_n += 1;
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
