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
    stack: Stack,
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
    fn merge(&self, emb: &Tensor, start: i64) -> Tensor {
        let (b, n, c, e) = emb.size4().expect("embedded poses are [b, n, coords, e]");
        emb.reshape([b, n, c * e]).apply(&self.merge)
            + sinusoid(start, n, self.d_x, emb.device()).unsqueeze(0)
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
        let x = self
            .pose
            .merge(&emb, start)
            .dropout(self.config.dropout, train);
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
    pub fn loss_with_input(
        &self,
        input: &Tensor,
        tokens: &Tensor,
        music: &Tensor,
        start: i64,
        train: bool,
    ) -> Tensor {
        let n = tokens.size()[1] - 1;
        let logits = self.forward(input, music, start, train);
        let target = tokens.narrow(1, 1, n).reshape([-1]);
        logits
            .reshape([-1, self.config.n_bins])
            .cross_entropy_for_logits(&target)
    }

    /// As [`Self::loss_with_input`], scoring only the predicted frames listed in `frames`
    /// (indices into 1..=n, minus one). Both streams still run over the whole window (every
    /// scored frame sees its full causal context); only the read-out, which is three quarters of
    /// a step's arithmetic (`coords × n_bins` logits per frame), runs on the chosen frames. An
    /// unbiased estimate of the full loss at a fraction of the cost.
    pub fn loss_on_frames(
        &self,
        input: &Tensor,
        tokens: &Tensor,
        music: &Tensor,
        start: i64,
        frames: &Tensor,
        train: bool,
    ) -> Tensor {
        let n = tokens.size()[1] - 1;
        let emb = input.narrow(1, 0, n).apply(&self.bin_embed);
        let x = self
            .pose
            .merge(&emb, start)
            .dropout(self.config.dropout, train);
        let mask = super::layers::causal_mask(n, tokens.device());
        let z_x = self
            .pose
            .stack
            .forward(&x, Some(&mask), train)
            .index_select(1, frames);
        let z_a = self
            .audio
            .forward(music, start, train)
            .narrow(1, 1, n)
            .index_select(1, frames);
        let logits = self.logits(&(z_x.apply(&self.w_x) + z_a.apply(&self.w_a)));
        let target = tokens.narrow(1, 1, n).index_select(1, frames).reshape([-1]);
        logits
            .reshape([-1, self.config.n_bins])
            .cross_entropy_for_logits(&target)
    }

    /// Encodes a whole song `[1, n, music_dim]`: `W^A z^A` `[n, coords * e_out]`.
    pub fn audio_logit_vectors(
        &self,
        music: &Tensor,
        mut on_chunk: impl FnMut(f32) -> bool,
    ) -> Option<Tensor> {
        let z = self
            .audio
            .forward_chunked(music, self.config.a_kernel, 0, 1000, &mut on_chunk)?;
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
}

#[cfg(test)]
mod tests {
    use super::sampling::reach_m;
    use super::*;
    use crate::models::smooth_columns;
    use ndarray::s;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use tch::nn::OptimizerConfig;

    fn model(seed: i64) -> (nn::VarStore, Tsmt) {
        tch::manual_seed(seed);
        let vs = nn::VarStore::new(Device::Cpu);
        let m = Tsmt::new(
            &vs.root(),
            Config {
                coords: 5,
                n_bins: 12,
                music_dim: 3,
                ..Config::tiny()
            },
        );
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
            let err = (&back.column(c) - &x.column(c))
                .mapv(f32::abs)
                .fold(0f32, |a, &v| a.max(v));
            assert!(
                err <= 0.5 * width + 1e-6,
                "column {c}: error {err}, bin {width}"
            );
        }
        assert_eq!(b.index(0, -100.0), 0);
        assert_eq!(b.index(0, 100.0), 299);
    }

    #[test]
    fn dequantising_removes_bin_jitter_and_keeps_the_opening() {
        // A slow ramp drawn one bin off at random every frame, after 5 given frames.
        let mut rng = StdRng::seed_from_u64(1);
        let clean = Array2::from_shape_fn((200, 1), |(t, _)| t as f32 * 0.004);
        let mut x = clean.mapv(|v| v)
            + Array2::from_shape_fn((200, 1), |_| 0.004 * rng.gen_range(-1..=1) as f32);
        let given = x.slice(s![..5, ..]).to_owned();
        let accel = |a: &Array2<f32>| {
            (6..194)
                .map(|t| (a[[t + 1, 0]] - 2.0 * a[[t, 0]] + a[[t - 1, 0]]).abs())
                .fold(0f32, f32::max)
        };
        let before = accel(&x);
        smooth_columns(&mut x, 5, 1.5);
        assert_eq!(x.slice(s![..5, ..]), given);
        let after = accel(&x);
        assert!(
            after < 0.25 * before,
            "second difference {before} -> {after}"
        );
        // The ramp itself is kept (away from the ends).
        let off = (20..180)
            .map(|t| (x[[t, 0]] - clean[[t, 0]]).abs())
            .fold(0f32, f32::max);
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
        let early = (a.narrow(1, 0, 6) - b.narrow(1, 0, 6))
            .abs()
            .max()
            .double_value(&[]);
        assert!(early < 1e-6, "frames ≤ 6 moved by {early}");
    }

    #[test]
    fn chunked_audio_equals_one_pass() {
        let (_vs, m) = model(1);
        let music = Tensor::randn([1, 70, 3], (Kind::Float, Device::Cpu));
        let whole = m.audio.forward(&music, 0, false);
        let chunked = m
            .audio
            .forward_chunked(&music, m.config.a_kernel, 0, 9, |_| true)
            .unwrap();
        let d = (whole - chunked).abs().max().double_value(&[]);
        assert!(d < 1e-5, "chunked audio differs by {d}");
    }

    #[test]
    fn cached_steps_equal_the_training_pass() {
        let (_vs, m) = model(2);
        let x = tokens(1, 9);
        let music = Tensor::randn([1, 9, 3], (Kind::Float, Device::Cpu));
        let logits = m.forward(&x, &music, 0, false); // [1, 8, 5, 12]
        let av = m
            .audio
            .forward(&music, 0, false)
            .squeeze_dim(0)
            .apply(&m.w_a);
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
        let g = Sampling {
            temperature: 1.0,
            top_k: 1,
        };
        assert_eq!(
            m.sample(&prefix, &av, g, 1, |_| true).unwrap(),
            m.sample(&prefix, &av, g, 2, |_| true).unwrap()
        );
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
        let s = Sampling {
            temperature: 0.3,
            top_k: 3,
        };
        let w = vec![0.01f32; 3];
        let never = StallGuard {
            min_reach_m: 0.0,
            window_frames: 5,
            boost: 10.0,
            reopen_reach_m: 0.0,
        };
        let always = StallGuard {
            min_reach_m: 1e9,
            window_frames: 5,
            boost: 10.0,
            reopen_reach_m: 0.0,
        };
        let plain = m.sample(&prefix, &av, s, 3, |_| true).unwrap();
        assert_eq!(
            m.sample_guarded(&prefix, &av, s, Some((&never, &w)), 3, |_| true)
                .unwrap(),
            plain
        );
        assert_ne!(
            m.sample_guarded(&prefix, &av, s, Some((&always, &w)), 3, |_| true)
                .unwrap(),
            plain
        );
    }

    #[test]
    fn top_k_and_temperature_shape_the_draws() {
        let logits = [0.0f32, 1.0, 2.0, 3.0];
        let mut probs = [0f32; 4];
        let mut rng = StdRng::seed_from_u64(0);
        let k2 = Sampling {
            temperature: 1.0,
            top_k: 2,
        };
        assert!((0..200).all(|_| k2.draw(&logits, &mut probs, &mut rng) >= 2));
        let cold = Sampling {
            temperature: 0.05,
            top_k: 0,
        };
        assert!((0..200).all(|_| cold.draw(&logits, &mut probs, &mut rng) == 3));
        let hot = Sampling {
            temperature: 5.0,
            top_k: 0,
        };
        let zeros = (0..400)
            .filter(|_| hot.draw(&logits, &mut probs, &mut rng) == 0)
            .count();
        assert!(
            zeros > 40,
            "a hot draw picked bin 0 only {zeros} of 400 times"
        );
    }

    #[test]
    fn loss_on_every_frame_equals_the_full_loss() {
        let (_vs, m) = model(5);
        let x = tokens(2, 9);
        let music = Tensor::randn([2, 9, 3], (Kind::Float, Device::Cpu));
        let all = Tensor::arange(8, (Kind::Int64, Device::Cpu));
        let full = m.loss(&x, &music, 3, false).double_value(&[]);
        let picked = m
            .loss_on_frames(&x, &x, &music, 3, &all, false)
            .double_value(&[]);
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
