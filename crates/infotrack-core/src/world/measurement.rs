//! The measurement model z = x + N(0, R) and its likelihood.

use nalgebra::{Cholesky, Matrix2};
use rand::Rng;
use rand_distr::StandardNormal;

use super::geometry::Enu2;

/// A zero-mean Gaussian in the plane, with what its density needs precomputed.
#[derive(Debug, Clone, Copy)]
pub struct Gaussian2 {
    /// Covariance, square metres.
    pub cov: Matrix2<f64>,
    inv: Matrix2<f64>,
    chol_l: Matrix2<f64>,
    log_norm: f64,
}

impl Gaussian2 {
    /// From a symmetric positive-definite covariance given row-major.
    ///
    /// Panics if the matrix is not positive definite; configurations are validated at load.
    pub fn new(cov: [[f64; 2]; 2]) -> Self {
        let cov = Matrix2::new(cov[0][0], cov[0][1], cov[1][0], cov[1][1]);
        let chol = Cholesky::new(cov).expect("covariance validated as positive definite");
        let inv = chol.inverse();
        let det = cov.determinant();
        Self {
            cov,
            inv,
            chol_l: chol.l(),
            log_norm: -(std::f64::consts::TAU.ln()) - 0.5 * det.ln(),
        }
    }

    /// Scaled copy: covariance multiplied by `s`.
    pub fn scaled(&self, s: f64) -> Self {
        let c = self.cov * s;
        Self::new([[c[(0, 0)], c[(0, 1)]], [c[(1, 0)], c[(1, 1)]]])
    }

    /// Log density of the offset `d`.
    #[inline]
    pub fn log_pdf(&self, d: &Enu2) -> f64 {
        let q = self.inv[(0, 0)] * d.x * d.x
            + 2.0 * self.inv[(0, 1)] * d.x * d.y
            + self.inv[(1, 1)] * d.y * d.y;
        self.log_norm - 0.5 * q
    }

    /// Density of the offset `d`.
    #[inline]
    pub fn pdf(&self, d: &Enu2) -> f64 {
        self.log_pdf(d).exp()
    }

    /// A draw.
    #[inline]
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Enu2 {
        let n = Enu2::new(rng.sample(StandardNormal), rng.sample(StandardNormal));
        self.chol_l * n
    }

    /// Entries of the inverse covariance `[a, b, c]` for a quadratic form a x^2 + 2 b x y + c y^2.
    pub fn inverse_entries(&self) -> [f64; 3] {
        [self.inv[(0, 0)], self.inv[(0, 1)], self.inv[(1, 1)]]
    }

    /// log of the normalising constant, -log(2 pi) - log(det)/2.
    pub fn log_norm(&self) -> f64 {
        self.log_norm
    }
}

/// z = x + n, n ~ N(0, R), in the world ENU frame.
#[derive(Debug, Clone, Copy)]
pub struct MeasurementModel {
    /// The noise distribution N(0, R).
    pub noise: Gaussian2,
}

impl MeasurementModel {
    /// With covariance R, square metres.
    pub fn new(r: [[f64; 2]; 2]) -> Self {
        Self {
            noise: Gaussian2::new(r),
        }
    }

    /// Simulates a measurement of a target at `x`.
    pub fn measure<R: Rng + ?Sized>(&self, x: &Enu2, rng: &mut R) -> Enu2 {
        x + self.noise.sample(rng)
    }

    /// log p(z | x).
    #[inline]
    pub fn log_likelihood(&self, z: &Enu2, x: &Enu2) -> f64 {
        self.noise.log_pdf(&(z - x))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn density_matches_the_closed_form() {
        let g = Gaussian2::new([[0.01, 0.0], [0.0, 0.04]]);
        let d = Enu2::new(0.1, -0.2);
        let expect = (-0.5f64 * (0.01 / 0.01 + 0.04 / 0.04)).exp()
            / (std::f64::consts::TAU * (0.01f64 * 0.04).sqrt());
        assert!((g.pdf(&d) - expect).abs() < 1e-9 * expect);
    }

    #[test]
    fn samples_have_the_configured_covariance() {
        let g = Gaussian2::new([[0.04, 0.01], [0.01, 0.01]]);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = 200_000;
        let mut s = Matrix2::zeros();
        for _ in 0..n {
            let x = g.sample(&mut rng);
            s += x * x.transpose();
        }
        s /= n as f64;
        assert!((s - g.cov).abs().max() < 1.5e-3, "{s}");
    }
}
