//! An imported world: the GeoJSON infotrack reads, where it lies, where the target starts,
//! and what was kept and dropped.

use std::collections::{HashMap, HashSet};
use std::fmt;

use infotrack_core::geodesy::GeodeticWgs84;
use serde_json::{json, Value};

use crate::graph::{edges_of, keep_within, largest_strongly_connected, Drivable, RoadEdge};
use crate::read::{OsmData, Way};
use crate::roads::{drivable, is_covered, Direction, NotDriven};
use crate::shapes::{band, clipped, enu, inside, lonlat, simplified};
use crate::{Bbox, OsmError, MAX_BOX_SIDE_M};

/// Shape points closer than this to the road's simplified line are dropped, m.
const ROAD_TOLERANCE_M: f64 = 2.0;
/// A wood's outline is simplified to this, m.
const WOOD_TOLERANCE_M: f64 = 5.0;
/// Half the width of a tunnel's occlusion around its road, m.
const TUNNEL_HALF_WIDTH_M: f64 = 8.0;
/// The cue's radius around the start, m.
const CUE_RADIUS_M: f64 = 100.0;
/// The slowest speed the search from the cue assumes (`acquisition.min_speed_mps`), m/s:
/// a town's car stands at lights and in queues, so a cued car may be standing. On SUMO's
/// traffic in four street networks this raised the mean %FOV of EER's search from 18.0 to
/// 24.6 (docs/src/traffic.md).
const CUE_MIN_SPEED_MPS: f64 = 0.0;

/// A world made from an extract.
#[derive(Debug, Clone)]
pub struct ImportedWorld {
    /// The GeoJSON world (`[world] geojson`).
    pub geojson: Value,
    /// The world's origin: the box's centre, on the ellipsoid (alt 0 m).
    pub origin: GeodeticWgs84,
    /// Where the simulated car starts and the cue is, world ENU, m.
    pub start_enu: [f64; 2],
    /// The geofence, world ENU: `[x_min, x_max, y_min, y_max]`, m.
    pub workspace_enu: [f64; 4],
    /// What was kept and dropped.
    pub summary: Summary,
}

/// What an import kept and dropped, and why.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Road pieces kept (junction to junction).
    pub roads: usize,
    /// Their junctions.
    pub junctions: usize,
    /// Their length, km.
    pub road_km: f64,
    /// Ways with a `highway` tag a car does not drive (footways, tracks, ...).
    pub not_car_class: usize,
    /// Ways closed to private cars.
    pub no_access: usize,
    /// Areas and reversible ways.
    pub odd_shape: usize,
    /// Road pieces outside the largest strongly connected part (a car could not drive
    /// there and back), and their length, km.
    pub disconnected: (usize, f64),
    /// Tunnels and covered roads kept as occlusions.
    pub tunnels: usize,
    /// Woods over the roads kept as occlusions.
    pub woods: usize,
    /// Woods drawn as multipolygon relations (not read).
    pub wood_relations: usize,
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "roads: {} pieces, {:.1} km, {} junctions (the largest part a car can drive from anywhere to anywhere)",
            self.roads, self.road_km, self.junctions
        )?;
        writeln!(
            f,
            "dropped: {} ways not for cars, {} closed to private cars, {} areas or reversible ways; {} road pieces ({:.1} km) cut off from the largest part",
            self.not_car_class, self.no_access, self.odd_shape, self.disconnected.0, self.disconnected.1
        )?;
        write!(
            f,
            "occlusions: {} tunnels or covered roads, {} woods over roads ({} woods drawn as multipolygons not read)",
            self.tunnels, self.woods, self.wood_relations
        )
    }
}

