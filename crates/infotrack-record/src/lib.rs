//! A run's visual record: an MCAP file that Foxglove opens and scrubs through. The roads,
//! occlusions and geofence once; then over time the drone, the target (when the truth is
//! known), the estimate, each measurement, the setpoint, the particles and the camera's
//! frames, all on the ground plane of world ENU (frame `world`).
//!
//! Why MCAP for Foxglove and not Rerun's `.rrd`: MCAP is an open, documented container
//! with small readers in many languages (the `mcap` crate is Foxglove's own, ~10
//! dependencies, no C), its messages are self-describing (a JSON Schema per channel), and
//! robotics users already open it in Foxglove and ROS 2 tools. The `rerun` crate pulls a
//! few hundred crates into the build and its file format changes between releases.

#![deny(missing_docs)]

pub mod messages;
pub mod schemas;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use infotrack_core::world::geometry::Enu2;
use infotrack_core::world::World;

/// A record that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write the visual record {path}: {message}")]
pub struct RecordError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong.
    pub message: String,
}

/// What one filter step shows: where everything was, world ENU.
#[derive(Debug, Clone, Copy)]
pub struct RecordStep {
    /// Time since the start of the run, s.
    pub t_s: f64,
    /// The drone's ground position, world ENU, m.
    pub drone_enu: Enu2,
    /// Its height above the ground, m.
    pub drone_altitude_m: f64,
    /// The way the camera's view faces, world ENU (counter-clockwise from east), rad.
    pub view_yaw_enu_rad: f64,
    /// The target's true position, when it is known (simulation), world ENU.
    pub truth_enu: Option<Enu2>,
    /// The estimate, world ENU.
    pub estimate_enu: Enu2,
    /// The measurement of this step, if the target was seen, world ENU.
    pub measurement_enu: Option<Enu2>,
    /// The setpoint the drone flies to, world ENU.
    pub setpoint_enu: Enu2,
}

/// The topics, in the order their channels are made.
pub const TOPICS: [(&str, &str); 8] = [
    ("/world", "foxglove.SceneUpdate"),
    ("/drone", "foxglove.PoseInFrame"),
    ("/target/truth", "foxglove.PoseInFrame"),
    ("/target/estimate", "foxglove.PoseInFrame"),
    ("/target/measurement", "foxglove.PoseInFrame"),
    ("/setpoint", "foxglove.PoseInFrame"),
    ("/particles", "foxglove.PointCloud"),
    ("/camera", "foxglove.CompressedImage"),
];

/// Writes a record as a run goes; [`Recorder::finish`] writes its summary and index.
pub struct Recorder {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    channels: BTreeMap<&'static str, u16>,
    start_ns: u64,
    sequence: u32,
}

impl Recorder {
    /// Creates `path` (and its folder) and writes the world into it. Message times are
    /// `start_ns` (ns since the Unix epoch; 0 for a simulation) plus the run's time.
    pub fn create(path: &Path, world: &World, start_ns: u64) -> Result<Self, RecordError> {
        let fail = |message: String| RecordError {
            path: path.to_path_buf(),
            message,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| fail(e.to_string()))?;
        }
        let file = File::create(path).map_err(|e| fail(e.to_string()))?;
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library(concat!("infotrack ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| fail(e.to_string()))?;
        let mut channels = BTreeMap::new();
        for (topic, schema_name) in TOPICS {
            let schema = schema_text(schema_name);
            let schema_id = writer
                .add_schema(schema_name, "jsonschema", schema.as_bytes())
                .map_err(|e| fail(e.to_string()))?;
            let id = writer
                .add_channel(schema_id, topic, "json", &BTreeMap::new())
                .map_err(|e| fail(e.to_string()))?;
            channels.insert(topic, id);
        }
        let mut r = Self {
            path: path.to_path_buf(),
            writer,
            channels,
            start_ns,
            sequence: 0,
        };
        r.write("/world", 0.0, &messages::world_scene(start_ns, world))?;
        Ok(r)
    }

    fn ns(&self, t_s: f64) -> u64 {
        self.start_ns + (t_s.max(0.0) * 1e9).round() as u64
    }

    fn write(&mut self, topic: &str, t_s: f64, msg: &serde_json::Value) -> Result<(), RecordError> {
        let channel_id = self.channels[topic];
        let log_time = self.ns(t_s);
        self.sequence += 1;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time,
            publish_time: log_time,
        };
        self.writer
            .write_to_known_channel(&header, msg.to_string().as_bytes())
            .map_err(|e| RecordError {
                path: self.path.clone(),
                message: e.to_string(),
            })
    }

    /// One filter step: the drone, the target, the estimate, the measurement, the setpoint.
    pub fn step(&mut self, s: &RecordStep) -> Result<(), RecordError> {
        let ns = self.ns(s.t_s);
        let on_ground = |p: Enu2| messages::pose_in_frame(ns, [p.x, p.y, 0.0], 0.0);
        let drone = [s.drone_enu.x, s.drone_enu.y, s.drone_altitude_m];
        self.write(
            "/drone",
            s.t_s,
            &messages::pose_in_frame(ns, drone, s.view_yaw_enu_rad),
        )?;
        if let Some(t) = s.truth_enu {
            self.write("/target/truth", s.t_s, &on_ground(t))?;
        }
        self.write("/target/estimate", s.t_s, &on_ground(s.estimate_enu))?;
        if let Some(z) = s.measurement_enu {
            self.write("/target/measurement", s.t_s, &on_ground(z))?;
        }
        self.write("/setpoint", s.t_s, &on_ground(s.setpoint_enu))
    }

    /// The particle set at `t_s`, with the weights (empty: unknown).
    pub fn particles(
        &mut self,
        t_s: f64,
        positions: &[Enu2],
        weights: &[f64],
    ) -> Result<(), RecordError> {
        let msg = messages::particles(self.ns(t_s), positions, weights);
        self.write("/particles", t_s, &msg)
    }

    /// A camera frame at `t_s`: 8-bit grey, row-major, `width * height` bytes.
    pub fn frame(
        &mut self,
        t_s: f64,
        width: u32,
        height: u32,
        grey: &[u8],
    ) -> Result<(), RecordError> {
        let msg = messages::grey_image(self.ns(t_s), width, height, grey).map_err(|message| {
            RecordError {
                path: self.path.clone(),
                message,
            }
        })?;
        self.write("/camera", t_s, &msg)
    }

    /// Writes the summary and the index, and closes the file.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.writer.finish().map_err(|e| RecordError {
            path: self.path.clone(),
            message: e.to_string(),
        })?;
        Ok(())
    }
}

fn schema_text(name: &str) -> String {
    match name {
        "foxglove.SceneUpdate" => schemas::scene_update(),
        "foxglove.PointCloud" => schemas::point_cloud(),
        "foxglove.CompressedImage" => schemas::compressed_image(),
        _ => schemas::pose_in_frame(),
    }
    .to_string()
}

#[cfg(test)]
mod tests;
