//! A flight folder explains itself: the config as loaded, what flew (version, commit, seed,
//! vehicle, the hashes of the files read), when and how it ended, the daemon's log and every
//! figure of the end table; `replay FOLDER` needs no other argument; a start that fails
//! leaves a folder that says so.

use std::path::Path;
use std::process::{Command, Output};

use sha2::{Digest, Sha256};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn infotrack(cwd: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn sha256_hex(path: &Path) -> String {
    Sha256::digest(std::fs::read(path).unwrap())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// `infotrack run --quiet --out FOLDER` with `args`, from the repository.
fn run_into(folder: &Path, args: &[&str]) -> Output {
    let mut all = vec!["run", "--quiet", "--out", folder.to_str().unwrap()];
    all.extend_from_slice(args);
    infotrack(root(), &all)
}

/// `infotrack replay FOLDER` from `cwd`: whether it succeeded, and what it printed (stdout
/// then stderr).
fn replayed(cwd: &Path, folder: &Path) -> (bool, String) {
    let o = infotrack(cwd, &["replay", folder.to_str().unwrap()]);
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    (o.status.success(), said)
}

/// The `a/b` of the table's "frames with tag" column.
fn frames_with_tag(table: &str) -> (u64, u64) {
    let header = table
        .lines()
        .position(|l| l.contains("frames with tag"))
        .unwrap();
    let row = table.lines().nth(header + 2).unwrap();
    let cell = row.split('|').map(str::trim).nth(5).unwrap();
    let (a, b) = cell.split_once('/').unwrap();
    (a.parse().unwrap(), b.parse().unwrap())
}

/// A closed-loop flight over the shipped Helsinki world (a GeoJSON world placed on the
/// globe) leaves a folder from which everything about it can be told, and which replays
/// identically from another directory with no other argument.
#[test]
fn a_flight_folder_explains_itself_and_replays_alone() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("flight");
    let config = root().join("config/helsinki/helsinki.toml");
    let o = infotrack(
        root(),
        &[
            "sim",
            "--closed-loop",
            "--config",
            config.to_str().unwrap(),
            "--duration",
            "20",
            "--motion",
            "cv",
            "--seed",
            "5",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );

    let manifest = json(&out.join("flight.json"));
    assert_eq!(manifest["outcome"], "flown", "{manifest}");
    assert_eq!(manifest["seed"], 5);
    assert_eq!(manifest["motion"], "cv");
    assert_eq!(manifest["flavour"], "px4");
    assert_eq!(manifest["stopped_by"], "Duration");
    let version = String::from_utf8(infotrack(root(), &["--version"]).stdout).unwrap();
    let commit = manifest["infotrack"]["commit"].as_str().unwrap();
    assert!(
        version.contains(commit)
            && version.contains(manifest["infotrack"]["version"].as_str().unwrap()),
        "{version} vs {manifest}"
    );
    assert!(manifest["started_utc"].as_str().unwrap() <= manifest["ended_utc"].as_str().unwrap());
    let geojson = root().join("config/helsinki/helsinki.geojson");
    let hashed = manifest["files"].as_array().unwrap();
    let world = hashed
        .iter()
        .find(|f| f["role"] == "world.geojson")
        .unwrap();
    assert_eq!(world["sha256"], sha256_hex(&geojson));
    let source = hashed.iter().find(|f| f["role"] == "config").unwrap();
    assert_eq!(source["sha256"], sha256_hex(&config));

    // The config as loaded loads again, and means the same: printed, it is what was written.
    let written = std::fs::read_to_string(out.join("config.toml")).unwrap();
    let printed = infotrack(
        dir.path(),
        &[
            "config",
            "--config",
            out.join("config.toml").to_str().unwrap(),
        ],
    );
    assert!(
        printed.status.success(),
        "{}",
        String::from_utf8_lossy(&printed.stderr)
    );
    let body: String = written
        .lines()
        .skip_while(|l| l.starts_with('#') || l.is_empty())
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(String::from_utf8(printed.stdout).unwrap(), body);

    let log = std::fs::read_to_string(out.join("daemon.log")).unwrap();
    assert!(
        log.contains("tracking started") && log.contains("INFO"),
        "{log}"
    );

    // Every figure of the end table is in summary.json.
    let summary = json(&out.join("summary.json"));
    let flight = &summary["flight"];
    let (tagged, frames) = frames_with_tag(&stdout);
    assert_eq!(
        (
            flight["frames_with_tag"].as_u64(),
            flight["frames"].as_u64()
        ),
        (Some(tagged), Some(frames)),
        "{flight}"
    );
    for key in [
        "guidance_overruns",
        "link_losses",
        "geofence_refusals",
        "filter_periods_without_frame",
        "filter_steps",
    ] {
        assert!(flight[key].is_u64(), "{key}: {flight}");
    }
    for key in [
        "frame_to_setpoint_ms",
        "detection_ms",
        "filter_ms",
        "guidance_ms",
    ] {
        assert!(
            flight[key]["p50"].as_f64().unwrap() <= flight[key]["p99"].as_f64().unwrap(),
            "{key}: {flight}"
        );
    }
    assert!(
        flight["final_mode"].as_str().unwrap().starts_with("HOLD"),
        "{flight}"
    );
    assert!(
        flight["resources"]["peak_resident_memory_mb"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert!(summary["fov_percent"].is_number());

    let (ok, said) = replayed(dir.path(), &out);
    assert!(
        ok && said.contains("(the flight's own)") && said.contains("(identical)"),
        "{said}"
    );
}

/// A start refused before take-off leaves a folder marked failed, with the reason, and a
/// replay of it says that instead of what its empty records lack.
#[test]
fn a_start_that_fails_leaves_a_folder_that_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("flight");
    let o = run_into(
        &out,
        &[
            "--vehicle",
            "tcpout:127.0.0.1:1",
            "--allow-simulation-on-vehicle",
        ],
    );
    assert!(!o.status.success());
    let manifest = json(&out.join("flight.json"));
    assert_eq!(manifest["outcome"], "failed", "{manifest}");
    assert!(
        manifest["failure"]
            .as_str()
            .unwrap()
            .contains("refusing to arm"),
        "{manifest}"
    );
    assert!(manifest["ended_utc"].is_string());
    let (ok, err) = replayed(dir.path(), &out);
    assert!(
        !ok && err.contains("failed before it flew") && err.contains("refusing to arm"),
        "{err}"
    );
}

/// A folder without config.toml (written before folders carried one) is replayed with the
/// embedded default, and the replay says so.
#[test]
fn a_folder_without_its_config_is_replayed_with_the_default_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("flight");
    let o = run_into(&out, &["--duration", "6", "--motion", "cv"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::remove_file(out.join("config.toml")).unwrap();
    let (ok, said) = replayed(dir.path(), &out);
    assert!(
        ok && said.contains("the embedded default") && said.contains("has no config.toml"),
        "{said}"
    );
}
