//! Layers point down only. The check reads the source: every `crate::` / `super::` path in
//! a module's non-test code must name a module its layer may use. Test code (a `tests.rs`
//! file or what follows `#[cfg(test)]` in a file) may use anything: the lab scenario comes
//! from the configuration.

use std::collections::BTreeSet;
use std::path::Path;

/// The core: pure, synchronous, no I/O layer.
const CORE: &[&str] = &[
    "frames",
    "geodesy",
    "world",
    "motion",
    "estimation",
    "guidance",
    "tracker",
    "metrics",
    "rng",
];

/// What each layer may import, besides itself.
fn allowed(layer: &str) -> Vec<&'static str> {
    let core = CORE.to_vec();
    let with = |extra: &[&'static str]| -> Vec<&'static str> {
        core.iter().copied().chain(extra.iter().copied()).collect()
    };
    match layer {
        l if CORE.contains(&l) => core,
        // Reading a user's file without trusting it: a shell of its own, below the others.
        "bounded_file" => Vec::new(),
        "vision" => with(&["bounded_file"]),
        // Recorded target tracks: files read into world ENU, for the config to check and the
        // simulated target to drive.
        "recorded_track" => with(&["bounded_file"]),
        // Validation checks vehicle URLs with the link's own parser.
        "config" => with(&["vision", "autopilot", "bounded_file", "recorded_track"]),
        // The vehicle link: never the mock, the simulator or the daemon.
        "autopilot" => with(&["bounded_file"]),
        "mock" => with(&["autopilot"]),
        "simulated" => with(&["vision", "config", "recorded_track"]),
        "report" => with(&["config", "sim", "simulated"]),
        "sim" => with(&["vision", "config", "simulated", "report"]),
        // The daemon uses the simulated sources, never the simulator's internals.
        "daemon" => with(&[
            "vision",
            "config",
            "simulated",
            "autopilot",
            "mock",
            "report",
        ]),
        other => panic!("module `{other}` has no layer: add it to tests/layers.rs"),
    }
}

/// The top-level modules a file's non-test code names.
fn imports(text: &str, own: &str) -> BTreeSet<String> {
    let code = text.split("#[cfg(test)]").next().unwrap_or("");
    let mut found = BTreeSet::new();
    for line in code.lines() {
        let line = line.trim_start();
        if line.starts_with("//") {
            continue;
        }
        let mut rest = line;
        while let Some(i) = rest.find("crate::") {
            rest = &rest[i + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() && name != own {
                found.insert(name);
            }
        }
    }
    found
}

fn files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") && p.file_name().unwrap() != "tests.rs" {
            out.push(p);
        }
    }
}

#[test]
fn every_layer_imports_only_layers_below_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut all = Vec::new();
    files(&src, &mut all);
    let mut violations = Vec::new();
    let mut checked = 0;
    for f in &all {
        let rel = f.strip_prefix(&src).unwrap();
        let top = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_str()
            .unwrap();
        let layer = top.trim_end_matches(".rs");
        // The binary (main.rs, cli/) and the crate root may use everything.
        if ["main", "lib", "cli"].contains(&layer) {
            continue;
        }
        checked += 1;
        let ok = allowed(layer);
        for m in imports(&std::fs::read_to_string(f).unwrap(), layer) {
            if !ok.contains(&m.as_str()) {
                violations.push(format!("{} imports crate::{m}", rel.display()));
            }
        }
    }
    assert!(checked > 60, "only {checked} files checked");
    assert!(violations.is_empty(), "{}", violations.join("\n"));
}

#[test]
fn the_check_sees_a_violation() {
    // A core file that imported the vehicle link would be caught.
    let text = "use crate::autopilot::link::VehicleLink;\nuse crate::world::World;\n";
    let found = imports(text, "tracker");
    assert!(found.contains("autopilot") && !allowed("tracker").contains(&"autopilot"));
    // Test code is not counted.
    let text = "use crate::world::World;\n#[cfg(test)]\nmod t { use crate::config::Config; }";
    assert!(!imports(text, "tracker").contains("config"));
}
