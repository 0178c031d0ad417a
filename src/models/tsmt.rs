//! TSMT: Li, Yin, Chu, Zhou, Wang, Fidler, Li, "Learning to Generate Diverse Dance Motions with
//! Transformer" (arXiv 2008.08171, 2020). Served as `tsmt`.
//!
//! - §3.1 **discrete poses**: every coordinate of a pose is cut into `n_bins` = 300 uniform bins
//!   whose ranges come from the train split ([`Bins`]); a bin embedding shared by all coordinates,
//!   the embeddings of one frame merged by a linear layer to the pose stream's width, sinusoidal
//!   positions. The coordinates are the motion module's pose features (`motion::repr`): 69
//!   root-relative joint coordinates in the facing frame, the root's per-frame displacement and
//!   yaw change (its velocity: the global path is integrated from them, so the dancer neither
//!   drifts off nor depends on where it starts), and the lowest foot's clearance above the floor
//!   in place of the root's height (`repr::height_to_clearance`), so the height follows the legs.
//! - §3.2 **two streams**: the audio stream embeds MFCC 13 + Δ and the beat one-hot
//!   (`audio::features::tsmt`, 27-d), a 1-D convolution, positions and a transformer (paper: 2
//!   blocks, 2 heads, D 64); the pose stream is a causal transformer over the discrete poses.
//!   The audio attention is a band of ±`a_band` frames, so a whole song is encoded in chunks that
//!   give exactly what one pass would (cost linear in length).
//! - §3.3 **late fusion**: per-coordinate logits `W^X z^X_{t−1} + W^A z^A_t`, trained with
//!   cross-entropy on every step of a window in parallel (causal mask). `W^X`, `W^A` are stored
//!   factorised: each stream maps to a `e_out`-wide vector per coordinate, and a shared output
//!   table of bin vectors (plus a per-coordinate bias) turns the sum into 300 logits: linear in
//!   `z`, a rank-`e_out` `W` per coordinate, at a fifth of the parameters and time. A linear
//!   read-out makes each coordinate's 300 logits a linear function of one `D`-wide vector, so a
//!   sharp peak at the previous value (what a 25 fps pose mostly needs) cannot be formed for
//!   every coordinate at once; with `head_hidden > 0` the fused per-coordinate vector goes
//!   through one shared GELU layer before the bin table (the fusion itself stays the sum of the
//!   two streams' linear maps). The model card says which the committed weights use.
//! - §3.4 **inference**: each coordinate sampled (seeded RNG, `temperature`, `top_k`), one frame
//!   at a time, with a key/value cache that keeps the last `window` frames (cost per frame is
//!   constant, so a song's cost is linear in its length). The seed motion is the request's, or
//!   a real clip of the train split drawn by the job's seed ([`SeedClips`]).
//!
//! Sizes differ from the paper to train on one CPU core; the model card says where and why.
use std::path::Path;

use ndarray::{s, Array2};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use tch::nn;
use tch::{Device, Kind, Tensor};

use super::folder::{self, SeedClips, SEED_CLIPS_FILE};
use super::layers::{sinusoid, Dims, KvCache, Stack};
use super::{smooth_columns, to_tensor, Cancelled, Capabilities, DanceModel, GenerateRequest, Generated, InstancePool, ModelError, ModelId, ModelInfo, Progress};
use crate::motion::repr::{self, RootStart, FEATURE_DIM};

/// The API id.
pub const ID: &str = "tsmt";
/// The last song frame a served song can reach: 15 minutes at 25 fps (the upload limit's
/// length); training draws window positions over all of it.
pub const MAX_POSITION: i64 = 15 * 60 * 25 + 1024;

/// Hyper-parameters, with the paper's names.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Config {
    /// Coordinates per pose (73: `motion::repr`'s features).
    pub coords: i64,
    /// Bins per coordinate (paper: 300).
    pub n_bins: i64,
    /// Music feature width (27).
    pub music_dim: i64,
    /// Width of the shared bin embedding.
    pub e_bin: i64,
    /// `D^X`: pose stream width (paper's script: 128).
    pub d_x: i64,
    /// Pose stream blocks (paper: 4).
    pub x_layers: i64,
    /// Pose stream heads (paper: 4).
    pub x_heads: i64,
    /// `D^A`: audio stream width (paper: 64).
    pub d_a: i64,
    /// Audio stream blocks (paper: 2).
    pub a_layers: i64,
    /// Audio stream heads (paper: 2).
    pub a_heads: i64,
    /// Audio 1-D convolution kernel, frames (centred).
    pub a_kernel: i64,
    /// Audio attention reaches ±`a_band` frames.
    pub a_band: i64,
    /// Width of each stream's per-coordinate output vector (rank of the factorised `W`).
    pub e_out: i64,
    /// Width of the shared non-linear bin read-out after the fusion (0: the paper's linear
    /// read-out; see the module doc).
    #[serde(default)]
    pub head_hidden: i64,
    /// Context window of the pose stream, frames (training window length and the cache kept).
    pub window: i64,
    pub dropout: f64,
}

impl Config {
    /// The configuration the committed weights were trained with (sized for one CPU core).
    pub fn cpu() -> Self {
        Self {
            coords: FEATURE_DIM as i64,
            n_bins: 300,
            music_dim: crate::audio::features::TSMT_DIM as i64,
            e_bin: 16,
            d_x: 96,
            x_layers: 3,
            x_heads: 4,
            d_a: 64,
            a_layers: 2,
            a_heads: 2,
            a_kernel: 5,
            a_band: 25,
            e_out: 32,
            head_hidden: 64,
            window: 80,
            dropout: 0.1,
        }
    }

