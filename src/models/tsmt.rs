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
use ndarray::Array2;
use serde::{Deserialize, Serialize};
use tch::nn;
use tch::{Device, Kind, Tensor};

use super::layers::{sinusoid, Dims, KvCache, Stack};
use super::ModelError;
use crate::motion::repr::{self, FEATURE_DIM};

mod opening;
pub mod sampling;
pub mod served;

pub use sampling::{Sampling, StallGuard};
pub use served::{Generation, ModelFile, Schedule, Served, Serving};

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
    /// The step clock (`models::step_clock`): a phase that turns once per step
    /// of the song's beats, added to the pose stream's input frames and to the fusion
    /// ([`StepClockIn`]). Absent in older `model.json` files: off.
    #[serde(default)]
    pub step_clock: bool,
}

impl Config {
    /// The step's arithmetic per motion frame (a multiply-add counts 2), the keys and values of
    /// earlier frames kept: the pose bins merged, `x_layers` layers attending over at most
    /// `window` frames, the pose stream's projection, and the read-out over `n_bins` bins per
    /// coordinate. The audio stream runs once per song and is not in it.
    pub fn frame_flops(&self) -> f64 {
        let (c, b, e_bin, d, l, e_out, h, w) = (
            self.coords as f64,
            self.n_bins as f64,
            self.e_bin as f64,
            self.d_x as f64,
            self.x_layers as f64,
            self.e_out as f64,
            self.head_hidden as f64,
            self.window as f64,
        );
        let merge = 2.0 * c * e_bin * d;
        let clock = if self.step_clock { 8.0 * d } else { 0.0 };
        // Per layer: q, k, v and out projections 8d², the 4d feed-forward 16d², scores and
        // weighted sum over the window 4·w·d.
        let layers = l * (24.0 * d * d + 4.0 * w * d);
        let w_x = 2.0 * d * c * e_out;
        let read_out = 2.0 * c * e_out * h + 2.0 * c * h * b;
        merge + clock + layers + w_x + read_out
    }

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
            step_clock: false,
        }
    }

    /// A tiny configuration for tests and smoke runs.
    pub fn tiny() -> Self {
        Self {
            e_bin: 4,
            d_x: 16,
            x_layers: 1,
            x_heads: 2,
            d_a: 8,
            a_layers: 1,
            a_heads: 2,
            a_band: 6,
            e_out: 8,
            head_hidden: 8,
            window: 16,
            dropout: 0.0,
            ..Self::cpu()
        }
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
    pub fn fit<'a>(
        rows: impl IntoIterator<Item = &'a Array2<f32>>,
        n: usize,
    ) -> Result<Self, ModelError> {
        let rows: Vec<&Array2<f32>> = rows.into_iter().collect();
        let d = rows
            .first()
            .map(|r| r.ncols())
            .ok_or_else(|| ModelError::Input("no rows to fit bins on".into()))?;
        let (mut lo, mut hi) = (Vec::with_capacity(d), Vec::with_capacity(d));
        for c in 0..d {
            let col: Vec<f32> = rows.iter().flat_map(|r| r.column(c).to_vec()).collect();
            let (a, b) = (
                repr::percentile(&col, 100.0 * BIN_TAIL),
                repr::percentile(&col, 100.0 * (1.0 - BIN_TAIL)),
            );
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
    pub fn values<S: ndarray::Data<Elem = i64>>(
        &self,
        tokens: &ndarray::ArrayBase<S, ndarray::Ix2>,
    ) -> Array2<f32> {
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
        let conv_cfg = nn::ConvConfig {
            padding: c.a_kernel / 2,
            ..Default::default()
        };
        Self {
            embed: nn::linear(&p / "embed", c.music_dim, c.d_a, Default::default()),
            conv: nn::conv1d(&p / "conv", c.d_a, c.d_a, c.a_kernel, conv_cfg),
            stack: Stack::new(
                &p / "stack",
                Dims {
                    d: c.d_a,
                    n_heads: c.a_heads,
                    d_ff: 4 * c.d_a,
                    dropout: c.dropout,
                },
                c.a_layers,
            ),
            d_a: c.d_a,
            band: c.a_band,
        }
    }

    /// Encodes a window whose first frame is song position `start`.
    pub fn forward(&self, music: &Tensor, start: i64, train: bool) -> Tensor {
        let n = music.size()[1];
        let x = music.apply(&self.embed); // [b, n, d_a]
        let x = x
            .transpose(1, 2)
            .apply(&self.conv)
            .gelu("none")
            .transpose(1, 2); // [b, n, d_a]
        let x = x + sinusoid(start, n, self.d_a, music.device()).unsqueeze(0);
        self.stack
            .forward(&x, Some(&band_mask(n, self.band, music.device())), train)
    }

    /// Frames on each side of a chunk that every output inside it can see: the convolution's
    /// half kernel plus one band per block.
    fn reach(&self, kernel: i64) -> i64 {
        kernel / 2 + self.band * self.stack.layers.len() as i64
    }

    /// Encodes a whole song `[1, n, music_dim]` in chunks with enough context on each side to
    /// equal one pass; `on_chunk` gets the fraction done and may stop it.
    pub fn forward_chunked(
        &self,
        music: &Tensor,
        kernel: i64,
        start: i64,
        chunk: i64,
        on_chunk: impl FnMut(f32) -> bool,
    ) -> Option<Tensor> {
        let n = music.size()[1];
        super::layers::chunked(
            n,
            chunk,
            self.reach(kernel),
            |cs, len| self.forward(&music.narrow(1, cs, len), start + cs, false),
            on_chunk,
        )
    }
}

/// The pose stream (§3.2): tokens `[b, n, coords]` → `z^X` `[b, n, d_x]`, causal.
#[derive(Debug)]
pub struct PoseStream {
    merge: nn::Linear,
    pub(in crate::models) stack: Stack,
    d_x: i64,
}

impl PoseStream {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            merge: nn::linear(&p / "merge", c.coords * c.e_bin, c.d_x, Default::default()),
            stack: Stack::new(
                &p / "stack",
                Dims {
                    d: c.d_x,
                    n_heads: c.x_heads,
                    d_ff: 4 * c.d_x,
                    dropout: c.dropout,
                },
                c.x_layers,
            ),
            d_x: c.d_x,
        }
    }

    /// Embedded frames `[b, n, coords, e_bin]` → merged `[b, n, d_x]` with positions from `start`.
    pub(in crate::models) fn merge(&self, emb: &Tensor, start: i64) -> Tensor {
        let (b, n, c, e) = emb.size4().expect("embedded poses are [b, n, coords, e]");
        emb.reshape([b, n, c * e]).apply(&self.merge)
            + sinusoid(start, n, self.d_x, emb.device()).unsqueeze(0)
    }
}

