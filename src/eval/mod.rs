//! `choreo eval`: every model judged by the same numbers, on the test split and on whole songs.
//!
//! Two sections, never mixed:
//! - **Test split**: the test dances' songs, each cut to the span its dance covers.
//!   - **Real**: the test dances, with their own songs.
//!   - **Mismatched real**: each test song paired with a real *train* dance (chosen by the seed),
//!     cropped to the test dance's length: real motion that ignores this music. A rhythm metric
//!     that cannot tell Real from Mismatched real measures nothing.
//!   - two rows per served model: as served (after [`crate::motion::after_model`], the steps
//!     moved onto the beats and the feet planted, and [`crate::motion::serve`], the export's rigid
//!     skeleton: what motion.json holds) and the network's raw output; each dance is generated
//!     once and finished both ways. Every model dance also keeps the network's own musicality
//!     (`musicality_raw`), so the served row shows the tempo lock before and after beat alignment.
//! - **Extra songs**: every audio file of `../shared/audio` (and of each `--songs` folder), whole,
//!   danced by each model; no real dance exists for them, so only model rows.
//!
//! Every model dances every song with seeds `seed, seed+1, …` (`--seeds`, default 2), so the same
//! seeds give the same numbers and the seed sensitivity ([`crate::metrics::physical::seed_distance_m`],
//! per song pair, averaged) is measured. Every row carries the physical-plausibility numbers of
//! [`crate::metrics::physical`] and its plausibility verdict (each criterion as the row's worst
//! dance has it).
//!
//! FID in two protocols: `fid_*_window` fits a Gaussian to every 5-s window of the row (biased
//! by sample size: the Mismatched-real row with one train dance per song scores FID_k 38.9, with
//! 40 per song 2.0); `fid_*_dance` to one whole-dance vector per dance (Bailando's protocol;
//! with 6–12 dances against 37 train dances its covariance is singular, so compare rows of the
//! same size only).
//!
//! Music beats come from [`crate::audio::analyze`] on the whole song and are moved onto the
//! dance's clock (motion frame 0 = song time `start_position / 25`).
pub mod made_from;
mod rows;
mod songs;
pub mod style_control;
pub mod tables;
pub mod tempo;
pub mod tempo_change;

use std::path::{Path, PathBuf};

use rand::seq::SliceRandom;
use rand::SeedableRng;

use crate::audio::{self, AudioError};
use crate::metrics::diversity::Diversity;
use crate::metrics::reference::ReferenceStats;
use crate::metrics::rotation_flips::RotationFlips;
use crate::metrics::score::{score_dance, SetScores};
use crate::metrics::MetricsError;
use crate::models::motion_style::{MotionStyle, StyleError};
use crate::models::{ModelError, ModelId, Registry};
use crate::motion::beat_align::BeatAlignSummary;
use crate::motion::dataset::{Dance, Dataset, Fold};
use crate::motion::{KeyPose, Motion, MotionError};
use crate::report::preview::PreviewError;
use rows::{crop, model_rows, row, Quiet};
use songs::{name_apart, song_segment, songs_in, whole_song, Song};
pub use tables::markdown;

/// Where [`write_reference`] writes the committed, compiled-in statistics (`choreo eval
/// --write-reference`'s default).
pub const REFERENCE_PATH: &str = "src/metrics/reference_train.json";
/// The songs every model dances besides the test split (relative to the repository root).
pub const SHARED_SONGS: &str = "../shared/audio";

