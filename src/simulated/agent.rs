//! The simulated agent: a multicopter at fixed altitude following position setpoints with a
//! proportional velocity controller, per-axis speed limit and an acceleration limit.

use crate::config::AgentConfig;
use crate::world::geometry::Enu2;

/// Agent state in the world ENU frame (horizontal; altitude is fixed).
#[derive(Debug, Clone)]
pub struct AgentSim {
    /// Position, metres.
    pub position_enu: Enu2,
    /// Velocity, m/s.
    pub velocity_enu: Enu2,
    params: AgentConfig,
}

impl AgentSim {
    /// At the configured start, at rest.
    pub fn new(params: AgentConfig) -> Self {
        Self {
            position_enu: Enu2::new(params.start_enu_m[0], params.start_enu_m[1]),
            velocity_enu: Enu2::zeros(),
            params,
        }
    }

    /// Advances `dt_s` toward `setpoint_enu`, with `feed_forward_enu` (m/s) added to the
    /// position loop's velocity command as a real autopilot does with a position + velocity
    /// target.
    pub fn step(&mut self, setpoint_enu: &Enu2, feed_forward_enu: &Enu2, dt_s: f64) {
        let p = &self.params;
        let err = setpoint_enu - self.position_enu;
        let v_p = if err.norm() < p.dead_zone_m {
            Enu2::zeros()
        } else {
            err * p.gain_per_s
        };
        let v_cmd =
            (v_p + feed_forward_enu).map(|v| v.clamp(-p.speed_limit_mps, p.speed_limit_mps));
        let mut dv = v_cmd - self.velocity_enu;
        let max_dv = p.accel_limit_mps2 * dt_s;
        if dv.norm() > max_dv {
            dv *= max_dv / dv.norm();
        }
        self.velocity_enu += dv;
        self.position_enu += self.velocity_enu * dt_s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    #[test]
    fn converges_to_the_setpoint_within_the_limits() {
        let c = Config::default_lab();
        let mut a = AgentSim::new(c.agent.clone());
        let goal = Enu2::new(0.8, -1.0);
        let dt = 1.0 / 30.0;
        let mut prev_v = a.velocity_enu;
        for _ in 0..(20 * 30) {
            a.step(&goal, &Enu2::zeros(), dt);
            assert!(a.velocity_enu.x.abs() <= 1.0 + 1e-9 && a.velocity_enu.y.abs() <= 1.0 + 1e-9);
            assert!((a.velocity_enu - prev_v).norm() <= 2.0 * dt + 1e-9);
            prev_v = a.velocity_enu;
        }
        assert!((a.position_enu - goal).norm() < 0.15, "{}", a.position_enu);
    }

    #[test]
    fn feed_forward_removes_the_lag_behind_a_moving_setpoint() {
        let mut c = Config::default_lab();
        c.agent.speed_limit_mps = 20.0;
        c.agent.accel_limit_mps2 = 10.0;
        let v = Enu2::new(10.0, 0.0);
        let dt = 1.0 / 30.0;
        let lag = |ff: bool| {
            let mut a = AgentSim::new(c.agent.clone());
            let start = a.position_enu;
            let mut sp = start;
            for _ in 0..(30 * 30) {
                sp += v * dt;
                a.step(&sp, &if ff { v } else { Enu2::zeros() }, dt);
            }
            (sp - a.position_enu).norm()
        };
        // Position only: the loop trails by speed / gain; with the feed-forward it does not.
        let without = lag(false);
        assert!(
            (without - 10.0 / c.agent.gain_per_s).abs() < 0.5,
            "{without}"
        );
        // (What remains is one physics step of motion: the setpoint moves before the agent.)
        assert!(lag(true) < 10.0 / 30.0 + 0.05, "{}", lag(true));
    }
}
