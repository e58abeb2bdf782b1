//! How much of the traffic each road carries: where a car that drives the road graph's
//! Markov chain is likely to be found when nothing has been seen of it yet.
//!
//! A car that drives the graph (at each node the next edge drawn by its probability) spends,
//! in the long run, a share of its time on edge u->v proportional to pi(u) p(u->v) times the
//! edge's length, where pi is the chain's stationary distribution over the nodes: per metre
//! of road, the edge's traffic flow pi(u) p(u->v). An operator's cue says only "within this
//! radius"; spread by length alone, the prior gave a fork's 0.25 branch as much of the
//! belief per metre as its 0.75 one (random-3: the search flew the 0.25 branch first in
//! 9 runs of 10, the car took the other in 7; BENCHMARKS.md).

use serde::{Deserialize, Serialize};

use super::RoadNode;

/// How a belief is spread over the roads where nothing has been seen of the target
/// (`acquisition.prior`: the prior from an operator's cue and, until the first sighting,
/// the re-spread from the cue's roads).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RoadWeighting {
    /// Each road by its share of the traffic per metre (the graph's turn probabilities in
    /// the long run): where a car driving the graph is likely to be.
    #[default]
    Traffic,
    /// Each road by its length alone (the simpler prior):
    /// for a graph whose turn probabilities are not to be trusted.
    Length,
}

/// The most power iterations of the lazy chain: a drawn or mapped graph is tens to
/// thousands of nodes, and the iteration stops as soon as an iteration moves the
/// distribution by less than [`SETTLED`] (in the L1 norm).
const MAX_ITERATIONS: usize = 10_000;

/// An iteration that moves the stationary distribution by less than this has settled.
const SETTLED: f64 = 1e-13;

/// The traffic per metre of each directed edge, in the order of the nodes and, within a
/// node, of its outgoing edges (the order of `RoadNetwork::segments`), scaled so that the
/// edges' mean is 1. The stationary distribution comes from the lazy chain (stay with
/// probability 1/2), which has the same stationary distribution and converges on periodic
/// graphs too (a ring). A node without an outgoing edge keeps what reaches it. All 1 when
/// the flows vanish (no edges, or probabilities that are all 0).
pub(super) fn traffic_per_m(nodes: &[RoadNode]) -> Vec<f64> {
    let n = nodes.len();
    if n == 0 {
        return Vec::new();
    }
    let out_sum: Vec<f64> = nodes
        .iter()
        .map(|node| node.next.iter().map(|(_, p)| p.max(0.0)).sum())
        .collect();
    let mut pi = vec![1.0 / n as f64; n];
    let mut next = vec![0.0; n];
    for _ in 0..MAX_ITERATIONS {
        next.iter_mut().for_each(|x| *x = 0.0);
        for (u, node) in nodes.iter().enumerate() {
            if out_sum[u] <= 0.0 {
                // A node without a way out keeps what reaches it.
                next[u] += pi[u];
                continue;
            }
            let moving = 0.5 * pi[u];
            next[u] += pi[u] - moving;
            for &(v, p) in &node.next {
                next[v] += moving * p.max(0.0) / out_sum[u];
            }
        }
        let moved: f64 = pi.iter().zip(&next).map(|(a, b)| (a - b).abs()).sum();
        std::mem::swap(&mut pi, &mut next);
        if moved < SETTLED {
            break;
        }
    }
    let flows: Vec<f64> = nodes
        .iter()
        .enumerate()
        .flat_map(|(u, node)| {
            let total = out_sum[u];
            let pi_u = pi[u];
            node.next.iter().map(move |&(_, p)| {
                if total > 0.0 {
                    pi_u * p.max(0.0) / total
                } else {
                    0.0
                }
            })
        })
        .collect();
    let mean = flows.iter().sum::<f64>() / flows.len().max(1) as f64;
    if !(mean.is_finite() && mean > 0.0) {
        return vec![1.0; flows.len()];
    }
    flows.iter().map(|f| f / mean).collect()
}