/// The world of `data` within `bbox`.
pub fn import(data: &OsmData, bbox: &Bbox) -> Result<ImportedWorld, OsmError> {
    let [lon, lat] = bbox.centre();
    let origin = GeodeticWgs84 {
        lat_deg: lat,
        lon_deg: lon,
        alt_m: 0.0,
    };
    let workspace = workspace_of(bbox, &origin)?;
    let mut summary = Summary {
        wood_relations: data.wood_relations,
        ..Summary::default()
    };
    let roads = drivable_ways(&data.ways, &mut summary);
    let edges = edges_of(&roads, &data.nodes, bbox);
    let connected = largest_strongly_connected(&edges);
    let (kept, dropped) = keep_within(edges, &connected);
    if kept.is_empty() {
        return Err(OsmError::Empty(
            "no road a car may drive lies in the box (is it the right extract and box?)".into(),
        ));
    }
    let project = |id: &i64| enu(&origin, data.nodes[id]);
    let length = |e: &RoadEdge| {
        e.nodes
            .windows(2)
            .map(|w| dist(project(&w[0]), project(&w[1])))
            .sum::<f64>()
    };
    summary.disconnected = (dropped.len(), dropped.iter().map(length).sum::<f64>() / 1e3);
    summary.roads = kept.len();
    summary.road_km = kept.iter().map(length).sum::<f64>() / 1e3;
    summary.junctions = junctions(&kept);
    let start = start_edge(&kept, &project);
    let mut features: Vec<Value> = kept
        .iter()
        .enumerate()
        .map(|(i, e)| road_feature(e, data, &origin, i == start))
        .collect();
    let road_points: Vec<[f64; 2]> = kept
        .iter()
        .flat_map(|e| e.nodes.iter().map(project))
        .collect();
    features.extend(tunnels(&kept, &project, &origin, &workspace, &mut summary));
    features.extend(woods(data, &road_points, &origin, &workspace, &mut summary));
    let start_enu = project(&driven_from(&kept[start]));
    features.push(geofence(&workspace, &origin));
    features.push(json!({
        "type": "Feature",
        "geometry": {"type": "Point", "coordinates": lonlat(&origin, start_enu)},
        "properties": {"infotrack": "cue", "radius_m": CUE_RADIUS_M, "min_speed_mps": CUE_MIN_SPEED_MPS},
    }));
    Ok(ImportedWorld {
        geojson: json!({
            "type": "FeatureCollection",
            "attribution": "© OpenStreetMap contributors, ODbL 1.0 (https://www.openstreetmap.org/copyright)",
            "features": features,
        }),
        origin,
        start_enu,
        workspace_enu: workspace,
        summary,
    })
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The ways a car may drive; the others counted by why not.
fn drivable_ways<'a>(ways: &'a [Way], summary: &mut Summary) -> Vec<Drivable<'a>> {
    let mut out = Vec::new();
    for way in ways.iter().filter(|w| w.tag("highway").is_some()) {
        match drivable(way) {
            Ok(direction) => out.push(Drivable {
                way,
                direction,
                covered: is_covered(way),
            }),
            Err(NotDriven::Class) => summary.not_car_class += 1,
            Err(NotDriven::Access) => summary.no_access += 1,
            Err(NotDriven::Shape) => summary.odd_shape += 1,
        }
    }
    out
}

/// The geofence: the smallest world ENU rectangle around the box (its edges sampled, as a
/// parallel bows in the plane) and a metre, `[x_min, x_max, y_min, y_max]`.
fn workspace_of(bbox: &Bbox, origin: &GeodeticWgs84) -> Result<[f64; 4], OsmError> {
    let mut r = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for k in 0..=32 {
        let f = k as f64 / 32.0;
        let lon = bbox.lon_min + f * (bbox.lon_max - bbox.lon_min);
        let lat = bbox.lat_min + f * (bbox.lat_max - bbox.lat_min);
        for p in [
            [lon, bbox.lat_min],
            [lon, bbox.lat_max],
            [bbox.lon_min, lat],
            [bbox.lon_max, lat],
        ] {
            let [e, n] = enu(origin, p);
            r = [r[0].min(e), r[1].max(e), r[2].min(n), r[3].max(n)];
        }
    }
    // A metre more each way: the geofence is written in degrees and read back, and a
    // road node on the box's edge must stay inside.
    let r = [r[0] - 1.0, r[1] + 1.0, r[2] - 1.0, r[3] + 1.0];
    if r[1] - r[0] > MAX_BOX_SIDE_M || r[3] - r[2] > MAX_BOX_SIDE_M {
        return Err(OsmError::Bbox(format!(
            "is {:.1} km x {:.1} km: at most {:.0} km a side (a town, not a region)",
            (r[1] - r[0]) / 1e3,
            (r[3] - r[2]) / 1e3,
            MAX_BOX_SIDE_M / 1e3
        )));
    }
    Ok(r)
}

/// The junctions of the kept roads.
fn junctions(kept: &[RoadEdge]) -> usize {
    kept.iter()
        .flat_map(|e| [e.nodes[0], *e.nodes.last().expect("two nodes")])
        .collect::<HashSet<i64>>()
        .len()
}

/// The junction a car enters `e` from.
fn driven_from(e: &RoadEdge) -> i64 {
    match e.direction {
        Direction::Backward => *e.nodes.last().expect("two nodes"),
        _ => e.nodes[0],
    }
}

/// The road the simulated car starts on: the one entered nearest the box's centre.
fn start_edge(kept: &[RoadEdge], project: &impl Fn(&i64) -> [f64; 2]) -> usize {
    (0..kept.len())
        .min_by(|a, b| {
            let d = |i: &usize| dist(project(&driven_from(&kept[*i])), [0.0, 0.0]);
            d(a).total_cmp(&d(b))
        })
        .expect("a road")
}

