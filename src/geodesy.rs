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
