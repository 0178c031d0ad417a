//! DanceRevolution: Huang, Hu, Wang, Sun, Chen, Tan, "Dance Revolution: Long-Term Dance
//! Generation with Music via Curriculum Learning", ICLR 2021.
//!
//! - §3.1 **music encoder**: a linear embedding of the acoustic features to `d_z`, sinusoidal
//!   positions, then `N` transformer encoder layers whose self-attention is *local*: position i
//!   attends only to the `k` positions around it. [`LocalSelfAttention`] gathers each window with
//!   `unfold`, so memory is O(n·k), never an n×n mask.
//! - §3.2 **dance decoder**: a multi-layer LSTM fed the previous pose; the pose is read out as
//!   `ŷ_i = [h_i; z_i]·W + b`. The initial state `h_0` is drawn from N(0, I) per dance, from the
//!   request's seed, which makes the output varied across seeds and fixed for one seed.
//! - §3.3 **dynamic auto-condition** (curriculum): during training the decoder input alternates
//!   `p` ground-truth frames with `q` of its own predictions, `q = ⌊λ·epoch⌋` (the linear schedule
//!   the paper found best). See [`DanceRevolution::forward_curriculum`].
//!
//! Sized for CPU: the paper's d_z = 1024 and a 3×1024 LSTM become the [`Config`] defaults below.
use serde::{Deserialize, Serialize};
use tch::nn;
use tch::{Device, Kind, Tensor};

use super::folder;
use super::layers::{sinusoid, Lstm, LstmState};
use crate::motion::dataset::NormStats;

mod served;
use served::StallWatch;
pub use served::{Served, Serving, StallGuard, WARM_UP_FRAMES};

/// Hyper-parameters, with the paper's symbols.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Config {
    /// Input music feature width (438 for the DanceRevolution feature set).
    pub music_dim: i64,
    /// Pose vector width (the motion module's model representation).
    pub pose_dim: i64,
    /// `d_z`: music encoder width (paper: 1024).
    pub d_z: i64,
    /// `N`: encoder layers (paper: 2).
    pub n_layers: i64,
    /// Attention heads (paper: 8).
    pub n_heads: i64,
    /// `k`: local attention window, in frames, centred on each position (paper: 100).
    pub k: i64,
    /// Position-wise FFN width.
    pub d_ff: i64,
    /// LSTM hidden width (paper: 1024).
    pub hidden: i64,
    /// LSTM layers (paper: 3).
    pub lstm_layers: i64,
    /// Dropout in the encoder during training.
    pub dropout: f64,
    /// The music features end with the beat clock ([`crate::audio::clock`], issue 25): weights
    /// trained before it read the paper's 438 columns only.
    #[serde(default)]
    pub beat_clock: bool,
    /// Hidden width of the arm head ([`ArmHead`], issue 25; not in the paper); 0: none, as every
    /// run before it.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub arm_head: i64,
}

fn is_zero(v: &i64) -> bool {
    *v == 0
}

impl Config {
    /// The configuration the committed weights were trained with: small enough for 2 CPU cores.
    pub fn cpu() -> Self {
        Self {
            music_dim: 438,
            pose_dim: 0,
            d_z: 128,
            n_layers: 2,
            n_heads: 8,
            k: 100,
            d_ff: 256,
            hidden: 256,
            lstm_layers: 3,
            dropout: 0.1,
            beat_clock: false,
            arm_head: 0,
        }
    }

    /// A tiny configuration for tests: same blocks, a fraction of the width.
    pub fn tiny(music_dim: i64, pose_dim: i64) -> Self {
        Self {
            music_dim,
            pose_dim,
            d_z: 16,
            n_layers: 1,
            n_heads: 2,
            k: 8,
            d_ff: 32,
            hidden: 32,
            lstm_layers: 2,
            dropout: 0.0,
            beat_clock: false,
            arm_head: 0,
        }
    }
}

/// The last song frame a served song can reach: 15 minutes at 25 fps (the upload limit's length).
pub const MAX_POSITION: i64 = 15 * 60 * 25;

/// Multi-head self-attention restricted to a window of `k` neighbours (paper §3.1).
#[derive(Debug)]
struct LocalSelfAttention {
    qkv: nn::Linear,
    out: nn::Linear,
    n_heads: i64,
    half: i64,
}

