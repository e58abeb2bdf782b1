//! The mock autopilot's kinematic multicopter, in MAVLink local NED (the frame the
//! autopilot itself reports in).

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

const POSITION_GAIN_PER_S: f64 = 1.0;
const GRAVITY_MPS2: f64 = 9.80665;

impl KinematicState {
    /// Moves `dt_s` toward `target_ned_m` (or brakes to a stop with `None`) within `limits`;
    /// `feed_forward_ned_mps` is added to the position loop's velocity command (a position
    /// + velocity target).
    pub fn step(
        &mut self,
        target_ned_m: Option<[f64; 3]>,
        feed_forward_ned_mps: [f64; 3],
        limits: &Limits,
        dt_s: f64,
    ) {
        let desired = match target_ned_m {
            Some(t) => {
                let mut v = [0.0; 3];
                for (k, vk) in v.iter_mut().enumerate() {
                    *vk =
                        POSITION_GAIN_PER_S * (t[k] - self.pos_ned_m[k]) + feed_forward_ned_mps[k];
                }
                // Horizontal speed limit on the norm; vertical limits by direction.
                let h = (v[0] * v[0] + v[1] * v[1]).sqrt();
                if h > limits.xy_speed_mps {
                    v[0] *= limits.xy_speed_mps / h;
                    v[1] *= limits.xy_speed_mps / h;
                }
                v[2] = v[2].clamp(-limits.climb_mps, limits.descend_mps);
                v
            }
            None => [0.0, 0.0, 0.0],
        };
        let mut dv = [
            desired[0] - self.vel_ned_mps[0],
            desired[1] - self.vel_ned_mps[1],
        ];
        let n = (dv[0] * dv[0] + dv[1] * dv[1]).sqrt();
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

    #[test]
    fn flies_to_the_target_within_limits() {
        let mut s = KinematicState::default();
        let t = [20.0, -10.0, -15.0];
        let dt = 0.02;
        let mut max_speed: f64 = 0.0;
        let mut max_climb: f64 = 0.0;
        for _ in 0..(40.0 / dt) as usize {
            s.step(Some(t), [0.0; 3], &L, dt);
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
        s.step(Some([100.0, 0.0, 0.0]), [0.0; 3], &L, 0.05);
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
        s.step(Some([0.0, 0.0, 5.0]), [0.0; 3], &L, 0.1);
        assert_eq!(s.pos_ned_m[2], 0.0);
    }
}
