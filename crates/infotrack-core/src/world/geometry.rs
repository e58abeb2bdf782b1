//! Planar geometry in the world ENU frame: points, axis-aligned bounds, polygons.

use serde::{Deserialize, Serialize};

pub use crate::frames::{wrap_angle, Enu2};

/// An axis-aligned rectangle in the world ENU frame (metres).
///
/// Used as the workspace: where particles live and the geofence the agent may fly in.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoundsEnu {
    /// Western edge, metres.
    pub x_min_m: f64,
    /// Eastern edge, metres.
    pub x_max_m: f64,
    /// Southern edge, metres.
    pub y_min_m: f64,
    /// Northern edge, metres.
    pub y_max_m: f64,
}

impl BoundsEnu {
    /// Whether `p` lies inside or on the edge.
    pub fn contains(&self, p: &Enu2) -> bool {
        p.x >= self.x_min_m && p.x <= self.x_max_m && p.y >= self.y_min_m && p.y <= self.y_max_m
    }

    /// The closest point of the rectangle to `p` (the geofence clamp).
    pub fn clamp(&self, p: &Enu2) -> Enu2 {
        Enu2::new(
            p.x.clamp(self.x_min_m, self.x_max_m),
            p.y.clamp(self.y_min_m, self.y_max_m),
        )
    }

    /// Width along x, metres.
    pub fn width_m(&self) -> f64 {
        self.x_max_m - self.x_min_m
    }

    /// Height along y, metres.
    pub fn height_m(&self) -> f64 {
        self.y_max_m - self.y_min_m
    }

    /// Area in square metres.
    pub fn area_m2(&self) -> f64 {
        self.width_m() * self.height_m()
    }

    /// Centre point.
    pub fn center(&self) -> Enu2 {
        Enu2::new(
            0.5 * (self.x_min_m + self.x_max_m),
            0.5 * (self.y_min_m + self.y_max_m),
        )
    }
}

/// A simple polygon (no self-intersection) in the world ENU frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PolygonEnu {
    vertices: Vec<Enu2>,
    /// Cached bounding box for a cheap rejection before the crossing test.
    bbox: BoundsEnu,
}

impl PolygonEnu {
    /// Builds a polygon from at least three vertices, in either winding.
    ///
    /// Returns `None` when there are fewer than three vertices or any is not finite.
    pub fn new(vertices: Vec<Enu2>) -> Option<Self> {
        if vertices.len() < 3
            || vertices
                .iter()
                .any(|v| !v.x.is_finite() || !v.y.is_finite())
        {
            return None;
        }
        let mut bbox = BoundsEnu {
            x_min_m: f64::INFINITY,
            x_max_m: f64::NEG_INFINITY,
            y_min_m: f64::INFINITY,
            y_max_m: f64::NEG_INFINITY,
        };
        for v in &vertices {
            bbox.x_min_m = bbox.x_min_m.min(v.x);
            bbox.x_max_m = bbox.x_max_m.max(v.x);
            bbox.y_min_m = bbox.y_min_m.min(v.y);
            bbox.y_max_m = bbox.y_max_m.max(v.y);
        }
        Some(Self { vertices, bbox })
    }

    /// An axis-aligned square of side `side_m` centred at `center`.
    pub fn square(center: Enu2, side_m: f64) -> Self {
        let h = 0.5 * side_m;
        Self::new(vec![
            Enu2::new(center.x - h, center.y - h),
            Enu2::new(center.x + h, center.y - h),
            Enu2::new(center.x + h, center.y + h),
            Enu2::new(center.x - h, center.y + h),
        ])
        .expect("four finite vertices")
    }

    /// The vertices in the order given.
    pub fn vertices(&self) -> &[Enu2] {
        &self.vertices
    }

    /// The axis-aligned bounding box.
    pub fn bbox(&self) -> &BoundsEnu {
        &self.bbox
    }

    /// Point-in-polygon by the even-odd crossing rule; points on the boundary count as inside
    /// only for axis-aligned edges (good enough for occlusion tests, which are measure-zero there).
    pub fn contains(&self, p: &Enu2) -> bool {
        if !self.bbox.contains(p) {
            return false;
        }
        let mut inside = false;
        let n = self.vertices.len();
        let mut j = n - 1;
        for i in 0..n {
            let (vi, vj) = (self.vertices[i], self.vertices[j]);
            if (vi.y > p.y) != (vj.y > p.y) {
                let x_cross = vj.x + (p.y - vj.y) / (vi.y - vj.y) * (vi.x - vj.x);
                if p.x < x_cross {
                    inside = !inside;
                }
            }
            j = i;
        }
        inside
    }

