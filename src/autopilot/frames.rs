//! The one place where the world frame meets MAVLink's local frame.
//!
//! World: ENU (x east, y north, z up), metres, origin at the vehicle's local origin.
//! MAVLink local: NED (x north, y east, z down), metres, same origin.
//! Yaw: ENU yaw is counter-clockwise from east; NED yaw is clockwise from north.

use std::f64::consts::FRAC_PI_2;

use crate::world::geometry::{wrap_angle, Enu2};

/// A position in the world ENU frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionEnu {
    /// East, m.
    pub x_east_m: f64,
    /// North, m.
    pub y_north_m: f64,
    /// Up, m.
    pub z_up_m: f64,
}

/// A position in MAVLink's local NED frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionNed {
    /// North, m.
    pub x_north_m: f64,
    /// East, m.
    pub y_east_m: f64,
    /// Down, m.
    pub z_down_m: f64,
}

impl PositionEnu {
    /// A ground-plane point at altitude `z_up_m`.
    pub fn from_xy(p: &Enu2, z_up_m: f64) -> Self {
        Self {
            x_east_m: p.x,
            y_north_m: p.y,
            z_up_m,
        }
    }

    /// The horizontal part.
    pub fn xy(&self) -> Enu2 {
        Enu2::new(self.x_east_m, self.y_north_m)
    }

    /// The same point in MAVLink local NED.
    pub fn to_ned(&self) -> PositionNed {
        PositionNed {
            x_north_m: self.y_north_m,
            y_east_m: self.x_east_m,
            z_down_m: -self.z_up_m,
        }
    }
}

impl PositionNed {
    /// The same point in the world ENU frame.
    pub fn to_enu(&self) -> PositionEnu {
        PositionEnu {
            x_east_m: self.y_east_m,
            y_north_m: self.x_north_m,
            z_up_m: -self.z_down_m,
        }
    }
}

/// ENU yaw (counter-clockwise from east) to NED yaw (clockwise from north), radians in (-pi, pi].
pub fn yaw_enu_to_ned(yaw_enu_rad: f64) -> f64 {
    wrap_angle(FRAC_PI_2 - yaw_enu_rad)
}

/// NED yaw to ENU yaw, radians in (-pi, pi].
pub fn yaw_ned_to_enu(yaw_ned_rad: f64) -> f64 {
    wrap_angle(FRAC_PI_2 - yaw_ned_rad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn east_north_up_maps_to_ned_axes() {
        let east = PositionEnu {
            x_east_m: 3.0,
            y_north_m: 0.0,
            z_up_m: 0.0,
        }
        .to_ned();
        assert_eq!(
            (east.x_north_m, east.y_east_m, east.z_down_m),
            (0.0, 3.0, -0.0)
        );
        let north = PositionEnu {
            x_east_m: 0.0,
            y_north_m: 2.0,
            z_up_m: 0.0,
        }
        .to_ned();
        assert_eq!((north.x_north_m, north.y_east_m), (2.0, 0.0));
        let up = PositionEnu {
            x_east_m: 0.0,
            y_north_m: 0.0,
            z_up_m: 1.2,
        }
        .to_ned();
        assert_eq!(up.z_down_m, -1.2);
    }

    #[test]
    fn positions_round_trip_both_ways() {
        for (x, y, z) in [(1.5, -2.0, 30.0), (-0.3, 0.7, 1.2), (0.0, 0.0, 0.0)] {
            let p = PositionEnu {
                x_east_m: x,
                y_north_m: y,
                z_up_m: z,
            };
            assert_eq!(p.to_ned().to_enu(), p);
            let n = PositionNed {
                x_north_m: x,
                y_east_m: y,
                z_down_m: -z,
            };
            assert_eq!(n.to_enu().to_ned(), n);
        }
    }

    #[test]
    fn yaw_conventions() {
        use std::f64::consts::PI;
        // Facing east: ENU 0, NED pi/2. Facing north: ENU pi/2, NED 0.
        assert!((yaw_enu_to_ned(0.0) - PI / 2.0).abs() < 1e-12);
        assert!(yaw_enu_to_ned(PI / 2.0).abs() < 1e-12);
        // Facing west: ENU pi, NED -pi/2.
        assert!((yaw_enu_to_ned(PI) + PI / 2.0).abs() < 1e-12);
        for k in -8..8 {
            let a = 0.37 * k as f64;
            assert!((wrap_angle(yaw_ned_to_enu(yaw_enu_to_ned(a)) - a)).abs() < 1e-12);
        }
    }
}
