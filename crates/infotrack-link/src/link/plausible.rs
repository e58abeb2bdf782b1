//! Which telemetry the vehicle can have flown: positions, altitudes, velocities and
//! attitudes beyond the vehicle's speed envelope since the last accepted sample, or outside
//! any world it can be in, are dropped before they reach the vehicle state (and so the
//! tracker, the records, the geofence and the hold).
//!
//! Why: a baro or GPS glitch, or a frame spoofed with the vehicle's ids, is finite and looks
//! like telemetry; one GLOBAL_POSITION_INT at -10 km read at the stop would send the hold's
//! altitude to the ground. A real estimator reset that moves the vehicle's position and
//! stays there is taken after [`REANCHOR_AFTER_S`] of samples that agree with each other and
//! none that agrees with the old track, so a genuine jump is not dropped for ever.

use tokio::time::Instant;

/// Samples that agree with each other and not with the accepted track for this long (and
/// [`REANCHOR_SAMPLES`] of them) become the track: an estimator reset, not a glitch, s.
pub const REANCHOR_AFTER_S: f64 = 2.0;
/// See [`REANCHOR_AFTER_S`].
pub const REANCHOR_SAMPLES: u32 = 10;

/// What the vehicle can do, with margin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// Fastest plausible speed, horizontal or vertical, m/s.
    pub max_speed_mps: f64,
    /// Position change always allowed between two samples (noise, latency), m.
    pub slack_m: f64,
    /// Farthest plausible horizontal distance from the vehicle's local origin, m.
    pub max_range_m: f64,
    /// Highest plausible height above the local origin, m (and as far below it).
    pub max_height_m: f64,
}

impl Default for Envelope {
    /// A multirotor: 40 m/s, 3 m of slack, 20 km from its origin, 3 km above or below it.
    fn default() -> Self {
        Self {
            max_speed_mps: 40.0,
            slack_m: 3.0,
            max_range_m: 20_000.0,
            max_height_m: 3_000.0,
        }
    }
}

impl Envelope {
    /// Twice the planned speed plus 5 m/s (a pilot may fly faster than infotrack plans),
    /// and 1 km beyond the geofence's farthest corner (where a pilot may launch it).
    pub fn for_vehicle(planned_speed_mps: f64, fence_reach_m: f64) -> Self {
        Self {
            max_speed_mps: 2.0 * planned_speed_mps.max(0.0) + 5.0,
            max_range_m: fence_reach_m.max(0.0) + 1_000.0,
            ..Self::default()
        }
    }

    /// How far the vehicle can move in `dt_s`, m.
    fn reach_m(&self, dt_s: f64) -> f64 {
        // Half a second of latency allowance: frames delivered in a burst after a stall.
        self.slack_m + self.max_speed_mps * (dt_s.max(0.0) + 0.5)
    }
}

/// A position sample in some frame's metres: (north or east, ...), (up).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    at: Instant,
    horizontal_m: [f64; 2],
    up_m: f64,
}

/// The accepted track of one position stream and the candidate that may replace it.
#[derive(Debug, Clone, Default)]
pub struct Track {
    accepted: Option<Sample>,
    candidate: Option<(Sample, Instant, u32)>,
}

/// Why a sample was dropped.
#[derive(Debug, Clone, PartialEq)]
pub struct Implausible(pub String);

impl Track {
    /// Accepts `horizontal_m` / `up_m` at `at` if the vehicle can be there; a sample out of
    /// the envelope only replaces the track once the old track has been silent and the
    /// new one consistent for [`REANCHOR_AFTER_S`].
    pub fn check(
        &mut self,
        env: &Envelope,
        at: Instant,
        horizontal_m: [f64; 2],
        up_m: f64,
    ) -> Result<(), Implausible> {
        let s = Sample {
            at,
            horizontal_m,
            up_m,
        };
        let Some(last) = self.accepted else {
            self.accepted = Some(s);
            return Ok(());
        };
        if follows(env, &last, &s) {
            self.accepted = Some(s);
            self.candidate = None;
            return Ok(());
        }
        let moved_m = distance_m(&last, &s);
        let (first_at, count) = match self.candidate {
            Some((c, first_at, n)) if follows(env, &c, &s) => (first_at, n + 1),
            _ => (at, 1),
        };
        self.candidate = Some((s, first_at, count));
        if count >= REANCHOR_SAMPLES && (at - first_at).as_secs_f64() >= REANCHOR_AFTER_S {
            tracing::warn!(
                "the vehicle's position jumped {moved_m:.1} m and stayed there for {:.1} s \
                 (an estimator reset?): taken as its position from now on",
                (at - first_at).as_secs_f64()
            );
            self.accepted = Some(s);
            self.candidate = None;
            return Ok(());
        }
        Err(Implausible(format!(
            "{moved_m:.1} m from the last accepted position {:.2} s before (at most {:.1} m)",
            (at - last.at).as_secs_f64(),
            env.reach_m((at - last.at).as_secs_f64())
        )))
    }
}

fn distance_m(a: &Sample, b: &Sample) -> f64 {
    (a.horizontal_m[0] - b.horizontal_m[0])
        .hypot(a.horizontal_m[1] - b.horizontal_m[1])
        .hypot(a.up_m - b.up_m)
}

/// Whether `next` can follow `last` within the envelope.
fn follows(env: &Envelope, last: &Sample, next: &Sample) -> bool {
    let dt_s = next.at.saturating_duration_since(last.at).as_secs_f64();
    distance_m(last, next) <= env.reach_m(dt_s)
}

