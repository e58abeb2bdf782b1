//! The road network: a Markov chain over nodes joined by straight edges.

use rand::Rng;

use super::geometry::Enu2;
use serde::{Deserialize, Serialize};

mod check;
mod learn;
mod nearby;
mod route;
mod traffic;
pub use learn::TurnCounts;
pub use route::RoadPath;
pub use traffic::RoadWeighting;

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

/// Which edges count as near a point for a heading to choose among
/// ([`RoadNetwork::reachable_from`], [`RoadNetwork::drive`]): those within twice the nearest
/// edge's distance plus this share of the network's shortest edge (the roads that meet at a
/// junction, or run both ways along one line, are equally near; a road elsewhere in the
/// network is not).
pub const NEAR_EDGE_SHARE: f64 = 0.05;

/// Road network, indexed densely; configuration ids are kept for reports.
#[derive(Debug, Clone)]
pub struct RoadNetwork {
    /// Nodes in configuration order.
    pub nodes: Vec<RoadNode>,
    /// Index of the start node.
    pub start: usize,
    /// Every directed edge as its end points, world ENU (nodes in order, each node's exits
    /// in order).
    segments: Vec<(Enu2, Enu2)>,
    /// The (from, to) node indices of each of `segments`.
    edge_ends: Vec<(usize, usize)>,
    /// `segments` by where they lie.
    nearby: nearby::SegmentIndex,
    /// [`NEAR_EDGE_SHARE`] of the shortest edge, m (infinite without edges).
    near_tolerance_m: f64,
    /// The roads as an undirected graph weighed by length ([`Self::path_between`]).
    graph: petgraph::graph::UnGraph<Enu2, f64>,
    /// The traffic per metre of each of `segments`, relative to the mean edge's
    /// ([`Self::traffic_within`]).
    traffic_per_m: Vec<f64>,
}

impl RoadNetwork {
    /// From a configuration: every edge's ends and the start must be nodes of it.
    pub fn from_config(c: &RoadConfig) -> Result<Self, RoadError> {
        Self::try_from(c)
    }
}

/// A road configuration that is not a network.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RoadError {
    /// An edge or the start names a node that is not there.
    #[error("road.{what} names node {id}, which is not one of road.nodes")]
    UnknownNode {
        /// Where the id is used (`edges[3].to`, `start_node`).
        what: String,
        /// The id.
        id: u32,
    },
}

impl TryFrom<&RoadConfig> for RoadNetwork {
    type Error = RoadError;

    fn try_from(c: &RoadConfig) -> Result<Self, RoadError> {
        // Id -> the first node with it: a lookup per edge, not a scan (a town has thousands).
        let mut by_id = std::collections::HashMap::with_capacity(c.nodes.len());
        for (k, n) in c.nodes.iter().enumerate() {
            by_id.entry(n.id).or_insert(k);
        }
        let index = |id: u32, what: &dyn Fn() -> String| {
            by_id
                .get(&id)
                .copied()
                .ok_or_else(|| RoadError::UnknownNode { what: what(), id })
        };
        let mut next = vec![Vec::new(); c.nodes.len()];
        for (k, e) in c.edges.iter().enumerate() {
            let from = index(e.from, &|| format!("edges[{k}].from"))?;
            next[from].push((index(e.to, &|| format!("edges[{k}].to"))?, e.p));
        }
        let nodes = c
            .nodes
            .iter()
            .zip(next)
            .map(|(n, next)| RoadNode {
                id: n.id,
                position_enu: Enu2::new(n.x_m, n.y_m),
                next,
            })
            .collect();
        let start = index(c.start_node, &|| "start_node".to_string())?;
        Ok(RoadNetwork::assemble(nodes, start))
    }
}

