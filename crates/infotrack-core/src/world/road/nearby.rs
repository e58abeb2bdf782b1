//! Which road segments lie near a point: an R-tree (`rstar`) over the segments, so that a
//! query costs the segments near the point rather than every segment of the network. The
//! distances themselves are the network's own; the tree only narrows the candidates, so a
//! query answers exactly what a scan of every segment would.

use rstar::primitives::{GeomWithData, Line};
use rstar::{RTree, AABB};

use crate::world::geometry::Enu2;

type Indexed = GeomWithData<Line<[f64; 2]>, usize>;

/// The segments of a network by where they lie.
#[derive(Debug, Clone, Default)]
pub(super) struct SegmentIndex {
    tree: RTree<Indexed>,
}

impl SegmentIndex {
    /// Indexes `segments` (world ENU); a query names a segment by its index there.
    pub(super) fn new(segments: &[(Enu2, Enu2)]) -> Self {
        let items = segments
            .iter()
            .enumerate()
            .map(|(k, (a, b))| GeomWithData::new(Line::new([a.x, a.y], [b.x, b.y]), k))
            .collect();
        Self {
            tree: RTree::bulk_load(items),
        }
    }

    /// The segments whose bounding box comes within `r` of `p` (every segment within `r`
    /// of it, and perhaps a few more), in index order.
    pub(super) fn within(&self, p: &Enu2, r: f64) -> Vec<usize> {
        let square = AABB::from_corners([p.x - r, p.y - r], [p.x + r, p.y + r]);
        let mut found: Vec<usize> = self
            .tree
            .locate_in_envelope_intersecting(&square)
            .map(|g| g.data)
            .collect();
        found.sort_unstable();
        found
    }

    /// Every segment, the nearest to `p` first.
    pub(super) fn nearest_first<'a>(&'a self, p: &Enu2) -> impl Iterator<Item = usize> + 'a {
        self.tree.nearest_neighbor_iter(&[p.x, p.y]).map(|g| g.data)
    }
}

/// A hair more than `d`: the tree's distances and the network's may differ in their last
/// bits, and a query within this of a distance the network computed misses no segment.
pub(super) fn reach(d: f64) -> f64 {
    d * (1.0 + 1e-9) + 1e-9
}
