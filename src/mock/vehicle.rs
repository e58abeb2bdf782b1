//! The mock autopilot's kinematic multicopter, in MAVLink local NED (the frame the
//! autopilot itself reports in).

use crate::autopilot::modes::Flavor;

/// Limits of the kinematic model, from the flavour's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Horizontal speed limit, m/s.
    pub xy_speed_mps: f64,
    /// Horizontal acceleration limit, m/s^2.
    pub xy_accel_mps2: f64,
    /// Climb rate limit, m/s.
    pub climb_mps: f64,
    /// Descent rate limit, m/s.
    pub descend_mps: f64,
}

/// Position and velocity, local NED, metres and m/s.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct KinematicState {
    /// [north, east, down], m.
    pub pos_ned_m: [f64; 3],
    /// [north, east, down], m/s.
    pub vel_ned_mps: [f64; 3],
    /// Last horizontal acceleration [north, east], m/s^2 (for the attitude).
    pub acc_ned_mps2: [f64; 2],
}

/// How a firmware's position loop answers a companion's targets, beyond its speed and
/// acceleration parameters: what `tests/common/probe.rs` measured on its SITL build
/// (`tests/fixtures/sitl/`, fitted in BENCHMARKS.md "The mock calibrated against SITL").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Response {
    /// Horizontal velocity commanded per metre of position error, 1/s.
    pub position_gain_per_s: f64,
    /// Time constant of the horizontal velocity following its command, s (0: as fast as
    /// the acceleration limit allows).
    pub velocity_lag_s: f64,
    /// Climb rate commanded per metre of altitude error, 1/s.
    pub vertical_gain_per_s: f64,
    /// Seconds from arming until the vehicle leaves the ground (motors spooling up, the
    /// takeoff command's handling).
    pub spool_up_s: f64,
    /// Climb rate while taking off, m/s (until the altitude is first reached).
    pub takeoff_climb_mps: f64,
    /// The loop's wander: the point the vehicle holds moves around the target as a
    /// Gauss-Markov process (the estimator's error and disturbances as the SITL's physics
    /// make them), standard deviation per horizontal axis, m.
    pub wander_horizontal_m: f64,
    /// The same vertically, m.
    pub wander_vertical_m: f64,
    /// The wander's correlation time, s.
    pub wander_correlation_s: f64,
}

impl Response {
    /// The calibrated response of `flavor`'s SITL build.
    pub fn sitl(flavor: Flavor) -> Response {
        match flavor {
            Flavor::Px4 => Response::PX4_SIH,
            Flavor::ArduPilot => Response::ARDUCOPTER_SITL,
        }
    }

    /// A loop that follows its target exactly within the speed and acceleration limits
    /// (gain 1/s, no lag, no wander): the mock before its calibration, and the paper's
    /// simulated agent.
    pub const IDEAL: Response = Response {
        position_gain_per_s: 1.0,
        velocity_lag_s: 0.0,
        vertical_gain_per_s: 1.0,
        spool_up_s: 0.0,
        takeoff_climb_mps: f64::INFINITY,
        wander_horizontal_m: 0.0,
        wander_vertical_m: 0.0,
        wander_correlation_s: 1.0,
    };

    /// PX4 SIH (airframe 10040, default parameters) answering offboard position targets:
    /// a slow, underdamped loop that never settles (SIH's simulated GPS and estimator).
    pub const PX4_SIH: Response = Response {
        position_gain_per_s: 0.95,
        velocity_lag_s: 1.8,
        vertical_gain_per_s: 0.35,
        spool_up_s: 2.3,
        takeoff_climb_mps: 0.3,
        wander_horizontal_m: 0.25,
        wander_vertical_m: 0.08,
        wander_correlation_s: 2.5,
    };