    /// A tiny configuration for tests and smoke runs.
    pub fn tiny() -> Self {
        Self { e_bin: 4, d_x: 16, x_layers: 1, x_heads: 2, d_a: 8, a_layers: 1, a_heads: 2, a_band: 6, e_out: 8, head_hidden: 8, window: 16, dropout: 0.0, ..Self::cpu() }
    }
}

/// Uniform bins per coordinate over `[lo, hi]`, fitted on the train split (§3.1). Values outside
/// fall in the end bins.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Bins {
    pub n: usize,
    pub lo: Vec<f32>,
    pub hi: Vec<f32>,
}

/// Share of values left outside the fitted range at each end (marker glitches should not
/// widen every bin).
const BIN_TAIL: f64 = 0.001;

impl Bins {
    /// Ranges from the 0.1th to the 99.9th percentile of each column of `rows`, widened by 5 %
    /// each side.
    pub fn fit<'a>(rows: impl IntoIterator<Item = &'a Array2<f32>>, n: usize) -> Result<Self, ModelError> {
        let rows: Vec<&Array2<f32>> = rows.into_iter().collect();
        let d = rows.first().map(|r| r.ncols()).ok_or_else(|| ModelError::Invalid("no rows to fit bins on".into()))?;
        let (mut lo, mut hi) = (Vec::with_capacity(d), Vec::with_capacity(d));
        for c in 0..d {
            let col: Vec<f32> = rows.iter().flat_map(|r| r.column(c).to_vec()).collect();
            let (a, b) = (repr::percentile(&col, 100.0 * BIN_TAIL), repr::percentile(&col, 100.0 * (1.0 - BIN_TAIL)));
            let pad = 0.05 * (b - a).max(1e-4);
            lo.push(a - pad);
            hi.push(b + pad);
        }
        Ok(Self { n, lo, hi })
    }

    /// Bin of value `v` in coordinate `c`.
    pub fn index(&self, c: usize, v: f32) -> i64 {
        let f = (v - self.lo[c]) / (self.hi[c] - self.lo[c]) * self.n as f32;
        if f.is_nan() {
            return (self.n / 2) as i64;
        }
        (f.floor() as i64).clamp(0, self.n as i64 - 1)
    }

    /// Centre of bin `i` of coordinate `c`.
    pub fn centre(&self, c: usize, i: i64) -> f32 {
        self.lo[c] + (i as f32 + 0.5) * (self.hi[c] - self.lo[c]) / self.n as f32
    }

    /// Bins `[T, D]` of feature rows `[T, D]`.
    pub fn tokens(&self, x: &Array2<f32>) -> Array2<i64> {
        Array2::from_shape_fn(x.dim(), |(t, c)| self.index(c, x[[t, c]]))
    }

    /// Bin centres `[T, D]` of tokens `[T, D]`.
    pub fn values(&self, tokens: &Array2<i64>) -> Array2<f32> {
        Array2::from_shape_fn(tokens.dim(), |(t, c)| self.centre(c, tokens[[t, c]]))
    }
}

/// The audio stream (§3.2): features `[b, n, music_dim]` → `z^A` `[b, n, d_a]`.
#[derive(Debug)]
pub struct AudioStream {
    embed: nn::Linear,
    conv: nn::Conv1D,
    stack: Stack,
    d_a: i64,
    band: i64,
}

/// `[n, n]` additive mask keeping `|i − j| ≤ band`.
fn band_mask(n: i64, band: i64, device: Device) -> Tensor {
    let i = Tensor::arange(n, (Kind::Int64, device));
    let off = (i.unsqueeze(1) - i.unsqueeze(0)).abs();
    Tensor::zeros([n, n], (Kind::Float, device)).masked_fill(&off.gt(band), f64::NEG_INFINITY)
}

impl AudioStream {
    fn new(p: nn::Path, c: &Config) -> Self {
        let conv_cfg = nn::ConvConfig { padding: c.a_kernel / 2, ..Default::default() };
        Self {
            embed: nn::linear(&p / "embed", c.music_dim, c.d_a, Default::default()),
            conv: nn::conv1d(&p / "conv", c.d_a, c.d_a, c.a_kernel, conv_cfg),
            stack: Stack::new(&p / "stack", Dims { d: c.d_a, n_heads: c.a_heads, d_ff: 4 * c.d_a, dropout: c.dropout }, c.a_layers),
            d_a: c.d_a,
            band: c.a_band,
        }
    }

    /// Encodes a window whose first frame is song position `start`.
    pub fn forward(&self, music: &Tensor, start: i64, train: bool) -> Tensor {
        let n = music.size()[1];
        let x = music.apply(&self.embed); // [b, n, d_a]
        let x = x.transpose(1, 2).apply(&self.conv).gelu("none").transpose(1, 2); // [b, n, d_a]
        let x = x + sinusoid(start, n, self.d_a, music.device()).unsqueeze(0);
        self.stack.forward(&x, Some(&band_mask(n, self.band, music.device())), train)
    }

    /// Frames on each side of a chunk that every output inside it can see: the convolution's
    /// half kernel plus one band per block.
    fn reach(&self, kernel: i64) -> i64 {
        kernel / 2 + self.band * self.stack.layers.len() as i64
    }

