//! Target state estimation: the particle filter (with any [`crate::motion::MotionModel`])
//! and the constant-velocity Kalman filter baseline.

pub mod kalman;
pub mod particle_filter;
pub mod road_following;
pub mod sections;

pub use kalman::{KalmanFilter, KalmanParams};
pub use particle_filter::{
    FilterCounters, FilterError, FilterParams, ParticleFilter, ResampleAction, RouteStart,
    StepReport,
};
