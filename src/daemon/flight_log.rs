//! The daemon's per-step flight log (`flight.csv`): everything the pipeline consumed
//! (vehicle pose, whether a frame was taken, the measurement) at full precision, and what it
//! decided, so that `infotrack replay` can re-run estimation and guidance on it exactly.
//!
//! A first comment line carries the seed and the motion model: `# infotrack flight log
//! seed=7 motion=dmmn`.

use std::fmt::Write as _;

use thiserror::Error;

use crate::frames::PositionNed;
use crate::metrics::StepRecord;
use crate::tracker::{Command, TrackState};
use crate::vision::camera_model::VehiclePoseNed;
use crate::world::geometry::Enu2;

/// One filter step of the daemon, beyond what the simulator records.
#[derive(Debug, Clone)]
pub struct FlightRecord {
    /// The simulator-compatible record (truth, vehicle position, measurement, estimate...).
    pub step: StepRecord,
    /// Vehicle pose at the frame.
    pub pose: VehiclePoseNed,
    /// Tracking state.
    pub state: TrackState,
    /// Whether a camera frame was taken at this step.
    pub frame: bool,
    /// The command in force after this step.
    pub command: Option<Command>,
    /// Entropy of the estimate at the latest EER decision (NaN before the first).
    pub entropy: f64,
    /// The flight mode the vehicle reported at this step.
    pub vehicle_mode: Option<crate::autopilot::modes::Mode>,
    /// Faults injected at this step (`camera-freeze`, `link-cut`, `loss=30`), `+`-joined;
    /// empty: none.
    pub faults: String,
}

/// The header row. Vehicle pose in MAVLink local NED (m, rad); measurement, estimate and
/// command in world ENU (m); covariance in m^2; `entropy` at the latest EER decision;
/// `vehicle_mode` as the autopilot reported it; `faults` the injected ones in force,
/// `+`-joined (empty: none).
pub const HEADER: &str = "t_s,vehicle_n_m,vehicle_e_m,vehicle_d_m,roll_rad,pitch_rad,yaw_rad,frame,measured,meas_x_m,meas_y_m,est_x_m,est_y_m,cov_xx,cov_xy,cov_yy,n_eff,eer,state,command,cmd_x_m,cmd_y_m,entropy,vehicle_mode,faults";

/// The header of the first version (no entropy, mode or faults), still read.
pub const HEADER_V1: &str = "t_s,vehicle_n_m,vehicle_e_m,vehicle_d_m,roll_rad,pitch_rad,yaw_rad,frame,measured,meas_x_m,meas_y_m,est_x_m,est_y_m,cov_xx,cov_xy,cov_yy,n_eff,eer,state,command,cmd_x_m,cmd_y_m";

/// A flight log that cannot be read.
#[derive(Debug, Error)]
#[error("{path}, line {line}: {message}")]
pub struct FlightLogError {
    /// The file.
    pub path: String,
    /// 1-based line.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// One logged filter step, as replay needs it.
#[derive(Debug, Clone, PartialEq)]
pub struct LoggedStep {
    /// Time since tracking started, s.
    pub t_s: f64,
    /// Vehicle position, world ENU, m.
    pub vehicle_enu: Enu2,
    /// Vehicle heading, local NED yaw (rad): the camera's view faces it turned by the mount.
    pub vehicle_yaw_ned_rad: f64,
    /// Whether a camera frame was taken (false: the camera gave nothing).
    pub frame: bool,
    /// The measurement, world ENU, m.
    pub measurement_enu: Option<Enu2>,
    /// The estimate the flight had after this step, world ENU, m.
    pub estimate_enu: Enu2,
    /// The waypoint in force after this step, world ENU, m (None: none or hold).
    pub command_enu: Option<Enu2>,
}

/// Writes the log. Inputs are written with Rust's shortest round-trip formatting, so that
/// replay reads back exactly the numbers the filter saw.
pub fn render(records: &[FlightRecord], seed: u64, motion: &str) -> String {
    let mut s = preamble(seed, motion);
    for r in records {
        s.push_str(&render_row(r));
    }
    s
}

/// The first two lines: the seed and motion model, and the header.
pub fn preamble(seed: u64, motion: &str) -> String {
    format!("# infotrack flight log seed={seed} motion={motion}\n{HEADER}\n")
}

/// One record as a row, newline included.
pub fn render_row(r: &FlightRecord) -> String {
    let mut s = String::with_capacity(256);
    {
        let (mx, my) = r
            .step
            .measurement_enu
            .map_or((f64::NAN, f64::NAN), |z| (z.x, z.y));
        let (cmd, cx, cy) = match r.command {
            // The setpoint at the decision (its velocity is in the tlog's targets).
            Some(Command::GoTo {
                position_enu: w, ..
            }) => ("goto", w.x, w.y),
            Some(Command::HoldHere) => ("hold", f64::NAN, f64::NAN),
            None => ("none", f64::NAN, f64::NAN),
        };
        let p = &r.pose;
        let c = &r.step.cov_m2;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.step.t_s,
            p.position_ned_m[0],
            p.position_ned_m[1],
            p.position_ned_m[2],
            p.roll_rad,
            p.pitch_rad,
            p.yaw_rad,
            r.frame as u8,
            r.step.measurement_enu.is_some() as u8,
            mx,
            my,
            r.step.estimate_enu.x,
            r.step.estimate_enu.y,
            c[(0, 0)],
            c[(0, 1)],
            c[(1, 1)],
            r.step.n_eff,
            r.step.eer,
            r.state.as_str(),
            cmd,
            cx,
            cy,
            r.entropy,
            r.vehicle_mode
                .map_or_else(|| "unknown".to_string(), |m| format!("{m:?}")),
            r.faults
        );
    }
    s
}

