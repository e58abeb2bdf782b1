//! WGS84 latitude/longitude/height and a local world-ENU frame around a geodetic origin,
//! through the `map_3d` crate (exact: via Earth-centred coordinates, no flat-Earth
//! approximation). Angles in degrees at this interface, heights in metres above the WGS84
//! ellipsoid.

use map_3d::Ellipsoid;
use serde::{Deserialize, Serialize};

/// A point in WGS84.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeodeticWgs84 {
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Height above the WGS84 ellipsoid, m.
    pub alt_m: f64,
}

impl GeodeticWgs84 {
    /// The point `enu_m` (east, north, up, m) of the local ENU frame whose origin is `self`.
    pub fn offset_by_enu(&self, enu_m: [f64; 3]) -> GeodeticWgs84 {
        let (lat, lon, alt) = map_3d::enu2geodetic(
            enu_m[0],
            enu_m[1],
            enu_m[2],
            self.lat_deg.to_radians(),
            self.lon_deg.to_radians(),
            self.alt_m,
            Ellipsoid::WGS84,
        );
        GeodeticWgs84 {
            lat_deg: lat.to_degrees(),
            lon_deg: lon.to_degrees(),
            alt_m: alt,
        }
    }

    /// Horizontal distance to `p` along the local ground plane, m.
    pub fn horizontal_distance_m(&self, p: &GeodeticWgs84) -> f64 {
        let [e, n, _] = self.enu_of(p);
        e.hypot(n)
    }

    /// Where `p` lies in the local ENU frame whose origin is `self`: east, north, up, m.
    pub fn enu_of(&self, p: &GeodeticWgs84) -> [f64; 3] {
        let (e, n, u) = map_3d::geodetic2enu(
            p.lat_deg.to_radians(),
            p.lon_deg.to_radians(),
            p.alt_m,
            self.lat_deg.to_radians(),
            self.lon_deg.to_radians(),
            self.alt_m,
            Ellipsoid::WGS84,
        );
        [e, n, u]
    }
}

/// Where a vehicle's local frame lies in the world frame, when both are anchored on Earth:
/// the world's origin (`[world] origin`) and the vehicle's (its GPS_GLOBAL_ORIGIN, where its
/// estimator started). Horizontal positions convert exactly, through latitude and longitude
/// (two tangent planes 1 km apart are tilted by 1.6e-4 rad: a plain shift would be off by
/// 0.16 m per km of distance). Heights do not convert: a world's heights and a vehicle's are
/// both above its own ground origin, and the two origins' altitudes are given in different
/// datums (the world's above the ellipsoid, GPS_GLOBAL_ORIGIN's above mean sea level: tens
/// of metres apart), so converting them would move the vehicle up or down by the geoid's
/// height. Velocities keep their components (the tilt changes them by under 0.02 %).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldPlacement {
    world_origin: GeodeticWgs84,
    vehicle_origin: GeodeticWgs84,
}

impl WorldPlacement {
    /// The placement of a vehicle whose local origin is `vehicle_origin` in a world whose
    /// origin is `world_origin`.
    pub fn new(world_origin: GeodeticWgs84, vehicle_origin: GeodeticWgs84) -> Self {
        // Both on the world's ground (its height is the one given in the ellipsoid's datum):
        // distances on a plane 1,673 m up are 2.6e-4 longer than at sea level.
        Self {
            world_origin,
            vehicle_origin: GeodeticWgs84 {
                alt_m: world_origin.alt_m,
                ..vehicle_origin
            },
        }
    }

    /// The vehicle's local origin in the world frame: east, north, m.
    pub fn vehicle_origin_in_world_en_m(&self) -> [f64; 2] {
        let [e, n, _] = self.world_origin.enu_of(&self.vehicle_origin);
        [e, n]
    }

    /// A point of the world ENU frame (east, north, m) in the vehicle's local ENU frame.
    pub fn world_to_vehicle_en_m(&self, world_en_m: [f64; 2]) -> [f64; 2] {
        Self::between(&self.world_origin, &self.vehicle_origin, world_en_m)
    }

    /// A point of the vehicle's local ENU frame (east, north, m) in the world ENU frame.
    pub fn vehicle_to_world_en_m(&self, vehicle_en_m: [f64; 2]) -> [f64; 2] {
        Self::between(&self.vehicle_origin, &self.world_origin, vehicle_en_m)
    }

