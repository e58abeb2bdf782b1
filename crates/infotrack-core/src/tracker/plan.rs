//! The guidance decision: the law in force (or the failsafe's), EER's plan and the
//! setpoint it becomes.

use super::*;

impl Tracker {
    /// One guidance decision at `t_s` for a vehicle seeing `vehicle` (`truth`: the true
    /// target's position and velocity, world ENU, where a simulator knows them). `None`: no
    /// decision is taken on a stale vehicle state (link lost). Public for `infotrack
    /// replay`.
    pub fn decide(
        &mut self,
        t_s: f64,
        vehicle: &View,
        truth: Option<(Enu2, Enu2)>,
        clock: &dyn Clock,
    ) -> Result<Option<Decision>, TrackerError> {
        if self.state == TrackState::LinkLost {
            return Ok(None);
        }
        let started = clock.now_s();
        self.planned_view_yaw_enu_rad = None;
        let decided = self.choose(t_s, vehicle, truth);
        let compute_ms = (clock.now_s() - started) * 1e3;
        let failsafe = self.params.failsafe;
        let over_budget = failsafe.is_some_and(|f| compute_ms > f.guidance_budget_ms);
        if let Some(f) = failsafe.filter(|_| self.params.guidance == GuidanceKind::Eer) {
            self.adapt_effort(compute_ms, f.guidance_budget_ms);
        }
        let command = match decided {
            Ok(c) => c,
            Err(e) if failsafe.is_some() => {
                return Ok(Some(Decision::Failed {
                    reason: e.to_string(),
                    compute_ms,
                    over_budget,
                }))
            }
            Err(e) => return Err(e),
        };
        if over_budget {
            return Ok(Some(Decision::Overrun { compute_ms }));
        }
        let command = match command {
            Some((position_enu, velocity_enu)) => {
                let position_enu = self.world.workspace_enu.clamp(&position_enu);
                let by_rule =
                    self.params
                        .heading
                        .yaw_enu_rad(vehicle, &position_enu, &velocity_enu);
                Command::GoTo {
                    position_enu,
                    velocity_enu,
                    view_yaw_enu_rad: self.planned_view_yaw_enu_rad.unwrap_or(by_rule),
                }
            }
            None => Command::HoldHere,
        };
        self.command = Some(command);
        Ok(Some(Decision::Command {
            command,
            compute_ms,
        }))
    }

    /// Lowers or raises EER's effort after a decision that took `compute_ms` of its budget
    /// ([`effort::Effort`]), and says so.
    fn adapt_effort(&mut self, compute_ms: f64, budget_ms: f64) {
        let Some(change) = self.effort.note(compute_ms, budget_ms) else {
            return;
        };
        self.planner.set_effort_divisor(self.effort.divisor());
        let n_h = self.params.eer.entropy_particles / self.effort.divisor();
        match change {
            effort::EffortChange::Lowered { .. } => tracing::warn!(
                "guidance took {compute_ms:.0} ms of its {budget_ms:.0} ms budget: EER now weighs {n_h} hypotheses (1/{} of its {})",
                self.effort.divisor(),
                self.params.eer.entropy_particles
            ),
            effort::EffortChange::Raised { .. } => tracing::info!(
                "guidance is quick again: EER now weighs {n_h} hypotheses (1/{} of its {})",
                self.effort.divisor(),
                self.params.eer.entropy_particles
            ),
        }
    }

    /// How much of its hypotheses EER weighs: 1 / 2^level (0: all of them).
    pub fn effort_level(&self) -> u8 {
        self.effort.level()
    }

    /// What the guidance law (or the failsafe in force) says, before the geofence and the
    /// heading: a setpoint and its velocity (world ENU, m and m/s), or `None` to hold.
    fn choose(
        &mut self,
        t_s: f64,
        vehicle: &View,
        truth: Option<(Enu2, Enu2)>,
    ) -> Result<Option<(Enu2, Enu2)>, TrackerError> {
        let fixed = |p: Enu2| Some((p, Enu2::zeros()));
        if let Some(f) = self.params.failsafe {
            match (self.state, f.fallback) {
                (TrackState::CameraLost, _) | (TrackState::Lost, LostFallback::Hold) => {
                    return Ok(None)
                }
                (TrackState::Lost, LostFallback::Lawn) => return Ok(fixed(self.lawn.next_point())),
                _ => {}
            }
        }
        Ok(match self.params.guidance {
            GuidanceKind::Eer => Some(self.plan_eer(vehicle, t_s)?),
            GuidanceKind::Pfwm => Some((self.estimator.mean(), self.confident_velocity())),
            GuidanceKind::Kf => match &self.side_kf {
                Some(k) => Some((k.mean(), k.velocity())),
                None => Some((self.estimator.mean(), self.estimator.velocity())),
            },
            GuidanceKind::Truth => Some(truth.ok_or(TrackerError::NoTruth)?),
            GuidanceKind::Lawn => fixed(match self.last_measurement {
                Some((tm, z)) if t_s - tm <= self.params.lawn.track_measurement_for_s => z,
                _ => self.lawn.next_point(),
            }),
        })
    }

