//! The figures of a flight's end table beyond the tracking metrics (frames, latency, the
//! vehicle's story, resources), computed once for the terminal and `summary.json` alike.

use serde_json::{json, Value};

use infotrack::autopilot::modes::Mode;
use infotrack::daemon::DaemonReport;

/// The `p` quantile (0..1) of `v` by the nearest rank; NaN for no values.
pub fn percentile(v: &[f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    s[((s.len() - 1) as f64 * p).round() as usize]
}

/// What the flight cost this machine.
#[derive(Debug, Clone, Copy)]
pub struct Resources {
    /// CPU time of the whole process over the flight, s.
    pub cpu_s: f64,
    /// Wall time of the flight, s.
    pub wall_s: f64,
    /// Simulated or real time flown, s (the last filter step's).
    pub flown_s: f64,
    /// Peak resident memory, MB.
    pub peak_rss_mb: f64,
}

impl Resources {
    /// The share of one core used, percent.
    pub fn cpu_percent(&self) -> f64 {
        100.0 * self.cpu_s / self.wall_s
    }

    /// Flight time per wall time.
    pub fn real_time_factor(&self) -> f64 {
        self.flown_s / self.wall_s
    }

    /// The terminal's resources line; a figure the system would not give is "unknown".
    pub fn line(&self) -> String {
        let memory = if self.peak_rss_mb.is_finite() {
            format!("{:.0} MB", self.peak_rss_mb)
        } else {
            "unknown".to_string()
        };
        format!(
            "resources: {:.0}% of one core over {:.1} s of wall time for {:.1} s of flight ({:.1}x real time), peak resident memory {memory}",
            self.cpu_percent(),
            self.wall_s,
            self.flown_s,
            self.real_time_factor(),
        )
    }
}

/// The p50 and p99 of `v`, ms.
fn quantiles(v: &[f64]) -> Value {
    json!({"p50": finite(percentile(v, 0.5)), "p99": finite(percentile(v, 0.99))})
}

/// JSON has no NaN: a figure that could not be measured is `null`.
fn finite(x: f64) -> Value {
    if x.is_finite() {
        x.into()
    } else {
        Value::Null
    }
}

fn mode_changes(v: &[(Mode, Mode)]) -> Value {
    v.iter()
        .map(|(a, b)| json!({"from": a.to_string(), "to": b.to_string()}))
        .collect()
}

/// Each filter step's estimate spread, m: the standard deviation along the covariance's
/// widest axis (the square root of its largest eigenvalue). What a flight without ground
/// truth can say of how well it knows where the target is.
pub fn estimate_spread_m(records: &[infotrack::daemon::flight_log::FlightRecord]) -> Vec<f64> {
    records
        .iter()
        .map(|r| r.step.cov_m2.symmetric_eigenvalues().max().max(0.0).sqrt())
        .filter(|v| v.is_finite())
        .collect()
}

/// Every figure of the end table that the tracking metrics do not hold.
pub fn figures(r: &DaemonReport, res: &Resources) -> Value {
    let o = &r.output;
    json!({
        "vehicle": r.vehicle,
        "flavour": r.flavor.to_string(),
        "stopped_by": format!("{:?}", r.stopped_by),
        "filter_steps": o.records.len(),
        "frames": o.vision.frames,
        "frames_with_tag": o.vision.detections,
        "filter_periods_without_frame": o.frames_missed,
        "guidance_overruns": o.guidance_overruns,
        "lowest_effort_level": o.lowest_effort_level,
        "estimate_spread_m": quantiles(&estimate_spread_m(&o.records)),
        "frame_to_setpoint_ms": quantiles(&o.latency_ms),
        "detection_ms": quantiles(&o.detect_ms),
        "filter_ms": quantiles(&o.update_ms),
        "guidance_ms": quantiles(&o.guidance_ms),
        "final_mode": r.final_mode.map(|m| m.to_string()),
        "mode_changes_not_commanded": mode_changes(&r.unexpected_mode_changes),
        "mode_changes_before_arming": mode_changes(&r.mode_changes_before_arming),
        "link_losses": r.link_losses,
        "geofence_refusals": r.geofence_refusals,
        "setpoints_sent": r.setpoints_sent,
        "setpoint_rate_hz": r.setpoint_rate_hz.map_or(Value::Null, finite),
        "resources": {
            "cpu_percent_of_one_core": finite(res.cpu_percent()),
            "wall_s": res.wall_s,
            "flown_s": res.flown_s,
            "real_time_factor": finite(res.real_time_factor()),
            "peak_resident_memory_mb": finite(res.peak_rss_mb),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::Resources;

    fn resources(peak_rss_mb: f64) -> Resources {
        Resources {
            cpu_s: 5.0,
            wall_s: 10.0,
            flown_s: 20.0,
            peak_rss_mb,
        }
    }

    #[test]
    fn the_resources_line_gives_the_share_of_a_core_and_memory() {
        let line = resources(123.4).line();
        assert!(line.contains("50% of one core"), "{line}");
        assert!(line.contains("(2.0x real time)"), "{line}");
        assert!(line.ends_with("peak resident memory 123 MB"), "{line}");
    }

    #[test]
    fn memory_the_system_would_not_give_is_unknown_not_nan() {
        let line = resources(f64::NAN).line();
        assert!(line.ends_with("peak resident memory unknown"), "{line}");
        assert!(!line.contains("NaN"), "{line}");
    }
}
