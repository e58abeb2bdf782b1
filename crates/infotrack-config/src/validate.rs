//! Range and consistency checks of a parsed [`Config`].

use std::collections::{BTreeMap, BTreeSet};

use super::{Config, ConfigError, RoadConfig};
use infotrack_core::world::geometry::{Enu2, PolygonEnu};

fn invalid(key: impl Into<String>, value: impl std::fmt::Debug, reason: &str) -> ConfigError {
    ConfigError::Invalid {
        key: key.into(),
        value: format!("{value:?}"),
        reason: reason.to_string(),
    }
}

fn positive(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(key, v, "must be a finite number greater than 0"))
    }
}

fn non_negative(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(key, v, "must be a finite number >= 0"))
    }
}

fn in_unit(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(invalid(key, v, "must lie in [0, 1]"))
    }
}

fn count(key: &str, v: usize) -> Result<(), ConfigError> {
    if v > 0 {
        Ok(())
    } else {
        Err(invalid(key, v, "must be at least 1"))
    }
}

/// A 2x2 covariance must be symmetric positive definite.
fn covariance(key: &str, m: &[[f64; 2]; 2]) -> Result<(), ConfigError> {
    let finite = m.iter().flatten().all(|v| v.is_finite());
    let symmetric = (m[0][1] - m[1][0]).abs() <= 1e-12 * (1.0 + m[0][1].abs());
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    if finite && symmetric && m[0][0] > 0.0 && det > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            key,
            m,
            "must be a symmetric positive-definite 2x2 matrix",
        ))
    }
}

pub(super) fn validate(c: &Config) -> Result<(), ConfigError> {
    validate_workspace(c)?;
    validate_road(c)?;
    validate_vision(c)?;
    validate_daemon(c)?;
    validate_acquisition(c)?;
    validate_world(c)?;
    validate_road_sigma(c)?;
    validate_start_gate(c)?;
    validate_occlusions(c)?;
    validate_target(c)?;
    validate_agent(c)?;
    validate_camera(c)?;
    validate_rates(c)?;
    validate_estimators(c)?;
    validate_guidance(c)?;
    validate_lawn(c)?;
    super::bounds::check(c)
}

/// Checks the workspace (geofence).
fn validate_workspace(c: &Config) -> Result<(), ConfigError> {
    let ws = &c.workspace_enu;
    for (k, v) in [
        ("workspace_enu.x_min_m", ws.x_min_m),
        ("workspace_enu.x_max_m", ws.x_max_m),
        ("workspace_enu.y_min_m", ws.y_min_m),
        ("workspace_enu.y_max_m", ws.y_max_m),
    ] {
        if !v.is_finite() {
            return Err(invalid(k, v, "must be finite"));
        }
    }
    if ws.x_max_m <= ws.x_min_m {
        return Err(invalid(
            "workspace_enu.x_max_m",
            ws.x_max_m,
            "must be greater than workspace_enu.x_min_m",
        ));
    }
    if ws.y_max_m <= ws.y_min_m {
        return Err(invalid(
            "workspace_enu.y_max_m",
            ws.y_max_m,
            "must be greater than workspace_enu.y_min_m",
        ));
    }
    Ok(())
}

