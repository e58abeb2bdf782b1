//! `--record`: a run's visual record, read back with the MCAP format's own reader (the
//! `mcap` crate, Foxglove's), as a user's viewer would read it.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use base64::Engine;

mod common;

fn infotrack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_infotrack"))
}

fn run_ok(c: &mut Command) -> String {
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Each topic's messages (log time, JSON) and its schema's name.
type Topics = BTreeMap<String, (String, Vec<(u64, serde_json::Value)>)>;

fn read_record(path: &Path) -> Topics {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary and index");
    assert!(summary.stats.is_some_and(|s| s.message_count > 0));
    let mut topics = Topics::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap().name.clone();
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        let e = topics
            .entry(m.channel.topic.clone())
            .or_insert((schema, Vec::new()));
        e.1.push((m.log_time, v));
    }
    topics
}

fn times_increase(msgs: &[(u64, serde_json::Value)]) -> bool {
    msgs.windows(2).all(|w| w[0].0 <= w[1].0)
}

#[test]
fn a_monte_carlo_records_each_laws_first_run() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let said = run_ok(
        infotrack()
            .args([
                "sim",
                "--runs",
                "2",
                "--duration",
                "20",
                "--guidance",
                "eer,kf",
                "--motion",
                "cv,kf",
                "--quiet",
                "--record",
            ])
            .arg(&rec),
    );
    let eer = rec.join("eer_cv_run000.mcap");
    assert!(said.contains(&eer.display().to_string()), "{said}");
    let t = read_record(&eer);
    assert_eq!(t["/world"].0, "foxglove.SceneUpdate");
    assert_eq!(t["/drone"].0, "foxglove.PoseInFrame");
    assert_eq!(t["/particles"].0, "foxglove.PointCloud");
    let steps = t["/drone"].1.len();
    assert!(
        steps >= 19,
        "a filter step a second or more over 20 s: {steps}"
    );
    for topic in [
        "/target/truth",
        "/target/estimate",
        "/setpoint",
        "/particles",
    ] {
        assert_eq!(t[topic].1.len(), steps, "{topic}");
        assert!(times_increase(&t[topic].1), "{topic}");
    }
    // The drone flies at the config's altitude; particles carry x, y, z and weight.
    let cfg: toml::Value = run_ok(infotrack().arg("config")).parse().unwrap();
    let altitude = cfg["agent"]["altitude_m"].as_float().unwrap();
    assert_eq!(t["/drone"].1[0].1["pose"]["position"]["z"], altitude);
    let cloud = &t["/particles"].1[0].1;
    let data = base64::engine::general_purpose::STANDARD
        .decode(cloud["data"].as_str().unwrap())
        .unwrap();
    assert_eq!(data.len() % 16, 0);
    assert!(data.len() / 16 >= 100, "particles: {}", data.len() / 16);
    // The Kalman estimator has no particles: its record has none.
    let kf = read_record(&rec.join("kf_kf_run000.mcap"));
    assert!(!kf.contains_key("/particles"));
    assert_eq!(kf["/drone"].1.len(), kf["/target/estimate"].1.len());
}

#[test]
fn a_closed_loop_flight_records_its_camera_frames_as_it_goes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flight.mcap");
    run_ok(
        infotrack()
            .args(["sim", "--closed-loop", "--duration", "20", "--record"])
            .arg(&path),
    );
    let t = read_record(&path);
    let frames = &t["/camera"].1;
    assert_eq!(t["/camera"].0, "foxglove.CompressedImage");
    assert!(
        (15..=21).contains(&frames.len()),
        "a frame a second: {}",
        frames.len()
    );
    let png_bytes = base64::engine::general_purpose::STANDARD
        .decode(frames[0].1["data"].as_str().unwrap())
        .unwrap();
    let info = png::Decoder::new(std::io::Cursor::new(png_bytes))
        .read_info()
        .unwrap();
    let (w, h) = (info.info().width, info.info().height);
    assert!(w >= 320 && h >= 240, "{w}x{h}");
    assert!(t["/target/measurement"].1.len() > 5, "the tag was seen");
    let first = t["/drone"].1[0].0;
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap();
    assert!(
        first > now.as_nanos() as u64 - 600_000_000_000,
        "times are dates"
    );
}

#[test]
fn a_record_that_cannot_be_written_stops_the_start_and_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, "").unwrap();
    let path = blocker.join("flight.mcap");
    let o = infotrack()
        .args(["sim", "--closed-loop", "--duration", "5", "--record"])
        .arg(&path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains(&path.display().to_string()) && !err.contains("panicked"),
        "{err}"
    );
}

/// A flight with a real camera (a film of a tag, hovering where it was taken): no ground
/// truth, so the end table and `summary.json` give what can be known without it (frames with
/// the tag, the estimate's spread, latency), and the record holds the camera's own frames.
#[test]
fn a_real_camera_flight_reports_what_it_can_know_and_records_its_frames() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = infotrack::config::Config::default_lab();
    let (video, calib) = common::film_a_tag(dir.path(), &cfg, [0.1, 0.15]);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut table: toml::Table = std::fs::read_to_string(root.join("config/default.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let set = |t: &mut toml::Table, key: &str, v: toml::Value| {
        let (t, name) = common::table_for(t, key);
        t.insert(name.to_string(), v);
    };
    set(
        &mut table,
        "daemon.camera",
        video.display().to_string().into(),
    );
    set(
        &mut table,
        "daemon.calibration",
        calib.display().to_string().into(),
    );
    set(
        &mut table,
        "agent.start_enu_m",
        toml::Value::Array(vec![0.0.into(), 0.0.into()]),
    );
    set(&mut table, "agent.speed_limit_mps", 0.005.into());
    let config = dir.path().join("film.toml");
    std::fs::write(&config, toml::to_string(&table).unwrap()).unwrap();
    let (out, record) = (dir.path().join("flight"), dir.path().join("flight.mcap"));
    let o = infotrack()
        .args([
            "run",
            "--quiet",
            "--motion",
            "cv",
            "--duration",
            "14",
            "--config",
        ])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .arg("--record")
        .arg(&record)
        .output()
        .unwrap();
    let said = common::output_text(&o);
    assert!(
        said.contains("flight (real camera, no ground truth)"),
        "{said}"
    );
    assert!(
        said.contains("estimate spread p50/p99") && !said.contains("NaN"),
        "{said}"
    );
    assert!(!said.contains("tracking error (m)"), "{said}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let spread = summary["flight"]["estimate_spread_m"]["p50"].as_f64();
    assert!(spread.is_some_and(|s| s > 0.0 && s < 1.0), "{summary}");
    let t = read_record(&record);
    assert!(!t.contains_key("/target/truth"), "no truth in the field");
    assert!(!t["/camera"].1.is_empty() && !t["/target/measurement"].1.is_empty());
    let png_bytes = base64::engine::general_purpose::STANDARD
        .decode(t["/camera"].1[0].1["data"].as_str().unwrap())
        .unwrap();
    let info = png::Decoder::new(std::io::Cursor::new(png_bytes))
        .read_info()
        .unwrap();
    assert_eq!((info.info().width, info.info().height), (640, 480));
}
