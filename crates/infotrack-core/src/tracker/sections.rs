//! The tracker's tables of a configuration: loop rates and the operator's cue.

use serde::{Deserialize, Serialize};

/// Loop rates and run length.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimingConfig {
    /// Particle filter (and measurement) rate, Hz; its period is the motion model's dt.
    pub filter_hz: f64,
    /// Guidance rate, Hz.
    pub guidance_hz: f64,
    /// Physics integration rate of the simulators, Hz.
    pub physics_hz: f64,
    /// Length of one run, seconds.
    pub duration_s: f64,
}

/// The operator's cue: where the target is when tracking starts, and how sure they are.
/// Without one, the filter starts spread over the whole road network.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AcquisitionConfig {
    /// Where the target is said to be, `[x, y]` in the world ENU frame, metres.
    pub cue_enu_m: [f64; 2],
    /// How sure: the target is on a road within this radius of the cue, metres.
    pub cue_radius_m: f64,
    /// The slowest speed the search from the cue assumes the target drives at, m/s: the
    /// prior's hypotheses (and the re-spread's until the first sighting) get speeds from
    /// this to `motion.cv_max_speed_mps`. Absent: half of `motion.cv_max_speed_mps` (a
    /// cued target is on the move). 0: the target may be standing.
    #[serde(default)]
    pub min_speed_mps: Option<f64>,
    /// How the belief is spread over the roads within the cue's radius (and, until the
    /// first sighting, the re-spread from them): `traffic`, each road by its share of the
    /// traffic per metre that a car driving the road graph's turn probabilities puts on it
    /// (past a fork, a 0.75 turn holds three times the belief of a 0.25 one), or `length`,
    /// by length alone (before session 55). Absent: `traffic`.
    #[serde(default)]
    pub prior: Option<crate::world::road::RoadWeighting>,
}
