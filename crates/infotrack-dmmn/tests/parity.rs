//! Parity with PyTorch: the shipped models through ONNX Runtime give the outputs their
//! training export recorded (`models/*/dmmn_parity.json`). Needs the ONNX Runtime library
//! (`scripts/setup.sh`; `ORT_DYLIB_PATH` names another, as the arm64 build does).

use std::path::{Path, PathBuf};

use infotrack_core::motion::{Histories, MotionModel, MotionParams};
use infotrack_core::world::geometry::Enu2;
use infotrack_dmmn::Dmmn;

fn models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A JSON array of number arrays, row after row, as f32.
fn flatten_f32(rows: &serde_json::Value) -> Vec<f32> {
    let rows = rows.as_array().expect("rows");
    rows.iter()
        .flat_map(|row| row.as_array().expect("a row").iter())
        .map(|v| v.as_f64().expect("a number") as f32)
        .collect()
}

/// The model in `dir` with the filter period and history its metadata gives, and its
/// parity fixture's inputs and outputs.
fn model_and_fixture(dir: &Path) -> (Dmmn, Vec<f32>, Vec<f32>) {
    let meta = read_json(&dir.join("dmmn.json"));
    let params = MotionParams {
        dt_s: meta["dt_s"].as_f64().expect("dt_s"),
        history_len: meta["k_in"].as_u64().expect("k_in") as usize,
        cv_max_speed_mps: 1.0,
        dmmn_model: dir.join("dmmn.onnx"),
        onnxruntime_library: None,
        world: None,
        allow_model_from_other_world: false,
    };
    let model = Dmmn::load(&params.dmmn_model, &params).expect("the model loads");
    let fixture = read_json(&dir.join("dmmn_parity.json"));
    (
        model,
        flatten_f32(&fixture["inputs"]),
        flatten_f32(&fixture["outputs"]),
    )
}

fn largest_difference(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn the_lab_model_matches_pytorch_within_1e_5() {
    let (mut m, inputs, expected) = model_and_fixture(&models());
    let n = expected.len() / 2;
    assert!(n >= 32, "fixture has {n} cases");
    assert_eq!(inputs.len(), n * 10 * 2);
    let got = m.predict_raw(&inputs, n).expect("a prediction");
    let worst = largest_difference(&got, &expected);
    assert!(worst <= 1e-5, "largest difference {worst}");

    // The same through the MotionModel interface (f64 histories), one batch.
    let mut h = Histories::new(n, 10);
    for i in 0..n {
        for (t, v) in h.track_mut(i).iter_mut().enumerate() {
            *v = f64::from(inputs[i * 20 + t]);
        }
    }
    let mut out = vec![Enu2::zeros(); n];
    m.predict(&h, &mut out).expect("a prediction");
    for i in 0..n {
        assert!(
            (out[i].x - f64::from(expected[2 * i])).abs() <= 1e-5,
            "case {i}"
        );
        assert!(
            (out[i].y - f64::from(expected[2 * i + 1])).abs() <= 1e-5,
            "case {i}"
        );
    }
}

/// The outdoor model (workspace normalisation, displacement output) reproduces its PyTorch
/// fixture too: within 1e-5 m plus two float32 roundings of the largest coordinate it reads
/// (positions up to ~1.5 km, where one rounding is 1.2e-4 m; `training/fast_graph.py`
/// checks the same tolerance when it writes the graph).
#[test]
fn the_outdoor_model_matches_pytorch_within_float32_rounding() {
    let (mut m, inputs, expected) = model_and_fixture(&models().join("outdoor"));
    let n = expected.len() / 2;
    assert!(n >= 32, "fixture has {n} cases");
    let largest = inputs.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let ulp = f32::from_bits(largest.to_bits() + 1) - largest;
    let tolerance = 1e-5 + 2.0 * ulp;
    let got = m.predict_raw(&inputs, n).expect("a prediction");
    let worst = largest_difference(&got, &expected);
    assert!(
        worst <= tolerance,
        "largest difference {worst} m, tolerance {tolerance} m"
    );
}