impl LocalSelfAttention {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            qkv: nn::linear(&p / "qkv", c.d_z, 3 * c.d_z, Default::default()),
            out: nn::linear(&p / "out", c.d_z, c.d_z, Default::default()),
            n_heads: c.n_heads,
            half: c.k / 2,
        }
    }

    /// `x`: `[b, n, d]` → `[b, n, d]`.
    ///
    /// Sliding chunks: the sequence is cut into blocks of `w = k/2` frames; block `j`'s queries
    /// score against blocks `j-1, j, j+1` (3w keys), and a band mask keeps `|i - i'| ≤ w`. Every
    /// tensor is O(n·k), and the products are dense batched matmuls rather than gathers.
    fn forward(&self, x: &Tensor) -> Tensor {
        let (b, n, d) = x.size3().expect("encoder input is [b, n, d]");
        let (h, w) = (self.n_heads, self.half.max(1));
        let dh = d / h;
        let nb = (n + w - 1) / w; // blocks
        let np = nb * w; // padded length
        let dev = x.device();
        // [b, n, 3, h, dh] → three of [b, h, nb, w, dh], time padded to a whole number of blocks.
        let qkv = x
            .apply(&self.qkv)
            .view([b, n, 3, h, dh])
            .permute([2, 0, 3, 1, 4]);
        let qkv = qkv
            .constant_pad_nd([0, 0, 0, np - n])
            .view([3, b, h, nb, w, dh]);
        let (q, k, v) = (qkv.get(0), qkv.get(1), qkv.get(2));
        let window = |t: Tensor| {
            let p = t.constant_pad_nd([0, 0, 0, 0, 1, 1]); // one empty block each side: [b, h, nb+2, w, dh]
            Tensor::cat(
                &[p.narrow(2, 0, nb), p.narrow(2, 1, nb), p.narrow(2, 2, nb)],
                3,
            ) // [b, h, nb, 3w, dh]
        };
        let (k, v) = (window(k), window(v));
        let scores = q.matmul(&k.transpose(-1, -2)) / (dh as f64).sqrt(); // [b, h, nb, w, 3w]
                                                                          // Query at blk*w + r, key slot s ↔ position (blk-1)*w + s: keep |offset| ≤ w, inside [0, n).
        let r = Tensor::arange(w, (Kind::Int64, dev)).view([1, w, 1]);
        let s = Tensor::arange(3 * w, (Kind::Int64, dev)).view([1, 1, 3 * w]);
        let blk = Tensor::arange(nb, (Kind::Int64, dev)).view([nb, 1, 1]);
        let kpos = (&blk - 1) * w + &s;
        let off = &s - &r; // = kpos - qpos + w
        let outside = off
            .lt(0)
            .logical_or(&off.gt(2 * w))
            .logical_or(&kpos.lt(0))
            .logical_or(&kpos.ge(n));
        let attn = scores
            .masked_fill(&outside.view([1, 1, nb, w, 3 * w]), f64::NEG_INFINITY)
            .softmax(-1, Kind::Float);
        let y = attn.matmul(&v).view([b, h, np, dh]).narrow(2, 0, n); // [b, h, n, dh]
        y.permute([0, 2, 1, 3])
            .contiguous()
            .view([b, n, d])
            .apply(&self.out)
    }
}

/// One encoder layer: local attention and a position-wise FFN, each with residual + layer norm.
#[derive(Debug)]
struct EncoderLayer {
    attn: LocalSelfAttention,
    norm1: nn::LayerNorm,
    ff1: nn::Linear,
    ff2: nn::Linear,
    norm2: nn::LayerNorm,
    dropout: f64,
}

impl EncoderLayer {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            attn: LocalSelfAttention::new(&p / "attn", c),
            norm1: nn::layer_norm(&p / "norm1", vec![c.d_z], Default::default()),
            ff1: nn::linear(&p / "ff1", c.d_z, c.d_ff, Default::default()),
            ff2: nn::linear(&p / "ff2", c.d_ff, c.d_z, Default::default()),
            norm2: nn::layer_norm(&p / "norm2", vec![c.d_z], Default::default()),
            dropout: c.dropout,
        }
    }

    fn forward(&self, x: &Tensor, train: bool) -> Tensor {
        let a = self.attn.forward(x).dropout(self.dropout, train);
        let x = (x + a).apply(&self.norm1);
        let f = x
            .apply(&self.ff1)
            .relu()
            .apply(&self.ff2)
            .dropout(self.dropout, train);
        (x + f).apply(&self.norm2)
    }
}

/// The music encoder (§3.1): features `[b, n, music_dim]` → `z` `[b, n, d_z]`.
#[derive(Debug)]
pub struct MusicEncoder {
    embed: nn::Linear,
    layers: Vec<EncoderLayer>,
    d_z: i64,
    k: i64,
}