/// Reads a log: the seed and motion model from its first line, and the steps.
pub fn parse(text: &str, path: &str) -> Result<(u64, String, Vec<LoggedStep>), FlightLogError> {
    let err = |line: usize, message: String| FlightLogError {
        path: path.to_string(),
        line,
        message,
    };
    let mut lines = text.lines().enumerate();
    let (_, first) = lines.next().ok_or_else(|| err(1, "empty file".into()))?;
    let meta = first
        .strip_prefix("# infotrack flight log ")
        .ok_or_else(|| {
            err(
                1,
                "not an infotrack flight log (no `# infotrack flight log` line)".into(),
            )
        })?;
    let mut seed = None;
    let mut motion = None;
    for kv in meta.split_whitespace() {
        match kv.split_once('=') {
            Some(("seed", v)) => seed = v.parse().ok(),
            Some(("motion", v)) => motion = Some(v.to_string()),
            _ => {}
        }
    }
    let seed = seed.ok_or_else(|| err(1, "no seed=N".into()))?;
    let motion = motion.ok_or_else(|| err(1, "no motion=NAME".into()))?;
    let fields = match lines.next() {
        Some((_, h)) if h == HEADER => 25,
        Some((_, h)) if h == HEADER_V1 => 22,
        _ => return Err(err(2, format!("expected the header `{HEADER}`"))),
    };
    let mut steps = Vec::new();
    // A flight stopped mid-write (SIGKILL, power) leaves a last line without its newline:
    // what is before it is read, it is dropped with a warning.
    let cut_last = !text.is_empty() && !text.ends_with('\n');
    let body: Vec<(usize, &str)> = lines.collect();
    let last = body.len();
    for (k, (i, line)) in body.into_iter().enumerate() {
        let n = i + 1;
        match parse_row(line, n, fields, &err) {
            Ok(step) => steps.push(step),
            Err(e) if cut_last && k + 1 == last => {
                tracing::warn!("{path}: the last line ({n}) is cut short and is left out: {e}");
            }
            Err(e) => return Err(e),
        }
    }
    if steps.is_empty() {
        return Err(err(
            3,
            "no filter steps after the header: nothing to replay (the flight never tracked?)"
                .into(),
        ));
    }
    Ok((seed, motion, steps))
}

