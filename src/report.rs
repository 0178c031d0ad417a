//! The per-job report: every metric that applies to a generated dance, with the series a web
//! tool plots (music and kinematic beat times, the windowed FID_k curve, motion energy).
//!
//! The worker calls [`build`] once the dance exists and [`write`] to store `report.json`; the
//! schema is [`Report`], documented in the OpenAPI spec through `utoipa::ToSchema`.
use crate::audio::Analysis;
use crate::metrics::kinematics::Freezing;
use crate::metrics::reference::ReferenceStats;
use crate::metrics::score::{fid_k_curve, score_dance, CurvePoint, DanceScores, KinematicBeats};
use crate::metrics::MetricsError;
use crate::motion::{KeyPose, Motion};

pub mod preview;
pub mod serving;

/// Version of the report schema; bumped when a field changes meaning.
pub const REPORT_VERSION: u32 = 1;

/// How well a dance dances, as `report.json` stores it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct Report {
    pub version: u32,
    /// Frame rate of the dance.
    pub fps: f64,
    /// Frames in the dance.
    pub frames: usize,
    /// Duration in seconds.
    pub duration_s: f64,
    /// Music beat times (s) within the dance, from the audio analysis.
    pub music_beat_times: Vec<f64>,
    /// The music's tempo through the song, from the audio analysis (`Analysis::tempo_curve`;
    /// empty in reports written before it existed).
    #[serde(default)]
    pub music_tempo_curve: Vec<crate::audio::TempoPoint>,
    /// Kinematic beat times (s), both published variants.
    pub kinematic_beat_times: KinematicBeats,
    /// Every per-dance score (BAS in both conventions, FID_k/FID_g, diversity, smoothness, foot
    /// skating, freezing ratio, plausibility, key-pose error), the physical-plausibility numbers
    /// (floor contact, ground penetration, pops, speed) and their pass/fail verdict.
    pub scores: DanceScores,
    /// FID_k over consecutive 4-s windows.
    pub fid_k_curve: Vec<CurvePoint>,
    /// Motion energy per second, to see a dance that freezes.
    pub freezing: Freezing,
    /// What the FID and plausibility compare against.
    pub reference: String,
    /// The worst key-pose error (cm) of the model's own motion, before the export fits one rigid
    /// skeleton to it; `scores` measure the exported motion (what `motion.json` holds). The two
    /// differ when the key poses' own bone lengths differ from each other (captured poses do).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_key_pose_error_cm: Option<f64>,
    /// The style danced, for models that dance one: asked for, or predicted from the song.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub style: Option<crate::models::StyleChoice>,
    /// What the beat-align stage did ([`crate::motion::beat_align`]), with the network's own
    /// tempo lock before it; absent where the stage did not run (`choreo generate
    /// --no-beat-align`, reports written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beat_align: Option<BeatAlignReport>,
    /// The clock the network ran on, for a model in beat time (`GET /v1/models` lists each
    /// model's `beat_time`): the reference tempo and the factor this song was heard at. Absent for
    /// a model in seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beat_time: Option<crate::models::beat_time::BeatTimeUsed>,
    /// Which draw of the seed was danced, for a model with an opening check
    /// (`models::opening_check`: dance-revolution and dancenet without a seed motion): each draw
    /// dances the song's first 20 s, and one that shuffles or flails gives way to the next. Absent
    /// where no check ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub opening_check: Option<crate::models::opening_check::OpeningChosen>,
    /// What a composed dance was made of (beat-graph): its slots, how many training dances its
    /// units came from, and the longest stretch it took in order from one of them. Absent for
    /// the networks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub composition: Option<crate::models::beat_graph::Composition>,
    /// What each serving stage after the model did to the dance, in the order they ran
    /// ([`serving`]): whether and how much it moved it, what it counted, and the dance's
    /// authenticity and coherence before and after it. Empty in reports written before it existed.
    #[serde(default)]
    pub serving: Vec<serving::StageTrace>,
}

/// The beat-align stage in report.json: its summary, and the tempo lock of the motion as the
/// network made it (`scores.musicality.tempo_lock` is the served dance's), so a report shows
/// how much of the lock is the network's own.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct BeatAlignReport {
    #[serde(flatten)]
    pub summary: crate::motion::beat_align::BeatAlignSummary,
    /// `None` where the network's dance is too short or has too few beats to measure.
    pub tempo_lock_before: Option<crate::metrics::musicality::TempoLock>,
}

/// Builds the report of `motion` danced to the song `analysis` describes (motion frame 0 at song
/// time 0), with the key poses the user fixed (may be empty).
pub fn build(
    motion: &Motion,
    analysis: &Analysis,
    key_poses: &[KeyPose],
    reference: &ReferenceStats,
) -> Result<Report, MetricsError> {
    let scored = score_dance(motion, &analysis.beat_times, key_poses, reference)?;
    Ok(Report {
        version: REPORT_VERSION,
        fps: motion.fps,
        frames: motion.positions.dim().0,
        duration_s: motion.positions.dim().0 as f64 / motion.fps,
        music_beat_times: scored.music_beats,
        music_tempo_curve: analysis.tempo_curve.clone(),
        kinematic_beat_times: scored.kinematic_beats,
        scores: scored.scores,
        fid_k_curve: fid_k_curve(motion, reference),
        freezing: scored.freezing,
        reference: format!("{} ({} dances)", reference.source, reference.dances.len()),
        model_key_pose_error_cm: None,
        style: None,
        beat_align: None,
        beat_time: None,
        opening_check: None,
        composition: None,
        serving: Vec::new(),
    })
}

/// Writes the report as pretty JSON to `path`.
pub fn write(report: &Report, path: &std::path::Path) -> Result<(), MetricsError> {
    let text = serde_json::to_string_pretty(report)?;
    std::fs::write(path, text).map_err(|source| MetricsError::Io {
        path: path.display().to_string(),
        source,
    })
}
