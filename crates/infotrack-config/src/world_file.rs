//! `[world] geojson`: the world's roads, occlusions, geofence and cue drawn in WGS84 with a
//! GIS tool (QGIS, geojson.io, ...) instead of written as ENU metres. The file is read when
//! the config is, converted about `[world] origin` (exactly, `geodesy`) and put where the
//! config's own sections would be, so everything after loading sees ENU metres as always.
//!
//! Each feature says what it is with a property `"infotrack"`:
//! * `"road"`: a LineString driven from its first position to its last (`"oneway": false`
//!   adds the way back); positions within [`NODE_MERGE_M`] of each other are one node, so
//!   roads that share an end meet there. `"p"`: the probability that a target at the road's
//!   first position takes this road (the roads leaving a node without one share what is
//!   left equally). `"start": true`: the simulated target starts at its first position
//!   (otherwise the first road's).
//! * `"occlusion"`: a Polygon (its outer ring) where the target cannot be seen; `"name"`.
//! * `"geofence"`: a Polygon whose bounding rectangle (east/north) is the workspace and
//!   geofence.
//! * `"cue"`: a Point, the operator's cue, with `"radius_m"` (and optionally
//!   `"min_speed_mps"`, `acquisition.min_speed_mps`).
//!
//! Positions are `[longitude, latitude]` in that order (RFC 7946). A section given both in
//! the config and in the file is refused (which one wins would be a guess); occlusions from
//! both are kept. Features without `"infotrack"` are counted in a warning, not used.

use std::path::Path;

use geojson::{Feature, GeoJson, GeometryValue, Position};
use serde_json::Value as Json;

use super::ConfigError;
use infotrack_core::geodesy::GeodeticWgs84;

/// Road positions closer than this are one node, metres.
pub const NODE_MERGE_M: f64 = 1.0;

/// What the file gives, in world ENU metres, as TOML values of the config's own sections.
#[derive(Default)]
struct WorldFromFile {
    road: Option<toml::Value>,
    occlusions: Vec<toml::Value>,
    workspace: Option<toml::Value>,
    cue: Option<toml::Value>,
}

/// Why a GeoJSON world cannot be read; shown after the file's name.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WorldFileError {
    /// The text is not GeoJSON.
    #[error("{0}")]
    NotGeoJson(String),
    /// A geometry without features.
    #[error("a bare geometry: infotrack needs Features with an \"infotrack\" property")]
    BareGeometry,
    /// One feature is wrong.
    #[error("feature {index}: {problem}")]
    Feature {
        /// Its index in the collection.
        index: usize,
        /// What is wrong with it.
        problem: FeatureError,
    },
    /// The turn probabilities drawn at a junction do not add up.
    #[error("the roads leaving the node at east {east_m:.1} m, north {north_m:.1} m have \"p\" summing to {sum}, not 1")]
    TurnProbabilities {
        /// The junction, world ENU east, m.
        east_m: f64,
        /// The junction, world ENU north, m.
        north_m: f64,
        /// What the given probabilities sum to.
        sum: f64,
    },
}

