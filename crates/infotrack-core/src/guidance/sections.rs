//! The guidance laws' table of a configuration.

use serde::{Deserialize, Serialize};

use crate::check::{count, covariance, in_unit, invalid, non_negative, positive, Checked};
use crate::world::geometry::BoundsEnu;

use super::LawnConfig;

/// Guidance laws.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GuidanceConfig {
    /// N_H: particles used for entropy and EER (drawn with replacement; N_H = N uses them all).
    pub entropy_particles: usize,
    /// N_H while the belief is concentrated (its standard deviation along each world axis at
    /// most a quarter of the camera footprint's width along it, so +-2 sigma is in view at
    /// once), at a fraction of the O(N_H^2) cost. Outdoors 300 of 1000 matched every
    /// hypothesis in the Monte Carlo runs but tracked worse in the closed loop (BENCHMARKS
    /// BENCHMARKS.md): the shipped configs leave it unset. Optional; absent,
    /// `entropy_particles` always.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub entropy_particles_concentrated: Option<usize>,
    /// N_M: simulated measurements per particle.
    pub measurements_per_particle: usize,
    /// K: planning horizon in filter steps.
    pub horizon_steps: usize,
    /// Side of the grid of reachable candidate waypoints (side x side points).
    pub candidate_grid_side: usize,
    /// Covariance of the Gaussian transition kernel p(x_i | x_j) in the entropy formulas,
    /// square metres (the paper's code uses Q).
    pub entropy_kernel_cov_m2: [[f64; 2]; 2],
    /// Far candidates as intercepts once the target has been seen, seconds: a predicted
    /// particle beyond the reach of one horizon becomes the point where the drone, at its top
    /// speed, meets it carried on at its own velocity, looked ahead by at most this long (and
    /// EER judges what a far candidate sees at that time). Before the first detection the
    /// paper's candidate (the particle where it is at the horizon's end). Optional; absent,
    /// the paper's candidates always (the field configs set 10 s: BENCHMARKS.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intercept_within_s: Option<f64>,
    /// Commitment while searching (before the first sighting; after a loss the argmax
    /// decides), a share of the EER range in [0, 1]:
    /// of the candidates whose EER is within this share of the range below the best, the plan
    /// keeps to the one nearest its previous waypoint, so the drone flies to one mode of a
    /// spread belief instead of back and forth between them (a departure from the paper's
    /// argmax; BENCHMARKS.md). Once the drone sees its previous
    /// waypoint it has got there, and the argmax decides again (BENCHMARKS.md). Tracking, the
    /// argmax. Optional; absent,
    /// 0.2; 0 with `centring_share = 0` restores the paper's argmax always (exact ties broken
    /// toward the belief's mean).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search_commitment: Option<f64>,
    /// Centring while tracking (and whenever there is no previous waypoint to keep to: the
    /// first plan of a search, or `search_commitment = 0`), a share of the EER range in [0, 1]: of the
    /// candidates whose EER is within this share of the range below the best, the plan takes
    /// the one nearest the belief's predicted mean, so the view is centred on the target
    /// rather than anywhere that holds it (a choice among nearly equal maxima of the paper's
    /// argmax; BENCHMARKS.md). Optional; absent, 0.02; 0 breaks exact
    /// ties only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub centring_share: Option<f64>,
    /// The search from a cue, before the first sighting: each hypothesis's weight in EER is
    /// multiplied by `floor + (1 - floor) x` its speed away from the drone over the fastest
    /// hypothesis's, so that the plan looks first where the belief escapes (one coming
    /// toward the drone can be looked at later); this is the floor, in [0, 1]. A departure
    /// from the paper's weights (BENCHMARKS.md). Optional; absent, 0.3
    /// (0.1 chased the belief's fastest front too hard); 1 restores the paper's. Without a cue (the lab), never applied.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search_escape_floor: Option<f64>,
    /// Waiting where a long-lost target will pass: once the target has been unseen for 40 s
    /// and the belief is spread over more than two views' lengths, the drone flies to the
    /// point along the roads that the most hypotheses, driven on along the roads, pass in
    /// this many seconds after it gets there, per second of flight and wait, and waits there
    /// (`guidance::ambush`; BENCHMARKS.md). Optional; absent, 30 s; 0:
    /// off (EER searches). Without a cue (the lab), never applied.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambush_window_s: Option<f64>,
    /// Which way the camera's image faces: `north` (the paper's constant heading, the image's
    /// width along world east), `along_track` (the image's width, its long side, along the
    /// direction of travel, a chased car's road; the vehicle turns at
    /// `agent.yaw_rate_limit_rad_s`, and EER judges each candidate at the heading the vehicle
    /// will have there) or `informed` (EER judges each candidate at the `along_track` heading
    /// and a quarter turn from it and flies the better: the long side across a covered
    /// junction's two exits; level with `along_track` on average, BENCHMARKS.md; other laws fly `along_track`). Optional; absent, `along_track` with an
    /// `[acquisition]` cue (a field flight: the outdoor closed loop seeds 1-3 kept the car in
    /// view 80-81 % of the frames instead of 73-80 %, BENCHMARKS.md) and
    /// `north` without one (the paper's lab, whose numbers stay the paper's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view_heading: Option<crate::guidance::ViewHeading>,
    /// The lawnmower sweep.
    pub lawn: LawnConfig,
}

