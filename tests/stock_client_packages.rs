//! The mock flown by the stock clients themselves, installed from PyPI by `scripts/setup-tests.sh`
//! into `.deps/stock-clients` (pinned in `tests/stock_clients/requirements.txt`): MAVSDK (the
//! C++ library through its Python binding) flies the PX4 mock; pymavlink's mavutil and
//! MAVProxy's console fly the ArduPilot mock. Each client runs its script in
//! `tests/stock_clients/` against `infotrack mock-autopilot` in its own process, as it would
//! against a real autopilot, and says what failed. `tests/stock_client.rs` keeps the same
//! flights written with the mavlink crate, message by message.
//!
//! Without the virtual environment these tests fail and say how to make it: never a silent
//! skip.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;
use common::{free_udp_port, mock_process};

/// The virtual environment's Python, or a failure that says how to make it.
fn stock_python() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = root.join(".deps/stock-clients/bin/python");
    assert!(
        python.exists(),
        "{} is missing: run `bash scripts/setup-tests.sh` (it installs MAVSDK, pymavlink and MAVProxy \
         from PyPI into .deps/stock-clients)",
        python.display()
    );
    python
}

/// Runs `tests/stock_clients/SCRIPT PORT [WORKDIR]` with the stock clients' Python.
fn run_client(script: &str, port: u16, workdir: Option<&Path>) -> Output {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut c = Command::new(stock_python());
    c.arg(root.join("tests/stock_clients").join(script))
        .arg(port.to_string());
    if let Some(w) = workdir {
        c.arg(w);
    }
    c.output().unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "exit {:?}\n--- stdout\n{}\n--- stderr\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn assert_flew(o: &Output, client: &str) {
    let all = text(o);
    println!("{all}");
    assert!(
        o.status.success(),
        "{client} failed against the mock\n{all}"
    );
    assert!(
        String::from_utf8_lossy(&o.stdout).contains(&format!("{client}: OK")),
        "{client} did not finish its flight\n{all}"
    );
}

#[test]
fn mavsdk_flies_the_px4_mock() {
    let port = free_udp_port();
    let _mock = mock_process("px4", port, None);
    let o = run_client("mavsdk_px4.py", port, None);
    assert_flew(&o, "mavsdk");
    let out = String::from_utf8_lossy(&o.stdout);
    // MAVSDK's own telemetry said what the steps need: health, home, the climb, the move,
    // and the landed state after the disarm.
    for step in [
        "health all OK",
        "home lat",
        "airborne",
        "moved north",
        "landed state ON_GROUND",
    ] {
        assert!(out.contains(step), "no `{step}`\n{}", text(&o));
    }
}

#[test]
fn pymavlink_flies_the_ardupilot_mock() {
    let port = free_udp_port();
    let _mock = mock_process("ardupilot", port, None);
    let o = run_client("pymavlink_ardupilot.py", port, None);
    assert_flew(&o, "pymavlink");
    let out = String::from_utf8_lossy(&o.stdout);
    for step in [
        "position lat",
        "GUIDED",
        "armed",
        "airborne",
        "moved north",
        "disarmed on touchdown",
    ] {
        assert!(out.contains(step), "no `{step}`\n{}", text(&o));
    }
}

#[test]
fn mavproxy_flies_the_ardupilot_mock() {
    let port = free_udp_port();
    let _mock = mock_process("ardupilot", port, None);
    let dir = tempfile::tempdir().unwrap();
    let o = run_client("mavproxy_ardupilot.py", port, Some(dir.path()));
    assert_flew(&o, "mavproxy");
}
