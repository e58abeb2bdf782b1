//! A bounded property test over config values: any number (NaN, infinities, negatives,
//! zero, tiny and huge values) written into any of the lab's size, rate, timeout and
//! geometry keys either loads, and then every derived size is within its bound, or is
//! refused with an error naming that key (or, for a workspace edge, what no longer fits in
//! the workspace). Loading never panics.

mod common;

use std::path::Path;

use infotrack::config::bounds::{MAX_EER_WORK, MAX_PARTICLES, MAX_SWEEP_POINTS};
use infotrack::config::{Config, DEFAULT_TOML};
use proptest::prelude::*;

/// Keys whose values size or time something, dotted.
const KEYS: &[&str] = &[
    "filter.particles",
    "filter.history_len",
    "guidance.entropy_particles",
    "guidance.measurements_per_particle",
    "guidance.horizon_steps",
    "guidance.candidate_grid_side",
    "guidance.lawn.point_spacing_m",
    "guidance.lawn.y_min_m",
    "timing.physics_hz",
    "timing.filter_hz",
    "timing.guidance_hz",
    "timing.duration_s",
    "agent.speed_limit_mps",
    "agent.accel_limit_mps2",
    "agent.altitude_m",
    "daemon.setpoint_hz",
    "daemon.connect_timeout_s",
    "daemon.guidance_budget_ms",
    "workspace_enu.x_max_m",
    "camera.fov_x_rad",
];

/// A float from every corner: specials, signs, tiny and huge magnitudes, plain values.
fn any_number() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(-0.0),
        Just(1e-300),
        Just(1e300),
        (-30i32..30).prop_map(|e| 10f64.powi(e)),
        (-30i32..30).prop_map(|e| -(10f64.powi(e))),
        -1e4..1e4f64,
    ]
}

/// The lab config with `key` set to `value` (as an integer when it is one and the key
/// takes integers, else as a float).
fn lab_with(key: &str, value: f64) -> String {
    let mut table: toml::Table = DEFAULT_TOML.parse().unwrap();
    let (t, last) = common::table_for(&mut table, key);
    let literal = match t.get(last) {
        Some(toml::Value::Integer(_)) if value.fract() == 0.0 && value.abs() < 9e18 => {
            toml::Value::Integer(value as i64)
        }
        _ => toml::Value::Float(value),
    };
    t.insert(last.to_string(), literal);
    toml::to_string(&table).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn any_value_loads_within_bounds_or_is_refused_naming_its_key(
        k in 0..KEYS.len(),
        value in any_number(),
    ) {
        let key = KEYS[k];
        let text = lab_with(key, value);
        let loaded = std::panic::catch_unwind(|| Config::from_toml_str(&text, Path::new("p.toml")));
        let loaded = loaded.map_err(|_| TestCaseError::fail(format!("{key} = {value}: panicked")))?;
        match loaded {
            Ok(c) => {
                let g = &c.guidance;
                let work = (g.candidate_grid_side as f64).powi(2)
                    * g.entropy_particles as f64
                    * g.measurements_per_particle as f64
                    * g.horizon_steps as f64;
                prop_assert!(work <= MAX_EER_WORK, "{key} = {value}: EER work {work}");
                prop_assert!(c.filter.particles <= MAX_PARTICLES);
                let l = &g.lawn;
                let points = (l.y_max_m - l.y_min_m).abs() * l.legs_x_m.len() as f64 / l.point_spacing_m;
                prop_assert!(points <= MAX_SWEEP_POINTS, "{key} = {value}: {points} sweep points");
                prop_assert!(c.timing.physics_hz.is_finite() && c.timing.physics_hz > 0.0);
            }
            Err(e) => {
                let said = e.to_string();
                // The key itself, or (a workspace edge) what no longer fits inside it.
                let name = key.rsplit('.').next().unwrap();
                let section = key.split(['.', '_']).next().unwrap();
                prop_assert!(said.contains(name) || said.contains(section), "{key} = {value}: {said}");
            }
        }
    }
}
