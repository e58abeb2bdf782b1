//! Traffic that is not ours: `scripts/sumo-traffic.py` makes a world and tracks of a car
//! that Eclipse SUMO drives among background traffic (installed into `.deps/sumo` by
//! `scripts/setup-tests.sh`), and `infotrack sim` flies the config it writes.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn sumo_python() -> PathBuf {
    let python = root().join(".deps/sumo/bin/python");
    assert!(
        python.exists(),
        "{} is missing: run `bash scripts/setup-tests.sh` (it installs Eclipse SUMO from PyPI)",
        python.display()
    );
    python
}

/// Runs the script with `args` into `out` from a scratch working folder; panics with its
/// output if it fails or leaves anything in the folder it was started from.
fn sumo_traffic(out: &Path, args: &[&str]) {
    let cwd = tempfile::tempdir().unwrap();
    let o = Command::new(sumo_python())
        .current_dir(cwd.path())
        .arg(root().join("scripts/sumo-traffic.py"))
        .args(args)
        .arg("--out")
        .arg(out)
        .args(["--infotrack", env!("CARGO_BIN_EXE_infotrack")])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let stray: Vec<_> = std::fs::read_dir(cwd.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert!(
        stray.is_empty(),
        "sumo-traffic.py wrote {stray:?} into its working folder"
    );
}

/// `infotrack sim` of `config` with the extra `args`; the results' JSON.
fn sim(config: &Path, out: &Path, args: &[&str]) -> serde_json::Value {
    let o = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .arg("sim")
        .arg("--config")
        .arg(config)
        .args(args)
        .args(["--motion", "cv", "--quiet", "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap()
}

/// The `(t_s, speed_mps)` of the vehicle `target` in a SUMO FCD file.
fn fcd_speeds(fcd: &str) -> Vec<(f64, f64)> {
    let attr = |tag: &str, name: &str| -> Option<f64> {
        let at = tag.find(&format!(" {name}=\""))? + name.len() + 3;
        tag[at..].split('"').next()?.parse().ok()
    };
    let mut t_s = f64::NAN;
    let mut out = Vec::new();
    for tag in fcd.split('<') {
        if tag.starts_with("timestep ") {
            t_s = attr(tag, "time").unwrap();
        } else if tag.starts_with("vehicle ") && tag.contains(" id=\"target\"") {
            out.push((t_s, attr(tag, "speed").unwrap()));
        }
    }
    out
}

/// On a grid netgenerate draws, each run drives its own SUMO track (run i, track i mod n),
/// cued where the track starts; flown to the true car the drone keeps it in view.
#[test]
fn a_generated_network_gives_a_world_and_tracks_the_simulator_flies() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("grid");
    let args = [
        "--netgenerate",
        "grid",
        "--junctions",
        "36",
        "--tracks",
        "2",
    ];
    sumo_traffic(
        &out,
        &[&args[..], &["--duration", "120", "--seed", "3"]].concat(),
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("traffic.json")).unwrap()).unwrap();
    let tracks = summary["tracks"].as_array().unwrap();
    assert_eq!(tracks.len(), 2, "{summary}");
    for t in tracks {
        let csv = std::fs::read_to_string(out.join(t["file"].as_str().unwrap())).unwrap();
        assert!(csv.starts_with("t_s,lon_deg,lat_deg\n"), "{csv:.80}");
        assert!(csv.lines().count() > 100, "{} rows", csv.lines().count());
    }
    let results = sim(
        &out.join("traffic.toml"),
        &dir.path().join("sim"),
        &["--runs", "2", "--guidance", "truth", "--duration", "120"],
    );
    let truth = &results["results"][0];
    assert_eq!(truth["guidance"], "truth");
    let fov = truth["fov_percent"]["mean"].as_f64().unwrap();
    assert!(
        fov > 50.0,
        "flown to the true car, it is in view {fov} % of the time"
    );
    let runs = truth["per_run"].as_array().unwrap();
    assert!(
        runs.iter().all(|r| r["first_sighting_s"].is_number()),
        "{truth}"
    );
    // Each run is named by what reproduces it: index, seed and track (run i, track i mod n).
    for (i, r) in runs.iter().enumerate() {
        assert_eq!(r["run"].as_u64(), Some(i as u64), "{r}");
        assert!(r["seed"].is_u64() && r["seed"] == results["seed"], "{r}");
        assert_eq!(r["version"], env!("CARGO_PKG_VERSION"), "{r}");
        assert!(r["world"].as_str().unwrap().ends_with(".geojson"), "{r}");
        let track = r["track"].as_str().unwrap();
        assert!(
            track.ends_with(tracks[i % 2]["file"].as_str().unwrap()),
            "{track}"
        );
    }
    let version = results["infotrack"]["version"].as_str().unwrap();
    assert_eq!(version, env!("CARGO_PKG_VERSION"));
    assert!(results["infotrack"]["commit"]
        .as_str()
        .is_some_and(|c| !c.is_empty()));
    assert!(results["config"]
        .as_str()
        .unwrap()
        .ends_with("traffic.toml"));
}

/// On a real town's streets (the Helsinki extract), SUMO's car stops at lights and behind
/// other cars, which our simulated car never does; its FCD tracks load as they are.
#[test]
fn a_town_from_openstreetmap_gives_tracks_of_a_car_that_stops() {
    let pbf = root().join(".deps/osm/Helsinki.osm.pbf");
    assert!(
        pbf.exists(),
        "{} is missing: run `bash scripts/setup.sh`",
        pbf.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("helsinki");
    let bbox = "24.934,60.163,24.955,60.18";
    let pbf = pbf.to_str().unwrap();
    let args = [
        "--osm", pbf, "--bbox", bbox, "--tracks", "2", "--name", "helsinki",
    ];
    sumo_traffic(
        &out,
        &[&args[..], &["--duration", "200", "--seed", "5"]].concat(),
    );
    let mut stopped_s = 0.0;
    for i in 0..2 {
        let fcd = std::fs::read_to_string(out.join(format!("tracks/track-{i:02}.xml"))).unwrap();
        let speeds = fcd_speeds(&fcd);
        assert!(speeds.len() > 100, "track {i}: {} samples", speeds.len());
        let top = speeds.iter().map(|s| s.1).fold(0.0, f64::max);
        assert!(
            top <= 12.0 * 1.1 + 1e-9,
            "track {i}: capped at 12 m/s, drove {top}"
        );
        stopped_s += speeds.iter().filter(|s| s.1 < 0.1).count() as f64;
    }
    assert!(stopped_s >= 5.0, "the cars stood for {stopped_s} s in all");
    let results = sim(
        &out.join("helsinki.toml"),
        &dir.path().join("sim"),
        &["--runs", "2", "--guidance", "truth", "--duration", "60"],
    );
    assert_eq!(results["results"][0]["runs"], 2, "{results}");
}
