//! The training harness the models share: paired (music, pose) sequences from the real dataset,
//! normalisation on the train split, seeded random windows, and per-epoch logs.
use std::path::{Path, PathBuf};

use ndarray::{s, Array2};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};
use std::time::Instant;
use tch::nn::{self, OptimizerConfig};
use tch::{Device, Tensor};

use crate::audio::DecodedAudio;
use crate::models::folder::{TrainingRecord, MODEL_FILE, TRAIN_LOG_FILE, WEIGHTS_FILE};
use crate::motion::dataset::{Dataset, NormStats};

/// Errors while preparing data or training.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("dataset: {0}")]
    Motion(#[from] crate::motion::MotionError),
    #[error("audio: {0}")]
    Audio(#[from] crate::audio::AudioError),
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    #[error("i/o at {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    #[error("model: {0}")]
    Model(#[from] crate::models::ModelError),
    #[error("no training windows: every dance is shorter than the window ({0} frames)")]
    NoWindows(usize),
    #[error("invalid option: {0}")]
    InvalidOption(String),
}

impl From<crate::motion::dataset::FoldError> for TrainError {
    fn from(e: crate::motion::dataset::FoldError) -> Self {
        TrainError::InvalidOption(e.to_string())
    }
}

impl TrainError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            TrainError::Motion(e) => e.code(),
            TrainError::Audio(e) => e.code(),
            TrainError::Torch(_) => "train-libtorch",
            TrainError::Io { .. } => "train-io",
            TrainError::Json(_) => "train-json",
            TrainError::Model(_) => "train-model",
            TrainError::NoWindows(_) => "train-no-windows",
            TrainError::InvalidOption(_) => "train-invalid-option",
        }
    }
}

/// Computes a feature matrix `[n_frames, F]` at `fps` whose row i is the music at `start_s + i/fps`.
pub type FeatureFn =
    fn(&DecodedAudio, f64, f64, usize) -> Result<Array2<f32>, crate::audio::AudioError>;

/// One dance with its music, frame-aligned: row i of both is motion frame i.
#[derive(Clone, Debug)]
pub struct Sequence {
    pub id: String,
    pub music: Array2<f32>,
    pub poses: Array2<f32>,
    /// The beat rate (Hz) of the song over the dance, as the service's beat tracker hears it
    /// (`audio::analyze`, the one jobs use): what [`crate::models::beat_time`] re-times by.
    pub beat_hz: Option<f64>,
}

/// Whether loading analyses each song's tempo ([`Sequence::beat_hz`]): about a second per dance
/// on top of the features, which only a run in beat time needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tempo {
    Analysed,
    Skipped,
}

/// Loads the dances `ids` with their music features, aligned so that motion frame i gets the
/// music at song time `(start_position + i) / fps`, and poses as `motion::repr` features.
pub fn load_sequences(
    ds: &Dataset,
    ids: &[String],
    features: FeatureFn,
    tempo: Tempo,
) -> Result<Vec<Sequence>, TrainError> {
    let mut out = Vec::new();
    for id in ids {
        let dance = ds.load(id)?;
        let audio = crate::audio::decode_path(&dance.audio_path)?;
        let fps = dance.motion.fps;
        let t = dance.motion.num_frames();
        let music = features(&audio, fps, dance.song_time_s(0), t)?;
        let (poses, _) =
            crate::motion::repr::to_features(dance.motion.positions.view(), dance.center.view())?;
        let beat_hz = match tempo {
            Tempo::Skipped => None,
            Tempo::Analysed => {
                let t0 = dance.song_time_s(0);
                let beats: Vec<f64> = crate::audio::analyze(&audio)?
                    .beat_times
                    .iter()
                    .map(|b| b - t0)
                    .collect();
                crate::metrics::musicality::beat_rate_hz(&beats, t as f64 / fps)
            }
        };
        tracing::info!(dance = %id, frames = t, ?beat_hz, "loaded");
        out.push(Sequence {
            id: id.clone(),
            music,
            poses,
            beat_hz,
        });
    }
    Ok(out)
}

/// Options every trainer takes, flattened into each model's own `Options`.
#[derive(Clone, Debug)]
pub struct CommonOptions {
    /// The dance-with-melody folder.
    pub data: PathBuf,
    /// The model folder to write [default: models/<id>].
    pub out: Option<PathBuf>,
    /// libtorch intra-op threads.
    pub threads: i32,
    /// Stop after this many minutes even if epochs remain (the weights are saved either way).
    pub max_minutes: Option<f64>,
    /// Start from these weights (same configuration), e.g. to continue a committed run; the log
    /// is then appended to, not replaced.
    pub init: Option<PathBuf>,
    /// Use the tiny test configuration (for smoke runs, never for committed weights).
    pub tiny: bool,
}

