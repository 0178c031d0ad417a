//! `choreo eval`: every model judged by the same numbers, on the test split and on whole songs.
//!
//! Two sections, never mixed:
//! - **Test split**: the test dances' songs, each cut to the span its dance covers.
//!   - **Real**: the test dances, with their own songs.
//!   - **Mismatched real**: each test song paired with a real *train* dance (chosen by the seed),
//!     cropped to the test dance's length: real motion that ignores this music. A rhythm metric
//!     that cannot tell Real from Mismatched real measures nothing.
//!   - two rows per served model: as served (after [`crate::motion::finish`], feet planted, and
//!     the export's rigid skeleton: what motion.json holds) and
//!     the network's raw output; each dance is generated once and finished both ways.
//! - **Extra songs**: every audio file of `../shared/audio` (and of each `--songs` folder), whole,
//!   danced by each model; no real dance exists for them, so only model rows.
//!
//! Every model dances every song with seeds `seed, seed+1, …` (`--seeds`, default 2), so the same
//! seeds give the same numbers and the seed sensitivity ([`crate::metrics::physical::seed_distance_m`],
//! per song pair, averaged) is measured. Every row carries the physical-plausibility numbers of
//! [`crate::metrics::physical`] and issue 10's verdict (each criterion as the row's worst dance has it).
//!
//! FID in two protocols: `fid_*_window` fits a Gaussian to every 5-s window of the row (biased
//! by sample size: the Mismatched-real row with one train dance per song scores FID_k 38.9, with
//! 40 per song 2.0); `fid_*_dance` to one whole-dance vector per dance (Bailando's protocol;
//! with 6–12 dances against 37 train dances its covariance is singular, so compare rows of the
//! same size only).
//!
//! Music beats come from [`crate::audio::analyze`] on the whole song and are moved onto the
//! dance's clock (motion frame 0 = song time `start_position / 25`).
pub mod style_control;

use std::path::{Path, PathBuf};

use rand::seq::SliceRandom;
use rand::SeedableRng;

use crate::metrics::diversity::{diversity, Diversity};
use crate::metrics::physical::{seed_distance_m, Criterion, PhysicalScores, Verdict};
use crate::metrics::reference::ReferenceStats;
use crate::metrics::score::{multimodality, score_dance, score_set, ScoredDance, SetScores};
use crate::metrics::MetricsError;
use crate::audio::{self, DecodedAudio};
use crate::models::{Cancelled, GenerateRequest, ModelId, Progress, Registry};
use crate::motion::dataset::{Dance, Dataset};
use crate::motion::{KeyPose, Motion, MOTION_FPS};

/// Where `--write-reference` writes by default (the committed, compiled-in file).
pub const REFERENCE_PATH: &str = "src/metrics/reference_train.json";
/// The songs every model dances besides the test split (relative to the repository root).
pub const SHARED_SONGS: &str = "../shared/audio";

/// Arguments of `choreo eval`.
#[derive(Clone, Debug, clap::Args)]
pub struct EvalArgs {
    /// Model ids to evaluate (e.g. dance-revolution); none means every model served from
    /// --models-dir.
    pub models: Vec<String>,
    /// Real and Mismatched real only: no model is run.
    #[arg(long)]
    pub real_only: bool,
    /// Dataset split whose songs are evaluated.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// More folders of songs (every audio file in each), danced whole by each model beside
    /// ../shared/audio.
    #[arg(long)]
    pub songs: Vec<PathBuf>,
    /// Leave out ../shared/audio (the test split and --songs only).
    #[arg(long)]
    pub no_shared_songs: bool,
    /// Write the full results as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// The dance-with-melody folder.
    #[arg(long, default_value = crate::motion::dataset::DEFAULT_ROOT)]
    pub data: PathBuf,
    /// Where trained models live.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// First seed (mismatch pairing and generation).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Dances generated per song and model (seeds seed..seed+N); ≥ 2 gives multimodality and
    /// the seed sensitivity.
    #[arg(long, default_value_t = 2)]
    pub seeds: u64,
    /// Key poses given to models that take them, on each test song: this many poses of the real
    /// test dance (root-relative) at frames drawn by the seed after its first second. Extra songs
    /// get none. The key-pose error column then shows how closely the dances pass through them.
    #[arg(long, default_value_t = 0)]
    pub key_poses: usize,
    /// Write each generated dance's contact sheet (as served) here as
    /// `<model>_<song>_seed<seed>.png` (the picture jobs serve as preview.png).
    #[arg(long, value_name = "DIR")]
    pub previews: Option<PathBuf>,
    /// Train dances paired with each test song in the Mismatched-real row.
    #[arg(long, default_value_t = 1)]
    pub mismatch_per_song: usize,
    /// Recompute the reference statistics from the train split, write them to
    /// src/metrics/reference_train.json (or --reference-out) and exit.
    #[arg(long)]
    pub write_reference: bool,
    /// Output path for --write-reference.
    #[arg(long, default_value = REFERENCE_PATH)]
    pub reference_out: PathBuf,
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
}