/// What `choreo eval` evaluates. `Default` is the committed protocol (the CLI's defaults).
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Model ids to evaluate (e.g. dance-revolution); none means every model served from
    /// `models_dir`.
    pub models: Vec<String>,
    /// Real and Mismatched real only: no model is run.
    pub real_only: bool,
    /// Dataset split whose songs are evaluated (`test` or `train`).
    pub split: String,
    /// More folders of songs (every audio file in each), danced whole by each model beside
    /// [`SHARED_SONGS`].
    pub songs: Vec<PathBuf>,
    /// Leave out [`SHARED_SONGS`] (the test split and `songs` only).
    pub no_shared_songs: bool,
    /// The dance-with-melody folder.
    pub data: PathBuf,
    /// Where trained models live.
    pub models_dir: PathBuf,
    /// First seed (mismatch pairing and generation).
    pub seed: u64,
    /// Dances generated per song and model (seeds seed..seed+N); ≥ 2 gives multimodality and
    /// the seed sensitivity.
    pub seeds: u64,
    /// Key poses given to models that take them, on each test song: this many poses of the real
    /// test dance (root-relative) at frames drawn by the seed after its first second. Extra songs
    /// get none.
    pub key_poses: usize,
    /// Write each generated dance's contact sheet (as served) here as
    /// `<model>_<song>_seed<seed>.png` (the picture jobs serve as preview.png); the tempo
    /// section's copies as `<model>_<song>_<factor>x_seed<seed>.png`.
    pub previews: Option<PathBuf>,
    /// Train dances paired with each test song in the Mismatched-real row.
    pub mismatch_per_song: usize,
    /// Tempo factors every extra song is also danced at (with sox; [`tempo`]); empty: no tempo
    /// section.
    pub tempi: Vec<f64>,
    /// With the train split: only the dances of this fold, the ones a model built with the same
    /// `--hold-out` left out, so that settings are chosen on dances it has not seen and the test
    /// split stays held out.
    pub hold_out: Option<Fold>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            models: Vec::new(),
            real_only: false,
            split: "test".into(),
            songs: Vec::new(),
            no_shared_songs: false,
            data: PathBuf::from(crate::motion::dataset::DEFAULT_ROOT),
            models_dir: PathBuf::from("models"),
            seed: 0,
            seeds: 2,
            key_poses: 0,
            previews: None,
            mismatch_per_song: 1,
            tempi: tempo::TEMPI.to_vec(),
            hold_out: None,
        }
    }
}

impl EvalOptions {
    /// Whether the extra-song section will miss [`SHARED_SONGS`] (asked for, but not there).
    pub fn shared_songs_missing(&self) -> bool {
        !self.real_only && !self.no_shared_songs && !Path::new(SHARED_SONGS).is_dir()
    }
}

/// Everything that can stop `choreo eval`.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    #[error("dataset: {0}")]
    Dataset(#[from] MotionError),
    #[error("unknown split {0:?} (test or train)")]
    UnknownSplit(String),
    #[error("--hold-out {0} leaves out train dances: it needs --split train")]
    HoldOutNeedsTrain(Fold),
    #[error("audio: {0}")]
    Audio(#[from] AudioError),
    #[error("loading models: {0}")]
    Models(ModelError),
    #[error("model {id} not found under {dir}")]
    UnknownModel { id: String, dir: PathBuf },
    /// `model` may carry the style asked for, e.g. `dancenet (waltz)`.
    #[error("{model} on {song}: {source}")]
    Generate {
        model: String,
        song: String,
        source: ModelError,
    },
    #[error("{model} on {song}: export: {source}")]
    Export {
        model: String,
        song: String,
        source: MotionError,
    },
    /// `dance`: the real dance being classified, if it was one.
    #[error("motion style classifier{}: {source}", .dance.as_ref().map(|d| format!(" on {d}")).unwrap_or_default())]
    Classifier {
        dance: Option<String>,
        source: StyleError,
    },
    #[error("{path}: {source}")]
    Preview { path: PathBuf, source: PreviewError },
    #[error("i/o error on {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

impl EvalError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            EvalError::Metrics(e) => e.code(),
            EvalError::Dataset(e) => e.code(),
            EvalError::UnknownSplit(_) => "eval-unknown-split",
            EvalError::HoldOutNeedsTrain(_) => "eval-hold-out-needs-train",
            EvalError::Audio(e) => e.code(),
            EvalError::Models(_) => "eval-models-unavailable",
            EvalError::UnknownModel { .. } => "eval-unknown-model",
            EvalError::Generate { .. } => "eval-generate-failed",
            EvalError::Export { .. } => "eval-export-failed",
            EvalError::Classifier { source, .. } => source.code(),
            EvalError::Preview { source, .. } => source.code(),
            EvalError::Io { .. } => "eval-io",
        }
    }
}

/// One row of the table.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct EvalRow {
    pub name: String,
    /// The set's scores; `scores.mean.verdict` is the row's verdict, with the seed criterion.
    pub scores: SetScores,
    /// Mean over songs of the distance between dances from different seeds.
    pub multimodality: Option<f64>,
    /// Seed sensitivity: the root-relative distance (m) between dances of the same song from
    /// different seeds, per song pair, averaged.
    pub seed_distance_m: Option<f64>,
    /// The smallest seed distance of any song pair (the verdict's value).
    pub seed_distance_min_m: Option<f64>,
    /// The two dances (`song motion`) of the smallest seed distance, to find the pair.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed_distance_min_between: Option<[String; 2]>,
    /// Song sensitivity: the root-relative distance (m) between dances of the same seed on two
    /// different songs, per song pair and seed, averaged (model rows only).
    #[serde(default)]
    pub song_distance_m: Option<f64>,
    /// The smallest such distance (the musicality bar: ≥ 0.15 m; two real dances are 0.34 apart).
    #[serde(default)]
    pub song_distance_min_m: Option<f64>,
    /// The two dances (`song motion`) of the smallest song distance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub song_distance_min_between: Option<[String; 2]>,
    /// The tempo lock, arms and knees of the network's own motion, before the beat-align stage
    /// and the feet (model rows only; `scores.musicality` is the row's motion's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub musicality_raw: Option<crate::metrics::musicality::MusicalitySummary>,
    /// TSMT's A-seq-D, I-seq-D and S-music-D ([`crate::metrics::diversity`]) on z-normalised kinetic
    /// windows; S-music-D only where one song has dances from several seeds.
    #[serde(default)]
    pub diversity: Diversity,
    /// Per-dance detail: what was danced to what.
    pub dances: Vec<EvalDance>,
}

