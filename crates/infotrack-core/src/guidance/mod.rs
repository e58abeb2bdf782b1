//! Guidance: where the agent should go next.
//!
//! * `eer`: maximise the expected entropy reduction (the paper's method).
//! * `pfwm`: go to the particle filter's weighted mean.
//! * `lawn`: go to the last measurement when there is a recent one, else sweep a lawnmower path.
//! * `kf`: go to the Kalman filter's mean.
//! * `truth`: go to the true target position (for the estimation comparison).
//!
//! Every waypoint is clamped to the geofence before it leaves this module.

pub mod ambush;
pub mod eer;
pub mod entropy;
pub mod lawn;
pub mod sections;
pub mod view_heading;

use std::fmt;
use std::str::FromStr;

pub use eer::{EerDecision, EerParams, EerPlanner, ReachShape};
pub use lawn::{LawnConfig, LawnmowerPath};
pub use view_heading::{HeadingRule, ViewHeading};

/// A guidance law.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum GuidanceKind {
    /// Expected entropy reduction.
    Eer,
    /// Particle filter weighted mean.
    Pfwm,
    /// Lawnmower and tracking.
    Lawn,
    /// Kalman filter mean.
    Kf,
    /// True target position.
    Truth,
}

impl GuidanceKind {
    /// All laws, in report order.
    pub const ALL: [GuidanceKind; 5] = [Self::Eer, Self::Pfwm, Self::Lawn, Self::Kf, Self::Truth];

    /// The name used on the command line and in reports.
    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Eer => "eer",
            Self::Pfwm => "pfwm",
            Self::Lawn => "lawn",
            Self::Kf => "kf",
            Self::Truth => "truth",
        }
    }

    /// Whether the law reads the particle set (and so cannot run with a Kalman estimator).
    pub fn needs_particles(&self) -> bool {
        matches!(self, Self::Eer | Self::Pfwm)
    }
}

impl fmt::Display for GuidanceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A guidance-law name that names none.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown guidance law `{0}` (expected one of eer, pfwm, lawn, kf, truth)")]
pub struct UnknownGuidance(pub String);

impl FromStr for GuidanceKind {
    type Err = UnknownGuidance;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .iter()
            .find(|g| g.as_str() == s.trim())
            .copied()
            .ok_or_else(|| UnknownGuidance(s.to_string()))
    }
}