/// The whole model. Its parts are open to `crate::models` so the trainer's free run
/// (`train::tsmt::free_run`) can step the network frame by frame with the tape kept.
#[derive(Debug)]
pub struct Tsmt {
    pub config: Config,
    /// The bin embedding shared by every coordinate `[n_bins, e_bin]`.
    pub(in crate::models) bin_embed: nn::Embedding,
    pub pose: PoseStream,
    pub audio: AudioStream,
    /// `W^X`, factorised: `z^X` → `[coords, e_out]`.
    pub(in crate::models) w_x: nn::Linear,
    /// `W^A`, factorised: `z^A` → `[coords, e_out]`.
    pub(in crate::models) w_a: nn::Linear,
    /// The shared non-linear read-out `e_out → head_hidden` (GELU), when `head_hidden > 0`.
    head: Option<nn::Linear>,
    /// The shared output bin vectors `[n_bins, head_hidden or e_out]`.
    bin_out: Tensor,
    /// Per-coordinate logit bias `[coords, n_bins]`.
    bias: Tensor,
    /// The step clock's two maps, when [`Config::step_clock`].
    pub(in crate::models) clock: Option<StepClockIn>,
}

/// Where the step clock enters TSMT: each input frame's clock is added to the pose stream's
/// merged frame (so `z^X_{t−1}` knows where in the step the dancer was), and frame t's clock to
/// the fusion beside `W^A z^A_t` (so the read-out knows where the next frame lies). Both start at
/// zero (`train::ADDED_MODULES`): a network given the clock computes what it did without it
/// until training moves them. Late fusion keeps the clock out of the audio stream, whose band
/// attention would smear a phase that must be exact per frame.
#[derive(Debug)]
pub struct StepClockIn {
    pub(in crate::models) pose: nn::Linear,
    pub(in crate::models) fusion: nn::Linear,
}

