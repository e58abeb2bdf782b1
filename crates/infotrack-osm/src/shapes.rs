//! Shapes on the ground in the world's ENU frame about the box's centre: projection,
//! simplification, a band around a road, a polygon cut to the box.

use infotrack_core::geodesy::GeodeticWgs84;

/// Projects `[longitude, latitude]` (degrees, WGS84) to world ENU `[east, north]`, metres.
pub fn enu(origin: &GeodeticWgs84, lonlat: [f64; 2]) -> [f64; 2] {
    let [e, n, _] = origin.enu_of(&GeodeticWgs84 {
        lat_deg: lonlat[1],
        lon_deg: lonlat[0],
        alt_m: origin.alt_m,
    });
    [e, n]
}

/// World ENU `[east, north]` back to `[longitude, latitude]`.
pub fn lonlat(origin: &GeodeticWgs84, enu_m: [f64; 2]) -> [f64; 2] {
    let g = origin.offset_by_enu([enu_m[0], enu_m[1], 0.0]);
    [g.lon_deg, g.lat_deg]
}

/// Distance from `p` to the segment `a`-`b`, m.
fn to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// The indices of `pts` that Douglas-Peucker keeps at `tolerance_m` (the ends always).
pub fn simplified(pts: &[[f64; 2]], tolerance_m: f64) -> Vec<usize> {
    if pts.len() <= 2 {
        return (0..pts.len()).collect();
    }
    let last = pts.len() - 1;
    let mut keep = vec![false; pts.len()];
    (keep[0], keep[last]) = (true, true);
    let mut stack = vec![(0, last)];
    while let Some((a, b)) = stack.pop() {
        let far = (a + 1..b)
            .map(|i| (i, to_segment(pts[i], pts[a], pts[b])))
            .max_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((i, _)) = far.filter(|(_, d)| *d > tolerance_m) {
            keep[i] = true;
            stack.push((a, i));
            stack.push((i, b));
        }
    }
    (0..pts.len()).filter(|i| keep[*i]).collect()
}

/// A closed band `half_width_m` either side of the polyline `pts` (its outline, not
/// closed): the shape of a tunnel over its road.
pub fn band(pts: &[[f64; 2]], half_width_m: f64) -> Vec<[f64; 2]> {
    let normal = |a: [f64; 2], b: [f64; 2]| {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l = dx.hypot(dy).max(1e-9);
        [-dy / l, dx / l]
    };
    let at = |i: usize| {
        let before = if i > 0 {
            normal(pts[i - 1], pts[i])
        } else {
            normal(pts[0], pts[1])
        };
        let after = if i + 1 < pts.len() {
            normal(pts[i], pts[i + 1])
        } else {
            before
        };
        let (nx, ny) = (before[0] + after[0], before[1] + after[1]);
        let l = nx.hypot(ny).max(1e-9);
        [nx / l * half_width_m, ny / l * half_width_m]
    };
    let left = (0..pts.len()).map(|i| [pts[i][0] + at(i)[0], pts[i][1] + at(i)[1]]);
    let right: Vec<[f64; 2]> = (0..pts.len())
        .rev()
        .map(|i| [pts[i][0] - at(i)[0], pts[i][1] - at(i)[1]])
        .collect();
    left.chain(right).collect()
}

/// The polygon `ring` (not closed) cut to the rectangle `[min, max]` (Sutherland-Hodgman).
pub fn clipped(ring: &[[f64; 2]], min: [f64; 2], max: [f64; 2]) -> Vec<[f64; 2]> {
    let mut out = ring.to_vec();
    for (axis, bound, keep_below) in [
        (0, min[0], false),
        (0, max[0], true),
        (1, min[1], false),
        (1, max[1], true),
    ] {
        let inside = |p: &[f64; 2]| {
            if keep_below {
                p[axis] <= bound
            } else {
                p[axis] >= bound
            }
        };
        let input = std::mem::take(&mut out);
        for (i, p) in input.iter().enumerate() {
            let q = input[(i + input.len() - 1) % input.len()];
            let cross = |a: [f64; 2], b: [f64; 2]| {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
            };
            match (inside(p), inside(&q)) {
                (true, true) => out.push(*p),
                (true, false) => out.extend([cross(q, *p), *p]),
                (false, true) => out.push(cross(q, *p)),
                (false, false) => {}
            }
        }
    }
    out
}

/// Whether `p` lies inside the polygon `ring` (even-odd rule).
pub fn inside(ring: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut c = false;
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[(i + ring.len() - 1) % ring.len()]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0]
        {
            c = !c;
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_straight_run_keeps_its_ends_and_a_corner_keeps_the_corner() {
        let straight = [[0.0, 0.0], [10.0, 0.5], [20.0, -0.5], [30.0, 0.0]];
        assert_eq!(simplified(&straight, 2.0), vec![0, 3]);
        let corner = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]];
        assert_eq!(simplified(&corner, 2.0), vec![0, 1, 2]);
    }

    #[test]
    fn a_polygon_cut_to_a_box_stays_inside_it_and_keeps_what_was_inside() {
        let ring = [[-5.0, -5.0], [5.0, -5.0], [5.0, 5.0], [-5.0, 5.0]];
        let cut = clipped(&ring, [0.0, 0.0], [10.0, 10.0]);
        assert!(cut
            .iter()
            .all(|p| (0.0..=10.0).contains(&p[0]) && (0.0..=10.0).contains(&p[1])));
        assert!(inside(&cut, [2.0, 2.0]) && !inside(&cut, [7.0, 7.0]));
        assert!(clipped(&ring, [20.0, 20.0], [30.0, 30.0]).is_empty());
    }

    #[test]
    fn a_band_surrounds_its_road_and_the_projection_goes_both_ways() {
        let road = [[0.0, 0.0], [100.0, 0.0], [100.0, 50.0]];
        let ring = band(&road, 8.0);
        assert!(inside(&ring, [50.0, 0.0]) && inside(&ring, [100.0, 25.0]));
        assert!(!inside(&ring, [50.0, 20.0]));
        let origin = GeodeticWgs84 {
            lat_deg: 60.17,
            lon_deg: 24.94,
            alt_m: 0.0,
        };
        let there = lonlat(&origin, [1234.5, -678.9]);
        // Back on the ellipsoid rather than the tangent plane 0.2 m above it: the same to
        // well under a millimetre.
        let back = enu(&origin, there);
        assert!(
            (back[0] - 1234.5).abs() < 1e-3 && (back[1] + 678.9).abs() < 1e-3,
            "{back:?}"
        );
    }
}