impl Default for CommonOptions {
    fn default() -> Self {
        Self {
            data: PathBuf::from("../shared/data/dance-with-melody"),
            out: None,
            threads: 2,
            max_minutes: None,
            init: None,
            tiny: false,
        }
    }
}

impl CommonOptions {
    /// The model folder: `--out`, or `models/<id>`.
    pub fn out_dir(&self, id: &str) -> PathBuf {
        self.out
            .clone()
            .unwrap_or_else(|| Path::new("models").join(id))
    }
}

/// The real dances a trainer learns from: train and test split, as loaded (`*_raw`) and
/// normalised with statistics fitted on the train split.
pub struct Data {
    pub dataset: Dataset,
    pub train_raw: Vec<Sequence>,
    pub test_raw: Vec<Sequence>,
    pub train: Vec<Sequence>,
    pub test: Vec<Sequence>,
    pub music_norm: NormStats,
    pub pose_norm: NormStats,
}

impl Data {
    /// Loads both splits with `features` for the music (and the songs' tempi where `tempo` asks),
    /// applies `map` to each loaded sequence
    /// (a model's own pose representation), and normalises.
    pub fn load(
        folder: &Path,
        features: FeatureFn,
        tempo: Tempo,
        mut map: impl FnMut(&mut Sequence) -> Result<(), TrainError>,
    ) -> Result<Self, TrainError> {
        let started = Instant::now();
        let dataset = Dataset::open(folder)?;
        let mut train_raw = load_sequences(&dataset, dataset.train_ids(), features, tempo)?;
        let mut test_raw = load_sequences(&dataset, dataset.test_ids(), features, tempo)?;
        for s in train_raw.iter_mut().chain(test_raw.iter_mut()) {
            map(s)?;
        }
        let (music_norm, pose_norm) = fit_normalizers(&train_raw)?;
        let norm = |seqs: &[Sequence]| normalize_all(seqs, &music_norm, &pose_norm);
        let (train, test) = (norm(&train_raw)?, norm(&test_raw)?);
        tracing::info!(
            seconds = started.elapsed().as_secs_f64(),
            train = train.len(),
            test = test.len(),
            "data ready"
        );
        Ok(Self {
            dataset,
            train_raw,
            test_raw,
            train,
            test,
            music_norm,
            pose_norm,
        })
    }
}

/// `seqs` with their music and poses normalised by the split's statistics.
fn normalize_all(
    seqs: &[Sequence],
    music_norm: &NormStats,
    pose_norm: &NormStats,
) -> Result<Vec<Sequence>, TrainError> {
    seqs.iter()
        .map(|s| {
            Ok(Sequence {
                music: music_norm.normalize(&s.music)?,
                poses: pose_norm.normalize(&s.poses)?,
                id: s.id.clone(),
                beat_hz: s.beat_hz,
            })
        })
        .collect()
}

/// When a run must stop (`--max-minutes`), checked between batches and epochs.
#[derive(Clone, Copy, Debug)]
pub struct Deadline {
    started: Instant,
    max_minutes: Option<f64>,
}

impl Deadline {
    /// True once the run has used its minutes.
    pub fn expired(&self) -> bool {
        self.max_minutes
            .is_some_and(|m| self.started.elapsed().as_secs_f64() > m * 60.0)
    }

    /// Minutes since the run started.
    pub fn minutes(&self) -> f64 {
        self.started.elapsed().as_secs_f64() / 60.0
    }
}

/// What one epoch of a model's training reports to [`Trainer::run`].
pub struct EpochResult {
    pub train_loss: f64,
    pub test_loss: Option<f64>,
    /// Curriculum state or any other per-model schedule value.
    pub note: String,
}

/// The files a trainer writes into its folder: a model folder's ([`FolderFiles::MODEL`]), or
/// others where a second network shares the folder (DanceNet's style classifier beside DanceNet),
/// so that neither overwrites the other's weights or log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FolderFiles {
    pub weights: &'static str,
    pub description: &'static str,
    pub log: &'static str,
}

impl FolderFiles {
    /// `weights.safetensors`, `model.json`, `train_log.jsonl`.
    pub const MODEL: Self = Self {
        weights: WEIGHTS_FILE,
        description: MODEL_FILE,
        log: TRAIN_LOG_FILE,
    };
}

