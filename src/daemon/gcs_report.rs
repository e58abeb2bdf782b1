//! What the ground station is told about the tracker: a STATUSTEXT at each event (tracking
//! started, target acquired, lost, found again, the lost-target fallback, camera lost and
//! back, flight records that stopped on a full disk, the stop and hold) and, once a second, NAMED_VALUE_FLOATs with the tracker's state
//! (`IT_SEEN` 0/1, `IT_NEFF` effective sample size, `IT_H` entropy, `IT_RAD_M` the
//! estimate's one-sigma radius in metres), with the target estimate as ADS-B traffic
//! (ADSB_VEHICLE, callsign `TARGET`) that QGroundControl and Mission Planner draw on their
//! maps. Every ground station shows STATUSTEXT in its messages panel; QGroundControl plots
//! NAMED_VALUE_FLOATs in its MAVLink Inspector and Mission Planner in its Quick tab. Pure: the supervisor sends what this returns.

use std::time::Duration;

use tokio::time::Instant;

use mavlink::dialects::ardupilotmega::MavSeverity;

use super::pipeline::Status;
use crate::tracker::TrackState;

/// How often the values go out.
pub const VALUES_EVERY: Duration = Duration::from_secs(1);

/// Remembers what was last said, to speak only of changes.
#[derive(Debug)]
pub struct GcsReporter {
    fallback: String,
    last_state: Option<TrackState>,
    ever_seen: bool,
    records_failure_said: bool,
    last_values: Option<Instant>,
    effort_level: u8,
}

impl GcsReporter {
    /// A reporter for a flight whose lost-target fallback is `fallback` (`eer`, `lawn`,
    /// `hold`).
    pub fn new(fallback: &str) -> Self {
        Self {
            fallback: fallback.to_string(),
            last_state: None,
            ever_seen: false,
            records_failure_said: false,
            last_values: None,
            effort_level: 0,
        }
    }

    /// The message when tracking begins.
    pub fn started(motion: &str) -> (MavSeverity, String) {
        (
            MavSeverity::MAV_SEVERITY_NOTICE,
            format!("infotrack: tracking started ({motion})"),
        )
    }

    /// The message when the daemon stops and holds the vehicle.
    pub fn stopped(why: &str) -> (MavSeverity, String) {
        (
            MavSeverity::MAV_SEVERITY_NOTICE,
            format!("infotrack: stopped ({why}), vehicle in hold"),
        )
    }

    /// The message when the daemon stops while the pilot has the vehicle (nothing changed).
    pub fn stopped_released(why: &str) -> (MavSeverity, String) {
        (
            MavSeverity::MAV_SEVERITY_NOTICE,
            format!("infotrack: stopped ({why}); pilot has it"),
        )
    }

    /// The events since the last status, as STATUSTEXTs to send.
    pub fn events(&mut self, s: &Status) -> Vec<(MavSeverity, String)> {
        use MavSeverity::*;
        let mut out = Vec::new();
        if s.records_failed && !self.records_failure_said {
            self.records_failure_said = true;
            out.push((
                MAV_SEVERITY_CRITICAL,
                "infotrack: log write failed (disk full?)".to_string(),
            ));
        }
        if s.effort_level != self.effort_level {
            out.push(effort_said(self.effort_level, s.effort_level));
            self.effort_level = s.effort_level;
        }
        if s.seen && !self.ever_seen {
            self.ever_seen = true;
            out.push((
                MAV_SEVERITY_NOTICE,
                "infotrack: target acquired".to_string(),
            ));
        }
        let before = self.last_state.replace(s.state);
        if before == Some(s.state) {
            return out;
        }
        match (before, s.state) {
            (_, TrackState::Lost) => out.push((
                MAV_SEVERITY_WARNING,
                format!(
                    "infotrack: target lost; fallback {}",
                    self.fallback.to_uppercase()
                ),
            )),
            (Some(TrackState::Lost), TrackState::Tracking) => out.push((
                MAV_SEVERITY_NOTICE,
                "infotrack: target found again".to_string(),
            )),
            (_, TrackState::CameraLost) => out.push((
                MAV_SEVERITY_ERROR,
                "infotrack: camera lost, holding position".to_string(),
            )),
            (Some(TrackState::CameraLost), TrackState::Tracking) => out.push((
                MAV_SEVERITY_NOTICE,
                "infotrack: camera back, tracking".to_string(),
            )),
            _ => {}
        }
        out
    }

