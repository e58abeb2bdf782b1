//! Where the target can be while it is unseen: the measured track, the speeds of the
//! hypotheses, the re-spread along the roads and the hypotheses injected before the first
//! sighting.

use super::*;

impl Tracker {
    pub(super) fn remember_measurement(&mut self, t_s: f64, z: Enu2) {
        self.last_measurement = Some((t_s, z));
        self.recent_measurements.push_back((t_s, z));
        while self
            .recent_measurements
            .front()
            .is_some_and(|(t, _)| t_s - t > MEASURED_TRACK_S)
        {
            self.recent_measurements.pop_front();
        }
    }

    /// The target's velocity as its measurements of the last [`MEASURED_TRACK_S`] seconds
    /// show it (first to last), when they span at least half that; else the estimate's.
    /// After a re-seed a particle filter's velocity starts again from zero, and the speed
    /// the re-spread bands are drawn with must not: measured motion is what the target did.
    pub(super) fn measured_velocity(&self) -> Enu2 {
        match (
            self.recent_measurements.front(),
            self.recent_measurements.back(),
        ) {
            (Some((t0, z0)), Some((t1, z1))) if t1 - t0 >= 0.5 * MEASURED_TRACK_S => {
                (z1 - z0) / (t1 - t0)
            }
            _ => self.estimator.velocity(),
        }
    }

    /// The way the target was driving when last seen, when its measurements showed it
    /// moving (faster than a tenth of the largest speed a hypothesis gets, and at least half
    /// the fastest it was measured cruising at over the last [`CRUISE_WINDOW_S`]); `None`
    /// for a target seen (nearly) standing, whose measured velocity is the measurement
    /// noise's. A car that had stopped at a junction to turn was last measured at 0.6 m/s
    /// "west", and every re-spread route started on the road west while it drove south
    /// (field-ring seed 2, BENCHMARKS.md); without a heading each
    /// route starts on the road nearest its own draw of where the target was, either way
    /// along a two-way street. A car last measured pulling out of a turn back (1.6 m/s after
    /// cruising at 12) had for a heading the chord of its turn, 50 degrees off the road it
    /// took: every route went up the crossing road, the filter's belief on the right road
    /// was thrown away, and the car was never found again (random-6, BENCHMARKS.md).
    pub(super) fn last_seen_heading(&self) -> Option<Enu2> {
        let s = self.last_seen_speed_mps;
        let moving =
            s > 0.1 * self.params.filter.init_speed_max_mps && s >= 0.5 * self.cruise_mps();
        moving.then_some(self.last_seen_velocity_enu)
    }

    /// The fastest the target was measured driving over the last [`CRUISE_WINDOW_S`], m/s.
    fn cruise_mps(&self) -> f64 {
        self.recent_speeds
            .iter()
            .map(|(_, v)| *v)
            .fold(self.last_seen_speed_mps, f64::max)
    }

    /// The speeds new hypotheses get: from 0.7 x the speed the target had when last seen
    /// to 1.3 x the fastest it was measured driving over the last [`CRUISE_WINDOW_S`] (a
    /// car keeps its speed through a junction it cannot be seen at, and one last seen
    /// slowing for a turn drives on at its cruising speed); never seen, the search from the
    /// cue's speeds (`TrackerParams::cue_speeds_mps`); seen not moving, any speed the motion
    /// model allows.
    pub(super) fn hypothesis_speeds(&self) -> std::ops::RangeInclusive<f64> {
        let v_max = self.params.filter.init_speed_max_mps;
        let s = self.last_seen_speed_mps;
        let cruise = self.cruise_mps();
        if self.last_measurement.is_some() && cruise > 0.1 * v_max {
            (0.7 * s).min(v_max)..=(1.3 * cruise).min(v_max)
        } else if self.last_measurement.is_none() {
            self.params.cue_speeds_mps.clone()
        } else {
            0.0..=v_max
        }
    }

