//! The motion models' table of a configuration.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// Motion models of the particle filter.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionConfig {
    /// Particle constant-velocity model: the largest speed a particle is given, m/s.
    pub cv_max_speed_mps: f64,
    /// The learned model for `--motion dmmn`: an ONNX file with `dmmn.json` beside it.
    /// A relative path is taken from the config file's folder; the default
    /// `models/dmmn.onnx` (the lab's) from the current directory.
    #[serde(default = "default_dmmn_model")]
    pub dmmn_model: PathBuf,
    /// The ONNX Runtime shared library to load; default: `ORT_DYLIB_PATH`, then beside the
    /// program (`scripts/install.sh`), then `.deps/onnxruntime/libonnxruntime.so.1.31.1`
    /// (`scripts/setup.sh`).
    #[serde(default)]
    pub onnxruntime_library: Option<PathBuf>,
    /// Use a learned model whose metadata says it was trained for another world (other
    /// roads, workspace or target speeds) anyway, with a warning. Default false: such a
    /// model is refused at start, naming both worlds.
    #[serde(default)]
    pub allow_model_from_other_world: bool,
}

fn default_dmmn_model() -> PathBuf {
    PathBuf::from(super::DEFAULT_MODEL_PATH)
}

impl MotionConfig {
    /// Checks `motion`: a top speed.
    pub fn check(&self) -> crate::check::Checked {
        crate::check::positive("motion.cv_max_speed_mps", self.cv_max_speed_mps)
    }
}
