//! The version `infotrack --version` prints is the newest release CHANGELOG.md describes
//! (above it, an `[Unreleased]` section may collect what the next release will bring).

use std::process::Command;

#[test]
fn the_version_is_the_changelogs_newest_release() {
    let root = env!("CARGO_MANIFEST_DIR");
    let log = std::fs::read_to_string(format!("{root}/CHANGELOG.md")).unwrap();
    let newest = log
        .lines()
        .filter_map(|l| l.strip_prefix("## ["))
        .filter_map(|l| l.split(']').next())
        .find(|name| *name != "Unreleased")
        .expect("CHANGELOG.md names a release as `## [X.Y.Z] - DATE`");
    assert_eq!(newest, env!("CARGO_PKG_VERSION"));
    let out = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .arg("--version")
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.starts_with(&format!("infotrack {newest} (")), "{said}");
}
