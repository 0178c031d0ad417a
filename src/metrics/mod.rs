//! Dance quality metrics, each with its formula and source.
//!
//! All metrics take world joint positions in metres, y up, `[T, J, 3]`, and the motion's fps.
//! - [`beats`]: kinematic beats (FACT and Bailando variants), BAS in both conventions, beat
//!   coverage / hit rate (DanceRevolution), rhythm hit (DanceNet), and `mir_eval`'s beat metrics.
//! - [`features`]: AIST++ kinetic and geometric features; [`fid`]: FID and diversity.
//! - [`kinematics`]: smoothness, foot skating, freezing, key-pose error.
pub mod beats;
pub mod eval;
pub mod features;
pub mod fid;
pub mod kinematics;
pub mod plausibility;
pub mod reference;
pub mod score;
pub mod skeleton_map;

/// Errors from computing metrics or loading their reference statistics.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    #[error("motion has {got} joints, the metrics need {want}")]
    JointCount { got: usize, want: usize },
    #[error("not enough data: {0}")]
    NotEnoughData(String),
    #[error("reference statistics: {0}")]
    Reference(String),
    #[error("i/o error on {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
}
