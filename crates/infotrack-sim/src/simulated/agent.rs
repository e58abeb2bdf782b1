//! The simulated agent: a multicopter at fixed altitude following position setpoints with a
//! proportional velocity controller, a speed limit (per axis or on the norm, as configured)
//! and an acceleration limit, turning its camera's view at a yaw-rate limit.

use infotrack_config::{AgentConfig, SpeedLimitShape};
use infotrack_core::frames::wrap_angle;
use infotrack_core::world::camera::{View, NORTH_VIEW_YAW_ENU_RAD};
use infotrack_core::world::geometry::Enu2;

/// Agent state in the world ENU frame (horizontal; altitude is fixed).
#[derive(Debug, Clone)]
pub struct AgentSim {
    /// Position, metres.
    pub position_enu: Enu2,
    /// Velocity, m/s.
    pub velocity_enu: Enu2,
    /// Which way the camera's image faces (the nose: the camera is mounted straight), world
    /// ENU yaw, rad.
    pub view_yaw_enu_rad: f64,
    params: AgentConfig,
}

impl AgentSim {
    /// At the configured start, at rest.
    pub fn new(params: AgentConfig) -> Self {
        Self {
            position_enu: Enu2::new(params.start_enu_m[0], params.start_enu_m[1]),
            velocity_enu: Enu2::zeros(),
            view_yaw_enu_rad: NORTH_VIEW_YAW_ENU_RAD,
            params,
        }
    }

    /// What the camera sees from now: its position and heading.
    pub fn view(&self) -> View {
        View::new(self.position_enu, self.view_yaw_enu_rad)
    }

    /// Turns `dt_s` toward the heading `yaw_enu_rad` (world ENU) the short way round, at
    /// most at the yaw-rate limit.
    pub fn turn_toward(&mut self, yaw_enu_rad: f64, dt_s: f64) {
        let max_step = self.params.yaw_rate_limit_rad_s() * dt_s;
        let to_go = wrap_angle(yaw_enu_rad - self.view_yaw_enu_rad);
        if to_go != 0.0 {
            self.view_yaw_enu_rad =
                wrap_angle(self.view_yaw_enu_rad + to_go.clamp(-max_step, max_step));
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
        let v_cmd = limit_speed(
            v_p + feed_forward_enu,
            p.speed_limit_mps,
            p.speed_limit_shape,
        );
        let mut dv = v_cmd - self.velocity_enu;
        let max_dv = p.accel_limit_mps2 * dt_s;
        if dv.norm() > max_dv {
            dv *= max_dv / dv.norm();
        }
        self.velocity_enu += dv;
        self.position_enu += self.velocity_enu * dt_s;
    }
}

/// The commanded velocity within the speed limit: per axis (the paper's lab agent), or
/// scaled down along its own direction (PX4 and ArduCopter).
fn limit_speed(v_enu: Enu2, limit_mps: f64, shape: SpeedLimitShape) -> Enu2 {
    match shape {
        SpeedLimitShape::PerAxis => v_enu.map(|v| v.clamp(-limit_mps, limit_mps)),
        SpeedLimitShape::Norm => {
            let speed = v_enu.norm();
            if speed > limit_mps {
                v_enu * (limit_mps / speed)
            } else {
                v_enu
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use infotrack_config::Config;

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
    fn turns_the_short_way_round_at_the_yaw_rate_limit() {
        let c = Config::default_lab();
        let mut a = AgentSim::new(c.agent.clone());
        assert_eq!(a.view_yaw_enu_rad, NORTH_VIEW_YAW_ENU_RAD);
        let rate = c.agent.yaw_rate_limit_rad_s();
        assert!((rate - 45f64.to_radians()).abs() < 1e-12);
        // North (pi/2) to just past west (pi + 0.1 = -pi + 0.1): counter-clockwise, 1.67 rad.
        let target = -std::f64::consts::PI + 0.1;
        let dt = 0.1;
        let mut prev = a.view_yaw_enu_rad;
        for _ in 0..30 {
            a.turn_toward(target, dt);
            let step = wrap_angle(a.view_yaw_enu_rad - prev);
            assert!((0.0..=rate * dt + 1e-12).contains(&step), "{step}");
            prev = a.view_yaw_enu_rad;
        }
        assert!(
            (a.view_yaw_enu_rad - target).abs() < 1e-12,
            "{}",
            a.view_yaw_enu_rad
        );
        assert_eq!(a.view().yaw_enu_rad, target);
        // At the heading it stays exactly there.
        a.turn_toward(target, dt);
        assert_eq!(a.view_yaw_enu_rad, target);
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

    /// A saturated diagonal command: per axis, both components reach the limit (1.41x the
    /// speed, the paper's lab agent); on the norm the speed is the limit and the command's
    /// direction is kept (PX4, ArduCopter). Both ways, an off-diagonal command.
    #[test]
    fn the_speed_limit_applies_per_axis_or_on_the_norm_as_configured() {
        let v = Enu2::new(30.0, 10.0);
        let per_axis = limit_speed(v, 15.0, SpeedLimitShape::PerAxis);
        assert_eq!(per_axis, Enu2::new(15.0, 10.0));
        let norm = limit_speed(v, 15.0, SpeedLimitShape::Norm);
        assert!((norm.norm() - 15.0).abs() < 1e-9, "{norm}");
        assert!((norm.y / norm.x - 10.0 / 30.0).abs() < 1e-12, "{norm}");
        // Within the limit, neither changes the command.
        let slow = Enu2::new(-3.0, 4.0);
        assert_eq!(limit_speed(slow, 15.0, SpeedLimitShape::Norm), slow);
        assert_eq!(limit_speed(slow, 15.0, SpeedLimitShape::PerAxis), slow);
    }

    /// An agent limited on the norm flies a long diagonal leg at the limit and straight at
    /// its goal (per axis it would fly 1.41x faster, along the diagonal).
    #[test]
    fn a_norm_limited_agent_flies_straight_at_the_limit() {
        let mut c = Config::default_lab();
        c.agent.speed_limit_mps = 10.0;
        c.agent.accel_limit_mps2 = 5.0;
        c.agent.speed_limit_shape = SpeedLimitShape::Norm;
        let mut a = AgentSim::new(c.agent.clone());
        let start = a.position_enu;
        let goal = start + Enu2::new(400.0, 100.0);
        let dt = 0.1;
        for _ in 0..200 {
            a.step(&goal, &Enu2::zeros(), dt);
            assert!(a.velocity_enu.norm() <= 10.0 + 1e-9);
            let off = a.position_enu - start;
            // On the line from the start to the goal (cross product ~ 0).
            assert!(
                (off.x * 100.0 - off.y * 400.0).abs() / 412.3 < 1e-6,
                "{off}"
            );
        }
        assert!((a.velocity_enu.norm() - 10.0).abs() < 1e-9);
    }
}
