//! Simulated sources, shared by the simulator (`infotrack sim`) and the daemon on its
//! embedded default: the target driving its roads, the agent flying to its setpoints, and
//! the two simulated sensors the tracker can be lent (the analytic measurement model, and
//! frames rendered by the synthetic camera through the real detector).

pub mod agent;
pub mod rendered_camera;
pub mod sensors;
pub mod target;

pub use agent::AgentSim;
pub use rendered_camera::{VisionSensor, VisionStats};
pub use sensors::{AnalyticSensor, RenderedSensor};
pub use target::TargetSim;
