//! `infotrack world learn`: recorded tracks of a world's traffic move its turn probabilities
//! toward the turns the cars took; the learned world keeps the same roads and flies; bad
//! input is named.

use std::path::{Path, PathBuf};
use std::process::Output;

use infotrack::config::{Config, RoadConfig};
use infotrack::frames::Enu2;
use infotrack::world::road::RoadNetwork;
use rand::SeedableRng;

mod common;

use common::{infotrack_in_project as infotrack, output_text as text};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The drawn town of `tests/fixtures/osm/town.osm` imported into `dir`: its config.
fn import_town(dir: &Path) -> PathBuf {
    let o = infotrack(&[
        "world",
        "import",
        "--osm",
        "tests/fixtures/osm/town.osm",
        "--bbox",
        "8.538673,47.389100,8.547961,47.395399",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    dir.join("town.toml")
}

/// The roads with every node's first exit taken 9 times in 10 (the rest share the tenth).
fn favouring_the_first_exit(road: &RoadConfig) -> RoadConfig {
    let mut r = road.clone();
    for from in r.nodes.iter().map(|n| n.id) {
        let exits: Vec<usize> = (0..r.edges.len())
            .filter(|&k| r.edges[k].from == from)
            .collect();
        for (j, &k) in exits.iter().enumerate() {
            r.edges[k].p = match (j, exits.len()) {
                (_, 1) => 1.0,
                (0, _) => 0.9,
                (_, n) => 0.1 / (n - 1) as f64,
            };
        }
    }
    r
}

/// `n` cars that drive `road` for 60 s at 8 m/s from its start, as CSV files in world ENU
/// in `dir`.
fn write_tracks(road: &RoadConfig, dir: &Path, n: usize) -> Vec<PathBuf> {
    let net = RoadNetwork::from_config(road).unwrap();
    let start = net.nodes[net.start].position_enu;
    let first = net.nodes[net.nodes[net.start].next[0].0].position_enu;
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let distances: Vec<f64> = (0..60).map(|k| 1.0 + 8.0 * k as f64).collect();
    (0..n)
        .map(|i| {
            let route = net
                .drive(&start, Some(first - start), &distances, &mut rng)
                .unwrap();
            let mut csv = String::from("t_s,x_m,y_m\n");
            for (k, (p, _)) in route.iter().enumerate() {
                csv += &format!("{k},{:.2},{:.2}\n", p.x, p.y);
            }
            let file = dir.join(format!("car-{i:03}.csv"));
            std::fs::write(&file, csv).unwrap();
            file
        })
        .collect()
}

fn learn(config: &Path, tracks: &[PathBuf], name: &str) -> Output {
    let mut args = vec!["world", "learn", "--config", config.to_str().unwrap()];
    for t in tracks {
        args.extend(["--track", t.to_str().unwrap()]);
    }
    args.extend(["--name", name]);
    infotrack(&args)
}

/// A directed edge's ends (east, north of each, cm) and its probability.
type EdgeAt = ((i64, i64, i64, i64), f64);

/// Each directed edge's probability by its ends' positions (metres, rounded to 1 cm).
fn by_position(road: &RoadConfig) -> Vec<EdgeAt> {
    let at = |id: u32| {
        let n = road.nodes.iter().find(|n| n.id == id).unwrap();
        (
            (n.x_m * 100.0).round() as i64,
            (n.y_m * 100.0).round() as i64,
        )
    };
    let mut out: Vec<_> = road
        .edges
        .iter()
        .map(|e| {
            let (a, b) = (at(e.from), at(e.to));
            ((a.0, a.1, b.0, b.1), e.p)
        })
        .collect();
    out.sort_by_key(|e| e.0);
    out
}

#[test]
fn tracks_that_favour_one_exit_teach_the_world_to_and_it_keeps_its_roads() {
    let dir = tempfile::tempdir().unwrap();
    let config = import_town(dir.path());
    let map = Config::load(&config).unwrap().road;
    let truth = favouring_the_first_exit(&map);
    let tracks = write_tracks(&truth, dir.path(), 200);
    let o = learn(&config, &tracks, "town-learned");
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains("200 tracks") && said.contains("turns counted"),
        "{said}"
    );
    let learned = Config::load(&dir.path().join("town-learned.toml")).unwrap();
    // The same roads: the same directed edges between the same places.
    let (was, now, want) = (
        by_position(&map),
        by_position(&learned.road),
        by_position(&truth),
    );
    let ends = |v: &[EdgeAt]| v.iter().map(|e| e.0).collect::<Vec<_>>();
    assert_eq!(ends(&was), ends(&now));
    // Where the cars had a choice, the favoured exit is now the likelier one.
    let favoured: Vec<(f64, f64)> = want
        .iter()
        .zip(&now)
        .zip(&was)
        .filter(|((w, _), m)| (w.1 - 0.9).abs() < 1e-12 && m.1 < 0.9)
        .map(|((_, n), m)| (m.1, n.1))
        .collect();
    // (Junctions the cars never reached keep the map's probabilities.)
    assert!(favoured.len() >= 3, "{favoured:?}");
    assert!(
        favoured.iter().all(|(map, learned)| learned >= map),
        "{favoured:?}"
    );
    assert!(
        favoured
            .iter()
            .any(|(map, learned)| *map <= 0.5 && *learned > 0.8),
        "{favoured:?}"
    );
    // Everything but the roads is as it was, and the learned world flies.
    assert_eq!(learned.occlusions.len(), 2);
    assert_eq!(learned.name, "town-learned");
    let o = infotrack(&[
        "sim",
        "--config",
        dir.path().join("town-learned.toml").to_str().unwrap(),
        "--runs",
        "1",
        "--duration",
        "20",
        "--guidance",
        "truth",
        "--motion",
        "cv",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

/// The point of a 10 m grid over the workspace (less 10 m along its edges) farthest from
/// every road; it must be more than 30 m from them.
fn farthest_from_the_roads(cfg: &Config) -> (f64, f64) {
    let net = RoadNetwork::from_config(&cfg.road).unwrap();
    let ws = &cfg.workspace_enu;
    let (nx, ny) = (
        ((ws.x_max_m - ws.x_min_m) / 10.0) as usize,
        ((ws.y_max_m - ws.y_min_m) / 10.0) as usize,
    );
    let grid = (1..nx).flat_map(|i| (1..ny.saturating_sub(2)).map(move |j| (i, j)));
    let at = |(i, j): (usize, usize)| (ws.x_min_m + 10.0 * i as f64, ws.y_min_m + 10.0 * j as f64);
    let far = |p: &(f64, f64)| net.distance_to_roads(&Enu2::new(p.0, p.1));
    let best = grid
        .map(at)
        .max_by(|a, b| far(a).total_cmp(&far(b)))
        .unwrap();
    assert!(far(&best) > 30.0, "{best:?}");
    best
}

#[test]
fn tracks_elsewhere_bad_rows_bad_names_and_worlds_without_a_geojson_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let config = import_town(dir.path());
    // A car in the workspace's place farthest from every road matches nothing.
    let far = dir.path().join("far.csv");
    let (x, y) = farthest_from_the_roads(&Config::load(&config).unwrap());
    let rows: String = (0..3)
        .map(|k| format!("{k},{x},{}\n", y + 5.0 * k as f64))
        .collect();
    std::fs::write(&far, format!("t_s,x_m,y_m\n{rows}")).unwrap();
    let o = learn(&config, &[far], "x");
    assert!(
        !o.status.success() && text(&o).contains("no turn was matched"),
        "{}",
        text(&o)
    );
    // A row that goes back in time names the file and the line.
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "t_s,x_m,y_m\n0,0,0\n2,10,0\n1,20,0\n").unwrap();
    let said = text(&learn(&config, &[bad], "x"));
    assert!(
        said.contains("--track") && said.contains("bad.csv") && said.contains("line 4"),
        "{said}"
    );
    let some = write_tracks(&Config::load(&config).unwrap().road, dir.path(), 1);
    let said = text(&learn(&config, &some, "../elsewhere"));
    assert!(said.contains("--name \"../elsewhere\""), "{said}");
    // A config whose roads are ENU metres in the config itself has no world file to copy.
    let said = text(&learn(&root().join("config/outdoor.toml"), &some, "x"));
    assert!(
        said.contains("needs a config whose roads come from [world] geojson"),
        "{said}"
    );
}
