//! The world a learned motion model was trained for: its name, workspace, road graph (as a
//! hash), the target's speeds and the filter's history and period. A model learns the
//! motion of one world's targets on one world's roads; `infotrack dataset` records this
//! beside its data, the training copies it into the model's metadata, and a model is
//! refused in a world whose signature differs (unless the user overrides it).

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::geometry::BoundsEnu;
use super::road::RoadConfig;

/// The target's speeds in a world, m/s.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedEnvelope {
    /// Cruise speed, m/s.
    pub cruise_mps: f64,
    /// Hard limit, m/s.
    pub max_mps: f64,
}

/// What identifies a world to a learned motion model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSignature {
    /// The scenario's name (for messages; not compared).
    pub name: String,
    /// The workspace, world ENU, m.
    pub workspace_enu: BoundsEnu,
    /// SHA-256 of the road graph in a canonical text form ([`road_graph_sha256`]).
    pub road_graph_sha256: String,
    /// The target's speeds.
    pub target_speed: SpeedEnvelope,
    /// History length (K_in).
    pub k_in: usize,
    /// Filter period, s.
    pub dt_s: f64,
}

/// SHA-256 (hex) of the road graph: nodes sorted by id with their positions to the
/// millimetre, edges sorted by (from, to) with their probabilities to 1e-6, the start node.
/// The order the configuration lists them in and float noise below those steps do not change
/// it; moving a node, adding a road or changing a turn probability does.
pub fn road_graph_sha256(road: &RoadConfig) -> String {
    let mut nodes: Vec<_> = road.nodes.iter().collect();
    nodes.sort_by_key(|n| n.id);
    let mut edges: Vec<_> = road.edges.iter().collect();
    edges.sort_by_key(|e| (e.from, e.to));
    let mut text = format!("start {}\n", road.start_node);
    for n in nodes {
        text += &format!("node {} {:.3} {:.3}\n", n.id, n.x_m, n.y_m);
    }
    for e in edges {
        text += &format!("edge {} {} {:.6}\n", e.from, e.to, e.p);
    }
    Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Lengths and speeds agree to this, m and m/s (a config written with fewer digits is the
/// same world).
const SAME_TOLERANCE: f64 = 1e-6;

impl WorldSignature {
    /// The differences that make `other` another world for a model trained in `self`, in
    /// words; empty: the same world (the names are not compared).
    pub fn differences(&self, other: &WorldSignature) -> Vec<&'static str> {
        let close = |a: f64, b: f64| (a - b).abs() <= SAME_TOLERANCE * a.abs().max(1.0);
        let (a, b) = (&self.workspace_enu, &other.workspace_enu);
        let mut d = Vec::new();
        if self.road_graph_sha256 != other.road_graph_sha256 {
            d.push("road graph");
        }
        if !(close(a.x_min_m, b.x_min_m)
            && close(a.x_max_m, b.x_max_m)
            && close(a.y_min_m, b.y_min_m)
            && close(a.y_max_m, b.y_max_m))
        {
            d.push("workspace");
        }
        if !(close(self.target_speed.cruise_mps, other.target_speed.cruise_mps)
            && close(self.target_speed.max_mps, other.target_speed.max_mps))
        {
            d.push("target speeds");
        }
        if self.k_in != other.k_in {
            d.push("history length K_in");
        }
        if !close(self.dt_s, other.dt_s) {
            d.push("filter period");
        }
        d
    }

    /// One line for messages: name, workspace, roads, speeds.
    pub fn describe(&self) -> String {
        let w = &self.workspace_enu;
        format!(
            "`{}` (workspace x {}..{} m, y {}..{} m; roads sha256 {}; target {}-{} m/s; K_in {}, dt {:.4} s)",
            self.name,
            w.x_min_m,
            w.x_max_m,
            w.y_min_m,
            w.y_max_m,
            &self.road_graph_sha256[..self.road_graph_sha256.len().min(12)],
            self.target_speed.cruise_mps,
            self.target_speed.max_mps,
            self.k_in,
            self.dt_s
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::road::{EdgeConfig, NodeConfig};

    fn road() -> RoadConfig {
        RoadConfig {
            nodes: vec![
                NodeConfig {
                    id: 0,
                    x_m: 0.0,
                    y_m: 0.0,
                },
                NodeConfig {
                    id: 1,
                    x_m: 100.0,
                    y_m: 0.0,
                },
            ],
            edges: vec![
                EdgeConfig {
                    from: 0,
                    to: 1,
                    p: 1.0,
                },
                EdgeConfig {
                    from: 1,
                    to: 0,
                    p: 1.0,
                },
            ],
            start_node: 0,
        }
    }

    fn signature(road: &RoadConfig) -> WorldSignature {
        WorldSignature {
            name: "a".into(),
            workspace_enu: BoundsEnu {
                x_min_m: -10.0,
                x_max_m: 110.0,
                y_min_m: -10.0,
                y_max_m: 10.0,
            },
            road_graph_sha256: road_graph_sha256(road),
            target_speed: SpeedEnvelope {
                cruise_mps: 10.0,
                max_mps: 12.0,
            },
            k_in: 10,
            dt_s: 1.0 / 3.0,
        }
    }

    #[test]
    fn the_road_hash_ignores_order_and_sees_every_change() {
        let a = road();
        let mut reordered = road();
        reordered.nodes.reverse();
        reordered.edges.reverse();
        assert_eq!(road_graph_sha256(&a), road_graph_sha256(&reordered));
        let mut moved = road();
        moved.nodes[1].x_m += 0.01;
        let mut turned = road();
        turned.edges[0].p = 0.9;
        let mut started = road();
        started.start_node = 1;
        for other in [moved, turned, started] {
            assert_ne!(road_graph_sha256(&a), road_graph_sha256(&other));
        }
        assert_eq!(road_graph_sha256(&a).len(), 64);
    }

    #[test]
    fn the_same_world_under_another_name_is_the_same_and_each_difference_is_named() {
        let a = signature(&road());
        let renamed = WorldSignature {
            name: "b".into(),
            ..a.clone()
        };
        assert!(a.differences(&renamed).is_empty());
        let mut other_roads = road();
        other_roads.nodes[1].y_m = 5.0;
        let mut b = signature(&other_roads);
        b.workspace_enu.x_max_m = 200.0;
        b.target_speed.max_mps = 15.0;
        assert_eq!(
            a.differences(&b),
            vec!["road graph", "workspace", "target speeds"]
        );
        assert!(a.describe().contains("`a`") && a.describe().contains("10-12 m/s"));
    }
}
