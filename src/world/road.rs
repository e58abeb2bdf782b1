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
    /// Every directed edge as its end points, world ENU.
    segments: Vec<(Enu2, Enu2)>,
    /// [`NEAR_EDGE_SHARE`] of the shortest edge, m (infinite without edges).
    near_tolerance_m: f64,
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
            near_tolerance_m: f64::INFINITY,
        };
        road.segments = road.edges_enu();
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
        self.segments
            .iter()
            .map(|(a, b)| distance_to_segment(p, a, b))
            .fold(f64::INFINITY, f64::min)
    }

    /// Distances from `p` to the nearest road, and to the nearest road one may drive in
    /// the direction `heading` (a unit vector, world ENU): an edge whose allowed direction
    /// lies within [`ALONG_HEADING_COS`] of it. m; infinite where there is none.
    pub fn distances_to_roads(&self, p: &Enu2, heading: &Enu2) -> (f64, f64) {
        self.segments
            .iter()
            .fold((f64::INFINITY, f64::INFINITY), |(any, along), (a, b)| {
                let d = distance_to_segment(p, a, b);
                let len = (b - a).norm();
                let agrees = len > 0.0 && (b - a).dot(heading) >= ALONG_HEADING_COS * len;
                (any.min(d), if agrees { along.min(d) } else { along })
            })
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
        let weights = vec![1.0; pieces.len()];
        RoadPieces {
            pieces,
            weights,
            total,
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
            .copied()
            .filter_map(|(a, b)| match region {
                None => Some((a, b)),
                Some((c, r)) => clip_to_disc(a, b, c, r),
            })
            .filter(|(a, b)| (b - a).norm() > 1e-9)
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
        let mut out = RoadPieces {
            pieces: Vec::new(),
            weights: Vec::new(),
            total: 0.0,
        };
        let Some((u, v, s0)) = self.nearest_edge(from, heading) else {
            return out;
        };
        self.walk(u, v, s0, 0.0, 1.0, distance_m, 0, &mut out);
        out.sum_total();
        out
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
    /// (ascending, m). A target at a node without a way on stops there. `None` without roads.
    pub fn drive<R: Rng + ?Sized>(
        &self,
        from: &Enu2,
        heading: Option<Enu2>,
        distances_m: &[f64],
        rng: &mut R,
    ) -> Option<Vec<(Enu2, Enu2)>> {
        let (mut u, mut v, s0) = self.nearest_edge(from, heading)?;
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
    /// it count only when no other is near.
    fn nearest_edge(&self, p: &Enu2, heading: Option<Enu2>) -> Option<(usize, usize, f64)> {
        let heading = heading.filter(|h| h.norm() > 1e-9).map(|h| h.normalize());
        let nearest = self
            .edge_projections(p)
            .map(|(dist, _, _)| dist)
            .fold(f64::INFINITY, f64::min);
        // The heading chooses only among the edges about as near as the nearest: with it
        // weighed against any distance (before session 25, a 90-degree difference as 1 km),
        // a slow track 10 m short of a junction whose velocity's noise pointed east was put
        // on the start of an east-going road 390 m back, and a track just past a gentle bend
        // back on the road before it, 58 m behind (BENCHMARKS "Field scale, part 23").
        let near = 2.0 * nearest + self.near_tolerance_m;
        let mut best: Option<(f64, (usize, usize, f64))> = None;
        for (dist, dir, edge) in self.edge_projections(p).filter(|e| e.0 <= near) {
            let cost = match heading {
                // Across or against the heading: as if up to 2 km farther away (a 5-degree
                // difference costs 4 m, a crossing road 1 km).
                Some(h) => dist + (1.0 - dir.dot(&h)) * 1e3,
                None => dist,
            };
            if best.map_or(true, |(c, _)| cost < c) {
                best = Some((cost, edge));
            }
        }
        best.map(|(_, e)| e)
    }

    /// Every edge of positive length with `p`'s distance to it, its unit direction and the
    /// edge (from-node, to-node indices, distance along it of `p`'s projection).
    fn edge_projections<'a>(
        &'a self,
        p: &'a Enu2,
    ) -> impl Iterator<Item = (f64, Enu2, (usize, usize, f64))> + 'a {
        self.nodes.iter().enumerate().flat_map(move |(u, node)| {
            node.next.iter().filter_map(move |&(v, _)| {
                let a = node.position_enu;
                let d = self.nodes[v].position_enu - a;
                let len = d.norm();
                if len <= 1e-9 {
                    return None;
                }
                let dir = d / len;
                let s = (p - a).dot(&dir).clamp(0.0, len);
                Some(((a + dir * s - p).norm(), dir, (u, v, s)))
            })
        })
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
mod tests {
    use super::*;
    use crate::config::Config;
    use rand::SeedableRng;

    fn outdoor_road() -> RoadNetwork {
        let cfg = Config::from_toml_str(
            include_str!("../../config/outdoor.toml"),
            std::path::Path::new("config/outdoor.toml"),
        )
        .unwrap();
        RoadNetwork::from_config(&cfg.road)
    }

    #[test]
    fn the_road_one_may_drive_a_heading_is_told_from_the_nearest_road() {
        // Outdoor: 0 (0,0) -> 1 (600,0) is one-way east; 6 <-> 1 runs both ways on x = 600.
        let road = outdoor_road();
        let p = Enu2::new(300.0, 2.0);
        let (any, east) = road.distances_to_roads(&p, &Enu2::new(1.0, 0.0));
        assert!(
            (any - 2.0).abs() < 1e-9 && (east - 2.0).abs() < 1e-9,
            "{any} {east}"
        );
        // Westward, the nearest road one may drive that way is elsewhere (farther).
        let (any, west) = road.distances_to_roads(&p, &Enu2::new(-1.0, 0.0));
        assert!((any - 2.0).abs() < 1e-9 && west > 100.0, "{any} {west}");
        // Within 60 degrees of the road's direction counts as along it; beyond, not.
        let h = |deg: f64| Enu2::new(deg.to_radians().cos(), deg.to_radians().sin());
        assert!(road.distances_to_roads(&p, &h(55.0)).1 < 3.0);
        assert!(road.distances_to_roads(&p, &h(65.0)).1 > 100.0);
        // A two-way road is along either way.
        let q = Enu2::new(601.0, 200.0);
        for dir in [Enu2::new(0.0, 1.0), Enu2::new(0.0, -1.0)] {
            let (any, along) = road.distances_to_roads(&q, &dir);
            assert!((any - 1.0).abs() < 1e-9 && (along - 1.0).abs() < 1e-9);
        }
    }

    /// A region holding road gives that road only; one holding none gives the whole
    /// network (a target on the roads is somewhere on them), as does no region.
    #[test]
    fn roads_within_a_region_fall_back_to_the_whole_network_only_where_it_holds_none() {
        let road = outdoor_road();
        let all = road.roads_within(None).length_m();
        let near_start = Some((Enu2::new(100.0, 0.0), 50.0));
        let within = road.roads_within_or_all(near_start).length_m();
        assert!(within > 0.0 && within < all, "{within} of {all}");
        assert!((within - road.length_within(near_start)).abs() < 1e-9);
        // Far outside the network: no road there, so all of it.
        let empty = Some((Enu2::new(-5000.0, -5000.0), 10.0));
        assert_eq!(road.roads_within(empty).length_m(), 0.0);
        assert!((road.roads_within_or_all(empty).length_m() - all).abs() < 1e-9);
        assert!((road.roads_within_or_all(None).length_m() - all).abs() < 1e-9);
    }

    #[test]
    fn reachable_roads_lie_ahead_within_the_distance_band_split_by_the_turns() {
        // Outdoor: 0 (0,0) -> 1 (600,0), then 1 -> 2 east with p 0.6, 1 -> 6 north with 0.4.
        let road = outdoor_road();
        let from = Enu2::new(550.0, 1.0);
        let heading = Some(Enu2::new(10.0, 0.0));
        let r = road.reachable_from(&from, heading, (80.0, 120.0));
        let pieces: Vec<_> = r.pieces().map(|(p, w)| (*p, w)).collect();
        assert_eq!(pieces.len(), 2, "{pieces:?}");
        let east = pieces.iter().find(|(p, _)| p.0.y.abs() < 1e-9).unwrap();
        let north = pieces
            .iter()
            .find(|(p, _)| (p.0.x - 600.0).abs() < 1e-9)
            .unwrap();
        // 50 m to the junction, then 30..70 m along each branch.
        assert!((east.0 .0.x - 630.0).abs() < 1e-6 && (east.0 .1.x - 670.0).abs() < 1e-6);
        assert!((north.0 .0.y - 30.0).abs() < 1e-6 && (north.0 .1.y - 70.0).abs() < 1e-6);
        assert!((east.1 - 0.6).abs() < 1e-12 && (north.1 - 0.4).abs() < 1e-12);
        // Nothing behind, and the total is weighted: 40 m x (0.6 + 0.4).
        assert!((r.length_m() - 40.0).abs() < 1e-6);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut on_east = 0;
        for _ in 0..4000 {
            let (p, dir) = r.sample(&mut rng).unwrap();
            assert!(p.x >= 600.0 - 1e-9, "behind the junction: {p:?}");
            if p.y.abs() < 1e-9 {
                on_east += 1;
                assert!((dir - Enu2::new(1.0, 0.0)).norm() < 1e-9);
            } else {
                assert!((dir - Enu2::new(0.0, 1.0)).norm() < 1e-9);
            }
        }
        let share = on_east as f64 / 4000.0;
        assert!((share - 0.6).abs() < 0.03, "east share {share}");
    }

    #[test]
    fn a_reversal_is_left_out_unless_it_is_the_only_way_on() {
        // Outdoor: 2 m before node 6 (600, 400) driving north on 1 -> 6; from 6 the roads go
        // on north to 4 (p 0.7) or back south to 1 (p 0.3, a U-turn).
        let road = outdoor_road();
        let north = Enu2::new(0.0, 10.0);
        let ahead = road.reachable_from(&Enu2::new(600.0, 398.0), Some(north), (0.0, 5.0));
        let heads_south = |r: &RoadPieces| r.pieces().any(|((a, b), _)| b.y < a.y - 1e-9);
        assert!(heads_south(&ahead), "the graph allows the U-turn");
        // Node 6 has a way on besides the U-turn: no dead end.
        assert!(!road.heads_into_a_dead_end(&Enu2::new(600.0, 398.0), Some(north)));
        // Its complement: the U-turn alone, 3 m at p 0.3; nothing without a heading.
        let back_only = ahead.clone().split_reversals(&north).1;
        assert!(back_only.pieces().all(|((a, b), _)| b.y < a.y - 1e-9));
        assert!((back_only.length_m() - 0.3 * 3.0).abs() < 1e-6);
        assert_eq!(
            ahead
                .clone()
                .split_reversals(&Enu2::zeros())
                .1
                .pieces()
                .count(),
            0
        );
        let on = ahead.without_reversals(&north);
        assert!(!heads_south(&on));
        assert!(on.pieces().any(|((a, _), _)| a.y >= 400.0 - 1e-9));
        assert!(
            (on.length_m() - (2.0 + 0.7 * 3.0)).abs() < 1e-6,
            "{}",
            on.length_m()
        );
        // Every piece against the heading: nothing else is left, so they stay.
        let back = road.reachable_from(&Enu2::new(600.0, 200.0), Some(-north), (0.0, 5.0));
        let kept = back.length_m();
        assert!((back.without_reversals(&north).length_m() - kept).abs() < 1e-9);
        assert!(kept > 0.0);
    }

    #[test]
    fn the_heading_picks_the_edge_and_a_crossing_road_is_not_taken() {
        // Outdoor has 6 -> 1 (south) and 1 -> 6 (north) on x = 600: the heading decides.
        let road = outdoor_road();
        let from = Enu2::new(600.0, 200.0);
        let north = road.reachable_from(&from, Some(Enu2::new(0.0, 10.0)), (10.0, 20.0));
        let south = road.reachable_from(&from, Some(Enu2::new(0.0, -10.0)), (10.0, 20.0));
        let first = |r: &RoadPieces| r.pieces().next().map(|(p, _)| *p).unwrap();
        assert!(first(&north).0.y > 200.0, "{:?}", first(&north));
        assert!(first(&south).0.y < 200.0, "{:?}", first(&south));
        // A point far off every road, heading north-east: still placed, never empty.
        let off = road.reachable_from(
            &Enu2::new(300.0, 400.0),
            Some(Enu2::new(1.0, 1.0)),
            (0.0, 5.0),
        );
        assert!(off.length_m() > 0.0);
    }

    fn rng() -> rand_chacha::ChaCha8Rng {
        rand_chacha::ChaCha8Rng::seed_from_u64(25)
    }

    /// A loop 0 -> 1 -> 2 with a gentle bend at 1 (14 degrees in, 11 out) and a chord 1 -> 5
    /// north, 5 -> 0 back south-west: the geometry of the track jumps BENCHMARKS "Field
    /// scale, part 23" found.
    fn bend_and_chord() -> RoadNetwork {
        network(
            &[
                (0, 0.0, 0.0),
                (1, 400.0, 100.0),
                (2, 900.0, 0.0),
                (5, 400.0, 500.0),
            ],
            &[
                (0, 1, 1.0),
                (1, 2, 0.6),
                (1, 5, 0.4),
                (2, 0, 1.0),
                (5, 0, 1.0),
            ],
        )
    }

    #[test]
    fn a_heading_never_moves_a_point_to_a_far_road() {
        let road = bend_and_chord();
        // Where `drive` places a point with a heading, and its road's direction.
        let place = |x: f64, y: f64, heading: Enu2| {
            road.drive(&Enu2::new(x, y), Some(heading), &[0.0], &mut rng())
                .unwrap()[0]
        };
        // 10 m short of node 5 on 1 -> 5, standing (a car turning in place), its velocity's
        // noise pointing east, along 1 -> 2 390 m away: it stays on 1 -> 5.
        let (p, dir) = place(402.0, 490.0, Enu2::new(1.1, 0.6));
        assert!((p - Enu2::new(400.0, 490.0)).norm() < 1e-6, "{p:?}");
        assert!((dir - Enu2::new(0.0, 1.0)).norm() < 1e-9, "{dir:?}");
        // 58 m past the bend on 1 -> 2 heading east-north-east, closer in direction to 0 -> 1
        // than to 1 -> 2: it stays where it is, not at the bend behind it.
        let (p, _) = place(458.0, 93.0, Enu2::new(12.3, 2.0));
        assert!(
            p.x > 450.0 && (p - Enu2::new(458.0, 93.0)).norm() < 5.0,
            "{p:?}"
        );
        let ahead = road.reachable_from(
            &Enu2::new(458.0, 93.0),
            Some(Enu2::new(12.3, 2.0)),
            (0.0, 4.0),
        );
        assert!(ahead.pieces().all(|((a, _), _)| a.x > 450.0), "{ahead:?}");
        // Where two roads are about as near, the heading still chooses: at node 1, east is
        // 1 -> 2 and north 1 -> 5.
        let (_, east) = place(401.0, 101.0, Enu2::new(1.0, -0.2));
        let (_, north) = place(401.0, 101.0, Enu2::new(0.0, 1.0));
        assert!(east.x > 0.9 && north.y > 0.99, "{east:?} {north:?}");
    }

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

    /// A fork: 0 -> 1 east, then at 1 an even choice of 2 (east, a dead end) or 3 (north,
    /// a dead end).
    fn fork() -> RoadNetwork {
        network(
            &[
                (0, 0.0, 0.0),
                (1, 100.0, 0.0),
                (2, 200.0, 0.0),
                (3, 100.0, 100.0),
            ],
            &[(0, 1, 1.0), (1, 2, 0.5), (1, 3, 0.5)],
        )
    }

    /// A network from `(id, x, y)` nodes and `(from, to, p)` edges, starting at node 0.
    fn network(nodes: &[(u32, f64, f64)], edges: &[(u32, u32, f64)]) -> RoadNetwork {
        RoadNetwork::from_config(&RoadConfig {
            nodes: nodes
                .iter()
                .map(|&(id, x_m, y_m)| NodeConfig { id, x_m, y_m })
                .collect(),
            edges: edges
                .iter()
                .map(|&(from, to, p)| EdgeConfig { from, to, p })
                .collect(),
            start_node: 0,
        })
    }

    #[test]
    fn a_route_is_driven_along_the_allowed_ways_and_takes_each_turn_by_its_probability() {
        let road = fork();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let from = Enu2::new(50.0, 1.0);
        let distances = [0.0, 25.0, 50.0, 80.0, 500.0];
        let mut east = 0;
        let n = 4000;
        for _ in 0..n {
            let route = road
                .drive(&from, Some(Enu2::new(1.0, 0.0)), &distances, &mut rng)
                .unwrap();
            let at: Vec<Enu2> = route.iter().map(|(p, _)| *p).collect();
            assert!((at[0] - Enu2::new(50.0, 0.0)).norm() < 1e-9, "{}", at[0]);
            assert!((at[1] - Enu2::new(75.0, 0.0)).norm() < 1e-9, "{}", at[1]);
            assert!((at[2] - Enu2::new(100.0, 0.0)).norm() < 1e-9, "{}", at[2]);
            assert!((route[1].1 - Enu2::new(1.0, 0.0)).norm() < 1e-9);
            // 30 m past the fork, on one branch or the other, heading along it; then
            // stopped at that branch's dead end.
            if (at[3] - Enu2::new(130.0, 0.0)).norm() < 1e-9 {
                east += 1;
                assert!((at[4] - Enu2::new(200.0, 0.0)).norm() < 1e-9, "{}", at[4]);
            } else {
                assert!((at[3] - Enu2::new(100.0, 30.0)).norm() < 1e-9, "{}", at[3]);
                assert!((route[3].1 - Enu2::new(0.0, 1.0)).norm() < 1e-9);
                assert!((at[4] - Enu2::new(100.0, 100.0)).norm() < 1e-9, "{}", at[4]);
            }
        }
        let share = east as f64 / n as f64;
        assert!((share - 0.5).abs() < 0.03, "{share}");
    }
}
