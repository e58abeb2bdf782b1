//! The JSON Schemas of the Foxglove message types the record uses. Foxglove's panels know a
//! message by its schema's name (`foxglove.PoseInFrame`, ...); the schema text itself
//! describes the fields infotrack writes, so that any MCAP reader can decode them.

use serde_json::{json, Value};

fn time() -> Value {
    json!({"type": "object", "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}})
}

fn xyz() -> Value {
    json!({"type": "object", "properties": {
        "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}})
}

fn pose() -> Value {
    json!({"type": "object", "properties": {
        "position": xyz(),
        "orientation": {"type": "object", "properties": {
            "x": {"type": "number"}, "y": {"type": "number"},
            "z": {"type": "number"}, "w": {"type": "number"}}}}})
}

fn colour() -> Value {
    json!({"type": "object", "properties": {
        "r": {"type": "number"}, "g": {"type": "number"},
        "b": {"type": "number"}, "a": {"type": "number"}}})
}

/// `foxglove.PoseInFrame`: a position and orientation in a named frame at a time.
pub fn pose_in_frame() -> Value {
    json!({"title": "foxglove.PoseInFrame", "type": "object", "properties": {
        "timestamp": time(), "frame_id": {"type": "string"}, "pose": pose()}})
}

/// `foxglove.PointCloud`: packed points (here x, y, z and weight as 32-bit floats).
pub fn point_cloud() -> Value {
    json!({"title": "foxglove.PointCloud", "type": "object", "properties": {
        "timestamp": time(), "frame_id": {"type": "string"}, "pose": pose(),
        "point_stride": {"type": "integer", "minimum": 0},
        "fields": {"type": "array", "items": {"type": "object", "properties": {
            "name": {"type": "string"},
            "offset": {"type": "integer", "minimum": 0},
            "type": {"type": "integer", "description": "7: FLOAT32"}}}},
        "data": {"type": "string", "contentEncoding": "base64"}}})
}

/// `foxglove.SceneUpdate`: entities made of line primitives (roads, occlusions, fence).
pub fn scene_update() -> Value {
    let line = json!({"type": "object", "properties": {
        "type": {"type": "integer", "description": "0: strip, 1: loop, 2: list"},
        "pose": pose(), "thickness": {"type": "number"},
        "scale_invariant": {"type": "boolean"},
        "points": {"type": "array", "items": xyz()},
        "color": colour(),
        "colors": {"type": "array", "items": colour()},
        "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}}}});
    json!({"title": "foxglove.SceneUpdate", "type": "object", "properties": {
        "deletions": {"type": "array", "items": {"type": "object"}},
        "entities": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": time(), "frame_id": {"type": "string"}, "id": {"type": "string"},
            "lifetime": time(), "frame_locked": {"type": "boolean"},
            "metadata": {"type": "array", "items": {"type": "object"}},
            "lines": {"type": "array", "items": line}}}}}})
}

/// `foxglove.CompressedImage`: an encoded camera frame.
pub fn compressed_image() -> Value {
    json!({"title": "foxglove.CompressedImage", "type": "object", "properties": {
        "timestamp": time(), "frame_id": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "format": {"type": "string"}}})
}
