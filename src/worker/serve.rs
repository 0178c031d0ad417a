//! The stages every dance goes through after its model, shared by jobs and `choreo generate`:
//! the motion stages ([`after_model`]), then export and the report ([`render`]).
use std::path::Path;

use super::WorkerError;
use crate::audio::Analysis;
use crate::models::Cancelled;
use crate::motion::{KeyPose, Motion, MotionStages};
use crate::queue::JobFiles;
use crate::report::preview::{self, Caption};
use crate::report::BeatAlignReport;
use crate::stage::Stage;

/// A dance after the motion stages, with what they knew: the input of [`render`].
pub struct Finished {
    /// Beat-aligned and feet planted: what the export fits its rigid skeleton to.
    pub motion: Motion,
    /// The song's analysis (beats on the dance's clock: motion frame 0 is song time 0).
    pub analysis: Analysis,
    /// The song's length (s), for the preview's time axis.
    pub song_duration_s: f64,
    /// The beat-align stage's summary and the network's tempo lock before it (none where the
    /// stage did not run).
    pub beat_align: Option<BeatAlignReport>,
    /// Whether the feet were planted (and the dance grounded): the export grounds its rigid
    /// skeleton too ([`crate::motion::serve`]).
    pub plant_feet: bool,
    /// The clock the network ran on (a model in beat time), for the report.
    pub beat_time: Option<crate::models::beat_time::BeatTimeUsed>,
    /// What the model's opening check chose, for the report.
    pub opening: Option<crate::models::opening_check::OpeningChosen>,
    /// What a composing model's dance was made of, for the report (set by the caller).
    pub composition: Option<crate::models::beat_graph::Composition>,
    /// Frames the request's seed motion opens the dance on (0 without): the export fits its
    /// skeleton on them ([`crate::motion::serve`]).
    pub seed_frames: usize,
    /// What each stage after the model did, in order; the export's stages follow in the report.
    pub serving: Vec<crate::report::serving::StageTrace>,
}

/// The motion stages after a model ([`crate::motion::after_model`]: beat alignment, then the feet
/// planted), with the network's own tempo lock measured before them for the report. Jobs and
/// `choreo generate` both call it, so both serve the same dance.
/// `seed_motion`: the request's, whose frames open the dance and are kept as they are;
/// `generated`'s clock (`beat_time`), opening check and composition are carried to the report. A
/// composed dance is on the song's beats already, so it is not warped to a changing tempo
/// ([`MotionStages::tempo_follow`]).
pub fn after_model(
    generated: crate::models::Generated,
    analysis: Analysis,
    song_duration_s: f64,
    key_poses: &[KeyPose],
    seed_motion: Option<&Motion>,
    stages: MotionStages,
) -> Result<Finished, WorkerError> {
    let crate::models::Generated {
        motion: model_motion,
        beat_time,
        opening,
        composition,
        style: _,
    } = generated;
    let stages = MotionStages {
        tempo_follow: stages.tempo_follow && composition.is_none(),
        ..stages
    };
    let tempo_lock_before = crate::metrics::musicality::tempo_lock(
        model_motion.positions.view(),
        model_motion.fps,
        &analysis.beat_times,
    );
    // The seed motion is on the dance's clock: its frames are the dance's first.
    let seed_frames =
        seed_motion.map_or(0, |m| (m.duration_s() * model_motion.fps).round() as usize);
    let reference = crate::metrics::reference::ReferenceStats::builtin()?;
    let mut recorder = crate::report::serving::Recorder::new(reference.angle_limits);
    let (motion, summary) = crate::motion::after_model_observed(
        model_motion,
        &analysis.beat_times,
        key_poses,
        seed_frames,
        stages,
        &mut recorder,
    );
    Ok(Finished {
        motion,
        analysis,
        song_duration_s,
        beat_align: summary.map(|summary| BeatAlignReport {
            summary,
            tempo_lock_before,
        }),
        plant_feet: stages.plant_feet,
        beat_time,
        opening,
        composition,
        seed_frames,
        serving: recorder.into_stages(),
    })
}

/// File name of a generate job's report.
pub const REPORT_FILE: &str = "report.json";

/// The last two stages of a dance, shared by jobs and the CLI: export (BVH, JSON, glb) and the
/// report (report.json and the contact sheet preview.png, titled by `caption`), each file written
/// atomically into `dir`. `on_stage` hears each stage as it starts, and may cancel it.
pub fn render(
    dir: &Path,
    finished: &Finished,
    key_poses: &[KeyPose],
    caption: &Caption,
    on_stage: &mut dyn FnMut(Stage) -> Result<(), Cancelled>,
) -> Result<JobFiles, WorkerError> {
    use crate::motion::export::{write_all_rig, write_atomic, BVH_FILE, GLB_FILE, JSON_FILE};
    std::fs::create_dir_all(dir)?;
    on_stage(Stage::Export)?;
    let model_motion = &finished.motion;
    let reference = crate::metrics::reference::ReferenceStats::builtin()?;
    let mut recorder = crate::report::serving::Recorder::new(reference.angle_limits.clone());
    let served = crate::motion::serve_observed(
        model_motion,
        key_poses,
        finished.plant_feet,
        finished.seed_frames,
        &mut recorder,
    )?;
    write_all_rig(&served.rig, dir)?;
    // The report and the preview judge what the user downloads: the rigid skeleton's motion.
    let motion = &served.motion;
    on_stage(Stage::Report)?;
    let mut report = crate::report::build(motion, &finished.analysis, key_poses, &reference)?;
    report.model_key_pose_error_cm = crate::metrics::kinematics::key_pose_error_cm(
        model_motion.positions.view(),
        model_motion.fps,
        key_poses,
    );
    report.style = caption.style.clone();
    report.beat_align = finished.beat_align.clone();
    report.beat_time = finished.beat_time;
    report.opening_check = finished.opening.clone();
    report.composition = finished.composition.clone();
    report.serving = finished.serving.clone();
    report.serving.extend(recorder.into_stages());
    report.scores.rotation_flips = Some(crate::metrics::rotation_flips::RotationFlips::of(
        &served.rig,
    ));
    let text = serde_json::to_vec_pretty(&report)
        .map_err(|e| WorkerError::Export(format!("report.json: {e}")))?;
    write_atomic(&dir.join(REPORT_FILE), &text)?;
    let key_pose_times: Vec<f64> = key_poses.iter().map(|k| k.time_s).collect();
    let sheet = preview::Sheet {
        motion,
        beat_times: &report.music_beat_times,
        key_pose_times: &key_pose_times,
        song_duration_s: finished.song_duration_s,
        caption,
        musicality: &report.scores.musicality,
    };
    let png = preview::render_png(&sheet)
        .map_err(|e| WorkerError::Export(format!("{}: {e}", preview::PREVIEW_FILE)))?;
    write_atomic(&dir.join(preview::PREVIEW_FILE), &png)?;
    Ok(JobFiles {
        files: [
            BVH_FILE,
            JSON_FILE,
            GLB_FILE,
            REPORT_FILE,
            preview::PREVIEW_FILE,
        ]
        .map(String::from)
        .to_vec(),
        style: caption.style.clone(),
        song_cache_bytes: 0,
    })
}
