//! Particle approximations of the entropy of a filtered density (the paper's eqs. 6, 7,
//! 10 and 11, after Boers et al. and Skoglar et al.).
//!
//! All of them have one shape. With prior weights w_i, a likelihood l_i of each particle
//! (1 when there is no measurement), and the transition sums S_i = sum_j p(x_i | x_j) w_j:
//!
//! ```text
//! H = log(sum_i l_i w_i) - sum_i w^_i log(l_i S_i),    w^_i = l_i w_i / sum_l l_l w_l
//! ```
//!
//! Eq. 6 / 10 are this with the measurement likelihood; eq. 7 / 11 are this with l = 1
//! (the first term is then log 1 = 0). A missed detection (negative information) is this
//! with l_i = p_miss for particles in view and 1 elsewhere. Everything is computed in the
//! log domain so that small likelihoods do not underflow.

use crate::world::geometry::Enu2;
use crate::world::measurement::Gaussian2;

/// `exp(x)`, with the arguments whose exponential rounds to zero (`exp` returns +0 below
/// -745.14; the cut is at -746) answered without calling it: glibc takes a slow
/// path for every result that underflows (setting errno), and a belief spread over a town
/// measured against a metre's noise underflows for nearly every pair. The same bits either
/// way.
#[inline]
pub fn exp_or_zero(x: f64) -> f64 {
    if x < -746.0 {
        0.0
    } else {
        x.exp()
    }
}

/// log(sum_i exp(a_i)), stable; `-inf` for an empty or all `-inf` input.
pub fn log_sum_exp(a: impl Iterator<Item = f64> + Clone) -> f64 {
    let max = a.clone().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return f64::NEG_INFINITY;
    }
    max + a.map(|v| exp_or_zero(v - max)).sum::<f64>().ln()
}

/// Quadratic forms beyond this contribute exp(-700) or less.
const FAR_Q: f64 = 1400.0;

/// `log S_i = log sum_j N(x_i - c_j; 0, kernel) w_j` for every i: the transition sums of
/// the entropy formulas, with the transition density a Gaussian kernel around the centres.
pub fn log_transition_sums(
    points: &[Enu2],
    centres: &[Enu2],
    weights: &[f64],
    kernel: &Gaussian2,
) -> Vec<f64> {
    let [a, b, c] = kernel.inverse_entries();
    let norm = kernel.log_norm().exp();
    let same = std::ptr::eq(points, centres);
    let n = points.len();
    let mut s = vec![0.0; n];
    if same {
        // Symmetric kernel: each pair once.
        for i in 0..n {
            s[i] += norm * weights[i];
            let (xi, yi) = (points[i].x, points[i].y);
            for j in (i + 1)..n {
                let dx = xi - points[j].x;
                let dy = yi - points[j].y;
                let q = a * dx * dx + 2.0 * b * dx * dy + c * dy * dy;
                // exp(-700) is below 1e-304: such a pair adds nothing representable next to
                // the self term, so skipping its exponential changes no digit.
                if q < FAR_Q {
                    let k = norm * (-0.5 * q).exp();
                    s[i] += k * weights[j];
                    s[j] += k * weights[i];
                }
            }
        }
    } else {
        for (i, p) in points.iter().enumerate() {
            let mut acc = 0.0;
            for (cj, wj) in centres.iter().zip(weights) {
                let dx = p.x - cj.x;
                let dy = p.y - cj.y;
                acc += exp_or_zero(-0.5 * (a * dx * dx + 2.0 * b * dx * dy + c * dy * dy)) * wj;
            }
            s[i] = norm * acc;
        }
    }
    s.into_iter().map(f64::ln).collect()
}

/// The common form above, from log-likelihoods `log_l`, prior weights `w` (normalised) and
/// `log_s` from [`log_transition_sums`].
pub fn entropy_with_likelihood(log_l: &[f64], w: &[f64], log_s: &[f64]) -> f64 {
    let lse = log_sum_exp(log_l.iter().zip(w).map(|(l, w)| l + w.ln()));
    let mut acc = 0.0;
    for i in 0..w.len() {
        let lw = log_l[i] + w[i].ln();
        if lw == f64::NEG_INFINITY {
            continue;
        }
        let w_post = exp_or_zero(lw - lse);
        acc += w_post * (log_l[i] + log_s[i]);
    }
    lse - acc
}

/// Eq. 7 / 11: entropy of a predicted density with no measurement,
/// `-sum_i w_i log(sum_j p(x_i | x_j) w_j)`.
pub fn entropy_prior(w: &[f64], log_s: &[f64]) -> f64 {
    -w.iter().zip(log_s).map(|(w, s)| w * s).sum::<f64>()
}