impl GuidanceConfig {
    /// Checks `guidance` (the lawnmower's table apart: [`LawnConfig::check`]).
    pub fn check(&self) -> Checked {
        count("guidance.entropy_particles", self.entropy_particles)?;
        if let Some(n) = self.entropy_particles_concentrated {
            count("guidance.entropy_particles_concentrated", n)?;
        }
        count(
            "guidance.measurements_per_particle",
            self.measurements_per_particle,
        )?;
        count("guidance.horizon_steps", self.horizon_steps)?;
        count("guidance.candidate_grid_side", self.candidate_grid_side)?;
        covariance(
            "guidance.entropy_kernel_cov_m2",
            &self.entropy_kernel_cov_m2,
        )?;
        if let Some(t) = self.intercept_within_s {
            positive("guidance.intercept_within_s", t)?;
        }
        self.check_shares()
    }

    fn check_shares(&self) -> Checked {
        for (key, share) in [
            ("guidance.search_commitment", self.search_commitment),
            ("guidance.centring_share", self.centring_share),
        ] {
            if let Some(share) = share.filter(|s| !(0.0..=1.0).contains(s)) {
                return Err(invalid(
                    key,
                    share,
                    "must be a share of the EER range, from 0 to 1",
                ));
            }
        }
        if let Some(t) = self.ambush_window_s {
            non_negative("guidance.ambush_window_s", t)?;
        }
        if let Some(floor) = self.search_escape_floor {
            in_unit("guidance.search_escape_floor", floor)?;
        }
        Ok(())
    }
}

impl LawnConfig {
    /// Checks `guidance.lawn`: legs and their ends inside the workspace `ws`.
    pub fn check(&self, ws: &BoundsEnu) -> Checked {
        if self.legs_x_m.is_empty() {
            return Err(invalid(
                "guidance.lawn.legs_x_m",
                &self.legs_x_m,
                "needs at least one leg",
            ));
        }
        if let Some(x) = self
            .legs_x_m
            .iter()
            .find(|x| !x.is_finite() || **x < ws.x_min_m || **x > ws.x_max_m)
        {
            return Err(invalid(
                "guidance.lawn.legs_x_m",
                x,
                "leg lies outside the workspace",
            ));
        }
        let (y_min, y_max) = (self.y_min_m, self.y_max_m);
        if !(y_min < y_max && y_min >= ws.y_min_m && y_max <= ws.y_max_m) {
            return Err(invalid(
                "guidance.lawn.y_max_m",
                [y_min, y_max],
                "need y_min_m < y_max_m, both inside the workspace",
            ));
        }
        positive("guidance.lawn.point_spacing_m", self.point_spacing_m)?;
        non_negative(
            "guidance.lawn.track_measurement_for_s",
            self.track_measurement_for_s,
        )
    }
}
