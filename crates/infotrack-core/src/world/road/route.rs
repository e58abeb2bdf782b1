//! The shortest way along the roads between two points, for a drone that flies the roads (in
//! either direction: it is not the car) rather than the straight line between them.

use petgraph::algo::astar;
use petgraph::graph::{NodeIndex, UnGraph};

use super::{Enu2, RoadNetwork};

/// The roads as an undirected graph: a node per road node (its position, world ENU), an
/// edge per road edge of positive length (its length, m). Both directions of a two-way road
/// become two parallel edges of one length, which changes no shortest path.
pub(super) fn undirected_graph(road: &RoadNetwork) -> UnGraph<Enu2, f64> {
    let mut graph = UnGraph::with_capacity(road.nodes.len(), road.segments.len());
    for node in &road.nodes {
        graph.add_node(node.position_enu);
    }
    for (u, node) in road.nodes.iter().enumerate() {
        for &(v, _) in &node.next {
            let length_m = (road.nodes[v].position_enu - node.position_enu).norm();
            if length_m > 1e-9 {
                graph.add_edge(NodeIndex::new(u), NodeIndex::new(v), length_m);
            }
        }
    }
    graph
}

/// A way along the roads: the points it turns at, world ENU, from its start (the road point
/// nearest where it was asked from) to its end (the road point nearest where it goes).
#[derive(Debug, Clone, PartialEq)]
pub struct RoadPath {
    points_enu: Vec<Enu2>,
    length_m: f64,
}

impl RoadPath {
    fn new(points_enu: Vec<Enu2>) -> Self {
        let length_m = points_enu.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        Self {
            points_enu,
            length_m,
        }
    }

    /// Its length, m.
    pub fn length_m(&self) -> f64 {
        self.length_m
    }

    /// The points it turns at, world ENU, start and end included.
    pub fn points_enu(&self) -> &[Enu2] {
        &self.points_enu
    }

    /// The point `s_m` metres along it (clamped to its ends), world ENU, and the unit
    /// direction of the piece it lies on (zero on a path of no length).
    pub fn point_at(&self, s_m: f64) -> (Enu2, Enu2) {
        let mut left = s_m.max(0.0);
        let mut last = (self.points_enu[0], Enu2::zeros());
        for w in self.points_enu.windows(2) {
            let piece = w[1] - w[0];
            let len = piece.norm();
            if len <= 1e-9 {
                continue;
            }
            let dir = piece / len;
            if left <= len {
                return (w[0] + dir * left, dir);
            }
            left -= len;
            last = (w[1], dir);
        }
        last
    }
}

impl RoadNetwork {
    /// The shortest way along the roads, either direction, from the road point nearest
    /// `from` to the road point nearest `to` (world ENU); `None` without roads or where
    /// none joins them. A* over the road nodes, with the straight line to `to`'s road point
    /// as its (admissible) estimate.
    pub fn path_between(&self, from: &Enu2, to: &Enu2) -> Option<RoadPath> {
        let (fu, fv, fs) = self.nearest_edge(from, None)?;
        let (tu, tv, ts) = self.nearest_edge(to, None)?;
        let on_edge = |u: usize, v: usize, s: f64| {
            let a = self.nodes[u].position_enu;
            let b = self.nodes[v].position_enu;
            (a + (b - a).normalize() * s, s, (b - a).norm() - s)
        };
        let (from_road, f_to_u, f_to_v) = on_edge(fu, fv, fs);
        let (to_road, t_to_u, t_to_v) = on_edge(tu, tv, ts);
        let mut graph = self.graph.clone();
        let start = graph.add_node(from_road);
        let goal = graph.add_node(to_road);
        graph.add_edge(start, NodeIndex::new(fu), f_to_u);
        graph.add_edge(start, NodeIndex::new(fv), f_to_v);
        graph.add_edge(goal, NodeIndex::new(tu), t_to_u);
        graph.add_edge(goal, NodeIndex::new(tv), t_to_v);
        // On one road (either of its directions), straight along it is a way too.
        if (fu, fv) == (tu, tv) || (fu, fv) == (tv, tu) {
            graph.add_edge(start, goal, (to_road - from_road).norm());
        }
        let (_, nodes) = astar(
            &graph,
            start,
            |n| n == goal,
            |e| *e.weight(),
            |n| (graph[n] - to_road).norm(),
        )?;
        Some(RoadPath::new(nodes.into_iter().map(|n| graph[n]).collect()))
    }
}
