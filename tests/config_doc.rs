//! docs/src/config.md, the reference of every config key, is what `scripts/config-doc.py`
//! generates from the config structs (doc comments, the lab's values, the bounds): a key
//! added, renamed or re-documented without regenerating it fails here.

use std::process::Command;

#[test]
fn the_config_reference_matches_the_code() {
    let root = env!("CARGO_MANIFEST_DIR");
    let out = Command::new("python3")
        .arg(format!("{root}/scripts/config-doc.py"))
        .arg("--check")
        .arg("--bin")
        .arg(env!("CARGO_BIN_EXE_infotrack"))
        .output()
        .expect("python3 runs scripts/config-doc.py (scripts/setup.sh needs it too)");
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    // Not vacuous: the reference names the keys an operator edits most.
    let doc = std::fs::read_to_string(format!("{root}/docs/src/config.md")).unwrap();
    for key in [
        "`daemon.engage`",
        "`daemon.vehicle`",
        "`daemon.calibration`",
        "`acquisition.cue_radius_m`",
        "`filter.particles`",
        "`vision.detector.decimation`",
    ] {
        assert!(doc.contains(key), "{key} missing from docs/src/config.md");
    }
}
