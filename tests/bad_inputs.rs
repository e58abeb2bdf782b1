//! The catalogue of bad inputs, one test each, against the real `infotrack` binary: command
//! line numbers, configs, parameter files, flight logs and images that a careless operator
//! or a corrupted disk produces. Each must end in a clear error that names what is wrong and
//! where, with the expected exit code, quickly, and never in a panic, an abort or a hang.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use opencv::prelude::*;
use std::time::{Duration, Instant};

use common::output_text;

/// The longest any bad input may take to be refused: far beyond a clear error's
/// milliseconds, far below a hang.
const PROMPT: Duration = Duration::from_secs(60);

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `infotrack args`, killing it if it outlives [`PROMPT`].
fn infotrack(args: &[&str]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_infotrack"))
        .args(args)
        .current_dir(root())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let began = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if began.elapsed() > PROMPT {
            let _ = child.kill();
            panic!("infotrack {args:?} hangs: still running after {PROMPT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// `infotrack args` exits with `code`, says `needle` on stderr and does not panic.
fn refused(args: &[&str], code: i32, needle: &str) {
    let out = infotrack(args);
    let all = output_text(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{args:?}: {all}");
    assert!(!stderr.contains("panicked"), "{args:?}: {all}");
    assert!(
        stderr.to_lowercase().contains(&needle.to_lowercase()),
        "{args:?} should say `{needle}`: {all}"
    );
}

/// The lab config with the dotted `key` (any depth) set to the TOML literal `value`.
fn lab_with(dir: &Path, key: &str, value: &str) -> PathBuf {
    let lab = dir.join("lab.toml");
    std::fs::copy(root().join("config/default.toml"), &lab).unwrap();
    lab_with_file(&lab, key, value)
}

/// The config `file` with the dotted `key` set to the TOML literal `value`, written beside it.
fn lab_with_file(file: &Path, key: &str, value: &str) -> PathBuf {
    let dir = file.parent().unwrap();
    let text = std::fs::read_to_string(file).unwrap();
    let mut table: toml::Table = text.parse().unwrap();
    let literal: toml::Table = format!("v = {value}").parse().unwrap();
    let (t, last) = common::table_for(&mut table, key);
    t.insert(last.to_string(), literal["v"].clone());
    let path = dir.join("bad.toml");
    std::fs::write(&path, toml::to_string(&table).unwrap()).unwrap();
    path
}

/// `infotrack config --config FILE` with the lab's `key` set to `value` is refused naming
/// the key.
fn config_key_refused(key: &str, value: &str, needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = lab_with(dir.path(), key, value);
    refused(&["config", "--config", cfg.to_str().unwrap()], 1, needle);
}

/// Each EER size within its own bound, their product hours per plan: refused at load.
#[test]
fn eer_sizes_together_beyond_their_bound() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = lab_with(dir.path(), "guidance.entropy_particles", "5000");
    for (key, value) in [
        ("guidance.measurements_per_particle", "64"),
        ("guidance.horizon_steps", "64"),
        ("guidance.candidate_grid_side", "64"),
    ] {
        let text = std::fs::read_to_string(&cfg).unwrap();
        let next = dir.path().join(format!("{key}.toml"));
        std::fs::write(&next, &text).unwrap();
        cfg = lab_with_file(&next, key, value);
    }
    refused(
        &["config", "--config", cfg.to_str().unwrap()],
        1,
        "measurements_per_particle x horizon_steps together",
    );
}

/// `infotrack config --config FILE` with the file `make` writes is refused saying `needle`.
fn config_file_refused(make: impl FnOnce(&Path) -> PathBuf, needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = make(dir.path());
    refused(&["config", "--config", cfg.to_str().unwrap()], 1, needle);
}

/// `infotrack params check FILE` of a file named `name` holding `text` is refused before
/// anything connects (the vehicle URL leads nowhere).
fn params_file_refused(name: &str, text: impl AsRef<str>, needle: &str) {
    let text = text.as_ref();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join(name);
    std::fs::write(&file, text).unwrap();
    let args = [
        "params",
        "check",
        file.to_str().unwrap(),
        "--connect",
        "udpout:127.0.0.1:9",
        "--timeout",
        "1",
    ];
    refused(&args, 1, needle);
}

/// `infotrack replay DIR` of a `flight.csv` holding `text` is refused saying `needle`.
fn replay_refused(text: impl AsRef<str>, needle: &str) {
    let text = text.as_ref();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("flight.csv"), text).unwrap();
    refused(&["replay", dir.path().to_str().unwrap()], 1, needle);
}

/// The first lines of a flight log.
fn log_head() -> String {
    format!(
        "# infotrack flight log seed=3 motion=cv\n{}\n",
        infotrack::daemon::flight_log::HEADER
    )
}

/// A valid flight-log row with field `k` (0-based) replaced by `v`.
fn log_row_with(k: usize, v: &str) -> String {
    let row = "0.33,1,2,-1.2,0,0,0,1,1,0.5,0.6,0.5,0.6,0.01,0,0.01,400,0.1,tracking,goto,0.5,0.7,3.2,Offboard,";
    let mut f: Vec<&str> = row.split(',').collect();
    f[k] = v;
    format!("{}\n", f.join(","))
}

macro_rules! cli_refused {
    ($($name:ident: [$($arg:expr),*] => $code:expr, $needle:expr;)*) => {$(
        #[test]
        fn $name() {
            refused(&[$($arg),*], $code, $needle);
        }
    )*};
}

macro_rules! config_keys_refused {
    ($($name:ident: $key:expr, $value:expr => $needle:expr;)*) => {$(
        #[test]
        fn $name() {
            config_key_refused($key, $value, $needle);
        }
    )*};
}

macro_rules! params_files_refused {
    ($($name:ident: $file:expr, $text:expr => $needle:expr;)*) => {$(
        #[test]
        fn $name() {
            params_file_refused($file, $text, $needle);
        }
    )*};
}

macro_rules! logs_refused {
    ($($name:ident: $text:expr => $needle:expr;)*) => {$(
        #[test]
        fn $name() {
            replay_refused($text, $needle);
        }
    )*};
}

// Command-line numbers: clap refuses them (exit code 2) naming the flag.
cli_refused! {
    params_timeout_negative: ["params", "check", "firmware-params/px4-offboard-tracking.params", "--connect", "udpout:127.0.0.1:9", "--timeout=-1"] => 2, "--timeout";
    params_timeout_nan: ["params", "check", "firmware-params/px4-offboard-tracking.params", "--connect", "udpout:127.0.0.1:9", "--timeout", "nan"] => 2, "--timeout";
    params_timeout_inf: ["params", "check", "firmware-params/px4-offboard-tracking.params", "--connect", "udpout:127.0.0.1:9", "--timeout", "inf"] => 2, "--timeout";
    params_timeout_huge: ["params", "check", "firmware-params/px4-offboard-tracking.params", "--connect", "udpout:127.0.0.1:9", "--timeout", "1e30"] => 2, "--timeout";
    params_timeout_zero: ["params", "check", "firmware-params/px4-offboard-tracking.params", "--connect", "udpout:127.0.0.1:9", "--timeout", "0"] => 2, "--timeout";
    params_unknown_action: ["params", "write", "firmware-params/px4-offboard-tracking.params", "--connect", "udpout:127.0.0.1:9"] => 1, "unknown params action";
    params_bad_url: ["params", "check", "firmware-params/px4-offboard-tracking.params", "--connect", "carrier-pigeon:1"] => 1, "carrier-pigeon";
    mock_loss_over_100: ["mock-autopilot", "--flavor", "px4", "--loss", "101"] => 2, "--loss";
    mock_loss_nan: ["mock-autopilot", "--flavor", "px4", "--loss", "nan"] => 2, "--loss";
    mock_delay_negative: ["mock-autopilot", "--flavor", "px4", "--delay-ms=-5"] => 2, "--delay-ms";
    mock_delay_huge: ["mock-autopilot", "--flavor", "px4", "--delay-ms", "1e300"] => 2, "--delay-ms";
    mock_duplicate_inf: ["mock-autopilot", "--flavor", "px4", "--duplicate", "inf"] => 2, "--duplicate";
    mock_reorder_negative: ["mock-autopilot", "--flavor", "px4", "--reorder=-1"] => 2, "--reorder";
    mock_ready_after_nan: ["mock-autopilot", "--flavor", "px4", "--estimator-ready-after", "nan"] => 2, "--estimator-ready-after";
    mock_unknown_flavor: ["mock-autopilot", "--flavor", "inav", "--listen", "udpin:127.0.0.1:0"] => 1, "inav";
    sim_runs_zero: ["sim", "--runs", "0"] => 2, "--runs";
    sim_runs_negative: ["sim", "--runs=-1"] => 2, "--runs";
    sim_runs_overflow: ["sim", "--runs", "18446744073709551616"] => 2, "--runs";
    sim_duration_nan: ["sim", "--duration", "nan"] => 2, "--duration";
    sim_duration_negative: ["sim", "--duration=-5"] => 2, "--duration";
    sim_duration_huge: ["sim", "--duration", "1e300"] => 2, "--duration";
    sim_threads_zero: ["sim", "--threads", "0"] => 2, "--threads";
    sim_unknown_guidance: ["sim", "--runs", "1", "--guidance", "teleport"] => 1, "teleport";
    sim_unknown_motion: ["sim", "--runs", "1", "--motion", "psychic"] => 1, "psychic";
    run_duration_negative: ["run", "--duration=-1"] => 2, "--duration";
    run_duration_nan: ["run", "--duration", "nan"] => 2, "--duration";
    run_duration_inf: ["run", "--duration", "inf"] => 2, "--duration";
    run_duration_huge: ["run", "--duration", "1e300"] => 2, "--duration";
    run_inject_endless: ["run", "--inject", "link-cut@1+1e300"] => 2, "--inject";
    run_inject_negative_start: ["run", "--inject", "camera-freeze@-1+2"] => 2, "--inject";
    run_inject_loss_over_100: ["run", "--inject", "loss=101@1+1"] => 2, "--inject";
    run_inject_nan_start: ["run", "--inject", "pipeline-panic@nan+1"] => 2, "--inject";
    run_inject_unknown_kind: ["run", "--inject", "meteor@1+1"] => 2, "--inject";
    run_inject_no_duration: ["run", "--inject", "link-cut@1"] => 2, "--inject";
    run_unknown_motion: ["run", "--motion", "psychic"] => 1, "psychic";
    run_bad_vehicle_url: ["run", "--vehicle", "carrier-pigeon:1"] => 1, "carrier-pigeon";
    run_simulation_on_a_vehicle: ["run", "--vehicle", "udpout:127.0.0.1:9"] => 1, "--allow-simulation-on-vehicle";
    run_auto_engage_on_a_vehicle: ["run", "--vehicle", "udpout:127.0.0.1:9", "--allow-simulation-on-vehicle"] => 1, "--allow-auto-engage";
    dataset_duration_nan: ["dataset", "--duration", "nan", "--out", "/tmp/never.csv"] => 2, "--duration";
    bench_repetitions_zero: ["bench", "--repetitions", "0"] => 2, "--repetitions";
    calibrate_every_nan: ["calibrate", "tests", "--board", "9x6", "--square-m", "0.025", "--out", "/tmp/never.yaml", "--every-s", "nan"] => 2, "--every-s";
    config_missing_file: ["config", "--config", "/nonexistent/infotrack.toml"] => 1, "/nonexistent/infotrack.toml";
    config_dev_zero: ["config", "--config", "/dev/zero"] => 1, "not a regular file";
    config_a_folder: ["config", "--config", "config"] => 1, "not a regular file";
    replay_missing_folder: ["replay", "/nonexistent/flight"] => 1, "/nonexistent/flight";
    detect_missing_image: ["detect", "/nonexistent/frame.png"] => 1, "/nonexistent/frame.png";
}

// Config values: each refused at load naming its key (exit code 1).
config_keys_refused! {
    particles_zero: "filter.particles", "0" => "filter.particles";
    particles_huge: "filter.particles", "1000000000" => "filter.particles";
    history_huge: "filter.history_len", "100000000" => "filter.history_len";
    physics_hz_zero: "timing.physics_hz", "0.0" => "timing.physics_hz";
    physics_hz_negative: "timing.physics_hz", "-10.0" => "timing.physics_hz";
    physics_hz_nan: "timing.physics_hz", "nan" => "timing.physics_hz";
    physics_hz_huge: "timing.physics_hz", "1e12" => "timing.physics_hz";
    filter_hz_inf: "timing.filter_hz", "inf" => "timing.filter_hz";
    duration_nan: "timing.duration_s", "nan" => "timing.duration_s";
    duration_forever: "timing.duration_s", "1e300" => "timing.duration_s";
    grid_side_huge: "guidance.candidate_grid_side", "1000000" => "guidance.candidate_grid_side";
    entropy_particles_huge: "guidance.entropy_particles", "1000000" => "guidance.entropy_particles";
    sweep_spacing_tiny: "guidance.lawn.point_spacing_m", "1e-12" => "guidance.lawn.point_spacing_m";
    sweep_spacing_zero: "guidance.lawn.point_spacing_m", "0.0" => "guidance.lawn.point_spacing_m";
    sweep_spacing_negative: "guidance.lawn.point_spacing_m", "-1.0" => "guidance.lawn.point_spacing_m";
    setpoint_rate_too_low: "daemon.setpoint_hz", "2.0" => "daemon.setpoint_hz";
    system_id_broadcast: "daemon.system_id", "0" => "daemon.system_id";
    system_id_overflow: "daemon.system_id", "256" => "system_id";
    vehicle_id_broadcast: "daemon.vehicle_id", "[0, 1]" => "daemon.vehicle_id";
    connect_timeout_negative: "daemon.connect_timeout_s", "-1.0" => "daemon.connect_timeout_s";
    connect_timeout_huge: "daemon.connect_timeout_s", "1e30" => "daemon.connect_timeout_s";
    engage_unknown: "daemon.engage", "\"maybe\"" => "engage";
    fallback_unknown: "daemon.target_lost_fallback", "\"pray\"" => "daemon.target_lost_fallback";
    speed_limit_negative: "agent.speed_limit_mps", "-1.0" => "agent.speed_limit_mps";
    altitude_nan: "agent.altitude_m", "nan" => "agent.altitude_m";
    workspace_inverted: "workspace_enu.x_max_m", "-10.0" => "workspace_enu";
    unknown_key: "filter.particels", "500" => "particels";
    wrong_type: "filter.particles", "\"many\"" => "expected usize";
    vehicle_url_bad: "daemon.vehicle", "\"carrier-pigeon:1\"" => "daemon.vehicle";
    world_file_missing: "world", "{ origin = { lat_deg = 47.0, lon_deg = 8.0, alt_m = 400.0 }, geojson = \"/nonexistent/world.geojson\" }" => "cannot read config file /nonexistent/world.geojson";
    world_file_dev_zero: "world", "{ origin = { lat_deg = 47.0, lon_deg = 8.0, alt_m = 400.0 }, geojson = \"/dev/zero\" }" => "not a regular file";
}

#[test]
fn config_too_large_is_refused_without_reading_it_all() {
    config_file_refused(
        |d| {
            let p = d.join("huge.toml");
            let f = std::fs::File::create(&p).unwrap();
            f.set_len(50 << 20).unwrap();
            p
        },
        "larger than",
    );
}

#[test]
fn config_not_utf8_is_refused() {
    config_file_refused(
        |d| {
            let p = d.join("latin1.toml");
            std::fs::write(&p, b"name = \"caf\xe9\"\n").unwrap();
            p
        },
        "not utf-8",
    );
}

#[test]
fn config_fifo_is_refused_without_blocking() {
    config_file_refused(
        |d| {
            let p = d.join("fifo.toml");
            assert!(Command::new("mkfifo").arg(&p).status().unwrap().success());
            p
        },
        "not a regular file",
    );
}

#[test]
fn config_empty_is_refused() {
    config_file_refused(
        |d| {
            let p = d.join("empty.toml");
            std::fs::write(&p, "").unwrap();
            p
        },
        "empty.toml",
    );
}

#[test]
fn config_bad_toml_names_the_line() {
    config_file_refused(
        |d| {
            let p = d.join("broken.toml");
            std::fs::write(&p, "name = \"x\"\n[filter\nparticles = 5\n").unwrap();
            p
        },
        "line 2",
    );
}

// Parameter files: refused before anything is sent, naming the file and line.
params_files_refused! {
    real_beyond_f32_1e308: "a.params", "1\t1\tMPC_XY_VEL_MAX\t1e308\t9\n" => "does not fit";
    real_beyond_f32_3_5e38: "a.params", "1\t1\tMPC_XY_VEL_MAX\t3.5e38\t9\n" => "does not fit";
    value_nan: "a.parm", "WPNAV_SPEED,nan\n" => "not finite";
    value_inf: "a.parm", "WPNAV_SPEED,inf\n" => "not finite";
    value_text: "a.parm", "WPNAV_SPEED,fast\n" => "not a number";
    integer_with_fraction: "a.params", "1\t1\tMAV_1_MODE\t1.5\t6\n" => "does not fit";
    integer_out_of_range: "a.params", "1\t1\tMAV_1_MODE\t300\t1\n" => "does not fit";
    duplicate_name: "a.parm", "WPNAV_SPEED,1500\nANGLE_MAX,4500\nWPNAV_SPEED,1000\n" => "set again (first on line 1)";
    wrong_field_count: "a.params", "1\t1\tMPC_XY_VEL_MAX\t12\n" => "expected 5 tab-separated fields";
    bad_type_number: "a.params", "1\t1\tMPC_XY_VEL_MAX\t12\t42\n" => "type 42";
    bad_vehicle_id: "a.params", "999\t1\tMPC_XY_VEL_MAX\t12\t9\n" => "vehicle id";
    name_too_long: "a.parm", "A_NAME_FAR_TOO_LONG_FOR_MAVLINK,1\n" => "A_NAME_FAR_TOO_LONG";
    only_comments: "a.parm", "# nothing here\n\n" => "no parameters";
    unknown_extension: "a.txt", "WPNAV_SPEED,1500\n" => "unknown parameter file type";
    three_fields: "a.parm", "WPNAV_SPEED,1500,extra\n" => "found 3 fields";
    too_many_lines: "a.parm", (0..20_001).map(|i| format!("P{i},1\n")).collect::<String>() => "more than 20000 lines";
}

#[test]
fn params_file_dev_zero_is_refused() {
    let args = [
        "params",
        "check",
        "/dev/zero",
        "--connect",
        "udpout:127.0.0.1:9",
        "--timeout",
        "1",
    ];
    refused(&args, 1, "not a regular file");
}

// Flight logs for `replay`: an error naming the row, never "identical ... NaN m over 0 steps".
logs_refused! {
    log_empty: "" => "empty file";
    log_header_only: log_head() => "no filter steps";
    log_not_ours: "t,x,y\n1,2,3\n" => "not an infotrack flight log";
    log_no_seed: "# infotrack flight log motion=cv\n" => "no seed";
    log_wrong_header: "# infotrack flight log seed=1 motion=cv\nt,x\n" => "expected the header";
    log_nan_time: format!("{}{}", log_head(), log_row_with(0, "NaN")) => "line 3";
    log_nan_vehicle: format!("{}{}", log_head(), log_row_with(1, "NaN")) => "not finite";
    log_inf_estimate: format!("{}{}", log_head(), log_row_with(11, "inf")) => "not finite";
    log_bad_flag: format!("{}{}{}", log_head(), log_row_with(7, "0"), log_row_with(7, "yes")) => "line 4";
    log_bad_command: format!("{}{}", log_head(), log_row_with(19, "jump")) => "not goto";
    log_measured_nan: format!("{}{}", log_head(), log_row_with(9, "NaN")) => "measurement is not finite";
    log_short_row: format!("{}{}\n{}", log_head(), "1,2,3", log_row_with(0, "1")) => "line 3";
}

// Images for `detect`: a file that is not an image is an error naming it.
#[test]
fn detect_text_file_as_image_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("frame.png");
    std::fs::write(&p, "this is not a PNG").unwrap();
    refused(&["detect", p.to_str().unwrap()], 1, "frame.png");
}

#[test]
fn detect_truncated_png_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("cut.png");
    std::fs::write(&p, b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR").unwrap();
    refused(&["detect", p.to_str().unwrap()], 1, "cut.png");
}

#[test]
fn detect_empty_folder_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    refused(&["detect", dir.path().to_str().unwrap()], 1, "no image");
}

