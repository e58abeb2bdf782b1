//! `infotrack params check|apply`: compare a parameter file with a vehicle, or write it.

use std::fmt::Write;

use super::link::{LinkError, ParamList, VehicleLink};
use super::params_file::{FileParam, ParamType};
use std::time::Duration;

use super::modes::Flavor;

/// One row of the report.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamRow {
    /// Name.
    pub name: String,
    /// Line in the file.
    pub line: usize,
    /// Value in the file.
    pub file_value: f64,
    /// Value on the vehicle (after apply: the confirmed value), if it has the parameter.
    pub vehicle_value: Option<f64>,
    /// Outcome.
    pub status: ParamStatus,
    /// For a name the vehicle lacks: the nearest one it has, when one is close (a typo).
    pub did_you_mean: Option<String>,
}

/// How a parameter compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamStatus {
    /// Same value.
    Match,
    /// Different value.
    Mismatch,
    /// The vehicle has no such parameter.
    Missing,
    /// The vehicle did not answer for it (the link says why, e.g. a signing mismatch).
    NoAnswer,
    /// Written and confirmed.
    Applied,
    /// Writing failed.
    Failed,
    /// The vehicle's type for it cannot hold the file's value (an integer parameter set to
    /// 1.5, a value out of its type's range).
    DoesNotFit,
    /// Not written: another parameter of the file is missing or does not fit, and a file is
    /// applied whole or not at all.
    NotWritten,
    /// Written, then set back to the value read before, because a later write failed.
    RolledBack,
    /// Written, and a later write failed, and setting it back failed too: the vehicle holds
    /// the file's value for it.
    RollbackFailed,
}

fn same(a: f64, b: f64) -> bool {
    // Values travel as f32.
    (a - b).abs() <= 1e-6 * a.abs().max(b.abs()).max(1.0)
}

/// How long a parameter list may go quiet before it counts as ended.
const LIST_SILENCE: Duration = Duration::from_secs(2);

/// Each file parameter's value and type on the vehicle, or why there is none: one batch
/// (PARAM_REQUEST_LIST) for all, then by name only those a lossy link did not deliver.
async fn read_all(
    link: &VehicleLink,
    params: &[FileParam],
) -> (Vec<Result<(f64, ParamType), ParamStatus>>, ParamList) {
    let list = link.param_list(LIST_SILENCE).await;
    let mut out = Vec::with_capacity(params.len());
    let mut asked = 0usize;
    for p in params {
        if let Some(v) = list.values.get(&p.name) {
            out.push(Ok(*v));
            continue;
        }
        // PX4 lists only the parameters in use (MAV_1_MODE only once MAV_1_CONFIG enables
        // the port) but answers for the others by name: a name the list lacks is asked for,
        // once when the list came whole (the link works), up to MAX_ASKED names.
        if asked >= MAX_ASKED {
            out.push(Err(ParamStatus::Missing));
            continue;
        }
        asked += 1;
        let read = if list.complete {
            link.param_read_tries(&p.name, 1).await
        } else {
            link.param_read(&p.name).await
        };
        out.push(match read {
            Ok(v) => Ok(v),
            Err(LinkError::NoSuchParam(_)) => Err(ParamStatus::Missing),
            Err(_) if list.complete => Err(ParamStatus::Missing),
            Err(_) => Err(ParamStatus::NoAnswer),
        });
    }
    if asked >= MAX_ASKED {
        tracing::warn!(
            "more than {MAX_ASKED} of the file's names are not in the vehicle's list: the rest were not asked for by name"
        );
    }
    (out, list)
}

/// Names outside the vehicle's list asked for one by one, at most (each may take an
/// acknowledgement timeout).
const MAX_ASKED: usize = 64;

/// The vehicle's name nearest to `name`, if it is a likely typo of it.
pub fn nearest_name(name: &str, list: &ParamList) -> Option<String> {
    list.values
        .keys()
        .map(|k| (strsim::levenshtein(name, k), k))
        .filter(|(d, _)| *d <= 2.max(name.len() / 5))
        .min()
        .map(|(_, k)| k.clone())
}