/// What is wrong with one feature of a GeoJSON world.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeatureError {
    /// A position beyond the range of degrees.
    #[error("position [{lon}, {lat}] is not [longitude, latitude] in degrees")]
    NotDegrees {
        /// Its first coordinate.
        lon: f64,
        /// Its second coordinate.
        lat: f64,
    },
    /// A position too far from the world's origin to be in its world.
    #[error(
        "position [{lon}, {lat}] is {:.0} km from the world's origin ({origin_lat:.6}, {origin_lon:.6}){}",
        distance_m / 1e3,
        if *swapped_near { ": latitude and longitude swapped? GeoJSON positions are [longitude, latitude]" } else { "" }
    )]
    FarFromOrigin {
        /// Its first coordinate.
        lon: f64,
        /// Its second coordinate.
        lat: f64,
        /// How far it is from the origin, m.
        distance_m: f64,
        /// The origin's latitude, degrees.
        origin_lat: f64,
        /// The origin's longitude, degrees.
        origin_lon: f64,
        /// Whether the position, read the other way round, is near the origin.
        swapped_near: bool,
    },
    /// A property of the wrong type.
    #[error("\"{key}\": {value} is not {expected}")]
    Property {
        /// The property.
        key: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        expected: &'static str,
    },
    /// The wrong geometry or too few positions for the feature's kind.
    #[error("{0}")]
    Shape(&'static str),
    /// A second feature of a kind a world has one of.
    #[error("a second {0}")]
    Second(&'static str),
    /// An `infotrack` property naming no kind.
    #[error("\"infotrack\": {0} is not one of \"road\", \"occlusion\", \"geofence\", \"cue\"")]
    UnknownKind(String),
}

/// Reads `[world] geojson` (relative to `base`, the config's folder) if the table has one
/// and puts its sections into `table`. `origin` names the config in errors.
pub(super) fn merge_world_file(
    table: &mut toml::Table,
    base: &Path,
    origin: &Path,
) -> Result<(), ConfigError> {
    let Some(world) = table.get("world").and_then(|w| w.as_table()) else {
        return Ok(());
    };
    let Some(file) = world.get("geojson") else {
        return Ok(());
    };
    let file = file
        .as_str()
        .ok_or_else(|| invalid("world.geojson", file, "must be a path"))?;
    let world_origin: GeodeticWgs84 = world
        .get("origin")
        .ok_or_else(|| invalid("world.geojson", file, "needs [world] origin to place it"))?
        .clone()
        .try_into()
        .map_err(|e| ConfigError::Parse {
            path: origin.to_path_buf(),
            message: format!("world.origin: {e}"),
        })?;
    let path = if Path::new(file).is_absolute() {
        Path::new(file).to_path_buf()
    } else {
        base.join(file)
    };
    /// A town's roads, woods and buildings from OpenStreetMap are a few MB of GeoJSON.
    const MAX_WORLD_BYTES: u64 = 64 << 20;
    let text = super::read_user_file(&path, MAX_WORLD_BYTES)?;
    let parsed = read(&text, &world_origin).map_err(|e| ConfigError::Parse {
        path: path.clone(),
        message: e.to_string(),
    })?;
    put(table, parsed, origin, &path)
}

/// Puts the file's sections into the table, refusing one the config gives too.
fn put(
    table: &mut toml::Table,
    parsed: WorldFromFile,
    origin: &Path,
    file: &Path,
) -> Result<(), ConfigError> {
    let mut place = |key: &str, what: &str, value: Option<toml::Value>| {
        let Some(v) = value else { return Ok(()) };
        if table.contains_key(key) {
            return Err(ConfigError::Parse {
                path: origin.to_path_buf(),
                message: format!(
                    "`{key}` is given twice: in this config and as {what} in {}; keep one",
                    file.display()
                ),
            });
        }
        table.insert(key.to_string(), v);
        Ok(())
    };
    place("road", "roads", parsed.road)?;
    place("workspace_enu", "the geofence", parsed.workspace)?;
    if let Some(cue) = parsed.cue {
        place("acquisition", "the cue", Some(cue))?;
    }
    if !parsed.occlusions.is_empty() {
        let list = table
            .entry("occlusions")
            .or_insert_with(|| toml::Value::Array(Vec::new()));
        match list.as_array_mut() {
            Some(a) => a.extend(parsed.occlusions),
            None => {
                return Err(ConfigError::Parse {
                    path: origin.to_path_buf(),
                    message: "`occlusions` must be an array of tables".into(),
                })
            }
        }
    }
    Ok(())
}

fn invalid(key: &str, value: impl std::fmt::Display, reason: &str) -> ConfigError {
    ConfigError::Invalid {
        key: key.into(),
        value: value.to_string(),
        reason: reason.into(),
    }
}

/// Parses the GeoJSON text and converts its features about `origin`.
fn read(text: &str, origin: &GeodeticWgs84) -> Result<WorldFromFile, WorldFileError> {
    let features = match text
        .parse::<GeoJson>()
        .map_err(|e| WorldFileError::NotGeoJson(e.to_string()))?
    {
        GeoJson::FeatureCollection(c) => c.features,
        GeoJson::Feature(f) => vec![f],
        GeoJson::Geometry(_) => return Err(WorldFileError::BareGeometry),
    };
    let mut out = WorldFromFile::default();
    let mut roads = Vec::new();
    let mut unused = 0;
    for (i, f) in features.iter().enumerate() {
        let at = |problem: FeatureError| WorldFileError::Feature { index: i, problem };
        let Some(kind) = f.property("infotrack") else {
            unused += 1;
            continue;
        };
        let en = |p: &Position| enu_of(p, origin);
        match kind.as_str() {
            Some("road") => roads.push(road_of(f, en).map_err(at)?),
            Some("occlusion") => out.occlusions.push(occlusion_of(f, en).map_err(at)?),
            Some("geofence") => {
                if out.workspace.is_some() {
                    return Err(at(FeatureError::Second("geofence")));
                }
                out.workspace = Some(geofence_of(f, en).map_err(at)?);
            }
            Some("cue") => {
                if out.cue.is_some() {
                    return Err(at(FeatureError::Second("cue")));
                }
                out.cue = Some(cue_of(f, en).map_err(at)?);
            }
            _ => return Err(at(FeatureError::UnknownKind(kind.to_string()))),
        }
    }
    if unused > 0 {
        tracing::warn!("{unused} feature(s) without an \"infotrack\" property are not used");
    }
    if !roads.is_empty() {
        out.road = Some(road_graph(&roads)?);
    }
    Ok(out)
}

/// `[longitude, latitude]` -> world ENU east, north, m.
fn enu_of(p: &Position, origin: &GeodeticWgs84) -> Result<[f64; 2], FeatureError> {
    let c = p.as_slice();
    let (lon, lat) = (c[0], c[1]);
    if !(lat.abs() <= 90.0 && lon.abs() <= 180.0) {
        return Err(FeatureError::NotDegrees { lon, lat });
    }
    let at = |lat_deg: f64, lon_deg: f64| GeodeticWgs84 {
        lat_deg,
        lon_deg,
        alt_m: origin.alt_m,
    };
    let here = at(lat, lon);
    let far_m = origin.horizontal_distance_m(&here);
    if far_m > FARTHEST_M {
        // [latitude, longitude] written for [longitude, latitude] lands far away; swapped,
        // it would be near.
        let swapped_near =
            lon.abs() <= 90.0 && origin.horizontal_distance_m(&at(lon, lat)) <= FARTHEST_M;
        return Err(FeatureError::FarFromOrigin {
            lon,
            lat,
            distance_m: far_m,
            origin_lat: origin.lat_deg,
            origin_lon: origin.lon_deg,
            swapped_near,
        });
    }
    let [e, n, _] = origin.enu_of(&here);
    Ok([e, n])
}

/// A world's features lie within this of its origin, m (a town is a few km across).
const FARTHEST_M: f64 = 100_000.0;

fn geometry(f: &Feature) -> Result<&GeometryValue, FeatureError> {
    f.geometry
        .as_ref()
        .map(|g| &g.value)
        .ok_or(FeatureError::Shape("no geometry"))
}

/// A property that must be a number (None when absent).
fn number(f: &Feature, key: &'static str) -> Result<Option<f64>, FeatureError> {
    match f.property(key) {
        None | Some(Json::Null) => Ok(None),
        Some(v) => v.as_f64().map(Some).ok_or_else(|| FeatureError::Property {
            key,
            value: v.to_string(),
            expected: "a number",
        }),
    }
}

/// A property that must be true or false (`default` when absent).
fn flag(f: &Feature, key: &'static str, default: bool) -> Result<bool, FeatureError> {
    match f.property(key) {
        None | Some(Json::Null) => Ok(default),
        Some(v) => v.as_bool().ok_or_else(|| FeatureError::Property {
            key,
            value: v.to_string(),
            expected: "true or false",
        }),
    }
}

/// One road as drawn: its positions (ENU), direction and turn probability.
struct Road {
    points: Vec<[f64; 2]>,
    oneway: bool,
    p: Option<f64>,
    start: bool,
}

fn road_of(
    f: &Feature,
    en: impl Fn(&Position) -> Result<[f64; 2], FeatureError>,
) -> Result<Road, FeatureError> {
    let GeometryValue::LineString { coordinates } = geometry(f)? else {
        return Err(FeatureError::Shape("a road must be a LineString"));
    };
    if coordinates.len() < 2 {
        return Err(FeatureError::Shape("a road needs at least two positions"));
    }
    Ok(Road {
        points: coordinates.iter().map(en).collect::<Result<_, _>>()?,
        oneway: flag(f, "oneway", true)?,
        p: number(f, "p")?,
        start: flag(f, "start", false)?,
    })
}

/// The outer ring of a Polygon, without the repeated closing position.
fn ring_of(
    f: &Feature,
    en: impl Fn(&Position) -> Result<[f64; 2], FeatureError>,
) -> Result<Vec<[f64; 2]>, FeatureError> {
    let GeometryValue::Polygon { coordinates } = geometry(f)? else {
        return Err(FeatureError::Shape("must be a Polygon"));
    };
    let outer = coordinates
        .first()
        .ok_or(FeatureError::Shape("a Polygon without a ring"))?;
    let mut ring: Vec<[f64; 2]> = outer.iter().map(en).collect::<Result<_, _>>()?;
    if ring.len() > 1 && ring.first() == ring.last() {
        ring.pop();
    }
    if ring.len() < 3 {
        return Err(FeatureError::Shape(
            "a Polygon needs at least three corners",
        ));
    }
    Ok(ring)
}

fn occlusion_of(
    f: &Feature,
    en: impl Fn(&Position) -> Result<[f64; 2], FeatureError>,
) -> Result<toml::Value, FeatureError> {
    let ring = ring_of(f, en)?;
    let mut t = toml::Table::new();
    if let Some(name) = f.property("name").and_then(|n| n.as_str()) {
        t.insert("name".into(), name.into());
    }
    t.insert("vertices_enu_m".into(), points(&ring));
    Ok(toml::Value::Table(t))
}

fn geofence_of(
    f: &Feature,
    en: impl Fn(&Position) -> Result<[f64; 2], FeatureError>,
) -> Result<toml::Value, FeatureError> {
    let ring = ring_of(f, en)?;
    let fold =
        |i: usize, pick: fn(f64, f64) -> f64, from: f64| ring.iter().map(|p| p[i]).fold(from, pick);
    let mut t = toml::Table::new();
    t.insert("x_min_m".into(), fold(0, f64::min, f64::INFINITY).into());
    t.insert(
        "x_max_m".into(),
        fold(0, f64::max, f64::NEG_INFINITY).into(),
    );
    t.insert("y_min_m".into(), fold(1, f64::min, f64::INFINITY).into());
    t.insert(
        "y_max_m".into(),
        fold(1, f64::max, f64::NEG_INFINITY).into(),
    );
    Ok(toml::Value::Table(t))
}

fn cue_of(
    f: &Feature,
    en: impl Fn(&Position) -> Result<[f64; 2], FeatureError>,
) -> Result<toml::Value, FeatureError> {
    let GeometryValue::Point { coordinates } = geometry(f)? else {
        return Err(FeatureError::Shape("a cue must be a Point"));
    };
    let radius = number(f, "radius_m")?.ok_or(FeatureError::Shape("a cue needs \"radius_m\""))?;
    let mut t = toml::Table::new();
    t.insert(
        "cue_enu_m".into(),
        points(&[en(coordinates)?]).as_array().unwrap()[0].clone(),
    );
    t.insert("cue_radius_m".into(), radius.into());
    if let Some(v) = number(f, "min_speed_mps")? {
        t.insert("min_speed_mps".into(), v.into());
    }
    Ok(toml::Value::Table(t))
}

fn points(ps: &[[f64; 2]]) -> toml::Value {
    toml::Value::Array(
        ps.iter()
            .map(|p| toml::Value::Array(vec![p[0].into(), p[1].into()]))
            .collect(),
    )
}

/// The roads as the config's `[road]`: nodes where positions meet, an edge per drawn
/// segment (and back for a two-way road), turn probabilities per node.
fn road_graph(roads: &[Road]) -> Result<toml::Value, WorldFileError> {
    let mut nodes: Vec<[f64; 2]> = Vec::new();
    let mut node_of = |p: [f64; 2]| -> usize {
        match nodes
            .iter()
            .position(|q| (q[0] - p[0]).hypot(q[1] - p[1]) <= NODE_MERGE_M)
        {
            Some(i) => i,
            None => {
                nodes.push(p);
                nodes.len() - 1
            }
        }
    };
    // (from, to, explicit probability)
    let mut edges: Vec<(usize, usize, Option<f64>)> = Vec::new();
    let mut start = None;
    for r in roads {
        let ids: Vec<usize> = r.points.iter().map(|p| node_of(*p)).collect();
        if r.start {
            start.get_or_insert(ids[0]);
        }
        for (k, w) in ids.windows(2).enumerate() {
            if w[0] == w[1] {
                continue;
            }
            let mut add = |a: usize, b: usize, p: Option<f64>| {
                if !edges.iter().any(|e| e.0 == a && e.1 == b) {
                    edges.push((a, b, p));
                }
            };
            add(w[0], w[1], if k == 0 { r.p } else { None });
            if !r.oneway {
                add(w[1], w[0], None);
            }
        }
    }
    let start = start.unwrap_or_else(|| node_of(roads[0].points[0]));
    let mut edge_rows = Vec::new();
    for (n, at) in nodes.iter().enumerate() {
        let out: Vec<&(usize, usize, Option<f64>)> = edges.iter().filter(|e| e.0 == n).collect();
        let given: f64 = out.iter().filter_map(|e| e.2).sum();
        let open = out.iter().filter(|e| e.2.is_none()).count();
        if given > 1.0 + 1e-9 || (open == 0 && !out.is_empty() && (given - 1.0).abs() > 1e-9) {
            return Err(WorldFileError::TurnProbabilities {
                east_m: at[0],
                north_m: at[1],
                sum: given,
            });
        }
        for e in out {
            let p = e.2.unwrap_or((1.0 - given) / open as f64);
            let mut t = toml::Table::new();
            t.insert("from".into(), (e.0 as i64).into());
            t.insert("to".into(), (e.1 as i64).into());
            t.insert("p".into(), p.into());
            edge_rows.push(toml::Value::Table(t));
        }
    }
    let node_rows = nodes
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut t = toml::Table::new();
            t.insert("id".into(), (i as i64).into());
            t.insert("x_m".into(), p[0].into());
            t.insert("y_m".into(), p[1].into());
            toml::Value::Table(t)
        })
        .collect();
    let mut t = toml::Table::new();
    t.insert("nodes".into(), toml::Value::Array(node_rows));
    t.insert("edges".into(), toml::Value::Array(edge_rows));
    t.insert("start_node".into(), (start as i64).into());
    Ok(toml::Value::Table(t))
}