impl MusicEncoder {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            embed: nn::linear(&p / "embed", c.music_dim, c.d_z, Default::default()),
            layers: (0..c.n_layers)
                .map(|i| EncoderLayer::new(&p / "layers" / i, c))
                .collect(),
            d_z: c.d_z,
            k: c.k,
        }
    }

    /// Encodes a window whose first frame is song frame `start` (for the position encoding).
    pub fn forward(&self, music: &Tensor, start: i64, train: bool) -> Tensor {
        let n = music.size()[1];
        let mut x =
            music.apply(&self.embed) + sinusoid(start, n, self.d_z, music.device()).unsqueeze(0);
        for layer in &self.layers {
            x = layer.forward(&x, train);
        }
        x
    }

    /// Encodes a whole song `[1, n, music_dim]` in overlapping chunks so memory stays bounded.
    /// Each chunk carries `k` frames of context on each side, which covers every window that an
    /// `N`-layer stack of local attention can see (`N·k/2` per side for `N` ≤ 2).
    pub fn forward_chunked(
        &self,
        music: &Tensor,
        chunk: i64,
        on_chunk: impl FnMut(f32) -> bool,
    ) -> Option<Tensor> {
        let n = music.size()[1];
        let ctx = self.k * (self.layers.len() as i64).max(1) / 2 + 1;
        super::layers::chunked(
            n,
            chunk,
            ctx,
            |cs, len| self.forward(&music.narrow(1, cs, len), cs, false),
            on_chunk,
        )
    }
}

/// The dance decoder (§3.2): an LSTM over the previous pose, read out with `[h_i; z_i]·W + b`.
#[derive(Debug)]
pub struct DanceDecoder {
    lstm: Lstm,
    readout: nn::Linear,
    arm_head: Option<ArmHead>,
}

/// The pose vector's columns of the elbows and wrists (`metrics::musicality::ARM_JOINTS`, x y z
/// each): what the [`ArmHead`] and `choreo train … --arm-readout-only` move.
pub fn arm_columns() -> Vec<i64> {
    crate::metrics::musicality::ARM_JOINTS
        .iter()
        .flat_map(|&j| (3 * j as i64)..(3 * j as i64 + 3))
        .collect()
}

/// Not in the paper (issue 25): a second read-out of the elbows and wrists from `[h_i; z_i]`, added
/// to the paper's read-out in what the decoder emits but never fed back, so the LSTM steps exactly
/// as it does without it: the legs and their timing (what the tempo test checks) stay the trained
/// network's own. Its last layer starts at zero, so a head added to trained weights changes
/// nothing until it trains. Training only the paper's read-out rows of the arms could not lift the
/// ballroom hold (0.32–0.35 m/s on the test waltzes, where the slowest real dance moves 0.43), and
/// its outputs, fed back, moved the other dances' timing.
#[derive(Debug)]
pub struct ArmHead {
    hidden: nn::Linear,
    out: nn::Linear,
    /// `[arm columns, pose_dim]`: one-hot, places the head's columns in the pose vector.
    place: Tensor,
}

impl ArmHead {
    fn new(p: nn::Path, c: &Config) -> Self {
        let columns = arm_columns();
        assert!(
            columns.iter().all(|&k| k < c.pose_dim),
            "the arm head needs the full pose vector"
        );
        let n = columns.len() as i64;
        let place = Tensor::zeros([n, c.pose_dim], (Kind::Float, p.device()));
        for (i, &k) in columns.iter().enumerate() {
            let _ = place.get(i as i64).get(k).fill_(1.0);
        }
        let zero = nn::LinearConfig {
            ws_init: nn::Init::Const(0.0),
            bs_init: Some(nn::Init::Const(0.0)),
            bias: true,
        };
        Self {
            hidden: nn::linear(
                &p / "hidden",
                c.hidden + c.d_z,
                c.arm_head,
                Default::default(),
            ),
            out: nn::linear(&p / "out", c.arm_head, n, zero),
            place,
        }
    }

    /// `[b, t, pose_dim]`: the head's offsets in the arm columns, zero elsewhere.
    fn forward(&self, hz: &Tensor) -> Tensor {
        hz.apply(&self.hidden)
            .tanh()
            .apply(&self.out)
            .matmul(&self.place)
    }
}