    /// ArduCopter SITL (the `quad` model, copter.parm) answering GUIDED position targets:
    /// well damped and steady.
    pub const ARDUCOPTER_SITL: Response = Response {
        position_gain_per_s: 0.9,
        velocity_lag_s: 0.6,
        vertical_gain_per_s: 2.0,
        spool_up_s: 3.1,
        takeoff_climb_mps: 1.0,
        wander_horizontal_m: 0.0,
        wander_vertical_m: 0.0,
        wander_correlation_s: 1.0,
    };
}

const GRAVITY_MPS2: f64 = 9.80665;

/// Where a [`KinematicState::step`] is told to go.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    /// The target, local NED, m (`None`: brake to a stop).
    pub target_ned_m: Option<[f64; 3]>,
    /// Velocity feed-forward added to the position loop's command (a position + velocity
    /// target), NED, m/s.
    pub feed_forward_ned_mps: [f64; 3],
    /// Still climbing out of a takeoff: the climb is limited to the takeoff rate.
    pub taking_off: bool,
}

impl KinematicState {
    /// Moves `dt_s` toward the command's target (or brakes to a stop) within `limits`, as
    /// `response` answers.
    pub fn step(&mut self, cmd: &Command, limits: &Limits, response: &Response, dt_s: f64) {
        let desired = match cmd.target_ned_m {
            Some(t) => {
                let ff = cmd.feed_forward_ned_mps;
                let k = response.position_gain_per_s;
                let mut v = [
                    k * (t[0] - self.pos_ned_m[0]) + ff[0],
                    k * (t[1] - self.pos_ned_m[1]) + ff[1],
                    response.vertical_gain_per_s * (t[2] - self.pos_ned_m[2]) + ff[2],
                ];
                // Horizontal speed limit on the norm; vertical limits by direction.
                let h = v[0].hypot(v[1]);
                if h > limits.xy_speed_mps {
                    v[0] *= limits.xy_speed_mps / h;
                    v[1] *= limits.xy_speed_mps / h;
                }
                let climb = if cmd.taking_off {
                    limits.climb_mps.min(response.takeoff_climb_mps)
                } else {
                    limits.climb_mps
                };
                v[2] = v[2].clamp(-climb, limits.descend_mps);
                v
            }
            None => [0.0, 0.0, 0.0],
        };
        // The velocity follows its command with the loop's lag, within the acceleration
        // limit (no lag: the whole difference in one step, as far as the limit allows).
        let lag = response.velocity_lag_s.max(dt_s);
        let mut dv = [
            (desired[0] - self.vel_ned_mps[0]) * dt_s / lag,
            (desired[1] - self.vel_ned_mps[1]) * dt_s / lag,
        ];
        let n = dv[0].hypot(dv[1]);
        let max = limits.xy_accel_mps2 * dt_s;
        if n > max {
            dv[0] *= max / n;
            dv[1] *= max / n;
        }
        self.acc_ned_mps2 = [dv[0] / dt_s, dv[1] / dt_s];
        self.vel_ned_mps[0] += dv[0];
        self.vel_ned_mps[1] += dv[1];
        // Vertical: first-order, fast enough that climbs are rate-limited, not lagged.
        self.vel_ned_mps[2] = desired[2];
        for k in 0..3 {
            self.pos_ned_m[k] += self.vel_ned_mps[k] * dt_s;
        }
        // The ground.
        if self.pos_ned_m[2] > 0.0 {
            self.pos_ned_m[2] = 0.0;
            self.vel_ned_mps[2] = self.vel_ned_mps[2].min(0.0);
        }
    }

    /// Roll and pitch (radians) that produce the current horizontal acceleration at yaw
    /// `yaw_ned_rad`: a multicopter tilts into its acceleration.
    pub fn attitude(&self, yaw_ned_rad: f64) -> (f64, f64) {
        let (s, c) = yaw_ned_rad.sin_cos();
        // Acceleration in the body frame (forward, right).
        let a_fwd = c * self.acc_ned_mps2[0] + s * self.acc_ned_mps2[1];
        let a_right = -s * self.acc_ned_mps2[0] + c * self.acc_ned_mps2[1];
        let pitch = -(a_fwd / GRAVITY_MPS2).atan();
        let roll = (a_right / GRAVITY_MPS2).atan();
        (roll, pitch)
    }

