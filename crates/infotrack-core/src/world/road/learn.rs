//! Turn probabilities learned from recorded tracks of the area: each track is matched to
//! the road graph, the turns it takes at each node are counted, and the counts update the
//! map's own probabilities (a Dirichlet prior whose mean is the map's turn probabilities
//! and whose weight is a number of pseudo-turns).
//!
//! The matching is deliberately simple and says so: a moving sample is put on the nearest
//! edge that goes its way ([`RoadNetwork::nearest_edge`]); only samples well inside an edge
//! count (near a node the edges that meet there are equally near, and a car cutting a
//! corner is matched to the wrong one); consecutive edges are joined by the shortest
//! directed path between them, within a few edges (a short edge passed between two samples);
//! a sample off every road, or edges that cannot be joined, end a stretch. A turn is counted
//! only where the car was seen to arrive at the node along an edge, so the node where a
//! stretch starts contributes nothing.

use std::collections::VecDeque;

use super::{distance_to_segment, RoadNetwork};
use crate::world::geometry::Enu2;

/// Slower than this, a sample's heading is noise: standing samples are not matched, m/s.
const MOVING_MPS: f64 = 1.0;

/// A sample counts as inside its edge when its projection lies at least this far from both
/// ends, m (or a quarter of a shorter edge's length).
const INSIDE_EDGE_M: f64 = 8.0;

/// Edges farther apart than this many edges are not joined (the car was lost between
/// them, not passing a short edge).
const MAX_JOIN_EDGES: usize = 6;

/// What matching recorded tracks to the road graph found.
#[derive(Debug, Clone, PartialEq)]
pub struct TurnCounts {
    /// Per node, per exit (in the order of [`super::RoadNode::next`]): how often a car
    /// arriving at the node left by that exit.
    pub counts: Vec<Vec<u32>>,
    /// Moving samples put on an edge.
    pub matched_samples: usize,
    /// Moving samples farther than the allowed distance from every road.
    pub off_road_samples: usize,
    /// Stretches ended because consecutive edges could not be joined.
    pub breaks: usize,
    /// Turns back along the edge the car arrived on (a U-turn), among the turns counted.
    pub turn_backs: usize,
}

impl TurnCounts {
    /// Turns counted in all.
    pub fn turns(&self) -> u64 {
        self.counts.iter().flatten().map(|&c| u64::from(c)).sum()
    }

    /// Nodes at which at least one turn was counted.
    pub fn nodes_seen(&self) -> usize {
        self.counts
            .iter()
            .filter(|c| c.iter().any(|&n| n > 0))
            .count()
    }
}

impl RoadNetwork {
    /// The node sequences that `samples` (time s, position world ENU) drove, one per
    /// unbroken stretch; samples farther than `max_off_road_m` from the edge they are put on
    /// break a stretch.
    pub fn match_track(
        &self,
        samples: &[(f64, Enu2)],
        max_off_road_m: f64,
        counts: &mut TurnCounts,
    ) -> Vec<Vec<usize>> {
        let mut stretches: Vec<Vec<usize>> = Vec::new();
        let mut current: Vec<usize> = Vec::new();
        for k in 0..samples.len() {
            let Some(heading) = moving_heading(samples, k) else {
                continue;
            };
            let p = samples[k].1;
            let Some((u, v, s)) = self.nearest_edge(&p, Some(heading)) else {
                return stretches;
            };
            let (a, b) = (self.nodes[u].position_enu, self.nodes[v].position_enu);
            if distance_to_segment(&p, &a, &b) > max_off_road_m {
                counts.off_road_samples += 1;
                finish(&mut stretches, &mut current);
                continue;
            }
            counts.matched_samples += 1;
            let len = (b - a).norm();
            let margin = INSIDE_EDGE_M.min(len / 4.0);
            if s < margin || len - s < margin {
                continue;
            }
            if !self.extend(&mut current, u, v) {
                counts.breaks += 1;
                finish(&mut stretches, &mut current);
                current = vec![u, v];
            }
        }
        finish(&mut stretches, &mut current);
        stretches
    }

