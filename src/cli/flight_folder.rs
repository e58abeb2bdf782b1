//! A flight folder that explains itself: `config.toml` (the configuration as loaded, every
//! key filled in, the GeoJSON world's sections inline and file paths absolute, so that it
//! loads again from anywhere), `flight.json` (what flew: version and commit, seed, motion
//! model, vehicle, the SHA-256 of every file the config read, start and end in UTC, how it
//! ended) and `daemon.log` (the daemon's log at `info`, or at `--log`'s filter).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde_json::{json, Map, Value};
use sha2::{Digest, Sha256};

use infotrack::config::Config;
use infotrack::daemon::DaemonReport;

use super::folder_log;

/// The folder's `flight.json`, kept up to date as the flight goes from start to end.
pub struct FlightFolder {
    dir: PathBuf,
    manifest: Map<String, Value>,
}

/// What a config was loaded from: a file, or the embedded default.
pub fn source_name(source: Option<&Path>) -> String {
    source.map_or_else(
        || "the embedded default (config/default.toml)".to_string(),
        |p| p.display().to_string(),
    )
}

impl FlightFolder {
    /// Writes `config.toml` and `flight.json` (outcome `flying`) into `dir` and starts
    /// copying the log into `daemon.log`. `source`: the config file (`None`: the embedded
    /// default).
    pub fn begin(dir: &Path, cfg: &Config, source: Option<&Path>, seed: u64) -> Result<Self> {
        let as_loaded = self_contained(cfg, source)?;
        let text = format!(
            "# The configuration this flight loaded from {}, as loaded: every key filled in,\n\
             # the GeoJSON world's sections inline, file paths absolute. `infotrack replay` of\n\
             # this folder reads it.\n\n{}",
            source_name(source),
            toml::to_string(&as_loaded).context("the config as TOML")?
        );
        write(&dir.join("config.toml"), text.as_bytes())?;
        folder_log::start(&dir.join("daemon.log"))
            .with_context(|| format!("cannot write {}", dir.join("daemon.log").display()))?;
        let mut manifest = Map::new();
        manifest.insert(
            "infotrack".into(),
            json!({"version": env!("CARGO_PKG_VERSION"), "commit": env!("INFOTRACK_COMMIT")}),
        );
        manifest.insert(
            "config".into(),
            json!({"source": source_name(source), "as_loaded": "config.toml"}),
        );
        manifest.insert("files".into(), Value::Array(hashed_files(cfg, source)?));
        manifest.insert("seed".into(), seed.into());
        manifest.insert("motion".into(), cfg.daemon.motion.clone().into());
        manifest.insert("vehicle_url".into(), cfg.daemon.vehicle.clone().into());
        manifest.insert("started_utc".into(), now_utc().into());
        manifest.insert("outcome".into(), "flying".into());
        let folder = Self {
            dir: dir.to_path_buf(),
            manifest,
        };
        folder.write_manifest()?;
        Ok(folder)
    }

    /// The flight ended (cleanly or stopped by an error in flight, which `report` says).
    pub fn flown(mut self, report: &DaemonReport) -> Result<()> {
        let m = &mut self.manifest;
        m.insert("outcome".into(), "flown".into());
        m.insert("ended_utc".into(), now_utc().into());
        m.insert(
            "stopped_by".into(),
            format!("{:?}", report.stopped_by).into(),
        );
        m.insert("flavour".into(), report.flavor.to_string().into());
        m.insert("vehicle".into(), report.vehicle.clone().into());
        folder_log::stop();
        self.write_manifest()
    }

    /// The flight failed before it could fly (or the daemon returned an error): the folder
    /// says so and why, so that no one mistakes its empty records for a flight.
    pub fn failed(mut self, why: &str) -> Result<()> {
        let m = &mut self.manifest;
        m.insert("outcome".into(), "failed".into());
        m.insert("ended_utc".into(), now_utc().into());
        m.insert("failure".into(), why.into());
        folder_log::stop();
        self.write_manifest()
    }

    fn write_manifest(&self) -> Result<()> {
        let bytes = serde_json::to_vec_pretty(&Value::Object(self.manifest.clone()))
            .context("flight.json")?;
        write(&self.dir.join("flight.json"), &bytes)
    }
}

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

fn now_utc() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}

/// The config as it loads again from any folder: the GeoJSON's sections are already inline
/// (the file is named in `flight.json` with its hash) and every file path is absolute.
fn self_contained(cfg: &Config, source: Option<&Path>) -> Result<Config> {
    let mut c = cfg.clone();
    if let Some(w) = c.world.as_mut() {
        w.geojson = None;
    }
    let absolute = |p: &mut PathBuf| -> Result<()> {
        *p = std::path::absolute(&*p).with_context(|| format!("{}", p.display()))?;
        Ok(())
    };
    for p in c
        .daemon
        .calibration
        .iter_mut()
        .chain(c.daemon.signing_key.iter_mut())
    {
        absolute(p)?;
    }
    if let Some(l) = c.motion.onnxruntime_library.as_mut() {
        absolute(l)?;
    }
    // The embedded default's model path is the program's to find, not the config's.
    if source.is_some() {
        absolute(&mut c.motion.dmmn_model)?;
    }
    if let Some(t) = c.target.trajectory.as_mut() {
        for f in t.files_mut() {
            absolute(f)?;
        }
    }
    Ok(c)
}

/// Every file the flight reads, with its role and SHA-256 (one that is not there is listed
/// with `"missing": true`, and the flight's own error says what that did).
fn hashed_files(cfg: &Config, source: Option<&Path>) -> Result<Vec<Value>> {
    let base = source.and_then(Path::parent).unwrap_or(Path::new("."));
    let mut files: Vec<(&str, PathBuf)> = Vec::new();
    if let Some(s) = source {
        files.push(("config", s.to_path_buf()));
    }
    if let Some(g) = cfg.world.as_ref().and_then(|w| w.geojson.as_ref()) {
        files.push(("world.geojson", base.join(g)));
    }
    if cfg.daemon.motion == "dmmn" {
        files.push(("motion.dmmn_model", cfg.motion.dmmn_model.clone()));
    }
    if let Some(c) = &cfg.daemon.calibration {
        files.push(("daemon.calibration", c.clone()));
    }
    if let Some(t) = &cfg.target.trajectory {
        files.extend(
            t.files()
                .into_iter()
                .map(|f| ("target.trajectory", f.clone())),
        );
    }
    files
        .into_iter()
        .map(|(role, path)| {
            let shown = std::path::absolute(&path).unwrap_or(path.clone());
            Ok(match std::fs::read(&path) {
                Ok(bytes) => json!({"role": role, "path": shown, "sha256": sha256_hex(&bytes)}),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    json!({"role": role, "path": shown, "missing": true})
                }
                Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
            })
        })
        .collect()
}

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}
