//! The search from a cue values the hypotheses that escape. Before the first sighting
//! EER's 2 s horizon scores a candidate by the belief it would see, wherever that belief is
//! going; over a cue's belief, spread both ways along the roads, the densest views were
//! hypotheses coming toward the drone or about to (a road into the cue's junction, whose
//! hypotheses all turn onto the road the car took), and the drone swept them while the
//! hypotheses driving away, the car among them, ran out of reach (random-14: one road out of
//! the cue, the car found after 60-205 s in 9 runs of 10). A hypothesis coming toward the
//! drone can be looked at later at no cost; one driving away can be caught only now. So,
//! while the target has never been seen and the search starts from a cue, each
//! hypothesis's weight in EER is multiplied by `floor + (1 - floor) x` its speed away from
//! the agent over the fastest's (the predicted velocity's component along the line from the
//! agent, 0 when it comes closer), and renormalised: the plan looks first where the
//! escaping belief is. The filter's belief is untouched (only EER's copy of the weights);
//! the expectation weights alpha move with them. A departure from the paper's eq. 13-14,
//! documented; `guidance.search_escape_floor = 1` restores them. BENCHMARKS.md.

use super::EerInputs;
use crate::world::geometry::Enu2;

/// `guidance.search_escape_floor` when a config leaves it out: the weight a hypothesis that
/// is not driving away gets, relative to one driving away at the fastest speed. At
/// 0.3 rather than 0.1 (BENCHMARKS.md) the plan chases the
/// belief's fastest front less (field-hill's drone had flown past the car 22 m to its side
/// after hypotheses 5 m/s faster), and the stand-ins and the random worlds both gain.
pub const DEFAULT_SEARCH_ESCAPE_FLOOR: f64 = 0.3;

/// Each hypothesis's weight in EER's copy of the belief times `floor + (1 - floor) x` its
/// speed away from `agent_enu` over the fastest predicted speed, the weights and the
/// expectation weights (`alpha`, `n_m` per hypothesis) renormalised. Nothing changes when
/// `floor >= 1`, when no hypothesis moves, or when every factor would vanish.
pub fn weigh_by_escape(inputs: &mut EerInputs, agent_enu: &Enu2, floor: f64) {
    if floor >= 1.0 || inputs.weights.is_empty() {
        return;
    }
    let fastest = inputs.velocity.iter().map(|v| v.norm()).fold(0.0, f64::max);
    if fastest <= 0.0 || !fastest.is_finite() {
        return;
    }
    let floor = floor.max(0.0);
    let factors: Vec<f64> = inputs
        .predicted
        .iter()
        .zip(&inputs.velocity)
        .map(|(p, v)| floor + (1.0 - floor) * speed_away_mps(agent_enu, p, v) / fastest)
        .collect();
    let total: f64 = inputs
        .weights
        .iter()
        .zip(&factors)
        .map(|(w, f)| w * f)
        .sum();
    if total <= 0.0 || !total.is_finite() {
        return;
    }
    for (w, f) in inputs.weights.iter_mut().zip(&factors) {
        *w *= f / total;
    }
    // alpha_jm is proportional to w_j times a likelihood, so it takes the same factor, but
    // its own sum (not the weights') renormalises it: eq. 13's expectation needs it to sum
    // to 1 (the evaluation weighs the missed detection by 1 - the alpha in view).
    let n_m = inputs.n_m.max(1);
    for (j, a) in inputs.alpha.iter_mut().enumerate() {
        *a *= factors[j / n_m];
    }
    let alpha_total: f64 = inputs.alpha.iter().sum();
    if alpha_total > 0.0 && alpha_total.is_finite() {
        inputs.alpha.iter_mut().for_each(|a| *a /= alpha_total);
    }
}