    /// Appends edge u->v to a node sequence: nothing when it is the sequence's last edge,
    /// the edge itself when it leaves the last node, else the shortest directed path to it.
    /// False when it cannot be joined within [`MAX_JOIN_EDGES`].
    fn extend(&self, seq: &mut Vec<usize>, u: usize, v: usize) -> bool {
        let n = seq.len();
        if n == 0 {
            seq.extend([u, v]);
            return true;
        }
        // The last edge again, or the one before it (a sample near a bend or a junction
        // matched back): nothing new was driven.
        let was = |k: usize| n > k && seq[n - 1 - k] == u && seq[n - k] == v;
        if was(1) || was(2) {
            return true;
        }
        if seq[n - 1] == u {
            seq.push(v);
            return true;
        }
        match self.directed_path(seq[n - 1], u) {
            Some(path) => {
                seq.extend(path.into_iter().skip(1));
                seq.push(v);
                true
            }
            None => false,
        }
    }

    /// The fewest-edges directed path from `from` to `to` (both included), if it takes at
    /// most [`MAX_JOIN_EDGES`] edges.
    fn directed_path(&self, from: usize, to: usize) -> Option<Vec<usize>> {
        let mut came_from = vec![usize::MAX; self.nodes.len()];
        let mut depth = vec![0usize; self.nodes.len()];
        let mut queue = VecDeque::from([from]);
        came_from[from] = from;
        while let Some(x) = queue.pop_front() {
            if x == to {
                let mut path = vec![to];
                while *path.last()? != from {
                    path.push(came_from[*path.last()?]);
                }
                path.reverse();
                return Some(path);
            }
            if depth[x] == MAX_JOIN_EDGES {
                continue;
            }
            for &(y, _) in &self.nodes[x].next {
                if came_from[y] == usize::MAX {
                    came_from[y] = x;
                    depth[y] = depth[x] + 1;
                    queue.push_back(y);
                }
            }
        }
        None
    }

    /// Counts the turns of `tracks` (each a list of (time s, position world ENU)) and
    /// returns them with the node sequences they were counted from.
    pub fn count_turns(
        &self,
        tracks: &[Vec<(f64, Enu2)>],
        max_off_road_m: f64,
    ) -> (TurnCounts, Vec<Vec<usize>>) {
        let mut counts = TurnCounts {
            counts: self.nodes.iter().map(|n| vec![0; n.next.len()]).collect(),
            matched_samples: 0,
            off_road_samples: 0,
            breaks: 0,
            turn_backs: 0,
        };
        let mut sequences = Vec::new();
        for track in tracks {
            for seq in self.match_track(track, max_off_road_m, &mut counts) {
                for w in seq.windows(2).skip(1) {
                    let exits = &self.nodes[w[0]].next;
                    if let Some(j) = exits.iter().position(|&(to, _)| to == w[1]) {
                        counts.counts[w[0]][j] += 1;
                    }
                }
                counts.turn_backs += seq.windows(3).filter(|w| w[0] == w[2]).count();
                sequences.push(seq);
            }
        }
        (counts, sequences)
    }

    /// Each node's exits' probabilities after `counts`: (count + a x map's p) / (n + a),
    /// where `pseudo_turns` is a: nodes without counts keep the map's probabilities, and an
    /// exit never seen keeps a share of its own (a few tracks are not all the traffic).
    pub fn learned_probabilities(&self, counts: &TurnCounts, pseudo_turns: f64) -> Vec<Vec<f64>> {
        self.nodes
            .iter()
            .zip(&counts.counts)
            .map(|(node, seen)| {
                let n: f64 = seen.iter().map(|&c| f64::from(c)).sum();
                node.next
                    .iter()
                    .zip(seen)
                    .map(|(&(_, p), &c)| (f64::from(c) + pseudo_turns * p) / (n + pseudo_turns))
                    .collect()
            })
            .collect()
    }
}

/// The unit heading of sample `k`, from its neighbours, if the car moved faster than
/// [`MOVING_MPS`] there.
fn moving_heading(samples: &[(f64, Enu2)], k: usize) -> Option<Enu2> {
    let before = samples[k.saturating_sub(1)];
    let after = samples[(k + 1).min(samples.len() - 1)];
    let dt = after.0 - before.0;
    let d = after.1 - before.1;
    (dt > 0.0 && d.norm() / dt > MOVING_MPS).then(|| d / d.norm())
}

/// Ends the current stretch, keeping it if it holds at least one edge.
fn finish(stretches: &mut Vec<Vec<usize>>, current: &mut Vec<usize>) {
    if current.len() >= 2 {
        stretches.push(std::mem::take(current));
    } else {
        current.clear();
    }
}
