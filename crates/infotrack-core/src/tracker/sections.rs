//! The tracker's tables of a configuration: loop rates and the operator's cue.

use serde::{Deserialize, Serialize};

use crate::check::{invalid, positive, Checked};
use crate::world::geometry::{BoundsEnu, Enu2};
use crate::world::road::RoadNetwork;

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
    /// Where the target is said to be, `[x, y]` in the world ENU frame, metres. Absent with
    /// a recorded target (`target.trajectory`): each run is cued where its track starts
    /// (the simulator knows it; an operator would say it). Needed otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cue_enu_m: Option<[f64; 2]>,
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
    /// by length alone (the simpler prior). Absent: `traffic`.
    #[serde(default)]
    pub prior: Option<crate::world::road::RoadWeighting>,
}

impl TimingConfig {
    /// Checks `timing`: positive rates, physics at least as fast as the loops it drives.
    pub fn check(&self) -> Checked {
        positive("timing.filter_hz", self.filter_hz)?;
        positive("timing.guidance_hz", self.guidance_hz)?;
        positive("timing.physics_hz", self.physics_hz)?;
        positive("timing.duration_s", self.duration_s)?;
        if self.physics_hz < self.filter_hz || self.physics_hz < self.guidance_hz {
            return Err(invalid(
                "timing.physics_hz",
                self.physics_hz,
                "must be at least timing.filter_hz and timing.guidance_hz",
            ));
        }
        Ok(())
    }
}

impl AcquisitionConfig {
    /// Checks `acquisition`: a radius, a slowest speed up to `cv_max_speed_mps`
    /// (`motion.cv_max_speed_mps`), a cue (when given) inside the workspace `ws` with a road
    /// of `roads` within its radius.
    pub fn check(&self, ws: &BoundsEnu, cv_max_speed_mps: f64, roads: &RoadNetwork) -> Checked {
        positive("acquisition.cue_radius_m", self.cue_radius_m)?;
        if let Some(v) = self.min_speed_mps {
            if !(v.is_finite() && (0.0..=cv_max_speed_mps).contains(&v)) {
                return Err(invalid(
                    "acquisition.min_speed_mps",
                    v,
                    &format!("must lie in [0, motion.cv_max_speed_mps = {cv_max_speed_mps}] m/s"),
                ));
            }
        }
        let Some(cue_enu_m) = self.cue_enu_m else {
            return Ok(());
        };
        let cue = Enu2::new(cue_enu_m[0], cue_enu_m[1]);
        if !(cue.x.is_finite() && cue.y.is_finite() && ws.contains(&cue)) {
            return Err(invalid(
                "acquisition.cue_enu_m",
                cue_enu_m,
                &format!(
                    "must lie inside the workspace (workspace_enu: x {}..{}, y {}..{})",
                    ws.x_min_m, ws.x_max_m, ws.y_min_m, ws.y_max_m
                ),
            ));
        }
        if roads.length_within(Some((cue, self.cue_radius_m))) <= 0.0 {
            return Err(invalid(
                "acquisition.cue_enu_m",
                cue_enu_m,
                &format!(
                    "no road lies within acquisition.cue_radius_m = {} m of the cue: the target \
                     drives on the roads, so the cue must be near one",
                    self.cue_radius_m
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cue_must_lie_near_a_road_inside_the_workspace() {
        let lab = crate::testing::Config::default_lab();
        let roads = RoadNetwork::try_from(&lab.road).expect("the lab's roads");
        let node = &lab.road.nodes[0];
        let mut cue = AcquisitionConfig {
            cue_enu_m: Some([node.x_m, node.y_m]),
            cue_radius_m: 20.0,
            min_speed_mps: None,
            prior: None,
        };
        let ws = &lab.workspace_enu;
        let v_max = lab.motion.cv_max_speed_mps;
        assert_eq!(cue.check(ws, v_max, &roads), Ok(()));
        cue.min_speed_mps = Some(v_max + 0.1);
        let e = cue.check(ws, v_max, &roads).unwrap_err();
        assert_eq!(e.key, "acquisition.min_speed_mps");
        cue.min_speed_mps = None;
        cue.cue_enu_m = Some([ws.x_max_m + 1.0, node.y_m]);
        let e = cue.check(ws, v_max, &roads).unwrap_err();
        assert_eq!(e.key, "acquisition.cue_enu_m");
    }

    #[test]
    fn physics_must_be_at_least_as_fast_as_the_loops() {
        let mut timing = crate::testing::Config::default_lab().timing;
        assert_eq!(timing.check(), Ok(()));
        timing.physics_hz = timing.filter_hz / 2.0;
        assert_eq!(timing.check().unwrap_err().key, "timing.physics_hz");
    }
}