#[test]
fn detect_pose_file_dev_zero_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("frame.png");
    let black = opencv::core::Mat::zeros(48, 64, opencv::core::CV_8UC1)
        .unwrap()
        .to_mat()
        .unwrap();
    assert!(
        opencv::imgcodecs::imwrite(p.to_str().unwrap(), &black, &opencv::core::Vector::new())
            .unwrap()
    );
    refused(
        &["detect", p.to_str().unwrap(), "--pose", "/dev/zero"],
        1,
        "/dev/zero",
    );
}

/// The version names the commit; completions and the manual page come from the command
/// line's own definitions.
#[test]
fn version_completions_and_manual_page() {
    let v = infotrack(&["--version"]);
    let text = String::from_utf8_lossy(&v.stdout);
    assert!(
        text.starts_with("infotrack ") && text.contains("(commit "),
        "{text}"
    );
    let bash = infotrack(&["completions", "bash"]);
    let text = String::from_utf8_lossy(&bash.stdout);
    assert!(
        bash.status.success() && text.contains("mock-autopilot"),
        "{text}"
    );
    let man = infotrack(&["man"]);
    let text = String::from_utf8_lossy(&man.stdout);
    assert!(
        man.status.success() && text.contains(".TH infotrack"),
        "{text}"
    );
    refused(&["completions", "tcsh"], 2, "tcsh");
}
