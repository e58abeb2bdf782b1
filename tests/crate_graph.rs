//! The crate graph is the architecture: what each workspace crate depends on (from
//! `cargo metadata`) is what ARCHITECTURE.md draws, and the core depends on data crates
//! only and touches no file, socket, process or environment.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

type Graph = BTreeMap<String, BTreeSet<String>>;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// `cargo metadata` of the workspace, without resolving the dependencies' own.
fn metadata() -> serde_json::Value {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--no-deps",
            "--format-version",
            "1",
            "--offline",
        ])
        .current_dir(root())
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("cargo metadata prints JSON")
}

/// Each package's normal (not dev, not build) dependencies, by name.
fn normal_dependencies(meta: &serde_json::Value) -> Graph {
    let mut graph = Graph::new();
    for p in meta["packages"].as_array().unwrap() {
        let deps = p["dependencies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| d["kind"].is_null())
            .map(|d| d["name"].as_str().unwrap().to_string())
            .collect();
        graph.insert(p["name"].as_str().unwrap().to_string(), deps);
    }
    graph
}

/// The graph drawn in ARCHITECTURE.md: the fenced block after the line that names this
/// test, one `crate -> dependency ...` line per crate.
fn drawn_graph() -> Graph {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let after = text
        .split("<!-- the crate graph, checked by tests/crate_graph.rs -->")
        .nth(1)
        .expect("ARCHITECTURE.md draws the crate graph");
    let block = after.split("```").nth(1).expect("a fenced block");
    block
        .lines()
        .filter_map(|l| l.split_once("->"))
        .map(|(name, deps)| {
            let deps = deps.split_whitespace().map(str::to_string).collect();
            (name.trim().to_string(), deps)
        })
        .collect()
}

#[test]
fn the_workspace_crates_depend_on_each_other_as_architecture_md_draws() {
    let workspace: Graph = normal_dependencies(&metadata())
        .into_iter()
        .map(|(name, deps)| {
            let ours = deps
                .into_iter()
                .filter(|d| d.starts_with("infotrack"))
                .collect();
            (name, ours)
        })
        .collect();
    let drawn = drawn_graph();
    assert_eq!(
        workspace, drawn,
        "cargo metadata (left) against ARCHITECTURE.md (right)"
    );
    // Not vacuous: the core, the shells and the program are all drawn.
    assert!(drawn.len() >= 8 && drawn["infotrack-core"].is_empty());
}

#[test]
fn the_core_depends_on_numeric_and_data_crates_only() {
    const DATA_CRATES: &[&str] = &[
        "map_3d",
        "nalgebra",
        "petgraph",
        "rand",
        "rand_chacha",
        "rand_distr",
        "rstar",
        "serde",
        "sha2",
        "statrs",
        "thiserror",
        "toml",
        "tracing",
    ];
    const IO_CRATES: &[&str] = &[
        "tokio",
        "tokio-serial",
        "mavlink",
        "opencv",
        "ort",
        "apriltag",
        "apriltag-sys",
        "libc",
        "plotters",
        "rayon",
        "infotrack-files",
    ];
    let graph = normal_dependencies(&metadata());
    let core = &graph["infotrack-core"];
    for dep in core {
        assert!(
            DATA_CRATES.contains(&dep.as_str()),
            "the core depends on {dep}"
        );
        assert!(!IO_CRATES.contains(&dep.as_str()));
    }
    assert!(core.contains("nalgebra"), "{core:?}");
}

#[test]
fn nothing_the_core_or_its_tests_build_on_needs_opencv_onnx_runtime_tokio_or_mavlink() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "tree",
            "-p",
            "infotrack-core",
            "-e",
            "normal,dev",
            "--prefix",
            "none",
        ])
        .args(["--offline", "--format", "{p}"])
        .current_dir(root())
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let tree = String::from_utf8_lossy(&out.stdout);
    let crates: BTreeSet<&str> = tree
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    for io in [
        "opencv",
        "ort",
        "ort-sys",
        "tokio",
        "mavlink",
        "apriltag-sys",
        "infotrack-files",
    ] {
        assert!(!crates.contains(io), "the core's build pulls in {io}");
    }
    assert!(
        crates.contains("nalgebra") && crates.contains("proptest"),
        "{crates:?}"
    );
}

/// Whether `text` names `path` as a path of its own: not as the end of a longer name
/// (`effort::` is not `ort::`, `MyFile::` not `File::`).
fn uses(text: &str, path: &str) -> bool {
    text.match_indices(path).any(|(i, _)| {
        !text[..i]
            .chars()
            .next_back()
            .is_some_and(|c| c.is_alphanumeric() || c == '_')
    })
}

#[test]
fn the_scan_tells_a_path_from_the_end_of_a_longer_name() {
    assert!(uses("use ort::session;", "ort::"));
    assert!(uses("(ort::Error)", "ort::"));
    assert!(!uses("let e = effort::Effort::default();", "ort::"));
    assert!(!uses("MyFile::open", "File::"));
    assert!(uses("std::fs::read", "std::fs"));
}

#[test]
fn no_core_source_touches_files_sockets_processes_or_the_environment() {
    const IO_PATHS: &[&str] = &[
        "std::fs",
        "std::net",
        "std::process",
        "std::env",
        "File::",
        "TcpStream",
        "UdpSocket",
        "tokio",
        "opencv",
        "mavlink",
        "ort::",
    ];
    let mut files = vec![root().join("crates/infotrack-core/src")];
    let mut checked = 0;
    while let Some(p) = files.pop() {
        if p.is_dir() {
            files.extend(std::fs::read_dir(&p).unwrap().map(|e| e.unwrap().path()));
            continue;
        }
        let text = std::fs::read_to_string(&p).unwrap();
        for path in IO_PATHS {
            assert!(!uses(&text, path), "{} uses {path}", p.display());
        }
        checked += 1;
    }
    assert!(checked > 40, "only {checked} files of the core were read");
}

/// The flight daemon lives in the program's crate beside the wiring; it must reach the
/// mock autopilot and the simulator only through the parts the program hands it
/// (`daemon::simulators`), so a field build's daemon cannot fly a simulated part by itself.
#[test]
fn the_daemon_imports_neither_the_mock_nor_the_simulator() {
    const SIMULATED: &[&str] = &[
        "crate::mock",
        "crate::sim",
        "crate::simulated",
        "crate::render",
        "crate::report",
        "crate::wiring",
        "infotrack_mock",
        "infotrack_sim",
    ];
    let dir = root().join("src/daemon");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let p = entry.unwrap().path();
        let text = std::fs::read_to_string(&p).unwrap();
        for path in SIMULATED {
            for (i, line) in text.lines().enumerate() {
                let code = line.split("//").next().unwrap_or("");
                assert!(
                    !code.contains(&format!("{path}::")) && !code.contains(&format!("{path};")),
                    "{}:{}: {line}",
                    p.display(),
                    i + 1
                );
            }
        }
        checked += 1;
    }
    assert!(
        checked >= 15,
        "only {checked} files of the daemon were read"
    );
}
