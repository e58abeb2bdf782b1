//! The vehicle's momentum in the plan: how much later than from rest a vehicle already
//! moving gets to each candidate, given its acceleration limit. A field-scale extension of
//! the paper's candidate set, whose agent (the lab's, at 1 m/s) stops at once: a drone at
//! 15 m/s with 4 m/s^2 needs 3.75 s and 28 m to stop, so a candidate behind it is reached
//! seconds after the horizon's end, and by then the target has driven on. EER judges each
//! candidate with its particles carried on by that delay ([`super::evaluate_fast_led`]), as
//! it judges an intercept.

use crate::world::geometry::Enu2;

/// Step of the flight model, s: a tenth of a field horizon (2 s).
const STEP_S: f64 = 0.1;

/// The vehicle's state and limits as the plan models its flight to a candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Momentum {
    /// The vehicle's velocity now, world ENU, m/s.
    pub velocity_enu: Enu2,
    /// Its horizontal acceleration limit, m/s^2.
    pub accel_limit_mps2: f64,
    /// Its horizontal speed limit, m/s.
    pub speed_limit_mps: f64,
    /// Within this distance of a candidate the vehicle is over it, m.
    pub arrived_within_m: f64,
    /// The longest flight modelled, s: a candidate not reached by then is reached then.
    pub longest_s: f64,
}

/// When a vehicle at `from_enu` moving at `velocity_enu` gets within
/// `m.arrived_within_m` of `to_enu`, s, flying at `m`'s limits: each step it turns its
/// velocity toward the top speed straight at the candidate, changing it by at most the
/// acceleration limit (braking and turning share it, as a multicopter's tilt does).
pub fn arrival_s(from_enu: &Enu2, velocity_enu: &Enu2, to_enu: &Enu2, m: &Momentum) -> f64 {
    let (mut p, mut v) = (*from_enu, *velocity_enu);
    let max_dv = m.accel_limit_mps2 * STEP_S;
    let mut t = 0.0;
    while t < m.longest_s {
        let to_go = to_enu - p;
        let distance = to_go.norm();
        if distance <= m.arrived_within_m {
            return t;
        }
        let mut dv = to_go * (m.speed_limit_mps / distance) - v;
        if dv.norm() > max_dv {
            dv *= max_dv / dv.norm();
        }
        v += dv;
        p += v * STEP_S;
        t += STEP_S;
    }
    m.longest_s
}

/// How late after the horizon's end (`horizon_s`) the vehicle, moving as it is, gets to
/// each candidate, beyond when it would from rest, s: `max(0, T_moving - max(H, T_rest))`.
/// The paper's agent is at each reachable candidate at the horizon's end, and an intercept
/// is where it meets its particle flying from rest at its top speed; the momentum only adds
/// what comes on top of that: zero for a candidate the vehicle gets to by the horizon's end
/// or no later than from rest (its momentum carries it there).
pub fn momentum_delays_s(
    candidates: &[Enu2],
    agent_enu: &Enu2,
    horizon_s: f64,
    m: &Momentum,
) -> Vec<f64> {
    let at_rest = Enu2::zeros();
    candidates
        .iter()
        .map(|c| {
            if m.velocity_enu == at_rest {
                return 0.0;
            }
            let moving = arrival_s(agent_enu, &m.velocity_enu, c, m);
            let resting = arrival_s(agent_enu, &at_rest, c, m);
            (moving - resting.max(horizon_s)).max(0.0)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(velocity_enu: Enu2) -> Momentum {
        Momentum {
            velocity_enu,
            accel_limit_mps2: 4.0,
            speed_limit_mps: 15.0,
            arrived_within_m: 1.0,
            longest_s: 30.0,
        }
    }

    #[test]
    fn from_rest_a_far_point_takes_the_acceleration_then_the_cruise() {
        // 3.75 s to reach 15 m/s over 28.1 m, then (300 - 1 - 28.1) / 15 = 18.1 s.
        let m = field(Enu2::zeros());
        let t = arrival_s(&Enu2::zeros(), &Enu2::zeros(), &Enu2::new(300.0, 0.0), &m);
        assert!((t - 21.8).abs() < 0.3, "{t}");
    }

    #[test]
    fn a_candidate_behind_a_fast_vehicle_is_late_and_one_ahead_is_not() {
        let m = field(Enu2::new(15.0, 0.0));
        let agent = Enu2::new(100.0, 50.0);
        let cands = [agent + Enu2::new(-30.0, 0.0), agent + Enu2::new(30.0, 0.0)];
        let d = momentum_delays_s(&cands, &agent, 2.0, &m);
        // Behind: 3.75 s to stop 28 m on, then 58 m back; from rest 30 m. Ahead: sooner.
        assert!(d[0] > 4.0 && d[0] < 8.0, "{d:?}");
        assert_eq!(d[1], 0.0);
    }

    #[test]
    fn the_frames_agree_a_north_bound_vehicle_is_late_to_the_south_only() {
        let m = field(Enu2::new(0.0, 15.0));
        let agent = Enu2::new(-20.0, 10.0);
        let cands = [agent + Enu2::new(0.0, -30.0), agent + Enu2::new(0.0, 30.0)];
        let d = momentum_delays_s(&cands, &agent, 2.0, &m);
        assert!(d[0] > 4.0, "{d:?}");
        assert_eq!(d[1], 0.0);
    }

    #[test]
    fn a_candidate_reached_by_the_horizons_end_is_not_late() {
        // 10 m to the side of a vehicle at 3 m/s: later than from rest, but within 2 s.
        let m = Momentum {
            arrived_within_m: 8.0,
            ..field(Enu2::new(3.0, 0.0))
        };
        let side = [Enu2::new(0.0, 10.0)];
        assert_eq!(momentum_delays_s(&side, &Enu2::zeros(), 2.0, &m), vec![0.0]);
        let moving = arrival_s(&Enu2::zeros(), &m.velocity_enu, &side[0], &m);
        let resting = arrival_s(&Enu2::zeros(), &Enu2::zeros(), &side[0], &m);
        assert!(moving > resting && moving <= 2.0, "{moving} {resting}");
    }

    #[test]
    fn at_rest_nothing_is_late() {
        let m = field(Enu2::zeros());
        let d = momentum_delays_s(&[Enu2::new(-50.0, 3.0)], &Enu2::zeros(), 2.0, &m);
        assert_eq!(d, vec![0.0]);
    }

    #[test]
    fn an_unreachable_candidate_is_reached_at_the_longest_flight() {
        let m = Momentum {
            longest_s: 2.0,
            ..field(Enu2::zeros())
        };
        let t = arrival_s(&Enu2::zeros(), &Enu2::zeros(), &Enu2::new(1e4, 0.0), &m);
        assert!((t - 2.0).abs() < 0.11, "{t}");
    }
}
