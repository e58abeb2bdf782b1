//! Upper bounds on every size and rate a config sets, checked at load so that a config that
//! loads cannot exhaust the memory of the smallest supported companion computer (2 GiB) or
//! make a loop that never finishes. Each bound is far above what any scenario shipped uses
//! (the largest: 1,000 particles, K_in 10, a 16 x 16 candidate grid, 30 Hz physics) and far
//! below what would allocate gigabytes.

use super::{Config, ConfigError};

/// Particles in the filter (the paper: 500; field worlds: 1,000).
pub const MAX_PARTICLES: usize = 200_000;
/// Positions of history per particle (K_in; the paper: 10).
pub const MAX_HISTORY_LEN: usize = 256;
/// Particles x history: the histories' f64 pairs, 16 B each (64 MB at the bound).
pub const MAX_PARTICLE_HISTORY: usize = 4_000_000;
/// Candidate waypoints per side of the EER grid (the bound squared is evaluated per cycle).
pub const MAX_CANDIDATE_GRID_SIDE: usize = 64;
/// Particles in the EER's entropy estimate (N_H; pairwise kernels cost N_H^2).
pub const MAX_ENTROPY_PARTICLES: usize = 5_000;
/// Simulated measurements per entropy particle.
pub const MAX_MEASUREMENTS_PER_PARTICLE: usize = 64;
/// EER horizon, filter steps.
pub const MAX_HORIZON_STEPS: usize = 64;
/// EER's work per plan: candidates (grid side squared) x entropy particles x measurements
/// per particle x horizon steps. The field configs plan 256 x 1,000 x 1 x 6 = 1.5e6 in ~10 ms;
/// each key within its own bound could multiply to 8e10, hours per plan.
pub const MAX_EER_WORK: f64 = 1e8;
/// Points of the lawnmower sweep (legs and turns over the point spacing).
pub const MAX_SWEEP_POINTS: f64 = 1e6;
/// Physics rate, Hz.
pub const MAX_PHYSICS_HZ: f64 = 1_000.0;
/// Filter and guidance rates, Hz.
pub const MAX_LOOP_HZ: f64 = 100.0;
/// One run or flight, s (a day).
pub const MAX_DURATION_S: f64 = 86_400.0;
/// Physics ticks in one run (duration x physics rate).
pub const MAX_TICKS: f64 = 20_000_000.0;
/// Any timeout or wait the daemon is given, s.
pub const MAX_WAIT_S: f64 = 3_600.0;

fn too_large(key: &str, value: impl std::fmt::Debug, bound: impl std::fmt::Display) -> ConfigError {
    ConfigError::Invalid {
        key: key.to_string(),
        value: format!("{value:?}"),
        reason: format!(
            "must be at most {bound} (a bound that keeps a loaded config within a 2 GiB companion)"
        ),
    }
}

fn at_most_usize(key: &str, v: usize, bound: usize) -> Result<(), ConfigError> {
    if v <= bound {
        Ok(())
    } else {
        Err(too_large(key, v, bound))
    }
}

fn at_most(key: &str, v: f64, bound: f64) -> Result<(), ConfigError> {
    // NaN is refused by the range checks that run before.
    if v <= bound {
        Ok(())
    } else {
        Err(too_large(key, v, bound))
    }
}

/// Checks every bound; the ranges below them (positive, finite, ...) are checked by
/// `validate` first.
pub(super) fn check(c: &Config) -> Result<(), ConfigError> {
    check_filter(&c.filter)?;
    check_guidance(c)?;
    let t = &c.timing;
    at_most("timing.physics_hz", t.physics_hz, MAX_PHYSICS_HZ)?;
    at_most("timing.filter_hz", t.filter_hz, MAX_LOOP_HZ)?;
    at_most("timing.guidance_hz", t.guidance_hz, MAX_LOOP_HZ)?;
    check_duration("timing.duration_s", t.duration_s, t.physics_hz)?;
    check_daemon(&c.daemon)
}

/// The particle filter's sizes.
fn check_filter(f: &super::FilterConfig) -> Result<(), ConfigError> {
    at_most_usize("filter.particles", f.particles, MAX_PARTICLES)?;
    at_most_usize("filter.history_len", f.history_len, MAX_HISTORY_LEN)?;
    at_most_usize(
        "filter.particles",
        f.particles.saturating_mul(f.history_len),
        MAX_PARTICLE_HISTORY,
    )
    .map_err(|_| {
        too_large(
            "filter.particles",
            f.particles,
            format!(
                "{} with filter.history_len = {} (particles x history <= {MAX_PARTICLE_HISTORY})",
                MAX_PARTICLE_HISTORY / f.history_len.max(1),
                f.history_len
            ),
        )
    })?;
    Ok(())
}

