//! Commitment while searching. EER is myopic and its estimate is noisy (one simulated
//! measurement per particle: re-planned over the same belief, the EER of one mode moved
//! between -0.4 and 1.4 nats); over a spread belief (the operator's cue, whose hypotheses
//! run both ways along every road, the belief re-spread after a loss, or the belief split
//! at a covered junction) the argmax jumped between far apart modes from one plan to the
//! next, and the drone flew back and forth between them and reached neither (field-town: a
//! median of 166 s to the first sighting; field-eight: between the covered crossing's two
//! exits; BENCHMARKS.md). While searching (the target not yet
//! seen, see the tracker), the plan keeps to the candidate
//! nearest its previous waypoint among those whose EER is within a share of the EER range
//! below the best, so the drone flies to one mode unless another is clearly better. A
//! departure from the paper's eq. 14 (the argmax), documented. The commitment lasts until
//! the drone gets there: once the vehicle's view holds its previous waypoint, the planner
//! passes none ([`super::EerPlanner::decide`]) and the argmax decides again. Kept to the
//! end, it chased the refuted mode's fastest hypotheses past a covered junction while the
//! car drove off the other way (the outdoor closed loop: 5 of 80 seeds lost the car for good;
//! BENCHMARKS.md). So the commitment ends at the first
//! sighting: after a loss the argmax decides, which with hypotheses that slow down to turn
//! back ([`crate::estimation::road_following::reroute_track`]) lost the car for good on 1
//! seed of 80 against 3, and no longer flip-flops at field-eight's covered crossing.
//!
//! Centring otherwise ([`Centring`]): with no previous waypoint to keep to (tracking, the
//! first plan of a search, or `guidance.search_commitment = 0`), the candidate nearest the
//! belief's predicted mean among those within `guidance.centring_share` of the best. Both
//! shares 0 give the paper's argmax, exact ties broken toward the mean.

use crate::world::geometry::Enu2;

/// Relative difference below which two EERs count as equal whatever the centring share.
const TIE_TOLERANCE: f64 = 1e-9;

/// While tracking, where to centre the view among nearly equal candidates.
///
/// Once the belief fits in the view, every candidate whose view holds all of it has the same
/// EER give or take the estimate's noise (one simulated measurement per particle), and the
/// argmax fell anywhere among them: the first of the candidate list or a noise-driven pick
/// up to a view's half width from the target. The drone was then ~11 m from a car it saw
/// in every frame (field-ring, config seed) and swung from one side of it to the other.
/// Of the candidates within `share` of the EER range below the best, the one nearest the
/// belief's predicted mean is taken: the view is centred on the target. A choice among
/// (nearly) equal maxima of the paper's eq. 14, documented; share 0 breaks exact ties only.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Centring {
    /// The belief's weighted mean at the end of the horizon, world ENU.
    pub mean_enu: Enu2,
    /// The share of the EER range below the best within which candidates count as equal.
    pub share: f64,
}

/// The index of the candidate to fly to: the argmax of `eer`; with a `previous` waypoint and
/// a `share` > 0 (searching), the candidate nearest `previous` among those whose EER is at
/// least `best - share * (best - worst)`; otherwise, with a `centring`, the candidate
/// nearest its mean among those within its share of the best ([`Centring`]), else the first
/// of equal maxima. Non-finite values count as absent. `None` when there is nothing to
/// choose between: no finite EER, or all of them equal (no candidate sees any particle).
pub fn committed_choice(
    eer: &[f64],
    candidates_enu: &[Enu2],
    previous_enu: Option<Enu2>,
    share: f64,
    centring: Option<Centring>,
) -> Option<usize> {
    let finite = || eer.iter().enumerate().filter(|(_, v)| v.is_finite());
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
    let (anchor, within) = match (previous_enu.filter(|_| share > 0.0), centring) {
        (Some(previous), _) => (previous, share * (best_v - worst_v)),
        (None, Some(c)) => (
            c.mean_enu,
            c.share * (best_v - worst_v) + TIE_TOLERANCE * best_v.abs(),
        ),
        (None, None) => return best,
    };
    let floor = best_v - within;
    let distance = |i: usize| (candidates_enu[i] - anchor).norm();
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
        assert_eq!(committed_choice(&eer, &cands(), None, 0.2, None), Some(0));
        let prev = Some(Enu2::new(0.0, 280.0));
        assert_eq!(committed_choice(&eer, &cands(), prev, 0.0, None), Some(0));
    }

    #[test]
    fn a_nearly_as_good_candidate_near_the_previous_waypoint_is_kept() {
        // The previous plan flew north; east is 5 % of the range better: stay north.
        let eer = [1.0, 0.95, 0.0];
        let prev = Some(Enu2::new(0.0, 280.0));
        assert_eq!(committed_choice(&eer, &cands(), prev, 0.2, None), Some(1));
        // Previously east: east it stays (and it is the best).
        let east = Some(Enu2::new(290.0, 0.0));
        assert_eq!(committed_choice(&eer, &cands(), east, 0.2, None), Some(0));
    }

    #[test]
    fn a_clearly_better_candidate_wins_over_the_previous_waypoint() {
        // North is 50 % of the range below the best: outside a 0.2 share.
        let eer = [1.0, 0.5, 0.0];
        let prev = Some(Enu2::new(0.0, 280.0));
        assert_eq!(committed_choice(&eer, &cands(), prev, 0.2, None), Some(0));
    }

    #[test]
    fn non_finite_values_are_never_chosen_and_nothing_to_choose_between_is_none() {
        let eer = [f64::NAN, 0.5, 0.4];
        let prev = Some(Enu2::new(300.0, 0.0));
        assert_eq!(committed_choice(&eer, &cands(), prev, 0.2, None), Some(1));
        assert_eq!(
            committed_choice(&[f64::NAN; 3], &cands(), prev, 0.2, None),
            None
        );
        assert_eq!(committed_choice(&[], &[], prev, 0.2, None), None);
        // Every candidate alike: no view sees any particle.
        assert_eq!(committed_choice(&[0.3; 3], &cands(), None, 0.2, None), None);
    }

    #[test]
    fn tracking_the_view_is_centred_among_nearly_equal_candidates() {
        // Candidates 0 and 2 hold the whole belief (EER within 1 % of each other); the
        // belief's mean is at (12, 12): the candidate at (10, 10), not the first best.
        let eer = [1.0, 0.0, 0.99];
        let centring = |share| {
            Some(Centring {
                mean_enu: Enu2::new(12.0, 12.0),
                share,
            })
        };
        assert_eq!(
            committed_choice(&eer, &cands(), None, 0.2, centring(0.02)),
            Some(2)
        );
        // A share smaller than the difference: the argmax.
        assert_eq!(
            committed_choice(&eer, &cands(), None, 0.2, centring(0.005)),
            Some(0)
        );
        // Share 0 breaks exact ties only, toward the mean, whichever comes first.
        let tied = [1.0, 0.0, 1.0];
        assert_eq!(
            committed_choice(&tied, &cands(), None, 0.2, centring(0.0)),
            Some(2)
        );
        assert_eq!(committed_choice(&tied, &cands(), None, 0.2, None), Some(0));
        // Searching, the commitment to the previous waypoint decides, not the centring.
        let prev = Some(Enu2::new(290.0, 0.0));
        assert_eq!(
            committed_choice(&eer, &cands(), prev, 0.2, centring(0.02)),
            Some(0)
        );
    }
}
