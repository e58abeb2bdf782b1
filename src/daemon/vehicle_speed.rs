//! Whether the vehicle can fly the speed the guidance plans with: its speed parameter and
//! lean limit, read at connection, and what to tell the operator when they fall short.

use crate::autopilot::link::VehicleLink;
use crate::autopilot::modes::Flavor;
use crate::config::Config;

/// Reads the vehicle's horizontal speed and lean limits and warns when they cannot fly the
/// speed the guidance plans with (`agent.speed_limit_mps`): a vehicle slower than planned
/// trails the plans and, at field scale, never catches the car (BENCHMARKS.md, "The field
/// world on ArduCopter"). A parameter that cannot be read is said, not guessed.
pub(super) async fn warn_if_slower_than_planned(cfg: &Config, link: &VehicleLink, flavor: Flavor) {
    let (speed_name, speed_scale, tilt_name, tilt_scale) = match flavor {
        Flavor::Px4 => ("MPC_XY_VEL_MAX", 1.0, "MPC_TILTMAX_AIR", 1.0),
        // ArduPilot: cm/s and centidegrees.
        Flavor::ArduPilot => ("WPNAV_SPEED", 0.01, "ANGLE_MAX", 0.01),
    };
    let read = |name: &'static str, scale: f64| async move {
        match link.param_read(name).await {
            Ok((v, _)) => Some(v * scale),
            Err(e) => {
                tracing::warn!("could not read the vehicle's {name} to check its speed: {e}");
                None
            }
        }
    };
    let speed = read(speed_name, speed_scale).await;
    let tilt = read(tilt_name, tilt_scale).await;
    for w in speed_warnings(flavor, speed, tilt, cfg.agent.speed_limit_mps) {
        tracing::warn!("{w}");
    }
}

/// What to tell the operator about a vehicle whose speed parameter (m/s) or lean limit
/// (degrees) may keep it from flying `planned_mps`.
fn speed_warnings(
    flavor: Flavor,
    speed_mps: Option<f64>,
    tilt_deg: Option<f64>,
    planned_mps: f64,
) -> Vec<String> {
    let (speed_name, tilt_name, file) = match flavor {
        Flavor::Px4 => (
            "MPC_XY_VEL_MAX",
            "MPC_TILTMAX_AIR",
            "firmware-params/px4-offboard-tracking.params",
        ),
        Flavor::ArduPilot => (
            "WPNAV_SPEED",
            "ANGLE_MAX",
            "firmware-params/ardupilot-guided-tracking.parm",
        ),
    };
    let mut out = Vec::new();
    if let Some(v) = speed_mps.filter(|v| *v + 1e-6 < planned_mps) {
        out.push(format!(
            "the vehicle's {speed_name} is {v:.1} m/s, below agent.speed_limit_mps = \
             {planned_mps:.1} m/s: it will trail the guidance's plans; load {file} (or set \
             {speed_name}) before take-off and reboot"
        ));
    }
    // What the SITL airframes held at their lean limits (10.3 m/s at 30 degrees for
    // ArduCopter's quad, 9.9 m/s at 45 for PX4 SIH): below 45 degrees a fast plan is
    // doubtful on most multicopters.
    if let Some(t) = tilt_deg.filter(|t| *t + 1e-6 < 45.0 && planned_mps > 10.0) {
        out.push(format!(
            "the vehicle's {tilt_name} allows {t:.0} degrees of lean: check that the airframe \
             holds agent.speed_limit_mps = {planned_mps:.1} m/s at that lean (ArduCopter's SITL \
             quad holds 10.3 m/s at 30 degrees)"
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vehicle_slower_than_planned_is_named_with_its_parameter_and_file() {
        let w = speed_warnings(Flavor::ArduPilot, Some(10.0), Some(30.0), 15.0);
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(w[0].contains("WPNAV_SPEED is 10.0 m/s") && w[0].contains("15.0"));
        assert!(w[0].contains("ardupilot-guided-tracking.parm"));
        assert!(w[1].contains("ANGLE_MAX allows 30 degrees"));
        assert!(w.iter().all(|x| !x.contains("  ")), "one line each: {w:?}");
        let w = speed_warnings(Flavor::Px4, Some(12.0), Some(45.0), 15.0);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("MPC_XY_VEL_MAX is 12.0 m/s"));
    }

    #[test]
    fn a_vehicle_set_up_as_shipped_gets_no_warning() {
        assert!(speed_warnings(Flavor::ArduPilot, Some(15.0), Some(45.0), 15.0).is_empty());
        assert!(speed_warnings(Flavor::Px4, Some(15.0), Some(45.0), 15.0).is_empty());
        // The lab: slow plans, any lean.
        assert!(speed_warnings(Flavor::ArduPilot, Some(10.0), Some(30.0), 1.0).is_empty());
        // Unreadable parameters: nothing guessed here (the reader says it could not read).
        assert!(speed_warnings(Flavor::Px4, None, None, 15.0).is_empty());
    }
}
