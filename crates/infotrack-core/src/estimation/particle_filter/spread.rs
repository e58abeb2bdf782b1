//! Placing particles on the roads: the prior from a cue, the re-spread along routes, the
//! re-routing at junctions and the hypotheses injected while the target is unseen.

use super::*;

impl ParticleFilter {
    /// A filter with particles on the roads of `world` within `region` (a centre and a
    /// radius, world ENU; `None`: the whole network), each moving along its road's
    /// allowed direction at a speed drawn from `speeds_mps`.
    pub fn on_roads<R: Rng + ?Sized>(
        params: FilterParams,
        world: &World,
        region: Option<(Enu2, f64)>,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) -> Self {
        let mut pf = Self::new(params, world.workspace_enu, rng);
        pf.spread_on_roads_at(world, region, speeds_mps, rng);
        pf
    }

    /// A filter with particles on the roads within `region` (a centre and a radius, world
    /// ENU) drawn as `weighting` says (by traffic: where a car driving the road graph is
    /// likely to be, [`crate::world::road::RoadNetwork::traffic_within`]), each moving along
    /// its road's allowed direction at a speed drawn from `speeds_mps`; as
    /// [`Self::on_roads`] where no road in the region carries weight.
    pub fn on_weighted_roads<R: Rng + ?Sized>(
        params: FilterParams,
        world: &World,
        region: (Enu2, f64),
        weighting: crate::world::road::RoadWeighting,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) -> Self {
        let roads = world.road.weighted_within(Some(region), weighting);
        if roads.length_m() <= 0.0 {
            return Self::on_roads(params, world, Some(region), speeds_mps, rng);
        }
        let mut pf = Self::new(params, world.workspace_enu, rng);
        pf.spread_on_pieces(&roads, speeds_mps, rng);
        pf
    }