    /// After `respread_after_s` without a measurement, and again at the times
    /// [`respread_due_s`] gives while the target stays unseen: the particles go back on
    /// the roads the target can have driven to since it was last seen, each on one route
    /// forward from the last measurement and weighted by the empty frames since
    /// ([`Self::respread_along_routes`]); never seen, each on a route from a point on the
    /// cue's roads, weighted by every empty frame since the start (the cue's
    /// roads carried forward instead gave the roads the drone had flown along empty
    /// their share back: on field-eight the car was never found in 4 runs of 10); anywhere
    /// without a cue. A disc around the last measurement would put half the belief behind
    /// the target and on roads it cannot have reached; spreading over the reachable roads
    /// alone gave the branches the camera had already ruled out their
    /// share back (field-grid: the belief that had found the car turning north was split
    /// even again at the re-spread, and the drone flew east after it).
    ///
    /// Re-spread once per spell, a long search lost the hypotheses it needed: the
    /// empty views killed every particle but those hidden under an occlusion, resampling
    /// multiplied those, and the belief sat under a warehouse for 150 s while the car, which
    /// had turned back there, drove away (outdoor seed 7). A repeated re-spread is drawn
    /// along routes only, and keeps [`RESPREAD_KEEP_SHARE`] of the filter's belief
    /// ([`ParticleFilter::keep_part_of`]); BENCHMARKS.md.
    pub(super) fn respread_if_long_unseen(&mut self, t_s: f64) {
        let Some(after) = self.params.respread_after_s else {
            return;
        };
        if t_s - self.last_seen_s <= respread_due_s(after, self.respreads_in_spell) {
            return;
        }
        let repeat = self.respreads_in_spell > 0;
        self.respreads_in_spell += 1;
        let before = match (&self.estimator, repeat) {
            (Estimator::Particle { pf, .. }, true) => Some(pf.clone()),
            _ => None,
        };
        if self.respread_along_routes(t_s) {
            if let (Some(before), Estimator::Particle { pf, .. }) = (before, &mut self.estimator) {
                // Refused (a group without weight), the routes stand alone, as a first
                // re-spread's do.
                pf.keep_part_of(&before, RESPREAD_KEEP_SHARE, &mut self.rng_filter);
            }
            return;
        }
        if repeat {
            // Without routes, a repeat would only spread the belief over the roads again
            // and give back what the camera has ruled out.
            return;
        }
        // No route to draw (no cue, or no road): the roads around where it can be.
        let speeds = self.hypothesis_speeds();
        let v_far = *speeds.end();
        let region = match self.last_measurement {
            Some((tm, zm)) => Some((zm, v_far * (t_s - tm))),
            None => self.params.cue.map(|(c, r)| (c, r + v_far * t_s)),
        };
        if let Estimator::Particle { pf, .. } = &mut self.estimator {
            pf.spread_on_roads_at(&self.world, region, speeds, &mut self.rng_filter);
        }
    }

    /// The re-spread along routes: every particle on a route the target can have driven
    /// since it was last measured (never seen: since the start, from a point on the cue's
    /// roads), weighted by the empty frames since (see
    /// [`ParticleFilter::spread_along_routes`]). False when it cannot be (never seen
    /// without a cue, no roads within it, or the Kalman filter).
    fn respread_along_routes(&mut self, t_s: f64) -> bool {
        let cue_roads;
        let (tm, start) = match (self.last_measurement, self.params.cue) {
            (Some((tm, zm)), _) => (tm, RouteStart::At(zm, self.last_seen_heading())),
            (None, Some(cue)) => {
                cue_roads = self
                    .world
                    .road
                    .weighted_within(Some(cue), self.params.cue_prior);
                if cue_roads.length_m() <= 0.0 {
                    return false;
                }
                (0.0, RouteStart::On(&cue_roads))
            }
            _ => return false,
        };
        let speeds = self.hypothesis_speeds();
        let looked: Vec<(f64, View)> = self
            .empty_frames
            .iter()
            .filter(|(t, _)| *t >= tm)
            .map(|(t, camera)| (t - tm, *camera))
            .collect();
        match &mut self.estimator {
            Estimator::Particle { pf, .. } => pf.spread_along_routes(
                &self.world,
                start,
                speeds,
                (t_s - tm).max(0.0),
                &looked,
                &mut self.rng_filter,
            ),
            Estimator::Kalman(_) => false,
        }
    }

    /// At each step without a measurement: once the target has been seen, the particles at
    /// a junction are re-routed onto the roads they can take, whatever the motion model
    /// (`ParticleFilter::reroute_at_junctions`: the belief itself, so what the agent has
    /// ruled out stays ruled out). A learned model that knows the roads still predicts one
    /// next position per track: at a fork it sends every track the same way (the outdoor
    /// DMMN: all of them on east at node 1, the car north), and only the re-routing splits
    /// the belief over the branches by their probabilities (BENCHMARKS.md). Before the first sighting, for a model that does not know the roads
    /// (constant velocity), a share of the particles (`injection_share`) is replaced by
    /// hypotheses on the roads around the belief (within two standard deviations of its
    /// mean plus a second at the largest speed). A share of 0 turns both off.
    pub(super) fn inject_where_it_can_be(&mut self) {
        let share = self.params.injection_share;
        if share <= 0.0 {
            return;
        }
        if self.last_measurement.is_some() {
            if let Estimator::Particle { pf, .. } = &mut self.estimator {
                pf.reroute_at_junctions(&self.world, &mut self.rng_filter);
            }
            return;
        }
        let knows_roads = match &self.estimator {
            Estimator::Particle { model, .. } => model.knows_the_roads(),
            Estimator::Kalman(_) => true,
        };
        if knows_roads {
            return;
        }
        // Only what the pre-sighting injection needs, computed only when it runs.
        let v_max = self.params.filter.init_speed_max_mps;
        let sd = self.estimator.largest_sd_m();
        let region = Some((self.estimator.mean(), 2.0 * sd + v_max));
        let speeds = self.hypothesis_speeds();
        let count = (share * self.params.filter.particles as f64).round() as usize;
        if let Estimator::Particle { pf, .. } = &mut self.estimator {
            pf.inject_on_roads(&self.world, region, count, speeds, &mut self.rng_filter);
        }
    }
}

/// How long after the last measurement the re-spread that follows `done` earlier ones in
/// the same spell is due, s: `after` for the first, then every `after` again while the
/// target stays unseen.
pub(super) fn respread_due_s(after_s: f64, done: u32) -> f64 {
    after_s * f64::from(done + 1)
}
