//! Frames in one place: the world ENU frame the tracker thinks in, the vehicle's local NED
//! frame MAVLink speaks, the body FRD frame attitudes and the camera mount are given in,
//! and the one conversion between ENU and NED. Nothing else in infotrack swaps axes.
//!
//! * world ENU: x east, y north, z up, metres; origin at the vehicle's local origin on the
//!   ground (the tracker works in its horizontal plane, [`Enu2`]);
//! * vehicle local NED: x north, y east, z down, metres, same origin (LOCAL_POSITION_NED,
//!   SET_POSITION_TARGET_LOCAL_NED);
//! * body FRD: x forward, y right, z down, attached to the vehicle;
//! * yaw: ENU yaw is counter-clockwise from east; NED yaw is clockwise from north.

use std::f64::consts::FRAC_PI_2;

use nalgebra::{Rotation3, Vector2};
use serde::{Deserialize, Serialize};

/// A horizontal point or vector in the world ENU frame: x east, y north, metres.
pub type Enu2 = Vector2<f64>;

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

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let mut x = a % std::f64::consts::TAU;
    if x > std::f64::consts::PI {
        x -= std::f64::consts::TAU;
    } else if x <= -std::f64::consts::PI {
        x += std::f64::consts::TAU;
    }
    x
}

/// The vehicle's pose in local NED at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VehiclePoseNed {
    /// Position, m, NED axes about the world's origin (z negative above the ground): the
    /// vehicle's local NED, moved into the world when `[world] origin` places it there.
    pub position_ned_m: [f64; 3],
    /// Roll, rad (body FRD relative to NED, ZYX Euler angles as in MAVLink ATTITUDE).
    pub roll_rad: f64,
    /// Pitch, rad.
    pub pitch_rad: f64,
    /// Yaw, rad, from north toward east.
    pub yaw_rad: f64,
}

impl VehiclePoseNed {
    /// A level pose (no roll or pitch, nose north) above the world ENU point `p` at
    /// `altitude_m`.
    pub fn level_above(p: &Enu2, altitude_m: f64) -> Self {
        let ned = PositionEnu::from_xy(p, altitude_m).to_ned();
        Self {
            position_ned_m: [ned.x_north_m, ned.y_east_m, ned.z_down_m],
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: 0.0,
        }
    }

    /// The position in local NED.
    pub fn position_ned(&self) -> PositionNed {
        let [x, y, z] = self.position_ned_m;
        PositionNed {
            x_north_m: x,
            y_east_m: y,
            z_down_m: z,
        }
    }

    /// The horizontal position, world ENU.
    pub fn position_enu(&self) -> Enu2 {
        self.position_ned().to_enu().xy()
    }

    /// Rotation taking body FRD vectors to local NED.
    pub fn ned_from_body(&self) -> Rotation3<f64> {
        Rotation3::from_euler_angles(self.roll_rad, self.pitch_rad, self.yaw_rad)
    }

    /// Altitude above the ground plane `z_ned = 0`, m.
    pub fn altitude_m(&self) -> f64 {
        -self.position_ned_m[2]
    }
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
    fn a_vehicle_pose_in_ned_is_at_the_same_place_in_enu() {
        // 3 m north, 2 m east, 10 m up: ENU (2, 3).
        let p = VehiclePoseNed {
            position_ned_m: [3.0, 2.0, -10.0],
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: 0.0,
        };
        assert_eq!(p.position_enu(), Enu2::new(2.0, 3.0));
        assert_eq!(p.altitude_m(), 10.0);
        // And back: a level pose above ENU (2, 3) is 3 m north, 2 m east.
        let q = VehiclePoseNed::level_above(&Enu2::new(2.0, 3.0), 10.0);
        assert_eq!(q.position_ned_m, [3.0, 2.0, -10.0]);
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
