//! The world model: road network, occlusions, workspace (geofence), camera footprint and
//! the measurement model. Pure data and geometry; no I/O.

pub mod camera;
pub mod geometry;
pub mod measurement;
pub mod road;
pub mod signature;

use camera::Footprint;
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
}

impl World {
    /// Builds the world from its parts (the configuration assembles them: see
    /// `Config::world`).
    pub fn new(
        workspace_enu: BoundsEnu,
        road: &road::RoadConfig,
        occlusions: Vec<PolygonEnu>,
        footprint: Footprint,
        measurement: MeasurementModel,
    ) -> Self {
        Self {
            workspace_enu,
            road: RoadNetwork::from_config(road),
            occlusions,
            footprint,
            measurement,
        }
    }

    /// Whether a ground point is hidden by any occlusion.
    pub fn is_occluded(&self, p: &Enu2) -> bool {
        self.occlusions.iter().any(|o| o.contains(p))
    }

    /// Whether a target at `target` is seen by an agent at `agent`: inside the footprint
    /// and outside every occlusion (the paper's x in S and not in O).
    pub fn is_visible(&self, agent: &Enu2, target: &Enu2) -> bool {
        self.footprint.contains(agent, target) && !self.is_occluded(target)
    }
}
