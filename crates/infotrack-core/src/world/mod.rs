//! The world model: road network, occlusions, workspace (geofence), camera footprint and
//! the measurement model. Pure data and geometry; no I/O.

pub mod camera;
pub mod geometry;
pub mod measurement;
pub mod road;
pub mod sections;
pub mod signature;

use camera::{Footprint, View};
use geometry::{BoundsEnu, Enu2, PolygonEnu};
use measurement::MeasurementModel;
use road::RoadNetwork;

/// Everything about the scene that the estimator, the guidance and the simulators share.
#[derive(Debug, Clone)]
pub struct World {
    /// Workspace and geofence, world ENU.
    pub workspace_enu: BoundsEnu,
    /// The target's road network.
    pub road: RoadNetwork,
    /// Occlusion regions, world ENU.
    pub occlusions: Vec<PolygonEnu>,
    /// The camera footprint geometry at the configured altitude.
    pub footprint: Footprint,
    /// z = x + N(0, R).
    pub measurement: MeasurementModel,
    /// How near the edge of the view or an occlusion a tag's centre may be and the tag
    /// still be cut off (half its diagonal, metres): a detector finds only whole tags, so
    /// a missing detection says nothing about a target in that band. 0 by default.
    pub detection_margin_m: f64,
}

impl World {
    /// Builds the world from its parts (the configuration assembles them: see
    /// `Config::world`); the road network is built fallibly beforehand
    /// (`RoadNetwork::try_from`).
    pub fn new(
        workspace_enu: BoundsEnu,
        road: RoadNetwork,
        occlusions: Vec<PolygonEnu>,
        footprint: Footprint,
        measurement: MeasurementModel,
    ) -> Self {
        Self {
            workspace_enu,
            road,
            occlusions,
            footprint,
            measurement,
            detection_margin_m: 0.0,
        }
    }

    /// The same world, its detector finding only tags whose centre lies `margin_m` or more
    /// inside the view and clear of every occlusion (see [`Self::is_wholly_visible`]).
    pub fn with_detection_margin(mut self, margin_m: f64) -> Self {
        self.detection_margin_m = margin_m.max(0.0);
        self
    }

    /// Whether a ground point is hidden by any occlusion.
    pub fn is_occluded(&self, p: &Enu2) -> bool {
        self.occlusions.iter().any(|o| o.contains(p))
    }

    /// Whether a target at `target` is seen from `view`: inside the footprint and outside
    /// every occlusion (the paper's x in S and not in O).
    pub fn is_visible(&self, view: &View, target: &Enu2) -> bool {
        self.footprint.contains(view, target) && !self.is_occluded(target)
    }

    /// Whether a target at `target` shows its whole tag to `view`: its centre
    /// at least the detection margin inside the footprint and away from every occlusion.
    /// Only there does a frame without a detection say the target is not there (negative
    /// information); a tag cut by the image's edge or half under a roof is missed by the
    /// detector (eight PX4 SIH lab flights: 98 of 118 misses of a target in view and clear
    /// of occlusions had its centre within 0.071 m of the edge, half the 0.1 m tag's
    /// diagonal).
    pub fn is_wholly_visible(&self, view: &View, target: &Enu2) -> bool {
        self.footprint
            .contains_inset(view, target, self.detection_margin_m)
            && !self.may_hide_the_tag(target)
    }

    /// Whether an occlusion may cover part of a tag centred at `p`: `p` inside one, or
    /// within the detection margin of one.
    pub fn may_hide_the_tag(&self, p: &Enu2) -> bool {
        let m = self.detection_margin_m;
        self.occlusions.iter().any(|o| o.contains_or_near(p, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Config;

    #[test]
    fn a_whole_tag_is_seen_only_clear_of_the_edge_and_of_every_occlusion() {
        let plain = Config::default_lab().world();
        let w = plain.clone().with_detection_margin(0.07);
        let agent = View::north(Enu2::new(-2.0, 1.5));
        let half = w.footprint.half_width_m;
        // Near the east edge: in view, but the tag may be cut off.
        let edge = Enu2::new(-2.0 + half - 0.03, 1.5);
        assert!(w.is_visible(&agent, &edge) && !w.is_wholly_visible(&agent, &edge));
        let inside = Enu2::new(-2.0 + half - 0.1, 1.5);
        assert!(w.is_wholly_visible(&agent, &inside));
        // The same at the north edge, and with no margin the band is in view.
        let north = Enu2::new(-2.0, 1.5 + w.footprint.half_height_m - 0.05);
        assert!(!w.is_wholly_visible(&agent, &north));
        assert!(plain.is_wholly_visible(&agent, &north) && plain.is_visible(&agent, &north));
        // Occlusion "between B and C" spans x -0.15..0.85: 0.05 m west of it a tag is
        // half under it; 0.1 m west it is clear.
        let over = View::north(Enu2::new(0.0, 0.2));
        assert!(!w.is_wholly_visible(&over, &Enu2::new(-0.2, 0.2)));
        assert!(w.is_visible(&over, &Enu2::new(-0.2, 0.2)));
        assert!(w.is_wholly_visible(&over, &Enu2::new(-0.25, 0.2)));
    }
}
