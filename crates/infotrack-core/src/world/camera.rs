//! The downward camera's footprint on the ground plane, and the view that places and turns
//! it.

use super::geometry::Enu2;

/// The heading of the lab's views and of every view under `guidance.view_heading = "north"`,
/// world ENU yaw (rad): the image's top faces north (NED yaw 0), its width (camera x, body
/// right) along world east. The tracker's model of what the camera sees, the negative
/// information of every missed detection, is true only at the heading the vehicle reports:
/// every frame's [`View`] carries it.
pub const NORTH_VIEW_YAW_ENU_RAD: f64 = std::f64::consts::FRAC_PI_2;

/// Where a frame is seen from: the footprint's centre (the camera's ground point, under the
/// vehicle) and the heading its image faces. A nadir camera mounted straight sees a
/// rectangle whose height lies along the nose and whose width lies to its right (camera x =
/// body right); the vehicle's yaw turns it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// The footprint's centre, world ENU, m.
    pub centre_enu: Enu2,
    /// Which way the image's top faces, world ENU yaw (rad, counter-clockwise from east): the
    /// nose's, for a camera mounted straight.
    pub yaw_enu_rad: f64,
    /// cos and sin of the width axis's angle from east (`yaw - pi/2`), computed once: a
    /// north view's are exactly 1 and 0, so it tests points exactly as the axis-aligned
    /// footprint always did.
    width_axis: (f64, f64),
}

impl View {
    /// A view from `centre_enu` with its image's top facing `yaw_enu_rad` (world ENU).
    pub fn new(centre_enu: Enu2, yaw_enu_rad: f64) -> Self {
        let theta = yaw_enu_rad - NORTH_VIEW_YAW_ENU_RAD;
        Self {
            centre_enu,
            yaw_enu_rad,
            width_axis: (theta.cos(), theta.sin()),
        }
    }

    /// A view from `centre_enu` facing north (the image's width along world east): the lab's.
    pub fn north(centre_enu: Enu2) -> Self {
        Self::new(centre_enu, NORTH_VIEW_YAW_ENU_RAD)
    }

    /// `p` (world ENU) in the view's own axes: along its width (to the image's right) and
    /// along its height (to its top), m from the centre.
    #[inline]
    pub fn to_view_axes(&self, p: &Enu2) -> (f64, f64) {
        let (c, s) = self.width_axis;
        let d = p - self.centre_enu;
        (d.x * c + d.y * s, -d.x * s + d.y * c)
    }

    /// The world ENU point at `(across, up)` in the view's axes (the inverse of
    /// [`Self::to_view_axes`]).
    pub fn from_view_axes(&self, across_m: f64, up_m: f64) -> Enu2 {
        let (c, s) = self.width_axis;
        self.centre_enu + Enu2::new(across_m * c - up_m * s, across_m * s + up_m * c)
    }
}

/// The rectangle a nadir-pointing camera sees on flat ground, centred under the agent; a
/// [`View`] places it and turns it to the vehicle's heading (the paper's agent holds a
/// constant heading: [`View::north`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    /// Half width (across the image, along world x in a north view), metres.
    pub half_width_m: f64,
    /// Half height (up the image, along world y in a north view), metres.
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

    /// Whether ground point `p` (world ENU) is inside the footprint of `view`.
    #[inline]
    pub fn contains(&self, view: &View, p: &Enu2) -> bool {
        self.contains_inset(view, p, 0.0)
    }

    /// Whether ground point `p` (world ENU) is at least `inset_m` inside the footprint of
    /// `view`.
    #[inline]
    pub fn contains_inset(&self, view: &View, p: &Enu2, inset_m: f64) -> bool {
        let (across, up) = view.to_view_axes(p);
        across.abs() <= self.half_width_m - inset_m && up.abs() <= self.half_height_m - inset_m
    }

    /// The four corners, counter-clockwise from the image's bottom left (south-west in a
    /// north view), world ENU.
    pub fn corners(&self, view: &View) -> [Enu2; 4] {
        let (w, h) = (self.half_width_m, self.half_height_m);
        [
            view.from_view_axes(-w, -h),
            view.from_view_axes(w, -h),
            view.from_view_axes(w, h),
            view.from_view_axes(-w, h),
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
        let agent = View::north(Enu2::new(1.0, -1.0));
        assert!(f.contains(&agent, &Enu2::new(1.4, -0.6)));
        assert!(!f.contains(&agent, &Enu2::new(1.5, -1.0)));
        assert!(!f.contains(&View::north(Enu2::zeros()), &Enu2::new(1.4, -0.6)));
        for c in f.corners(&agent) {
            assert!(f.contains(&agent, &c));
        }
    }

    #[test]
    fn a_north_view_tests_points_exactly_as_the_world_axes() {
        let f = Footprint {
            half_width_m: 29.0,
            half_height_m: 15.5,
        };
        let v = View::north(Enu2::new(3.25, -7.5));
        for p in [
            Enu2::new(32.25, -7.5),
            Enu2::new(3.25, 8.0),
            Enu2::new(-25.75, -23.0),
        ] {
            let (across, up) = v.to_view_axes(&p);
            assert_eq!((across, up), (p.x - 3.25, p.y + 7.5));
            assert!(f.contains(&v, &p));
        }
        assert!(!f.contains(&v, &Enu2::new(32.26, -7.5)));
    }

    #[test]
    fn a_turned_view_lays_its_width_across_the_nose() {
        // Nose east (ENU yaw 0): the image's width (body right) lies north-south, its right
        // edge south; the 29 m half width reaches 29 m south, the 15.5 m half height 15.5 m
        // east, and not the other way round.
        let f = Footprint {
            half_width_m: 29.0,
            half_height_m: 15.5,
        };
        let centre = Enu2::new(100.0, 50.0);
        let east = View::new(centre, 0.0);
        assert!(f.contains(&east, &Enu2::new(100.0, 50.0 - 28.0)));
        assert!(f.contains(&east, &Enu2::new(100.0, 50.0 + 28.0)));
        assert!(f.contains(&east, &Enu2::new(100.0 + 15.0, 50.0)));
        assert!(!f.contains(&east, &Enu2::new(100.0 + 20.0, 50.0)));
        let north = View::north(centre);
        assert!(f.contains(&north, &Enu2::new(100.0 + 20.0, 50.0)));
        assert!(!f.contains(&north, &Enu2::new(100.0, 50.0 - 28.0)));
        let (across, up) = east.to_view_axes(&Enu2::new(100.0, 40.0));
        assert!(
            (across - 10.0).abs() < 1e-12 && up.abs() < 1e-12,
            "{across} {up}"
        );
        // Corners round-trip and lie on the rectangle's edges at any heading.
        for yaw in [0.0, 0.4, 2.0, -2.7] {
            let v = View::new(centre, yaw);
            for c in f.corners(&v) {
                let (a, u) = v.to_view_axes(&c);
                assert!((a.abs() - 29.0).abs() < 1e-9 && (u.abs() - 15.5).abs() < 1e-9);
            }
            let p = v.from_view_axes(3.0, -4.0);
            let (a, u) = v.to_view_axes(&p);
            assert!((a - 3.0).abs() < 1e-9 && (u + 4.0).abs() < 1e-9);
        }
    }
}