    /// Encodes a whole song `[1, n, music_dim]` in chunks with enough context on each side to
    /// equal one pass; `on_chunk` gets the fraction done and may stop it.
    pub fn forward_chunked(&self, music: &Tensor, kernel: i64, start: i64, chunk: i64, on_chunk: impl FnMut(f32) -> bool) -> Option<Tensor> {
        let n = music.size()[1];
        super::layers::chunked(n, chunk, self.reach(kernel), |cs, len| self.forward(&music.narrow(1, cs, len), start + cs, false), on_chunk)
    }
}

/// The pose stream (§3.2): tokens `[b, n, coords]` → `z^X` `[b, n, d_x]`, causal.
#[derive(Debug)]
pub struct PoseStream {
    merge: nn::Linear,
    stack: Stack,
    d_x: i64,
}

impl PoseStream {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            merge: nn::linear(&p / "merge", c.coords * c.e_bin, c.d_x, Default::default()),
            stack: Stack::new(&p / "stack", Dims { d: c.d_x, n_heads: c.x_heads, d_ff: 4 * c.d_x, dropout: c.dropout }, c.x_layers),
            d_x: c.d_x,
        }
    }

    /// Embedded frames `[b, n, coords, e_bin]` → merged `[b, n, d_x]` with positions from `start`.
    fn merge(&self, emb: &Tensor, start: i64) -> Tensor {
        let (b, n, c, e) = emb.size4().expect("embedded poses are [b, n, coords, e]");
        emb.reshape([b, n, c * e]).apply(&self.merge) + sinusoid(start, n, self.d_x, emb.device()).unsqueeze(0)
    }
}

/// The whole model.
#[derive(Debug)]
pub struct Tsmt {
    pub config: Config,
    /// The bin embedding shared by every coordinate `[n_bins, e_bin]`.
    bin_embed: nn::Embedding,
    pub pose: PoseStream,
    pub audio: AudioStream,
    /// `W^X`, factorised: `z^X` → `[coords, e_out]`.
    w_x: nn::Linear,
    /// `W^A`, factorised: `z^A` → `[coords, e_out]`.
    w_a: nn::Linear,
    /// The shared non-linear read-out `e_out → head_hidden` (GELU), when `head_hidden > 0`.
    head: Option<nn::Linear>,
    /// The shared output bin vectors `[n_bins, head_hidden or e_out]`.
    bin_out: Tensor,
    /// Per-coordinate logit bias `[coords, n_bins]`.
    bias: Tensor,
}

impl Tsmt {
    /// Builds the variables under `p` (checkpoint keys `bin_embed`, `pose.*`, `audio.*`, `w_x`,
    /// `w_a`, `bin_out`, `bias`).
    pub fn new(p: &nn::Path, config: Config) -> Self {
        let c = &config;
        Self {
            bin_embed: nn::embedding(p / "bin_embed", c.n_bins, c.e_bin, Default::default()),
            pose: PoseStream::new(p / "pose", c),
            audio: AudioStream::new(p / "audio", c),
            w_x: nn::linear(p / "w_x", c.d_x, c.coords * c.e_out, nn::LinearConfig { bias: false, ..Default::default() }),
            w_a: nn::linear(p / "w_a", c.d_a, c.coords * c.e_out, Default::default()),
            head: (c.head_hidden > 0).then(|| nn::linear(p / "head", c.e_out, c.head_hidden, Default::default())),
            bin_out: {
                let w = if c.head_hidden > 0 { c.head_hidden } else { c.e_out };
                p.var("bin_out", &[c.n_bins, w], nn::Init::Randn { mean: 0.0, stdev: 1.0 / (w as f64).sqrt() })
            },
            bias: p.var("bias", &[c.coords, c.n_bins], nn::Init::Const(0.0)),
            config,
        }
    }

    /// Per-coordinate logits `[.., coords, n_bins]` from the fused vectors `[.., coords * e_out]`.
    fn logits(&self, fused: &Tensor) -> Tensor {
        let mut shape = fused.size();
        let last = shape.pop().unwrap_or(0);
        shape.extend([self.config.coords, last / self.config.coords]);
        let h = fused.view(shape.as_slice());
        let h = match &self.head {
            Some(l) => h.apply(l).gelu("none"),
            None => h,
        };
        h.matmul(&self.bin_out.tr()) + &self.bias
    }

    /// Training pass (§3.3): `tokens` `[b, n + 1, coords]` (int64), `music` `[b, n + 1, music_dim]`,
    /// the window's first frame at song position `start`. Returns logits `[b, n, coords, n_bins]`
    /// for frames 1..=n: frame t from `z^X_{t−1}` (poses up to t − 1) and `z^A_t`.
    pub fn forward(&self, tokens: &Tensor, music: &Tensor, start: i64, train: bool) -> Tensor {
        let n = tokens.size()[1] - 1;
        let emb = tokens.narrow(1, 0, n).apply(&self.bin_embed); // [b, n, coords, e_bin]
        let x = self.pose.merge(&emb, start).dropout(self.config.dropout, train);
        let mask = super::layers::causal_mask(n, tokens.device());
        let z_x = self.pose.stack.forward(&x, Some(&mask), train); // [b, n, d_x]
        let z_a = self.audio.forward(music, start, train).narrow(1, 1, n); // [b, n, d_a]
        self.logits(&(z_x.apply(&self.w_x) + z_a.apply(&self.w_a)))
    }

