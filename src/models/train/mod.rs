//! The training harness the models share: paired (music, pose) sequences from the real dataset,
//! normalisation on the train split, seeded random windows, and per-epoch logs.
use std::path::{Path, PathBuf};

use ndarray::{s, Array2};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};
use tch::{Device, Tensor};

use crate::audio::DecodedAudio;
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
    Io { path: PathBuf, source: std::io::Error },
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    #[error("no training windows: every dance is shorter than the window ({0} frames)")]
    NoWindows(usize),
}

/// Computes a feature matrix `[n_frames, F]` at `fps` whose row i is the music at `start_s + i/fps`.
pub type FeatureFn = fn(&DecodedAudio, f64, f64, usize) -> Result<Array2<f32>, crate::audio::AudioError>;

/// One dance with its music, frame-aligned: row i of both is motion frame i.
#[derive(Clone, Debug)]
pub struct Sequence {
    pub id: String,
    pub music: Array2<f32>,
    pub poses: Array2<f32>,
}

/// Loads the dances `ids` with their music features, aligned so that motion frame i gets the
/// music at song time `(start_position + i) / fps`, and poses as `motion::repr` features.
pub fn load_sequences(ds: &Dataset, ids: &[String], features: FeatureFn) -> Result<Vec<Sequence>, TrainError> {
    let mut out = Vec::new();
    for id in ids {
        let dance = ds.load(id)?;
        let audio = crate::audio::decode_path(&dance.audio_path)?;
        let fps = dance.motion.fps;
        let t = dance.motion.num_frames();
        let music = features(&audio, fps, dance.song_time_s(0), t)?;
        let (poses, _) = crate::motion::repr::to_features(dance.motion.positions.view(), dance.center.view())?;
        tracing::info!(dance = %id, frames = t, "loaded");
        out.push(Sequence { id: id.clone(), music, poses });
    }
    Ok(out)
}

/// Normalisation for music and poses, fitted on the given (train) sequences.
pub fn fit_normalizers(seqs: &[Sequence]) -> Result<(NormStats, NormStats), TrainError> {
    Ok((NormStats::fit(seqs.iter().map(|s| &s.music))?, NormStats::fit(seqs.iter().map(|s| &s.poses))?))
}

/// Every window start `(sequence, frame)` of `len` frames with stride `stride`, shuffled by `seed`.
pub fn window_starts(seqs: &[Sequence], len: usize, stride: usize, seed: u64) -> Vec<(usize, usize)> {
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
pub fn batch_tensor(seqs: &[Sequence], starts: &[(usize, usize)], len: usize, pick: impl Fn(&Sequence) -> &Array2<f32>, device: Device) -> Tensor {
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
        .map_err(|source| TrainError::Io { path: path.to_owned(), source })?;
    writeln!(f, "{}", serde_json::to_string(line)?).map_err(|source| TrainError::Io { path: path.to_owned(), source })
}

/// Writes `bytes` to `path` atomically (temp file in the same folder, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    let io = |source| TrainError::Io { path: path.to_owned(), source };
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
pub mod dance_revolution;
pub mod keypose_transformer;
