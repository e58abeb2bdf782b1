//! The road network: a Markov chain over nodes joined by straight edges.

use rand::Rng;

use super::geometry::Enu2;
use serde::{Deserialize, Serialize};

/// A node of the road network.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeConfig {
    /// Identifier that edges refer to.
    pub id: u32,
    /// East coordinate, metres.
    pub x_m: f64,
    /// North coordinate, metres.
    pub y_m: f64,
}

/// A directed edge of the road network with its transition probability.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EdgeConfig {
    /// Node the edge leaves.
    pub from: u32,
    /// Node the edge enters.
    pub to: u32,
    /// Probability of taking this edge when at `from`; the edges leaving a node sum to 1.
    pub p: f64,
}

/// The road network as a Markov chain.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoadConfig {
    /// Nodes with their positions.
    pub nodes: Vec<NodeConfig>,
    /// Directed edges with transition probabilities.
    pub edges: Vec<EdgeConfig>,
    /// Node the target starts at.
    pub start_node: u32,
}

/// A node's position and its outgoing transitions.
#[derive(Debug, Clone)]
pub struct RoadNode {
    /// Identifier from the configuration.
    pub id: u32,
    /// Position, world ENU, metres.
    pub position_enu: Enu2,
    /// `(index of next node, probability)`; probabilities sum to 1.
    pub next: Vec<(usize, f64)>,
}

/// Road network, indexed densely; configuration ids are kept for reports.
#[derive(Debug, Clone)]
pub struct RoadNetwork {
    /// Nodes in configuration order.
    pub nodes: Vec<RoadNode>,
    /// Index of the start node.
    pub start: usize,
    /// Every directed edge as its end points, world ENU.
    segments: Vec<(Enu2, Enu2)>,
}

impl RoadNetwork {
    /// From a validated configuration.
    pub fn from_config(c: &RoadConfig) -> Self {
        let index = |id: u32| c.nodes.iter().position(|n| n.id == id).expect("validated");
        let nodes = c
            .nodes
            .iter()
            .map(|n| RoadNode {
                id: n.id,
                position_enu: Enu2::new(n.x_m, n.y_m),
                next: c
                    .edges
                    .iter()
                    .filter(|e| e.from == n.id)
                    .map(|e| (index(e.to), e.p))
                    .collect(),
            })
            .collect();
        let mut road = Self {
            nodes,
            start: index(c.start_node),
            segments: Vec::new(),
        };
        road.segments = road.edges_enu();
        road
    }