/// A song on a dance's clock: the audio of the segment and the beats within it.
struct Song {
    name: String,
    audio: DecodedAudio,
    /// Beat times in seconds from the segment start.
    beats: Vec<f64>,
}

fn audio_err(e: audio::AudioError) -> MetricsError {
    MetricsError::NotEnoughData(format!("audio: {e}"))
}

/// The test dance's song cut to the span the dance covers, with beats from the whole song.
fn song_segment(d: &Dance) -> Result<Song, MetricsError> {
    let full = audio::decode_path(&d.audio_path).map_err(audio_err)?;
    let analysis = audio::analyze(&full).map_err(audio_err)?;
    let start = d.song_time_s(0);
    let dur = d.motion.duration_s();
    let sr = full.sample_rate as f64;
    let a = ((start * sr).round() as usize).min(full.samples.len());
    let b = (((start + dur) * sr).round() as usize).min(full.samples.len());
    let audio = DecodedAudio { samples: full.samples[a..b].to_vec(), duration_s: (b - a) as f64 / sr, ..full };
    let beats = analysis.beat_times.iter().map(|t| t - start).filter(|t| *t >= 0.0 && *t <= dur).collect();
    Ok(Song { name: d.id.clone(), audio, beats })
}

/// An extra song, whole.
fn whole_song(path: &Path) -> Result<Song, MetricsError> {
    let audio = audio::decode_path(path).map_err(audio_err)?;
    let analysis = audio::analyze(&audio).map_err(audio_err)?;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(Song { name, audio, beats: analysis.beat_times })
}

/// A progress sink for the CLI: never cancels.
struct Quiet;
impl Progress for Quiet {
    fn report(&mut self, _stage: &str, _fraction: f32) -> Result<(), Cancelled> {
        Ok(())
    }
}

fn crop(m: &Motion, frames: usize) -> Motion {
    let n = frames.min(m.positions.dim().0);
    Motion { fps: m.fps, positions: m.positions.slice(ndarray::s![..n, .., ..]).to_owned() }
}

/// A row of scored dances; `per_song` groups the indices of dances of one song (different
/// seeds), with their motions, for multimodality and the seed distance.
fn row(name: &str, scored: Vec<(EvalDance, ScoredDance)>, per_song: Option<Vec<Vec<(usize, Motion)>>>, reference: &ReferenceStats) -> EvalRow {
    let dances: Vec<ScoredDance> = scored.iter().map(|(_, s)| s.clone()).collect();
    let mut scores = score_set(&dances, reference);
    // The paper's diversity measures: dances grouped by song (each dance alone without groups).
    let normed: Vec<Vec<Vec<f64>>> = dances.iter().map(|s| s.features.kinetic.iter().map(|r| reference.kinetic.normalise(r)).collect()).collect();
    let song_groups: Vec<Vec<usize>> = match &per_song {
        Some(groups) => groups.iter().map(|g| g.iter().map(|(i, _)| *i).collect()).collect(),
        None => (0..dances.len()).map(|i| vec![i]).collect(),
    };
    let by_song: Vec<Vec<&[Vec<f64>]>> = song_groups.iter().map(|g| g.iter().map(|&i| normed[i].as_slice()).collect()).collect();
    let diversity_v = diversity(&by_song);
    let (mut multimodality_v, mut seed_mean, mut seed_min) = (None, None, None);
    if let Some(groups) = per_song {
        let g: Vec<Vec<&ScoredDance>> = groups.iter().map(|ix| ix.iter().map(|(i, _)| &dances[*i]).collect()).collect();
        multimodality_v = multimodality(&g, reference);
        let per_pair: Vec<f64> = groups
            .iter()
            .flat_map(|grp| {
                let mut d = Vec::new();
                for a in 0..grp.len() {
                    for b in a + 1..grp.len() {
                        d.push(seed_distance_m(&grp[a].1, &grp[b].1));
                    }
                }
                d
            })
            .filter(|x| !x.is_nan())
            .collect();
        if !per_pair.is_empty() {
            seed_mean = Some(per_pair.iter().sum::<f64>() / per_pair.len() as f64);
            seed_min = per_pair.iter().copied().reduce(f64::min);
        }
        scores.mean.verdict = scores.mean.verdict.clone().with_seed_distance(seed_min);
    }
    EvalRow {
        name: name.into(),
        scores,
        multimodality: multimodality_v,
        seed_distance_m: seed_mean,
        seed_distance_min_m: seed_min,
        diversity: diversity_v,
        dances: scored.into_iter().map(|(e, _)| e).collect(),
    }
}