    /// The values to send now, if a second has passed since the last ones.
    pub fn values_due(&mut self, s: &Status, now: Instant) -> Option<[(&'static str, f32); 4]> {
        if self
            .last_values
            .is_some_and(|t| now.duration_since(t) < VALUES_EVERY)
        {
            return None;
        }
        self.last_values = Some(now);
        let finite = |v: f64| if v.is_finite() { v as f32 } else { -1.0 };
        Some([
            ("IT_SEEN", if s.seen { 1.0 } else { 0.0 }),
            ("IT_NEFF", finite(s.n_eff)),
            ("IT_H", finite(s.entropy)),
            ("IT_RAD_M", finite(s.radius_m)),
        ])
    }
}

/// What the GCS is told when EER's effort changes from level `before` to `now`.
fn effort_said(before: u8, now: u8) -> (MavSeverity, String) {
    if now > before {
        (
            MavSeverity::MAV_SEVERITY_WARNING,
            format!(
                "infotrack: computer too slow, planning with 1/{} of the hypotheses",
                1u32 << now
            ),
        )
    } else if now > 0 {
        (
            MavSeverity::MAV_SEVERITY_INFO,
            format!(
                "infotrack: planning with 1/{} of the hypotheses",
                1u32 << now
            ),
        )
    } else {
        (
            MavSeverity::MAV_SEVERITY_INFO,
            "infotrack: planning with every hypothesis again".to_string(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn status(seen: bool, state: TrackState) -> Status {
        Status {
            t_s: 0.0,
            seen,
            n_eff: 400.0,
            entropy: 3.5,
            state,
            radius_m: 2.0,
            records_failed: false,
            estimate_enu: [1.0, 2.0],
            effort_level: 0,
        }
    }

    #[test]
    fn a_lowered_effort_is_said_as_a_warning_and_its_return_as_information() {
        let mut r = GcsReporter::new("lawn");
        let mut s = status(false, TrackState::Tracking);
        r.events(&s);
        s.effort_level = 2;
        let said = r.events(&s);
        assert_eq!(said.len(), 1);
        assert_eq!(said[0].0, MavSeverity::MAV_SEVERITY_WARNING);
        assert!(said[0].1.contains("1/4 of the hypotheses"), "{said:?}");
        assert!(r.events(&s).is_empty(), "said once");
        s.effort_level = 0;
        let said = r.events(&s);
        assert_eq!(said[0].0, MavSeverity::MAV_SEVERITY_INFO);
        assert!(said[0].1.contains("every hypothesis again"), "{said:?}");
    }

    #[test]
    fn each_event_is_said_once_with_its_severity() {
        let mut r = GcsReporter::new("lawn");
        let texts = |v: Vec<(MavSeverity, String)>| -> Vec<String> {
            v.into_iter().map(|(_, t)| t).collect()
        };
        assert!(r.events(&status(false, TrackState::Tracking)).is_empty());
        assert_eq!(
            texts(r.events(&status(true, TrackState::Tracking))),
            ["infotrack: target acquired"]
        );
        assert!(r.events(&status(true, TrackState::Tracking)).is_empty());
        let lost = r.events(&status(false, TrackState::Lost));
        assert_eq!(lost[0].0, MavSeverity::MAV_SEVERITY_WARNING);
        assert_eq!(texts(lost), ["infotrack: target lost; fallback LAWN"]);
        assert!(r.events(&status(false, TrackState::Lost)).is_empty());
        assert_eq!(
            texts(r.events(&status(true, TrackState::Tracking))),
            ["infotrack: target found again"]
        );
        let cam = r.events(&status(false, TrackState::CameraLost));
        assert_eq!(cam[0].0, MavSeverity::MAV_SEVERITY_ERROR);
        assert_eq!(
            texts(r.events(&status(false, TrackState::Tracking))),
            ["infotrack: camera back, tracking"]
        );
        let mut full = status(false, TrackState::Tracking);
        full.records_failed = true;
        let said = r.events(&full);
        assert_eq!(said[0].0, MavSeverity::MAV_SEVERITY_CRITICAL);
        assert_eq!(texts(said), ["infotrack: log write failed (disk full?)"]);
        assert!(r.events(&full).is_empty(), "said once");
        for (_, t) in [
            GcsReporter::started("dmmn"),
            GcsReporter::stopped("signal"),
            GcsReporter::stopped_released("duration"),
        ] {
            assert!(t.len() <= 50, "{t}");
        }
    }

    #[test]
    fn values_go_out_once_a_second_and_never_as_nan() {
        let mut r = GcsReporter::new("eer");
        let t0 = Instant::now();
        let mut s = status(true, TrackState::Tracking);
        s.entropy = f64::NAN;
        let v = r.values_due(&s, t0).unwrap();
        assert_eq!(v[0], ("IT_SEEN", 1.0));
        assert_eq!(v[2], ("IT_H", -1.0));
        assert!(v.iter().all(|(n, _)| n.len() <= 10));
        assert!(r.values_due(&s, t0 + Duration::from_millis(500)).is_none());
        assert!(r.values_due(&s, t0 + Duration::from_millis(1000)).is_some());
    }
}
