//! The deep motion model network (DMMN): the paper's learned transformer, run with ONNX
//! Runtime on every particle in one batch.
//!
//! The model file (`dmmn.onnx`, made by `training/train_dmmn.py`) takes `history`
//! `[batch, K_in, 2]` (world ENU metres, oldest first, f32) and returns `next` `[batch, 2]`,
//! the absolute next position in metres. Any normalisation lives inside the graph. Beside it,
//! `dmmn.json` says which K_in and filter period the model was trained for; both are checked
//! against the configuration at load.
//!
//! ONNX Runtime is loaded at run time from `libonnxruntime.so` (the `ort` crate's
//! `load-dynamic`): from `motion.onnxruntime_library` in the config, else `ORT_DYLIB_PATH`,
//! else beside the program (where `scripts/install.sh` puts it), else `.deps/onnxruntime/`
//! where `scripts/setup.sh` puts the library of PyPI's
//! `onnxruntime==1.31.1` wheel. One environment per process, held for the process's life.
#![deny(missing_docs)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use ort::environment::Environment;
use ort::session::builder::GraphOptimizationLevel;
use ort::session::Session;
use ort::value::{TensorElementType, TensorRef, ValueType};
use serde::Deserialize;

use infotrack_core::motion::{Histories, MotionError, MotionModel, MotionParams};
use infotrack_core::world::geometry::Enu2;
use infotrack_core::world::signature::WorldSignature;

const NAME: &str = "dmmn";
/// The ONNX Runtime release the `ort` crate's API level (31) is built for.
pub const ORT_LIBRARY_FILE: &str = "libonnxruntime.so.1.31.1";

fn err(message: impl Into<String>) -> MotionError {
    MotionError::Backend {
        model: NAME.into(),
        message: message.into(),
    }
}

/// What `dmmn.json` says about the model.
#[derive(Debug, Clone, Deserialize)]
pub struct DmmnMetadata {
    /// Format tag, `infotrack-dmmn/1`.
    pub format: String,
    /// History length the model reads.
    pub k_in: usize,
    /// Filter period the model was trained at, seconds.
    pub dt_s: f64,
    /// Parameter count.
    pub parameters: u64,
    /// Input normalisation (documentation; it is inside the graph).
    pub input_normalisation: String,
    /// Output convention inside the graph (`absolute` or `displacement`).
    pub output_convention: String,
    /// The world it was trained for (models trained before this was recorded have none).
    #[serde(default)]
    pub world: Option<WorldSignature>,
}

impl DmmnMetadata {
    /// Reads and checks a metadata file.
    pub fn load(path: &Path) -> Result<Self, MotionError> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            err(format!(
                "cannot read model metadata {}: {e}",
                path.display()
            ))
        })?;
        let meta: Self = serde_json::from_str(&text).map_err(|e| {
            err(format!(
                "model metadata {} is not valid: {e}",
                path.display()
            ))
        })?;
        if meta.format != "infotrack-dmmn/1" {
            return Err(err(format!(
                "model metadata {}: format `{}` is not infotrack-dmmn/1",
                path.display(),
                meta.format
            )));
        }
        Ok(meta)
    }

    /// Checks the model was trained for this filter: same K_in and period.
    pub fn check_against(&self, params: &MotionParams, path: &Path) -> Result<(), MotionError> {
        if self.k_in != params.history_len {
            return Err(err(format!(
                "model metadata {} says K_in = {}, but filter.history_len = {}",
                path.display(),
                self.k_in,
                params.history_len
            )));
        }
        let dt = params.dt_s;
        if (self.dt_s - dt).abs() > 1e-3 * dt {
            return Err(err(format!(
                "model metadata {} says dt = {} s, but timing.filter_hz = {} gives {} s",
                path.display(),
                self.dt_s,
                1.0 / dt,
                dt
            )));
        }
        self.check_world(params, path)
    }

    /// Refuses a model trained for another world (another road graph, workspace or target
    /// speeds) unless the user allowed it; a model that does not say is used with a warning.
    fn check_world(&self, params: &MotionParams, path: &Path) -> Result<(), MotionError> {
        let Some(here) = &params.world else {
            return Ok(());
        };
        let Some(trained) = &self.world else {
            tracing::warn!(
                "model metadata {} does not say which world the model was trained for; using it in world {} unchecked",
                path.display(),
                here.describe()
            );
            return Ok(());
        };
        let differences = trained.differences(here);
        if differences.is_empty() {
            return Ok(());
        }
        let what = format!(
            "model metadata {} says the model was trained for world {}, but this is world {}: they differ in {}",
            path.display(),
            trained.describe(),
            here.describe(),
            differences.join(", ")
        );
        if params.allow_model_from_other_world {
            tracing::warn!("{what}; used anyway (motion.allow_model_from_other_world = true)");
            return Ok(());
        }
        Err(err(format!(
            "{what}. Train a model for this world (README: \"A model for your own area\"), use --motion cv, or set motion.allow_model_from_other_world = true"
        )))
    }
}

