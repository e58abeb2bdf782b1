//! The constant-velocity Kalman filter baseline: state `[x, y, vx, vy]` in the world ENU
//! frame, predict every filter period, update only when measured.

use nalgebra::{Matrix2, Matrix2x4, Matrix4, Vector4};

use crate::world::geometry::{BoundsEnu, Enu2};

/// The Kalman filter's parameters (the configuration assembles them).
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanParams {
    /// Filter period, s.
    pub dt_s: f64,
    /// Diagonal of the process noise Q: m^2, m^2, (m/s)^2, (m/s)^2.
    pub process_noise_diag: [f64; 4],
    /// Diagonal of the initial covariance P0 (same units).
    pub initial_cov_diag: [f64; 4],
    /// Measurement noise R, m^2.
    pub measurement_noise_cov_m2: [[f64; 2]; 2],
    /// The workspace, world ENU (the state is kept inside it).
    pub workspace_enu: BoundsEnu,
}

/// Constant-velocity Kalman filter.
///
/// Before its first measurement it knows nothing: its mean is the workspace centre and its
/// covariance that of a uniform distribution over the workspace. The first measurement
/// initialises the state at the measured position with zero velocity and covariance P0.
#[derive(Debug, Clone)]
pub struct KalmanFilter {
    f: Matrix4<f64>,
    q: Matrix4<f64>,
    r: Matrix2<f64>,
    p0: Matrix4<f64>,
    h: Matrix2x4<f64>,
    x: Vector4<f64>,
    p: Matrix4<f64>,
    initialised: bool,
    workspace_enu: BoundsEnu,
}

impl KalmanFilter {
    /// A filter with these parameters, not yet initialised (its first measurement does).
    pub fn new(params: KalmanParams) -> Self {
        let dt = params.dt_s;
        let mut f = Matrix4::identity();
        f[(0, 2)] = dt;
        f[(1, 3)] = dt;
        let r = params.measurement_noise_cov_m2;
        let ws = params.workspace_enu;
        let mut kf = Self {
            f,
            q: Matrix4::from_diagonal(&Vector4::from(params.process_noise_diag)),
            r: Matrix2::new(r[0][0], r[0][1], r[1][0], r[1][1]),
            p0: Matrix4::from_diagonal(&Vector4::from(params.initial_cov_diag)),
            h: Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0),
            x: Vector4::zeros(),
            p: Matrix4::zeros(),
            initialised: false,
            workspace_enu: ws,
        };
        kf.reset();
        kf
    }

    /// Back to knowing nothing.
    pub fn reset(&mut self) {
        let ws = self.workspace_enu;
        let c = ws.center();
        self.x = Vector4::new(c.x, c.y, 0.0, 0.0);
        self.p = Matrix4::from_diagonal(&Vector4::new(
            ws.width_m().powi(2) / 12.0,
            ws.height_m().powi(2) / 12.0,
            self.p0[(2, 2)],
            self.p0[(3, 3)],
        ));
        self.initialised = false;
    }

    /// One filter period: predict, then update if measured.
    pub fn step(&mut self, measurement: Option<Enu2>) {
        if self.initialised {
            self.x = self.f * self.x;
            self.p = self.f * self.p * self.f.transpose() + self.q;
        }
        if let Some(z) = measurement {
            if !self.initialised {
                self.x = Vector4::new(z.x, z.y, 0.0, 0.0);
                self.p = self.p0;
                self.initialised = true;
                return;
            }
            let s = self.h * self.p * self.h.transpose() + self.r;
            let Some(s_inv) = s.try_inverse() else {
                tracing::warn!("Kalman innovation covariance singular; measurement skipped");
                return;
            };
            let k = self.p * self.h.transpose() * s_inv;
            let innovation = z - self.h * self.x;
            self.x += k * innovation;
            // Joseph form keeps P symmetric positive semi-definite.
            let i_kh = Matrix4::identity() - k * self.h;
            self.p = i_kh * self.p * i_kh.transpose() + k * self.r * k.transpose();
        }
    }

    /// Position estimate, world ENU.
    pub fn mean(&self) -> Enu2 {
        Enu2::new(self.x[0], self.x[1])
    }

    /// Velocity estimate, world ENU, m/s.
    pub fn velocity(&self) -> Enu2 {
        Enu2::new(self.x[2], self.x[3])
    }

    /// Position covariance (2x2 block), square metres.
    pub fn covariance(&self) -> Matrix2<f64> {
        self.p.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// Whether a measurement has initialised the state.
    pub fn is_initialised(&self) -> bool {
        self.initialised
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Config;
    use rand::SeedableRng;

    #[test]
    fn tracks_a_constant_velocity_target_and_learns_its_velocity() {
        let c = Config::default_lab();
        let world = c.world();
        let mut rng = crate::rng::CoreRng::seed_from_u64(5);
        let mut kf = KalmanFilter::new(c.kalman_params());
        assert!(!kf.is_initialised());
        let v = Enu2::new(0.2, -0.1);
        let dt = c.filter_dt_s();
        let mut x = Enu2::new(-2.0, 1.0);
        for _ in 0..150 {
            x += v * dt;
            kf.step(Some(world.measurement.measure(&x, &mut rng)));
        }
        assert!((kf.mean() - x).norm() < 0.1, "{} vs {x}", kf.mean());
        assert!((kf.velocity() - v).norm() < 0.1, "{}", kf.velocity());
        let p = kf.covariance();
        assert!((p - p.transpose()).abs().max() < 1e-12);
        assert!(p.determinant() > 0.0);
    }

    #[test]
    fn covariance_grows_without_measurements() {
        let c = Config::default_lab();
        let mut kf = KalmanFilter::new(c.kalman_params());
        kf.step(Some(Enu2::zeros()));
        let d0 = kf.covariance().determinant();
        for _ in 0..10 {
            kf.step(None);
        }
        assert!(kf.covariance().determinant() > d0);
    }
}