/// Eq. 6 / 10: entropy after a measurement `z` with model `noise` (z = x + noise).
pub fn entropy_measured(
    z: &Enu2,
    points: &[Enu2],
    w: &[f64],
    log_s: &[f64],
    noise: &Gaussian2,
) -> f64 {
    let log_l: Vec<f64> = points.iter().map(|x| noise.log_pdf(&(z - x))).collect();
    entropy_with_likelihood(&log_l, w, log_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kernel() -> Gaussian2 {
        Gaussian2::new([[0.01, 0.0], [0.0, 0.01]])
    }

    #[test]
    fn single_particle_prior_entropy_is_minus_log_peak_density() {
        // One particle: S = N(0; 0, k) = 1 / (2 pi 0.01); H = -log S.
        let p = [Enu2::new(0.3, 0.2)];
        let s = log_transition_sums(&p, &p, &[1.0], &kernel());
        let h = entropy_prior(&[1.0], &s);
        assert!(
            (h - (std::f64::consts::TAU * 0.01).ln()).abs() < 1e-12,
            "{h}"
        );
    }

    #[test]
    fn two_far_particles_have_log2_more_entropy_than_one() {
        // Far apart (kernel overlap ~ e^-5000): S_i = peak / 2 each, so H = log 2 - log peak.
        let p = [Enu2::new(0.0, 0.0), Enu2::new(10.0, 0.0)];
        let w = [0.5, 0.5];
        let s = log_transition_sums(&p, &p, &w, &kernel());
        let h = entropy_prior(&w, &s);
        let expect = 2f64.ln() + (std::f64::consts::TAU * 0.01).ln();
        assert!((h - expect).abs() < 1e-12, "{h} vs {expect}");
    }

    #[test]
    fn three_particles_by_hand() {
        // Particles at 0, d and 2d on a line with kernel variance v; w = (1/2, 1/4, 1/4).
        let v: f64 = 0.04;
        let d: f64 = 0.2;
        let k = Gaussian2::new([[v, 0.0], [0.0, v]]);
        let p = [
            Enu2::new(0.0, 0.0),
            Enu2::new(d, 0.0),
            Enu2::new(2.0 * d, 0.0),
        ];
        let w = [0.5, 0.25, 0.25];
        let peak = 1.0 / (std::f64::consts::TAU * v);
        let g = |dist: f64| peak * (-dist * dist / (2.0 * v)).exp();
        let s0 = g(0.0) * 0.5 + g(d) * 0.25 + g(2.0 * d) * 0.25;
        let s1 = g(d) * 0.5 + g(0.0) * 0.25 + g(d) * 0.25;
        let s2 = g(2.0 * d) * 0.5 + g(d) * 0.25 + g(0.0) * 0.25;
        let prior = -(0.5 * s0.ln() + 0.25 * s1.ln() + 0.25 * s2.ln());
        let log_s = log_transition_sums(&p, &p, &w, &k);
        assert!((entropy_prior(&w, &log_s) - prior).abs() < 1e-12);

        // A measurement at particle 2 with noise variance r.
        let r: f64 = 0.01;
        let noise = Gaussian2::new([[r, 0.0], [0.0, r]]);
        let lik = |dist: f64| (-dist * dist / (2.0 * r)).exp() / (std::f64::consts::TAU * r);
        let l = [lik(2.0 * d), lik(d), lik(0.0)];
        let norm: f64 = l.iter().zip(&w).map(|(l, w)| l * w).sum();
        let post: Vec<f64> = l.iter().zip(&w).map(|(l, w)| l * w / norm).collect();
        let s = [s0, s1, s2];
        let expect = norm.ln() - (0..3).map(|i| post[i] * (l[i] * s[i]).ln()).sum::<f64>();
        let got = entropy_measured(&p[2], &p, &w, &log_s, &noise);
        assert!((got - expect).abs() < 1e-10, "{got} vs {expect}");
    }

    #[test]
    fn measuring_a_spread_set_lowers_its_entropy() {
        let p: Vec<Enu2> = (0..20).map(|i| Enu2::new(0.1 * i as f64, 0.0)).collect();
        let w = vec![0.05; 20];
        let k = kernel();
        let log_s = log_transition_sums(&p, &p, &w, &k);
        let noise = Gaussian2::new([[0.01, 0.0], [0.0, 0.01]]);
        let prior = entropy_prior(&w, &log_s);
        let post = entropy_measured(&p[10], &p, &w, &log_s, &noise);
        assert!(post < prior, "{post} !< {prior}");
    }

    #[test]
    fn unit_likelihood_reduces_the_general_form_to_the_prior_form() {
        let p: Vec<Enu2> = (0..7)
            .map(|i| Enu2::new(0.05 * i as f64, 0.02 * (i * i) as f64))
            .collect();
        let w: Vec<f64> = (1..=7).map(|i| i as f64 / 28.0).collect();
        let log_s = log_transition_sums(&p, &p, &w, &kernel());
        let a = entropy_with_likelihood(&[0.0; 7], &w, &log_s);
        assert!((a - entropy_prior(&w, &log_s)).abs() < 1e-12);
    }

    #[test]
    fn symmetric_and_general_transition_sums_agree() {
        let p: Vec<Enu2> = (0..9)
            .map(|i| Enu2::new((i as f64).sin(), (i as f64 * 0.7).cos()))
            .collect();
        let w: Vec<f64> = (1..=9).map(|i| i as f64 / 45.0).collect();
        let k = Gaussian2::new([[0.2, 0.05], [0.05, 0.1]]);
        let a = log_transition_sums(&p, &p, &w, &k);
        let copy = p.clone();
        let b = log_transition_sums(&p, &copy, &w, &k);
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-12);
        }
    }
}
