//! `choreo eval`: every model judged by the same numbers on the test split.
//!
//! Rows of the table:
//! - **Real**: the test dances, with their own songs.
//! - **Mismatched real**: each test song paired with a real *train* dance (chosen by the seed),
//!   cropped to the test dance's length: real motion that ignores this music. A rhythm metric
//!   that cannot tell Real from Mismatched real measures nothing.
//! - one row per model named: a dance generated for each test song's segment (and each extra
//!   song), with seeds `seed, seed+1, …` (`--seeds`), so the same seeds give the same numbers.
//!
//! FID is biased by sample size (a Gaussian fitted to few, overlapping windows): the
//! Mismatched-real row with one train dance per song scores FID_k 38.9, with 40 per song 2.0.
//! Compare rows of similar size (`--seeds 1` gives a model row the size of Real).
//!
//! Music beats come from [`crate::audio::analyze`] on the whole song and are moved onto the
//! dance's clock (motion frame 0 = song time `start_position / 25`).
use std::path::{Path, PathBuf};

use rand::seq::SliceRandom;
use rand::SeedableRng;

use super::reference::ReferenceStats;
use super::score::{multimodality, score_dance, score_set, ScoredDance, SetScores};
use super::MetricsError;
use crate::audio::{self, DecodedAudio};
use crate::models::{Cancelled, GenerateRequest, ModelId, Progress, Registry};
use crate::motion::dataset::{Dance, Dataset};
use crate::motion::{KeyPose, Motion, MOTION_FPS};

/// Where `--write-reference` writes by default (the committed, compiled-in file).
pub const REFERENCE_PATH: &str = "src/metrics/reference_train.json";

/// Arguments of `choreo eval`.
#[derive(Clone, Debug, clap::Args)]
pub struct EvalArgs {
    /// Model ids to evaluate (e.g. dance-revolution); none prints Real and Mismatched real only.
    pub models: Vec<String>,
    /// Dataset split whose songs are evaluated.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Extra songs (every audio file in this folder) danced by each model.
    #[arg(long)]
    pub songs: Option<PathBuf>,
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
    /// Dances generated per song and model (seeds seed..seed+N); ≥ 2 gives multimodality.
    #[arg(long, default_value_t = 2)]
    pub seeds: u64,
    /// Key poses given to models that take them, on each test song: this many poses of the real
    /// test dance (root-relative) at frames drawn by the seed after its first second. Extra songs
    /// get none. The key-pose error column then shows how closely the dances pass through them.
    #[arg(long, default_value_t = 0)]
    pub key_poses: usize,
    /// Score generated dances as the model made them, without the foot planting that jobs and
    /// `choreo generate` apply by default (`motion::feet`).
    #[arg(long)]
    pub no_plant_feet: bool,
    /// Write each generated dance's contact sheet here as `<model>_<song>_seed<seed>.png`
    /// (the picture jobs serve as preview.png).
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
    pub scores: SetScores,
    /// Mean over songs of the distance between dances from different seeds.
    pub multimodality: Option<f64>,
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
    pub scores: super::score::DanceScores,
}

/// Everything `choreo eval` computed.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct EvalResult {
    pub split: String,
    pub seed: u64,
    pub rows: Vec<EvalRow>,
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

fn row(name: &str, scored: Vec<(EvalDance, ScoredDance)>, per_song: Option<Vec<Vec<usize>>>, reference: &ReferenceStats) -> EvalRow {
    let dances: Vec<ScoredDance> = scored.iter().map(|(_, s)| s.clone()).collect();
    let multimodality = per_song.and_then(|groups| {
        let g: Vec<Vec<&ScoredDance>> = groups.iter().map(|ix| ix.iter().map(|&i| &dances[i]).collect()).collect();
        multimodality(&g, reference)
    });
    EvalRow { name: name.into(), scores: score_set(&dances, reference), multimodality, dances: scored.into_iter().map(|(e, _)| e).collect() }
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

/// Runs the evaluation and returns the rows (printing nothing).
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

    // Models.
    if !args.models.is_empty() {
        let registry = Registry::load(&args.models_dir).map_err(|e| MetricsError::Reference(format!("loading models: {e}")))?;
        let mut extra = Vec::new();
        if let Some(dir) = &args.songs {
            let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
                .map_err(|source| MetricsError::Io { path: dir.display().to_string(), source })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && audio::decode_path(p).is_ok())
                .collect();
            paths.sort();
            for p in paths {
                extra.push(whole_song(&p)?);
            }
        }
        for id in &args.models {
            let model = registry
                .get(&ModelId(id.clone()))
                .ok_or_else(|| MetricsError::Reference(format!("model {id} not found under {}", args.models_dir.display())))?;
            let keyed = args.key_poses > 0 && model.info().capabilities.key_poses;
            let mut scored = Vec::new();
            let mut per_song = Vec::new();
            for (i, s) in songs.iter().chain(&extra).enumerate() {
                let keys = match eval_dances.get(i) {
                    Some(d) if keyed => key_poses_of(d, args.key_poses, args.seed + i as u64),
                    _ => Vec::new(),
                };
                let mut group = Vec::new();
                for seed in args.seed..args.seed + args.seeds.max(1) {
                    let req = GenerateRequest { audio: &s.audio, seed, key_poses: &keys, seed_motion: None };
                    let m = model.generate(&req, &mut Quiet).map_err(|e| MetricsError::Reference(format!("{id} on {}: {e}", s.name)))?;
                    // The motion stage every job runs, so the scores are those of what is served.
                    let m = crate::motion::finish(m, !args.no_plant_feet);
                    if let Some(dir) = &args.previews {
                        write_preview(dir, id, s, seed, &m, &keys)?;
                    }
                    let sc = score_dance(&m, &s.beats, &keys, &reference)?;
                    group.push(scored.len());
                    scored.push((EvalDance { song: s.name.clone(), motion: format!("{id}@{seed}"), seconds: m.duration_s(), scores: sc.scores.clone() }, sc));
                }
                per_song.push(group);
            }
            let mut name = if keyed { format!("{id} + {} key poses", args.key_poses) } else { id.clone() };
            if args.no_plant_feet {
                name += " (feet not planted)";
            }
            rows.push(row(&name, scored, Some(per_song), &reference));
        }
    }
    Ok(EvalResult { split: args.split.clone(), seed: args.seed, rows })
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
    let caption = Caption { model: model.to_string(), seed, song: Some(song.name.clone()) };
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

/// The Markdown table `choreo eval` prints.
pub fn markdown(result: &EvalResult) -> String {
    let mut out = String::from(
        "| Motion | n | BAS FACT ↑ | (chance) | BAS Bailando ↑ | Coverage | Hit rate ↑ | Rhythm hit ↑ | Beat F ↑ | FID_k ↓ | FID_g ↓ | Div_k | Div_g | S_cv ↓ | Skate ↓ | Freeze L/F | Authentic ↑ | Coherent ↑ | Multimodality | Key err cm ↓ |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in &result.rows {
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
            f(r.scores.fid_k),
            f(r.scores.fid_g),
            f(r.scores.div_k),
            f(r.scores.div_g),
            f(m.smoothness_cv),
            f(m.foot_skating.skate_ratio),
            f(m.freezing_ratio),
            f(m.plausibility.authenticity),
            f(m.plausibility.coherence),
            r.multimodality.map(f).unwrap_or_else(|| "–".into()),
            m.key_pose_error_cm.map(f).unwrap_or_else(|| "–".into()),
        ];
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
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