/// The training set-up every model shares: threads and seed, the network's variables and Adam,
/// `--init`, the model folder and its epoch log, the time budget, and saving.
pub struct Trainer {
    pub vs: nn::VarStore,
    pub opt: nn::Optimizer,
    pub out: PathBuf,
    pub files: FolderFiles,
    pub logs: Vec<EpochLog>,
    pub deadline: Deadline,
}

impl Trainer {
    /// Builds the network with `build` under a fresh VarStore (after seeding libtorch), loads
    /// `--init` if given, and prepares the folder and its log.
    pub fn new<M>(
        common: &CommonOptions,
        id: &str,
        lr: f64,
        seed: u64,
        build: impl FnOnce(&nn::Path) -> M,
    ) -> Result<(Self, M), TrainError> {
        Self::with_files(common, id, FolderFiles::MODEL, lr, seed, build)
    }

    /// [`Trainer::new`] writing `files` rather than the model folder's own.
    pub fn with_files<M>(
        common: &CommonOptions,
        id: &str,
        files: FolderFiles,
        lr: f64,
        seed: u64,
        build: impl FnOnce(&nn::Path) -> M,
    ) -> Result<(Self, M), TrainError> {
        tch::set_num_threads(common.threads);
        tch::manual_seed(seed as i64);
        let vs = nn::VarStore::new(Device::Cpu);
        let model = build(&vs.root());
        if let Some(init) = &common.init {
            let widened = load_widened(&vs, init)?;
            tracing::info!(from = %init.display(), ?widened, "initialised from earlier weights");
        }
        let opt = nn::Adam::default().build(&vs, lr)?;
        let out = common.out_dir(id);
        std::fs::create_dir_all(&out).map_err(|source| TrainError::Io {
            path: out.clone(),
            source,
        })?;
        if common.init.is_none() {
            let _ = std::fs::remove_file(out.join(files.log));
        }
        let deadline = Deadline {
            started: Instant::now(),
            max_minutes: common.max_minutes,
        };
        Ok((
            Self {
                vs,
                opt,
                out,
                files,
                logs: Vec::new(),
                deadline,
            },
            model,
        ))
    }

    /// Runs `epochs`, calling `one(epoch, optimiser, deadline)` for each, logging it, and saving
    /// the folder (`file` gives `model.json`) every `save_every` epochs, after the last and when the
    /// time budget runs out.
    pub fn run<F: Serialize>(
        &mut self,
        epochs: std::ops::Range<usize>,
        save_every: usize,
        mut one: impl FnMut(usize, &mut nn::Optimizer, &Deadline) -> Result<EpochResult, TrainError>,
        mut file: impl FnMut(&Self) -> F,
    ) -> Result<(), TrainError> {
        let last = epochs.end.saturating_sub(1);
        for epoch in epochs.clone() {
            let t0 = Instant::now();
            let r = one(epoch, &mut self.opt, &self.deadline)?;
            let line = EpochLog {
                epoch,
                train_loss: r.train_loss,
                test_loss: r.test_loss,
                note: r.note,
                seconds: t0.elapsed().as_secs_f64(),
            };
            tracing::info!(epoch, train_loss = line.train_loss, test_loss = ?line.test_loss, note = %line.note, seconds = line.seconds, "epoch");
            append_log(&self.out.join(self.files.log), &line)?;
            self.logs.push(line);
            let out_of_time = self.deadline.expired();
            if (epoch + 1 - epochs.start).is_multiple_of(save_every.max(1))
                || epoch == last
                || out_of_time
            {
                self.save(&file(self))?;
            }
            if out_of_time {
                tracing::warn!(epoch, "stopping: --max-minutes reached");
                break;
            }
        }
        Ok(())
    }

    /// The common training record so far, with the model's own fields.
    pub fn record<X>(&self, lr: f64, batch: usize, seed: u64, extra: X) -> TrainingRecord<X> {
        TrainingRecord {
            epochs: self.logs.last().map(|l| l.epoch + 1).unwrap_or(0),
            lr,
            batch,
            seed,
            final_train_loss: self.logs.last().map(|l| l.train_loss).unwrap_or(f64::NAN),
            minutes: self.deadline.minutes(),
            extra,
        }
    }

    /// Writes the weights and the description (`model.json`) into the folder, each atomically.
    pub fn save<F: Serialize>(&self, file: &F) -> Result<(), TrainError> {
        save_files(&self.vs, &self.out, self.files, file)
    }
}

/// Modules added to a network after earlier weights were saved, each built so that it adds
/// nothing until trained (dance-revolution's arm head: its last layer starts at zero; tsmt's
/// step clock: both its maps start at zero).
pub const ADDED_MODULES: [&str; 2] = ["decoder.arm_head.", "step_clock."];