/// One scored dance of a row.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct EvalDance {
    /// The song (test dance id or file name).
    pub song: String,
    /// The motion: a dance id, or `model@seed`.
    pub motion: String,
    pub seconds: f64,
    pub scores: crate::metrics::score::DanceScores,
    /// Model dances: the network's own motion's musicality, before beat alignment and the feet.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub musicality_raw: Option<crate::metrics::musicality::Musicality>,
    /// Served model dances: what the beat-align stage did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beat_align: Option<BeatAlignSummary>,
}

/// Everything `choreo eval` computed.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct EvalResult {
    pub split: String,
    pub seed: u64,
    /// Test-split rows: the test songs only.
    pub rows: Vec<EvalRow>,
    /// The extra songs (file names), danced whole.
    pub extra_songs: Vec<String>,
    /// Model rows on the extra songs.
    pub extra_rows: Vec<EvalRow>,
    /// Models that dance a style asked for: every song (test and extra) in every style.
    #[serde(default)]
    pub style_control: Vec<style_control::StyleControl>,
    /// The motion style classifier on the real test dances (when it and a style model ran).
    #[serde(default)]
    pub real_styles: Option<style_control::RealStyles>,
    /// Each model on every extra song at each of [`EvalOptions::tempi`].
    #[serde(default)]
    pub tempo: Vec<tempo::TempoRow>,
    /// The extra songs of 90 s or more slowed then sped up, as analysed and as each model
    /// danced them (with the tempo section: off with it).
    #[serde(default)]
    pub tempo_change: tempo_change::TempoChange,
    /// What each evaluated model was served from ([`made_from`]).
    #[serde(default)]
    pub made_from: Vec<made_from::MadeFrom>,
}

/// Recomputes the reference statistics from the train split and writes them.
pub fn write_reference(data: &Path, out: &Path) -> Result<ReferenceStats, EvalError> {
    let ds = Dataset::open(data)?;
    let ids = ds.train_ids().to_vec();
    let dances = ds.load_all(&ids)?;
    // Each dance's song beats on the dance's clock, for the musicality figures.
    let mut beats = Vec::with_capacity(dances.len());
    for d in &dances {
        let start = d.song_time_s(0);
        beats.push(
            audio::analyze(&audio::decode_path(&d.audio_path)?)?
                .beat_times
                .iter()
                .map(|t| t - start)
                .collect::<Vec<f64>>(),
        );
    }
    let motions: Vec<Motion> = dances.into_iter().map(|d| d.motion).collect();
    let mut stats = ReferenceStats::compute("dance-with-melody train split", ids, &motions)?;
    let paired: Vec<(&Motion, &[f64])> = motions
        .iter()
        .zip(&beats)
        .map(|(m, b)| (m, b.as_slice()))
        .collect();
    stats.musicality = crate::metrics::musicality::MusicalityReference::compute(&paired);
    stats.write(out)?;
    Ok(stats)
}

/// `model`'s (called `id`) dance of `req` on the song called `song`, and whether the model
/// composed it on the song's beats (what [`as_served`] needs to know).
pub(super) fn generate(
    model: &dyn crate::models::DanceModel,
    id: &str,
    song: &str,
    req: &crate::models::GenerateRequest<'_>,
    progress: &mut dyn crate::models::Progress,
) -> Result<(Motion, bool), EvalError> {
    let generated = model
        .generate(req, progress)
        .map_err(|source| EvalError::Generate {
            model: id.into(),
            song: song.into(),
            source,
        })?;
    let composed = generated.composition.is_some();
    Ok((generated.motion, composed))
}

