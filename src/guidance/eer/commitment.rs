//! Commitment while searching. EER is myopic and its estimate is noisy (one simulated
//! measurement per particle: re-planned over the same belief, the EER of one mode moved
//! between -0.4 and 1.4 nats); over a spread belief (the operator's cue, whose hypotheses
//! run both ways along every road, the belief re-spread after a loss, or the belief split
//! at a covered junction) the argmax jumped between far apart modes from one plan to the
//! next, and the drone flew back and forth between them and reached neither (field-town: a
//! median of 166 s to the first sighting; field-eight: between the covered crossing's two
//! exits; BENCHMARKS.md "Field scale, parts 26-27"). While searching (the target not seen
//! since the belief stopped being local, see the tracker), the plan keeps to the candidate
//! nearest its previous waypoint among those whose EER is within a share of the EER range
//! below the best, so the drone flies to one mode unless another is clearly better. A
//! departure from the paper's eq. 14 (the argmax), documented; `guidance.search_commitment
//! = 0` restores it.

use crate::world::geometry::Enu2;

/// The index of the candidate to fly to: the argmax of `eer` (the first of equal ones), or,
/// with a `previous` waypoint and a `share` > 0, the candidate nearest `previous` among those
/// whose EER is at least `best - share * (best - worst)`. Non-finite values count as absent.
/// `None` when there is nothing to choose between: no finite EER, or all of them equal (no
/// candidate sees any particle).
pub fn committed_choice(
    eer: &[f64],
    candidates_enu: &[Enu2],
    previous_enu: Option<Enu2>,
    share: f64,
) -> Option<usize> {
    let finite = || eer.iter().enumerate().filter(|(_, v)| v.is_finite());
    // The first of equal maxima, as eq. 14's argmax has always been taken here.
    let (best, best_v) = finite().fold((None, f64::NEG_INFINITY), |(b, bv), (i, v)| {
        if *v > bv {
            (Some(i), *v)
        } else {
            (b, bv)
        }
    });
    let worst_v = finite().map(|(_, v)| *v).fold(f64::INFINITY, f64::min);
    if best.is_none() || best_v - worst_v < 1e-12 {
        return None;
    }
    let Some(previous) = previous_enu.filter(|_| share > 0.0) else {
        return best;
    };
    let floor = best_v - share * (best_v - worst_v);
    let distance = |i: usize| (candidates_enu[i] - previous).norm();
    finite()
        .filter(|(_, v)| **v >= floor)
        .map(|(i, _)| i)
        .min_by(|a, b| distance(*a).total_cmp(&distance(*b)))
        .or(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cands() -> Vec<Enu2> {
        vec![
            Enu2::new(300.0, 0.0),
            Enu2::new(0.0, 300.0),
            Enu2::new(10.0, 10.0),
        ]
    }

    #[test]
    fn without_a_previous_waypoint_or_a_share_it_is_the_argmax() {
        let eer = [1.0, 0.95, 0.0];
        assert_eq!(committed_choice(&eer, &cands(), None, 0.2), Some(0));
        let prev = Some(Enu2::new(0.0, 280.0));
        assert_eq!(committed_choice(&eer, &cands(), prev, 0.0), Some(0));
    }

    #[test]
    fn a_nearly_as_good_candidate_near_the_previous_waypoint_is_kept() {
        // The previous plan flew north; east is 5 % of the range better: stay north.
        let eer = [1.0, 0.95, 0.0];
        let prev = Some(Enu2::new(0.0, 280.0));
        assert_eq!(committed_choice(&eer, &cands(), prev, 0.2), Some(1));
        // Previously east: east it stays (and it is the best).
        let east = Some(Enu2::new(290.0, 0.0));
        assert_eq!(committed_choice(&eer, &cands(), east, 0.2), Some(0));
    }

    #[test]
    fn a_clearly_better_candidate_wins_over_the_previous_waypoint() {
        // North is 50 % of the range below the best: outside a 0.2 share.
        let eer = [1.0, 0.5, 0.0];
        let prev = Some(Enu2::new(0.0, 280.0));
        assert_eq!(committed_choice(&eer, &cands(), prev, 0.2), Some(0));
    }

    #[test]
    fn non_finite_values_are_never_chosen_and_nothing_to_choose_between_is_none() {
        let eer = [f64::NAN, 0.5, 0.4];
        let prev = Some(Enu2::new(300.0, 0.0));
        assert_eq!(committed_choice(&eer, &cands(), prev, 0.2), Some(1));
        assert_eq!(committed_choice(&[f64::NAN; 3], &cands(), prev, 0.2), None);
        assert_eq!(committed_choice(&[], &[], prev, 0.2), None);
        // Every candidate alike: no view sees any particle.
        assert_eq!(committed_choice(&[0.3; 3], &cands(), None, 0.2), None);
    }
}
