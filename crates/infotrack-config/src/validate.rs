//! Range and consistency checks of a parsed [`Config`]: each core component checks its own
//! table (`check` beside it in `infotrack-core`); the application's tables are checked here.
//! The order decides which mistake a config with several reports first.

use super::{Config, ConfigError};
use infotrack_core::check::{non_negative, positive};
use infotrack_core::world::geometry::Enu2;

fn invalid(key: impl Into<String>, value: impl std::fmt::Debug, reason: &str) -> ConfigError {
    infotrack_core::check::invalid(key, value, reason).into()
}

pub(super) fn validate(c: &Config) -> Result<(), ConfigError> {
    c.workspace_enu.check_workspace()?;
    c.road.check(&c.workspace_enu)?;
    validate_vision(c)?;
    validate_daemon(c)?;
    validate_acquisition(c)?;
    validate_world(c)?;
    c.filter.check_road_terms()?;
    validate_start_gate(c)?;
    for (i, occlusion) in c.occlusions.iter().enumerate() {
        occlusion.check(i, &c.workspace_enu)?;
    }
    validate_target(c)?;
    validate_agent(c)?;
    c.camera.check(&c.workspace_enu, c.agent.altitude_m)?;
    c.measurement.check()?;
    c.timing.check()?;
    c.filter.check()?;
    c.motion.check()?;
    c.kalman.check()?;
    c.guidance.check()?;
    c.guidance.lawn.check(&c.workspace_enu)?;
    super::bounds::check(c)
}

/// Checks the simulated target.
fn validate_target(c: &Config) -> Result<(), ConfigError> {
    let t = &c.target;
    positive("target.cruise_speed_mps", t.cruise_speed_mps)?;
    positive("target.max_speed_mps", t.max_speed_mps)?;
    positive("target.max_yaw_rate_radps", t.max_yaw_rate_radps)?;
    positive("target.heading_gain_per_s", t.heading_gain_per_s)?;
    positive("target.goal_switch_radius_m", t.goal_switch_radius_m)?;
    if !(t.turn_in_place_above_rad > 0.0 && t.turn_in_place_above_rad <= std::f64::consts::PI) {
        return Err(invalid(
            "target.turn_in_place_above_rad",
            t.turn_in_place_above_rad,
            "must lie in (0, pi]",
        ));
    }
    Ok(())
}

/// Checks the simulated agent.
fn validate_agent(c: &Config) -> Result<(), ConfigError> {
    let ws = &c.workspace_enu;
    let a = &c.agent;
    positive("agent.altitude_m", a.altitude_m)?;
    positive("agent.gain_per_s", a.gain_per_s)?;
    positive("agent.speed_limit_mps", a.speed_limit_mps)?;
    positive("agent.accel_limit_mps2", a.accel_limit_mps2)?;
    non_negative("agent.dead_zone_m", a.dead_zone_m)?;
    if let Some(rate) = a.yaw_rate_limit_rad_s {
        positive("agent.yaw_rate_limit_rad_s", rate)?;
    }
    let start = Enu2::new(a.start_enu_m[0], a.start_enu_m[1]);
    if !ws.contains(&start) {
        return Err(invalid(
            "agent.start_enu_m",
            a.start_enu_m,
            "must lie inside the workspace (the geofence)",
        ));
    }
    Ok(())
}

fn validate_vision(c: &Config) -> Result<(), ConfigError> {
    let v = &c.vision;
    if !(64..=4096).contains(&v.image_width_px) {
        return Err(invalid(
            "vision.image_width_px",
            v.image_width_px,
            "must be 64-4096",
        ));
    }
    if v.tag_id >= infotrack_vision::tag_family::TAG36H11_CODES {
        return Err(invalid(
            "vision.tag_id",
            v.tag_id,
            "not a tag36h11 id (0-586)",
        ));
    }
    positive("vision.tag_size_m", v.tag_size_m)?;
    if !(1..=8).contains(&v.supersample) {
        return Err(invalid("vision.supersample", v.supersample, "must be 1-8"));
    }
    for (k, x) in [
        ("vision.noise_sigma", v.noise_sigma),
        ("vision.blur_sigma_px", v.blur_sigma_px),
    ] {
        if !(x.is_finite() && x >= 0.0) {
            return Err(invalid(k, x, "must be finite and >= 0"));
        }
    }
    v.detector
        .validate()
        .map_err(|e| invalid("vision.detector", &v.detector, &e.0))?;
    v.projection
        .validate()
        .map_err(|e| invalid("vision.projection", &v.projection, &e.0))?;
    Ok(())
}

