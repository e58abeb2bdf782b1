//! `[world] geojson`: roads, occlusions, geofence and cue drawn in WGS84 load as the same
//! world ENU metres a config would give, in the right order ([longitude, latitude]); what is
//! wrong is named.

use std::path::{Path, PathBuf};

use infotrack::config::Config;
use infotrack::geodesy::GeodeticWgs84;
use serde_json::json;

const ORIGIN: GeodeticWgs84 = GeodeticWgs84 {
    lat_deg: 47.397742,
    lon_deg: 8.545594,
    alt_m: 488.0,
};

/// `[longitude, latitude]` of the world ENU point (east, north).
fn lonlat(e: f64, n: f64) -> serde_json::Value {
    let g = ORIGIN.offset_by_enu([e, n, 0.0]);
    json!([g.lon_deg, g.lat_deg])
}

fn feature(
    kind: &str,
    geometry: serde_json::Value,
    mut props: serde_json::Value,
) -> serde_json::Value {
    props["infotrack"] = json!(kind);
    json!({"type": "Feature", "geometry": geometry, "properties": props})
}

/// A one-way square loop A(0,0) B(100,0) C(100,100) D(0,100), a two-way spur B-E(200,0)
/// taken from B with p = 0.3, an occlusion around C, a geofence, a cue on A-B, and one
/// feature that is not infotrack's.
fn area() -> serde_json::Value {
    let line = |pts: &[(f64, f64)]| json!({"type": "LineString", "coordinates": pts.iter().map(|p| lonlat(p.0, p.1)).collect::<Vec<_>>()});
    let poly = |pts: &[(f64, f64)]| {
        let mut ring: Vec<_> = pts.iter().map(|p| lonlat(p.0, p.1)).collect();
        ring.push(ring[0].clone());
        json!({"type": "Polygon", "coordinates": [ring]})
    };
    json!({"type": "FeatureCollection", "features": [
        feature("road", line(&[(0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (0.0, 100.0), (0.0, 0.0)]), json!({"start": true})),
        feature("road", line(&[(100.0, 0.3), (200.0, 0.0)]), json!({"oneway": false, "p": 0.3})),
        feature("occlusion", poly(&[(90.0, 90.0), (110.0, 90.0), (110.0, 110.0), (90.0, 110.0)]), json!({"name": "barn"})),
        feature("geofence", poly(&[(-50.0, -50.0), (250.0, -50.0), (250.0, 150.0), (-50.0, 150.0)]), json!({})),
        feature("cue", json!({"type": "Point", "coordinates": lonlat(50.0, 0.0)}), json!({"radius_m": 80.0, "min_speed_mps": 0.0})),
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": lonlat(5.0, 5.0)}, "properties": {"name": "a tree"}},
    ]})
}

/// The lab config without the sections the file gives, with `[world]` pointing at it.
fn config_with(dir: &Path, geojson: &serde_json::Value, drop: &[&str]) -> PathBuf {
    std::fs::write(dir.join("area.geojson"), geojson.to_string()).unwrap();
    let mut t: toml::Table = toml::from_str(infotrack::config::DEFAULT_TOML).unwrap();
    for k in drop {
        t.remove(*k);
    }
    let world: toml::Table = format!(
        "origin = {{ lat_deg = {}, lon_deg = {}, alt_m = {} }}\ngeojson = \"area.geojson\"",
        ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_m
    )
    .parse()
    .unwrap();
    t.insert("world".into(), toml::Value::Table(world));
    let path = dir.join("area.toml");
    std::fs::write(&path, toml::to_string(&t).unwrap()).unwrap();
    path
}

/// The error of loading `geojson` as the only source of roads, geofence and occlusions.
fn refused(dir: &Path, geojson: &serde_json::Value) -> String {
    load_error(&config_with(
        dir,
        geojson,
        &["road", "workspace_enu", "occlusions"],
    ))
}

fn load_error(path: &Path) -> String {
    Config::load(path)
        .expect_err("should be refused")
        .to_string()
}

#[test]
fn roads_occlusions_geofence_and_cue_load_as_world_enu_metres() {
    let dir = tempfile::tempdir().unwrap();
    let path = config_with(
        dir.path(),
        &area(),
        &["road", "workspace_enu", "occlusions"],
    );
    let c = Config::load(&path).unwrap();
    let close =
        |x: f64, y: f64, want: (f64, f64)| (x - want.0).abs() < 1e-6 && (y - want.1).abs() < 1e-6;
    // Nodes in drawing order; the spur's 0.3 m-off start is B (within 1 m).
    let nodes: Vec<(f64, f64)> = c.road.nodes.iter().map(|n| (n.x_m, n.y_m)).collect();
    let want = [
        (0.0, 0.0),
        (100.0, 0.0),
        (100.0, 100.0),
        (0.0, 100.0),
        (200.0, 0.0),
    ];
    assert_eq!(nodes.len(), want.len(), "{nodes:?}");
    for (got, w) in nodes.iter().zip(want) {
        // East is x: a [latitude, longitude] mix-up would put B 100 m north.
        assert!(close(got.0, got.1, w), "node {got:?}, want {w:?}");
    }
    assert_eq!(c.road.start_node, 0);
    let mut edges: Vec<(u32, u32, f64)> =
        c.road.edges.iter().map(|e| (e.from, e.to, e.p)).collect();
    edges.sort_by_key(|e| (e.0, e.1));
    let want = [
        (0, 1, 1.0),
        (1, 2, 0.7),
        (1, 4, 0.3),
        (2, 3, 1.0),
        (3, 0, 1.0),
        (4, 1, 1.0),
    ];
    assert_eq!(edges.len(), want.len(), "{edges:?}");
    for (got, w) in edges.iter().zip(want) {
        assert!(
            got.0 == w.0 && got.1 == w.1 && (got.2 - w.2).abs() < 1e-12,
            "{got:?} vs {w:?}"
        );
    }
    let occ = c.occlusions.iter().find(|o| o.name == "barn").unwrap();
    assert_eq!(occ.vertices_enu_m.len(), 4);
    assert!(close(
        occ.vertices_enu_m[1][0],
        occ.vertices_enu_m[1][1],
        (110.0, 90.0)
    ));
    let w = &c.workspace_enu;
    assert!(
        close(w.x_min_m, w.y_min_m, (-50.0, -50.0)) && close(w.x_max_m, w.y_max_m, (250.0, 150.0))
    );
    let cue = c.acquisition.as_ref().unwrap();
    assert!(
        cue.cue_enu_m.is_some_and(|[x, y]| close(x, y, (50.0, 0.0))) && cue.cue_radius_m == 80.0
    );
    assert_eq!(cue.min_speed_mps, Some(0.0));
}

#[test]
fn what_is_wrong_in_the_file_or_given_twice_is_named() {
    let dir = tempfile::tempdir().unwrap();
    // Roads in both the config and the file.
    let path = config_with(dir.path(), &area(), &["workspace_enu", "occlusions"]);
    let err = load_error(&path);
    assert!(
        err.contains("`road` is given twice") && err.contains("area.geojson"),
        "{err}"
    );

    // A kind infotrack does not know, named with its feature.
    let mut bad = area();
    bad["features"][2]["properties"]["infotrack"] = json!("building");
    let err = refused(dir.path(), &bad);
    assert!(
        err.contains("feature 2") && err.contains("\"building\""),
        "{err}"
    );

    // [latitude, longitude] written the wrong way round somewhere at 47 N 8 E is still a
    // valid position, but a latitude of 147 is not.
    let mut bad = area();
    bad["features"][4]["geometry"]["coordinates"] = json!([47.4, 147.4]);
    let err = refused(dir.path(), &bad);
    assert!(
        err.contains("feature 4") && err.contains("[longitude, latitude]"),
        "{err}"
    );

    // [latitude, longitude] swapped near 47 N 8 E: both in range, but 4,500 km away; the
    // message names the feature once, the position, and the likely swap.
    let mut bad = area();
    bad["features"][4]["geometry"]["coordinates"] = json!([ORIGIN.lat_deg, ORIGIN.lon_deg]);
    let err = refused(dir.path(), &bad);
    assert!(
        err.contains("feature 4: position") && err.contains("swapped?"),
        "{err}"
    );
    assert_eq!(err.matches("feature 4").count(), 1, "{err}");

    // Probabilities leaving a node over 1.
    let mut bad = area();
    bad["features"][0]["properties"]["p"] = json!(0.9);
    let err = refused(dir.path(), &bad);
    assert!(err.contains("summing to"), "{err}");

    // A cue's slowest speed that is not a number, named with its feature.
    let mut bad = area();
    bad["features"][4]["properties"]["min_speed_mps"] = json!("slow");
    let err = refused(dir.path(), &bad);
    assert!(
        err.contains("min_speed_mps") && err.contains("feature 4"),
        "{err}"
    );

    // No origin to place the file.
    let path = config_with(
        dir.path(),
        &area(),
        &["road", "workspace_enu", "occlusions"],
    );
    let text = std::fs::read_to_string(&path).unwrap();
    let mut t: toml::Table = toml::from_str(&text).unwrap();
    t["world"].as_table_mut().unwrap().remove("origin");
    std::fs::write(&path, toml::to_string(&t).unwrap()).unwrap();
    let err = load_error(&path);
    assert!(
        err.contains("world.geojson") && err.contains("origin"),
        "{err}"
    );

    // A missing file is named.
    std::fs::remove_file(dir.path().join("area.geojson")).unwrap();
    let path = dir.path().join("area.toml");
    let err = load_error(&path);
    assert!(err.contains("area.geojson"), "{err}");
}
