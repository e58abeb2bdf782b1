//! The LAWN baseline's boustrophedon (lawnmower) sweep: vertical legs joined by
//! semicircles, traversed one point per guidance step, back and forth.

use crate::world::geometry::Enu2;
use serde::{Deserialize, Serialize};

/// The lawnmower (boustrophedon) sweep of the LAWN baseline.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LawnConfig {
    /// x of each vertical leg, metres, in sweep order.
    pub legs_x_m: Vec<f64>,
    /// Southern end of the legs, metres.
    pub y_min_m: f64,
    /// Northern end of the legs, metres.
    pub y_max_m: f64,
    /// Distance between consecutive sweep points, metres.
    pub point_spacing_m: f64,
    /// A measurement younger than this is tracked instead of sweeping, seconds.
    pub track_measurement_for_s: f64,
}

/// The sweep path and where along it the agent is.
#[derive(Debug, Clone)]
pub struct LawnmowerPath {
    points: Vec<Enu2>,
    index: usize,
    forward: bool,
}

impl LawnmowerPath {
    /// Builds the path: leg 0 northward, leg 1 southward, ..., each pair of legs joined by a
    /// semicircle beyond the end they share.
    pub fn new(c: &LawnConfig) -> Self {
        let mut points = Vec::new();
        let spacing = c.point_spacing_m;
        let leg_len = c.y_max_m - c.y_min_m;
        let n_leg = (leg_len / spacing).floor() as usize;
        for (i, &x) in c.legs_x_m.iter().enumerate() {
            let north = i % 2 == 0;
            for k in 0..=n_leg {
                let d = k as f64 * spacing;
                let y = if north { c.y_min_m + d } else { c.y_max_m - d };
                points.push(Enu2::new(x, y));
            }
            if let Some(&x_next) = c.legs_x_m.get(i + 1) {
                let y_end = if north { c.y_max_m } else { c.y_min_m };
                let r = 0.5 * (x_next - x).abs();
                let cx = 0.5 * (x + x_next);
                let arc_len = std::f64::consts::PI * r;
                let n_arc = (arc_len / spacing).round().max(1.0) as usize;
                // From the end of this leg, over the top (or under the bottom), to the next.
                for k in 1..n_arc {
                    let t = k as f64 / n_arc as f64;
                    let ang = std::f64::consts::PI * (1.0 - t);
                    let dx = r * ang.cos() * (x_next - x).signum();
                    let dy = r * ang.sin() * if north { 1.0 } else { -1.0 };
                    points.push(Enu2::new(cx + dx, y_end + dy));
                }
            }
        }
        Self {
            points,
            index: 0,
            forward: true,
        }
    }

    /// All points of the path, world ENU.
    pub fn points(&self) -> &[Enu2] {
        &self.points
    }

    /// The current point, then advances one point (turning round at either end).
    pub fn next_point(&mut self) -> Enu2 {
        let p = self.points[self.index];
        if self.points.len() > 1 {
            if self.forward && self.index + 1 == self.points.len() {
                self.forward = false;
            } else if !self.forward && self.index == 0 {
                self.forward = true;
            }
            if self.forward {
                self.index += 1;
            } else {
                self.index -= 1;
            }
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Config;

    #[test]
    fn path_has_the_papers_legs_and_spacing() {
        let c = Config::default_lab();
        let path = LawnmowerPath::new(&c.guidance.lawn);
        let pts = path.points();
        // Leg 0: x = -1.4 from y = -0.55 to 1.25 every 0.2 m (10 points).
        assert_eq!(pts[0], Enu2::new(-1.4, -0.55));
        assert!((pts[9] - Enu2::new(-1.4, 1.25)).norm() < 1e-12);
        // Consecutive points are about one spacing apart, on legs and arcs alike.
        for w in pts.windows(2) {
            let d = (w[1] - w[0]).norm();
            assert!(d > 0.1 && d < 0.3, "{d}");
        }
        // The arc after leg 0 rises above y_max.
        assert!(pts[10].y > 1.25);
        let last = *pts.last().unwrap();
        assert!((last - Enu2::new(0.85, -0.55)).norm() < 1e-12, "{last}");
    }

    #[test]
    fn sweep_goes_back_and_forth() {
        let c = Config::default_lab();
        let mut path = LawnmowerPath::new(&c.guidance.lawn);
        let n = path.points().len();
        let first = path.next_point();
        for _ in 1..n {
            path.next_point();
        }
        // After the last point it comes back the way it went.
        let back = path.next_point();
        assert_eq!(back, path.points()[n - 2]);
        for _ in 0..(n - 3) {
            path.next_point();
        }
        assert_eq!(path.next_point(), first);
    }
}