/// Recomputes the reference statistics from the train split and writes them.
pub fn write_reference(data: &Path, out: &Path) -> Result<ReferenceStats, MetricsError> {
    let ds = Dataset::open(data).map_err(|e| MetricsError::Reference(e.to_string()))?;
    let ids = ds.train_ids().to_vec();
    let dances = ds.load_all(&ids).map_err(|e| MetricsError::Reference(e.to_string()))?;
    let motions: Vec<Motion> = dances.into_iter().map(|d| d.motion).collect();
    let stats = ReferenceStats::compute("dance-with-melody train split", ids, &motions)?;
    stats.write(out)?;
    Ok(stats)
}

/// The audio files of a folder, sorted by name.
fn songs_in(dir: &Path) -> Result<Vec<PathBuf>, MetricsError> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| MetricsError::Io { path: dir.display().to_string(), source })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && audio::decode_path(p).is_ok())
        .collect();
    paths.sort();
    Ok(paths)
}

/// The rows of one model: as served (feet planted) and as the network made them, on the test
/// songs and on the extra songs. Each dance is generated once and finished both ways.
struct ModelRows {
    test: [EvalRow; 2],
    extra: Option<[EvalRow; 2]>,
}

/// A model's dances of a list of songs, finished both ways, grouped by song.
#[derive(Default)]
struct Danced {
    scored: [Vec<(EvalDance, ScoredDance)>; 2],
    per_song: [Vec<Vec<(usize, Motion)>>; 2],
}

fn dance_songs(
    model: &dyn crate::models::DanceModel,
    id: &str,
    songs: &[Song],
    keys_of: impl Fn(usize) -> Vec<KeyPose>,
    args: &EvalArgs,
    reference: &ReferenceStats,
) -> Result<Danced, MetricsError> {
    let mut out = Danced::default();
    for (i, s) in songs.iter().enumerate() {
        let keys = keys_of(i);
        let mut groups: [Vec<(usize, Motion)>; 2] = Default::default();
        for seed in args.seed..args.seed + args.seeds.max(1) {
            let req = GenerateRequest { key_poses: &keys, ..GenerateRequest::plain(&s.audio, seed) };
            let raw = model.generate(&req, &mut Quiet).map_err(|e| MetricsError::Reference(format!("{id} on {}: {e}", s.name)))?.motion;
            // The motion stage every job runs (feet planted), and the network's motion as it came.
            // Served: planted and exported through the rigid skeleton, as motion.json holds it.
            let served = as_served(raw.clone(), &keys).map_err(|e| MetricsError::Reference(format!("{id} on {}: export: {e}", s.name)))?;
            let finished = [served, crate::motion::finish(raw, false)];
            if let Some(dir) = &args.previews {
                write_preview(dir, id, s, seed, &finished[0], &keys)?;
            }
            for (v, m) in finished.into_iter().enumerate() {
                let sc = score_dance(&m, &s.beats, &keys, reference)?;
                groups[v].push((out.scored[v].len(), m.clone()));
                let e = EvalDance { song: s.name.clone(), motion: format!("{id}@{seed}"), seconds: m.duration_s(), scores: sc.scores.clone() };
                out.scored[v].push((e, sc));
            }
        }
        for (v, g) in groups.into_iter().enumerate() {
            out.per_song[v].push(g);
        }
    }
    Ok(out)
}

/// A model's motion as a user downloads it: feet planted (the motion stage every job runs), then
/// fitted to the export's rigid skeleton with the key poses as anchors (what motion.json holds).
fn as_served(raw: Motion, keys: &[KeyPose]) -> Result<Motion, crate::motion::MotionError> {
    Ok(crate::motion::serve(&crate::motion::finish(raw, true), keys)?.motion)
}