/// Loads earlier weights into `vs`, where a variable may be wider than the saved one along one
/// axis (a network given new input columns, e.g. the beat clock): the saved values fill the
/// leading slice and the rest start at zero, so the widened network computes exactly what the
/// earlier one did until training moves the new weights. Returns the widened variables' names.
///
/// A variable of a module in [`ADDED_MODULES`] that the saved weights lack keeps its own
/// initialisation: each such module is built to add nothing until it trains.
pub fn load_widened(vs: &nn::VarStore, path: &Path) -> Result<Vec<String>, TrainError> {
    let saved: std::collections::HashMap<String, Tensor> =
        Tensor::read_safetensors(path)?.into_iter().collect();
    let mut widened = Vec::new();
    let mut vars: Vec<(String, Tensor)> = vs.variables().into_iter().collect();
    vars.sort_by(|a, b| a.0.cmp(&b.0));
    tch::no_grad(|| -> Result<(), TrainError> {
        for (name, mut var) in vars {
            if !saved.contains_key(&name) && ADDED_MODULES.iter().any(|m| name.starts_with(m)) {
                continue;
            }
            let src = saved.get(&name).ok_or_else(|| {
                TrainError::InvalidOption(format!("--init {}: no variable {name}", path.display()))
            })?;
            let (want, have) = (var.size(), src.size());
            if want == have {
                var.copy_(src);
                continue;
            }
            let differing: Vec<usize> = (0..want.len())
                .filter(|&d| want.len() == have.len() && want[d] != have[d])
                .collect();
            match differing.as_slice() {
                [d] if want[*d] > have[*d] => {
                    let _ = var.zero_();
                    var.narrow(*d as i64, 0, have[*d]).copy_(src);
                    widened.push(name);
                }
                _ => {
                    return Err(TrainError::InvalidOption(format!(
                        "--init {}: {name} is {have:?}, the network's is {want:?}",
                        path.display()
                    )))
                }
            }
        }
        Ok(())
    })?;
    Ok(widened)
}

/// Writes `weights.safetensors` and `model.json` into `dir`, each atomically.
pub fn save_folder<F: Serialize>(
    vs: &nn::VarStore,
    dir: &Path,
    file: &F,
) -> Result<(), TrainError> {
    save_files(vs, dir, FolderFiles::MODEL, file)
}

/// Writes the weights and the description named by `files` into `dir`, each atomically.
pub fn save_files<F: Serialize>(
    vs: &nn::VarStore,
    dir: &Path,
    files: FolderFiles,
    file: &F,
) -> Result<(), TrainError> {
    let tmp = dir.join(format!("{}.tmp.safetensors", files.weights));
    vs.save(&tmp)?;
    std::fs::rename(&tmp, dir.join(files.weights)).map_err(|source| TrainError::Io {
        path: dir.to_owned(),
        source,
    })?;
    write_atomic(
        &dir.join(files.description),
        serde_json::to_string_pretty(file)?.as_bytes(),
    )
}

/// Normalisation for music and poses, fitted on the given (train) sequences.
pub fn fit_normalizers(seqs: &[Sequence]) -> Result<(NormStats, NormStats), TrainError> {
    Ok((
        NormStats::fit(seqs.iter().map(|s| &s.music))?,
        NormStats::fit(seqs.iter().map(|s| &s.poses))?,
    ))
}

/// Every window start `(sequence, frame)` of `len` frames with stride `stride`, shuffled by `seed`.
pub fn window_starts(
    seqs: &[Sequence],
    len: usize,
    stride: usize,
    seed: u64,
) -> Vec<(usize, usize)> {
    let mut v = Vec::new();
    for (i, s) in seqs.iter().enumerate() {
        let t = s.poses.nrows();
        let mut f = 0;
        while f + len <= t {
            v.push((i, f));
            f += stride.max(1);
        }
    }
    v.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed));
    v
}

/// Stacks windows `[start, start + len)` of `pick(seq)` into a `[b, len, F]` tensor.
pub fn batch_tensor(
    seqs: &[Sequence],
    starts: &[(usize, usize)],
    len: usize,
    pick: impl Fn(&Sequence) -> &Array2<f32>,
    device: Device,
) -> Tensor {
    let parts: Vec<Tensor> = starts
        .iter()
        .map(|&(i, f)| {
            let m = pick(&seqs[i]).slice(s![f..f + len, ..]).to_owned();
            let (r, c) = m.dim();
            let data: Vec<f32> = m.into_iter().collect();
            Tensor::from_slice(&data).view([r as i64, c as i64])
        })
        .collect();
    Tensor::stack(&parts, 0).to_device(device)
}