/// One road as a GeoJSON LineString, in the direction a car drives it.
fn road_feature(e: &RoadEdge, data: &OsmData, origin: &GeodeticWgs84, start: bool) -> Value {
    let mut pts: Vec<[f64; 2]> = e.nodes.iter().map(|id| data.nodes[id]).collect();
    if e.direction == Direction::Backward {
        pts.reverse();
    }
    let plane: Vec<[f64; 2]> = pts.iter().map(|p| enu(origin, *p)).collect();
    let kept: Vec<[f64; 2]> = simplified(&plane, ROAD_TOLERANCE_M)
        .into_iter()
        .map(|i| pts[i])
        .collect();
    let mut props = json!({
        "infotrack": "road",
        "oneway": e.direction != Direction::Both,
        "highway": e.class,
        "osm_way": e.way,
    });
    if start {
        props["start"] = json!(true);
    }
    json!({"type": "Feature", "geometry": {"type": "LineString", "coordinates": kept}, "properties": props})
}

/// A polygon occlusion feature from a ring in world ENU.
fn occlusion(ring: &[[f64; 2]], origin: &GeodeticWgs84, name: String) -> Value {
    let mut coords: Vec<[f64; 2]> = ring.iter().map(|p| lonlat(origin, *p)).collect();
    coords.push(coords[0]);
    json!({
        "type": "Feature",
        "geometry": {"type": "Polygon", "coordinates": [coords]},
        "properties": {"infotrack": "occlusion", "name": name},
    })
}

fn inside_workspace(ring: &[[f64; 2]], ws: &[f64; 4]) -> Vec<[f64; 2]> {
    clipped(ring, [ws[0], ws[2]], [ws[1], ws[3]])
}

/// Tunnels and covered roads: a band over each kept covered road.
fn tunnels(
    kept: &[RoadEdge],
    project: &impl Fn(&i64) -> [f64; 2],
    origin: &GeodeticWgs84,
    ws: &[f64; 4],
    summary: &mut Summary,
) -> Vec<Value> {
    let out: Vec<Value> = kept
        .iter()
        .filter(|e| e.covered)
        .filter_map(|e| {
            let line: Vec<[f64; 2]> = e.nodes.iter().map(project).collect();
            let ring = inside_workspace(&band(&line, TUNNEL_HALF_WIDTH_M), ws);
            (ring.len() >= 3)
                .then(|| occlusion(&ring, origin, format!("tunnel (OSM way {})", e.way)))
        })
        .collect();
    summary.tunnels = out.len();
    out
}

/// Woods (closed ways) with a kept road under them, cut to the geofence.
fn woods(
    data: &OsmData,
    road_points: &[[f64; 2]],
    origin: &GeodeticWgs84,
    ws: &[f64; 4],
    summary: &mut Summary,
) -> Vec<Value> {
    let nodes: &HashMap<i64, [f64; 2]> = &data.nodes;
    let out: Vec<Value> = data
        .ways
        .iter()
        .filter(|w| {
            w.tag("highway").is_none() && w.refs.len() >= 4 && w.refs.first() == w.refs.last()
        })
        .filter_map(|w| {
            let ring: Vec<[f64; 2]> = w.refs[..w.refs.len() - 1]
                .iter()
                .filter_map(|id| nodes.get(id).map(|p| enu(origin, *p)))
                .collect();
            let ring = inside_workspace(&ring, ws);
            let keep = simplified(&ring, WOOD_TOLERANCE_M);
            let ring: Vec<[f64; 2]> = keep.into_iter().map(|i| ring[i]).collect();
            let over_road = road_points.iter().any(|p| inside(&ring, *p));
            (ring.len() >= 3 && over_road)
                .then(|| occlusion(&ring, origin, format!("wood (OSM way {})", w.id)))
        })
        .collect();
    summary.woods = out.len();
    out
}

/// The geofence feature: the workspace rectangle.
fn geofence(ws: &[f64; 4], origin: &GeodeticWgs84) -> Value {
    let ring = [
        [ws[0], ws[2]],
        [ws[1], ws[2]],
        [ws[1], ws[3]],
        [ws[0], ws[3]],
    ];
    let mut coords: Vec<[f64; 2]> = ring.iter().map(|p| lonlat(origin, *p)).collect();
    coords.push(coords[0]);
    json!({
        "type": "Feature",
        "geometry": {"type": "Polygon", "coordinates": [coords]},
        "properties": {"infotrack": "geofence"},
    })
}