/// Fills `did_you_mean` for the rows the vehicle lacks.
fn suggest(rows: &mut [ParamRow], list: &ParamList) {
    for r in rows.iter_mut().filter(|r| r.status == ParamStatus::Missing) {
        r.did_you_mean = nearest_name(&r.name, list);
    }
}

fn row(p: &FileParam, vehicle_value: Option<f64>, status: ParamStatus) -> ParamRow {
    ParamRow {
        name: p.name.clone(),
        line: p.line,
        file_value: p.value,
        vehicle_value,
        status,
        did_you_mean: None,
    }
}

/// Reads every parameter of the file from the vehicle.
pub async fn check(link: &VehicleLink, params: &[FileParam]) -> Vec<ParamRow> {
    let (found, list) = read_all(link, params).await;
    let mut rows: Vec<ParamRow> = params
        .iter()
        .zip(found)
        .map(|(p, f)| match f {
            Ok((v, _)) if same(v, p.value) => row(p, Some(v), ParamStatus::Match),
            Ok((v, _)) => row(p, Some(v), ParamStatus::Mismatch),
            Err(status) => row(p, None, status),
        })
        .collect();
    suggest(&mut rows, &list);
    rows
}

/// Writes every parameter of the file, with the type the vehicle reports for it: all or
/// nothing. Every parameter is read first; if the vehicle lacks one, or its type cannot hold
/// the file's value, nothing is written and the report says which. If a write fails
/// midway, the ones written before are set back to the values read before.
pub async fn apply(link: &VehicleLink, params: &[FileParam]) -> Vec<ParamRow> {
    let (found, list) = read_all(link, params).await;
    let found: Vec<_> = found
        .into_iter()
        .zip(params)
        .map(|(f, p)| match f {
            Ok((_, ty)) if !ty.accepts(p.value) => Err(ParamStatus::DoesNotFit),
            other => other,
        })
        .collect();
    if found.iter().any(|f| f.is_err()) {
        let mut rows: Vec<ParamRow> = params
            .iter()
            .zip(found)
            .map(|(p, f)| match f {
                Err(status) => row(p, None, status),
                Ok((v, _)) => row(p, Some(v), ParamStatus::NotWritten),
            })
            .collect();
        suggest(&mut rows, &list);
        return rows;
    }
    let before: Vec<(f64, ParamType)> = found.into_iter().flatten().collect();
    let mut rows: Vec<ParamRow> = Vec::with_capacity(params.len());
    for (p, &(old, ty)) in params.iter().zip(&before) {
        if let Some(file_ty) = p.ty.filter(|t| *t != ty) {
            tracing::warn!(
                "{}: the file says type {file_ty:?}, the vehicle {ty:?}; using the vehicle's",
                p.name
            );
        }
        match link.param_set(&p.name, p.value, ty).await {
            Ok(v) => rows.push(row(p, Some(v), ParamStatus::Applied)),
            Err(e) => {
                tracing::error!(
                    "{}: {e}; setting back the parameters written before",
                    p.name
                );
                rows.push(row(p, Some(old), ParamStatus::Failed));
                roll_back(link, params, &before, &mut rows).await;
                break;
            }
        }
    }
    for p in &params[rows.len()..] {
        rows.push(row(p, None, ParamStatus::NotWritten));
    }
    rows
}

/// Sets every applied row back to the value read before, newest first.
async fn roll_back(
    link: &VehicleLink,
    params: &[FileParam],
    before: &[(f64, ParamType)],
    rows: &mut [ParamRow],
) {
    for i in (0..rows.len()).rev() {
        if rows[i].status != ParamStatus::Applied {
            continue;
        }
        let (old, ty) = before[i];
        rows[i].status = match link.param_set(&params[i].name, old, ty).await {
            Ok(v) => {
                rows[i].vehicle_value = Some(v);
                ParamStatus::RolledBack
            }
            Err(e) => {
                tracing::error!("{}: could not set it back to {old}: {e}", params[i].name);
                ParamStatus::RollbackFailed
            }
        };
    }
}