fn validate_daemon(c: &Config) -> Result<(), ConfigError> {
    let d = &c.daemon;
    match d.vehicle.as_str() {
        "mock:px4" | "mock:ardupilot" => {}
        url if url.starts_with("file:") => return Err(invalid(
            "daemon.vehicle",
            url,
            "a telemetry log is read, not flown: give the vehicle's link (udpin:..., serial:...)",
        )),
        url => infotrack_link::link::check_url(url).map_err(|e| {
            invalid(
                "daemon.vehicle",
                url,
                &format!("not mock:px4, mock:ardupilot or a MAVLink URL: {e}"),
            )
        })?,
    }
    if d.camera != "synthetic" {
        infotrack_vision::capture_source::CaptureSource::parse(&d.camera)
            .map_err(|e| invalid("daemon.camera", &d.camera, &e.to_string()))?;
        if d.calibration.is_none() {
            return Err(invalid(
                "daemon.calibration",
                "none",
                "a real camera needs its OpenCV calibration file",
            ));
        }
    }
    for (k, v) in d
        .camera_mount_rpy_rad
        .iter()
        .chain(&d.camera_offset_body_frd_m)
        .enumerate()
    {
        if !v.is_finite() {
            return Err(invalid(
                if k < 3 {
                    "daemon.camera_mount_rpy_rad"
                } else {
                    "daemon.camera_offset_body_frd_m"
                },
                v,
                "must be finite",
            ));
        }
    }
    if !infotrack_core::motion::MODEL_NAMES.contains(&d.motion.as_str()) {
        return Err(invalid(
            "daemon.motion",
            &d.motion,
            &format!("must be one of {:?}", infotrack_core::motion::MODEL_NAMES),
        ));
    }
    if !(d.camera_fps.is_finite() && d.camera_fps >= 0.0) {
        return Err(invalid("daemon.camera_fps", d.camera_fps, "must be >= 0"));
    }
    if !(d.setpoint_hz.is_finite() && (10.0..=100.0).contains(&d.setpoint_hz)) {
        return Err(invalid(
            "daemon.setpoint_hz",
            d.setpoint_hz,
            "must be 10-100 Hz",
        ));
    }
    positive("daemon.connect_timeout_s", d.connect_timeout_s)?;
    positive("daemon.takeoff_timeout_s", d.takeoff_timeout_s)?;
    positive("daemon.target_lost_after_s", d.target_lost_after_s)?;
    positive("daemon.guidance_budget_ms", d.guidance_budget_ms)?;
    positive("daemon.camera_timeout_s", d.camera_timeout_s)?;
    if !["eer", "lawn", "hold"].contains(&d.target_lost_fallback.as_str()) {
        return Err(invalid(
            "daemon.target_lost_fallback",
            &d.target_lost_fallback,
            "must be eer, lawn or hold",
        ));
    }
    Ok(())
}

fn validate_start_gate(c: &Config) -> Result<(), ConfigError> {
    if let Some(t) = c.daemon.start_tolerance_m {
        positive("daemon.start_tolerance_m", t)?;
    }
    Ok(positive("daemon.start_settle_s", c.daemon.start_settle_s)?)
}

fn validate_world(c: &Config) -> Result<(), ConfigError> {
    let Some(w) = &c.world else {
        return Ok(());
    };
    let o = &w.origin;
    if !(o.lat_deg.is_finite() && (-90.0..=90.0).contains(&o.lat_deg)) {
        return Err(invalid(
            "world.origin.lat_deg",
            o.lat_deg,
            "must be -90..90 degrees",
        ));
    }
    if !(o.lon_deg.is_finite() && (-180.0..=180.0).contains(&o.lon_deg)) {
        return Err(invalid(
            "world.origin.lon_deg",
            o.lon_deg,
            "must be -180..180 degrees",
        ));
    }
    if !(o.alt_m.is_finite() && (-1000.0..=10_000.0).contains(&o.alt_m)) {
        return Err(invalid(
            "world.origin.alt_m",
            o.alt_m,
            "must be -1000..10000 m (height above the WGS84 ellipsoid)",
        ));
    }
    Ok(positive("world.origin_tolerance_m", w.origin_tolerance_m)?)
}

/// The core checks the cue; a cue may be left out only where recorded tracks give it.
fn validate_acquisition(c: &Config) -> Result<(), ConfigError> {
    let Some(a) = &c.acquisition else {
        return Ok(());
    };
    let roads = c.road_network();
    a.check(&c.workspace_enu, c.motion.cv_max_speed_mps, &roads)?;
    if a.cue_enu_m.is_none() && c.target.trajectory.is_none() {
        return Err(invalid(
            "acquisition.cue_enu_m",
            "(absent)",
            "needed unless target.trajectory gives recorded tracks, whose starts cue each run",
        ));
    }
    Ok(())
}
