//! The record read back with the `mcap` crate's own reader.

use std::collections::BTreeMap;

use super::*;

fn world() -> World {
    infotrack_config::Config::default_lab().world()
}

fn step(t_s: f64, seen: bool) -> RecordStep {
    RecordStep {
        t_s,
        drone_enu: Enu2::new(1.0, 2.0),
        drone_altitude_m: 3.5,
        view_yaw_enu_rad: std::f64::consts::FRAC_PI_2,
        truth_enu: Some(Enu2::new(4.0, 5.0)),
        estimate_enu: Enu2::new(4.5, 5.5),
        measurement_enu: seen.then(|| Enu2::new(4.1, 5.1)),
        setpoint_enu: Enu2::new(3.0, 3.0),
    }
}

/// Messages by topic: (log time, JSON).
type ByTopic = BTreeMap<String, Vec<(u64, serde_json::Value)>>;

/// Every message of the file by topic, with each channel's schema name.
fn read_back(path: &Path) -> (ByTopic, BTreeMap<String, String>) {
    let bytes = std::fs::read(path).unwrap();
    let mut by_topic = ByTopic::new();
    let mut schemas = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.channel.message_encoding, "json");
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "jsonschema");
        let parsed: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
        assert_eq!(parsed["title"], schema.name.as_str());
        schemas.insert(m.channel.topic.clone(), schema.name.clone());
        let v = serde_json::from_slice(&m.data).unwrap();
        by_topic
            .entry(m.channel.topic.clone())
            .or_default()
            .push((m.log_time, v));
    }
    (by_topic, schemas)
}

#[test]
fn a_record_reads_back_with_every_topic_its_schema_and_its_times() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let w = world();
    let mut r = Recorder::create(&path, &w, 1_000_000_000).unwrap();
    r.step(&step(0.1, false)).unwrap();
    r.particles(
        0.1,
        &[Enu2::new(1.0, -2.0), Enu2::new(3.0, 4.0)],
        &[0.25, 0.75],
    )
    .unwrap();
    r.step(&step(0.2, true)).unwrap();
    r.frame(0.2, 4, 2, &[0, 50, 100, 150, 200, 250, 255, 1])
        .unwrap();
    r.finish().unwrap();

    let (msgs, schemas) = read_back(&path);
    for (topic, schema) in TOPICS {
        assert_eq!(
            schemas.get(topic).map(String::as_str),
            Some(schema),
            "{topic}"
        );
    }
    let count = |t: &str| msgs.get(t).map_or(0, Vec::len);
    assert_eq!(
        (
            count("/drone"),
            count("/target/measurement"),
            count("/particles")
        ),
        (2, 1, 1)
    );
    let (t, drone) = &msgs["/drone"][1];
    assert_eq!(*t, 1_200_000_000);
    assert_eq!(drone["frame_id"], "world");
    assert_eq!(drone["pose"]["position"]["z"], 3.5);
    // A quarter turn about up: (0, 0, sin 45°, cos 45°).
    let q = &drone["pose"]["orientation"];
    assert!(
        (q["z"].as_f64().unwrap() - 0.5f64.sqrt()).abs() < 1e-12,
        "{q}"
    );
    let world_msg = &msgs["/world"][0].1;
    let roads = &world_msg["entities"][0]["lines"][0]["points"];
    assert_eq!(
        roads.as_array().unwrap().len(),
        2 * w.road.edges_enu().len()
    );
}

#[test]
fn particles_and_frames_decode_to_what_was_recorded() {
    use base64::Engine;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let mut r = Recorder::create(&path, &world(), 0).unwrap();
    r.particles(
        0.5,
        &[Enu2::new(1.5, -2.0), Enu2::new(3.0, 4.25)],
        &[0.25, 0.75],
    )
    .unwrap();
    let grey = [0u8, 50, 100, 150, 200, 250, 255, 1];
    r.frame(0.5, 4, 2, &grey).unwrap();
    r.finish().unwrap();
    let (msgs, _) = read_back(&path);
    let b64 = base64::engine::general_purpose::STANDARD;
    let cloud = &msgs["/particles"][0].1;
    assert_eq!(cloud["point_stride"], 16);
    let data = b64.decode(cloud["data"].as_str().unwrap()).unwrap();
    let floats: Vec<f32> = data
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(floats, [1.5, -2.0, 0.0, 0.25, 3.0, 4.25, 0.0, 0.75]);
    let image = &msgs["/camera"][0].1;
    assert_eq!(image["format"], "png");
    let png_bytes = b64.decode(image["data"].as_str().unwrap()).unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(png_bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (4, 2));
    assert_eq!(&buf[..8], &grey);
}

#[test]
fn a_record_that_cannot_be_written_names_its_file() {
    let dir = tempfile::tempdir().unwrap();
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, "").unwrap();
    let path = blocker.join("run.mcap");
    let e = Recorder::create(&path, &world(), 0).err().unwrap();
    assert!(e.to_string().contains(&path.display().to_string()), "{e}");
}