/// One data row (line `n`).
fn parse_row(
    line: &str,
    n: usize,
    fields: usize,
    err: &dyn Fn(usize, String) -> FlightLogError,
) -> Result<LoggedStep, FlightLogError> {
    {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != fields {
            return Err(err(n, format!("{} fields, expected {fields}", f.len())));
        }
        let any_num = |k: usize| -> Result<f64, FlightLogError> {
            f[k].parse::<f64>()
                .map_err(|_| err(n, format!("field {} `{}` is not a number", k + 1, f[k])))
        };
        // Only the measurement may be NaN (a step without one); a NaN time, pose, estimate
        // or command would replay as a comparison of nothing.
        let num = |k: usize| -> Result<f64, FlightLogError> {
            let v = any_num(k)?;
            if !v.is_finite() {
                return Err(err(n, format!("field {} `{}` is not finite", k + 1, f[k])));
            }
            Ok(v)
        };
        let flag = |k: usize| -> Result<bool, FlightLogError> {
            match f[k] {
                "0" => Ok(false),
                "1" => Ok(true),
                v => Err(err(n, format!("field {} `{v}` must be 0 or 1", k + 1))),
            }
        };
        let measured = flag(8)?;
        let z = Enu2::new(any_num(9)?, any_num(10)?);
        if measured && !(z.x.is_finite() && z.y.is_finite()) {
            return Err(err(n, "measured, but the measurement is not finite".into()));
        }
        let cmd = match f[19] {
            "goto" => Some(Enu2::new(num(20)?, num(21)?)),
            "hold" | "none" => None,
            v => return Err(err(n, format!("command `{v}` is not goto, hold or none"))),
        };
        Ok(LoggedStep {
            t_s: num(0)?,
            vehicle_enu: PositionNed {
                x_north_m: num(1)?,
                y_east_m: num(2)?,
                z_down_m: 0.0,
            }
            .to_enu()
            .xy(),
            vehicle_yaw_ned_rad: num(6)?,
            frame: flag(7)?,
            measurement_enu: measured.then_some(z),
            estimate_enu: Enu2::new(num(11)?, num(12)?),
            command_enu: cmd,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A log cut mid-line (the process killed while writing) reads up to its last
    /// complete row; the same damage inside the file is an error naming the line.
    #[test]
    fn a_cut_last_line_is_left_out_but_a_bad_middle_line_is_an_error() {
        let head = format!("# infotrack flight log seed=3 motion=cv\n{HEADER}\n");
        let row = "0.33,1,2,-1.2,0,0,0,1,1,0.5,0.6,0.5,0.6,0.01,0,0.01,400,0.1,tracking,goto,0.5,0.7,3.2,Offboard,";
        let cut = &row[..40];
        let (_, _, steps) = parse(&format!("{head}{row}\n{row}\n{cut}"), "f").unwrap();
        assert_eq!(steps.len(), 2);
        let e = parse(&format!("{head}{row}\n{cut}\n{row}\n"), "f")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 4"), "{e}");
    }

    #[test]
    fn bad_logs_name_the_line() {
        let ok_head = format!("# infotrack flight log seed=3 motion=cv\n{HEADER}\n");
        // A header without a step is nothing to replay, not a comparison over 0 steps.
        let e = parse(&ok_head, "f").unwrap_err().to_string();
        assert!(
            e.contains("f, line 3") && e.contains("no filter steps"),
            "{e}"
        );
        let e = parse("t_s,x\n", "f.csv").unwrap_err().to_string();
        assert!(
            e.contains("f.csv, line 1") && e.contains("not an infotrack flight log"),
            "{e}"
        );
        let row = "0.33,1,2,-1.2,0,0,0,1,1,0.5,0.6,0.5,0.6,0.01,0,0.01,400,0.1,tracking,goto,0.5,0.7,3.2,Offboard,camera-freeze+loss=30";
        let (_, _, steps) = parse(&format!("{ok_head}{row}\n"), "f").unwrap();
        // A log of the first version (22 fields) still reads.
        let v1_row = row.splitn(23, ',').take(22).collect::<Vec<_>>().join(",");
        let v1 = format!("# infotrack flight log seed=3 motion=cv\n{HEADER_V1}\n{v1_row}\n");
        assert_eq!(parse(&v1, "f").unwrap().2, steps);
        assert_eq!(steps[0].vehicle_enu, Enu2::new(2.0, 1.0), "NED -> ENU");
        assert_eq!(steps[0].measurement_enu, Some(Enu2::new(0.5, 0.6)));
        assert_eq!(steps[0].command_enu, Some(Enu2::new(0.5, 0.7)));
        let bad = row.replace(",1,1,0.5", ",2,1,0.5");
        let e = parse(&format!("{ok_head}{bad}\n"), "f")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3") && e.contains("0 or 1"), "{e}");
        let e = parse(&format!("{ok_head}1,2\n"), "f")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3") && e.contains("2 fields"), "{e}");
    }
}
