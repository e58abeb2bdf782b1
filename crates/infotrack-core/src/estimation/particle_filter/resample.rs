//! Resampling and re-seeding: multinomial resampling with roughening, the re-seed around
//! the measurements and the uniform re-draw (the authors' scheme, thresholds a and b).

use super::*;

impl ParticleFilter {
    /// Multinomial resampling in O(N): sorted uniforms from normalised exponential spacings,
    /// walked against the cumulative weights. Whole histories are copied; weights reset.
    pub(super) fn resample_multinomial<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let n = self.weights.len();
        // u_(k) = S_k / S_{n+1} with S the partial sums of n+1 Exp(1) draws are the order
        // statistics of n uniforms.
        let mut spacings: Vec<f64> = (0..=n).map(|_| Exp1.sample(rng)).collect();
        let total: f64 = spacings.iter().sum();
        let mut acc = 0.0;
        for s in spacings.iter_mut() {
            acc += *s;
            *s = acc / total;
        }
        self.indices.clear();
        let mut cum = self.weights[0];
        let mut j = 0;
        for u in spacings.iter().take(n) {
            while *u > cum && j + 1 < n {
                j += 1;
                cum += self.weights[j];
            }
            self.indices.push(j);
        }
        self.histories
            .gather_into(&self.indices, &mut self.resampled);
        std::mem::swap(&mut self.histories, &mut self.resampled);
        self.weights.fill(1.0 / n as f64);
    }

    /// Gaussian jitter with sigma = c x per-axis spread x N^(-1/3); the whole track moves so
    /// the particle keeps the velocity its history encodes.
    pub(super) fn roughen<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let n = self.weights.len();
        if self.params.roughening == 0.0 || n < 2 {
            return;
        }
        let (mut lo, mut hi) = (Enu2::repeat(f64::INFINITY), Enu2::repeat(f64::NEG_INFINITY));
        for i in 0..n {
            let p = self.histories.newest(i);
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
        let k = self.params.roughening * (n as f64).powf(-1.0 / 3.0);
        let mut sigma = (hi - lo) * k;
        if let Some(road) = self.params.road_sigma_m {
            // A cloud spread along a long road would get jitter across it as large as its
            // length allows, which the road constraint then punishes on the roads that run
            // across the larger spread: keep the jitter within the road's width.
            sigma = sigma.map(|s| s.min(0.5 * road));
        }
        for i in 0..n {
            let jitter = Enu2::new(
                sigma.x * rng.sample::<f64, _>(StandardNormal),
                sigma.y * rng.sample::<f64, _>(StandardNormal),
            );
            self.histories.translate(i, &jitter);
        }
    }

    /// Every particle, every history slot: a recent measurement + N(0, R), equal weights.
    ///
    /// Slot t of the history takes the newest measurement at or before that step within
    /// the window (the oldest one for earlier slots), so the seeded tracks follow what was
    /// actually seen. With one measurement in the window (the target has just come back
    /// into view) every slot would take it and every track would stand still: a car that
    /// drives out from under a bridge at 14 m/s was followed by a belief at rest, slow
    /// hypotheses under the bridge the camera cannot refute took the weight, and the car
    /// was lost for good (field-ring, BENCHMARKS.md). So, with
    /// `keep_velocity` (a motion model that does not know the roads: constant velocity, whose
    /// state the track's velocity is), each track through one measurement moves at the
    /// velocity of a particle drawn by weight, the prediction's own belief of how the target
    /// moves. The DMMN reads its motion from the history and the roads it learned; there the
    /// change measured neutral (lab closed loop, 16 seeds: +0.9 points, the config's seed
    /// -6.7) and it is left as it was.
    pub(super) fn reseed_around_measurements<R: Rng + ?Sized>(
        &mut self,
        world: &World,
        keep_velocity: bool,
        rng: &mut R,
    ) {
        let k = self.params.history_len;
        let n = self.weights.len();
        let now = self.step_index;
        let window_start = now.saturating_sub(k as u64 - 1);
        let in_window: Vec<(u64, Enu2)> = self
            .recent
            .iter()
            .filter(|(s, _)| *s >= window_start)
            .cloned()
            .collect();
        let Some(&(_, oldest)) = in_window.first() else {
            self.redraw(world, rng);
            return;
        };
        let slot_centre: Vec<Enu2> = (0..k)
            .map(|t| {
                // Slots before the filter's first step (a re-seed within its first k
                // steps) take the oldest measurement; this used to wrap around in u64 and
                // took the newest.
                (now + t as u64 + 1)
                    .checked_sub(k as u64)
                    .and_then(|step| in_window.iter().rev().find(|(s, _)| *s <= step))
                    .map(|(_, z)| *z)
                    .unwrap_or(oldest)
            })
            .collect();
        let dt = self.params.dt_s;
        let velocities = if keep_velocity && in_window.len() < 2 {
            self.velocities_drawn_by_weight(rng)
        } else {
            vec![Enu2::zeros(); n]
        };
        for (i, v) in velocities.iter().enumerate() {
            let tr = self.histories.track_mut(i);
            for (t, c) in slot_centre.iter().enumerate() {
                let p = world.measurement.measure(c, rng) - v * ((k - 1 - t) as f64 * dt);
                tr[2 * t] = p.x;
                tr[2 * t + 1] = p.y;
            }
        }
        self.weights.fill(1.0 / n as f64);
    }

    /// One velocity per particle (world ENU, m/s), each a particle's mean velocity over its
    /// history, the particle drawn by weight; each particle's own where the weights are
    /// degenerate (all zero or not finite: a recovery).
    fn velocities_drawn_by_weight<R: Rng + ?Sized>(&self, rng: &mut R) -> Vec<Enu2> {
        let by_weight =
            self.weights.iter().all(|w| w.is_finite()) && self.weights.iter().sum::<f64>() > 0.0;
        (0..self.weights.len())
            .map(|i| {
                let j = if by_weight {
                    self.draw_by_weight(rng)
                } else {
                    i
                };
                self.track_velocity(j)
            })
            .collect()
    }

    /// Track `i`'s mean velocity over its whole history, world ENU, m/s; zero when not
    /// finite or when the history holds one position.
    pub(super) fn track_velocity(&self, i: usize) -> Enu2 {
        road_following::track_velocity(&self.histories, i, self.params.dt_s)
    }

    /// Uniform positions over the workspace, each with a straight track at a speed drawn
    /// from [0, init_speed_max] and a uniform heading; equal weights.
    pub(super) fn redraw_uniform<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let ws = self.workspace_enu;
        let k = self.params.history_len;
        let n = self.weights.len();
        for i in 0..n {
            let p = Enu2::new(
                rng.gen_range(ws.x_min_m..=ws.x_max_m),
                rng.gen_range(ws.y_min_m..=ws.y_max_m),
            );
            let speed = rng.gen_range(0.0..=self.params.init_speed_max_mps);
            let heading = rng.gen_range(0.0..std::f64::consts::TAU);
            let v_step = Enu2::new(heading.cos(), heading.sin()) * speed * self.params.dt_s;
            let tr = self.histories.track_mut(i);
            for t in 0..k {
                let q = p - v_step * (k - 1 - t) as f64;
                tr[2 * t] = q.x;
                tr[2 * t + 1] = q.y;
            }
        }
        self.weights.fill(1.0 / n as f64);
    }
}