impl RoadNetwork {
    /// The network from its nodes (with their exits) and start: segments, traffic, graph.
    fn assemble(nodes: Vec<RoadNode>, start: usize) -> Self {
        let mut road = Self {
            nodes,
            start,
            segments: Vec::new(),
            edge_ends: Vec::new(),
            nearby: Default::default(),
            near_tolerance_m: f64::INFINITY,
            graph: Default::default(),
            traffic_per_m: Vec::new(),
        };
        road.segments = road.edges_enu();
        road.edge_ends = road
            .nodes
            .iter()
            .enumerate()
            .flat_map(|(u, n)| n.next.iter().map(move |&(v, _)| (u, v)))
            .collect();
        road.nearby = nearby::SegmentIndex::new(&road.segments);
        road.traffic_per_m = traffic::traffic_per_m(&road.nodes);
        road.graph = route::undirected_graph(&road);
        let shortest = road
            .segments
            .iter()
            .map(|(a, b)| (b - a).norm())
            .filter(|len| *len > 1e-9)
            .fold(f64::INFINITY, f64::min);
        road.near_tolerance_m = NEAR_EDGE_SHARE * shortest;
        road
    }

    /// Distance from `p` to the nearest road, m (infinite without roads).
    pub fn distance_to_roads(&self, p: &Enu2) -> f64 {
        self.nearest_distance(p, |_| true)
    }

    /// Distances from `p` to the nearest road, and to the nearest road one may drive in
    /// the direction `heading` (a unit vector, world ENU): an edge whose allowed direction
    /// lies within [`ALONG_HEADING_COS`] of it. m; infinite where there is none.
    pub fn distances_to_roads(&self, p: &Enu2, heading: &Enu2) -> (f64, f64) {
        let agrees = |k: usize| {
            let (a, b) = self.segments[k];
            let len = (b - a).norm();
            len > 0.0 && (b - a).dot(heading) >= ALONG_HEADING_COS * len
        };
        (self.distance_to_roads(p), self.nearest_distance(p, agrees))
    }

    /// Distance from `p` to the nearest segment `keep` admits, m (infinite without one):
    /// the nearest such segment by the index, then every segment within a hair of it, each
    /// measured as a scan of all would measure it.
    fn nearest_distance(&self, p: &Enu2, keep: impl Fn(usize) -> bool) -> f64 {
        let distance = |k: usize| {
            let (a, b) = self.segments[k];
            distance_to_segment(p, &a, &b)
        };
        let Some(first) = self.nearby.nearest_first(p).find(|k| keep(*k)) else {
            return f64::INFINITY;
        };
        self.nearby
            .within(p, nearby::reach(distance(first)))
            .into_iter()
            .filter(|k| keep(*k))
            .map(distance)
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
        self.weighted_pieces_within(region, std::iter::repeat(1.0))
    }

    /// [`Self::roads_within`] weighted by traffic: each edge's part in `region` weighs its
    /// traffic flow per metre (the road graph's Markov chain in the long run, see
    /// `traffic.rs`), so that a point drawn from them is where a car driving the graph is
    /// likely to be. The prior from an operator's cue.
    pub fn traffic_within(&self, region: Option<(Enu2, f64)>) -> RoadPieces {
        self.weighted_pieces_within(region, self.traffic_per_m.iter().copied())
    }

    /// The parts of every directed edge inside `region` (as [`Self::pieces_within`]), each
    /// weighing its edge's entry of `weight_per_m` (in the order of the segments); edges of
    /// weight 0 are left out, as no point can be drawn from them.
    fn weighted_pieces_within(
        &self,
        region: Option<(Enu2, f64)>,
        weight_per_m: impl Iterator<Item = f64>,
    ) -> RoadPieces {
        let mut out = RoadPieces {
            pieces: Vec::new(),
            weights: Vec::new(),
            total: 0.0,
        };
        for (&(a, b), w) in self.segments.iter().zip(weight_per_m) {
            if let Some(piece) = clip_piece(a, b, region).filter(|_| w > 0.0) {
                out.pieces.push(piece);
                out.weights.push(w);
            }
        }
        out.sum_total();
        out
    }