/// Whether every row is a match or an applied value.
pub fn all_ok(rows: &[ParamRow]) -> bool {
    rows.iter()
        .all(|r| matches!(r.status, ParamStatus::Match | ParamStatus::Applied))
}

/// The report as a table.
pub fn render(rows: &[ParamRow]) -> String {
    let mut s = format!(
        "{:<17} {:>5} {:>14} {:>14}  {}\n",
        "parameter", "line", "file", "vehicle", "status"
    );
    for r in rows {
        let v = r
            .vehicle_value
            .map(|v| format!("{v}"))
            .unwrap_or_else(|| "-".into());
        let status = match r.status {
            ParamStatus::Match => "match",
            ParamStatus::Mismatch => "MISMATCH",
            ParamStatus::Missing => "NOT ON VEHICLE",
            ParamStatus::NoAnswer => "NO ANSWER",
            ParamStatus::Applied => "applied",
            ParamStatus::Failed => "FAILED",
            ParamStatus::DoesNotFit => "DOES NOT FIT ITS TYPE",
            ParamStatus::NotWritten => "not written",
            ParamStatus::RolledBack => "set back (a later write failed)",
            ParamStatus::RollbackFailed => "WRITTEN, SETTING BACK FAILED",
        };
        let hint = r
            .did_you_mean
            .as_ref()
            .map_or_else(String::new, |n| format!(" (did you mean {n}?)"));
        let _ = writeln!(
            s,
            "{:<17} {:>5} {:>14} {:>14}  {status}{hint}",
            r.name, r.line, r.file_value, v
        );
    }
    let bad = rows
        .iter()
        .filter(|r| !matches!(r.status, ParamStatus::Match | ParamStatus::Applied))
        .count();
    let _ = writeln!(s, "{} parameters, {} not as the file says", rows.len(), bad);
    s
}

/// What the operator should know after a report: a file for the other firmware, and the
/// reboot some parameters need before they take effect.
pub fn advice(rows: &[ParamRow], flavor: Flavor, applied: bool) -> Vec<String> {
    let mut out = Vec::new();
    let missing = rows
        .iter()
        .filter(|r| r.status == ParamStatus::Missing)
        .count();
    if missing * 2 > rows.len() {
        let (this, other) = match flavor {
            Flavor::Px4 => ("PX4", "ArduPilot"),
            Flavor::ArduPilot => ("ArduPilot", "PX4"),
        };
        out.push(format!(
            "{missing} of the file's {} parameters are not on this {this} vehicle: is the file for {other}?",
            rows.len()
        ));
    }
    let written = rows.iter().any(|r| r.status == ParamStatus::Applied);
    if applied && written {
        out.push(match flavor {
            Flavor::ArduPilot => "reboot the autopilot now: ArduPilot reads some of these (the \
                GUIDED speeds among them) only at boot"
                .to_string(),
            Flavor::Px4 => "reboot the autopilot now: PX4 applies some parameters (MAVLink and \
                serial ports, the estimator's) only at boot"
                .to_string(),
        });
    }
    out
}

/// Every parameter of the vehicle, sorted by name, as a file of the format the path's
/// extension names (`.params`: QGroundControl, `.parm`/`.param`: Mission Planner).
pub fn render_backup(
    list: &ParamList,
    format: super::params_file::ParamFormat,
    (sysid, compid): (u8, u8),
) -> String {
    let mut all: Vec<(String, f64, ParamType)> = list
        .values
        .iter()
        .map(|(n, (v, t))| (n.clone(), *v, *t))
        .collect();
    all.sort_by(|a, b| a.0.cmp(&b.0));
    match format {
        super::params_file::ParamFormat::Qgc => super::params_file::render_qgc(&all, sysid, compid),
        super::params_file::ParamFormat::MissionPlanner => {
            let pairs: Vec<(String, f64)> = all.into_iter().map(|(n, v, _)| (n, v)).collect();
            super::params_file::render_parm(&pairs)
        }
    }
}