/// A local position (NED, m) and velocity (m/s) inside the envelope's world.
pub fn local_in_world(
    env: &Envelope,
    ned_m: [f64; 3],
    vel_mps: [f64; 3],
) -> Result<(), Implausible> {
    if ned_m[0].hypot(ned_m[1]) > env.max_range_m || ned_m[2].abs() > env.max_height_m {
        return Err(Implausible(format!(
            "position ({:.0}, {:.0}, {:.0}) m NED is outside any world the vehicle can be in",
            ned_m[0], ned_m[1], ned_m[2]
        )));
    }
    speed_in_envelope(env, vel_mps)
}

/// A velocity (m/s) the vehicle can fly.
pub fn speed_in_envelope(env: &Envelope, vel_mps: [f64; 3]) -> Result<(), Implausible> {
    let speed = vel_mps.iter().map(|v| v * v).sum::<f64>().sqrt();
    if speed > env.max_speed_mps {
        return Err(Implausible(format!(
            "a speed of {speed:.1} m/s (at most {:.1})",
            env.max_speed_mps
        )));
    }
    Ok(())
}

/// An attitude (rad) and its rates (rad/s) a vehicle can report: angles within a turn
/// either way, rates under 50 rad/s.
pub fn attitude(angles_rad: [f64; 3], rates_radps: [f64; 3]) -> Result<(), Implausible> {
    const MAX_RATE_RADPS: f64 = 50.0;
    let turn = 2.0 * std::f64::consts::PI;
    if angles_rad.iter().any(|a| a.abs() > turn)
        || rates_radps.iter().any(|r| r.abs() > MAX_RATE_RADPS)
    {
        return Err(Implausible(format!(
            "an attitude of {angles_rad:?} rad at {rates_radps:?} rad/s"
        )));
    }
    Ok(())
}

/// A WGS84 position (deg) and a height above home (m) on Earth and in the envelope.
pub fn global_on_earth(
    env: &Envelope,
    lat_deg: f64,
    lon_deg: f64,
    relative_m: f64,
) -> Result<(), Implausible> {
    if !(lat_deg.abs() <= 90.0 && lon_deg.abs() <= 180.0) || relative_m.abs() > env.max_height_m {
        return Err(Implausible(format!(
            "a global position of ({lat_deg:.7}, {lon_deg:.7}) at {relative_m:.0} m above home"
        )));
    }
    Ok(())
}

/// A height above mean sea level on Earth: between the Dead Sea's shore and 9 km, m.
pub fn amsl_on_earth(amsl_m: f64) -> Result<(), Implausible> {
    if !(-500.0..=9_000.0).contains(&amsl_m) {
        return Err(Implausible(format!("an altitude of {amsl_m:.0} m AMSL")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn at(t0: Instant, s: f64) -> Instant {
        t0 + Duration::from_secs_f64(s)
    }

    #[tokio::test(start_paused = true)]
    async fn a_ten_km_jump_is_dropped_and_the_track_goes_on() {
        let env = Envelope::for_vehicle(1.0, 10.0);
        let t0 = Instant::now();
        let mut t = Track::default();
        assert!(t.check(&env, t0, [0.0, 0.0], 1.0).is_ok());
        assert!(t.check(&env, at(t0, 0.1), [10_000.0, 0.0], 1.0).is_err());
        assert!(t.check(&env, at(t0, 0.2), [0.1, 0.0], 1.0).is_ok());
        assert!(t.check(&env, at(t0, 0.3), [0.0, 0.0], -10_000.0).is_err());
    }

    #[tokio::test(start_paused = true)]
    async fn a_jump_that_stays_is_taken_after_the_reanchor_time() {
        let env = Envelope::for_vehicle(1.0, 10.0);
        let t0 = Instant::now();
        let mut t = Track::default();
        t.check(&env, t0, [0.0, 0.0], 1.0).unwrap();
        let mut taken_at = None;
        for i in 1..=40 {
            let s = 0.1 * i as f64;
            if t.check(&env, at(t0, s), [500.0, 0.0], 1.0).is_ok() {
                taken_at = Some(s);
                break;
            }
        }
        let s = taken_at.expect("a reset that stays is taken");
        assert!(
            (REANCHOR_AFTER_S..REANCHOR_AFTER_S + 0.3).contains(&s),
            "{s}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn glitches_among_real_samples_never_become_the_track() {
        let env = Envelope::for_vehicle(1.0, 10.0);
        let t0 = Instant::now();
        let mut t = Track::default();
        for i in 0..200 {
            let s = 0.05 * i as f64;
            let real = t.check(&env, at(t0, s), [0.01 * i as f64, 0.0], 1.0);
            assert!(real.is_ok(), "{i}: {real:?}");
            let fake = t.check(&env, at(t0, s + 0.01), [9_000.0, 0.0], 1.0);
            assert!(fake.is_err(), "{i}");
        }
    }

    #[test]
    fn bounds_refuse_what_no_vehicle_reports() {
        let env = Envelope::default();
        assert!(local_in_world(&env, [0.0, 0.0, -10_000.0], [0.0; 3]).is_err());
        assert!(local_in_world(&env, [0.0, 0.0, -10.0], [3e38, 0.0, 0.0]).is_err());
        assert!(local_in_world(&env, [0.0, 0.0, -10.0], [3.0, 0.0, 0.0]).is_ok());
        assert!(attitude([0.0, 0.0, 1e30], [0.0; 3]).is_err());
        assert!(attitude([0.1, -0.1, 3.0], [0.5; 3]).is_ok());
        assert!(global_on_earth(&env, 47.0, 8.0, -10_000.0).is_err());
        assert!(global_on_earth(&env, 91.0, 8.0, 10.0).is_err());
        assert!(global_on_earth(&env, 47.0, 8.0, 10.0).is_ok());
        assert!(amsl_on_earth(-10_000.0).is_err());
        assert!(amsl_on_earth(488.0).is_ok());
    }
}