    /// The roads within `region` weighted as `weighting` says: [`Self::traffic_within`] or
    /// [`Self::roads_within`].
    pub fn weighted_within(
        &self,
        region: Option<(Enu2, f64)>,
        weighting: RoadWeighting,
    ) -> RoadPieces {
        match weighting {
            RoadWeighting::Traffic => self.traffic_within(region),
            RoadWeighting::Length => self.roads_within(region),
        }
    }

    /// [`Self::roads_within`] `region`, or the whole network where no road lies in it: where
    /// a target that must be on some road can be drawn when the region holds none.
    pub fn roads_within_or_all(&self, region: Option<(Enu2, f64)>) -> RoadPieces {
        let roads = self.roads_within(region);
        if roads.length_m() > 0.0 || region.is_none() {
            return roads;
        }
        self.roads_within(None)
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
            .filter_map(|&(a, b)| clip_piece(a, b, region))
            .collect()
    }

    /// The roads the target can be on after driving a path length in `distance_m` from
    /// `from`, along the allowed directions, each piece weighted by the probability of the
    /// turns that lead to it (the product of the transition probabilities on the way).
    /// `from` is placed on the nearest edge whose direction agrees with `heading` (when
    /// given and not zero). Empty when there is no road.
    pub fn reachable_from(
        &self,
        from: &Enu2,
        heading: Option<Enu2>,
        distance_m: (f64, f64),
    ) -> RoadPieces {
        self.reachable_along(from, heading, distance_m).0
    }

    /// [`Self::reachable_from`], and the unit direction (world ENU) of the edge `from` was
    /// placed on (`None` without roads): what a turn back is told against.
    pub fn reachable_along(
        &self,
        from: &Enu2,
        heading: Option<Enu2>,
        distance_m: (f64, f64),
    ) -> (RoadPieces, Option<Enu2>) {
        let mut out = RoadPieces {
            pieces: Vec::new(),
            weights: Vec::new(),
            total: 0.0,
        };
        let Some((u, v, s0)) = self.nearest_edge(from, heading) else {
            return (out, None);
        };
        self.walk(u, v, s0, 0.0, 1.0, distance_m, 0, &mut out);
        out.sum_total();
        let d = self.nodes[v].position_enu - self.nodes[u].position_enu;
        (out, (d.norm() > 1e-9).then(|| d.normalize()))
    }

    /// Whether the road a target at `from` (heading `heading`, placed as in
    /// [`Self::reachable_from`]) is on ends at a dead end: every edge out of its end node
    /// leads back to its start node (a spur the car can only turn round in). False without
    /// roads, and at a node with no edge out (nothing to turn back along).
    pub fn heads_into_a_dead_end(&self, from: &Enu2, heading: Option<Enu2>) -> bool {
        let Some((u, v, _)) = self.nearest_edge(from, heading) else {
            return false;
        };
        let next = &self.nodes[v].next;
        !next.is_empty() && next.iter().all(|(w, _)| *w == u)
    }

    /// One route a target at `from` (heading `heading`, placed as in
    /// [`Self::reachable_from`]) can drive, its turns drawn by their probabilities: where
    /// it is, and the unit direction of its road, after each path length in `distances_m`
    /// (ascending, m). Without a heading, a target on a two-way street drives it either way
    /// with even chances. A target at a node without a way on stops there. `None` without
    /// roads.
    pub fn drive<R: Rng + ?Sized>(
        &self,
        from: &Enu2,
        heading: Option<Enu2>,
        distances_m: &[f64],
        rng: &mut R,
    ) -> Option<Vec<(Enu2, Enu2)>> {
        let (mut u, mut v, mut s0) = self.nearest_edge(from, heading)?;
        // The nearest edge alone would send every route the way its edge is listed.
        if heading.is_none() && self.nodes[v].next.iter().any(|(w, _)| *w == u) && rng.gen_bool(0.5)
        {
            let len = (self.nodes[v].position_enu - self.nodes[u].position_enu).norm();
            (u, v, s0) = (v, u, len - s0);
        }
        // Path length at the start of edge u->v (negative: `from` lies along it).
        let mut edge_start = -s0;
        let mut out = Vec::with_capacity(distances_m.len());
        // A bound on edges driven (a loop of zero-length edges would never add length).
        let mut edges_left = 100_000usize;
        for &d in distances_m {
            loop {
                let a = self.nodes[u].position_enu;
                let b = self.nodes[v].position_enu;
                let len = (b - a).norm();
                let dir = if len > 1e-9 {
                    (b - a) / len
                } else {
                    Enu2::zeros()
                };
                if d <= edge_start + len || self.nodes[v].next.is_empty() || edges_left == 0 {
                    let along = (d - edge_start).clamp(0.0, len);
                    out.push((a + dir * along, dir));
                    break;
                }
                edge_start += len;
                edges_left -= 1;
                let w = self.sample_next(v, rng);
                (u, v) = (v, w);
            }
        }
        Some(out)
    }