/// How fast a hypothesis at `at_enu` moving at `velocity_enu` gets farther from `agent_enu`,
/// m/s: its velocity along the line from the agent, 0 when it comes closer or is there.
pub fn speed_away_mps(agent_enu: &Enu2, at_enu: &Enu2, velocity_enu: &Enu2) -> f64 {
    let r = at_enu - agent_enu;
    let d = r.norm();
    if d <= 1e-9 {
        return 0.0;
    }
    (velocity_enu.dot(&r) / d).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two hypotheses 100 m east of an agent at the origin, one driving east (away) at
    /// 10 m/s, one west (toward it); one measurement each.
    fn two_ways() -> EerInputs {
        EerInputs {
            current: vec![Enu2::new(100.0, 0.0); 2],
            weights: vec![0.5, 0.5],
            predicted: vec![Enu2::new(100.0, 0.0); 2],
            measurements: vec![Enu2::new(100.0, 0.0); 2],
            alpha: vec![0.5, 0.5],
            n_m: 1,
            velocity: vec![Enu2::new(10.0, 0.0), Enu2::new(-10.0, 0.0)],
        }
    }

    #[test]
    fn a_hypothesis_driving_away_outweighs_one_coming_closer_by_one_over_the_floor() {
        let mut inp = two_ways();
        weigh_by_escape(&mut inp, &Enu2::zeros(), 0.1);
        // Factors 1 (away at the fastest speed) and 0.1 (coming closer): 1/1.1 and 0.1/1.1.
        assert!(
            (inp.weights[0] - 1.0 / 1.1).abs() < 1e-12,
            "{:?}",
            inp.weights
        );
        assert!(
            (inp.weights[1] - 0.1 / 1.1).abs() < 1e-12,
            "{:?}",
            inp.weights
        );
        assert_eq!(inp.alpha, inp.weights);
        // Seen from the far side (x = 200), the west-going one is the one escaping.
        let mut inp = two_ways();
        weigh_by_escape(&mut inp, &Enu2::new(200.0, 0.0), 0.1);
        assert!(
            inp.weights[1] > 0.9 && inp.weights[0] < 0.1,
            "{:?}",
            inp.weights
        );
    }

    #[test]
    fn floor_one_no_motion_or_no_weight_leave_the_weights_as_they_are() {
        let mut inp = two_ways();
        weigh_by_escape(&mut inp, &Enu2::zeros(), 1.0);
        assert_eq!(inp.weights, vec![0.5, 0.5]);
        let mut inp = two_ways();
        inp.velocity = vec![Enu2::zeros(); 2];
        weigh_by_escape(&mut inp, &Enu2::zeros(), 0.1);
        assert_eq!(inp.weights, vec![0.5, 0.5]);
        // Floor 0 and both coming closer: every factor 0, nothing to renormalise by.
        let mut inp = two_ways();
        inp.velocity = vec![Enu2::new(-10.0, 0.0); 2];
        weigh_by_escape(&mut inp, &Enu2::zeros(), 0.0);
        assert_eq!(inp.weights, vec![0.5, 0.5]);
    }

    #[test]
    fn alpha_follows_its_hypothesis_with_several_measurements_each() {
        let mut inp = two_ways();
        inp.n_m = 2;
        inp.measurements = vec![Enu2::new(100.0, 0.0); 4];
        inp.alpha = vec![0.25; 4];
        weigh_by_escape(&mut inp, &Enu2::zeros(), 0.1);
        let sum: f64 = inp.alpha.iter().sum();
        assert!((sum - 1.0).abs() < 1e-12);
        assert!((inp.alpha[0] - inp.alpha[1]).abs() < 1e-15);
        assert!(
            (inp.alpha[0] / inp.alpha[2] - 10.0).abs() < 1e-9,
            "{:?}",
            inp.alpha
        );
        // Expectation weights that do not add up to each hypothesis's weight (likelihoods
        // differ per measurement) still sum to 1 after the weighting.
        let mut uneven = two_ways();
        uneven.n_m = 2;
        uneven.measurements = vec![Enu2::new(100.0, 0.0); 4];
        uneven.alpha = vec![0.4, 0.3, 0.2, 0.1];
        weigh_by_escape(&mut uneven, &Enu2::zeros(), 0.1);
        let sum: f64 = uneven.alpha.iter().sum();
        assert!((sum - 1.0).abs() < 1e-12, "{:?}", uneven.alpha);
        assert!(
            (uneven.alpha[0] / uneven.alpha[2] - 20.0).abs() < 1e-9,
            "{:?}",
            uneven.alpha
        );
    }

    #[test]
    fn speed_away_is_the_velocity_along_the_line_from_the_agent() {
        let a = Enu2::zeros();
        let p = Enu2::new(0.0, 50.0);
        assert!((speed_away_mps(&a, &p, &Enu2::new(3.0, 4.0)) - 4.0).abs() < 1e-12);
        assert_eq!(speed_away_mps(&a, &p, &Enu2::new(3.0, -4.0)), 0.0);
        assert_eq!(speed_away_mps(&a, &a, &Enu2::new(3.0, 4.0)), 0.0);
    }
}