impl StepClockIn {
    /// Variables under `step_clock.` (`pose`, `fusion`), zero.
    fn new(p: nn::Path, c: &Config) -> Self {
        let zero = nn::LinearConfig {
            ws_init: nn::Init::Const(0.0),
            bias: false,
            ..Default::default()
        };
        Self {
            pose: nn::linear(&p / "pose", crate::models::step_clock::WIDTH, c.d_x, zero),
            fusion: nn::linear(
                &p / "fusion",
                crate::models::step_clock::WIDTH,
                c.coords * c.e_out,
                zero,
            ),
        }
    }
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
            w_x: nn::linear(
                p / "w_x",
                c.d_x,
                c.coords * c.e_out,
                nn::LinearConfig {
                    bias: false,
                    ..Default::default()
                },
            ),
            w_a: nn::linear(p / "w_a", c.d_a, c.coords * c.e_out, Default::default()),
            head: (c.head_hidden > 0)
                .then(|| nn::linear(p / "head", c.e_out, c.head_hidden, Default::default())),
            bin_out: {
                let w = if c.head_hidden > 0 {
                    c.head_hidden
                } else {
                    c.e_out
                };
                p.var(
                    "bin_out",
                    &[c.n_bins, w],
                    nn::Init::Randn {
                        mean: 0.0,
                        stdev: 1.0 / (w as f64).sqrt(),
                    },
                )
            },
            bias: p.var("bias", &[c.coords, c.n_bins], nn::Init::Const(0.0)),
            clock: c.step_clock.then(|| StepClockIn::new(p / "step_clock", c)),
            config,
        }
    }

    /// Per-coordinate logits `[.., coords, n_bins]` from the fused vectors `[.., coords * e_out]`.
    pub(in crate::models) fn logits(&self, fused: &Tensor) -> Tensor {
        let mut shape = fused.size();
        let last = shape.pop().unwrap_or(0);
        shape.extend([self.config.coords, last / self.config.coords]);
        self.read_out(&fused.view(shape.as_slice()), &self.bias)
    }

    /// The shared read-out: per-coordinate vectors `[.., k, e_out]` through the head (when there
    /// is one) onto the bin table, plus `bias` `[k, n_bins]` (those coordinates' rows).
    fn read_out(&self, h: &Tensor, bias: &Tensor) -> Tensor {
        let h = match &self.head {
            Some(l) => h.apply(l).gelu("none"),
            None => h.shallow_clone(),
        };
        h.matmul(&self.bin_out.tr()) + bias
    }

    /// The fused vectors `[b, n, coords * e_out]` of frames 1..=n of a window (the pose stream
    /// over `input` frames 0..n−1, causal; the audio stream's frame t), before the read-out;
    /// `clock` `[b, n + 1, WIDTH]` the window's step clock where the network has one.
    pub fn fused(
        &self,
        input: &Tensor,
        music: &Tensor,
        clock: Option<&Tensor>,
        start: i64,
        train: bool,
    ) -> Tensor {
        let n = input.size()[1] - 1;
        let emb = input.narrow(1, 0, n).apply(&self.bin_embed); // [b, n, coords, e_bin]
        let x = self.pose.merge(&emb, start);
        let step = self.clock.as_ref().zip(clock);
        let x = match step {
            Some((k, c)) => x + c.narrow(1, 0, n).apply(&k.pose),
            None => x,
        };
        let x = x.dropout(self.config.dropout, train);
        let mask = super::layers::causal_mask(n, input.device());
        let z_x = self.pose.stack.forward(&x, Some(&mask), train); // [b, n, d_x]
        let z_a = self.audio.forward(music, start, train).narrow(1, 1, n); // [b, n, d_a]
        let fused = z_x.apply(&self.w_x) + z_a.apply(&self.w_a);
        match step {
            Some((k, c)) => fused + c.narrow(1, 1, n).apply(&k.fusion),
            None => fused,
        }
    }

    /// Training pass (§3.3): `tokens` `[b, n + 1, coords]` (int64), `music` `[b, n + 1, music_dim]`,
    /// the window's first frame at song position `start`. Returns logits `[b, n, coords, n_bins]`
    /// for frames 1..=n: frame t from `z^X_{t−1}` (poses up to t − 1) and `z^A_t`.
    pub fn forward(
        &self,
        tokens: &Tensor,
        music: &Tensor,
        clock: Option<&Tensor>,
        start: i64,
        train: bool,
    ) -> Tensor {
        self.logits(&self.fused(tokens, music, clock, start, train))
    }

    /// Mean cross-entropy of [`Self::forward`] against frames 1..=n of `tokens`.
    pub fn loss(
        &self,
        tokens: &Tensor,
        music: &Tensor,
        clock: Option<&Tensor>,
        start: i64,
        train: bool,
    ) -> Tensor {
        let n = tokens.size()[1] - 1;
        let all = Tensor::arange(n, (Kind::Int64, tokens.device()));
        let fused = self.fused(tokens, music, clock, start, train);
        self.loss_on_frames(&fused, tokens, &all)
    }

    /// The cross-entropy of the fused vectors `fused` ([`Self::fused`]) against frames 1..=n of
    /// `tokens`, scoring only the predicted frames listed in `frames` (indices into 1..=n,
    /// minus one): the read-out, which is most of a step's arithmetic (`coords × n_bins` logits
    /// per frame), runs on the chosen frames only. An unbiased estimate of the full loss at a
    /// fraction of the cost.
    pub fn loss_on_frames(&self, fused: &Tensor, tokens: &Tensor, frames: &Tensor) -> Tensor {
        let n = tokens.size()[1] - 1;
        let logits = self.logits(&fused.index_select(1, frames));
        let target = tokens.narrow(1, 1, n).index_select(1, frames).reshape([-1]);
        logits
            .reshape([-1, self.config.n_bins])
            .cross_entropy_for_logits(&target)
    }

    /// The expected value `[b, n, k]` of the coordinates `coords` (`k` of them) under the
    /// read-out of `fused` ([`Self::fused`]), with `centres` `[k, n_bins]` their bin centres:
    /// what the network means to draw, differentiable (the step clock's lock term).
    pub fn expected(&self, fused: &Tensor, coords: &Tensor, centres: &Tensor) -> Tensor {
        let (b, n, _) = fused.size3().expect("fused is [b, n, coords * e_out]");
        let h = fused
            .view([b, n, self.config.coords, -1])
            .index_select(2, coords);
        let logits = self.read_out(&h, &self.bias.index_select(0, coords));
        (logits.softmax(-1, Kind::Float) * centres).sum_dim_intlist(-1, false, Kind::Float)
    }

    /// Encodes a whole song `[1, n, music_dim]`: `W^A z^A` `[n, coords * e_out]`, plus the step
    /// clock's part of the fusion where the network has one and `clock` `[n, WIDTH]` is given.
    pub fn audio_logit_vectors(
        &self,
        music: &Tensor,
        clock: Option<&Tensor>,
        on_chunk: impl FnMut(f32) -> bool,
    ) -> Option<Tensor> {
        let z = self.encode_song(music, on_chunk)?;
        Some(self.logit_vectors_of(&z, clock))
    }

    /// The audio stream over a whole song `[1, n, music_dim]`: `z^A` `[1, n, d_a]`, in chunks.
    pub fn encode_song(
        &self,
        music: &Tensor,
        mut on_chunk: impl FnMut(f32) -> bool,
    ) -> Option<Tensor> {
        self.audio
            .forward_chunked(music, self.config.a_kernel, 0, 1000, &mut on_chunk)
    }

    /// [`Self::audio_logit_vectors`] from the song's `z^A` ([`Self::encode_song`]).
    pub fn logit_vectors_of(&self, z: &Tensor, clock: Option<&Tensor>) -> Tensor {
        let v = z.squeeze_dim(0).apply(&self.w_a);
        match self.clock.as_ref().zip(clock) {
            Some((k, c)) => v + c.apply(&k.fusion),
            None => v,
        }
    }

    /// One pose-stream step: the frame at position `pos` (tokens `[coords]`, its step clock
    /// `clock` `[WIDTH]` where the network has one) against the caches; returns `W^X z^X`
    /// `[coords * e_out]` for the next frame.
    fn step(
        &self,
        tokens: &Tensor,
        clock: Option<&Tensor>,
        pos: i64,
        caches: &mut [KvCache],
    ) -> Tensor {
        let emb = tokens.view([1, 1, -1]).apply(&self.bin_embed); // [1, 1, coords, e_bin]
        let x = self.pose.merge(&emb, pos);
        let x = match self.clock.as_ref().zip(clock) {
            Some((k, c)) => x + c.view([1, 1, -1]).apply(&k.pose),
            None => x,
        };
        let z = self.pose.stack.forward_cached(&x, caches);
        for c in caches.iter_mut() {
            c.keep_last(self.config.window - 1);
        }
        z.view([-1]).apply(&self.w_x)
    }
}

#[cfg(test)]
mod tests;
