//! The downward camera's footprint on the ground plane.

use super::geometry::Enu2;

/// The heading the footprint is drawn for, NED yaw (rad, from north toward east): the nose
/// north. The nadir camera's image width (camera x, body right) then lies along world east
/// (the footprint's `half_width_m`) and its height along world north. A vehicle must hold
/// this heading (its camera turned by the mount's yaw accounted for) for the tracker's model
/// of what the camera sees, the negative information of every missed detection, to be true.
pub const FOOTPRINT_YAW_NED_RAD: f64 = 0.0;

/// The rectangle a nadir-pointing camera sees on flat ground, centred under the agent and
/// aligned with the world axes (the agent holds a constant heading, as in the paper:
/// [`FOOTPRINT_YAW_NED_RAD`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    /// Half width along world x, metres.
    pub half_width_m: f64,
    /// Half height along world y, metres.
    pub half_height_m: f64,
}

impl Footprint {
    /// Footprint of a pinhole camera at `altitude_m` with full fields of view in radians.
    pub fn from_fov(altitude_m: f64, fov_x_rad: f64, fov_y_rad: f64) -> Self {
        Self {
            half_width_m: altitude_m * (0.5 * fov_x_rad).tan(),
            half_height_m: altitude_m * (0.5 * fov_y_rad).tan(),
        }
    }

    /// A quarter of the footprint's smaller side, m: how far from a point the camera can be
    /// and still hold it comfortably in view (a belief this concentrated fits in one view; a
    /// point this near a road is seen by a camera looking at the road).
    pub fn quarter_view_m(&self) -> f64 {
        0.5 * self.half_width_m.min(self.half_height_m)
    }

    /// Whether ground point `p` is inside the footprint of an agent at `agent` (both world ENU).
    #[inline]
    pub fn contains(&self, agent: &Enu2, p: &Enu2) -> bool {
        (p.x - agent.x).abs() <= self.half_width_m && (p.y - agent.y).abs() <= self.half_height_m
    }

    /// Whether ground point `p` is at least `inset_m` inside the footprint of an agent at
    /// `agent` (both world ENU).
    #[inline]
    pub fn contains_inset(&self, agent: &Enu2, p: &Enu2, inset_m: f64) -> bool {
        (p.x - agent.x).abs() <= self.half_width_m - inset_m
            && (p.y - agent.y).abs() <= self.half_height_m - inset_m
    }

    /// The four corners, counter-clockwise from south-west, world ENU.
    pub fn corners(&self, agent: &Enu2) -> [Enu2; 4] {
        let (w, h) = (self.half_width_m, self.half_height_m);
        [
            Enu2::new(agent.x - w, agent.y - h),
            Enu2::new(agent.x + w, agent.y - h),
            Enu2::new(agent.x + w, agent.y + h),
            Enu2::new(agent.x - w, agent.y + h),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn footprint_grows_linearly_with_altitude() {
        let a = Footprint::from_fov(1.0, 1.0, 0.5);
        let b = Footprint::from_fov(3.0, 1.0, 0.5);
        assert!((b.half_width_m - 3.0 * a.half_width_m).abs() < 1e-12);
        assert!((a.half_width_m - (0.5f64).tan()).abs() < 1e-12);
    }

    #[test]
    fn contains_is_relative_to_the_agent() {
        let f = Footprint {
            half_width_m: 0.42,
            half_height_m: 0.42,
        };
        let agent = Enu2::new(1.0, -1.0);
        assert!(f.contains(&agent, &Enu2::new(1.4, -0.6)));
        assert!(!f.contains(&agent, &Enu2::new(1.5, -1.0)));
        assert!(!f.contains(&Enu2::zeros(), &Enu2::new(1.4, -0.6)));
        for c in f.corners(&agent) {
            assert!(f.contains(&agent, &c));
        }
    }
}
