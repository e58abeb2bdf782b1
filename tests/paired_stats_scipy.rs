//! The paired statistics (`metrics::paired`) against SciPy itself, on the same numbers:
//! `scripts/setup-tests.sh` installs SciPy (pinned, `tests/stats/requirements.txt`) into
//! `.deps/stats`, and `tests/stats/scipy_paired.py` computes what SciPy says.

use std::path::Path;
use std::process::Command;

use infotrack::metrics::bootstrap::bca_mean_ci95;
use infotrack::metrics::paired::{holm, paired_t_test, wilcoxon_signed_rank};
use infotrack::rng::{stream_rng, Stream};

/// Pairs of samples: small and exact, with ties, with zero differences (the normal
/// approximation), over 50 pairs, and a draw as the Monte Carlo runs give them.
fn cases() -> Vec<(Vec<f64>, Vec<f64>)> {
    let mut lcg = 12345u64;
    let mut next = || {
        lcg = lcg
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (lcg >> 11) as f64 / (1u64 << 53) as f64
    };
    let long_a: Vec<f64> = (0..60).map(|_| 70.0 + 20.0 * next()).collect();
    let long_b: Vec<f64> = long_a.iter().map(|x| x - 3.0 + 8.0 * next()).collect();
    vec![
        (
            vec![81.2, 77.5, 90.1, 65.3, 88.8, 72.0],
            vec![70.1, 79.9, 60.4, 61.0, 85.5, 59.9],
        ),
        (
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0],
            vec![0.5, 2.5, 2.0, 3.0, 5.5, 5.0, 6.0],
        ),
        (
            vec![3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0],
            vec![3.0, 2.0, 3.0, 1.0, 4.0, 7.0, 2.0, 5.0],
        ),
        (
            vec![
                10.0, 12.0, 14.0, 16.0, 18.0, 20.0, 22.0, 24.0, 26.0, 28.0, 30.0, 32.0,
            ],
            vec![
                11.0, 10.0, 13.0, 15.0, 19.0, 18.0, 20.0, 25.0, 23.0, 27.0, 26.0, 29.0,
            ],
        ),
        (long_a, long_b),
    ]
}

fn python() -> std::path::PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(".deps/stats/bin/python");
    assert!(
        p.exists(),
        "{} is missing: run scripts/setup-tests.sh",
        p.display()
    );
    p
}

fn close(what: &str, ours: f64, scipy: f64, tol: f64) {
    assert!(
        (ours - scipy).abs() <= tol * scipy.abs().max(1.0),
        "{what}: ours {ours}, SciPy {scipy}"
    );
}

#[test]
fn paired_tests_and_holm_agree_with_scipy_to_1e_9() {
    let cases = cases();
    let scipy = scipy_on(&cases);
    let mut p_family = Vec::new();
    for (k, (a, b)) in cases.iter().enumerate() {
        let s = &scipy["cases"][k];
        let f = |key: &str| {
            s[key]
                .as_f64()
                .unwrap_or_else(|| panic!("case {k}: no {key} in {s}"))
        };
        let t = paired_t_test(a, b).unwrap();
        close(&format!("case {k} t"), t.t, f("t"), 1e-9);
        close(&format!("case {k} t p"), t.p_value, f("t_p"), 1e-9);
        close(&format!("case {k} ci low"), t.ci95[0], f("ci_low"), 1e-9);
        close(&format!("case {k} ci high"), t.ci95[1], f("ci_high"), 1e-9);
        let w = wilcoxon_signed_rank(a, b).unwrap();
        close(&format!("case {k} W"), w.statistic, f("w"), 1e-12);
        close(&format!("case {k} W p"), w.p_value, f("w_p"), 1e-9);
        p_family.push(w.p_value);
    }
    for (k, (ours, theirs)) in holm(&p_family)
        .iter()
        .zip(scipy["holm"].as_array().unwrap())
        .enumerate()
    {
        close(&format!("holm {k}"), *ours, theirs.as_f64().unwrap(), 1e-9);
    }
}

/// A resampled interval cannot agree to the last digit with one drawn from another
/// generator; both ends must agree to within 3 % of the interval's width (about five times
/// what the resampling noise of 200 000 resamples leaves) or, for differences that take a
/// few discrete values, one step of the lattice the resampled means live on (SciPy's own
/// ends move by that step from one of its seeds to another).
#[test]
fn bca_bootstrap_intervals_agree_with_scipy_within_resampling_noise() {
    let cases = cases();
    let scipy = scipy_on(&cases);
    for (k, (a, b)) in cases.iter().enumerate() {
        let s = &scipy["cases"][k];
        let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
        let mut rng = stream_rng(11, k as u64, Stream::Statistics, 0);
        let ours = bca_mean_ci95(&d, 200_000, &mut rng).unwrap();
        let theirs = [
            s["bca_low"].as_f64().unwrap(),
            s["bca_high"].as_f64().unwrap(),
        ];
        let width = theirs[1] - theirs[0];
        let tolerance = (0.03 * width).max(lattice_step(&d) + 1e-12);
        for (end, (o, t)) in ["low", "high"].iter().zip(ours.iter().zip(theirs)) {
            assert!(
                (o - t).abs() <= tolerance,
                "case {k} BCa {end}: ours {o}, SciPy {t} (width {width})"
            );
        }
    }
}

/// The spacing of the means of `d.len()` values drawn from `d`: the smallest gap between
/// two of its distinct values over their count.
fn lattice_step(d: &[f64]) -> f64 {
    let mut v = d.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let gap = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|g| *g > 1e-12)
        .fold(f64::INFINITY, f64::min);
    gap / d.len() as f64
}

/// What SciPy says of the cases.
fn scipy_on(cases: &[(Vec<f64>, Vec<f64>)]) -> serde_json::Value {
    let input = serde_json::json!(cases
        .iter()
        .map(|(a, b)| serde_json::json!({"a": a, "b": b}))
        .collect::<Vec<_>>());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/stats/scipy_paired.py");
    let out = Command::new(python())
        .arg(script)
        .arg(input.to_string())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}
