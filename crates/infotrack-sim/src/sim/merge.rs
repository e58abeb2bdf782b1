//! A campaign joined from its shards (`sim --shard K/N --json`, `infotrack merge`): the
//! shards' runs put back in campaign order and aggregated, compared and tested exactly as
//! one process would (every run draws from its own seeded streams, and the per-run figures
//! are read back bit for bit). What one process measures over all steps at once, the
//! median filter and guidance step times, is the median of the runs' medians here: those
//! are measurements of the machine, not results.

use std::collections::BTreeMap;

use serde_json::{json, Value};

use super::monte_carlo::{compare, ComboResult, MonteCarloResult, Shard, VisionSummary};
use infotrack_core::metrics::{median, RunSummary};

/// Shards that do not make one campaign.
#[derive(Debug, thiserror::Error)]
#[error("{shard}: {message}")]
pub struct MergeError {
    /// The shard's name (its file).
    pub shard: String,
    /// What is wrong.
    pub message: String,
}

/// What every shard of one campaign must agree on.
const CAMPAIGN_KEYS: [&str; 5] = ["seed", "scenario", "duration_s", "config", "infotrack"];

/// One combination's runs gathered from the shards: campaign index -> (summary, the JSON
/// entry with its names), and the frame counts.
#[derive(Default)]
struct Gathered {
    runs: BTreeMap<u64, (RunSummary, Value)>,
    vision: Option<VisionSummary>,
}

/// Joins `shards` (name, results JSON) into the campaign's result and its results JSON.
pub fn merge(shards: &[(String, Value)]) -> Result<(MonteCarloResult, Value), MergeError> {
    let fail = |shard: &str, message: String| MergeError {
        shard: shard.to_string(),
        message,
    };
    let (first_name, first) = shards
        .first()
        .ok_or_else(|| fail("merge", "no shard given".into()))?;
    check_shards(shards)?;
    let mut combos: Vec<((String, String), Gathered)> = Vec::new();
    for (name, v) in shards {
        for c in v["results"].as_array().into_iter().flatten() {
            let key = (str_of(&c["guidance"]), str_of(&c["motion"]));
            let at = match combos.iter().position(|(k, _)| *k == key) {
                Some(i) => i,
                None => {
                    combos.push((key, Gathered::default()));
                    combos.len() - 1
                }
            };
            gather(&mut combos[at].1, c).map_err(|m| fail(name, m))?;
        }
    }
    let mut results = Vec::new();
    for ((g, m), gathered) in combos {
        results.push(combo_of(g, m, gathered).map_err(|e| fail(first_name, e))?);
    }
    let seed = first["seed"].as_u64().unwrap_or(0);
    compare(&mut results, seed);
    let result = MonteCarloResult {
        results,
        refused: serde_json::from_value(first["refused"].clone()).unwrap_or_default(),
        seed,
        scenario: str_of(&first["scenario"]),
        duration_s: first["duration_s"].as_f64().unwrap_or(f64::NAN),
        outputs: BTreeMap::new(),
    };
    let json = results_json(&result, shards).map_err(|e| fail(first_name, e))?;
    Ok((result, json))
}

fn str_of(v: &Value) -> String {
    v.as_str().unwrap_or("?").to_string()
}

/// The shards agree on the campaign and are each one of the same N, every one of them
/// once; returns N.
fn check_shards(shards: &[(String, Value)]) -> Result<u64, MergeError> {
    let first = &shards[0].1;
    let mut seen = BTreeMap::new();
    for (name, v) in shards {
        let fail = |message: String| MergeError {
            shard: name.clone(),
            message,
        };
        let shard: Shard = serde_json::from_value(v["shard"].clone())
            .map_err(|_| fail("no \"shard\": not written by `sim --shard K/N --json`".into()))?;
        for key in CAMPAIGN_KEYS {
            if v[key] != first[key] {
                return Err(fail(format!(
                    "its {key} {} differs from {}'s {}: not the same campaign",
                    v[key], shards[0].0, first[key]
                )));
            }
        }
        if let Some(other) = seen.insert(shard.index, name.clone()) {
            return Err(fail(format!("shard {} is also {other}", shard.index)));
        }
        if seen.keys().any(|k| *k >= shard.count) || shard.count != count_of(first) {
            return Err(fail(format!(
                "a shard of {} where the first is of {}",
                shard.count,
                count_of(first)
            )));
        }
    }
    let count = count_of(first);
    if seen.len() as u64 != count {
        let missing: Vec<u64> = (0..count).filter(|k| !seen.contains_key(k)).collect();
        return Err(MergeError {
            shard: "merge".into(),
            message: format!("shards {missing:?} of {count} are missing"),
        });
    }
    Ok(count)
}

