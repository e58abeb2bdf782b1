//! The road graph of an extract: each drivable way cut to the box, split at junctions, kept
//! to its largest strongly connected part (a car can drive from any kept junction to any
//! other and back).

use std::collections::{HashMap, HashSet};

use petgraph::algo::kosaraju_scc;
use petgraph::graph::{DiGraph, NodeIndex};

use crate::read::Way;
use crate::roads::Direction;
use crate::Bbox;

/// A road between two junctions (or a junction and a dead end).
#[derive(Debug, Clone, PartialEq)]
pub struct RoadEdge {
    /// Its OSM nodes, junction to junction.
    pub nodes: Vec<i64>,
    /// Which way a car drives it.
    pub direction: Direction,
    /// The OSM way it is part of.
    pub way: i64,
    /// Its `highway` class.
    pub class: String,
    /// Under a tunnel or a cover.
    pub covered: bool,
}

/// A drivable way, its direction and whether it is covered.
pub struct Drivable<'a> {
    /// The way.
    pub way: &'a Way,
    /// Which way a car drives it.
    pub direction: Direction,
    /// Under a tunnel or a cover.
    pub covered: bool,
}

/// The runs of consecutive nodes of `refs` that lie inside the box.
fn inside_runs(refs: &[i64], nodes: &HashMap<i64, [f64; 2]>, bbox: &Bbox) -> Vec<Vec<i64>> {
    let mut runs = vec![Vec::new()];
    for r in refs {
        if nodes.get(r).is_some_and(|p| bbox.contains(p[0], p[1])) {
            runs.last_mut().expect("one run").push(*r);
        } else if !runs.last().expect("one run").is_empty() {
            runs.push(Vec::new());
        }
    }
    runs.into_iter().filter(|r| r.len() >= 2).collect()
}

/// The roads of `ways` inside the box, split where they meet: a node used by two roads (or
/// twice by one), and every road's ends, is a junction.
pub fn edges_of(ways: &[Drivable], nodes: &HashMap<i64, [f64; 2]>, bbox: &Bbox) -> Vec<RoadEdge> {
    let pieces: Vec<(usize, Vec<i64>)> = ways
        .iter()
        .enumerate()
        .flat_map(|(i, d)| {
            inside_runs(&d.way.refs, nodes, bbox)
                .into_iter()
                .map(move |r| (i, r))
        })
        .collect();
    let mut uses: HashMap<i64, u32> = HashMap::new();
    for (_, p) in &pieces {
        for n in p {
            *uses.entry(*n).or_default() += 1;
        }
        // Ends are junctions whatever meets them.
        *uses.entry(p[0]).or_default() += 1;
        *uses.entry(*p.last().expect("two nodes")).or_default() += 1;
    }
    let mut edges = Vec::new();
    for (i, p) in pieces {
        let d = &ways[i];
        let mut current = vec![p[0]];
        for n in &p[1..] {
            current.push(*n);
            if uses[n] >= 2 {
                edges.push(RoadEdge {
                    nodes: std::mem::replace(&mut current, vec![*n]),
                    direction: d.direction,
                    way: d.way.id,
                    class: d.way.tag("highway").unwrap_or("").to_string(),
                    covered: d.covered,
                });
            }
        }
    }
    edges
}

/// The arcs a car can drive on `e`, as (from junction, to junction).
fn arcs(e: &RoadEdge) -> Vec<(i64, i64)> {
    let (a, b) = (e.nodes[0], *e.nodes.last().expect("two nodes"));
    match e.direction {
        Direction::Forward => vec![(a, b)],
        Direction::Backward => vec![(b, a)],
        Direction::Both => vec![(a, b), (b, a)],
    }
}

/// The junctions of the largest strongly connected part of the graph `edges` draw.
pub fn largest_strongly_connected(edges: &[RoadEdge]) -> HashSet<i64> {
    let mut g: DiGraph<i64, ()> = DiGraph::new();
    let mut index: HashMap<i64, NodeIndex> = HashMap::new();
    let mut node =
        |g: &mut DiGraph<i64, ()>, id: i64| *index.entry(id).or_insert_with(|| g.add_node(id));
    for e in edges {
        for (a, b) in arcs(e) {
            let (ia, ib) = (node(&mut g, a), node(&mut g, b));
            if ia != ib {
                g.add_edge(ia, ib, ());
            }
        }
    }
    kosaraju_scc(&g)
        .into_iter()
        .max_by_key(Vec::len)
        .unwrap_or_default()
        .into_iter()
        .map(|i| g[i])
        .collect()
}

/// `edges` with both ends in `kept`, and the ones dropped.
pub fn keep_within(edges: Vec<RoadEdge>, kept: &HashSet<i64>) -> (Vec<RoadEdge>, Vec<RoadEdge>) {
    edges.into_iter().partition(|e| {
        kept.contains(&e.nodes[0]) && kept.contains(e.nodes.last().expect("two nodes"))
    })
}