/// Why ONNX Runtime could not be set up, remembered for the process's life (it cannot be
/// initialised twice).
#[derive(Debug, Clone, thiserror::Error)]
#[error("{0}")]
struct RuntimeUnavailable(String);

static ENVIRONMENT: OnceLock<Result<Environment, RuntimeUnavailable>> = OnceLock::new();

/// Where the ONNX Runtime library is looked for, in order. A configured path is the only
/// candidate: a user who names a library must not silently get another.
pub fn library_candidates(configured: Option<&Path>) -> Vec<PathBuf> {
    if let Some(p) = configured {
        return vec![p.to_path_buf()];
    }
    let mut v = Vec::new();
    if let Some(p) = std::env::var_os("ORT_DYLIB_PATH") {
        v.push(PathBuf::from(p));
    }
    // Installed (scripts/install.sh): beside the program.
    if let Some(dir) = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(Path::to_path_buf))
    {
        v.push(dir.join(ORT_LIBRARY_FILE));
    }
    v.push(PathBuf::from(".deps/onnxruntime").join(ORT_LIBRARY_FILE));
    v.push(
        Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .join(".deps/onnxruntime")
            .join(ORT_LIBRARY_FILE),
    );
    v
}

/// The process's ONNX Runtime environment, created on first use from the first library
/// found. A failure is remembered: ONNX Runtime cannot be initialised twice.
pub fn environment(configured: Option<&Path>) -> Result<Environment, MotionError> {
    ENVIRONMENT
        .get_or_init(|| {
            let candidates = library_candidates(configured);
            let Some(lib) = candidates.iter().find(|p| p.is_file()) else {
                return Err(RuntimeUnavailable(format!(
                    "ONNX Runtime library not found (looked at: {}). Run `bash scripts/setup.sh`, which fetches \
                     onnxruntime==1.31.1 from PyPI into .deps/onnxruntime/, or set ORT_DYLIB_PATH to a {ORT_LIBRARY_FILE}",
                    candidates.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
                )));
            };
            tracing::info!("ONNX Runtime loaded from {}", lib.display());
            let builder = ort::init_from(lib)
                .map_err(|e| {
                RuntimeUnavailable(format!("cannot load ONNX Runtime from {}: {e}", lib.display()))
            })?;
            builder
                .with_name("infotrack")
                .build()
                .map_err(|e| {
                    RuntimeUnavailable(format!(
                        "cannot create the ONNX Runtime environment from {}: {e}",
                        lib.display()
                    ))
                })
        })
        .clone()
        .map_err(|e| err(e.0))
}

/// The DMMN as a [`MotionModel`].
pub struct Dmmn {
    session: Session,
    k_in: usize,
    input: Vec<f32>,
    metadata: DmmnMetadata,
}

impl std::fmt::Debug for Dmmn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Dmmn")
            .field("k_in", &self.k_in)
            .field("metadata", &self.metadata)
            .finish()
    }
}