impl DanceDecoder {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            lstm: Lstm::new(&p / "lstm", c.pose_dim, c.hidden, c.lstm_layers),
            readout: nn::linear(
                &p / "readout",
                c.hidden + c.d_z,
                c.pose_dim,
                Default::default(),
            ),
            arm_head: (c.arm_head > 0).then(|| ArmHead::new(&p / "arm_head", c)),
        }
    }

    /// `h_0 ~ N(0, I)`, `c_0 = 0`, drawn from `seed` (not libtorch's global generator, which
    /// workers share).
    pub fn initial_state(&self, batch: i64, seed: u64, device: Device) -> LstmState {
        self.lstm.random_state(batch, seed, device)
    }

    /// Runs `inputs` `[b, t, pose]` (the poses *before* each output frame) against `z` `[b, t, d_z]`.
    /// Returns the paper's read-out, which the next step is fed, and the pose emitted (the same
    /// plus the [`ArmHead`]'s offsets where there is one).
    fn run(&self, inputs: &Tensor, z: &Tensor, state: &mut LstmState) -> (Tensor, Tensor) {
        let (fed, emitted, _) = self.run_with_input(inputs, z, state);
        (fed, emitted)
    }

    /// [`Self::run`], also returning `[h; z]`, what the read-outs read.
    fn run_with_input(
        &self,
        inputs: &Tensor,
        z: &Tensor,
        state: &mut LstmState,
    ) -> (Tensor, Tensor, Tensor) {
        let t = inputs.size()[1];
        let hs: Vec<Tensor> = (0..t)
            .map(|i| self.lstm.step(&inputs.select(1, i), state))
            .collect();
        let hz = Tensor::cat(&[Tensor::stack(&hs, 1), z.shallow_clone()], 2);
        let fed = hz.apply(&self.readout);
        let emitted = match self.arm_offsets(&hz) {
            Some(offsets) => &fed + offsets,
            None => fed.shallow_clone(),
        };
        (fed, emitted, hz)
    }

    /// The [`ArmHead`]'s offsets `[b, t, pose]` for read-out inputs `hz` `[b, t, hidden + d_z]`;
    /// `None` without a head.
    pub fn arm_offsets(&self, hz: &Tensor) -> Option<Tensor> {
        self.arm_head.as_ref().map(|head| head.forward(hz))
    }
}

/// The whole model.
#[derive(Debug)]
pub struct DanceRevolution {
    pub config: Config,
    pub encoder: MusicEncoder,
    pub decoder: DanceDecoder,
}

impl DanceRevolution {
    /// Builds the model's variables under `p` (checkpoint keys `encoder.*`, `decoder.*`).
    pub fn new(p: &nn::Path, config: Config) -> Self {
        Self {
            encoder: MusicEncoder::new(p / "encoder", &config),
            decoder: DanceDecoder::new(p / "decoder", &config),
            config,
        }
    }

    /// Training forward pass with the dynamic auto-condition curriculum (§3.3).
    ///
    /// `music` `[b, t, music_dim]`, `poses` `[b, t + 1, pose]`: frame 0 is the pose before the
    /// window and is only ever an input. Returns predictions for frames 1..=t. Inputs follow the
    /// pattern: `p` ground-truth frames, then `q` of the model's own previous outputs, repeated.
    /// With `q = 0` the whole window is teacher-forced in one LSTM call. `start` is the song frame
    /// the window begins at, for the encoder's position encoding: training draws it over every
    /// position a served song can reach ([`MAX_POSITION`]), so training and serving see the same
    /// encodings.
    #[allow(clippy::too_many_arguments)]
    pub fn forward_curriculum(
        &self,
        music: &Tensor,
        poses: &Tensor,
        start: i64,
        p: i64,
        q: i64,
        seed: u64,
        train: bool,
    ) -> Tensor {
        let (b, t, _) = music.size3().expect("music is [b, t, music_dim]");
        let z = self.encoder.forward(music, start, train);
        let mut state = self.decoder.initial_state(b, seed, music.device());
        // What the decoder emitted, and what it was fed next (they differ by the arm head).
        let (mut outputs, mut fed): (Vec<Tensor>, Vec<Tensor>) = (Vec::new(), Vec::new());
        let mut i = 0;
        while i < t {
            // Ground-truth segment: inputs are the true poses before frames i..i+p.
            let len = p.min(t - i);
            if len > 0 {
                let (f, e) =
                    self.decoder
                        .run(&poses.narrow(1, i, len), &z.narrow(1, i, len), &mut state);
                fed.push(f);
                outputs.push(e);
                i += len;
            }
            // Auto-conditioned segment: each input is the previous prediction.
            let free = if p == 0 { t - i } else { q.min(t - i) };
            for _ in 0..free {
                let prev = match fed.last() {
                    Some(y) => y.narrow(1, -1, 1),
                    None => poses.narrow(1, 0, 1),
                };
                let (f, e) = self.decoder.run(&prev, &z.narrow(1, i, 1), &mut state);
                fed.push(f);
                outputs.push(e);
                i += 1;
            }
        }
        Tensor::cat(&outputs, 1)
    }