    /// The edge (from-node, to-node indices) nearest to `p` and the distance along it of
    /// `p`'s projection. With a `heading`, the edge is chosen among the near ones (see
    /// [`NEAR_EDGE_SHARE`]) by how well it agrees with the heading: edges heading against
    /// it count only when no other is near; and edges that run alongside `p` (its
    /// projection falls inside them) and go its way ([`ALONG_HEADING_COS`]) come before
    /// edges it lies beyond an end of.
    fn nearest_edge(&self, p: &Enu2, heading: Option<Enu2>) -> Option<(usize, usize, f64)> {
        let heading = heading.filter(|h| h.norm() > 1e-9).map(|h| h.normalize());
        let goes_its_way = |e: &EdgeProjection| {
            heading
                .is_some_and(|h| e.overshoot_m <= 0.0 && e.direction.dot(&h) >= ALONG_HEADING_COS)
        };
        // The nearest edge's distance from the index; then the edges about as near, in the
        // network's order (the first of equal costs wins, as in a scan of every edge).
        let first = self
            .nearby
            .nearest_first(p)
            .find_map(|k| self.projection(k, p))?;
        let nearest = self
            .projections_within(p, nearby::reach(first.distance_m))
            .fold(f64::INFINITY, |any, e| any.min(e.distance_m));
        // The heading chooses only among the edges about as near as the nearest: with it
        // weighed against any distance (a 90-degree difference as 1 km, say),
        // a slow track 10 m short of a junction whose velocity's noise pointed east was put
        // on the start of an east-going road 390 m back, and a track just past a gentle bend
        // back on the road before it, 58 m behind (BENCHMARKS.md).
        let near = 2.0 * nearest + self.near_tolerance_m;
        let candidates: Vec<EdgeProjection> =
            self.projections_within(p, nearby::reach(near)).collect();
        let nearest_its_way = candidates
            .iter()
            .filter(|e| goes_its_way(e))
            .fold(f64::INFINITY, |its_way, e| its_way.min(e.distance_m));
        // A point beyond an edge's end is not on it: its projection is the end node. Chosen
        // by the heading alone, a car 29 m past a junction and 8 m beside its new road (it
        // had cut the corner), heading 23 degrees off that road, was put back on the road it
        // came in on, at the junction, and re-routed from there: the whole belief jumped 29 m
        // back, its share down the other branch survived the camera while the car drove out
        // of view, and the drone followed it (field-ring seed 1, BENCHMARKS.md).
        let alongside = nearest_its_way <= near;
        let mut best: Option<(f64, (usize, usize, f64))> = None;
        for e in candidates {
            if e.distance_m > near || (alongside && !goes_its_way(&e)) {
                continue;
            }
            let cost = match heading {
                // Across or against the heading: as if up to 2 km farther away (a 5-degree
                // difference costs 4 m, a crossing road 1 km).
                Some(h) => e.distance_m + (1.0 - e.direction.dot(&h)) * 1e3,
                None => e.distance_m,
            };
            if best.map_or(true, |(c, _)| cost < c) {
                best = Some((cost, e.edge));
            }
        }
        best.map(|(_, e)| e)
    }