/// Names of the two rows of a model.
fn row_names(base: &str) -> [String; 2] {
    [base.to_string(), format!("{base} (raw network output, feet not planted)")]
}

fn rows_of(d: Danced, names: &[String; 2], reference: &ReferenceStats) -> [EvalRow; 2] {
    let Danced { scored: [s0, s1], per_song: [g0, g1] } = d;
    [row(&names[0], s0, Some(g0), reference), row(&names[1], s1, Some(g1), reference)]
}

fn model_rows(
    model: &dyn crate::models::DanceModel,
    id: &str,
    test: (&[Song], &[Dance]),
    extra: &[Song],
    args: &EvalArgs,
    reference: &ReferenceStats,
) -> Result<ModelRows, MetricsError> {
    let keyed = args.key_poses > 0 && model.info().capabilities.key_poses;
    let (songs, dances) = test;
    let keys_of = |i: usize| if keyed { key_poses_of(&dances[i], args.key_poses, args.seed + i as u64) } else { Vec::new() };
    let base = if keyed { format!("{id} + {} key poses", args.key_poses) } else { id.to_string() };
    let test_rows = rows_of(dance_songs(model, id, songs, keys_of, args, reference)?, &row_names(&base), reference);
    let extra_rows = if extra.is_empty() {
        None
    } else {
        Some(rows_of(dance_songs(model, id, extra, |_| Vec::new(), args, reference)?, &row_names(id), reference))
    };
    Ok(ModelRows { test: test_rows, extra: extra_rows })
}

/// Runs the evaluation and returns the rows (printing nothing but a note for a missing
/// ../shared/audio).
pub fn evaluate(args: &EvalArgs) -> Result<EvalResult, MetricsError> {
    let reference = ReferenceStats::builtin()?;
    let ds = Dataset::open(&args.data).map_err(|e| MetricsError::Reference(e.to_string()))?;
    let ids: Vec<String> = match args.split.as_str() {
        "test" => ds.test_ids().to_vec(),
        "train" => ds.train_ids().to_vec(),
        other => return Err(MetricsError::NotEnoughData(format!("unknown split {other:?} (test or train)"))),
    };
    let eval_dances = ds.load_all(&ids).map_err(|e| MetricsError::Reference(e.to_string()))?;
    let songs: Vec<Song> = eval_dances.iter().map(song_segment).collect::<Result<_, _>>()?;
    let mut rows = Vec::new();

    // Real: each dance with its own music.
    let mut real = Vec::new();
    for (d, s) in eval_dances.iter().zip(&songs) {
        let sc = score_dance(&d.motion, &s.beats, &[], &reference)?;
        real.push((EvalDance { song: s.name.clone(), motion: d.id.clone(), seconds: d.motion.duration_s(), scores: sc.scores.clone() }, sc));
    }
    rows.push(row("Real", real, None, &reference));

    // Mismatched real: train dances (never the song's own) on each song, seeded.
    let train = ds.load_all(ds.train_ids()).map_err(|e| MetricsError::Reference(e.to_string()))?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(args.seed);
    let mut mism = Vec::new();
    for (d, s) in eval_dances.iter().zip(&songs) {
        let t = d.motion.num_frames();
        let mut candidates: Vec<&Dance> = train.iter().filter(|o| o.id != d.id && o.motion.num_frames() >= t).collect();
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
            mism.push((EvalDance { song: s.name.clone(), motion: o.id.clone(), seconds: m.duration_s(), scores: sc.scores.clone() }, sc));
        }
    }
    rows.push(row("Mismatched real", mism, None, &reference));

    // Models, on the test songs and on the extra songs.
    let mut extra_rows = Vec::new();
    let mut extra_names = Vec::new();
    let (mut style_control, mut real_styles) = (Vec::new(), None);
    if !args.real_only {
        let registry = Registry::load(&args.models_dir).map_err(|e| MetricsError::Reference(format!("loading models: {e}")))?;
        let mut folders: Vec<PathBuf> = Vec::new();
        if !args.no_shared_songs {
            let shared = PathBuf::from(SHARED_SONGS);
            if shared.is_dir() {
                folders.push(shared);
            } else {
                eprintln!("note: {SHARED_SONGS} not found; the extra-song section covers --songs only");
            }
        }
        folders.extend(args.songs.iter().cloned());
        let mut extra = Vec::new();
        for dir in &folders {
            for p in songs_in(dir)? {
                extra.push(whole_song(&p)?);
            }
        }
        extra_names = extra.iter().map(|s| s.name.clone()).collect();
        let ids: Vec<String> = if args.models.is_empty() { registry.list().into_iter().map(|m| m.id.0).collect() } else { args.models.clone() };
        // The motion style classifier, for style control (absent: distances and verdicts only).
        let classifier_dir = args.models_dir.join(crate::models::motion_style::ID);
        let classifier = if classifier_dir.is_dir() { Some(crate::models::motion_style::MotionStyle::load(&classifier_dir).map_err(|e| MetricsError::Reference(format!("motion style classifier: {e}")))?) } else { None };
        for id in &ids {
            let model = registry
                .get(&ModelId(id.clone()))
                .ok_or_else(|| MetricsError::Reference(format!("model {id} not found under {}", args.models_dir.display())))?;
            let r = model_rows(model.as_ref(), id, (&songs, &eval_dances), &extra, args, &reference)?;
            rows.extend(r.test);
            if let Some(e) = r.extra {
                extra_rows.extend(e);
            }
            if model.info().capabilities.style {
                let all: Vec<style_control::StyleSong<'_>> =
                    songs.iter().chain(&extra).map(|s| style_control::StyleSong { name: &s.name, audio: &s.audio, beats: &s.beats }).collect();
                style_control.push(style_control::style_control(model.as_ref(), id, &all, args.seed, classifier.as_ref(), &reference, &mut Quiet)?);
            }
        }
        if let (Some(c), false) = (&classifier, style_control.is_empty()) {
            let real: Vec<(&str, &Motion)> = eval_dances.iter().map(|d| (d.id.as_str(), &d.motion)).collect();
            real_styles = Some(style_control::real_styles(c, &real)?);
        }
    }
    Ok(EvalResult { split: args.split.clone(), seed: args.seed, rows, extra_songs: extra_names, extra_rows, style_control, real_styles })
}

