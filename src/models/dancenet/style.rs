//! DanceNet's musical style classifier (Zhuang et al., "Music2Dance: DanceNet for Music-driven
//! Dance Generation", 2020): the song's style, which DanceNet takes as its global condition when
//! the user names none.
//!
//! - **Input**: 30-s windows ([`WINDOW_S`]) of the music control signals DanceNet is conditioned
//!   on (`audio::features::dancenet`, 15-d at 25 fps: onset strength, beat and downbeat one-hots,
//!   chroma 12), normalised with train-split statistics.
//! - **Network**, as the paper: three temporal convolutions of kernel 2 with 16, 24 and 32
//!   channels (ReLU), a Bi-LSTM, and a fully connected layer to the four styles. The FC layer
//!   reads the mean over time of the Bi-LSTM's outputs ([`Readout::Mean`]; its last states, the
//!   other reading, did worse on train songs held out of training: see the card).
//! - **Pooling** (ours): a max-pool of stride 2 after each convolution (`pool`). The 750 steps of
//!   a window become 93 for the LSTM (8× less sequential work on CPU, 8× shorter paths for the
//!   gradient through it), and the convolutions, which see 2 frames each, reach 15 frames (0.6 s)
//!   before the LSTM rather than 4. Without it the held-out songs did worse (card).
//! - **Serving** ([`ServedStyle`]): a song's probabilities are the mean of the softmax over its
//!   30-s windows every 15 s ([`HOP_S`]), the last window aligned to the song's end; a song shorter
//!   than 30 s is one shorter window.
//!
//! The same network over motion is the motion style metric (`crate::models::motion_style`);
//! [`WindowedClassifier`] and [`evaluate`] serve both. Its card is the section "Musical style
//! classifier" of `models/dancenet/README.md`; `choreo train dancenet-style` writes the files.
use std::ops::Range;
use std::path::{Path, PathBuf};

use ndarray::{s, Array2};
use serde::{Deserialize, Serialize};
use tch::nn::{self, RNN};
use tch::{Kind, Tensor};

use crate::models::folder::TrainingRecord;
use crate::models::{DanceStyle, InstancePool, ModelError};
use crate::motion::dataset::NormStats;

/// The classifier's weights, beside DanceNet's in `models/dancenet/`.
pub const STYLE_WEIGHTS_FILE: &str = "style.safetensors";
/// The classifier's description: configuration, normalisation, windows, training, test accuracy.
pub const STYLE_FILE: &str = "style.json";
/// One JSON line per training epoch (DanceNet's own log is `train_log.jsonl`).
pub const STYLE_LOG_FILE: &str = "style_log.jsonl";
/// The folder (under the models dir) the classifier lives in: DanceNet's.
pub const FOLDER: &str = "dancenet";
/// Window the paper classifies, seconds.
pub const WINDOW_S: f64 = 30.0;
/// Step between served windows, seconds.
pub const HOP_S: f64 = 15.0;
/// The chroma columns of the features (C first): a song's key says nothing of its style.
pub const CHROMA: Range<usize> = 3..15;
/// Frame rate of the features.
pub const FPS: f64 = crate::motion::MOTION_FPS;
/// Number of styles (the classes, [`DanceStyle::ALL`] order).
pub const STYLES: usize = DanceStyle::ALL.len();

/// Hyper-parameters of the convolutions + Bi-LSTM + FC classifier.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StyleConfig {
    /// Features per frame (15: `audio::features::dancenet`).
    pub input_dim: i64,
    /// Output channels of the temporal convolutions, one per layer (paper: 16, 24, 32).
    pub channels: Vec<i64>,
    /// Temporal kernel of every convolution, frames (paper: 2).
    pub kernel: i64,
    /// Max-pool stride after each convolution (1: none, as the paper; see the module doc).
    pub pool: i64,
    /// Bi-LSTM hidden width per direction (ours).
    pub hidden: i64,
    /// Dropout on the Bi-LSTM's read-out before the FC layer, in training.
    pub dropout: f64,
    /// What the FC layer reads of the Bi-LSTM.
    pub readout: Readout,
    /// Styles (4, [`DanceStyle::ALL`] order).
    pub classes: i64,
}

impl StyleConfig {
    /// The configuration the committed weights were trained with.
    pub fn cpu() -> Self {
        Self {
            input_dim: crate::audio::features::DANCENET_DIM as i64,
            channels: vec![16, 24, 32],
            kernel: 2,
            pool: 2,
            hidden: 32,
            dropout: 0.3,
            readout: Readout::Mean,
            classes: STYLES as i64,
        }
    }

    /// A tiny configuration for tests and smoke runs.
    pub fn tiny() -> Self {
        Self {
            channels: vec![4, 6, 8],
            hidden: 8,
            dropout: 0.0,
            ..Self::cpu()
        }
    }

