//! Training data for a learned motion model: the simulated target observed at the filter
//! rate with measurement noise, as if a camera saw it at every step. The records have the
//! same CSV format as the per-step flight logs, so a model can be trained the same way on
//! real flights.

use crate::simulated::TargetSim;
use infotrack_config::Config;
use infotrack_core::metrics::StepRecord;
use infotrack_core::rng::{stream_rng, CoreRng, Stream};

/// Records `duration_s` of target motion, one noisy position per filter period.
pub fn record(cfg: &Config, seed: u64, duration_s: f64) -> Vec<StepRecord> {
    let world = cfg.world();
    let mut rng_target: CoreRng = stream_rng(seed, u64::MAX, Stream::Tools, 1);
    let mut rng_meas: CoreRng = stream_rng(seed, u64::MAX, Stream::Tools, 2);
    let mut target = TargetSim::new(&world.road, cfg.target.clone(), &mut rng_target);
    let dt_phys = 1.0 / cfg.timing.physics_hz;
    let n_phys = (duration_s * cfg.timing.physics_hz).round() as u64;
    let r = world.measurement.noise.cov;
    let mut next_filter = 1u64;
    let mut out = Vec::with_capacity((duration_s * cfg.timing.filter_hz) as usize + 1);
    for tick in 1..=n_phys {
        let t = tick as f64 * dt_phys;
        target.step(&world.road, dt_phys, &mut rng_target);
        if t + 1e-9 >= next_filter as f64 / cfg.timing.filter_hz {
            next_filter += 1;
            let x = target.position_enu;
            let z = world.measurement.measure(&x, &mut rng_meas);
            out.push(StepRecord {
                t_s: t,
                target_enu: x,
                agent_enu: x,
                waypoint_enu: x,
                measurement_enu: Some(z),
                estimate_enu: z,
                cov_m2: r,
                n_eff: f64::NAN,
                eer: f64::NAN,
                target_occluded: false,
                target_in_footprint: true,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_one_noisy_position_per_filter_period() {
        let c = Config::default_lab();
        let a = record(&c, 1, 60.0);
        assert_eq!(a.len(), 180);
        let b = record(&c, 1, 60.0);
        assert_eq!(
            a.last().unwrap().measurement_enu,
            b.last().unwrap().measurement_enu
        );
        let err: f64 = a
            .iter()
            .map(|s| (s.measurement_enu.unwrap() - s.target_enu).norm_squared())
            .sum::<f64>()
            / a.len() as f64;
        // E|n|^2 = trace(R) = 0.02 m^2.
        assert!((err - 0.02).abs() < 0.007, "{err}");
    }
}
