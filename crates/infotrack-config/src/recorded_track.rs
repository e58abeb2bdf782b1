//! A target that drives a recorded track instead of our own Markov car: a car that goes
//! where it goes, at its own speeds, stopping where it stopped. Read from CSV
//! (`t_s,lon_deg,lat_deg` or `t_s,x_m,y_m` in world ENU, with a header row), GPX 1.1 tracks
//! with times, or SUMO's FCD output written with `--fcd-output.geo`; interpolated in time.
//! A track that leaves the workspace, goes backwards in time or moves faster than any car
//! is refused, naming the file and the row.

use std::path::{Path, PathBuf};

use thiserror::Error;

use infotrack_core::frames::Enu2;
use infotrack_core::geodesy::GeodeticWgs84;
use infotrack_core::world::geometry::BoundsEnu;

/// Faster than this between two samples is no car: a glitch or the wrong file, m/s.
pub const MAX_CAR_SPEED_MPS: f64 = 70.0;
/// A track file larger than this is refused, bytes.
pub const MAX_TRACK_BYTES: u64 = 256 << 20;

/// A track, its times from its first sample, positions world ENU.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedTrack {
    /// The file it came from (for messages).
    pub file: PathBuf,
    /// (t_s from the first sample, position world ENU, m), time strictly increasing.
    pub samples: Vec<(f64, Enu2)>,
}

/// Why a track file was refused.
#[derive(Debug, Error)]
pub enum TrackError {
    /// Unreadable.
    #[error("target.trajectory {file}: {message}")]
    File {
        /// The file.
        file: PathBuf,
        /// Why.
        message: String,
    },
    /// A row (a CSV line, a GPX point, an FCD time step) that cannot be.
    #[error("target.trajectory {file}, {row}: {message}")]
    Row {
        /// The file.
        file: PathBuf,
        /// Where in it: `line 7`, `point 12`.
        row: String,
        /// What is wrong.
        message: String,
    },
}

/// Where the tracks are placed and what they must respect.
#[derive(Debug, Clone, Copy)]
pub struct TrackFrame<'a> {
    /// The world's origin on Earth (`[world] origin`): needed for longitude/latitude tracks.
    pub origin: Option<&'a GeodeticWgs84>,
    /// The workspace the track must stay in.
    pub workspace: &'a BoundsEnu,
    /// In an FCD file with several vehicles, which one.
    pub vehicle: Option<&'a str>,
}

/// One raw sample before checks: time (any epoch) and where, with its row's name.
struct Raw {
    row: String,
    t_s: f64,
    at: Position,
}

enum Position {
    Enu(Enu2),
    LonLat(f64, f64),
}

/// Reads and checks the track in `file`; the format follows from the extension (`.csv`,
/// `.gpx`, `.xml` for SUMO FCD).
pub fn load(file: &Path, frame: &TrackFrame) -> Result<RecordedTrack, TrackError> {
    let fail = |message: String| TrackError::File {
        file: file.to_path_buf(),
        message,
    };
    let text =
        infotrack_files::read_text(file, MAX_TRACK_BYTES).map_err(|e| fail(e.to_string()))?;
    let ext = file
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let raw = match ext.as_deref() {
        Some("csv") => csv_rows(&text),
        Some("gpx") => gpx_points(&text),
        Some("xml") => fcd_steps(&text, frame.vehicle),
        _ => Err((
            String::new(),
            "unknown track type (expected .csv, .gpx or SUMO FCD .xml)".into(),
        )),
    };
    let raw = raw.map_err(|(row, message)| match row.is_empty() {
        true => fail(message),
        false => TrackError::Row {
            file: file.to_path_buf(),
            row,
            message,
        },
    })?;
    checked(file, raw, frame)
}