fn count_of(v: &Value) -> u64 {
    v["shard"]["count"].as_u64().unwrap_or(0)
}

/// Adds one shard's runs of a combination.
fn gather(g: &mut Gathered, combo: &Value) -> Result<(), String> {
    let runs = combo["per_run"].as_array().cloned().unwrap_or_default();
    for entry in runs {
        let index = entry["run"]
            .as_u64()
            .ok_or_else(|| format!("a run of {} has no \"run\" index", combo["guidance"]))?;
        let summary: RunSummary = serde_json::from_value(entry.clone())
            .map_err(|e| format!("run {index} of {}: {e}", combo["guidance"]))?;
        if g.runs.insert(index, (summary, entry)).is_some() {
            return Err(format!(
                "run {index} of {} is in two shards",
                combo["guidance"]
            ));
        }
    }
    if let Some(v) = combo.get("vision").filter(|v| v.is_object()) {
        let n = |k: &str| v[k].as_u64().unwrap_or(0);
        g.vision = Some(VisionSummary::sum(
            g.vision,
            n("frames"),
            n("detections"),
            n("roi_hits"),
        ));
    }
    Ok(())
}

/// A combination's aggregates from its gathered runs, which must be 0..R without a gap.
fn combo_of(guidance: String, motion: String, g: Gathered) -> Result<ComboResult, String> {
    let indices: Vec<u64> = g.runs.keys().copied().collect();
    if indices.iter().enumerate().any(|(i, r)| *r != i as u64) {
        return Err(format!(
            "{guidance}/{motion}: runs {indices:?} are not 0..{} without a gap",
            indices.len()
        ));
    }
    let per_run: Vec<RunSummary> = g.runs.values().map(|(s, _)| *s).collect();
    let medians = [
        median(&per_run.iter().map(|s| s.filter_step_ms).collect::<Vec<_>>()),
        median(
            &per_run
                .iter()
                .map(|s| s.guidance_step_ms)
                .collect::<Vec<_>>(),
        ),
    ];
    Ok(ComboResult::from_runs(
        (guidance, motion),
        per_run,
        indices,
        medians,
        g.vision,
    ))
}

/// The merged results as JSON, each run keeping the names its shard gave it (index, seed,
/// world, version, track), and the campaign's version and config.
fn results_json(result: &MonteCarloResult, shards: &[(String, Value)]) -> Result<Value, String> {
    let mut v = serde_json::to_value(result).map_err(|e| e.to_string())?;
    let mut entries: BTreeMap<(String, String, u64), Value> = BTreeMap::new();
    for (_, s) in shards {
        for c in s["results"].as_array().into_iter().flatten() {
            for e in c["per_run"].as_array().into_iter().flatten() {
                let key = (
                    str_of(&c["guidance"]),
                    str_of(&c["motion"]),
                    e["run"].as_u64().unwrap_or(0),
                );
                entries.insert(key, e.clone());
            }
        }
    }
    for combo in v["results"].as_array_mut().into_iter().flatten() {
        let (g, m) = (str_of(&combo["guidance"]), str_of(&combo["motion"]));
        for (i, run) in combo["per_run"]
            .as_array_mut()
            .into_iter()
            .flatten()
            .enumerate()
        {
            let Some(named) = entries.get(&(g.clone(), m.clone(), i as u64)) else {
                continue;
            };
            for key in ["run", "seed", "world", "version", "track"] {
                if let Some(x) = named.get(key) {
                    run[key] = x.clone();
                }
            }
        }
    }
    v["infotrack"] = shards[0].1["infotrack"].clone();
    v["config"] = shards[0].1["config"].clone();
    v["merged_from"] = json!(shards.len());
    Ok(v)
}