    /// Steps the LSTM sees for an `n`-frame input, or `None` when a convolution would get fewer
    /// frames than its kernel.
    pub fn steps(&self, n: i64) -> Option<i64> {
        let mut n = n;
        for _ in &self.channels {
            if n < self.kernel {
                return None;
            }
            n = n - self.kernel + 1;
            if self.pool > 1 {
                // Pooling rounds up (ceil mode), so no frame is dropped at the end.
                n = (n + self.pool - 1) / self.pool;
            }
        }
        (n >= 1).then_some(n)
    }

    /// The fewest frames the network can classify.
    pub fn min_frames(&self) -> usize {
        (1..).find(|&n| self.steps(n).is_some()).unwrap_or(1) as usize
    }
}

/// What the fully connected layer reads of the Bi-LSTM.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Readout {
    /// The forward direction's last state and the backward direction's first.
    Last,
    /// The mean over time of the outputs of both directions.
    Mean,
}

/// The network: `x` `[b, T, input_dim]` → logits `[b, classes]`.
#[derive(Debug)]
pub struct StyleClassifier {
    convs: Vec<nn::Conv1D>,
    lstm: nn::LSTM,
    fc: nn::Linear,
    config: StyleConfig,
}

impl StyleClassifier {
    /// Variables `conv/<i>`, `lstm` (PyTorch's `weight_ih_l0`, `…_reverse` names) and `fc`.
    pub fn new(p: &nn::Path, c: &StyleConfig) -> Self {
        let mut convs = Vec::with_capacity(c.channels.len());
        let mut inp = c.input_dim;
        for (i, &out) in c.channels.iter().enumerate() {
            convs.push(nn::conv1d(
                p / "conv" / i,
                inp,
                out,
                c.kernel,
                Default::default(),
            ));
            inp = out;
        }
        let rnn = nn::RNNConfig {
            bidirectional: true,
            batch_first: true,
            ..Default::default()
        };
        let lstm = nn::lstm(p / "lstm", inp, c.hidden, rnn);
        let fc = nn::linear(p / "fc", 2 * c.hidden, c.classes, Default::default());
        Self {
            convs,
            lstm,
            fc,
            config: c.clone(),
        }
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &StyleConfig {
        &self.config
    }

    /// Logits `[b, classes]` of normalised features `[b, T, input_dim]`; `T` must be at least
    /// [`StyleConfig::min_frames`].
    pub fn forward(&self, x: &Tensor, train: bool) -> Tensor {
        let mut h = x.transpose(1, 2); // [b, F, T]
        for conv in &self.convs {
            h = h.apply(conv).relu(); // [b, C, T - kernel + 1]
            if self.config.pool > 1 {
                let k = [self.config.pool];
                h = h.max_pool1d(k, k, [0], [1], true); // [b, C, ⌈·/pool⌉]
            }
        }
        let h = h.transpose(1, 2); // [b, T', C]
        let (out, state) = self.lstm.seq(&h); // out [b, T', 2·hidden]
        let both = match self.config.readout {
            Readout::Last => {
                let last = state.h(); // [2, b, hidden]: forward direction's last step, backward's first
                Tensor::cat(&[last.get(0), last.get(1)], 1) // [b, 2·hidden]
            }
            Readout::Mean => out.mean_dim(1, false, Kind::Float), // [b, 2·hidden]
        };
        both.dropout(self.config.dropout, train).apply(&self.fc)
    }

    /// Mean cross-entropy of logits against style indices `y` `[b]` (int64).
    pub fn loss(&self, x: &Tensor, y: &Tensor, train: bool) -> Tensor {
        self.forward(x, train).cross_entropy_for_logits(y)
    }
}

/// The windows a sequence of `n` frames is classified in: every `hop` frames, the last one
/// aligned to the end so the closing frames count; one shorter window when `n ≤ len`.
pub fn windows(n: usize, len: usize, hop: usize) -> Vec<Range<usize>> {
    if n == 0 {
        return Vec::new();
    }
    if n <= len {
        return std::iter::once(0..n).collect();
    }
    let mut out: Vec<Range<usize>> = (0..=n - len)
        .step_by(hop.max(1))
        .map(|s| s..s + len)
        .collect();
    if out.last().is_some_and(|w| w.end < n) {
        out.push(n - len..n);
    }
    out
}

/// Softmax `[windows, classes]` of each window of normalised features `x` `[T, F]`.
pub fn window_probabilities(
    model: &StyleClassifier,
    x: &Array2<f32>,
    len: usize,
    hop: usize,
) -> Result<Tensor, ModelError> {
    let (n, f) = x.dim();
    let min = model.config().min_frames();
    if n < min {
        return Err(ModelError::Input(format!(
            "{n} frames is too short to classify (at least {min})"
        )));
    }
    if f as i64 != model.config().input_dim {
        return Err(ModelError::Shape(format!(
            "{f} features per frame, the classifier takes {}",
            model.config().input_dim
        )));
    }
    let parts: Vec<Tensor> = windows(n, len, hop)
        .into_iter()
        .map(|w| crate::models::to_tensor(&x.slice(s![w, ..]).to_owned()))
        .collect();
    let batch = Tensor::stack(&parts, 0); // [windows, len, F]
    Ok(tch::no_grad(|| {
        model.forward(&batch, false).softmax(-1, Kind::Float)
    }))
}

/// One dance (or song) to classify: its id, its style, and its normalised features `[T, F]`.
#[derive(Clone, Debug)]
pub struct Labelled {
    pub id: String,
    pub style: DanceStyle,
    pub features: Array2<f32>,
}

/// One dance's result in an [`Evaluation`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DanceResult {
    pub id: String,
    pub style: DanceStyle,
    pub windows: usize,
    /// Windows whose most probable style is the dance's.
    pub windows_right: usize,
    /// Mean of the windows' probabilities, [`DanceStyle::ALL`] order (what serving returns).
    pub probabilities: [f32; STYLES],
}