    /// Distance from `p` to the nearest road, m (infinite without roads).
    pub fn distance_to_roads(&self, p: &Enu2) -> f64 {
        self.segments
            .iter()
            .map(|(a, b)| {
                let d = b - a;
                let len2 = d.dot(&d);
                let t = if len2 > 0.0 {
                    ((p - a).dot(&d) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (a + d * t - p).norm()
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Samples the node after `from` by its transition probabilities.
    pub fn sample_next<R: Rng + ?Sized>(&self, from: usize, rng: &mut R) -> usize {
        let next = &self.nodes[from].next;
        let u: f64 = rng.gen();
        let mut acc = 0.0;
        for &(to, p) in next {
            acc += p;
            if u < acc {
                return to;
            }
        }
        // Rounding can leave u just above the last cumulative sum.
        next.last().map(|&(to, _)| to).unwrap_or(from)
    }

    /// A point on the roads, drawn uniformly by length over the parts of every edge that lie
    /// within `region` (a centre and a radius, world ENU; `None`: the whole network), with
    /// the unit direction the edge allows. `None` when no road lies in the region.
    pub fn sample_on_roads<R: Rng + ?Sized>(
        &self,
        region: Option<(Enu2, f64)>,
        rng: &mut R,
    ) -> Option<(Enu2, Enu2)> {
        self.roads_within(region).sample(rng)
    }

    /// The roads within `region`, clipped once, to draw many points from.
    pub fn roads_within(&self, region: Option<(Enu2, f64)>) -> RoadPieces {
        let pieces = self.pieces_within(region);
        let total = pieces.iter().map(|(a, b)| (b - a).norm()).sum();
        RoadPieces { pieces, total }
    }

    /// Total length of road within `region`, m.
    pub fn length_within(&self, region: Option<(Enu2, f64)>) -> f64 {
        self.pieces_within(region)
            .iter()
            .map(|(a, b)| (b - a).norm())
            .sum()
    }

    /// The parts of every directed edge inside `region` (each edge is straight, so its part
    /// in a disc is one segment), in the edge's direction; zero-length parts left out.
    fn pieces_within(&self, region: Option<(Enu2, f64)>) -> Vec<(Enu2, Enu2)> {
        self.segments
            .iter()
            .copied()
            .filter_map(|(a, b)| match region {
                None => Some((a, b)),
                Some((c, r)) => clip_to_disc(a, b, c, r),
            })
            .filter(|(a, b)| (b - a).norm() > 1e-9)
            .collect()
    }

    /// Straight edges as pairs of end points (for plots).
    pub fn edges_enu(&self) -> Vec<(Enu2, Enu2)> {
        self.nodes
            .iter()
            .flat_map(|n| {
                n.next
                    .iter()
                    .map(move |&(to, _)| (n.position_enu, self.nodes[to].position_enu))
            })
            .collect()
    }
}

/// Road segments (each in its edge's direction) and their total length, m.
#[derive(Debug, Clone)]
pub struct RoadPieces {
    pieces: Vec<(Enu2, Enu2)>,
    total: f64,
}

impl RoadPieces {
    /// Total length, m.
    pub fn length_m(&self) -> f64 {
        self.total
    }

    /// A point drawn uniformly by length and the unit direction of its road; `None` when
    /// there is no road.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Option<(Enu2, Enu2)> {
        if self.total.is_nan() || self.total <= 0.0 {
            return None;
        }
        let mut u = rng.gen_range(0.0..self.total);
        for (a, b) in &self.pieces {
            let len = (b - a).norm();
            if u <= len {
                let dir = (b - a) / len;
                return Some((a + dir * u, dir));
            }
            u -= len;
        }
        let (a, b) = self.pieces.last()?;
        Some((*b, (b - a).normalize()))
    }
}

/// The part of segment a-b inside the disc (centre c, radius r), if any.
fn clip_to_disc(a: Enu2, b: Enu2, c: Enu2, r: f64) -> Option<(Enu2, Enu2)> {
    let d = b - a;
    let f = a - c;
    let (qa, qb, qc) = (d.dot(&d), 2.0 * f.dot(&d), f.dot(&f) - r * r);
    if qa <= 0.0 {
        return (qc <= 0.0).then_some((a, b));
    }
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    let t0 = ((-qb - sq) / (2.0 * qa)).max(0.0);
    let t1 = ((-qb + sq) / (2.0 * qa)).min(1.0);
    (t0 < t1).then(|| (a + d * t0, a + d * t1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use rand::SeedableRng;

    #[test]
    fn transitions_follow_their_probabilities() {
        let road = RoadNetwork::from_config(&Config::default_lab().road);
        let a = road.nodes.iter().position(|n| n.id == 1).unwrap();
        let b = road.nodes.iter().position(|n| n.id == 2).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let n = 20_000;
        let to_b = (0..n)
            .filter(|_| road.sample_next(a, &mut rng) == b)
            .count();
        let share = to_b as f64 / n as f64;
        // 0.3 expected; 4 sigma of a binomial at n = 20000 is 0.013.
        assert!((share - 0.3).abs() < 0.013, "{share}");
    }

    #[test]
    fn edges_connect_configured_nodes() {
        let road = RoadNetwork::from_config(&Config::default_lab().road);
        assert_eq!(road.edges_enu().len(), 7);
        assert_eq!(road.nodes[road.start].id, 1);
    }

    fn distance_to_roads(road: &RoadNetwork, p: &Enu2) -> f64 {
        road.distance_to_roads(p)
    }

    #[test]
    fn points_on_the_roads_lie_on_an_edge_inside_the_region_in_its_direction() {
        let road = RoadNetwork::from_config(&Config::default_lab().road);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let region = (Enu2::new(0.35, 0.2), 0.5);
        for _ in 0..2000 {
            let (p, dir) = road.sample_on_roads(Some(region), &mut rng).unwrap();
            assert!(distance_to_roads(&road, &p) < 1e-9, "{p} is off the roads");
            assert!(
                (p - region.0).norm() <= region.1 + 1e-9,
                "{p} outside the region"
            );
            assert!((dir.norm() - 1.0).abs() < 1e-12);
        }
        // Within 0.5 m of (0.35, 0.2) only the edge 2 -> 3 (x = 0.35, northward) passes:
        // every direction drawn there is north.
        let (_, dir) = road.sample_on_roads(Some(region), &mut rng).unwrap();
        assert!((dir - Enu2::new(0.0, 1.0)).norm() < 1e-9, "{dir}");
        assert!((road.length_within(Some(region)) - 1.0).abs() < 1e-9);
        // No road far away.
        assert!(road
            .sample_on_roads(Some((Enu2::new(50.0, 50.0), 1.0)), &mut rng)
            .is_none());
    }

    #[test]
    fn the_whole_network_is_drawn_by_length() {
        let road = RoadNetwork::from_config(&Config::default_lab().road);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let total = road.length_within(None);
        // Edge 2 -> 3 is 1.6 m of the network: its share of draws follows.
        let n = 20_000;
        let on_2_3 = (0..n)
            .filter(|_| {
                let (p, _) = road.sample_on_roads(None, &mut rng).unwrap();
                (p.x - 0.35).abs() < 1e-9 && p.y > -0.6 && p.y < 1.0
            })
            .count();
        let share = on_2_3 as f64 / n as f64;
        let expected = 1.6 / total;
        assert!((share - expected).abs() < 0.015, "{share} vs {expected}");
    }
}