/// A model's motion as a user downloads it: its steps moved onto the song's beats and its feet
/// planted (the motion stages every job runs, [`crate::motion::after_model`]), then fitted to the
/// export's rigid skeleton with the key poses as anchors (what motion.json holds). `beats` are
/// the song's on the dance's clock; `composed`: the model composed the dance on those beats (no
/// tempo warp, [`crate::motion::MotionStages::tempo_follow`]). Also what the beat-align stage did.
pub(super) fn as_served(
    raw: Motion,
    composed: bool,
    keys: &[KeyPose],
    beats: &[f64],
) -> Result<(Motion, BeatAlignSummary), MotionError> {
    as_served_measured(raw, composed, keys, beats).map(|(m, summary, _)| (m, summary))
}

/// As [`as_served`], with the rotation flips of the exported rig (what motion.bvh carries).
pub(super) fn as_served_measured(
    raw: Motion,
    composed: bool,
    keys: &[KeyPose],
    beats: &[f64],
) -> Result<(Motion, BeatAlignSummary, RotationFlips), MotionError> {
    let stages = crate::motion::MotionStages {
        tempo_follow: !composed,
        ..Default::default()
    };
    let (finished, summary) = crate::motion::after_model(raw, beats, keys, 0, stages);
    let served = crate::motion::serve(&finished, keys, true, 0)?;
    Ok((
        served.motion,
        summary.unwrap_or_default(),
        RotationFlips::of(&served.rig),
    ))
}

