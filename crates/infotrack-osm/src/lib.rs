//! Worlds from OpenStreetMap: the roads a car may drive within a box of an extract
//! (`.osm.pbf` or `.osm` XML), kept to their largest strongly connected part, with tunnels
//! and covered roads and the woods over roads as occlusions and the box as the geofence,
//! written as the GeoJSON world infotrack reads (`[world] geojson`).
//!
//! OpenStreetMap data is © OpenStreetMap contributors, under the Open Database Licence
//! (ODbL): a world made from it is a derived database and carries that attribution.
#![deny(missing_docs)]

pub mod graph;
pub mod read;
pub mod roads;
pub mod shapes;
pub mod world;

use std::path::{Path, PathBuf};

use thiserror::Error;

pub use world::{import, ImportedWorld, Summary};

/// A box on Earth, degrees (WGS84).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bbox {
    /// West edge, longitude.
    pub lon_min: f64,
    /// South edge, latitude.
    pub lat_min: f64,
    /// East edge, longitude.
    pub lon_max: f64,
    /// North edge, latitude.
    pub lat_max: f64,
}

/// The widest box an import takes, m: a town, not a country (the tracker's world is a few
/// km across).
pub const MAX_BOX_SIDE_M: f64 = 20_000.0;

impl Bbox {
    /// From `lon_min,lat_min,lon_max,lat_max`, checked: finite degrees in range, west of
    /// east, south of north.
    pub fn parse(text: &str) -> Result<Self, OsmError> {
        let bad = |why: &str| OsmError::Bbox(format!("`{text}`: {why}"));
        let v: Vec<f64> = text
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad("expected four numbers lon_min,lat_min,lon_max,lat_max"))?;
        let [lon_min, lat_min, lon_max, lat_max] = v[..] else {
            return Err(bad("expected four numbers lon_min,lat_min,lon_max,lat_max"));
        };
        if !v.iter().all(|x| x.is_finite())
            || lon_min.abs() > 180.0
            || lon_max.abs() > 180.0
            || lat_min.abs() > 85.0
            || lat_max.abs() > 85.0
        {
            return Err(bad(
                "longitudes are within +-180 and latitudes within +-85 degrees",
            ));
        }
        if lon_min >= lon_max || lat_min >= lat_max {
            return Err(bad(
                "the west edge must be west of the east one, the south edge south of the north one",
            ));
        }
        Ok(Self {
            lon_min,
            lat_min,
            lon_max,
            lat_max,
        })
    }

    /// Whether `[lon, lat]` lies inside.
    pub fn contains(&self, lon: f64, lat: f64) -> bool {
        (self.lon_min..=self.lon_max).contains(&lon) && (self.lat_min..=self.lat_max).contains(&lat)
    }

    /// Its centre, `[lon, lat]`.
    pub fn centre(&self) -> [f64; 2] {
        [
            0.5 * (self.lon_min + self.lon_max),
            0.5 * (self.lat_min + self.lat_max),
        ]
    }
}

/// Why an import failed.
#[derive(Debug, Error)]
pub enum OsmError {
    /// The box is not one.
    #[error("--bbox {0}")]
    Bbox(String),
    /// The extract could not be read.
    #[error("cannot read {path}: {message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// An element of an XML extract is malformed.
    #[error("{path}: line {line}: {message}")]
    Element {
        /// The file.
        path: PathBuf,
        /// Its line.
        line: u32,
        /// What is wrong.
        message: String,
    },
    /// Nothing to fly over.
    #[error("{0}")]
    Empty(String),
}

impl OsmError {
    fn read(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::Read {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}
