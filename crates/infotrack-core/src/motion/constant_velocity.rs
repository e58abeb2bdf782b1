//! The particle constant-velocity baseline of the paper.
//!
//! The paper: each particle "estimates the target's next position using an estimated
//! velocity computed by the change in observed position", with the velocity "randomly
//! sampled from a range of [0, 0.7] m/s". Here a particle's velocity is the one its own
//! history encodes: the mean displacement over its track, with the speed clipped to the
//! configured maximum. The random draw happens where tracks are created (filter
//! initialisation and uniform re-draws give each particle a straight track with a speed
//! drawn from [0, max] and a uniform heading), so the model itself is deterministic and
//! a resampled particle keeps its velocity with its history.

use super::{Histories, MotionError, MotionModel};
use crate::world::geometry::Enu2;

/// Constant-velocity prediction from each particle's own track.
#[derive(Debug, Clone)]
pub struct ConstantVelocity {
    max_step_m: f64,
}

impl ConstantVelocity {
    /// With a speed limit in m/s and the filter period in seconds.
    pub fn new(max_speed_mps: f64, dt_s: f64) -> Self {
        Self {
            max_step_m: max_speed_mps * dt_s,
        }
    }
}

impl MotionModel for ConstantVelocity {
    fn name(&self) -> &str {
        "cv"
    }

    fn required_history_len(&self) -> Option<usize> {
        None
    }

    fn predict(&mut self, histories: &Histories, out: &mut [Enu2]) -> Result<(), MotionError> {
        let k = histories.k_in();
        if k < 2 {
            return Err(MotionError::HistoryLength {
                model: "cv".into(),
                expected: 2,
                got: k,
            });
        }
        let steps = (k - 1) as f64;
        for (i, o) in out.iter_mut().enumerate() {
            let tr = histories.track(i);
            let (x0, y0) = (tr[0], tr[1]);
            let (x1, y1) = (tr[2 * k - 2], tr[2 * k - 1]);
            let mut vx = (x1 - x0) / steps;
            let mut vy = (y1 - y0) / steps;
            let s = (vx * vx + vy * vy).sqrt();
            if s > self.max_step_m {
                let f = self.max_step_m / s;
                vx *= f;
                vy *= f;
            }
            *o = Enu2::new(x1 + vx, y1 + vy);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_track_continues_at_its_speed() {
        let mut h = Histories::new(1, 4);
        for k in 0..4 {
            h.push(&[Enu2::new(0.1 * k as f64, 0.0)]);
        }
        let mut cv = ConstantVelocity::new(0.7, 1.0 / 3.0);
        let mut out = [Enu2::zeros()];
        cv.predict(&h, &mut out).unwrap();
        assert!((out[0] - Enu2::new(0.4, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn speed_is_clipped_to_the_maximum() {
        let mut h = Histories::new(1, 2);
        h.push(&[Enu2::new(0.0, 0.0)]);
        h.push(&[Enu2::new(0.0, 5.0)]);
        let mut cv = ConstantVelocity::new(0.6, 0.5);
        let mut out = [Enu2::zeros()];
        cv.predict(&h, &mut out).unwrap();
        assert!((out[0] - Enu2::new(0.0, 5.3)).norm() < 1e-12);
    }
}
