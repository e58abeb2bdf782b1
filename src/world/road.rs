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
        Self {
            nodes,
            start: index(c.start_node),
        }
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
}