    /// Generates `z.size(1)` frames autoregressively from encoded music `z` `[1, n, d_z]`.
    ///
    /// `seed_poses` `[1, s, pose]` (normalised), if given, are fed as ground truth for the first
    /// frames, so the dance continues from them; otherwise the first input is the mean pose (0).
    /// `on_step` is called every `report_every` frames with the fraction done and may stop the loop.
    /// `guard`, if given, kicks the LSTM state out of a held pose ([`StallGuard`]); its
    /// `NormStats` turn the normalised outputs back into metres. Without seed poses, the first
    /// `warm_up` frames are decoded and dropped before frame 0 ([`Serving::warm_up_frames`]).
    #[allow(clippy::too_many_arguments)]
    pub fn decode(
        &self,
        z: &Tensor,
        seed: u64,
        seed_poses: Option<&Tensor>,
        guard: Option<(&StallGuard, &NormStats)>,
        warm_up: i64,
        report_every: i64,
        on_step: impl FnMut(f32) -> bool,
    ) -> Option<Tensor> {
        self.decode_inner(
            z,
            seed,
            seed_poses,
            guard,
            warm_up,
            report_every,
            on_step,
            None,
        )
    }

    /// The network dancing alone as served (no seed poses): the read-out it fed itself `[1, n,
    /// pose]` and what the read-outs read at each frame, `[h; z]` `[1, n, hidden + d_z]`. What
    /// the arm head trains on (`choreo train dance-revolution --arm-head-only true`): the states
    /// a served dance is in, which windows of the curriculum never reach.
    pub fn rollout(
        &self,
        z: &Tensor,
        seed: u64,
        guard: Option<(&StallGuard, &NormStats)>,
        warm_up: i64,
    ) -> (Tensor, Tensor) {
        let mut steps = Vec::new();
        let _ = self.decode_inner(z, seed, None, guard, warm_up, 0, |_| true, Some(&mut steps));
        let (fed, hz): (Vec<Tensor>, Vec<Tensor>) = steps.into_iter().unzip();
        (Tensor::cat(&fed, 1), Tensor::cat(&hz, 1))
    }

    #[allow(clippy::too_many_arguments)]
    fn decode_inner(
        &self,
        z: &Tensor,
        seed: u64,
        seed_poses: Option<&Tensor>,
        guard: Option<(&StallGuard, &NormStats)>,
        warm_up: i64,
        report_every: i64,
        on_step: impl FnMut(f32) -> bool,
        sink: Option<&mut Vec<(Tensor, Tensor)>>,
    ) -> Option<Tensor> {
        let mut d = self.begin(z, seed, seed_poses, guard, warm_up);
        d.run_to(z, z.size()[1], report_every, on_step, sink)?;
        Some(d.output())
    }

    /// A decode of `z` `[1, n, d_z]` (the arguments of [`Self::decode`]) with its warm-up or
    /// seed poses run and nothing after them decoded yet: [`Decoding::run_to`] goes on.
    pub fn begin<'a>(
        &'a self,
        z: &Tensor,
        seed: u64,
        seed_poses: Option<&Tensor>,
        guard: Option<(&StallGuard, &'a NormStats)>,
        warm_up: i64,
    ) -> Decoding<'a> {
        let n = z.size()[1];
        let device = z.device();
        let mut d = Decoding {
            decoder: &self.decoder,
            state: self.decoder.initial_state(1, seed, device),
            // The guard's own draws: seeded apart from h_0's, so a dance that never stalls is
            // unchanged.
            watch: guard.map(|(g, norm)| StallWatch::new(*g, norm, seed)),
            prev: Tensor::zeros([1, 1, self.config.pose_dim], (Kind::Float, device)),
            out: Vec::with_capacity(n as usize),
            done: 0,
        };
        let seeded = seed_poses.map(|s| s.size()[1].min(n)).unwrap_or(0);
        if seeded == 0 {
            // Warm-up: the decoder starts from the mean pose, a standing stance it leaves only
            // slowly; run it over the song's opening and keep only its state and last pose.
            for i in 0..warm_up.min(n) {
                let (y, _) = d.decoder.run(&d.prev, &z.narrow(1, i, 1), &mut d.state);
                if let Some(w) = d.watch.as_mut() {
                    w.observe(&y, &mut d.state);
                }
                d.prev = y;
            }
        }
        if let Some(s) = seed_poses.filter(|_| seeded > 0) {
            // Teacher-force the seed frames: inputs are [mean, s_0 .. s_{m-2}], outputs replaced by s.
            let inputs = Tensor::cat(&[d.prev.shallow_clone(), s.narrow(1, 0, seeded - 1)], 1);
            let _ = d
                .decoder
                .run(&inputs, &z.narrow(1, 0, seeded), &mut d.state);
            let seg = s.narrow(1, 0, seeded);
            d.prev = seg.narrow(1, seeded - 1, 1);
            d.out.push(seg);
            d.done = seeded;
        }
        d
    }
}