/// The samples in world ENU, checked: at least two, time forward, in the workspace, at car
/// speeds.
fn checked(file: &Path, raw: Vec<Raw>, frame: &TrackFrame) -> Result<RecordedTrack, TrackError> {
    let row_err = |row: &str, message: String| TrackError::Row {
        file: file.to_path_buf(),
        row: row.to_string(),
        message,
    };
    if raw.len() < 2 {
        return Err(TrackError::File {
            file: file.to_path_buf(),
            message: format!("{} sample(s): a track needs at least two", raw.len()),
        });
    }
    let t0 = raw[0].t_s;
    let mut samples: Vec<(f64, Enu2)> = Vec::with_capacity(raw.len());
    for r in &raw {
        let p = match r.at {
            Position::Enu(p) => p,
            Position::LonLat(lon, lat) => {
                enu_of(lon, lat, frame.origin).map_err(|e| row_err(&r.row, e.to_string()))?
            }
        };
        let t = r.t_s - t0;
        if !(t.is_finite() && p.x.is_finite() && p.y.is_finite()) {
            return Err(row_err(&r.row, "not finite".into()));
        }
        if !frame.workspace.contains(&p) {
            return Err(row_err(
                &r.row,
                format!(
                    "({:.1}, {:.1}) m world ENU is outside the workspace",
                    p.x, p.y
                ),
            ));
        }
        if let Some(&(t_prev, p_prev)) = samples.last() {
            if t <= t_prev {
                return Err(row_err(
                    &r.row,
                    format!("time {t:.3} s does not follow {t_prev:.3} s"),
                ));
            }
            let speed = (p - p_prev).norm() / (t - t_prev);
            if speed > MAX_CAR_SPEED_MPS {
                return Err(row_err(
                    &r.row,
                    format!("{speed:.1} m/s since the sample before: faster than any car ({MAX_CAR_SPEED_MPS} m/s)"),
                ));
            }
        }
        samples.push((t, p));
    }
    Ok(RecordedTrack {
        file: file.to_path_buf(),
        samples,
    })
}

/// Why a row's longitude and latitude cannot be placed in the world.
#[derive(Debug, Clone, PartialEq, Error)]
enum PlaceError {
    /// The world has no origin on Earth.
    #[error("a longitude/latitude track needs the world placed on Earth ([world] origin)")]
    NoOrigin,
    /// Not degrees.
    #[error("[{0}, {1}] is not a longitude and latitude in degrees")]
    NotDegrees(f64, f64),
}

fn enu_of(lon: f64, lat: f64, origin: Option<&GeodeticWgs84>) -> Result<Enu2, PlaceError> {
    let origin = origin.ok_or(PlaceError::NoOrigin)?;
    if !(lat.abs() <= 90.0 && lon.abs() <= 180.0) {
        return Err(PlaceError::NotDegrees(lon, lat));
    }
    let [e, n, _] = origin.enu_of(&GeodeticWgs84 {
        lat_deg: lat,
        lon_deg: lon,
        alt_m: origin.alt_m,
    });
    Ok(Enu2::new(e, n))
}

type Rows = Result<Vec<Raw>, (String, String)>;

/// CSV with a header `t_s,lon_deg,lat_deg` or `t_s,x_m,y_m`.
fn csv_rows(text: &str) -> Rows {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines
        .next()
        .ok_or((String::new(), "empty file".to_string()))?;
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let geo = match columns.as_slice() {
        ["t_s", "lon_deg", "lat_deg"] => true,
        ["t_s", "x_m", "y_m"] => false,
        _ => {
            return Err((
                "line 1".into(),
                format!("header `{header}`: expected `t_s,lon_deg,lat_deg` or `t_s,x_m,y_m`"),
            ))
        }
    };
    lines
        .map(|(i, line)| {
            let row = format!("line {}", i + 1);
            let f: Vec<f64> = line
                .split(',')
                .map(|v| v.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| (row.clone(), format!("`{line}` is not three numbers")))?;
            let [t_s, a, b] = f[..] else {
                return Err((row, format!("{} fields, expected 3", f.len())));
            };
            let at = if geo {
                Position::LonLat(a, b)
            } else {
                Position::Enu(Enu2::new(a, b))
            };
            Ok(Raw { row, t_s, at })
        })
        .collect()
}

