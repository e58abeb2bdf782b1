//! The road table's rules, each with its own message naming the key: unique node ids inside
//! the workspace, edges between nodes that exist, turn probabilities that sum to 1 at each
//! node, a start, and a way out of every node the target can reach.

use std::collections::{BTreeMap, BTreeSet};

use super::RoadConfig;
use crate::check::{invalid, Checked};
use crate::world::geometry::{BoundsEnu, Enu2};

impl RoadConfig {
    /// Checks `road` against the workspace `ws`.
    pub fn check(&self, ws: &BoundsEnu) -> Checked {
        let ids = self.check_nodes(ws)?;
        let out_sum = self.check_edges(&ids)?;
        for (node, sum) in &out_sum {
            if (sum - 1.0).abs() > 1e-6 {
                return Err(invalid(
                    format!("road.edges (from = {node})"),
                    sum,
                    "transition probabilities leaving this node must sum to 1",
                ));
            }
        }
        if !ids.contains(&self.start_node) {
            return Err(invalid("road.start_node", self.start_node, "no such node"));
        }
        self.every_reachable_node_has_a_way_out(&out_sum)
    }

    /// Unique ids, finite positions inside `ws`; the set of ids.
    fn check_nodes(&self, ws: &BoundsEnu) -> Result<BTreeSet<u32>, crate::check::InvalidValue> {
        if self.nodes.is_empty() {
            return Err(invalid("road.nodes", "[]", "needs at least one node"));
        }
        let mut ids = BTreeSet::new();
        for (i, n) in self.nodes.iter().enumerate() {
            if !ids.insert(n.id) {
                return Err(invalid(
                    format!("road.nodes[{i}].id"),
                    n.id,
                    "duplicate node id",
                ));
            }
            let p = Enu2::new(n.x_m, n.y_m);
            if !(n.x_m.is_finite() && n.y_m.is_finite() && ws.contains(&p)) {
                return Err(invalid(
                    format!("road.nodes[{i}]"),
                    [n.x_m, n.y_m],
                    "node must be finite and inside the workspace",
                ));
            }
        }
        Ok(ids)
    }

    /// Edges between two different nodes of `ids` with a probability in (0, 1]; the sum of
    /// the probabilities leaving each node that has an exit.
    fn check_edges(
        &self,
        ids: &BTreeSet<u32>,
    ) -> Result<BTreeMap<u32, f64>, crate::check::InvalidValue> {
        let mut out_sum: BTreeMap<u32, f64> = BTreeMap::new();
        for (i, e) in self.edges.iter().enumerate() {
            let key = |field: &str| format!("road.edges[{i}].{field}");
            if !ids.contains(&e.from) {
                let why = "edge leaves a node that does not exist";
                return Err(invalid(key("from"), e.from, why));
            }
            if !ids.contains(&e.to) {
                let why = "edge enters a node that does not exist";
                return Err(invalid(key("to"), e.to, why));
            }
            if e.from == e.to {
                return Err(invalid(key("to"), e.to, "self-loop edge"));
            }
            if !(e.p.is_finite() && e.p > 0.0 && e.p <= 1.0) {
                return Err(invalid(key("p"), e.p, "must lie in (0, 1]"));
            }
            *out_sum.entry(e.from).or_default() += e.p;
        }
        Ok(out_sum)
    }

    /// Every node the target can reach from the start must have a way out, or it would stop
    /// for ever. `out_sum`: each node with an outgoing edge.
    fn every_reachable_node_has_a_way_out(&self, out_sum: &BTreeMap<u32, f64>) -> Checked {
        let mut exits: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        for e in &self.edges {
            exits.entry(e.from).or_default().push(e.to);
        }
        let mut seen = BTreeSet::new();
        let mut stack = vec![self.start_node];
        while let Some(n) = stack.pop() {
            if !seen.insert(n) {
                continue;
            }
            if !out_sum.contains_key(&n) {
                return Err(invalid(
                    "road.edges",
                    n,
                    "node is reachable from road.start_node but has no outgoing edge",
                ));
            }
            stack.extend(exits.get(&n).into_iter().flatten().copied());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::{EdgeConfig, NodeConfig};
    use super::*;

    const WS: BoundsEnu = BoundsEnu {
        x_min_m: 0.0,
        x_max_m: 100.0,
        y_min_m: 0.0,
        y_max_m: 100.0,
    };

    /// A triangle 1 -> 2 -> 3 -> 1, each exit taken for sure.
    fn triangle() -> RoadConfig {
        let node = |id, x_m, y_m| NodeConfig { id, x_m, y_m };
        let edge = |from, to| EdgeConfig { from, to, p: 1.0 };
        RoadConfig {
            nodes: vec![
                node(1, 10.0, 10.0),
                node(2, 90.0, 10.0),
                node(3, 50.0, 90.0),
            ],
            edges: vec![edge(1, 2), edge(2, 3), edge(3, 1)],
            start_node: 1,
        }
    }

    #[test]
    fn a_closed_circuit_inside_the_workspace_passes() {
        assert_eq!(triangle().check(&WS), Ok(()));
    }

    #[test]
    fn a_reachable_dead_end_is_named() {
        let mut road = triangle();
        road.edges.pop();
        let e = road.check(&WS).unwrap_err();
        assert_eq!((e.key.as_str(), e.value.as_str()), ("road.edges", "3"));
    }

    #[test]
    fn exits_that_do_not_sum_to_one_name_their_node() {
        let mut road = triangle();
        road.edges[0].p = 0.5;
        let e = road.check(&WS).unwrap_err();
        assert_eq!(e.key, "road.edges (from = 1)");
    }

    #[test]
    fn a_node_outside_the_workspace_and_a_missing_start_are_refused() {
        let mut road = triangle();
        road.nodes[1].x_m = 100.5;
        assert_eq!(road.check(&WS).unwrap_err().key, "road.nodes[1]");
        let mut road = triangle();
        road.start_node = 7;
        assert_eq!(road.check(&WS).unwrap_err().key, "road.start_node");
    }

    #[test]
    fn an_edge_to_an_unknown_node_names_the_edge_and_its_end() {
        let mut road = triangle();
        road.edges[1].to = 9;
        assert_eq!(road.check(&WS).unwrap_err().key, "road.edges[1].to");
    }
}