/// One decode of [`DanceRevolution::decode`] that can stop after any frame and go on later,
/// decoding exactly what one run would: the opening check decodes a draw's opening, and the
/// draw it keeps goes on from there instead of being decoded again from its warm-up.
pub struct Decoding<'a> {
    decoder: &'a DanceDecoder,
    state: LstmState,
    watch: Option<StallWatch<'a>>,
    prev: Tensor,
    /// The emitted frames, in runs of one or more.
    out: Vec<Tensor>,
    done: i64,
}

impl Decoding<'_> {
    /// Frames decoded so far (seed poses included).
    pub fn done(&self) -> i64 {
        self.done
    }

    /// Decodes on up to frame `end` of `z` (the song's encoding, or as much of its start as is
    /// decoded: frame i reads `z`'s frame i). `on_step` is called with the fraction of `z` done
    /// after every `report_every`-th frame (0: never) and may stop it: `None`. `sink` collects
    /// what [`DanceRevolution::rollout`] returns.
    pub fn run_to(
        &mut self,
        z: &Tensor,
        end: i64,
        report_every: i64,
        mut on_step: impl FnMut(f32) -> bool,
        mut sink: Option<&mut Vec<(Tensor, Tensor)>>,
    ) -> Option<()> {
        let n = z.size()[1];
        for i in self.done..end.min(n) {
            let (y, emitted, hz) =
                self.decoder
                    .run_with_input(&self.prev, &z.narrow(1, i, 1), &mut self.state);
            if let Some(sink) = sink.as_mut() {
                sink.push((y.shallow_clone(), hz));
            }
            if let Some(w) = self.watch.as_mut() {
                w.observe(&y, &mut self.state);
            }
            self.prev = y;
            self.out.push(emitted);
            self.done = i + 1;
            if report_every > 0
                && (i + 1) % report_every == 0
                && !on_step((i + 1) as f32 / n as f32)
            {
                return None;
            }
        }
        Some(())
    }

    /// The frames decoded so far `[1, done, pose]`.
    pub fn output(&self) -> Tensor {
        if let Some(w) = self.watch.as_ref() {
            tracing::debug!(
                frames = self.done,
                kicked = w.kicked,
                "dance-revolution stall guard"
            );
        }
        Tensor::cat(&self.out, 1)
    }
}

/// The API id.
pub const ID: &str = "dance-revolution";

/// The curriculum behind the committed weights, stored in `model.json` beside the common record.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Curriculum {
    pub window: usize,
    pub p: i64,
    pub lambda: f64,
    pub q_max: i64,
    /// Weight of the spectral loss of the run's last stage (`train::spectral`); 0: none.
    #[serde(default)]
    pub spectral_weight: f64,
    /// Weight of the arms' spectral loss against the spine (`train::spectral`); 0: none.
    #[serde(default)]
    pub arm_weight: f64,
    /// The run trained only the read-out's arm rows (`choreo train … --arm-readout-only`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub arm_readout_only: bool,
    /// The run trained only the arm head (`choreo train … --arm-head-only`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub arm_head_only: bool,
}

/// `model.json`: the configuration, normalisation and training record.
pub type ModelFile = folder::ModelFile<Config, Curriculum, Serving>;

/// `q = ⌊λ·epoch⌋`, the linear schedule of §3.3.
pub fn curriculum_q(lambda: f64, epoch: usize) -> i64 {
    (lambda * epoch as f64).floor() as i64
}

#[cfg(test)]
mod tests {
    use super::served::reach_m;
    use super::*;
    use tch::nn::OptimizerConfig;

    fn model(seed: i64) -> (nn::VarStore, DanceRevolution) {
        tch::manual_seed(seed);
        let vs = nn::VarStore::new(Device::Cpu);
        let m = DanceRevolution::new(&vs.root(), Config::tiny(6, 5));
        (vs, m)
    }

