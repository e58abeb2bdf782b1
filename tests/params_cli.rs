//! `infotrack params check|apply` against `infotrack mock-autopilot` in another process,
//! over UDP, with the shipped parameter files of both formats.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;
use common::{free_udp_port, mock_process, MockProcess};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_infotrack"))
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn mock(flavor: &str) -> (MockProcess, u16) {
    let port = free_udp_port();
    (mock_process(flavor, port, None), port)
}

fn params(action: &str, file: &Path, port: u16) -> Output {
    bin()
        .args(["params", action])
        .arg(file)
        .args([
            "--connect",
            &format!("udpout:127.0.0.1:{port}"),
            "--timeout",
            "5",
        ])
        .output()
        .unwrap()
}

fn round_trip(flavor: &str, file: &str) {
    let (_m, port) = mock(flavor);
    let file = root().join(file);
    let before = params("check", &file, port);
    let out = String::from_utf8_lossy(&before.stdout);
    assert!(
        !before.status.success(),
        "defaults differ from the file:\n{out}"
    );
    assert!(out.contains("MISMATCH"), "{out}");
    let applied = params("apply", &file, port);
    let out = String::from_utf8_lossy(&applied.stdout);
    assert!(
        applied.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&applied.stderr)
    );
    assert!(out.contains("applied") && !out.contains("FAILED"), "{out}");
    assert!(out.contains("reboot the autopilot now"), "{out}");
    let after = params("check", &file, port);
    let out = String::from_utf8_lossy(&after.stdout);
    assert!(after.status.success(), "{out}");
    assert!(
        !out.contains("MISMATCH") && out.contains("not as the file says"),
        "{out}"
    );
}

#[test]
fn px4_params_file_check_apply_check() {
    round_trip("px4", "firmware-params/px4-offboard-tracking.params");
}

#[test]
fn ardupilot_parm_file_check_apply_check() {
    round_trip(
        "ardupilot",
        "firmware-params/ardupilot-guided-tracking.parm",
    );
}

#[test]
fn a_parameter_the_vehicle_lacks_is_reported_not_skipped() {
    let (_m, port) = mock("ardupilot");
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("x.parm");
    std::fs::write(&f, "GUID_TIMEOUT,2\nNOT_A_PARAM,1\n").unwrap();
    let o = params("apply", &f, port);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success());
    assert!(
        out.contains("NOT_A_PARAM") && out.contains("NOT ON VEHICLE"),
        "{out}"
    );
    // All or nothing: the parameter the vehicle has is not written either.
    assert!(
        out.contains("GUID_TIMEOUT") && out.contains("not written") && !out.contains("applied"),
        "{out}"
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("nothing was written"), "{err}");
    let only = dir.path().join("only.parm");
    std::fs::write(&only, "GUID_TIMEOUT,2\n").unwrap();
    let o = params("check", &only, port);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("MISMATCH"),
        "still the vehicle's own value:\n{out}"
    );
}

#[test]
fn a_malformed_line_names_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("bad.params");
    std::fs::write(&f, "# ok\n1\t1\tCOM_OF_LOSS_T\t1.0\t9\n1\t1\tBROKEN\n").unwrap();
    let o = params("check", &f, 9);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("bad.params:3") && err.contains("expected 5"),
        "{err}"
    );
}

#[test]
fn a_signed_vehicle_answers_only_a_signed_companion() {
    let dir = tempfile::tempdir().unwrap();
    let key = dir.path().join("mavlink.key");
    std::fs::write(&key, format!("# lab key\n{}\n", "3c".repeat(32))).unwrap();
    let port = free_udp_port();
    let _mock = mock_process("ardupilot", port, Some(&key));
    let file = dir.path().join("one.parm");
    std::fs::write(&file, "WPNAV_SPEED,1000\n").unwrap();
    let run = |with_key: bool| {
        let mut c = bin();
        c.args(["params", "check"]).arg(&file).args([
            "--connect",
            &format!("udpout:127.0.0.1:{port}"),
            "--timeout",
            "3",
        ]);
        if with_key {
            c.arg("--signing-key").arg(&key);
        }
        c.output().unwrap()
    };
    let unsigned = run(false);
    assert!(
        !unsigned.status.success(),
        "an unsigned companion was answered"
    );
    let err = String::from_utf8_lossy(&unsigned.stderr);
    assert!(
        err.contains("signing mismatch: the vehicle signs its messages"),
        "the cause is named: {err}"
    );
    let signed = run(true);
    assert!(
        signed.status.success(),
        "{}{}",
        String::from_utf8_lossy(&signed.stdout),
        String::from_utf8_lossy(&signed.stderr)
    );
}

/// "All or nothing": the vehicle never confirms the second parameter of the file; the first,
/// already written, is set back to the value read before, and the run says so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_write_that_fails_midway_is_rolled_back() {
    use infotrack::autopilot::modes::Flavor;
    use infotrack::mock::MockConfig;
    use mavlink::dialects::ardupilotmega::MavMessage;
    let (mock, vehicle) = common::udp_mock(MockConfig::new(Flavor::Px4)).await;
    let never_acc_hor = |m: &MavMessage| matches!(m, MavMessage::PARAM_SET(s) if s.param_id.to_str().unwrap_or("").starts_with("MPC_ACC_HOR"));
    let (_relay, front) = common::relay::relay_dropping(
        vehicle,
        Vec::new(),
        std::time::Duration::ZERO,
        never_acc_hor,
    )
    .await;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("two.params");
    std::fs::write(
        &file,
        "1\t1\tMPC_XY_VEL_MAX\t13\t9\n1\t1\tMPC_ACC_HOR\t4\t9\n",
    )
    .unwrap();
    let out = tokio::task::spawn_blocking(move || params("apply", &file, front))
        .await
        .unwrap();
    let all = common::output_text(&out);
    assert_eq!(out.status.code(), Some(1), "{all}");
    assert!(
        all.contains("failed midway")
            && all.contains("1 parameter(s) written before were set back"),
        "{all}"
    );
    assert!(all.contains("set back (a later write failed)"), "{all}");
    let now = mock.with(|m| m.params().get("MPC_XY_VEL_MAX", -1.0));
    assert_eq!(now, 12.0, "MPC_XY_VEL_MAX is back to its value before");
}

/// A name one letter off is suggested; a file for the other firmware is named as such.
#[test]
fn a_typo_and_the_other_firmwares_file_are_named() {
    let (_m, port) = mock("ardupilot");
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("typo.parm");
    std::fs::write(&f, "WPNAV_SPEEED,1500\n").unwrap();
    let o = params("check", &f, port);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("did you mean WPNAV_SPEED?"), "{out}");
    let px4_file = root().join("firmware-params/px4-offboard-tracking.params");
    let o = params("check", &px4_file, port);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("not on this ArduPilot vehicle: is the file for PX4?"),
        "{out}"
    );
}

/// `params save` downloads every parameter, in the format the extension names, and the
/// backup checks clean against the vehicle it came from.
#[test]
fn the_vehicles_parameters_are_saved_and_check_clean() {
    for (flavor, name) in [("px4", "backup.params"), ("ardupilot", "backup.parm")] {
        let (_m, port) = mock(flavor);
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join(name);
        let o = params("save", &f, port);
        let all = common::output_text(&o);
        assert!(o.status.success(), "{all}");
        let saved = infotrack::autopilot::params_file::read(&f).unwrap();
        assert!(saved.len() > 20, "{flavor}: {} parameters", saved.len());
        let o = params("check", &f, port);
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{flavor}: {out}");
        assert!(out.contains(", 0 not as the file says"), "{flavor}: {out}");
    }
}