    /// Mean cross-entropy of [`Self::forward`] against frames 1..=n of `tokens`.
    pub fn loss(&self, tokens: &Tensor, music: &Tensor, start: i64, train: bool) -> Tensor {
        self.loss_with_input(tokens, tokens, music, start, train)
    }

    /// As [`Self::loss`], with the pose stream reading `input` (e.g. noised tokens) while the
    /// targets are `tokens`.
    pub fn loss_with_input(&self, input: &Tensor, tokens: &Tensor, music: &Tensor, start: i64, train: bool) -> Tensor {
        let n = tokens.size()[1] - 1;
        let logits = self.forward(input, music, start, train);
        let target = tokens.narrow(1, 1, n).reshape([-1]);
        logits.reshape([-1, self.config.n_bins]).cross_entropy_for_logits(&target)
    }

    /// As [`Self::loss_with_input`], scoring only the predicted frames listed in `frames`
    /// (indices into 1..=n, minus one). Both streams still run over the whole window (every
    /// scored frame sees its full causal context); only the read-out, which is three quarters of
    /// a step's arithmetic (`coords × n_bins` logits per frame), runs on the chosen frames. An
    /// unbiased estimate of the full loss at a fraction of the cost.
    pub fn loss_on_frames(&self, input: &Tensor, tokens: &Tensor, music: &Tensor, start: i64, frames: &Tensor, train: bool) -> Tensor {
        let n = tokens.size()[1] - 1;
        let emb = input.narrow(1, 0, n).apply(&self.bin_embed);
        let x = self.pose.merge(&emb, start).dropout(self.config.dropout, train);
        let mask = super::layers::causal_mask(n, tokens.device());
        let z_x = self.pose.stack.forward(&x, Some(&mask), train).index_select(1, frames);
        let z_a = self.audio.forward(music, start, train).narrow(1, 1, n).index_select(1, frames);
        let logits = self.logits(&(z_x.apply(&self.w_x) + z_a.apply(&self.w_a)));
        let target = tokens.narrow(1, 1, n).index_select(1, frames).reshape([-1]);
        logits.reshape([-1, self.config.n_bins]).cross_entropy_for_logits(&target)
    }

    /// Encodes a whole song `[1, n, music_dim]`: `W^A z^A` `[n, coords * e_out]`.
    pub fn audio_logit_vectors(&self, music: &Tensor, mut on_chunk: impl FnMut(f32) -> bool) -> Option<Tensor> {
        let z = self.audio.forward_chunked(music, self.config.a_kernel, 0, 1000, &mut on_chunk)?;
        Some(z.squeeze_dim(0).apply(&self.w_a))
    }

    /// One pose-stream step: the frame at position `pos` (tokens `[coords]`) against the caches;
    /// returns `W^X z^X` `[coords * e_out]` for the next frame.
    fn step(&self, tokens: &Tensor, pos: i64, caches: &mut [KvCache]) -> Tensor {
        let emb = tokens.view([1, 1, -1]).apply(&self.bin_embed); // [1, 1, coords, e_bin]
        let x = self.pose.merge(&emb, pos);
        let z = self.pose.stack.forward_cached(&x, caches);
        for c in caches.iter_mut() {
            c.keep_last(self.config.window - 1);
        }
        z.view([-1]).apply(&self.w_x)
    }

    /// Generates `n` frames of tokens after the context `prefix` `[m ≥ 1, coords]`, frame t
    /// from the last frames and row t of `audio_vectors` ([`Self::audio_logit_vectors`]).
    /// `on_step(done)` is called before the first frame and every 250 frames, and may stop it.
    pub fn sample(&self, prefix: &Array2<i64>, audio_vectors: &Tensor, sampling: Sampling, seed: u64, on_step: impl FnMut(usize) -> bool) -> Option<Array2<i64>> {
        self.sample_guarded(prefix, audio_vectors, sampling, None, seed, on_step)
    }

    /// [`Self::sample`] with an optional [`StallGuard`] and the metres per bin of each joint
    /// coordinate (the first `POSE_DIM` coordinates) it measures motion with.
    pub fn sample_guarded(
        &self,
        prefix: &Array2<i64>,
        audio_vectors: &Tensor,
        sampling: Sampling,
        guard: Option<(&StallGuard, &[f32])>,
        seed: u64,
        mut on_step: impl FnMut(usize) -> bool,
    ) -> Option<Array2<i64>> {
        let c = self.config.coords as usize;
        let n = audio_vectors.size()[0] as usize;
        let mut out = Array2::<i64>::zeros((n, c));
        let mut caches = self.pose.stack.new_caches();
        let mut rng = StdRng::seed_from_u64(seed ^ 0x7357_0000_D0CE);
        let tensor_of = |row: ndarray::ArrayView1<'_, i64>| Tensor::from_slice(&row.to_vec());
        // The context, all but its last frame, fills the caches (at most the window's worth).
        let m = prefix.nrows();
        let keep = (m as i64).min(self.config.window) as usize;
        let first = m - keep;
        let mut wx = Tensor::zeros([1], (Kind::Float, Device::Cpu));
        for (k, t) in (first..m).enumerate() {
            wx = self.step(&tensor_of(prefix.row(t)), k as i64, &mut caches);
        }
        let mut pos = keep as i64;
        let mut probs = vec![0f32; self.config.n_bins as usize];
        // Says the loop has begun (a stage clock starts timing it here, however short the song).
        if !on_step(0) {
            return None;
        }
        // The last frames drawn, for the guard.
        let mut recent: std::collections::VecDeque<Vec<i64>> = std::collections::VecDeque::new();
        for t in 0..n {
            let logits = self.logits(&(wx.shallow_clone() + audio_vectors.get(t as i64))); // [coords, n_bins]
            let flat: Vec<f32> = Vec::<f32>::try_from(logits.contiguous().view([-1])).ok()?;
            let now = match guard {
                Some((g, widths)) if recent.len() >= g.window_frames && reach_m(&recent, widths) < g.min_reach_m => g.boosted(sampling),
                _ => sampling,
            };
            for (ci, row) in flat.chunks(self.config.n_bins as usize).enumerate() {
                out[[t, ci]] = now.draw(row, &mut probs, &mut rng) as i64;
            }
            if let Some((g, _)) = guard {
                recent.push_back(out.row(t).to_vec());
                while recent.len() > g.window_frames {
                    recent.pop_front();
                }
            }
            wx = self.step(&tensor_of(out.row(t)), pos, &mut caches);
            pos += 1;
            if (t + 1) % 250 == 0 && !on_step(t + 1) {
                return None;
            }
        }
        Some(out)
    }
}

