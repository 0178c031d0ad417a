//! Dance quality metrics, each with its formula and source.
//!
//! All metrics take world joint positions in metres, y up, `[T, J, 3]`, and the motion's fps.
//! - [`beats`]: kinematic beats (FACT and Bailando variants), BAS in both conventions, beat
//!   coverage / hit rate (DanceRevolution), rhythm hit (DanceNet), beat precision/recall/F (TSMT),
//!   and `mir_eval`'s beat metrics.
//! - [`features`]: AIST++ kinetic and geometric features; [`fid`]: FID and diversity;
//!   [`diversity`]: TSMT's A-seq-D, I-seq-D and S-music-D.
//! - [`kinematics`]: smoothness, foot skating, freezing, key-pose error; [`plausibility`]:
//!   authenticity and coherence against real joint-angle limits (TSMT).
//! - [`physical`]: floor contact, ground penetration, pops, liveliness, seed sensitivity, and
//!   the pass/fail verdict on them; [`crate::motion::hang`]: a body held off the floor
//!   (both feet up) longer than a dancer can be; [`crate::motion::hold`]: a body standing in one
//!   pose longer than 41 of the 43 real dances do (both the motion's, read by served stages too,
//!   reported here).
//! - [`rotation_flips`]: frame steps on which a rig joint's local rotation turns past 60° / 90°
//!   (the exported rotations a skinned mesh follows; takes a `RigMotion`, not positions).
//! - [`reference`]: the committed train-split statistics; [`score`]: one dance and a set;
//!   [`skeleton_map`]: AIST++ joints on our 23-joint skeleton.
//!
//! Measures only: they take motion (and beats), never a model. The harness that runs the models
//! and scores them with these measures is the `eval` module (`choreo eval`), a layer above.
//!
//! # BAS on dance-with-melody: read it with its chance level
//! FACT's BAS uses σ = 0.05 s, so kinematic beats at *random* times already score about
//! `σ√(2π)/P` (0.18 at the waltzes' 86 bpm, 0.26 at the cha-cha's 123 bpm); every rhythm score
//! carries that chance level ([`beats::bas_fact_chance`]). On the six test dances, with beats
//! from [`crate::audio::analyze`], only the cha-cha (DANCE_C_8) scores above chance and above
//! every train dance laid on its song (0.31 vs chance 0.26 and 0.24 mismatched); the rumba and
//! the four waltzes score *below* chance (0.13–0.16 vs 0.18), and below mismatched real dances.
//! Their speed minima do not phase-lock to the tracked beats at any lag, time scale, or on the
//! bar grid (mean resultant length 0.05–0.14, chance level), while the speed's dominant period
//! does follow the metre: twice per 3-beat bar in the waltzes (≈ 57/min at 86 bpm), every
//! second beat in the cha-cha and rumba. So on this data BAS (either convention) measures little
//! beyond the cha-cha; judge rhythm by several numbers (beat F, rhythm hit, BAS against its
//! chance), never by BAS alone.
pub mod beats;
pub mod diversity;
pub mod features;
pub mod fid;
pub mod kinematics;
pub mod musicality;
pub mod physical;
pub mod plausibility;
pub mod posture;
pub mod reference;
pub mod rotation_flips;
pub mod score;
pub mod skeleton_map;

/// Errors from computing metrics or loading their reference statistics.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    #[error("motion has {got} joints, the metrics need {want}")]
    JointCount { got: usize, want: usize },
    #[error("not enough data: {0}")]
    NotEnoughData(String),
    #[error("reference statistics: the dances have different frame rates")]
    MixedFrameRates,
    #[error("i/o error on {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
}

impl MetricsError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            MetricsError::JointCount { .. } => "metrics-joint-count",
            MetricsError::NotEnoughData(_) => "metrics-not-enough-data",
            MetricsError::MixedFrameRates => "metrics-mixed-frame-rates",
            MetricsError::Io { .. } => "metrics-io",
            MetricsError::Json(_) => "metrics-json",
        }
    }
}