    /// Starts over on the roads within `region` (see [`Self::on_roads`]); where no road
    /// lies in the region, on the whole network; without roads, over the workspace.
    pub fn spread_on_roads<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        region: Option<(Enu2, f64)>,
        rng: &mut R,
    ) {
        let speeds = 0.0..=self.params.init_speed_max_mps;
        self.spread_on_roads_at(world, region, speeds, rng);
    }

    /// [`Self::spread_on_roads`] with speeds drawn from `speeds_mps`.
    pub fn spread_on_roads_at<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        region: Option<(Enu2, f64)>,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) {
        let roads = world.road.roads_within_or_all(region);
        self.spread_on_pieces(&roads, speeds_mps, rng);
    }

    /// Starts over on `roads` (drawn by weighted length, moving along their direction at
    /// speeds from `speeds_mps`); over the workspace when they are empty.
    pub fn spread_on_pieces<R: Rng + ?Sized>(
        &mut self,
        roads: &RoadPieces,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) {
        if roads.length_m() <= 0.0 {
            self.redraw_uniform(rng);
            return;
        }
        for i in 0..self.weights.len() {
            self.seed_on_roads(i, roads, speeds_mps.clone(), rng);
        }
        let n = self.weights.len();
        self.weights.fill(1.0 / n as f64);
    }

    /// Starts over with every particle on a route the target can have driven from `start`
    /// (see [`RouteStart`]) for `driven_s` seconds at one speed drawn from
    /// `speeds_mps`, its turns drawn by their probabilities ([`crate::world::road::RoadNetwork::drive`]). A
    /// particle's history is its route's last positions; its weight is the likelihood along
    /// its route of the empty frames `looked` (seconds after the start, ascending, and where
    /// the camera was): `miss_probability` for each frame that would have seen it there.
    /// So what the camera has ruled out since the start stays ruled out, where spreading
    /// over the reachable roads would give it back its share. False (nothing changed)
    /// without roads.
    pub fn spread_along_routes<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        start: RouteStart<'_>,
        speeds_mps: std::ops::RangeInclusive<f64>,
        driven_s: f64,
        looked: &[(f64, View)],
        rng: &mut R,
    ) -> bool {
        let n = self.weights.len();
        let k = self.params.history_len;
        if n == 0 || k == 0 || world.road.nodes.is_empty() {
            return false;
        }
        let dt = self.params.dt_s;
        // The frames' times, then the history's (oldest first), driven in time order.
        let mut times: Vec<f64> = looked.iter().map(|(t, _)| t.max(0.0)).collect();
        times.extend((0..k).map(|j| (driven_s - (k - 1 - j) as f64 * dt).max(0.0)));
        let mut order: Vec<usize> = (0..times.len()).collect();
        order.sort_by(|a, b| times[*a].total_cmp(&times[*b]));
        let ln_miss = self.params.miss_probability.ln();
        let mut log_w = vec![0.0; n];
        let mut at = vec![Enu2::zeros(); times.len()];
        for (i, lw) in log_w.iter_mut().enumerate() {
            let (from, heading) = match start {
                // Where the target was is the measurement give or take its noise: each
                // route starts at its own draw. From the measurement itself, every route
                // shared one start, and a car last measured a few metres short of an
                // occlusion left every route the first empty frame would have seen
                // refuted at 1e-6 except the fastest few: the re-spread put all the weight
                // on ~1 % of the routes, at the top speed, and ran ahead of the car
                // (BENCHMARKS.md).
                RouteStart::At(z, heading) => (z + world.measurement.noise.sample(rng), heading),
                RouteStart::On(roads) => match roads.sample(rng) {
                    Some((p, dir)) => (p, Some(dir)),
                    None => return false,
                },
            };
            let speed = rng.gen_range(speeds_mps.clone());
            let distances: Vec<f64> = order.iter().map(|&j| speed * times[j]).collect();
            let Some(route) = world.road.drive(&from, heading, &distances, rng) else {
                return false;
            };
            for (&j, (p, _)) in order.iter().zip(route) {
                at[j] = p;
            }
            let seen = looked
                .iter()
                .zip(&at)
                .filter(|((_, camera), p)| world.is_wholly_visible(camera, p))
                .count();
            *lw = if seen == 0 {
                0.0
            } else {
                seen as f64 * ln_miss
            };
            let tr = self.histories.track_mut(i);
            for (j, p) in at[looked.len()..].iter().enumerate() {
                tr[2 * j] = p.x;
                tr[2 * j + 1] = p.y;
            }
        }
        let max = log_w.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        if max.is_finite() {
            for (w, lw) in self.weights.iter_mut().zip(&log_w) {
                *w = (lw - max).exp();
            }
        } else {
            self.weights.fill(1.0);
        }
        if !self.normalize() {
            self.weights.fill(1.0 / n as f64);
        }
        true
    }

    /// Gives `share` of the belief back to `before` (this filter as it was before a
    /// re-spread): a random `share` of the particles take their tracks back from `before`,
    /// and the weights become `share` x `before`'s weights over those plus (1 - share) x the
    /// re-spread's weights over the rest, each group normalised on its own. A defensive
    /// mixture of two approximations of one posterior: the re-spread puts back hypotheses
    /// a long search lost to resampling, the kept share keeps the resolution the filter had
    /// reached where the camera has not looked. False, with nothing changed, when the
    /// filters differ in size or track length, `share` is not inside (0, 1), or either group
    /// is empty or carries no weight.
    pub fn keep_part_of<R: Rng + ?Sized>(
        &mut self,
        before: &ParticleFilter,
        share: f64,
        rng: &mut R,
    ) -> bool {
        let n = self.weights.len();
        if before.weights.len() != n
            || before.histories.k_in() != self.histories.k_in()
            || !(share > 0.0 && share < 1.0)
        {
            return false;
        }
        let kept: Vec<bool> = (0..n).map(|_| rng.gen_bool(share)).collect();
        let group_sum = |w: &[f64], want: bool| -> f64 {
            w.iter()
                .zip(&kept)
                .filter(|(_, k)| **k == want)
                .map(|(w, _)| *w)
                .sum()
        };
        let (old_sum, new_sum) = (
            group_sum(&before.weights, true),
            group_sum(&self.weights, false),
        );
        if !(old_sum > 0.0 && new_sum > 0.0 && old_sum.is_finite() && new_sum.is_finite()) {
            return false;
        }
        for (i, keep) in kept.iter().enumerate() {
            if *keep {
                self.histories
                    .track_mut(i)
                    .copy_from_slice(before.histories.track(i));
                self.weights[i] = share * before.weights[i] / old_sum;
            } else {
                self.weights[i] *= (1.0 - share) / new_sum;
            }
        }
        true
    }

    /// Re-routes in place every particle within a step of a junction: a constant-velocity
    /// particle drives straight on through a junction, off the road, where the road
    /// constraint kills it; so each one whose next step leaves its road is put on one of the
    /// roads it can take within that step (the turns drawn by their graph probabilities, the
    /// turn back at a node with a two-way street included: [`road_following::reroute_track`]),
    /// keeping its speed and its weight. The belief then goes through a junction the way the target can,
    /// every branch in proportion (with 2 % of the particles per step made road-following
    /// clones instead, a corner kept ~2 % of the weight that reached it, the belief
    /// slowed from 14 to 5-8 m/s at corners and slow clusters sat at the roads' ends;
    /// BENCHMARKS.md). A particle whose step stays on its road (one
    /// piece ahead, or two with the straight-on step within half a road sigma of a road:
    /// a bend it follows anyway) is left alone; one more than three road sigmas off every road
    /// with one piece ahead is put on that piece. Nothing without roads.
    pub fn reroute_at_junctions<R: Rng + ?Sized>(&mut self, world: &World, rng: &mut R) {
        let dt = self.params.dt_s;
        let on_road_m = 0.5 * self.params.road_sigma_m.unwrap_or(0.0);
        for i in 0..self.weights.len() {
            road_following::reroute_track(&mut self.histories, i, world, dt, on_road_m, rng);
        }
    }

    /// An index drawn with probability proportional to its weight.
    pub(super) fn draw_by_weight<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        let total: f64 = self.weights.iter().sum();
        let mut u = rng.gen_range(0.0..total.max(f64::MIN_POSITIVE));
        for (i, w) in self.weights.iter().enumerate() {
            if u < *w {
                return i;
            }
            u -= w;
        }
        self.weights.len() - 1
    }

    /// Weighted mean velocity, world ENU, m/s: each particle's motion over its last (up to)
    /// three filter periods, which averages out most of the process noise of single steps.
    pub fn mean_velocity(&self) -> Enu2 {
        let k = self.params.history_len;
        if k < 2 {
            return Enu2::zeros();
        }
        let span = (k - 1).min(3);
        let mut v = Enu2::zeros();
        for (i, w) in self.weights.iter().enumerate() {
            v += (self.histories.at(i, k - 1) - self.histories.at(i, k - 1 - span)) * *w;
        }
        v / (span as f64 * self.params.dt_s)
    }

    /// Replaces `count` particles drawn at random with new ones on the roads within
    /// `region` (see [`Self::on_roads`]), each given the mean weight: fresh hypotheses where
    /// the target can have gone, that the next frames confirm or rule out (sensor resetting,
    /// as in augmented Monte Carlo localisation).
    pub fn inject_on_roads<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        region: Option<(Enu2, f64)>,
        count: usize,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) {
        if count == 0 {
            return;
        }
        let roads = world.road.roads_within_or_all(region);
        self.inject_on_pieces(&roads, count, speeds_mps, rng);
    }

    /// Replaces `count` particles drawn at random by hypotheses on `roads` (see
    /// [`Self::spread_on_pieces`]) with the mean weight; nothing when `roads` is empty.
    pub fn inject_on_pieces<R: Rng + ?Sized>(
        &mut self,
        roads: &RoadPieces,
        count: usize,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) {
        let n = self.weights.len();
        if count == 0 || roads.length_m() <= 0.0 {
            return;
        }
        let w = 1.0 / n as f64;
        for _ in 0..count.min(n) {
            let i = rng.gen_range(0..n);
            if !self.seed_on_roads(i, roads, speeds_mps.clone(), rng) {
                return;
            }
            self.weights[i] = w;
        }
        self.normalize();
    }

    /// Particle `i` becomes a straight track along one of `roads`, ending at a point drawn
    /// on them, at a speed drawn from `speeds_mps`; false when there is no road.
    fn seed_on_roads<R: Rng + ?Sized>(
        &mut self,
        i: usize,
        roads: &RoadPieces,
        speeds_mps: std::ops::RangeInclusive<f64>,
        rng: &mut R,
    ) -> bool {
        let dt = self.params.dt_s;
        road_following::straight_track_on_roads(&mut self.histories, i, roads, speeds_mps, dt, rng)
    }

    /// Starts over with no information: on the roads or over the workspace (see
    /// [`FilterParams::redraw_on_roads`]).
    pub(super) fn redraw<R: Rng + ?Sized>(&mut self, world: &World, rng: &mut R) {
        if self.params.redraw_on_roads {
            self.spread_on_roads(world, None, rng);
        } else {
            self.redraw_uniform(rng);
        }
    }
}
