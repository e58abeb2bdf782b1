//! `infotrack params check|apply`: compare a parameter file with a vehicle, or write it.

use std::fmt::Write;

use super::link::{LinkError, VehicleLink};
use super::params_file::{FileParam, ParamType};
use std::time::Duration;

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
) -> Vec<Result<(f64, ParamType), ParamStatus>> {
    let list = link.param_list(LIST_SILENCE).await;
    let mut out = Vec::with_capacity(params.len());
    for p in params {
        out.push(match list.values.get(&p.name) {
            Some(v) => Ok(*v),
            None if list.complete => Err(ParamStatus::Missing),
            None => match link.param_read(&p.name).await {
                Ok(v) => Ok(v),
                Err(LinkError::NoSuchParam(_)) => Err(ParamStatus::Missing),
                Err(_) => Err(ParamStatus::NoAnswer),
            },
        });
    }
    out
}

fn row(p: &FileParam, vehicle_value: Option<f64>, status: ParamStatus) -> ParamRow {
    ParamRow {
        name: p.name.clone(),
        line: p.line,
        file_value: p.value,
        vehicle_value,
        status,
    }
}

/// Reads every parameter of the file from the vehicle.
pub async fn check(link: &VehicleLink, params: &[FileParam]) -> Vec<ParamRow> {
    let found = read_all(link, params).await;
    params
        .iter()
        .zip(found)
        .map(|(p, f)| match f {
            Ok((v, _)) if same(v, p.value) => row(p, Some(v), ParamStatus::Match),
            Ok((v, _)) => row(p, Some(v), ParamStatus::Mismatch),
            Err(status) => row(p, None, status),
        })
        .collect()
}

/// Writes every parameter of the file, with the type the vehicle reports for it: all or
/// nothing. Every parameter is read first; if the vehicle lacks one, or its type cannot hold
/// the file's value, nothing is written and the report says which. If a write fails
/// midway, the ones written before are set back to the values read before.
pub async fn apply(link: &VehicleLink, params: &[FileParam]) -> Vec<ParamRow> {
    let found: Vec<_> = read_all(link, params)
        .await
        .into_iter()
        .zip(params)
        .map(|(f, p)| match f {
            Ok((_, ty)) if !ty.accepts(p.value) => Err(ParamStatus::DoesNotFit),
            other => other,
        })
        .collect();
    if found.iter().any(|f| f.is_err()) {
        return params
            .iter()
            .zip(found)
            .map(|(p, f)| match f {
                Err(status) => row(p, None, status),
                Ok((v, _)) => row(p, Some(v), ParamStatus::NotWritten),
            })
            .collect();
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
        let _ = writeln!(
            s,
            "{:<17} {:>5} {:>14} {:>14}  {status}",
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