/// The guidance laws' sizes, each and together.
fn check_guidance(c: &Config) -> Result<(), ConfigError> {
    let g = &c.guidance;
    at_most_usize(
        "guidance.candidate_grid_side",
        g.candidate_grid_side,
        MAX_CANDIDATE_GRID_SIDE,
    )?;
    at_most_usize(
        "guidance.entropy_particles",
        g.entropy_particles,
        MAX_ENTROPY_PARTICLES,
    )?;
    if let Some(n) = g.entropy_particles_concentrated {
        at_most_usize(
            "guidance.entropy_particles_concentrated",
            n,
            MAX_ENTROPY_PARTICLES,
        )?;
    }
    at_most_usize(
        "guidance.measurements_per_particle",
        g.measurements_per_particle,
        MAX_MEASUREMENTS_PER_PARTICLE,
    )?;
    at_most_usize("guidance.horizon_steps", g.horizon_steps, MAX_HORIZON_STEPS)?;
    check_eer_work(c)?;
    check_sweep_points(&g.lawn)?;
    Ok(())
}

/// The daemon's waits and MAVLink ids.
fn check_daemon(d: &super::DaemonConfig) -> Result<(), ConfigError> {
    for (k, v) in [
        ("daemon.connect_timeout_s", d.connect_timeout_s),
        ("daemon.takeoff_timeout_s", d.takeoff_timeout_s),
        ("daemon.target_lost_after_s", d.target_lost_after_s),
        ("daemon.camera_timeout_s", d.camera_timeout_s),
        ("daemon.start_settle_s", d.start_settle_s),
    ] {
        at_most(k, v, MAX_WAIT_S)?;
    }
    at_most(
        "daemon.guidance_budget_ms",
        d.guidance_budget_ms,
        1e3 * MAX_WAIT_S,
    )?;
    if d.system_id == 0 {
        return Err(ConfigError::Invalid {
            key: "daemon.system_id".into(),
            value: "0".into(),
            reason: "0 is MAVLink's broadcast id; use 1-255 (the vehicle's is usually 1, a companion's too)".into(),
        });
    }
    if d.vehicle_id.is_some_and(|[s, c]| s == 0 || c == 0) {
        return Err(ConfigError::Invalid {
            key: "daemon.vehicle_id".into(),
            value: format!("{:?}", d.vehicle_id.unwrap_or_default()),
            reason: "0 is MAVLink's broadcast id; give the vehicle's own [system, component] (an autopilot is usually [1, 1])".into(),
        });
    }
    if d.component_id == 0 {
        return Err(ConfigError::Invalid {
            key: "daemon.component_id".into(),
            value: "0".into(),
            reason: "0 is MAVLink's broadcast id; use 1-255 (191: onboard computer)".into(),
        });
    }
    Ok(())
}

/// EER's sizes together, not only each on its own: see [`MAX_EER_WORK`].
fn check_eer_work(c: &Config) -> Result<(), ConfigError> {
    let g = &c.guidance;
    let particles = g
        .entropy_particles
        .max(g.entropy_particles_concentrated.unwrap_or(0));
    let work = (g.candidate_grid_side as f64).powi(2)
        * particles as f64
        * g.measurements_per_particle as f64
        * g.horizon_steps as f64;
    if work > MAX_EER_WORK {
        return Err(too_large(
            "guidance.entropy_particles",
            particles,
            format!(
                "{MAX_EER_WORK:e} for candidate_grid_side^2 x entropy_particles x \
                 measurements_per_particle x horizon_steps together \
                 ({}^2 x {particles} x {} x {} = {work:e}: one plan would take minutes to hours)",
                g.candidate_grid_side, g.measurements_per_particle, g.horizon_steps
            ),
        ));
    }
    Ok(())
}

/// The sweep's point count from its legs and spacing: see [`MAX_SWEEP_POINTS`].
fn check_sweep_points(l: &infotrack_core::guidance::lawn::LawnConfig) -> Result<(), ConfigError> {
    let leg_m = (l.y_max_m - l.y_min_m).abs();
    let turns_m: f64 = l
        .legs_x_m
        .windows(2)
        .map(|w| 0.5 * std::f64::consts::PI * (w[1] - w[0]).abs())
        .sum();
    let points = (leg_m * l.legs_x_m.len() as f64 + turns_m) / l.point_spacing_m;
    // NaN (a spacing of NaN is refused by validate first) counts as too many.
    if points.is_nan() || points > MAX_SWEEP_POINTS {
        return Err(too_large(
            "guidance.lawn.point_spacing_m",
            l.point_spacing_m,
            format!(
                "{MAX_SWEEP_POINTS:e} sweep points: at least {:.3e} m for these legs",
                (leg_m * l.legs_x_m.len() as f64 + turns_m) / MAX_SWEEP_POINTS
            ),
        ));
    }
    Ok(())
}

/// A run's length, from the config or a command line's `--duration` (named by `key`): at
/// most a day and at most [`MAX_TICKS`] physics ticks.
pub fn check_duration(key: &str, duration_s: f64, physics_hz: f64) -> Result<(), ConfigError> {
    at_most(key, duration_s, MAX_DURATION_S)?;
    if duration_s * physics_hz > MAX_TICKS {
        return Err(too_large(
            key,
            duration_s,
            format!(
                "{:.0} s at timing.physics_hz = {physics_hz} ({MAX_TICKS:.0} physics ticks)",
                MAX_TICKS / physics_hz
            ),
        ));
    }
    Ok(())
}