/// How far the pose has come within `frames` (tokens, oldest first): the largest, over the
/// earlier frames, of the mean distance (m) of the root-relative joints from where they are in
/// the last frame, from the metres per bin of each joint coordinate (`widths`, `POSE_DIM` long).
/// A bin or two of sampling jitter adds a centimetre or so; a dancer who moves reaches tens.
fn reach_m(frames: &std::collections::VecDeque<Vec<i64>>, widths: &[f32]) -> f32 {
    let joints = widths.len() / 3;
    let Some(last) = frames.back() else { return 0.0 };
    if joints == 0 || last.len() < 3 * joints {
        return 0.0;
    }
    frames
        .iter()
        .map(|f| {
            let sum: f32 = (0..joints)
                .map(|j| (0..3).map(|c| ((last[3 * j + c] - f[3 * j + c]) as f32 * widths[3 * j + c]).powi(2)).sum::<f32>().sqrt())
                .sum();
            sum / joints as f32
        })
        .fold(0.0, f32::max)
}

/// A served guard against stalls (not in the paper): a sampled model that reaches a held pose
/// (mostly a dance's closing pose) can stay in it for minutes, since each coordinate's likeliest
/// bin is its previous one. While no pose of the last `window_frames` frames is more than
/// `min_reach_m` (mean over joints, root-relative) from the newest ([`reach_m`]), draws use the
/// temperature times `boost` (and twice the top-k) until the dancer moves again.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct StallGuard {
    pub min_reach_m: f32,
    pub window_frames: usize,
    pub boost: f64,
}

impl StallGuard {
    fn boosted(&self, s: Sampling) -> Sampling {
        Sampling { temperature: s.temperature * self.boost, top_k: if s.top_k == 0 { 0 } else { s.top_k * 2 } }
    }
}

/// How logits become a draw (§3.4): temperature, then the `top_k` likeliest bins.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Sampling {
    pub temperature: f64,
    /// 0 keeps every bin.
    pub top_k: usize,
}

impl Default for Sampling {
    fn default() -> Self {
        Self { temperature: 1.0, top_k: 0 }
    }
}

impl Sampling {
    /// Draws a bin from one coordinate's `logits`; `probs` is scratch of the same length.
    pub fn draw(&self, logits: &[f32], probs: &mut [f32], rng: &mut StdRng) -> usize {
        let t = self.temperature.max(1e-3) as f32;
        let k = if self.top_k == 0 { logits.len() } else { self.top_k.min(logits.len()) };
        // The k-th largest logit is the cut (ties at the cut are kept).
        let cut = if k < logits.len() {
            let mut sorted: Vec<f32> = logits.to_vec();
            let (_, kth, _) = sorted.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a));
            *kth
        } else {
            f32::NEG_INFINITY
        };
        let max = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let mut total = 0f32;
        for (p, &l) in probs.iter_mut().zip(logits) {
            *p = if l >= cut { ((l - max) / t).exp() } else { 0.0 };
            total += *p;
        }
        let mut u = rng.gen::<f32>() * total;
        for (i, &p) in probs.iter().enumerate() {
            if u < p {
                return i;
            }
            u -= p;
        }
        // Rounding left u past the end: the last bin with any mass.
        probs.iter().rposition(|&p| p > 0.0).unwrap_or(0)
    }
}

/// The run behind the committed weights, beside the common record.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Schedule {
    pub window: usize,
    pub stride: usize,
    /// Standard deviation (bins) of the noise added to the pose stream's input tokens.
    pub input_noise_bins: f64,
    /// Share of each window's frames scored per step (1: all; see `train::tsmt::Options`).
    #[serde(default = "one")]
    pub loss_frames: f64,
    /// Windows whose last second was slower than this (m/s, root-relative joints) were left out
    /// (0: none).
    #[serde(default)]
    pub min_window_speed: f64,
    pub steps: usize,
}

fn one() -> f64 {
    1.0
}

