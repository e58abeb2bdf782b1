//! `scripts/install.sh --destdir`: the installed program finds ONNX Runtime beside itself
//! (no `.deps`, no ORT_DYLIB_PATH), the installed configs find their models, the unit runs
//! as the dedicated user with the journal-friendly logging, and a flight on the mock leaves
//! its logs in a per-flight folder under the installed log directory.

mod common;

use std::path::PathBuf;

use common::output_text;
use std::process::Command;

#[test]
fn install_into_a_destdir_gives_a_program_that_flies_the_mock_and_keeps_its_logs() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dest = tempfile::tempdir().unwrap();
    let d = dest.path();
    let out = Command::new("bash")
        .arg(root.join("scripts/install.sh"))
        .arg("--destdir")
        .arg(d)
        .arg("--binary")
        .arg(env!("CARGO_BIN_EXE_infotrack"))
        .output()
        .unwrap();
    let said = output_text(&out);
    assert!(out.status.success(), "{said}");
    let lib = d.join("usr/local/lib/infotrack");
    assert!(lib.join("infotrack").is_file());
    assert!(lib.join("libonnxruntime.so.1.31.1").is_file());
    for f in [
        "config/px4.toml",
        "config/ardupilot.toml",
        "config/default.toml",
        "config/camera-example.yaml",
        "models/dmmn.onnx",
        "models/outdoor/dmmn.onnx",
        "models/outdoor/dmmn.json",
    ] {
        assert!(
            d.join("etc/infotrack").join(f).is_file(),
            "{f} not installed"
        );
    }
    let unit = std::fs::read_to_string(d.join("etc/systemd/system/infotrack.service")).unwrap();
    for line in [
        "User=infotrack",
        "Environment=RUST_LOG=info",
        "WorkingDirectory=/etc/infotrack",
        "--log-dir /var/lib/infotrack/flights",
    ] {
        assert!(unit.contains(line), "the unit lacks `{line}`:\n{unit}");
    }

    // The installed program, from its own folder, with no hint where ONNX Runtime is: the
    // lab flight with the learned model on the mock, logs under the installed log folder.
    let flights = d.join("var/lib/infotrack/flights");
    let run = Command::new(d.join("usr/local/bin/infotrack"))
        .args(["run", "--quiet", "--duration", "4", "--motion", "dmmn"])
        .arg("--config")
        .arg(d.join("etc/infotrack/config/default.toml"))
        .arg("--log-dir")
        .arg(&flights)
        .args(["--log", "infotrack=info"])
        .env_remove("ORT_DYLIB_PATH")
        .current_dir(d.join("etc/infotrack"))
        .output()
        .unwrap();
    let said = output_text(&run);
    assert!(run.status.success(), "{said}");
    assert!(
        said.contains(&format!(
            "ONNX Runtime loaded from {}",
            lib.join("libonnxruntime.so.1.31.1").display()
        )),
        "{said}"
    );
    let folders: Vec<_> = std::fs::read_dir(&flights)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(folders.len(), 1, "{folders:?}");
    for f in ["flight.csv", "steps.csv", "link.tlog", "summary.json"] {
        assert!(
            folders[0].join(f).is_file(),
            "{f} missing in {:?}",
            folders[0]
        );
    }
    // No colour codes when not on a terminal (the journal).
    assert!(!said.contains('\u{1b}'), "ANSI codes in piped output");
}