    /// Whether the whole axis-aligned square of half side `half_m` about `center` lies
    /// inside, clear of the boundary: its corners inside, and no edge of the polygon meets
    /// its sides (touching counts as meeting) or has a vertex in it. For a simple polygon
    /// that puts every point of the square inside.
    pub fn contains_square(&self, center: &Enu2, half_m: f64) -> bool {
        let (lo, hi) = (center.add_scalar(-half_m), center.add_scalar(half_m));
        let corners = [lo, Enu2::new(hi.x, lo.y), hi, Enu2::new(lo.x, hi.y)];
        if !corners.iter().all(|c| self.contains(c)) {
            return false;
        }
        let n = self.vertices.len();
        (0..n).all(|i| {
            let (a, b) = (self.vertices[i], self.vertices[(i + 1) % n]);
            let vertex_in = a.x >= lo.x && a.x <= hi.x && a.y >= lo.y && a.y <= hi.y;
            !vertex_in && (0..4).all(|k| !segments_meet(&a, &b, &corners[k], &corners[(k + 1) % 4]))
        })
    }

    /// Whether `p` is inside or within `margin_m` of the boundary: the polygon grown by
    /// `margin_m` (an occlusion that may cover part of a tag centred at `p`).
    pub fn contains_or_near(&self, p: &Enu2, margin_m: f64) -> bool {
        let b = &self.bbox;
        if p.x < b.x_min_m - margin_m
            || p.x > b.x_max_m + margin_m
            || p.y < b.y_min_m - margin_m
            || p.y > b.y_max_m + margin_m
        {
            return false;
        }
        if self.contains(p) {
            return true;
        }
        if margin_m <= 0.0 {
            // Exactly `contains` (the analytic sensor's worlds, on every particle).
            return false;
        }
        let n = self.vertices.len();
        (0..n).any(|i| {
            let (a, c) = (self.vertices[i], self.vertices[(i + 1) % n]);
            let ab = c - a;
            let t = ((p - a).dot(&ab) / ab.norm_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
            (p - (a + ab * t)).norm() <= margin_m
        })
    }

    /// Signed-area magnitude in square metres (shoelace formula).
    pub fn area_m2(&self) -> f64 {
        let n = self.vertices.len();
        let mut s = 0.0;
        for i in 0..n {
            let a = self.vertices[i];
            let b = self.vertices[(i + 1) % n];
            s += a.x * b.y - b.x * a.y;
        }
        0.5 * s.abs()
    }
}

/// Whether segments `ab` and `cd` share a point (touching and collinear overlap count).
fn segments_meet(a: &Enu2, b: &Enu2, c: &Enu2, d: &Enu2) -> bool {
    let cross =
        |o: &Enu2, p: &Enu2, q: &Enu2| (p.x - o.x) * (q.y - o.y) - (p.y - o.y) * (q.x - o.x);
    // q on segment op, given that the three are collinear.
    let on = |o: &Enu2, p: &Enu2, q: &Enu2| {
        q.x >= o.x.min(p.x) && q.x <= o.x.max(p.x) && q.y >= o.y.min(p.y) && q.y <= o.y.max(p.y)
    };
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    let apart = |u: f64, v: f64| (u > 0.0 && v < 0.0) || (u < 0.0 && v > 0.0);
    (apart(d1, d2) && apart(d3, d4))
        || (d1 == 0.0 && on(c, d, a))
        || (d2 == 0.0 && on(c, d, b))
        || (d3 == 0.0 && on(a, b, c))
        || (d4 == 0.0 && on(a, b, d))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contains_or_near_grows_the_polygon_by_the_margin() {
        let sq = PolygonEnu::square(Enu2::new(1.0, 2.0), 2.0);
        assert!(sq.contains_or_near(&Enu2::new(1.0, 2.0), 0.1));
        assert!(sq.contains_or_near(&Enu2::new(2.05, 2.0), 0.1));
        assert!(!sq.contains_or_near(&Enu2::new(2.15, 2.0), 0.1));
        // Off a corner the grown polygon is round: 0.08 m along both axes is 0.113 m away.
        assert!(!sq.contains_or_near(&Enu2::new(2.08, 3.08), 0.1));
        assert!(sq.contains_or_near(&Enu2::new(2.06, 3.06), 0.1));
        assert!(!sq.contains_or_near(&Enu2::new(2.05, 2.0), 0.0));
    }

    fn lab() -> BoundsEnu {
        BoundsEnu {
            x_min_m: -3.0,
            x_max_m: 1.0,
            y_min_m: -1.2,
            y_max_m: 2.0,
        }
    }

    #[test]
    fn geofence_clamp_moves_outside_points_to_the_edge_and_keeps_inside_points() {
        let b = lab();
        assert_eq!(b.clamp(&Enu2::new(5.0, 5.0)), Enu2::new(1.0, 2.0));
        assert_eq!(b.clamp(&Enu2::new(-9.0, -0.5)), Enu2::new(-3.0, -0.5));
        let inside = Enu2::new(0.2, 0.3);
        assert_eq!(b.clamp(&inside), inside);
        assert!(b.contains(&b.clamp(&Enu2::new(-100.0, 100.0))));
    }

    #[test]
    fn square_contains_its_centre_and_not_points_beyond_its_half_side() {
        let sq = PolygonEnu::square(Enu2::new(-1.25, -0.6), 1.0);
        assert!(sq.contains(&Enu2::new(-1.25, -0.6)));
        assert!(sq.contains(&Enu2::new(-0.80, -0.15)));
        assert!(!sq.contains(&Enu2::new(-0.70, -0.6)));
        assert!(!sq.contains(&Enu2::new(-1.25, 0.0)));
        assert!((sq.area_m2() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn concave_polygon_excludes_its_notch() {
        // An L shape: the notch at (1.5, 1.5) is outside.
        let l = PolygonEnu::new(vec![
            Enu2::new(0.0, 0.0),
            Enu2::new(2.0, 0.0),
            Enu2::new(2.0, 1.0),
            Enu2::new(1.0, 1.0),
            Enu2::new(1.0, 2.0),
            Enu2::new(0.0, 2.0),
        ])
        .unwrap();
        assert!(l.contains(&Enu2::new(0.5, 1.5)));
        assert!(l.contains(&Enu2::new(1.5, 0.5)));
        assert!(!l.contains(&Enu2::new(1.5, 1.5)));
        assert!((l.area_m2() - 3.0).abs() < 1e-12);
    }

    /// A square well inside an L is inside; one over the L's inner corner, one poking out
    /// of a side, one touching the boundary and one around a notch are not.
    #[test]
    fn a_square_inside_a_polygon_is_clear_of_its_boundary() {
        let l = PolygonEnu::new(vec![
            Enu2::new(0.0, 0.0),
            Enu2::new(4.0, 0.0),
            Enu2::new(4.0, 2.0),
            Enu2::new(2.0, 2.0),
            Enu2::new(2.0, 4.0),
            Enu2::new(0.0, 4.0),
        ])
        .unwrap();
        assert!(l.contains_square(&Enu2::new(1.0, 1.0), 0.5));
        assert!(l.contains_square(&Enu2::new(3.0, 1.0), 0.9));
        // Over the L's inner corner (2, 2): three corners inside, one out.
        assert!(!l.contains_square(&Enu2::new(1.9, 1.9), 0.6));
        assert!(!l.contains_square(&Enu2::new(3.8, 1.0), 0.5));
        assert!(!l.contains_square(&Enu2::new(1.0, 1.0), 1.0));
        // A notch whose tip is inside the square while the square's corners are not cut off.
        let notched = PolygonEnu::new(vec![
            Enu2::new(0.0, 0.0),
            Enu2::new(4.0, 0.0),
            Enu2::new(4.0, 4.0),
            Enu2::new(2.1, 4.0),
            Enu2::new(2.0, 2.2),
            Enu2::new(1.9, 4.0),
            Enu2::new(0.0, 4.0),
        ])
        .unwrap();
        assert!(!notched.contains_square(&Enu2::new(2.0, 2.0), 0.5));
        assert!(notched.contains_square(&Enu2::new(2.0, 1.0), 0.5));
    }

    #[test]
    fn polygon_needs_three_finite_vertices() {
        assert!(PolygonEnu::new(vec![Enu2::zeros(), Enu2::new(1.0, 0.0)]).is_none());
        assert!(PolygonEnu::new(vec![
            Enu2::zeros(),
            Enu2::new(f64::NAN, 0.0),
            Enu2::new(0.0, 1.0)
        ])
        .is_none());
    }

    #[test]
    fn wrap_angle_stays_in_range() {
        for k in -20..20 {
            let a = 0.3 + k as f64 * std::f64::consts::TAU;
            assert!((wrap_angle(a) - 0.3).abs() < 1e-9);
        }
        assert!((wrap_angle(std::f64::consts::PI * 3.0) - std::f64::consts::PI).abs() < 1e-9);
    }
}