/// One epoch's line in `train_log.jsonl`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EpochLog {
    pub epoch: usize,
    pub train_loss: f64,
    pub test_loss: Option<f64>,
    /// Curriculum state or any other per-model schedule value.
    pub note: String,
    pub seconds: f64,
}

/// Appends one JSON line to `path`.
pub fn append_log(path: &Path, line: &EpochLog) -> Result<(), TrainError> {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|source| TrainError::Io {
            path: path.to_owned(),
            source,
        })?;
    writeln!(f, "{}", serde_json::to_string(line)?).map_err(|source| TrainError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Writes `bytes` to `path` atomically (temp file in the same folder, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    let io = |source| TrainError::Io {
        path: path.to_owned(),
        source,
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(io)?;
    let tmp = tempfile::NamedTempFile::new_in(dir).map_err(io)?;
    std::fs::write(tmp.path(), bytes).map_err(io)?;
    // Temp files are created 0600; model files are read by other users (the service's).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644)).map_err(io)?;
    }
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}
pub mod arm_head;
pub mod augment;
pub mod beat_graph;
mod windows;
pub use windows::Windows;
pub mod classify;
pub mod dance_revolution;
pub mod dancenet;
pub mod dancenet_style;
pub mod keypose_transformer;
pub mod motion_style;
pub mod spectral;
pub mod step_lock;
pub mod tsmt;

/// One training run (`choreo train <model>`): one variant per trainable model, with its options.
#[derive(Clone, Debug)]
pub enum Training {
    /// beat-graph (ChoreoMaster's manner): the unit library, its graph and the music match.
    BeatGraph(beat_graph::Options),
    /// DanceRevolution (Huang et al., ICLR 2021).
    DanceRevolution(dance_revolution::Options),
    /// DanceNet (Zhuang et al. 2020): dilated gated causal convolutions, mixture output, style control.
    Dancenet(dancenet::Options),
    /// Key-pose controllable cross-modal transformer.
    KeyposeTransformer(keypose_transformer::Options),
    /// TSMT, the two-stream motion transformer over discretised poses (Li et al. 2020).
    Tsmt(tsmt::Options),
    /// DanceNet's musical style classifier (Zhuang et al. 2020): song → style, into models/dancenet/style.*.
    DancenetStyle(dancenet_style::Options),
    /// The motion style classifier the metrics use: motion → style, into models/motion-style/.
    MotionStyle(motion_style::Options),
}

impl Training {
    /// Trains (or evaluates) and says what it wrote.
    pub fn run(&self) -> Result<String, TrainError> {
        match self {
            Self::BeatGraph(o) => {
                let file = beat_graph::train(o)?;
                Ok(format!(
                    "built {} units of {} dances into {} (held-out match AUC {:.3} against the library, {:.3} within a dance)",
                    file.library.units,
                    file.library.dances.len(),
                    o.common.out_dir(crate::models::beat_graph::ID).display(),
                    file.held_out.auc_library,
                    file.held_out.auc_same_dance,
                ))
            }
            Self::DanceRevolution(o) => {
                let logs = dance_revolution::train(o)?;
                Ok(format!(
                    "trained {} epochs into {}",
                    logs.len(),
                    o.common
                        .out_dir(crate::models::dance_revolution::ID)
                        .display()
                ))
            }
            Self::Dancenet(o) => {
                let logs = dancenet::train(o)?;
                Ok(format!(
                    "trained {} epochs into {}",
                    logs.len(),
                    o.common.out_dir(crate::models::dancenet::ID).display()
                ))
            }
            Self::KeyposeTransformer(o) => {
                let logs = keypose_transformer::train(o)?;
                let out = o.common.out_dir(crate::models::keypose_transformer::ID);
                Ok(if o.eval_only {
                    format!("evaluated {} (eval.json rewritten)", out.display())
                } else if o.bank_only {
                    format!("redrew the pose bank in {}", out.display())
                } else {
                    format!("trained {} epochs into {}", logs.len(), out.display())
                })
            }
            Self::Tsmt(o) if o.clips_only => {
                tsmt::train(o)?;
                Ok(format!(
                    "redrew the seed clips in {}",
                    o.common.out_dir(crate::models::tsmt::ID).display()
                ))
            }
            Self::Tsmt(o) => {
                let logs = tsmt::train(o)?;
                Ok(format!(
                    "trained {} epochs into {}",
                    logs.len(),
                    o.common.out_dir(crate::models::tsmt::ID).display()
                ))
            }
            Self::DancenetStyle(o) => dancenet_style::train(o),
            Self::MotionStyle(o) => motion_style::train(o),
        }
    }
}

#[cfg(test)]
mod tests;
