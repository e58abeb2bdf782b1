//! The simulated target: a unicycle that drives the road network's Markov chain.

use rand::Rng;

use infotrack_config::recorded_track::RecordedTrack;
use infotrack_config::TargetConfig;
use infotrack_core::world::geometry::{wrap_angle, Enu2};
use infotrack_core::world::road::RoadNetwork;

/// Target state in the world ENU frame.
#[derive(Debug, Clone)]
pub struct TargetSim {
    /// Position, metres.
    pub position_enu: Enu2,
    /// Heading from east, counter-clockwise, radians.
    pub heading_enu_rad: f64,
    /// Index of the node it is driving to.
    pub goal_node: usize,
    /// Velocity over the last step, m/s.
    pub velocity_enu: Enu2,
    params: TargetConfig,
    /// A recorded track driven instead of the roads' Markov chain, and the time along it.
    recorded: Option<(std::sync::Arc<RecordedTrack>, f64)>,
}

impl TargetSim {
    /// At the start node, facing its first sampled goal.
    pub fn new<R: Rng + ?Sized>(road: &RoadNetwork, params: TargetConfig, rng: &mut R) -> Self {
        let start = road.start;
        let goal = road.sample_next(start, rng);
        let p = road.nodes[start].position_enu;
        let d = road.nodes[goal].position_enu - p;
        Self {
            position_enu: p,
            heading_enu_rad: d.y.atan2(d.x),
            goal_node: goal,
            velocity_enu: Enu2::zeros(),
            params,
            recorded: None,
        }
    }

    /// At the start of a recorded track, which it then drives (`params` unused).
    pub fn recorded(track: std::sync::Arc<RecordedTrack>, params: TargetConfig) -> Self {
        let (p, _) = track.at(0.0);
        let ahead = track
            .samples
            .iter()
            .map(|s| s.1 - p)
            .find(|d| d.norm() > 1e-6);
        Self {
            position_enu: p,
            heading_enu_rad: ahead.map_or(0.0, |d| d.y.atan2(d.x)),
            goal_node: 0,
            velocity_enu: Enu2::zeros(),
            params,
            recorded: Some((track, 0.0)),
        }
    }

    /// The target of run `run_index`: recorded track `run_index mod n` of
    /// `target.trajectory`, or the simulated car on the roads.
    pub fn for_run<R: Rng + ?Sized>(
        cfg: &infotrack_config::Config,
        world: &infotrack_core::world::World,
        run_index: u64,
        rng: &mut R,
    ) -> Result<Self, infotrack_config::ConfigError> {
        let tracks = cfg.recorded_tracks()?;
        Ok(match tracks.len() {
            0 => Self::new(&world.road, cfg.target.clone(), rng),
            n => Self::recorded(
                tracks[(run_index % n as u64) as usize].clone(),
                cfg.target.clone(),
            ),
        })
    }

    /// The cue of a run whose target drives a recorded track and whose config leaves
    /// `acquisition.cue_enu_m` out: where the track starts, with the config's radius.
    pub fn cue(
        &self,
        cfg: &infotrack_config::Config,
    ) -> Option<(infotrack_core::frames::Enu2, f64)> {
        let radius_m = cfg.scenario().cue_at_track_start()?;
        let (track, _) = self.recorded.as_ref()?;
        Some((track.at(0.0).0, radius_m))
    }

    /// Whether a recorded track has ended (never, for the simulated car).
    pub fn ended(&self) -> bool {
        self.recorded
            .as_ref()
            .is_some_and(|(track, t_s)| *t_s >= track.duration_s())
    }

    /// Advances `dt_s`: switch goal near the current one, turn toward it (in place above the
    /// heading-error threshold), drive at cruise speed.
    pub fn step<R: Rng + ?Sized>(&mut self, road: &RoadNetwork, dt_s: f64, rng: &mut R) {
        if let Some((track, t_s)) = self.recorded.as_mut() {
            *t_s += dt_s;
            let (p, v) = track.at(*t_s);
            self.position_enu = p;
            self.velocity_enu = v;
            if v.norm() > 1e-6 {
                self.heading_enu_rad = v.y.atan2(v.x);
            }
            return;
        }
        let p = &self.params;
        let mut to_goal = road.nodes[self.goal_node].position_enu - self.position_enu;
        if to_goal.norm() < p.goal_switch_radius_m {
            self.goal_node = road.sample_next(self.goal_node, rng);
            to_goal = road.nodes[self.goal_node].position_enu - self.position_enu;
        }
        let err = wrap_angle(to_goal.y.atan2(to_goal.x) - self.heading_enu_rad);
        let yaw_rate =
            (p.heading_gain_per_s * err).clamp(-p.max_yaw_rate_radps, p.max_yaw_rate_radps);
        self.heading_enu_rad = wrap_angle(self.heading_enu_rad + yaw_rate * dt_s);
        let speed = if err.abs() > p.turn_in_place_above_rad {
            0.0
        } else {
            p.cruise_speed_mps.min(p.max_speed_mps)
        };
        self.velocity_enu =
            Enu2::new(self.heading_enu_rad.cos(), self.heading_enu_rad.sin()) * speed;
        self.position_enu += self.velocity_enu * dt_s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use infotrack_config::Config;
    use infotrack_core::rng::CoreRng;
    use rand::SeedableRng;

    #[test]
    fn target_stays_on_the_roads_and_visits_nodes() {
        let c = Config::default_lab();
        let road = RoadNetwork::from_config(&c.road).unwrap();
        let mut rng = CoreRng::seed_from_u64(1);
        let mut t = TargetSim::new(&road, c.target.clone(), &mut rng);
        let edges = road.edges_enu();
        let dist_to_road = |p: &Enu2| {
            edges
                .iter()
                .map(|(a, b)| {
                    let ab = b - a;
                    let s = ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
                    (p - (a + ab * s)).norm()
                })
                .fold(f64::INFINITY, f64::min)
        };
        let mut goals = std::collections::BTreeSet::new();
        let mut travelled = 0.0;
        for _ in 0..(90 * 30) {
            let before = t.position_enu;
            t.step(&road, 1.0 / 30.0, &mut rng);
            travelled += (t.position_enu - before).norm();
            goals.insert(t.goal_node);
            assert!(
                dist_to_road(&t.position_enu) < 0.15,
                "off road at {}",
                t.position_enu
            );
        }
        assert!(goals.len() >= 4, "{goals:?}");
        // Cruise 0.3 m/s minus turning time.
        assert!(
            travelled > 0.6 * 0.3 * 90.0 && travelled <= 0.3 * 90.0 + 1e-9,
            "{travelled}"
        );
    }
}