/// Accuracy on a set of dances, per window and per dance (mean probabilities), with confusion
/// matrices `[true style][predicted style]` in [`DanceStyle::ALL`] order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    pub windows: usize,
    pub window_accuracy: f64,
    /// Mean over the styles present of the share of their windows classified right, so the
    /// most numerous style does not decide the figure alone.
    pub window_balanced_accuracy: f64,
    /// Mean cross-entropy of the windows, nats.
    pub window_loss: f64,
    pub dances: usize,
    pub dance_accuracy: f64,
    pub window_confusion: [[usize; STYLES]; STYLES],
    pub dance_confusion: [[usize; STYLES]; STYLES],
    pub per_dance: Vec<DanceResult>,
}

fn argmax(p: &[f32]) -> usize {
    p.iter()
        .enumerate()
        .fold((0, f32::NEG_INFINITY), |best, (i, &v)| {
            if v > best.1 {
                (i, v)
            } else {
                best
            }
        })
        .0
}

/// Classifies every window (`len`, `hop`, as served) of every dance and tallies the result.
pub fn evaluate(
    model: &StyleClassifier,
    dances: &[Labelled],
    len: usize,
    hop: usize,
) -> Result<Evaluation, ModelError> {
    let mut e = Evaluation::default();
    let mut loss = 0.0;
    for d in dances {
        let probs = window_probabilities(model, &d.features, len, hop)?; // [w, classes]
        let rows: Vec<Vec<f32>> = Vec::<Vec<f32>>::try_from(&probs)?;
        let truth = d.style.index();
        let mut mean = [0f32; STYLES];
        let mut right = 0;
        for r in &rows {
            let guess = argmax(r);
            e.window_confusion[truth][guess] += 1;
            right += usize::from(guess == truth);
            loss -= f64::from(r[truth].max(1e-12)).ln();
            for (m, v) in mean.iter_mut().zip(r) {
                *m += v / rows.len() as f32;
            }
        }
        e.dance_confusion[truth][argmax(&mean)] += 1;
        e.windows += rows.len();
        e.per_dance.push(DanceResult {
            id: d.id.clone(),
            style: d.style,
            windows: rows.len(),
            windows_right: right,
            probabilities: mean,
        });
    }
    e.dances = dances.len();
    let diag = |m: &[[usize; STYLES]; STYLES]| (0..STYLES).map(|i| m[i][i]).sum::<usize>() as f64;
    e.window_accuracy = diag(&e.window_confusion) / e.windows.max(1) as f64;
    e.dance_accuracy = diag(&e.dance_confusion) / e.dances.max(1) as f64;
    e.window_loss = loss / e.windows.max(1) as f64;
    let recalls: Vec<f64> = e
        .window_confusion
        .iter()
        .enumerate()
        .filter(|(_, row)| row.iter().sum::<usize>() > 0)
        .map(|(i, row)| row[i] as f64 / row.iter().sum::<usize>() as f64)
        .collect();
    e.window_balanced_accuracy = recalls.iter().sum::<f64>() / recalls.len().max(1) as f64;
    Ok(e)
}

/// A trained classifier ready for raw feature rows: normalises, cuts windows, averages the
/// softmax. Usable from several threads (one network copy per concurrent call).
pub struct WindowedClassifier {
    norm: NormStats,
    window: usize,
    hop: usize,
    pool: InstancePool<StyleClassifier>,
}

