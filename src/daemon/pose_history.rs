//! The vehicle's recent poses, so that a camera frame is projected with the pose at its
//! capture time rather than the newest one (at 3 m/s a 50 ms-old frame is 15 cm off).

use std::collections::VecDeque;
use std::time::Duration;
use tokio::time::Instant;

use crate::vision::camera_model::VehiclePoseNed;

/// Poses with their arrival times on the companion's monotonic clock, oldest first.
#[derive(Debug, Default)]
pub struct PoseHistory {
    poses: VecDeque<(Instant, VehiclePoseNed)>,
    keep: Duration,
}

fn lerp_angle(a: f64, b: f64, f: f64) -> f64 {
    let d = (b - a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
        - std::f64::consts::PI;
    a + f * d
}

impl PoseHistory {
    /// Keeps `keep` of history.
    pub fn new(keep: Duration) -> Self {
        Self {
            poses: VecDeque::new(),
            keep,
        }
    }

    /// Adds a pose (times must not go back; an older one is ignored).
    pub fn push(&mut self, at: Instant, pose: VehiclePoseNed) {
        if self.poses.back().is_some_and(|(t, _)| *t > at) {
            return;
        }
        self.poses.push_back((at, pose));
        while self
            .poses
            .front()
            .is_some_and(|(t, _)| at.duration_since(*t) > self.keep)
        {
            self.poses.pop_front();
        }
    }

    /// The pose at `at`: interpolated between the two around it (angles the short way),
    /// the newest if `at` is later than all (up to `max_extrapolation`), `None` if the
    /// history does not cover it.
    pub fn at(&self, at: Instant, max_extrapolation: Duration) -> Option<VehiclePoseNed> {
        let (t_last, last) = *self.poses.back()?;
        if at >= t_last {
            return (at.duration_since(t_last) <= max_extrapolation).then_some(last);
        }
        let i = self.poses.iter().position(|(t, _)| *t > at)?;
        if i == 0 {
            return None;
        }
        let (t0, p0) = self.poses[i - 1];
        let (t1, p1) = self.poses[i];
        let f = at.duration_since(t0).as_secs_f64() / t1.duration_since(t0).as_secs_f64();
        let mut pos = [0.0; 3];
        for (k, v) in pos.iter_mut().enumerate() {
            *v = p0.position_ned_m[k] + f * (p1.position_ned_m[k] - p0.position_ned_m[k]);
        }
        Some(VehiclePoseNed {
            position_ned_m: pos,
            roll_rad: lerp_angle(p0.roll_rad, p1.roll_rad, f),
            pitch_rad: lerp_angle(p0.pitch_rad, p1.pitch_rad, f),
            yaw_rad: lerp_angle(p0.yaw_rad, p1.yaw_rad, f),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(n: f64, yaw: f64) -> VehiclePoseNed {
        VehiclePoseNed {
            position_ned_m: [n, 0.0, -10.0],
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: yaw,
        }
    }

    #[test]
    fn interpolates_between_poses_and_refuses_outside_the_history() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let mut h = PoseHistory::new(Duration::from_secs(1));
        h.push(t0, pose(0.0, 3.0));
        h.push(t0 + ms(100), pose(1.0, -3.0));
        let p = h.at(t0 + ms(25), ms(50)).unwrap();
        assert!((p.position_ned_m[0] - 0.25).abs() < 1e-9);
        // 3 rad to -3 rad goes through pi, not through 0.
        assert!(p.yaw_rad > 3.0, "{}", p.yaw_rad);
        assert_eq!(h.at(t0 + ms(120), ms(50)).unwrap().position_ned_m[0], 1.0);
        assert!(
            h.at(t0 + ms(200), ms(50)).is_none(),
            "too far past the newest"
        );
        assert!(h.at(t0 - ms(1), ms(50)).is_none(), "before the oldest");
        // Old poses are dropped.
        h.push(t0 + ms(1500), pose(2.0, 0.0));
        assert!(h.at(t0 + ms(50), ms(50)).is_none());
    }
}