/// Seconds since the Unix epoch of an RFC 3339 time.
fn epoch_s(text: &str) -> Option<f64> {
    let t = humantime::parse_rfc3339_weak(text.trim_end_matches('Z').trim_end_matches("+00:00"))
        .ok()?;
    t.duration_since(std::time::UNIX_EPOCH)
        .ok()
        .map(|d| d.as_secs_f64())
}

/// GPX 1.1: every track point of every track and segment, in order, with its time.
fn gpx_points(text: &str) -> Rows {
    let gpx = gpx::read(text.as_bytes()).map_err(|e| (String::new(), format!("not GPX: {e}")))?;
    let points = gpx
        .tracks
        .iter()
        .flat_map(|t| &t.segments)
        .flat_map(|s| &s.points);
    points
        .enumerate()
        .map(|(i, p)| {
            let row = format!("track point {}", i + 1);
            let time = p
                .time
                .as_ref()
                .ok_or((row.clone(), "no <time>".to_string()))?;
            let t_s = time
                .format()
                .ok()
                .and_then(|s| epoch_s(&s))
                .ok_or((row.clone(), "a time that is not UTC RFC 3339".to_string()))?;
            let xy = p.point();
            Ok(Raw {
                row,
                t_s,
                at: Position::LonLat(xy.x(), xy.y()),
            })
        })
        .collect()
}

/// SUMO FCD output written with `--fcd-output.geo`: `<timestep time=..><vehicle id x=lon
/// y=lat/>`; the one vehicle, or `vehicle`.
fn fcd_steps(text: &str, vehicle: Option<&str>) -> Rows {
    let doc =
        roxmltree::Document::parse(text).map_err(|e| (String::new(), format!("not XML: {e}")))?;
    let line = |n: roxmltree::Node| format!("line {}", doc.text_pos_at(n.range().start).row);
    let ids: std::collections::BTreeSet<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("vehicle"))
        .filter_map(|n| n.attribute("id"))
        .collect();
    let wanted = match (vehicle, ids.len()) {
        (Some(v), _) if ids.contains(v) => v,
        (Some(v), _) => {
            return Err((
                String::new(),
                format!("no vehicle `{v}` (target.trajectory_vehicle); it has {ids:?}"),
            ))
        }
        (None, 1) => ids.iter().next().copied().unwrap_or_default(),
        (None, n) => {
            return Err((
                String::new(),
                format!("{n} vehicles ({ids:?}): say which in target.trajectory_vehicle"),
            ))
        }
    };
    let mut out = Vec::new();
    for step in doc.descendants().filter(|n| n.has_tag_name("timestep")) {
        let Some(v) = step
            .children()
            .find(|c| c.has_tag_name("vehicle") && c.attribute("id") == Some(wanted))
        else {
            continue;
        };
        let num = |n: roxmltree::Node, k: &str| {
            n.attribute(k)
                .and_then(|s| s.parse::<f64>().ok())
                .ok_or((line(n), format!("no number `{k}`")))
        };
        let at = Position::LonLat(num(v, "x")?, num(v, "y")?);
        out.push(Raw {
            row: line(v),
            t_s: num(step, "time")?,
            at,
        });
    }
    Ok(out)
}

impl RecordedTrack {
    /// How long the track lasts, s.
    pub fn duration_s(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.0)
    }

    /// Position and velocity at `t_s` (linear between samples; held at the ends).
    pub fn at(&self, t_s: f64) -> (Enu2, Enu2) {
        let k = self.samples.partition_point(|s| s.0 <= t_s);
        if k == 0 {
            return (self.samples[0].1, Enu2::zeros());
        }
        if k >= self.samples.len() {
            return (self.samples[self.samples.len() - 1].1, Enu2::zeros());
        }
        let ((t0, p0), (t1, p1)) = (self.samples[k - 1], self.samples[k]);
        let v = (p1 - p0) / (t1 - t0);
        (p0 + v * (t_s - t0), v)
    }
}

#[cfg(test)]
mod tests;
