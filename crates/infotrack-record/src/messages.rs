//! The messages of the record, as Foxglove's JSON encoding has them. Every position is in
//! the frame `world`: world ENU metres (x east, y north, z up), the frame Foxglove's 3D
//! panel draws in when told to follow `world`.

use base64::Engine;
use serde_json::{json, Value};

use infotrack_core::world::geometry::Enu2;
use infotrack_core::world::World;

/// The frame every position of the record is in: world ENU.
pub const WORLD_FRAME: &str = "world";

/// A time in nanoseconds as Foxglove's `{sec, nsec}`.
pub fn time(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

/// A pose at `p` (world ENU, z up) facing `yaw_enu_rad` (counter-clockwise from east).
pub fn pose(p: [f64; 3], yaw_enu_rad: f64) -> Value {
    let half = 0.5 * yaw_enu_rad;
    json!({"position": {"x": p[0], "y": p[1], "z": p[2]},
           "orientation": {"x": 0.0, "y": 0.0, "z": half.sin(), "w": half.cos()}})
}

/// A `foxglove.PoseInFrame` in the world frame.
pub fn pose_in_frame(ns: u64, p: [f64; 3], yaw_enu_rad: f64) -> Value {
    json!({"timestamp": time(ns), "frame_id": WORLD_FRAME, "pose": pose(p, yaw_enu_rad)})
}

/// The particles as a `foxglove.PointCloud` on the ground (z = 0): x, y, z and the
/// particle's weight, little-endian 32-bit floats.
pub fn particles(ns: u64, positions: &[Enu2], weights: &[f64]) -> Value {
    let mut data = Vec::with_capacity(positions.len() * 16);
    for (i, p) in positions.iter().enumerate() {
        let w = weights.get(i).copied().unwrap_or(f64::NAN);
        for v in [p.x, p.y, 0.0, w] {
            data.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    let field = |name: &str, offset: u32| json!({"name": name, "offset": offset, "type": 7});
    json!({"timestamp": time(ns), "frame_id": WORLD_FRAME, "pose": pose([0.0; 3], 0.0),
           "point_stride": 16,
           "fields": [field("x", 0), field("y", 4), field("z", 8), field("weight", 12)],
           "data": base64::engine::general_purpose::STANDARD.encode(data)})
}

fn line(kind: u8, points: Vec<Value>, rgba: [f64; 4], thickness_m: f64) -> Value {
    json!({"type": kind, "pose": pose([0.0; 3], 0.0), "thickness": thickness_m,
           "scale_invariant": false, "points": points,
           "color": {"r": rgba[0], "g": rgba[1], "b": rgba[2], "a": rgba[3]},
           "colors": [], "indices": []})
}

fn ground(p: &Enu2) -> Value {
    json!({"x": p.x, "y": p.y, "z": 0.0})
}

fn entity(ns: u64, id: &str, lines: Vec<Value>) -> Value {
    json!({"timestamp": time(ns), "frame_id": WORLD_FRAME, "id": id,
           "lifetime": time(0), "frame_locked": false, "metadata": [], "lines": lines})
}

/// The world as a `foxglove.SceneUpdate`: the roads (grey), the occlusions (green
/// outlines) and the geofence (red), for the whole run (lifetime 0: forever).
pub fn world_scene(ns: u64, world: &World) -> Value {
    let roads: Vec<Value> = world
        .road
        .edges_enu()
        .iter()
        .flat_map(|(a, b)| [ground(a), ground(b)])
        .collect();
    let occlusions: Vec<Value> = world
        .occlusions
        .iter()
        .map(|o| {
            line(
                1,
                o.vertices().iter().map(ground).collect(),
                [0.1, 0.5, 0.1, 1.0],
                1.0,
            )
        })
        .collect();
    let w = &world.workspace_enu;
    let fence: Vec<Value> = [
        (w.x_min_m, w.y_min_m),
        (w.x_max_m, w.y_min_m),
        (w.x_max_m, w.y_max_m),
        (w.x_min_m, w.y_max_m),
    ]
    .iter()
    .map(|(x, y)| ground(&Enu2::new(*x, *y)))
    .collect();
    json!({"deletions": [], "entities": [
        entity(ns, "roads", vec![line(2, roads, [0.5, 0.5, 0.5, 1.0], 2.0)]),
        entity(ns, "occlusions", occlusions),
        entity(ns, "geofence", vec![line(1, fence, [0.9, 0.1, 0.1, 1.0], 1.0)]),
    ]})
}

/// An 8-bit grey frame as a `foxglove.CompressedImage` (PNG) in the frame `camera`.
pub fn grey_image(ns: u64, width: u32, height: u32, grey: &[u8]) -> Result<Value, String> {
    let mut png_bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut png_bytes, width, height);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(|e| e.to_string())?;
        w.write_image_data(grey).map_err(|e| e.to_string())?;
    }
    Ok(json!({"timestamp": time(ns), "frame_id": "camera",
              "data": base64::engine::general_purpose::STANDARD.encode(png_bytes),
              "format": "png"}))
}