/// `model.json`'s own fields: the bins, the default sampling and the de-quantisation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Serving {
    pub bins: Bins,
    /// Used where a job gives no `temperature` / `top_k`.
    pub sampling: Sampling,
    /// σ, in frames, of the Gaussian that smooths the sampled bin centres over time before the
    /// motion is rebuilt (0: none). Each coordinate is drawn on its own, so a joint's three
    /// coordinates jitter by a bin or two from frame to frame; at 25 fps one 4-mm bin of jitter
    /// is already ~2.5 m/s² of acceleration, and the model card measures what is left.
    #[serde(default)]
    pub smooth_frames: f64,
    /// σ, in frames, of a second Gaussian over the root height once it is rebuilt from the
    /// clearance (0: none). The height is the clearance minus the lowest foot point's local
    /// height, and which point is lowest hops between feet and heel/toe as each coordinate is
    /// drawn on its own: the whole body then rises or drops by up to 0.2 m in a frame (4–6 m/s).
    #[serde(default)]
    pub smooth_height_frames: f64,
    /// The stall guard, if any ([`StallGuard`]).
    #[serde(default)]
    pub stall_guard: Option<StallGuard>,
}

/// `model.json`.
pub type ModelFile = folder::ModelFile<Config, Schedule, Serving>;

/// A trained TSMT, ready to serve.
pub struct Served {
    file: ModelFile,
    clips: Option<SeedClips>,
    pool: InstancePool<Tsmt>,
}

/// What one generation made: the feature rows (foot clearance as the height) and the root start.
pub struct Generation {
    pub features: Array2<f32>,
    pub start: RootStart,
}

impl Served {
    /// Loads `dir/model.json`, `dir/weights.safetensors` and `dir/seed_clips.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        let (file, pool) = folder::load(dir, ID, |p, f: &ModelFile| Tsmt::new(p, f.config.clone()))?;
        let path = dir.join(SEED_CLIPS_FILE);
        let clips = if path.exists() { Some(SeedClips::load(&path, FEATURE_DIM)?) } else { None };
        Ok(Self { file, clips, pool })
    }

    /// The model's description file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }

    /// Generates `n` frames of features (clearance heights) for `audio`. The context is the seed
    /// motion's features (which then open the dance), else a drawn clip (context only).
    pub fn generate_features(&self, req: &GenerateRequest<'_>, n: usize, progress: &mut dyn Progress) -> Result<Generation, ModelError> {
        let fps = self.file.fps;
        let bins = &self.file.extra.bins;
        let sampling = Sampling {
            temperature: req.temperature.unwrap_or(self.file.extra.sampling.temperature),
            top_k: req.top_k.map(|k| k as usize).unwrap_or(self.file.extra.sampling.top_k),
        };
        progress.report("features", 0.0)?;
        let feats = crate::audio::features::tsmt(req.audio, fps, 0.0, n)?;
        let music = to_tensor(&self.file.music_norm.normalize(&feats)?).unsqueeze(0);
        progress.report("features", 1.0)?;
        // The opening: the request's seed motion (kept as the dance's first frames), or a real clip.
        let (context, opening, start) = match req.seed_motion {
            Some(m) if m.num_frames() > 0 => {
                let keep = m.num_frames().min(n);
                let root = crate::motion::skeleton::body_centre_track(m.positions.view());
                let (mut f, start) = repr::to_features(m.positions.view(), root.view())?;
                let floor = repr::floor_of_features(f.view());
                repr::height_to_clearance(&mut f, floor);
                let f = f.slice(s![..keep, ..]).to_owned();
                (bins.tokens(&f), Some(f), start)
            }
            _ => {
                let clip = match &self.clips {
                    Some(c) => c.pick(req.seed),
                    None => return Err(ModelError::Invalid(format!("{ID}: no seed motion and no {SEED_CLIPS_FILE}"))),
                };
                (bins.tokens(&clip), None, RootStart::default())
            }
        };
        let opened = opening.as_ref().map_or(0, |o| o.nrows());
        let out = self.pool.with(|model| {
            tch::no_grad(|| -> Result<Option<Array2<i64>>, ModelError> {
                let mut cancelled = false;
                let Some(vectors) = model.audio_logit_vectors(&music, |f| {
                    cancelled = progress.report("encode", f).is_err();
                    !cancelled
                }) else {
                    return Ok(None);
                };
                let rest = vectors.narrow(0, opened as i64, (n - opened) as i64);
                let total = (n - opened).max(1);
                let widths: Vec<f32> = (0..repr::POSE_DIM).map(|c| (bins.hi[c] - bins.lo[c]) / bins.n as f32).collect();
                let guard = self.file.extra.stall_guard.as_ref().map(|g| (g, widths.as_slice()));
                Ok(model.sample_guarded(&context, &rest, sampling, guard, req.seed, |done| progress.report("decode", done as f32 / total as f32).is_ok()))
            })
        })??;
        let Some(tokens) = out else { return Err(Cancelled.into()) };
        let mut sampled = bins.values(&tokens);
        smooth_columns(&mut sampled, 0, self.file.extra.smooth_frames);
        let features = match opening {
            Some(o) => ndarray::concatenate(ndarray::Axis(0), &[o.view(), sampled.view()]).map_err(|e| ModelError::Invalid(e.to_string()))?,
            None => sampled,
        };
        Ok(Generation { features, start })
    }
}

impl DanceModel for Served {
    fn info(&self) -> ModelInfo {
        ModelInfo {
            id: ModelId(ID.into()),
            paper: "Li et al., Learning to Generate Diverse Dance Motions with Transformer, 2020 (two-stream motion transformer)".into(),
            capabilities: Capabilities { key_poses: false, seed_motion: true, style: false, temperature: true, top_k: true },
        }
    }