/// Writes the contact sheet of `model`'s dance to `song` with `seed` into `dir`.
fn write_preview(dir: &Path, model: &str, song: &Song, seed: u64, motion: &Motion, keys: &[KeyPose]) -> Result<(), MetricsError> {
    use crate::report::preview::{write_png, Caption, Sheet};
    let stem = song.name.rsplit_once('.').map_or(song.name.as_str(), |(stem, _)| stem);
    let name: String = format!("{model}_{stem}_seed{seed}.png")
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' })
        .collect();
    std::fs::create_dir_all(dir).map_err(|source| MetricsError::Io { path: dir.display().to_string(), source })?;
    let caption = Caption { model: model.to_string(), seed, song: Some(song.name.clone()), style: None };
    let key_pose_times: Vec<f64> = keys.iter().map(|k| k.time_s).collect();
    let sheet = Sheet { motion, beat_times: &song.beats, key_pose_times: &key_pose_times, song_duration_s: song.audio.duration_s, caption: &caption };
    let path = dir.join(name);
    write_png(&path, &sheet).map_err(|e| MetricsError::Io { path: path.display().to_string(), source: std::io::Error::other(e) })
}

/// `n` poses of a real dance (root-relative, metres) at distinct frames after its first second,
/// drawn by `seed`, in time order.
fn key_poses_of(d: &Dance, n: usize, seed: u64) -> Vec<KeyPose> {
    let rel = d.root_relative();
    let first = MOTION_FPS as usize;
    let mut frames: Vec<usize> = (first..d.motion.num_frames()).collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    frames.shuffle(&mut rng);
    frames.truncate(n);
    frames.sort_unstable();
    frames
        .into_iter()
        .map(|f| KeyPose {
            time_s: f as f64 / d.motion.fps,
            joints: (0..rel.dim().1).map(|j| [0, 1, 2].map(|a| f64::from(rel[[f, j, a]]))).collect(),
        })
        .collect()
}

fn f(x: f64) -> String {
    if x.is_nan() {
        "–".into()
    } else {
        format!("{x:.3}")
    }
}

fn f2(x: f64) -> String {
    if x.is_nan() {
        "–".into()
    } else {
        format!("{x:.2}")
    }
}

fn opt(x: Option<f64>) -> String {
    x.map(f).unwrap_or_else(|| "–".into())
}