    /// The estimate's velocity when the belief is concentrated enough to be over the
    /// target (its largest standard deviation within half the footprint's smaller side);
    /// zero while it is spread out, when a mean velocity means nothing.
    fn confident_velocity(&self) -> Enu2 {
        let fp = &self.world.footprint;
        if self.estimator.largest_sd_m() <= fp.quarter_view_m() {
            self.estimator.velocity()
        } else {
            Enu2::zeros()
        }
    }

    /// EER's waypoint is where to be at the end of the horizon; with the target's velocity
    /// (when the belief is concentrated) the setpoint moves so as to get there then, riding
    /// along with the target instead of trailing it.
    fn plan_eer(&mut self, vehicle: &View, t_s: f64) -> Result<(Enu2, Enu2), TrackerError> {
        let vehicle_enu = &vehicle.centre_enu;
        let over_target_velocity_enu = self.confident_velocity();
        let horizon_s = self.params.eer.horizon_steps as f64 * self.params.filter.dt_s;
        // Searching, EER keeps to one mode (BENCHMARKS.md): until
        // the first sighting only. Once the target has been seen, the argmax decides even
        // through a loss; kept after a loss too, the commitment held the drone
        // on a refuted branch past covered junctions (BENCHMARKS.md).
        let searching = self.last_measurement.is_none();
        let Estimator::Particle { pf, model } = &mut self.estimator else {
            // Refused at construction by check_combination.
            return Err(TrackerError::Incompatible {
                guidance: GuidanceKind::Eer,
                motion: "kf".into(),
                reason: "eer needs a particle set".into(),
            });
        };
        self.planner.use_intercepts(self.last_measurement.is_some());
        self.planner
            .weigh_escape(self.last_measurement.is_none() && self.params.cue.is_some());
        self.planner.set_searching(searching);
        self.planner.ride_along(
            (over_target_velocity_enu != Enu2::zeros()).then_some(over_target_velocity_enu),
        );
        // EER plans with the prediction the filter makes: where the filter re-routes its
        // belief at junctions, so does the rollout. Straight on, the predicted tracks ran
        // off the road past every corner and EER sent the drone there: it overshot the
        // car's turns and chased from behind (BENCHMARKS.md).
        let reroutes = self.last_measurement.is_some() && self.params.injection_share > 0.0;
        let on_road_m = 0.5 * self.params.filter.road_sigma_m.unwrap_or(0.0);
        self.planner.reroute_rollout(reroutes.then_some(on_road_m));
        let d = self.planner.plan(
            pf,
            model.as_mut(),
            vehicle,
            &self.params.heading,
            &self.world,
            &mut self.rng_guidance,
        )?;
        self.entropy = d.h_now;
        self.last_eer = d.eer;
        if let Some(command) = self.ambush_command(vehicle, t_s, horizon_s) {
            return Ok(command);
        }
        let velocity_enu = if over_target_velocity_enu == Enu2::zeros() {
            approach_velocity(
                vehicle_enu,
                &d.waypoint_enu,
                horizon_s,
                self.params.eer.reach_m,
                self.params.eer.reach_shape,
            )
        } else {
            over_target_velocity_enu
        };
        let far = velocity_enu != Enu2::zeros() && over_target_velocity_enu == Enu2::zeros();
        // A waypoint flown to in transit is judged at the heading the transit gives; a near
        // one is flown at the view EER judged best there.
        if !far && self.params.heading.kind == ViewHeading::Informed {
            self.planned_view_yaw_enu_rad = Some(d.view_yaw_enu_rad);
        }
        // Before the first sighting and after a loss alike (see `along_the_roads`).
        if far && self.params.cue.is_some() {
            if let Some(along) = self.along_the_roads(vehicle_enu, &d.waypoint_enu, horizon_s) {
                return Ok(along);
            }
        }
        Ok((d.waypoint_enu - velocity_enu * horizon_s, velocity_enu))
    }

    /// While the target has been unseen for `ambush.after_s` and the belief is spread over
    /// more than two views' lengths, in a world with a cue: the setpoint toward the point
    /// where most hypotheses will pass ([`crate::guidance::ambush`]), at rest once there.
    fn ambush_command(&mut self, vehicle: &View, t_s: f64, horizon_s: f64) -> Option<(Enu2, Enu2)> {
        let params = self.params.ambush;
        let unseen_s = t_s - self.last_measurement.map_or(0.0, |(tm, _)| tm);
        let fp = &self.world.footprint;
        let long_side_m = 2.0 * fp.half_width_m.max(fp.half_height_m);
        let spread = self.estimator.largest_sd_m() > 2.0 * long_side_m;
        if self.params.cue.is_none()
            || !params.is_on()
            || unseen_s < params.after_s
            || !spread
            || horizon_s <= 0.0
        {
            self.ambush_point_enu = None;
            return None;
        }
        let Estimator::Particle { pf, .. } = &self.estimator else {
            return None;
        };
        let dt_s = self.params.filter.dt_s;
        let belief: Vec<crate::guidance::ambush::Hypothesis> = (0..pf.weights().len())
            .map(|i| crate::guidance::ambush::Hypothesis {
                position_enu: pf.particle(i),
                velocity_enu: crate::estimation::road_following::track_velocity(
                    pf.histories(),
                    i,
                    dt_s,
                ),
                weight: pf.weights()[i],
            })
            .collect();
        let vehicle_enu = vehicle.centre_enu;
        let point = crate::guidance::ambush::choose(
            &params,
            &belief,
            &self.world,
            &vehicle_enu,
            self.params.eer.reach_m / horizon_s,
            self.ambush_point_enu,
            self.params.eer.search_commitment,
            &mut self.rng_guidance,
        )?;
        self.ambush_point_enu = Some(point.point_enu);
        let c = point.point_enu;
        let reach_m = self.params.eer.reach_m;
        if (c - vehicle_enu).norm() <= reach_m {
            return Some((c, Enu2::zeros()));
        }
        if let Some(along) = self.along_the_roads(&vehicle_enu, &c, horizon_s) {
            return Some(along);
        }
        let v = (c - vehicle_enu).normalize() * (reach_m / horizon_s);
        Some((c - v * horizon_s, v))
    }