    fn between(from: &GeodeticWgs84, to: &GeodeticWgs84, en_m: [f64; 2]) -> [f64; 2] {
        // On the ground of `from`: the point's own height would tilt it by nothing that
        // matters, and heights are not converted (see the type's documentation).
        let p = from.offset_by_enu([en_m[0], en_m[1], 0.0]);
        let [e, n, _] = to.enu_of(&p);
        [e, n]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ZERMATT: GeodeticWgs84 = GeodeticWgs84 {
        lat_deg: 46.017,
        lon_deg: 7.750,
        alt_m: 1673.0,
    };
    const MATTERHORN: GeodeticWgs84 = GeodeticWgs84 {
        lat_deg: 45.976,
        lon_deg: 7.658,
        alt_m: 4531.0,
    };

    /// MathWorks' published example (geodetic2enu / enu2geodetic, WGS84): the Matterhorn
    /// from Zermatt is (-7134.8, -4556.3, 2852.4) m ENU, given to 0.1 m.
    #[test]
    fn the_published_matterhorn_example_both_ways() {
        let enu = ZERMATT.enu_of(&MATTERHORN);
        for (got, want) in enu.iter().zip([-7134.8, -4556.3, 2852.4]) {
            assert!((got - want).abs() < 0.05, "{enu:?}");
        }
        let back = ZERMATT.offset_by_enu([-7134.8, -4556.3, 2852.4]);
        // The published ENU is rounded to 0.1 m: about 1e-6 degree.
        assert!((back.lat_deg - MATTERHORN.lat_deg).abs() < 2e-6, "{back:?}");
        assert!((back.lon_deg - MATTERHORN.lon_deg).abs() < 2e-6, "{back:?}");
        assert!((back.alt_m - MATTERHORN.alt_m).abs() < 0.1, "{back:?}");
    }

    /// A vehicle powered up 30 m east and 40 m north of the world's origin: its local origin
    /// is there in the world, a world point is that much less in the vehicle's frame, and
    /// both directions undo each other; 2 km out the exact conversion differs from a plain
    /// shift by the tangent planes' tilt (~0.3 m per km of offset per km, here ~0.5 m).
    #[test]
    fn a_vehicle_origin_off_the_worlds_both_ways() {
        let world = ZERMATT;
        let vehicle = GeodeticWgs84 {
            alt_m: 1650.0, // another datum's number: ignored
            ..ZERMATT.offset_by_enu([30.0, 40.0, 0.0])
        };
        let place = WorldPlacement::new(world, vehicle);
        let [e, n] = place.vehicle_origin_in_world_en_m();
        assert!(
            (e - 30.0).abs() < 1e-6 && (n - 40.0).abs() < 1e-6,
            "{e} {n}"
        );
        let v = place.world_to_vehicle_en_m([100.0, -20.0]);
        assert!(
            (v[0] - 70.0).abs() < 1e-3 && (v[1] + 60.0).abs() < 1e-3,
            "{v:?}"
        );
        let w = place.vehicle_to_world_en_m([0.0, 0.0]);
        assert!(
            (w[0] - 30.0).abs() < 1e-6 && (w[1] - 40.0).abs() < 1e-6,
            "{w:?}"
        );
        for p in [[0.0, 0.0], [-1234.5, 678.9], [2000.0, 2000.0]] {
            let back = place.vehicle_to_world_en_m(place.world_to_vehicle_en_m(p));
            assert!((back[0] - p[0]).abs() < 1e-6 && (back[1] - p[1]).abs() < 1e-6);
        }
        // Far out: not a plain shift, and the difference is the planes' tilt.
        let far = place.world_to_vehicle_en_m([0.0, 2000.0]);
        let tilt = ((far[0] + 30.0).powi(2) + (far[1] - 1960.0).powi(2)).sqrt();
        assert!(tilt > 1e-3 && tilt < 0.05, "{tilt}");
    }

    #[test]
    fn east_is_east_and_north_is_north() {
        let o = GeodeticWgs84 {
            lat_deg: 29.6436,
            lon_deg: -82.3549,
            alt_m: 30.0,
        };
        let p = o.offset_by_enu([100.0, 0.0, 0.0]);
        assert!(p.lon_deg > o.lon_deg && (p.lat_deg - o.lat_deg).abs() < 1e-6);
        let q = o.offset_by_enu([0.0, 100.0, 0.0]);
        assert!(q.lat_deg > o.lat_deg && (q.lon_deg - o.lon_deg).abs() < 1e-9);
        // One degree of latitude here is ~110.8 km (WGS84 meridian arc).
        assert!(((q.lat_deg - o.lat_deg) * 110_800.0 - 100.0).abs() < 0.5);
        let round = o.enu_of(&o.offset_by_enu([-1234.5, 678.9, -3.0]));
        for (a, b) in round.iter().zip([-1234.5, 678.9, -3.0]) {
            assert!((a - b).abs() < 1e-6, "{round:?}");
        }
    }
}