pub use infotrack_core::motion::DEFAULT_MODEL_PATH;

/// `models/dmmn.json` beside `models/dmmn.onnx`.
pub fn metadata_path(model: &Path) -> PathBuf {
    model.with_extension("json")
}

impl Dmmn {
    /// Loads the model and its metadata and checks both against the configuration.
    pub fn load(model_path: &Path, params: &MotionParams) -> Result<Self, MotionError> {
        if !model_path.is_file() {
            let cwd =
                std::env::current_dir().map_or_else(|_| "?".into(), |d| d.display().to_string());
            return Err(err(format!(
                "model file {} not found (set motion.dmmn_model: a relative path there is read from the config file's folder; without the key, {DEFAULT_MODEL_PATH} is read from the current directory, {cwd})",
                model_path.display()
            )));
        }
        let meta_path = metadata_path(model_path);
        let metadata = DmmnMetadata::load(&meta_path)?;
        metadata.check_against(params, &meta_path)?;
        let env = environment(params.onnxruntime_library.as_deref())?;
        let session = Session::builder(&env)
            .and_then(|b| Ok(b.with_optimization_level(GraphOptimizationLevel::Level3)?))
            .and_then(|b| Ok(b.with_intra_threads(1)?))
            .and_then(|b| Ok(b.with_inter_threads(1)?))
            .and_then(|b| Ok(b.with_intra_op_spinning(false)?))
            .and_then(|b| Ok(b.with_inter_op_spinning(false)?))
            .and_then(|mut b| b.commit_from_file(model_path))
            .map_err(|e| err(format!("cannot load model {}: {e}", model_path.display())))?;
        let k_in = metadata.k_in;
        check_outlet(&session, model_path, true, &[-1, k_in as i64, 2])?;
        check_outlet(&session, model_path, false, &[-1, 2])?;
        let mut model = Self {
            session,
            k_in,
            input: Vec::new(),
            metadata,
        };
        model.refuse_non_finite(model_path, params)?;
        Ok(model)
    }

    /// Runs a probe batch of plausible histories (straight drives through the workspace's
    /// centre at the world's speeds, four headings) and refuses the model if any prediction
    /// is NaN or infinite: a model with broken weights would otherwise fly, degraded.
    fn refuse_non_finite(&mut self, path: &Path, params: &MotionParams) -> Result<(), MotionError> {
        let (centre, speeds) = match &params.world {
            Some(w) => {
                let b = &w.workspace_enu;
                (
                    [0.5 * (b.x_min_m + b.x_max_m), 0.5 * (b.y_min_m + b.y_max_m)],
                    [w.target_speed.cruise_mps, w.target_speed.max_mps],
                )
            }
            None => ([0.0, 0.0], [0.5, 1.0]),
        };
        let mut batch = Vec::new();
        for heading in [0.0f64, 0.5, 1.0, 1.5].map(|q| q * std::f64::consts::PI) {
            for v in speeds {
                for k in 0..self.k_in {
                    // Oldest first, ending at the centre.
                    let back = (self.k_in - 1 - k) as f64 * v * params.dt_s;
                    batch.push((centre[0] - back * heading.cos()) as f32);
                    batch.push((centre[1] - back * heading.sin()) as f32);
                }
            }
        }
        let n = batch.len() / (2 * self.k_in);
        let out = self.predict_raw(&batch, n)?;
        if out.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(err(format!(
                "model {} predicts NaN or infinite positions for plausible histories (its weights are broken?); refused",
                path.display()
            )))
        }
    }

    /// The metadata it was loaded with.
    pub fn metadata(&self) -> &DmmnMetadata {
        &self.metadata
    }

    /// Predicts for raw f32 histories `[n, K_in, 2]`; for tests and benchmarks.
    pub fn predict_raw(&mut self, histories: &[f32], n: usize) -> Result<Vec<f32>, MotionError> {
        let mut out = Vec::with_capacity(2 * n);
        self.run(histories, n, |data| out.extend_from_slice(data))?;
        Ok(out)
    }

    /// Runs the model on `[n, K_in, 2]` histories (read in place, no copy) and hands the
    /// `[n, 2]` output to `take` straight from ONNX Runtime's buffer (no copy either).
    fn run(
        &mut self,
        histories: &[f32],
        n: usize,
        take: impl FnOnce(&[f32]),
    ) -> Result<(), MotionError> {
        let input = TensorRef::from_array_view(([n, self.k_in, 2], histories))
            .map_err(|e| err(format!("cannot build the input tensor: {e}")))?;
        let outputs = self
            .session
            .run(ort::inputs![input])
            .map_err(|e| err(format!("inference failed: {e}")))?;
        let (shape, data) = outputs[0]
            .try_extract_tensor::<f32>()
            .map_err(|e| err(format!("output is not an f32 tensor: {e}")))?;
        if shape.len() != 2 || shape[0] as usize != n || shape[1] != 2 {
            return Err(err(format!(
                "output has shape {shape:?}, expected [{n}, 2]"
            )));
        }
        take(data);
        Ok(())
    }
}

