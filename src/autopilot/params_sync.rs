//! `infotrack params check|apply`: compare a parameter file with a vehicle, or write it.

use std::fmt::Write;

use super::link::{LinkError, VehicleLink};
use super::params_file::FileParam;

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
}

fn same(a: f64, b: f64) -> bool {
    // Values travel as f32.
    (a - b).abs() <= 1e-6 * a.abs().max(b.abs()).max(1.0)
}

/// Reads every parameter of the file from the vehicle.
pub async fn check(link: &VehicleLink, params: &[FileParam]) -> Vec<ParamRow> {
    let mut rows = Vec::new();
    for p in params {
        let (vehicle_value, status) = match link.param_read(&p.name).await {
            Ok((v, _)) if same(v, p.value) => (Some(v), ParamStatus::Match),
            Ok((v, _)) => (Some(v), ParamStatus::Mismatch),
            Err(LinkError::NoSuchParam(_)) => (None, ParamStatus::Missing),
            Err(_) => (None, ParamStatus::NoAnswer),
        };
        rows.push(ParamRow {
            name: p.name.clone(),
            line: p.line,
            file_value: p.value,
            vehicle_value,
            status,
        });
    }
    rows
}

/// Writes every parameter of the file, with the type the vehicle reports for it: all or
/// nothing. Every parameter is read first; if the vehicle lacks one, or its type cannot hold
/// the file's value, nothing is written and the report says which.
pub async fn apply(link: &VehicleLink, params: &[FileParam]) -> Vec<ParamRow> {
    let mut found = Vec::new();
    for p in params {
        found.push(match link.param_read(&p.name).await {
            Err(LinkError::NoSuchParam(_)) => Err(ParamStatus::Missing),
            Err(_) => Err(ParamStatus::NoAnswer),
            Ok((_, ty)) if !ty.accepts(p.value) => Err(ParamStatus::DoesNotFit),
            Ok((v, ty)) => Ok((v, ty)),
        });
    }
    let row = |p: &FileParam, vehicle_value, status| ParamRow {
        name: p.name.clone(),
        line: p.line,
        file_value: p.value,
        vehicle_value,
        status,
    };
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
    let mut rows = Vec::new();
    for (p, f) in params.iter().zip(found) {
        let ty = f.expect("all found").1;
        if let Some(file_ty) = p.ty.filter(|t| *t != ty) {
            tracing::warn!(
                "{}: the file says type {file_ty:?}, the vehicle {ty:?}; using the vehicle's",
                p.name
            );
        }
        rows.push(match link.param_set(&p.name, p.value, ty).await {
            Ok(v) => row(p, Some(v), ParamStatus::Applied),
            Err(LinkError::Timeout { .. }) | Err(_) => row(p, None, ParamStatus::Failed),
        });
    }
    rows
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