impl WindowedClassifier {
    /// Loads `weights` into networks of `config`.
    pub fn load(
        weights: PathBuf,
        config: StyleConfig,
        norm: NormStats,
        window: usize,
        hop: usize,
    ) -> Result<Self, ModelError> {
        if norm.dim() as i64 != config.input_dim {
            return Err(ModelError::BadModelFile(format!(
                "normalisation has {} features, the configuration {}",
                norm.dim(),
                config.input_dim
            )));
        }
        let pool = InstancePool::new(weights, move |p| StyleClassifier::new(p, &config))?;
        Ok(Self {
            norm,
            window,
            hop,
            pool,
        })
    }

    /// Style probabilities ([`DanceStyle::ALL`] order) of raw features `[T, F]`: the mean of the
    /// softmax over the windows.
    pub fn probabilities(&self, raw: &Array2<f32>) -> Result<[f32; STYLES], ModelError> {
        if raw.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::Input("features are not finite".into()));
        }
        let x = self
            .norm
            .normalize(raw)
            .map_err(|e| ModelError::Shape(e.to_string()))?;
        let probs = self
            .pool
            .with(|m| window_probabilities(m, &x, self.window, self.hop))??;
        let mean = Vec::<f32>::try_from(probs.mean_dim(0, false, Kind::Float))?;
        let mut out = [0f32; STYLES];
        for (o, v) in out.iter_mut().zip(mean) {
            *o = v;
        }
        Ok(out)
    }
}

/// What the training run did beyond the common record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Schedule {
    /// Training windows drawn per epoch.
    pub windows_per_epoch: usize,
    /// How windows were drawn (class balance, offsets).
    pub sampling: String,
    /// How training windows were changed, if they were.
    #[serde(default)]
    pub augmentation: String,
    /// Windows of no style added to each batch with a uniform target, and what they were (see
    /// `train::classify::Additions`).
    #[serde(default)]
    pub no_style: String,
    #[serde(default)]
    pub no_style_per_batch: usize,
    /// Optimiser steps taken.
    pub steps: usize,
}

/// `style.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StyleFile {
    pub config: StyleConfig,
    /// Normalisation of the 15 features, fitted on the train split's songs.
    pub music_norm: NormStats,
    pub fps: f64,
    /// Window and hop, frames.
    pub window: usize,
    pub hop: usize,
    pub training: TrainingRecord<Schedule>,
    /// Every window and song of the test split.
    pub test: Evaluation,
    /// Train dances left out of this run and scored (a leave-dances-out check; never the
    /// committed weights).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOut>,
}

/// Train-split dances a run left out of training, and how they scored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeldOut {
    /// `K/N`: fold K of N (see `choreo train … --hold-out`).
    pub fold: String,
    pub evaluation: Evaluation,
}

/// The trained musical style classifier, as DanceNet serves it.
pub struct ServedStyle {
    file: StyleFile,
    classifier: WindowedClassifier,
}

impl ServedStyle {
    /// Reads `dir/style.json` and loads `dir/style.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        let path = dir.join(STYLE_FILE);
        let text = std::fs::read_to_string(&path).map_err(|_| {
            ModelError::MissingWeights(
                format!("{FOLDER} style classifier"),
                path.display().to_string(),
            )
        })?;
        let file: StyleFile = serde_json::from_str(&text)
            .map_err(|e| ModelError::BadModelFile(format!("{}: {e}", path.display())))?;
        let classifier = WindowedClassifier::load(
            dir.join(STYLE_WEIGHTS_FILE),
            file.config.clone(),
            file.music_norm.clone(),
            file.window,
            file.hop,
        )?;
        Ok(Self { file, classifier })
    }

    /// What `style.json` says (configuration, training, test accuracy).
    pub fn file(&self) -> &StyleFile {
        &self.file
    }

    /// Style probabilities, [`DanceStyle::ALL`] order, of a song's raw DanceNet features
    /// `[T, 15]` at 25 fps (`audio::features::dancenet`).
    pub fn predict(&self, features: &Array2<f32>) -> Result<[f32; STYLES], ModelError> {
        self.classifier.probabilities(features)
    }

    /// [`ServedStyle::predict`] of a whole decoded song.
    pub fn predict_song(
        &self,
        audio: &crate::audio::DecodedAudio,
    ) -> Result<[f32; STYLES], ModelError> {
        let n = crate::motion::validate::song_frames(audio.duration_s, self.file.fps);
        self.predict(&crate::audio::features::dancenet(
            audio,
            self.file.fps,
            0.0,
            n,
        )?)
    }
}

/// The most probable style of a probability vector.
pub fn most_probable(p: &[f32; STYLES]) -> DanceStyle {
    DanceStyle::ALL[argmax(p)]
}

#[cfg(test)]
mod tests;