/// Runs the evaluation and returns the rows (printing nothing; without [`SHARED_SONGS`] the
/// extra-song section covers `songs` only: see [`EvalOptions::shared_songs_missing`]).
pub fn evaluate(args: &EvalOptions) -> Result<EvalResult, EvalError> {
    let reference = ReferenceStats::builtin()?;
    let ds = Dataset::open(&args.data)?;
    let ids: Vec<String> = match (args.split.as_str(), args.hold_out) {
        ("test", None) => ds.test_ids().to_vec(),
        ("test", Some(fold)) => return Err(EvalError::HoldOutNeedsTrain(fold)),
        ("train", None) => ds.train_ids().to_vec(),
        ("train", Some(fold)) => ds
            .train_ids()
            .iter()
            .zip(fold.holds_ids(ds.train_ids()))
            .filter(|(_, held)| *held)
            .map(|(id, _)| id.clone())
            .collect(),
        (other, _) => return Err(EvalError::UnknownSplit(other.to_string())),
    };
    let eval_dances = ds.load_all(&ids)?;
    let songs: Vec<Song> = eval_dances
        .iter()
        .map(song_segment)
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();

    // Real: each dance with its own music.
    let mut real = Vec::new();
    for (d, s) in eval_dances.iter().zip(&songs) {
        let mut sc = score_dance(&d.motion, &s.beats, &[], &reference)?;
        // Its rotations as `choreo export` writes them.
        sc.scores.rotation_flips = Some(RotationFlips::of(
            &crate::motion::export::prepare_with_root(&d.motion, d.center.view())?,
        ));
        real.push((
            EvalDance {
                song: s.name.clone(),
                motion: d.id.clone(),
                seconds: d.motion.duration_s(),
                scores: sc.scores.clone(),
                musicality_raw: None,
                beat_align: None,
            },
            sc,
        ));
    }
    rows.push(row("Real", real, None, &reference));

    // Mismatched real: train dances (never the song's own) on each song, seeded.
    let train = ds.load_all(ds.train_ids())?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(args.seed);
    let mut mism = Vec::new();
    for (d, s) in eval_dances.iter().zip(&songs) {
        let t = d.motion.num_frames();
        let mut candidates: Vec<&Dance> = train
            .iter()
            .filter(|o| o.id != d.id && o.motion.num_frames() >= t)
            .collect();
        if candidates.is_empty() {
            // No train dance is as long: take the longest ones and score the shorter span.
            candidates = train.iter().filter(|o| o.id != d.id).collect();
            candidates.sort_by_key(|o| std::cmp::Reverse(o.motion.num_frames()));
            candidates.truncate(args.mismatch_per_song.max(1));
        }
        candidates.sort_by(|a, b| a.id.cmp(&b.id));
        for o in candidates.choose_multiple(&mut rng, args.mismatch_per_song.max(1)) {
            let m = crop(&o.motion, t);
            let sc = score_dance(&m, &s.beats, &[], &reference)?;
            mism.push((
                EvalDance {
                    song: s.name.clone(),
                    motion: o.id.clone(),
                    seconds: m.duration_s(),
                    scores: sc.scores.clone(),
                    musicality_raw: None,
                    beat_align: None,
                },
                sc,
            ));
        }
    }
    rows.push(row("Mismatched real", mism, None, &reference));

    // Models, on the test songs and on the extra songs.
    let mut extra_rows = Vec::new();
    let mut extra_names = Vec::new();
    let (mut style_control, mut real_styles, mut tempo_rows) = (Vec::new(), None, Vec::new());
    let mut tempo_change_section = tempo_change::TempoChange::default();
    let mut made = Vec::new();
    if !args.real_only {
        let registry = Registry::load(&args.models_dir).map_err(EvalError::Models)?;
        let mut folders: Vec<PathBuf> = Vec::new();
        if !args.no_shared_songs {
            let shared = PathBuf::from(SHARED_SONGS);
            // Missing, it is left out (the CLI says so: `shared_songs_missing`).
            if shared.is_dir() {
                folders.push(shared);
            }
        }
        folders.extend(args.songs.iter().cloned());
        let (mut extra, mut extra_paths) = (Vec::new(), Vec::new());
        for dir in &folders {
            for p in songs_in(dir)? {
                extra.push(whole_song(&p)?);
                extra_paths.push(p);
            }
        }
        name_apart(&mut extra, &extra_paths);
        extra_names = extra.iter().map(|s| s.name.clone()).collect();
        // The songs that speed up in the middle, made once for every model.
        let change_dir = tempfile::tempdir().map_err(|source| EvalError::Io {
            path: std::env::temp_dir(),
            source,
        })?;
        let mut changed = Vec::new();
        if !args.tempi.is_empty() {
            for (p, name) in extra_paths.iter().zip(&extra_names) {
                if let Some(j) = tempo_change::joined(p, name, change_dir.path())? {
                    tempo_change_section.songs.push(j.song.clone());
                    changed.push(j);
                }
            }
        }
        let ids: Vec<String> = if args.models.is_empty() {
            registry.list().into_iter().map(|m| m.id.0).collect()
        } else {
            args.models.clone()
        };
        // The motion style classifier, for style control (absent: distances and verdicts only).
        let classifier_dir = args.models_dir.join(crate::models::motion_style::ID);
        let classifier = if classifier_dir.is_dir() {
            Some(
                MotionStyle::load(&classifier_dir).map_err(|source| EvalError::Classifier {
                    dance: None,
                    source,
                })?,
            )
        } else {
            None
        };
        for id in &ids {
            let dir = args.models_dir.join(id);
            made.push(
                made_from::MadeFrom::of(id, &dir)
                    .map_err(|source| EvalError::Io { path: dir, source })?,
            );
            let model =
                registry
                    .get(&ModelId(id.clone()))
                    .ok_or_else(|| EvalError::UnknownModel {
                        id: id.clone(),
                        dir: args.models_dir.clone(),
                    })?;
            let r = model_rows(
                model.as_ref(),
                id,
                (&songs, &eval_dances),
                &extra,
                args,
                &reference,
            )?;
            rows.extend(r.test);
            if let Some(e) = r.extra {
                extra_rows.extend(e);
            }
            if !args.tempi.is_empty() && !extra_paths.is_empty() {
                tempo_rows.push(tempo::tempo_row(
                    model.as_ref(),
                    id,
                    &extra_paths,
                    &extra_names,
                    args,
                    &reference,
                )?);
            }
            if !changed.is_empty() {
                tempo_change_section.rows.push(tempo_change::row(
                    model.as_ref(),
                    id,
                    &changed,
                    args.seed,
                    args.seeds,
                )?);
            }
            if model.info().capabilities.style {
                let all: Vec<style_control::StyleSong<'_>> = songs
                    .iter()
                    .chain(&extra)
                    .map(|s| style_control::StyleSong {
                        name: &s.name,
                        audio: &s.audio,
                        beats: &s.beats,
                    })
                    .collect();
                style_control.push(style_control::style_control(
                    model.as_ref(),
                    id,
                    &all,
                    args.seed,
                    classifier.as_ref(),
                    &reference,
                    &mut Quiet,
                )?);
            }
        }
        if let (Some(c), false) = (&classifier, style_control.is_empty()) {
            let real: Vec<(&str, &Motion)> = eval_dances
                .iter()
                .map(|d| (d.id.as_str(), &d.motion))
                .collect();
            real_styles = Some(style_control::real_styles(c, &real)?);
        }
    }
    Ok(EvalResult {
        split: match args.hold_out {
            Some(fold) => format!("{} (fold {fold} held out)", args.split),
            None => args.split.clone(),
        },
        seed: args.seed,
        rows,
        extra_songs: extra_names,
        extra_rows,
        style_control,
        real_styles,
        tempo: tempo_rows,
        tempo_change: tempo_change_section,
        made_from: made,
    })
}
