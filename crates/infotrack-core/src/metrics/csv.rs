//! The per-step record as a CSV row: the format of `steps.csv` (a simulated run's and a
//! flight's), text only.

use std::fmt::Write;

use super::StepRecord;

/// The header of a per-step log; every position is world ENU, metres.
pub const HEADER: &str = "t_s,target_x_enu_m,target_y_enu_m,agent_x_enu_m,agent_y_enu_m,waypoint_x_enu_m,waypoint_y_enu_m,measured,z_x_enu_m,z_y_enu_m,estimate_x_enu_m,estimate_y_enu_m,cov_xx_m2,cov_xy_m2,cov_yy_m2,n_eff,eer,target_occluded,target_in_footprint,tracking_error_m,estimation_error_m";

/// Renders step records as CSV text.
pub fn render(steps: &[StepRecord]) -> String {
    let mut s = String::with_capacity(steps.len() * 200);
    s.push_str(HEADER);
    s.push('\n');
    for r in steps {
        s.push_str(&render_row(r));
    }
    s
}

/// One step as a CSV row, newline included.
pub fn render_row(r: &StepRecord) -> String {
    let mut s = String::with_capacity(200);
    {
        let (zx, zy) = r
            .measurement_enu
            .map(|z| (z.x.to_string(), z.y.to_string()))
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "{:.4},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{},{},{},{:.5},{:.5},{:.6e},{:.6e},{:.6e},{:.2},{:.6},{},{},{:.5},{:.5}",
            r.t_s,
            r.target_enu.x,
            r.target_enu.y,
            r.agent_enu.x,
            r.agent_enu.y,
            r.waypoint_enu.x,
            r.waypoint_enu.y,
            u8::from(r.measurement_enu.is_some()),
            zx,
            zy,
            r.estimate_enu.x,
            r.estimate_enu.y,
            r.cov_m2[(0, 0)],
            r.cov_m2[(0, 1)],
            r.cov_m2[(1, 1)],
            r.n_eff,
            r.eer,
            u8::from(r.target_occluded),
            u8::from(r.target_in_footprint),
            r.tracking_error_m(),
            r.estimation_error_m()
        );
    }
    s
}
