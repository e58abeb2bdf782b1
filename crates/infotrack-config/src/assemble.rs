//! The configuration hands the core its tables as a [`Scenario`]; the core assembles each
//! component's parameters from them and never sees the application's `Config`.

use super::{Config, SpeedLimitShape};
use infotrack_core::guidance::ReachShape;
use infotrack_core::scenario::{Scenario, VehicleLimits};
use infotrack_core::tracker::{Failsafe, LostFallback};
use infotrack_core::world::signature::SpeedEnvelope;

impl Config {
    /// The core's tables of this configuration.
    pub fn scenario(&self) -> Scenario<'_> {
        Scenario {
            name: &self.name,
            workspace_enu: self.workspace_enu,
            road: &self.road,
            occlusions: &self.occlusions,
            camera: &self.camera,
            measurement: &self.measurement,
            timing: &self.timing,
            filter: &self.filter,
            motion: &self.motion,
            kalman: &self.kalman,
            guidance: &self.guidance,
            acquisition: self.acquisition.as_ref(),
            vehicle: VehicleLimits {
                altitude_m: self.agent.altitude_m,
                speed_limit_mps: self.agent.speed_limit_mps,
                reach_shape: match self.agent.speed_limit_shape {
                    SpeedLimitShape::PerAxis => ReachShape::Square,
                    SpeedLimitShape::Norm => ReachShape::Disc,
                },
            },
            failsafe: self.failsafe(),
            target_speed: SpeedEnvelope {
                cruise_mps: self.target.cruise_speed_mps,
                max_mps: self.target.max_speed_mps,
            },
            detection_margin_m: self.vision.detection_margin_m(),
        }
    }

    /// The daemon's failsafes.
    pub fn failsafe(&self) -> Failsafe {
        let d = &self.daemon;
        Failsafe {
            target_lost_after_s: d.target_lost_after_s,
            // Validated at load to be one of eer, lawn, hold.
            fallback: d.target_lost_fallback.parse().unwrap_or(LostFallback::Eer),
            camera_timeout_s: d.camera_timeout_s,
            guidance_budget_ms: d.guidance_budget_ms,
        }
    }

    infotrack_core::assembled_from_scenario!();
}