/// The model's first input (or output) must be f32 with this shape (-1: any).
fn check_outlet(
    session: &Session,
    path: &Path,
    input: bool,
    want: &[i64],
) -> Result<(), MotionError> {
    let (what, outlets) = if input {
        ("input", session.inputs())
    } else {
        ("output", session.outputs())
    };
    let Some(o) = outlets.first() else {
        return Err(err(format!("model {} has no {what}", path.display())));
    };
    match o.dtype() {
        ValueType::Tensor { ty, shape, .. } => {
            let dims: Vec<i64> = shape.iter().copied().collect();
            let fits = *ty == TensorElementType::Float32
                && dims.len() == want.len()
                && dims
                    .iter()
                    .zip(want)
                    .all(|(d, w)| *w == -1 || *d == -1 || d == w);
            if fits {
                Ok(())
            } else {
                Err(err(format!(
                    "model {} {what} `{}` is {ty:?} {dims:?}, expected f32 {want:?} (batch, K_in = {}, xy)",
                    path.display(),
                    o.name(),
                    want.get(1).copied().unwrap_or(2)
                )))
            }
        }
        other => Err(err(format!(
            "model {} {what} `{}` is {other:?}, expected an f32 tensor",
            path.display(),
            o.name()
        ))),
    }
}

impl MotionModel for Dmmn {
    fn name(&self) -> &str {
        NAME
    }

    fn required_history_len(&self) -> Option<usize> {
        Some(self.k_in)
    }

    fn knows_the_roads(&self) -> bool {
        true
    }

    fn predict(&mut self, histories: &Histories, out: &mut [Enu2]) -> Result<(), MotionError> {
        let n = histories.len();
        if histories.k_in() != self.k_in {
            return Err(MotionError::HistoryLength {
                model: NAME.into(),
                expected: self.k_in,
                got: histories.k_in(),
            });
        }
        if n == 0 {
            return Ok(());
        }
        let mut input = std::mem::take(&mut self.input);
        input.clear();
        input.extend(histories.as_slice().iter().map(|v| *v as f32));
        let result = self.run(&input, n, |data| {
            // Non-finite outputs are passed on: the filter rejects and counts them.
            for (o, xy) in out.iter_mut().zip(data.chunks_exact(2)) {
                *o = Enu2::new(xy[0] as f64, xy[1] as f64);
            }
        });
        self.input = input;
        result
    }
}

/// Loads the learned motion model named `name` (`dmmn`) from `params.dmmn_model`: the
/// loader the programs hand to [`infotrack_core::motion::build`].
pub fn load_learned(
    name: &str,
    params: &MotionParams,
) -> Result<Box<dyn MotionModel>, MotionError> {
    match name {
        "dmmn" => Ok(Box::new(Dmmn::load(&params.dmmn_model, params)?)),
        other => Err(infotrack_core::motion::unknown_model(other)),
    }
}