    /// The arm head is never fed back: a trained head changes the emitted elbows and wrists and no
    /// other column of any frame (a head fed back would move the legs of every later frame). And
    /// weights saved without a head (`--init`) load into a network with one that dances exactly as
    /// before, the head's last layer being zero.
    #[test]
    fn arm_head_moves_the_arms_alone_and_starts_at_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plain.safetensors");
        tch::manual_seed(3);
        let plain_vs = nn::VarStore::new(Device::Cpu);
        let plain = DanceRevolution::new(&plain_vs.root(), Config::tiny(6, 73));
        plain_vs.save(&path).unwrap();
        let headed_vs = nn::VarStore::new(Device::Cpu);
        let headed = DanceRevolution::new(
            &headed_vs.root(),
            Config {
                arm_head: 8,
                ..Config::tiny(6, 73)
            },
        );
        super::super::train::load_widened(&headed_vs, &path).unwrap();
        let x = Tensor::randn([1, 40, 6], (Kind::Float, Device::Cpu));
        let dance = |m: &DanceRevolution| {
            let z = m.encoder.forward(&x, 0, false);
            m.decode(&z, 5, None, None, 4, 0, |_| true).unwrap()
        };
        let before = dance(&plain);
        let d = (dance(&headed) - &before).abs().max().double_value(&[]);
        assert_eq!(d, 0.0, "an untrained head moved the dance by {d}");
        tch::no_grad(|| {
            for (name, mut v) in headed_vs.variables() {
                if name.starts_with("decoder.arm_head.") {
                    let _ = v.copy_(&(v.randn_like() * 0.5));
                }
            }
        });
        let after = dance(&headed);
        let moved: Vec<i64> = Vec::<bool>::try_from(
            (after - &before)
                .abs()
                .gt(0.0)
                .any_dim(1, false)
                .squeeze_dim(0),
        )
        .unwrap()
        .iter()
        .enumerate()
        .filter(|(_, &m)| m)
        .map(|(i, _)| i as i64)
        .collect();
        assert_eq!(moved, arm_columns());
    }

    #[test]
    fn local_attention_sees_only_its_window() {
        let (_vs, m) = model(0);
        let x = Tensor::randn([1, 40, 16], (Kind::Float, Device::Cpu));
        let attn = &m.encoder.layers[0].attn;
        let y0 = attn.forward(&x);
        // Changing frame 39 must not change frame 0 when the window (k = 8) cannot reach it.
        let x2 = x.copy();
        let _ = x2.narrow(1, 39, 1).fill_(5.0);
        let y1 = attn.forward(&x2);
        let d0 = (y0.narrow(1, 0, 1) - y1.narrow(1, 0, 1))
            .abs()
            .max()
            .double_value(&[]);
        let d39 = (y0.narrow(1, 39, 1) - y1.narrow(1, 39, 1))
            .abs()
            .max()
            .double_value(&[]);
        assert!(d0 < 1e-6, "frame 0 moved by {d0}");
        assert!(d39 > 1e-3, "frame 39 did not move");
    }

    #[test]
    fn chunked_encoding_equals_whole() {
        let (_vs, m) = model(1);
        let x = Tensor::randn([1, 50, 6], (Kind::Float, Device::Cpu));
        let whole = m.encoder.forward(&x, 0, false);
        let chunked = m.encoder.forward_chunked(&x, 7, |_| true).unwrap();
        let d = (whole - chunked).abs().max().double_value(&[]);
        assert!(d < 1e-5, "chunked encoder differs by {d}");
    }

    #[test]
    fn same_seed_same_dance_other_seed_other_dance() {
        let (_vs, m) = model(2);
        let x = Tensor::randn([1, 30, 6], (Kind::Float, Device::Cpu));
        let z = m.encoder.forward(&x, 0, false);
        let a = m.decode(&z, 7, None, None, 0, 0, |_| true).unwrap();
        let b = m.decode(&z, 7, None, None, 0, 0, |_| true).unwrap();
        let c = m.decode(&z, 8, None, None, 0, 0, |_| true).unwrap();
        assert_eq!(a.size(), vec![1, 30, 5]);
        assert!((a.shallow_clone() - b).abs().max().double_value(&[]) == 0.0);
        assert!((a - c).abs().max().double_value(&[]) > 1e-4);
    }

    #[test]
    fn reach_is_the_farthest_pose_of_the_window_from_the_newest() {
        let h: std::collections::VecDeque<Vec<f32>> = [
            vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            vec![0.3, 0.4, 0.0, 0.0, 0.0, 0.0],
            vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.1],
        ]
        .into();
        // Newest is frame 2: frame 1 is (0.5 + 0.1) / 2 away, frame 0 is (0 + 0.1) / 2.
        assert!((reach_m(&h) - 0.3).abs() < 1e-6, "{}", reach_m(&h));
    }

    /// A 40-frame song encoded by `m` (random music), and the identity normalisation its
    /// stall guard reads poses through.
    fn guarded_song(m: &DanceRevolution) -> (Tensor, NormStats) {
        let x = Tensor::randn([1, 40, 6], (Kind::Float, Device::Cpu));
        let norm = NormStats {
            mean: vec![0.0; 5],
            std: vec![1.0; 5],
        };
        (m.encoder.forward(&x, 0, false), norm)
    }

    #[test]
    fn stall_guard_acts_only_on_a_held_pose() {
        let (_vs, m) = model(5);
        let (z, norm) = guarded_song(&m);
        let plain = m.decode(&z, 3, None, None, 0, 0, |_| true).unwrap();
        // A reach of 0 is always met: nothing is kicked and the dance is the unguarded one.
        let never = StallGuard {
            min_reach_m: 0.0,
            window_frames: 10,
            kick: 0.3,
        };
        let same = m
            .decode(&z, 3, None, Some((&never, &norm)), 0, 0, |_| true)
            .unwrap();
        assert_eq!(
            (plain.shallow_clone() - same).abs().max().double_value(&[]),
            0.0
        );
        // A reach no pose meets: the state is kicked from the 10th frame on, so frames 0..9 are as before.
        let always = StallGuard {
            min_reach_m: 1e9,
            window_frames: 10,
            kick: 0.3,
        };
        let kicked = m
            .decode(&z, 3, None, Some((&always, &norm)), 0, 0, |_| true)
            .unwrap();
        let head = (plain.narrow(1, 0, 10) - kicked.narrow(1, 0, 10))
            .abs()
            .max()
            .double_value(&[]);
        let tail = (plain.narrow(1, 10, 30) - kicked.narrow(1, 10, 30))
            .abs()
            .max()
            .double_value(&[]);
        assert_eq!(head, 0.0);
        assert!(tail > 1e-4, "kicks changed nothing");
        // Warm-up drops its frames: the dance still has one frame per music frame.
        let warmed = m
            .decode(&z, 3, None, Some((&never, &norm)), 12, 0, |_| true)
            .unwrap();
        assert_eq!(warmed.size(), vec![1, 40, 5]);
        assert!((plain - warmed).abs().max().double_value(&[]) > 1e-4);
    }

    /// The opening check decodes a draw's opening on the song's first frames and the kept draw
    /// goes on from there: with a warm-up and a guard that kicks, that is the one run's dance.
    #[test]
    fn a_decode_stopped_and_gone_on_with_is_the_one_runs() {
        let (_vs, m) = model(5);
        let (z, norm) = guarded_song(&m);
        // Kicks from the 4th frame on: the warm-up's and every later frame's.
        let always = StallGuard {
            min_reach_m: 1e9,
            window_frames: 4,
            kick: 0.3,
        };
        let guard = Some((&always, &norm));
        let one = m.decode(&z, 3, None, guard, 6, 0, |_| true).unwrap();
        let head = z.narrow(1, 0, 17);
        let mut d = m.begin(&head, 3, None, guard, 6);
        d.run_to(&head, 17, 0, |_| true, None).unwrap();
        assert_eq!(d.done(), 17);
        let opening = d.output();
        let mut reports = Vec::new();
        d.run_to(
            &z,
            40,
            10,
            |f| {
                reports.push(f);
                true
            },
            None,
        )
        .unwrap();
        let gone_on = d.output();
        assert_eq!(gone_on.size(), vec![1, 40, 5]);
        assert_eq!((&one - &gone_on).abs().max().double_value(&[]), 0.0);
        assert_eq!(
            (one.narrow(1, 0, 17) - opening)
                .abs()
                .max()
                .double_value(&[]),
            0.0
        );
        // Reported as a whole decode reports: after frames 20, 30 and 40 of 40.
        assert_eq!(reports, vec![0.5, 0.75, 1.0]);
    }

    #[test]
    fn curriculum_with_q_zero_is_teacher_forcing() {
        let (_vs, m) = model(3);
        let x = Tensor::randn([2, 25, 6], (Kind::Float, Device::Cpu));
        let y = Tensor::randn([2, 26, 5], (Kind::Float, Device::Cpu));
        let a = m.forward_curriculum(&x, &y, 0, 10, 0, 1, false);
        let b = m.forward_curriculum(&x, &y, 0, 25, 0, 1, false);
        assert_eq!(a.size(), vec![2, 25, 5]);
        assert!((a - b).abs().max().double_value(&[]) < 1e-5);
        let c = m.forward_curriculum(&x, &y, 0, 10, 5, 1, false);
        assert_eq!(c.size(), vec![2, 25, 5]);
    }

    #[test]
    fn loss_falls_on_a_few_batches() {
        let (vs, m) = model(4);
        let mut opt = nn::Adam::default().build(&vs, 3e-3).unwrap();
        let x = Tensor::randn([4, 20, 6], (Kind::Float, Device::Cpu));
        let y = Tensor::randn([4, 21, 5], (Kind::Float, Device::Cpu)).cumsum(1, Kind::Float) * 0.1;
        let loss = |m: &DanceRevolution| {
            (m.forward_curriculum(&x, &y, 0, 10, 2, 9, true) - y.narrow(1, 1, 20))
                .abs()
                .mean(Kind::Float)
        };
        let first = loss(&m).double_value(&[]);
        for _ in 0..40 {
            opt.backward_step(&loss(&m));
        }
        let last = loss(&m).double_value(&[]);
        assert!(last < 0.8 * first, "loss {first} -> {last}");
    }
}
