//! Motion models the particle filter predicts with.
//!
//! A model maps each particle's history of its last `K_in` positions (oldest first, world
//! ENU) to its next position, one filter period later. Models take the whole batch in one
//! call so that a learned model can run every particle in one inference. Models are
//! deterministic; the filter adds the process noise.

pub mod constant_velocity;
pub mod histories;
pub mod sections;

/// The lab's learned model, the default of `motion.dmmn_model` (from the current directory).
pub const DEFAULT_MODEL_PATH: &str = "models/dmmn.onnx";

use thiserror::Error;

pub use constant_velocity::ConstantVelocity;
pub use histories::Histories;

use std::path::PathBuf;

use crate::world::geometry::Enu2;

/// Names of the motion models a particle filter can use (`--motion`).
pub const MODEL_NAMES: &[&str] = &["cv", "dmmn"];

/// What the motion models are built from (the configuration assembles it).
#[derive(Debug, Clone, PartialEq)]
pub struct MotionParams {
    /// Filter period dt, s: the step every model predicts over.
    pub dt_s: f64,
    /// History length the filter keeps (K_in).
    pub history_len: usize,
    /// Constant-velocity model: the largest speed a particle is given, m/s.
    pub cv_max_speed_mps: f64,
    /// The learned model's ONNX file (`dmmn.json` beside it).
    pub dmmn_model: PathBuf,
    /// The ONNX Runtime library to load; `None`: the default search.
    pub onnxruntime_library: Option<PathBuf>,
    /// The world the filter runs in, checked against the one a learned model was trained
    /// for; `None`: not checked.
    pub world: Option<crate::world::signature::WorldSignature>,
    /// Use a learned model trained for another world anyway (with a warning).
    pub allow_model_from_other_world: bool,
}

/// Loads a learned motion model by name (`infotrack-dmmn` provides the one infotrack
/// ships); the core itself reads no model file.
pub type LearnedLoader<'a> =
    &'a dyn Fn(&str, &MotionParams) -> Result<Box<dyn MotionModel>, MotionError>;

/// Builds the named motion model: constant velocity here, any other name through `learned`.
pub fn build(
    name: &str,
    params: &MotionParams,
    learned: LearnedLoader<'_>,
) -> Result<Box<dyn MotionModel>, MotionError> {
    match name {
        "cv" => Ok(Box::new(ConstantVelocity::new(
            params.cv_max_speed_mps,
            params.dt_s,
        ))),
        other if MODEL_NAMES.contains(&other) => learned(other, params),
        other => Err(unknown_model(other)),
    }
}

/// The error for a motion-model name that names no model.
pub fn unknown_model(name: &str) -> MotionError {
    MotionError::Backend {
        model: name.to_string(),
        message: format!(
            "no such motion model (expected one of {})",
            MODEL_NAMES.join(", ")
        ),
    }
}

/// A loader that knows no learned model: for programs and tests that use only the
/// built-in constant-velocity model.
pub fn no_learned_model(name: &str, _: &MotionParams) -> Result<Box<dyn MotionModel>, MotionError> {
    Err(MotionError::Backend {
        model: name.to_string(),
        message: "this program was built without learned motion models".into(),
    })
}

/// Why a motion model could not predict.
#[derive(Debug, Error)]
pub enum MotionError {
    /// The model needs a different history length than the filter keeps.
    #[error(
        "motion model `{model}` needs histories of {expected} positions, the filter keeps {got}"
    )]
    HistoryLength {
        /// The model.
        model: String,
        /// What it needs.
        expected: usize,
        /// What it was given.
        got: usize,
    },
    /// The model's runtime failed.
    #[error("motion model `{model}` failed: {message}")]
    Backend {
        /// The model.
        model: String,
        /// What went wrong.
        message: String,
    },
}

/// A batch predictor of next positions.
pub trait MotionModel: Send {
    /// Short name used in reports (`cv`, `dmmn`).
    fn name(&self) -> &str;

    /// Number of history positions the model reads (`K_in`); `None` if any length works.
    fn required_history_len(&self) -> Option<usize>;

    /// Whether the model knows where the roads go (a learned model trained on this world
    /// turns where the roads turn); the tracker injects road hypotheses before the first
    /// sighting, and the filter weighs a track's heading against its road, only for models
    /// that do not. Re-routing at junctions applies to every model: one prediction per
    /// track cannot split a belief at a fork.
    fn knows_the_roads(&self) -> bool {
        false
    }

    /// Writes into `out[i]` the predicted next position of track `i` of `histories`.
    ///
    /// `out.len() == histories.len()`. Outputs may be non-finite if the model misbehaves:
    /// the caller checks.
    fn predict(&mut self, histories: &Histories, out: &mut [Enu2]) -> Result<(), MotionError>;
}