    /// `p`'s projection on segment `k`, if the segment has a length.
    fn projection(&self, k: usize, p: &Enu2) -> Option<EdgeProjection> {
        let (u, v) = self.edge_ends[k];
        let a = self.nodes[u].position_enu;
        let d = self.nodes[v].position_enu - a;
        let len = d.norm();
        if len <= 1e-9 {
            return None;
        }
        let direction = d / len;
        let along = (p - a).dot(&direction);
        let s = along.clamp(0.0, len);
        Some(EdgeProjection {
            distance_m: (a + direction * s - p).norm(),
            direction,
            overshoot_m: (along - len).max(-along).max(0.0),
            edge: (u, v, s),
        })
    }

    /// `p`'s projections on the edges of positive length within `r` of it (and perhaps a
    /// few more), in the network's order.
    fn projections_within<'a>(
        &'a self,
        p: &'a Enu2,
        r: f64,
    ) -> impl Iterator<Item = EdgeProjection> + 'a {
        self.nearby
            .within(p, r)
            .into_iter()
            .filter_map(move |k| self.projection(k, p))
    }

    /// Collects the part of edge u->v (from `s0` metres along it, `travelled` metres of path
    /// behind) that lies within `distance_m` of path, then the edges after it.
    #[allow(clippy::too_many_arguments)]
    fn walk(
        &self,
        u: usize,
        v: usize,
        s0: f64,
        travelled: f64,
        probability: f64,
        distance_m: (f64, f64),
        depth: usize,
        out: &mut RoadPieces,
    ) {
        // A bound on turns taken: a path through a 1e-6-likely chain of turns, or longer
        // than any search radius could need, carries nothing worth drawing.
        if depth > 256 || probability < 1e-6 {
            return;
        }
        let a = self.nodes[u].position_enu;
        let d = self.nodes[v].position_enu - a;
        let len = d.norm();
        let (d_min, d_max) = distance_m;
        if len > 1e-9 {
            let dir = d / len;
            let lo = s0.max(s0 + d_min - travelled);
            let hi = len.min(s0 + d_max - travelled);
            if hi - lo > 1e-9 {
                out.pieces.push((a + dir * lo, a + dir * hi));
                out.weights.push(probability);
            }
        }
        let at_end = travelled + (len - s0).max(0.0);
        if at_end >= d_max {
            return;
        }
        for &(w, p) in &self.nodes[v].next {
            self.walk(
                v,
                w,
                0.0,
                at_end.max(travelled + 1e-9),
                probability * p,
                distance_m,
                depth + 1,
                out,
            );
        }
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

/// A point's projection on one directed edge.
#[derive(Debug, Clone, Copy)]
struct EdgeProjection {
    /// Distance from the point to the edge, m.
    distance_m: f64,
    /// The edge's unit direction, world ENU.
    direction: Enu2,
    /// How far the point lies beyond either end of the edge, along it, m (0: alongside).
    overshoot_m: f64,
    /// From-node and to-node indices and the distance along the edge of the projection.
    edge: (usize, usize, f64),
}

/// Distance from `p` to the segment a-b, m.
fn distance_to_segment(p: &Enu2, a: &Enu2, b: &Enu2) -> f64 {
    let d = b - a;
    let len2 = d.dot(&d);
    let t = if len2 > 0.0 {
        ((p - a).dot(&d) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + d * t - p).norm()
}

/// The cosine within which a heading drives along a road's allowed direction (60 degrees:
/// a track's heading scatters with the process noise, and lags a bend).
pub const ALONG_HEADING_COS: f64 = 0.5;

/// Road segments (each in its edge's direction), each with a weight per metre, and their
/// total weighted length.
#[derive(Debug, Clone)]
pub struct RoadPieces {
    pieces: Vec<(Enu2, Enu2)>,
    weights: Vec<f64>,
    total: f64,
}

impl RoadPieces {
    /// Sets the total weighted length from the pieces (after they are collected).
    fn sum_total(&mut self) {
        self.total = self
            .pieces
            .iter()
            .zip(&self.weights)
            .map(|((a, b), w)| (b - a).norm() * w)
            .sum();
    }

    /// Total weighted length, m (the plain length when every weight is 1).
    pub fn length_m(&self) -> f64 {
        self.total
    }

    /// The segments and their weights per metre.
    pub fn pieces(&self) -> impl Iterator<Item = (&(Enu2, Enu2), f64)> {
        self.pieces.iter().zip(self.weights.iter().copied())
    }

    /// These pieces split in one pass: those that do not run back against `heading` (more
    /// than ~154 degrees from it: a U-turn), or all of them when nothing else is left; and
    /// the reversals alone (none without a heading).
    pub fn split_reversals(self, heading: &Enu2) -> (RoadPieces, RoadPieces) {
        let h = heading.norm();
        let empty = || RoadPieces {
            pieces: Vec::new(),
            weights: Vec::new(),
            total: 0.0,
        };
        if h <= 1e-9 {
            return (self, empty());
        }
        let (mut ahead, mut back) = (empty(), empty());
        for (piece, w) in self.pieces.into_iter().zip(self.weights) {
            let side = if is_reversal(&piece, heading, h) {
                &mut back
            } else {
                &mut ahead
            };
            side.pieces.push(piece);
            side.weights.push(w);
        }
        if ahead.pieces.is_empty() {
            ahead.pieces.clone_from(&back.pieces);
            ahead.weights.clone_from(&back.weights);
        }
        ahead.sum_total();
        back.sum_total();
        (ahead, back)
    }

    /// How many of these pieces run back against `heading` (see [`Self::split_reversals`]).
    pub fn reversals(&self, heading: &Enu2) -> usize {
        let h = heading.norm();
        if h <= 1e-9 {
            return 0;
        }
        self.pieces
            .iter()
            .filter(|p| is_reversal(p, heading, h))
            .count()
    }

    /// These pieces less those that run back against `heading` (more than ~154 degrees
    /// from it: a U-turn), unless nothing else is left.
    pub fn without_reversals(self, heading: &Enu2) -> RoadPieces {
        self.split_reversals(heading).0
    }

    /// A point drawn by weighted length and the unit direction of its road; `None` when
    /// there is no road.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Option<(Enu2, Enu2)> {
        if self.total.is_nan() || self.total <= 0.0 {
            return None;
        }
        let mut u = rng.gen_range(0.0..self.total);
        for ((a, b), w) in self.pieces.iter().zip(&self.weights) {
            let len = (b - a).norm();
            let mass = len * w;
            if u <= mass {
                let dir = (b - a) / len;
                return Some((a + dir * (u / w), dir));
            }
            u -= mass;
        }
        let (a, b) = self.pieces.last()?;
        Some((*b, (b - a).normalize()))
    }
}

/// The part of the directed edge a-b inside `region` (a disc: centre and radius, world
/// ENU; `None`: the whole edge), if any of non-zero length.
fn clip_piece(a: Enu2, b: Enu2, region: Option<(Enu2, f64)>) -> Option<(Enu2, Enu2)> {
    let clipped = match region {
        None => Some((a, b)),
        Some((c, r)) => clip_to_disc(a, b, c, r),
    };
    clipped.filter(|(a, b)| (b - a).norm() > 1e-9)
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

/// Whether `piece` runs back against `heading` (of norm `h` > 0): more than ~154 degrees
/// from it, a U-turn.
fn is_reversal((a, b): &(Enu2, Enu2), heading: &Enu2, h: f64) -> bool {
    let d = b - a;
    d.norm() > 1e-9 && d.dot(heading) / (d.norm() * h) <= -0.9
}

#[cfg(test)]
mod tests;