/// The failing criteria with their values, or "pass".
fn verdict_cell(v: &Verdict) -> String {
    let fails: Vec<String> = v
        .criteria
        .iter()
        .filter(|c: &&Criterion| c.pass == Some(false))
        .map(|c| format!("✗ {} {}", c.name, c.value.map(f2).unwrap_or_default()))
        .collect();
    if fails.is_empty() {
        "pass".into()
    } else {
        fails.join("; ")
    }
}

/// The scores table of a set of rows.
fn scores_table(rows: &[EvalRow]) -> String {
    let mut out = String::from(
        "| Motion | n | BAS FACT ↑ | (chance) | BAS Bailando ↑ | Coverage | Hit rate ↑ | Rhythm hit ↑ | Beat F ↑ | FID_k window ↓ | FID_g window ↓ | FID_k dance ↓ | FID_g dance ↓ | Div_k | Div_g | S_cv ↓ | Skate ↓ | Authentic ↑ | Coherent ↑ | Multimodality |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let m = &r.scores.mean;
        let cells = [
            r.name.clone(),
            r.scores.dances.to_string(),
            f(m.rhythm.bas_fact),
            f(m.rhythm.bas_fact_chance),
            f(m.rhythm.bas_bailando),
            f(m.rhythm.beat_coverage),
            f(m.rhythm.beat_hit_rate),
            f(m.rhythm.rhythm_hit),
            f(m.rhythm.f_measure),
            f(r.scores.fid_k_window),
            f(r.scores.fid_g_window),
            f(r.scores.fid_k_dance),
            f(r.scores.fid_g_dance),
            f(r.scores.div_k),
            f(r.scores.div_g),
            f(m.smoothness_cv),
            f(m.foot_skating.skate_ratio),
            f(m.plausibility.authenticity),
            f(m.plausibility.coherence),
            opt(r.multimodality),
        ];
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out
}

const PHYSICAL_HEADER: &str = "| Motion | n | Lowest foot p5 / median / p95 m | Below −5 cm | Deepest m | Accel median / p99 / p99.9 / max m/s² | Key pop max m/s² ↓ | Speed m/s | × real | Freeze L/F | Seed Δ m (min) | Key err cm (worst) ↓ | Verdict | Dances passing |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";

/// TSMT's own measures (Li et al. 2020): its three diversities, authenticity and coherence, and
/// beat precision/recall/F of FACT motion beats against music beats (±0.1 s).
fn paper_table(rows: &[EvalRow]) -> String {
    let mut out = String::from("| Motion | n | A-seq-D | I-seq-D | S-music-D | Authentic ↑ | Coherent ↑ | Beat P | Beat R | Beat F (TSMT) |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let m = &r.scores.mean;
        let d = &r.diversity;
        let b = &m.rhythm.beat_prf;
        let cells = [
            r.name.clone(),
            r.scores.dances.to_string(),
            opt(d.a_seq_d),
            opt(d.i_seq_d),
            opt(d.s_music_d),
            f(m.plausibility.authenticity),
            f(m.plausibility.coherence),
            f(b.precision),
            f(b.recall),
            f(b.f),
        ];
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out
}

/// One line of the physical table: `tail` is the seed distance, key error, verdict and passing cells.
fn physical_cells(name: &str, n: usize, p: &PhysicalScores, freeze: f64, tail: [String; 4]) -> String {
    let [seeds, key_err, verdict, passing] = tail;
    let cells = [
        name.to_string(),
        n.to_string(),
        format!("{} / {} / {}", f2(p.lowest_foot_m.p5), f2(p.lowest_foot_m.median), f2(p.lowest_foot_m.p95)),
        format!("{:.1} %", 100.0 * p.below_floor_share),
        f2(p.deepest_m),
        format!("{} / {} / {} / {}", f2(p.acceleration_m_s2.median), f2(p.acceleration_m_s2.p99), f2(p.acceleration_m_s2.p99_9), f2(p.acceleration_m_s2.max)),
        p.key_pose_pops_m_s2.iter().copied().reduce(f64::max).map(f2).unwrap_or_else(|| "–".into()),
        f2(p.mean_speed_m_s),
        f2(p.speed_ratio),
        f(freeze),
        seeds,
        key_err,
        verdict,
        passing,
    ];
    format!("| {} |\n", cells.join(" | "))
}

/// The physical-plausibility table of a set of rows, under the real train figures.
fn physical_table(rows: &[EvalRow], reference: Option<&ReferenceStats>) -> String {
    let mut out = String::from(PHYSICAL_HEADER);
    if let Some(r) = reference {
        let p = &r.physical;
        let name = format!("Real train (reference; speed per dance {:.2}–{:.2})", p.mean_speed_range_m_s[0], p.mean_speed_range_m_s[1]);
        out.push_str(&physical_cells(&name, r.dances.len(), &p.pooled, f64::NAN, ["–".into(), "–".into(), "–".into(), "–".into()]));
    }
    for r in rows {
        let m = &r.scores.mean;
        let seeds = match (r.seed_distance_m, r.seed_distance_min_m) {
            (Some(a), Some(b)) => format!("{} ({})", f2(a), f2(b)),
            _ => "–".into(),
        };
        let passing = format!("{}/{}", r.scores.dances_passing, r.scores.dances);
        let key_err = worst_key_error(r).map(f2).unwrap_or_else(|| "–".into());
        out.push_str(&physical_cells(&r.name, r.scores.dances, &m.physical, m.freezing_ratio, [seeds, key_err, verdict_cell(&m.verdict), passing]));
    }
    out
}

/// The row's worst key-pose error (cm), from its verdict.
fn worst_key_error(r: &EvalRow) -> Option<f64> {
    r.scores.mean.verdict.get(crate::metrics::physical::names::KEY_POSES).and_then(|c| c.value)
}

/// The Markdown `choreo eval` prints: per section, a scores table and a physical-plausibility
/// table (the verdict: each criterion as the row's worst dance has it; the values beside it are
/// every frame of the row pooled).
pub fn markdown(result: &EvalResult) -> String {
    let reference = ReferenceStats::builtin().ok();
    let mut out = format!("## {} split ({} songs, each cut to its dance)\n\n### Scores\n\n", result.split, result.rows.first().map_or(0, |r| r.scores.dances));
    out += &scores_table(&result.rows);
    out += "\n### Physical plausibility\n\n";
    out += &physical_table(&result.rows, reference.as_ref());
    out += "\n### TSMT's measures (diversity on z-normalised kinetic 5-s windows, beat P/R/F ±0.1 s)\n\n";
    out += &paper_table(&result.rows);
    if !result.extra_rows.is_empty() {
        out += &format!("\n## Extra songs, whole ({})\n\n### Scores\n\n", result.extra_songs.join(", "));
        out += &scores_table(&result.extra_rows);
        out += "\n### Physical plausibility\n\n";
        out += &physical_table(&result.extra_rows, reference.as_ref());
        out += "\n### TSMT's measures\n\n";
        out += &paper_table(&result.extra_rows);
    }
    if !result.style_control.is_empty() {
        out += "\n## Style control (every song above, test and extra, in each style)\n\n";
        out += &style_control::markdown(&result.style_control, result.real_styles.as_ref());
    }
    out
}

/// `choreo eval`: writes the reference, or evaluates, prints the table and writes the JSON.
pub fn run(args: &EvalArgs) -> Result<(), MetricsError> {
    if args.write_reference {
        let s = write_reference(&args.data, &args.reference_out)?;
        println!(
            "wrote {} ({} train dances, {} kinetic / {} geometric windows, body scale {:?})",
            args.reference_out.display(),
            s.dances.len(),
            s.kinetic.gaussian.count,
            s.geometric.gaussian.count,
            s.body_scale
        );
        let p = &s.physical;
        println!(
            "train physical: lowest foot p5 {:.3} / median {:.3} / p95 {:.3} m; acceleration median {:.2}, p99 {:.2}, p99.9 {:.2}, max {:.2} m/s²; mean joint speed {:.3} m/s (per dance {:.2}–{:.2})",
            p.pooled.lowest_foot_m.p5,
            p.pooled.lowest_foot_m.median,
            p.pooled.lowest_foot_m.p95,
            p.pooled.acceleration_m_s2.median,
            p.pooled.acceleration_m_s2.p99,
            p.pooled.acceleration_m_s2.p99_9,
            p.pooled.acceleration_m_s2.max,
            p.pooled.mean_speed_m_s,
            p.mean_speed_range_m_s[0],
            p.mean_speed_range_m_s[1]
        );
        return Ok(());
    }
    let result = evaluate(args)?;
    print!("{}", markdown(&result));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&result)?;
        std::fs::write(path, text).map_err(|source| MetricsError::Io { path: path.display().to_string(), source })?;
    }
    Ok(())
}