    /// Height above the origin, m.
    pub fn altitude_m(&self) -> f64 {
        -self.pos_ned_m[2]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const L: Limits = Limits {
        xy_speed_mps: 5.0,
        xy_accel_mps2: 3.0,
        climb_mps: 2.0,
        descend_mps: 1.0,
    };

    fn to(t: [f64; 3]) -> Command {
        Command {
            target_ned_m: Some(t),
            feed_forward_ned_mps: [0.0; 3],
            taking_off: false,
        }
    }

    /// A 1 m step: the calibrated loops rise and overshoot as their SITL builds did (PX4
    /// SIH: 90 % in 2.1-2.9 s, past the step by ~0.2 m; ArduCopter 2.1 s, 0.07 m), the
    /// ideal one settles without passing the target.
    #[test]
    fn calibrated_loops_answer_a_step_as_their_sitl_did() {
        for (r, rise, overshoot) in [
            (Response::PX4_SIH, 1.8..3.2, 0.08..0.35),
            (Response::ARDUCOPTER_SITL, 1.6..2.6, 0.0..0.12),
            (Response::IDEAL, 1.0..3.0, 0.0..1e-9),
        ] {
            let mut s = KinematicState::default();
            let dt = 0.01;
            let (mut t90, mut peak) = (None, 0.0f64);
            for i in 0..1000 {
                s.step(&to([1.0, 0.0, 0.0]), &L, &r, dt);
                if s.pos_ned_m[0] >= 0.9 && t90.is_none() {
                    t90 = Some(i as f64 * dt);
                }
                peak = peak.max(s.pos_ned_m[0] - 1.0);
            }
            let t90 = t90.unwrap();
            assert!(rise.contains(&t90), "{r:?}: 90 % after {t90} s");
            assert!(overshoot.contains(&peak), "{r:?}: overshoot {peak} m");
        }
    }

    #[test]
    fn flies_to_the_target_within_limits() {
        let mut s = KinematicState::default();
        let t = [20.0, -10.0, -15.0];
        let dt = 0.02;
        let mut max_speed: f64 = 0.0;
        let mut max_climb: f64 = 0.0;
        for _ in 0..(40.0 / dt) as usize {
            s.step(&to(t), &L, &Response::IDEAL, dt);
            max_speed = max_speed.max((s.vel_ned_mps[0].powi(2) + s.vel_ned_mps[1].powi(2)).sqrt());
            max_climb = max_climb.max(-s.vel_ned_mps[2]);
        }
        let err: f64 = (0..3)
            .map(|k| (s.pos_ned_m[k] - t[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(err < 0.05, "{:?}", s.pos_ned_m);
        assert!(max_speed <= 5.0 + 1e-9 && max_climb <= 2.0 + 1e-9);
    }

    #[test]
    fn tilts_into_its_acceleration() {
        let mut s = KinematicState::default();
        s.step(&to([100.0, 0.0, 0.0]), &L, &Response::IDEAL, 0.05);
        // Accelerating north while facing north: nose down (negative pitch), no roll.
        let (roll, pitch) = s.attitude(0.0);
        assert!(pitch < -0.2 && roll.abs() < 1e-9, "{roll} {pitch}");
        // Facing east, the same acceleration is to the left: roll negative.
        let (roll, pitch) = s.attitude(std::f64::consts::FRAC_PI_2);
        assert!(roll < -0.2 && pitch.abs() < 1e-9, "{roll} {pitch}");
    }

    #[test]
    fn stays_on_the_ground() {
        let mut s = KinematicState::default();
        s.step(&to([0.0, 0.0, 5.0]), &L, &Response::IDEAL, 0.1);
        assert_eq!(s.pos_ned_m[2], 0.0);
    }
}