/// Checks the occlusions.
fn validate_occlusions(c: &Config) -> Result<(), ConfigError> {
    let ws = &c.workspace_enu;
    for (i, occ) in c.occlusions.iter().enumerate() {
        let key = format!("occlusions[{i}].vertices_enu_m");
        let verts: Vec<Enu2> = occ
            .vertices_enu_m
            .iter()
            .map(|v| Enu2::new(v[0], v[1]))
            .collect();
        let poly = PolygonEnu::new(verts.clone()).ok_or_else(|| {
            invalid(
                &key,
                &occ.vertices_enu_m,
                "an occlusion needs at least three finite vertices",
            )
        })?;
        if let Some(v) = verts.iter().find(|v| !ws.contains(v)) {
            return Err(invalid(
                &key,
                [v.x, v.y],
                "vertex lies outside the workspace (workspace_enu)",
            ));
        }
        if poly.area_m2() <= 0.0 {
            return Err(invalid(&key, &occ.vertices_enu_m, "polygon has zero area"));
        }
    }
    Ok(())
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

/// Checks the camera and the footprint it has at the agent's altitude.
fn validate_camera(c: &Config) -> Result<(), ConfigError> {
    let ws = &c.workspace_enu;
    let a = &c.agent;
    let cam = &c.camera;
    for (k, v) in [
        ("camera.fov_x_rad", cam.fov_x_rad),
        ("camera.fov_y_rad", cam.fov_y_rad),
    ] {
        if !(v.is_finite() && v > 0.0 && v < std::f64::consts::PI) {
            return Err(invalid(k, v, "must lie in (0, pi) radians"));
        }
    }
    let fp_w = 2.0 * a.altitude_m * (0.5 * cam.fov_x_rad).tan();
    let fp_h = 2.0 * a.altitude_m * (0.5 * cam.fov_y_rad).tan();
    if fp_w >= ws.width_m() || fp_h >= ws.height_m() {
        return Err(invalid(
            "camera.fov_x_rad",
            cam.fov_x_rad,
            &format!(
                "camera footprint {fp_w:.2} m x {fp_h:.2} m at agent.altitude_m = {} is not smaller \
                 than the workspace {:.2} m x {:.2} m: there would be nothing to search",
                a.altitude_m,
                ws.width_m(),
                ws.height_m()
            ),
        ));
    }
    Ok(())
}

/// Checks the measurement noise and the loop rates.
fn validate_rates(c: &Config) -> Result<(), ConfigError> {
    covariance("measurement.noise_cov_m2", &c.measurement.noise_cov_m2)?;

    let tm = &c.timing;
    positive("timing.filter_hz", tm.filter_hz)?;
    positive("timing.guidance_hz", tm.guidance_hz)?;
    positive("timing.physics_hz", tm.physics_hz)?;
    positive("timing.duration_s", tm.duration_s)?;
    if tm.physics_hz < tm.filter_hz || tm.physics_hz < tm.guidance_hz {
        return Err(invalid(
            "timing.physics_hz",
            tm.physics_hz,
            "must be at least timing.filter_hz and timing.guidance_hz",
        ));
    }
    Ok(())
}

/// Checks the particle filter, the motion models and the Kalman filter.
fn validate_estimators(c: &Config) -> Result<(), ConfigError> {
    let f = &c.filter;
    count("filter.particles", f.particles)?;
    count("filter.history_len", f.history_len)?;
    if f.history_len < 2 {
        return Err(invalid(
            "filter.history_len",
            f.history_len,
            "must be at least 2 (a velocity needs two positions)",
        ));
    }
    covariance("filter.process_noise_cov_m2", &f.process_noise_cov_m2)?;
    in_unit("filter.resample_threshold", f.resample_threshold)?;
    in_unit("filter.reseed_threshold", f.reseed_threshold)?;
    if f.reseed_threshold > f.resample_threshold {
        return Err(invalid(
            "filter.reseed_threshold",
            f.reseed_threshold,
            "must not exceed filter.resample_threshold",
        ));
    }
    non_negative("filter.roughening", f.roughening)?;
    if !(f.miss_probability > 0.0 && f.miss_probability <= 1.0) {
        return Err(invalid(
            "filter.miss_probability",
            f.miss_probability,
            "must lie in (0, 1]",
        ));
    }
    in_unit("filter.max_outside_fraction", f.max_outside_fraction)?;

    positive("motion.cv_max_speed_mps", c.motion.cv_max_speed_mps)?;

    for (i, v) in c.kalman.process_noise_diag.iter().enumerate() {
        positive(&format!("kalman.process_noise_diag[{i}]"), *v)?;
    }
    for (i, v) in c.kalman.initial_cov_diag.iter().enumerate() {
        positive(&format!("kalman.initial_cov_diag[{i}]"), *v)?;
    }
    Ok(())
}

/// Checks the guidance laws.
fn validate_guidance(c: &Config) -> Result<(), ConfigError> {
    let g = &c.guidance;
    count("guidance.entropy_particles", g.entropy_particles)?;
    if let Some(n) = g.entropy_particles_concentrated {
        count("guidance.entropy_particles_concentrated", n)?;
    }
    count(
        "guidance.measurements_per_particle",
        g.measurements_per_particle,
    )?;
    count("guidance.horizon_steps", g.horizon_steps)?;
    count("guidance.candidate_grid_side", g.candidate_grid_side)?;
    covariance("guidance.entropy_kernel_cov_m2", &g.entropy_kernel_cov_m2)?;
    if let Some(t) = g.intercept_within_s {
        positive("guidance.intercept_within_s", t)?;
    }
    for (key, share) in [
        ("guidance.search_commitment", g.search_commitment),
        ("guidance.centring_share", g.centring_share),
    ] {
        if let Some(share) = share.filter(|s| !(0.0..=1.0).contains(s)) {
            return Err(invalid(
                key,
                share,
                "must be a share of the EER range, from 0 to 1",
            ));
        }
    }
    if let Some(t) = g.ambush_window_s {
        non_negative("guidance.ambush_window_s", t)?;
    }
    if let Some(floor) = g.search_escape_floor {
        in_unit("guidance.search_escape_floor", floor)?;
    }
    Ok(())
}

/// Checks the lawnmower sweep.
fn validate_lawn(c: &Config) -> Result<(), ConfigError> {
    let ws = &c.workspace_enu;
    let g = &c.guidance;
    let l = &g.lawn;
    if l.legs_x_m.is_empty() {
        return Err(invalid(
            "guidance.lawn.legs_x_m",
            &l.legs_x_m,
            "needs at least one leg",
        ));
    }
    if let Some(x) = l
        .legs_x_m
        .iter()
        .find(|x| !x.is_finite() || **x < ws.x_min_m || **x > ws.x_max_m)
    {
        return Err(invalid(
            "guidance.lawn.legs_x_m",
            x,
            "leg lies outside the workspace",
        ));
    }
    if !(l.y_min_m < l.y_max_m && l.y_min_m >= ws.y_min_m && l.y_max_m <= ws.y_max_m) {
        return Err(invalid(
            "guidance.lawn.y_max_m",
            [l.y_min_m, l.y_max_m],
            "need y_min_m < y_max_m, both inside the workspace",
        ));
    }
    positive("guidance.lawn.point_spacing_m", l.point_spacing_m)?;
    non_negative(
        "guidance.lawn.track_measurement_for_s",
        l.track_measurement_for_s,
    )?;
    Ok(())
}

// Long because each road-graph rule (ids, edges, probabilities, reachability) is checked
// in order with its own message naming the key.
fn validate_road(c: &Config) -> Result<(), ConfigError> {
    let ws = &c.workspace_enu;
    let road = &c.road;
    if road.nodes.is_empty() {
        return Err(invalid("road.nodes", "[]", "needs at least one node"));
    }
    let mut ids = BTreeSet::new();
    for (i, n) in road.nodes.iter().enumerate() {
        if !ids.insert(n.id) {
            return Err(invalid(
                format!("road.nodes[{i}].id"),
                n.id,
                "duplicate node id",
            ));
        }
        let p = Enu2::new(n.x_m, n.y_m);
        if !(n.x_m.is_finite() && n.y_m.is_finite() && ws.contains(&p)) {
            return Err(invalid(
                format!("road.nodes[{i}]"),
                [n.x_m, n.y_m],
                "node must be finite and inside the workspace",
            ));
        }
    }
    let mut out_sum: BTreeMap<u32, f64> = BTreeMap::new();
    for (i, e) in road.edges.iter().enumerate() {
        if !ids.contains(&e.from) {
            return Err(invalid(
                format!("road.edges[{i}].from"),
                e.from,
                "edge leaves a node that does not exist",
            ));
        }
        if !ids.contains(&e.to) {
            return Err(invalid(
                format!("road.edges[{i}].to"),
                e.to,
                "edge enters a node that does not exist",
            ));
        }
        if e.from == e.to {
            return Err(invalid(
                format!("road.edges[{i}].to"),
                e.to,
                "self-loop edge",
            ));
        }
        if !(e.p.is_finite() && e.p > 0.0 && e.p <= 1.0) {
            return Err(invalid(
                format!("road.edges[{i}].p"),
                e.p,
                "must lie in (0, 1]",
            ));
        }
        *out_sum.entry(e.from).or_default() += e.p;
    }
    for (node, sum) in &out_sum {
        if (sum - 1.0).abs() > 1e-6 {
            return Err(invalid(
                format!("road.edges (from = {node})"),
                sum,
                "transition probabilities leaving this node must sum to 1",
            ));
        }
    }
    if !ids.contains(&road.start_node) {
        return Err(invalid("road.start_node", road.start_node, "no such node"));
    }
    every_reachable_node_has_a_way_out(road, &out_sum)
}

/// Every node the target can reach from the start must have a way out, or it would stop
/// for ever. `out_sum`: each node with an outgoing edge.
fn every_reachable_node_has_a_way_out(
    road: &RoadConfig,
    out_sum: &BTreeMap<u32, f64>,
) -> Result<(), ConfigError> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![road.start_node];
    while let Some(n) = stack.pop() {
        if !seen.insert(n) {
            continue;
        }
        if !out_sum.contains_key(&n) {
            return Err(invalid(
                "road.edges",
                n,
                "node is reachable from road.start_node but has no outgoing edge",
            ));
        }
        stack.extend(road.edges.iter().filter(|e| e.from == n).map(|e| e.to));
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
        infotrack_vision::capture::CaptureSource::parse(&d.camera)
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
    positive("daemon.start_settle_s", c.daemon.start_settle_s)
}

fn validate_road_sigma(c: &Config) -> Result<(), ConfigError> {
    in_unit("filter.hypothesis_injection", c.filter.hypothesis_injection)?;
    match c.filter.road_sigma_m {
        Some(s) => non_negative("filter.road_sigma_m", s),
        None => Ok(()),
    }
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
    positive("world.origin_tolerance_m", w.origin_tolerance_m)
}

fn validate_acquisition(c: &Config) -> Result<(), ConfigError> {
    let Some(a) = &c.acquisition else {
        return Ok(());
    };
    positive("acquisition.cue_radius_m", a.cue_radius_m)?;
    if let Some(v) = a.min_speed_mps {
        let v_max = c.motion.cv_max_speed_mps;
        if !(v.is_finite() && (0.0..=v_max).contains(&v)) {
            return Err(invalid(
                "acquisition.min_speed_mps",
                v,
                &format!("must lie in [0, motion.cv_max_speed_mps = {v_max}] m/s"),
            ));
        }
    }
    let cue = Enu2::new(a.cue_enu_m[0], a.cue_enu_m[1]);
    if !(cue.x.is_finite() && cue.y.is_finite() && c.workspace_enu.contains(&cue)) {
        return Err(invalid(
            "acquisition.cue_enu_m",
            a.cue_enu_m,
            &format!(
                "must lie inside the workspace (workspace_enu: x {}..{}, y {}..{})",
                c.workspace_enu.x_min_m,
                c.workspace_enu.x_max_m,
                c.workspace_enu.y_min_m,
                c.workspace_enu.y_max_m
            ),
        ));
    }
    let road = c.road_network();
    if road.length_within(Some((cue, a.cue_radius_m))) <= 0.0 {
        return Err(invalid(
            "acquisition.cue_enu_m",
            a.cue_enu_m,
            &format!(
                "no road lies within acquisition.cue_radius_m = {} m of the cue: the target \
                 drives on the roads, so the cue must be near one",
                a.cue_radius_m
            ),
        ));
    }
    Ok(())
}