    /// In a world with a cue (a field flight), a far waypoint (beyond the reachable region,
    /// flown to at top speed while the belief is spread: before the first sighting or after
    /// a loss) is flown to along the shortest road path, either way, instead of the
    /// straight line: the setpoint one reach ahead on that path, with the top speed along its
    /// piece of road as feed-forward. On the way the camera sweeps roads the car may be on,
    /// not the fields between them. Straight (`None`) when the drone is farther from every
    /// road than the view's shorter side, or when the road path is longer than
    /// [`ROAD_PATH_DETOUR`] x the straight line. Over 40 outdoor closed-loop seeds the car
    /// was in view more often on 29 (sign test p ~ 0.006) and lost for good on none, where
    /// the straight line lost it on three (BENCHMARKS.md). Flown
    /// only before the first sighting, after a loss the drone flew
    /// straight, kept the offset it had from cutting a junction's corner, and passed the car
    /// 15-20 m beside its road, outside the view's shorter side. Flying the roads after a
    /// loss too: +1.4 and +1.6 points of FOV over 22 worlds on two seeds, the closed loop's
    /// seed 3 25.3 -> 6.7 m, but two closed-loop seeds of 80 lost for good where the car
    /// turns back unseen under cover (BENCHMARKS.md). There the road path was in force for one
    /// plan only; the drone's flight past the cover came from EER's near waypoints (BENCHMARKS.md).
    pub(super) fn along_the_roads(
        &self,
        vehicle_enu: &Enu2,
        waypoint_enu: &Enu2,
        horizon_s: f64,
    ) -> Option<(Enu2, Enu2)> {
        let fp = &self.world.footprint;
        let view_m = 2.0 * fp.half_width_m.min(fp.half_height_m);
        let road = &self.world.road;
        if road.distance_to_roads(vehicle_enu) > view_m {
            return None;
        }
        let path = road.path_between(vehicle_enu, waypoint_enu)?;
        if path.length_m() > ROAD_PATH_DETOUR * (waypoint_enu - vehicle_enu).norm() {
            return None;
        }
        let reach_m = self.params.eer.reach_m;
        let (setpoint_enu, direction_enu) = path.point_at(reach_m);
        Some((setpoint_enu, direction_enu * (reach_m / horizon_s)))
    }
}

/// How much longer than the straight line a road path to a far waypoint may be and still be
/// flown ([`Tracker::along_the_roads`]): a quarter, the one value measured (BENCHMARKS.md
/// BENCHMARKS.md). Beyond it the roads wind away from where the drone must go.
pub(super) const ROAD_PATH_DETOUR: f64 = 1.25;

/// The planned motion toward a waypoint beyond every candidate of the reachable region (a
/// square's corners lie at sqrt(2) x reach, a disc's rim at reach; beyond them a waypoint is
/// a far predicted particle) while the belief is
/// spread out: the agent's top speed along the way, so that the setpoint (`reach` short of
/// the waypoint, moving to it) carries the transit's speed as feed-forward instead of
/// trailing it by speed / position gain. Otherwise zero, a fixed point, which arrives
/// sooner than a setpoint that spreads the move over the horizon (that cost the lab's closed
/// loop 12-17 points of FOV). The threshold was `reach` at first; at the grid's corners the
/// transit cost the lab's closed loop 1.3 points over 16 seeds (BENCHMARKS.md).
pub(super) fn approach_velocity(
    vehicle_enu: &Enu2,
    waypoint_enu: &Enu2,
    horizon_s: f64,
    reach_m: f64,
    reach_shape: ReachShape,
) -> Enu2 {
    let to_go = waypoint_enu - vehicle_enu;
    let distance = to_go.norm();
    // The tolerance keeps the region's own farthest candidates (a square's corners, a
    // disc's rim, exactly there before rounding) on the fixed-point side.
    let farthest_candidate_m = reach_shape.farthest_in_reaches() * reach_m + 1e-9;
    if distance <= farthest_candidate_m || horizon_s <= 0.0 {
        return Enu2::zeros();
    }
    to_go * (reach_m / distance / horizon_s)
}