    fn generate(&self, req: &GenerateRequest<'_>, progress: &mut dyn Progress) -> Result<Generated, ModelError> {
        self.refuse_unsupported(req)?;
        let n = ((req.audio.duration_s * self.file.fps).floor() as usize).max(1);
        let mut g = self.generate_features(req, n, progress)?;
        repr::clearance_to_height(&mut g.features);
        // The root height follows the lowest foot point, which hops between feet and points as
        // their coordinates are drawn; smoothing the height itself (not the clearance) keeps the
        // body from jumping with it. The opening (a request's seed motion) is kept.
        let keep = req.seed_motion.map_or(0, |m| m.num_frames().min(n));
        let mut h = g.features.column(repr::ROOT_Y).to_owned().insert_axis(ndarray::Axis(1));
        smooth_columns(&mut h, keep, self.file.extra.smooth_height_frames);
        g.features.column_mut(repr::ROOT_Y).assign(&h.column(0));
        let (motion, _root) = repr::from_features(g.features.view(), g.start, self.file.fps)?;
        Ok(motion.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::nn::OptimizerConfig;

    fn model(seed: i64) -> (nn::VarStore, Tsmt) {
        tch::manual_seed(seed);
        let vs = nn::VarStore::new(Device::Cpu);
        let m = Tsmt::new(&vs.root(), Config { coords: 5, n_bins: 12, music_dim: 3, ..Config::tiny() });
        (vs, m)
    }

    fn tokens(b: i64, n: i64) -> Tensor {
        Tensor::randint(12, [b, n, 5], (Kind::Int64, Device::Cpu))
    }

    #[test]
    fn bins_round_trip_within_half_a_bin() {
        let x = Array2::from_shape_fn((400, 2), |(t, c)| ((t as f32) * 0.01 + c as f32).sin());
        let b = Bins::fit([&x], 300).unwrap();
        let back = b.values(&b.tokens(&x));
        for c in 0..2 {
            let width = (b.hi[c] - b.lo[c]) / 300.0;
            let err = (&back.column(c) - &x.column(c)).mapv(f32::abs).fold(0f32, |a, &v| a.max(v));
            assert!(err <= 0.5 * width + 1e-6, "column {c}: error {err}, bin {width}");
        }
        assert_eq!(b.index(0, -100.0), 0);
        assert_eq!(b.index(0, 100.0), 299);
    }

    #[test]
    fn dequantising_removes_bin_jitter_and_keeps_the_opening() {
        // A slow ramp drawn one bin off at random every frame, after 5 given frames.
        let mut rng = StdRng::seed_from_u64(1);
        let clean = Array2::from_shape_fn((200, 1), |(t, _)| t as f32 * 0.004);
        let mut x = clean.mapv(|v| v) + Array2::from_shape_fn((200, 1), |_| 0.004 * rng.gen_range(-1..=1) as f32);
        let given = x.slice(s![..5, ..]).to_owned();
        let accel = |a: &Array2<f32>| (6..194).map(|t| (a[[t + 1, 0]] - 2.0 * a[[t, 0]] + a[[t - 1, 0]]).abs()).fold(0f32, f32::max);
        let before = accel(&x);
        smooth_columns(&mut x, 5, 1.5);
        assert_eq!(x.slice(s![..5, ..]), given);
        let after = accel(&x);
        assert!(after < 0.25 * before, "second difference {before} -> {after}");
        // The ramp itself is kept (away from the ends).
        let off = (20..180).map(|t| (x[[t, 0]] - clean[[t, 0]]).abs()).fold(0f32, f32::max);
        assert!(off < 0.004, "smoothing moved the ramp by {off}");
    }

    #[test]
    fn logits_do_not_see_the_future_pose() {
        let (_vs, m) = model(0);
        let x = tokens(1, 11);
        let music = Tensor::randn([1, 11, 3], (Kind::Float, Device::Cpu));
        let a = m.forward(&x, &music, 0, false);
        assert_eq!(a.size(), vec![1, 10, 5, 12]);
        // Changing pose frame 6 may change logits of frames 7.. (index 6..), never frames ≤ 6.
        let x2 = x.copy();
        let _ = x2.narrow(1, 6, 1).fill_(3);
        let b = m.forward(&x2, &music, 0, false);
        let early = (a.narrow(1, 0, 6) - b.narrow(1, 0, 6)).abs().max().double_value(&[]);
        assert!(early < 1e-6, "frames ≤ 6 moved by {early}");
    }

    #[test]
    fn chunked_audio_equals_one_pass() {
        let (_vs, m) = model(1);
        let music = Tensor::randn([1, 70, 3], (Kind::Float, Device::Cpu));
        let whole = m.audio.forward(&music, 0, false);
        let chunked = m.audio.forward_chunked(&music, m.config.a_kernel, 0, 9, |_| true).unwrap();
        let d = (whole - chunked).abs().max().double_value(&[]);
        assert!(d < 1e-5, "chunked audio differs by {d}");
    }

    #[test]
    fn cached_steps_equal_the_training_pass() {
        let (_vs, m) = model(2);
        let x = tokens(1, 9);
        let music = Tensor::randn([1, 9, 3], (Kind::Float, Device::Cpu));
        let logits = m.forward(&x, &music, 0, false); // [1, 8, 5, 12]
        let av = m.audio.forward(&music, 0, false).squeeze_dim(0).apply(&m.w_a);
        let mut caches = m.pose.stack.new_caches();
        for t in 0..8 {
            let wx = m.step(&x.get(0).get(t), t, &mut caches);
            let l = m.logits(&(wx + av.get(t + 1)));
            let d = (l - logits.get(0).get(t)).abs().max().double_value(&[]);
            assert!(d < 1e-4, "step {t} differs by {d}");
        }
    }

    #[test]
    fn same_seed_same_dance_other_seed_other_dance() {
        let (_vs, m) = model(3);
        let music = Tensor::randn([1, 40, 3], (Kind::Float, Device::Cpu));
        let av = m.audio_logit_vectors(&music, |_| true).unwrap();
        let prefix = Array2::from_shape_fn((20, 5), |(t, c)| ((t + c) % 12) as i64);
        let s = Sampling::default();
        let a = m.sample(&prefix, &av, s, 7, |_| true).unwrap();
        let b = m.sample(&prefix, &av, s, 7, |_| true).unwrap();
        let c = m.sample(&prefix, &av, s, 8, |_| true).unwrap();
        assert_eq!(a.dim(), (40, 5));
        assert_eq!(a, b);
        assert_ne!(a, c);
        // top_k = 1 is greedy: the same whatever the seed.
        let g = Sampling { temperature: 1.0, top_k: 1 };
        assert_eq!(m.sample(&prefix, &av, g, 1, |_| true).unwrap(), m.sample(&prefix, &av, g, 2, |_| true).unwrap());
    }

    #[test]
    fn reach_measures_how_far_the_pose_came_and_the_guard_only_acts_on_a_stall() {
        // Two joints, 1 cm per bin: a held pose reaches 0; a joint 30 bins away 0.15 m on the mean.
        let widths = vec![0.01f32; 6];
        let held: std::collections::VecDeque<Vec<i64>> = (0..10).map(|_| vec![5i64; 6]).collect();
        assert_eq!(reach_m(&held, &widths), 0.0);
        let mut moved = held.clone();
        moved.push_front(vec![35, 5, 5, 5, 5, 5]);
        assert!((reach_m(&moved, &widths) - 0.15).abs() < 1e-6);
        // A guard that never fires leaves the draws as they were; one that always fires changes them.
        let (_vs, m) = model(6);
        let music = Tensor::randn([1, 30, 3], (Kind::Float, Device::Cpu));
        let av = m.audio_logit_vectors(&music, |_| true).unwrap();
        let prefix = Array2::from_shape_fn((10, 5), |(t, c)| ((t + c) % 12) as i64);
        let s = Sampling { temperature: 0.3, top_k: 3 };
        let w = vec![0.01f32; 3];
        let never = StallGuard { min_reach_m: 0.0, window_frames: 5, boost: 10.0 };
        let always = StallGuard { min_reach_m: 1e9, window_frames: 5, boost: 10.0 };
        let plain = m.sample(&prefix, &av, s, 3, |_| true).unwrap();
        assert_eq!(m.sample_guarded(&prefix, &av, s, Some((&never, &w)), 3, |_| true).unwrap(), plain);
        assert_ne!(m.sample_guarded(&prefix, &av, s, Some((&always, &w)), 3, |_| true).unwrap(), plain);
    }

    #[test]
    fn top_k_and_temperature_shape_the_draws() {
        let logits = [0.0f32, 1.0, 2.0, 3.0];
        let mut probs = [0f32; 4];
        let mut rng = StdRng::seed_from_u64(0);
        let k2 = Sampling { temperature: 1.0, top_k: 2 };
        assert!((0..200).all(|_| k2.draw(&logits, &mut probs, &mut rng) >= 2));
        let cold = Sampling { temperature: 0.05, top_k: 0 };
        assert!((0..200).all(|_| cold.draw(&logits, &mut probs, &mut rng) == 3));
        let hot = Sampling { temperature: 5.0, top_k: 0 };
        let zeros = (0..400).filter(|_| hot.draw(&logits, &mut probs, &mut rng) == 0).count();
        assert!(zeros > 40, "a hot draw picked bin 0 only {zeros} of 400 times");
    }

    #[test]
    fn loss_on_every_frame_equals_the_full_loss() {
        let (_vs, m) = model(5);
        let x = tokens(2, 9);
        let music = Tensor::randn([2, 9, 3], (Kind::Float, Device::Cpu));
        let all = Tensor::arange(8, (Kind::Int64, Device::Cpu));
        let full = m.loss(&x, &music, 3, false).double_value(&[]);
        let picked = m.loss_on_frames(&x, &x, &music, 3, &all, false).double_value(&[]);
        assert!((full - picked).abs() < 1e-5, "{full} vs {picked}");
    }

    #[test]
    fn loss_falls_on_a_few_batches() {
        let (vs, m) = model(4);
        let mut opt = nn::Adam::default().build(&vs, 3e-3).unwrap();
        let x = tokens(4, 13);
        let music = Tensor::randn([4, 13, 3], (Kind::Float, Device::Cpu));
        let first = m.loss(&x, &music, 0, true).double_value(&[]);
        for _ in 0..40 {
            opt.backward_step(&m.loss(&x, &music, 0, true));
        }
        let last = m.loss(&x, &music, 0, true).double_value(&[]);
        assert!(last < 0.8 * first, "loss {first} -> {last}");
    }
}
