//! Key-pose controllable cross-modal transformer: "Controllable music-driven dance generation
//! with key-pose constraints" (its architecture §3, loss §3.4).
//!
//! - **Music transformer encoder** over the 15-d key-pose feature set (chroma 12, beat and
//!   downbeat 2, onset 1): [`MusicEncoder`].
//! - **Motion transformer encoder** over the seed motion, the first `T′` frames: [`MotionEncoder`].
//! - **Key-pose embedding** `E_k`: a linear map of the pose, zero on frames without a key pose:
//!   [`KeyPoseEmbedding`].
//! - **Local neighbour position embedding**: for frame t, the sinusoidal encodings of
//!   `|t − t_left|` and `|t − t_right|` (nearest key poses on either side), concatenated:
//!   [`local_position_embedding`].
//! - **Cross-modal transformer** over the time-concatenated `[motion; music]` tokens; music tokens
//!   also carry the key-pose embedding, the local position embedding and the ordinary position
//!   encoding: [`CrossModalTransformer`]. A linear **head** reads the poses off the music tokens.
//! - **Loss** (§3.4): reconstruction weighted by `ω(t) = 1 + λ·Σ_i exp(−(t − t_i)² / 2σ²)`:
//!   [`loss_weights`].
//!
//! Pose representation: the motion module's 73-d features (23 root-relative joint positions in
//! the facing frame, root velocity, yaw velocity), not the paper's 6-D rotations (the model card
//! says why), with the root height replaced by the lowest foot's clearance above the floor
//! ([`crate::motion::repr::height_to_clearance`]), so the height follows from the legs. Whole
//! songs are generated in overlapping windows, each seeded with the tail of the previous one
//! ([`KeyposeTransformer::generate_long`]).
//!
//! This file holds the network. [`keys`] maps key poses into pose space and pulls the result
//! through them; [`scaffold`] draws the seed motion and the scaffold of real poses that make the
//! seed and the song matter, retimed onto the song's beats by [`beats`]; [`served`] loads a
//! trained folder and serves it.
pub mod beats;
pub mod keys;
pub mod scaffold;
pub mod served;

pub use keys::{local_keys, pass_through_keys, to_local, LocalKey};
pub use served::{generate_features, Generation, KeySampling, ModelFile, Served, Serving, ID};

use serde::{Deserialize, Serialize};
use tch::nn;
use tch::{Kind, Tensor};

use super::layers::{position_encoding, sinusoid_of, Dims, Stack};
use crate::motion::repr::{self, POSE_DIM};
use crate::motion::smoothstep;

/// Hyper-parameters, with the paper's symbols.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Config {
    /// Music feature width (15: chroma 12, beat/downbeat 2, onset 1).
    pub music_dim: i64,
    /// Pose vector width (73: the motion module's features).
    pub pose_dim: i64,
    /// Key-pose width: the local joint positions only, no global translation (69).
    pub key_dim: i64,
    /// `d`: model width (paper's light model: 256).
    pub d: i64,
    /// Attention heads (paper: 4).
    pub n_heads: i64,
    /// Music encoder layers.
    pub music_layers: i64,
    /// Motion (seed) encoder layers.
    pub motion_layers: i64,
    /// Cross-modal transformer layers (paper's light model: 8 in all).
    pub cross_layers: i64,
    /// Position-wise FFN width.
    pub d_ff: i64,
    /// `T`: frames per generated window.
    pub window: i64,
    /// `T′`: seed-motion frames at the start of each window.
    pub seed_len: i64,
    /// Dropout during training.
    pub dropout: f64,
    /// `λ`: weight of the key-pose terms in ω(t).
    pub lambda: f64,
    /// `σ`: width of each key-pose term in ω(t), frames.
    pub sigma: f64,
}

impl Config {
    /// The arithmetic per motion frame (a multiply-add counts 2): every window of `window` frames
    /// runs the music, motion and cross stacks whole (self-attention over all its tokens), and
    /// windows advance by `window − seed_len − crossfade` frames ([`window_advance`]).
    pub fn frame_flops(&self) -> f64 {
        let (w, ts, d, ff) = (
            self.window as f64,
            self.seed_len as f64,
            self.d as f64,
            self.d_ff as f64,
        );
        let layer = |n: f64| n * (8.0 * d * d + 4.0 * d * ff) + 4.0 * n * n * d;
        let window = 2.0 * w * self.music_dim as f64 * d
            + self.music_layers as f64 * layer(w)
            + 2.0 * ts * self.pose_dim as f64 * d
            + self.motion_layers as f64 * layer(ts)
            + 2.0 * w * self.key_dim as f64 * d
            + self.cross_layers as f64 * layer(w + ts)
            + 2.0 * w * d * self.pose_dim as f64;
        window / window_advance(self.window, self.seed_len) as f64
    }

    /// The sizes of every transformer stack of the model.
    pub fn dims(&self) -> Dims {
        Dims {
            d: self.d,
            n_heads: self.n_heads,
            d_ff: self.d_ff,
            dropout: self.dropout,
        }
    }

    /// The configuration the committed weights were trained with: small enough for CPU.
    pub fn cpu() -> Self {
        Self {
            music_dim: crate::audio::features::KEYPOSE_DIM as i64,
            pose_dim: repr::FEATURE_DIM as i64,
            key_dim: POSE_DIM as i64,
            d: 128,
            n_heads: 4,
            music_layers: 2,
            motion_layers: 1,
            cross_layers: 3,
            d_ff: 256,
            window: 100,
            seed_len: 25,
            dropout: 0.1,
            lambda: 3.0,
            sigma: 3.0,
        }
    }

    /// A tiny configuration for tests: same blocks, a fraction of the width.
    pub fn tiny(music_dim: i64, pose_dim: i64, key_dim: i64) -> Self {
        Self {
            music_dim,
            pose_dim,
            key_dim,
            d: 16,
            n_heads: 2,
            music_layers: 1,
            motion_layers: 1,
            cross_layers: 1,
            d_ff: 32,
            window: 20,
            seed_len: 5,
            dropout: 0.0,
            lambda: 3.0,
            sigma: 2.0,
        }
    }
}

/// Distance used when a frame has no key pose on one side: far beyond any window.
const NO_KEY_DISTANCE: f64 = 1000.0;

/// The local neighbour position embedding `[n, d]` for key frames `keys` (sorted or not):
/// `[PE(|t − t_left|); PE(|t − t_right|)]`, each half `d/2` wide.
pub fn local_position_embedding(n: i64, keys: &[i64], d: i64) -> Vec<f32> {
    let half = d / 2;
    let mut left = Vec::with_capacity(n as usize);
    let mut right = Vec::with_capacity(n as usize);
    for t in 0..n {
        let l = keys
            .iter()
            .filter(|&&k| k <= t)
            .map(|&k| (t - k) as f64)
            .fold(NO_KEY_DISTANCE, f64::min);
        let r = keys
            .iter()
            .filter(|&&k| k >= t)
            .map(|&k| (k - t) as f64)
            .fold(NO_KEY_DISTANCE, f64::min);
        left.push(l);
        right.push(r);
    }
    let (a, b) = (sinusoid_of(&left, half), sinusoid_of(&right, d - half));
    let mut out = Vec::with_capacity((n * d) as usize);
    for t in 0..n as usize {
        out.extend_from_slice(&a[t * half as usize..(t + 1) * half as usize]);
        out.extend_from_slice(&b[t * (d - half) as usize..(t + 1) * (d - half) as usize]);
    }
    out
}

/// `ω(t) = 1 + λ·Σ_i exp(−(t − t_i)² / 2σ²)` for `t in 0..n` (§3.4).
pub fn loss_weights(n: i64, keys: &[i64], lambda: f64, sigma: f64) -> Vec<f32> {
    (0..n)
        .map(|t| {
            let s: f64 = keys
                .iter()
                .map(|&k| (-((t - k) as f64).powi(2) / (2.0 * sigma * sigma)).exp())
                .sum();
            (1.0 + lambda * s) as f32
        })
        .collect()
}

/// Music transformer encoder: `[b, T, music_dim]` → `[b, T, d]`.
#[derive(Debug)]
pub struct MusicEncoder {
    embed: nn::Linear,
    stack: Stack,
    d: i64,
}

impl MusicEncoder {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            embed: nn::linear(&p / "embed", c.music_dim, c.d, Default::default()),
            stack: Stack::new(&p / "encoder", c.dims(), c.music_layers),
            d: c.d,
        }
    }

    pub fn forward(&self, music: &Tensor, train: bool) -> Tensor {
        let n = music.size()[1];
        self.stack.forward(
            &(music.apply(&self.embed) + position_encoding(n, self.d, music.device()).unsqueeze(0)),
            None,
            train,
        )
    }
}

/// Motion transformer encoder over the seed motion: `[b, T′, pose_dim]` → `[b, T′, d]`.
#[derive(Debug)]
pub struct MotionEncoder {
    embed: nn::Linear,
    stack: Stack,
    d: i64,
}

impl MotionEncoder {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            embed: nn::linear(&p / "embed", c.pose_dim, c.d, Default::default()),
            stack: Stack::new(&p / "encoder", c.dims(), c.motion_layers),
            d: c.d,
        }
    }

    pub fn forward(&self, seed: &Tensor, train: bool) -> Tensor {
        let n = seed.size()[1];
        self.stack.forward(
            &(seed.apply(&self.embed) + position_encoding(n, self.d, seed.device()).unsqueeze(0)),
            None,
            train,
        )
    }
}

/// Key-pose embedding: `E_k = mask · (W_k·k + b_k)`, zero where no key pose is given.
#[derive(Debug)]
pub struct KeyPoseEmbedding {
    proj: nn::Linear,
}

impl KeyPoseEmbedding {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            proj: nn::linear(&p / "proj", c.key_dim, c.d, Default::default()),
        }
    }

    /// `keys` `[b, T, key_dim]`, `mask` `[b, T]` (1 on key frames) → `[b, T, d]`.
    pub fn forward(&self, keys: &Tensor, mask: &Tensor) -> Tensor {
        keys.apply(&self.proj) * mask.unsqueeze(-1)
    }
}

/// Cross-modal transformer over `[motion; music]` tokens, with a learned segment embedding so
/// the two modalities stay distinguishable when they share a time index.
#[derive(Debug)]
pub struct CrossModalTransformer {
    segment: Tensor,
    stack: Stack,
    d: i64,
}

impl CrossModalTransformer {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            segment: p.var(
                "segment",
                &[2, c.d],
                nn::Init::Randn {
                    mean: 0.0,
                    stdev: 0.02,
                },
            ),
            stack: Stack::new(&p / "encoder", c.dims(), c.cross_layers),
            d: c.d,
        }
    }

    /// `motion` `[b, T′, d]`, `music` `[b, T, d]` (already carrying key-pose and local position
    /// embeddings) → the music tokens after mixing, `[b, T, d]`.
    pub fn forward(&self, motion: &Tensor, music: &Tensor, train: bool) -> Tensor {
        let (ts, t) = (motion.size()[1], music.size()[1]);
        let dev = music.device();
        let m = motion + position_encoding(ts, self.d, dev).unsqueeze(0) + self.segment.get(0);
        let a = music + position_encoding(t, self.d, dev).unsqueeze(0) + self.segment.get(1);
        self.stack
            .forward(&Tensor::cat(&[m, a], 1), None, train)
            .narrow(1, ts, t)
    }
}

/// The inputs of one window, all normalised.
pub struct WindowInput {
    /// `[b, T, music_dim]`.
    pub music: Tensor,
    /// `[b, T′, pose_dim]`.
    pub seed: Tensor,
    /// `[b, T, key_dim]`, zero where no key pose.
    pub keys: Tensor,
    /// `[b, T]`, 1 on key frames.
    pub key_mask: Tensor,
    /// `[b, T, d]`, from [`local_position_embedding`].
    pub local_pos: Tensor,
}

/// Frames over which a window's output crossfades into the previous window's: `T′`, or less
/// when the window is too short to hold a seed, a crossfade and new frames.
pub fn crossfade_len(w: i64, ts: i64) -> i64 {
    ts.min((w - ts) / 2).max(0)
}

/// Frames one window of `w` frames seeded with `ts` advances on the one before it:
/// `w − T′ − crossfade`, at least 1.
pub fn window_advance(w: i64, ts: i64) -> i64 {
    (w - ts - crossfade_len(w, ts)).max(1)
}

/// Start frames of the overlapping windows [`KeyposeTransformer::generate_long`] uses for `total`
/// frames (at least one window long): windows of `w` frames advance by [`window_advance`], so
/// each is seeded with `T′` final frames and then overlaps the previous window's output by the
/// crossfade; the last window is aligned to the end.
pub fn generation_windows(total: i64, w: i64, ts: i64) -> Vec<i64> {
    let advance = window_advance(w, ts);
    let mut starts = Vec::new();
    let mut s = 0;
    loop {
        starts.push(s.min(total - w));
        if s + w >= total {
            break;
        }
        s += advance;
    }
    starts
}

/// The centre of each crossfade in an `n`-frame generation, where one window's output takes
/// over from the previous one's.
pub fn join_frames(n: usize, config: &Config) -> Vec<usize> {
    let (w, ts) = (config.window, config.seed_len);
    let starts = generation_windows((n as i64).max(w), w, ts);
    starts
        .windows(2)
        .map(|p| ((p[1] + ts + p[0] + w) / 2) as usize)
        .filter(|&f| f < n)
        .collect()
}

/// The whole model.
#[derive(Debug)]
pub struct KeyposeTransformer {
    pub config: Config,
    pub music: MusicEncoder,
    pub motion: MotionEncoder,
    pub key_embed: KeyPoseEmbedding,
    pub cross: CrossModalTransformer,
    head: nn::Linear,
}

impl KeyposeTransformer {
    /// Builds the variables under `p` (keys `music.*`, `motion.*`, `key_embed.*`, `cross.*`, `head.*`).
    pub fn new(p: &nn::Path, config: Config) -> Self {
        Self {
            music: MusicEncoder::new(p / "music", &config),
            motion: MotionEncoder::new(p / "motion", &config),
            key_embed: KeyPoseEmbedding::new(p / "key_embed", &config),
            cross: CrossModalTransformer::new(p / "cross", &config),
            head: nn::linear(p / "head", config.d, config.pose_dim, Default::default()),
            config,
        }
    }

    /// One window → poses `[b, T, pose_dim]` (normalised).
    pub fn forward(&self, x: &WindowInput, train: bool) -> Tensor {
        let music = self.music.forward(&x.music, train)
            + self.key_embed.forward(&x.keys, &x.key_mask)
            + &x.local_pos;
        let motion = self.motion.forward(&x.seed, train);
        self.cross.forward(&motion, &music, train).apply(&self.head)
    }

    /// Builds one window's inputs (batch 1) from rows and key frames local to the window.
    pub fn window_input(
        &self,
        music: &Tensor,
        seed: &Tensor,
        keys: &[(i64, Vec<f32>)],
    ) -> WindowInput {
        let c = &self.config;
        let t = music.size()[0];
        let mut k = vec![0f32; (t * c.key_dim) as usize];
        let mut mask = vec![0f32; t as usize];
        for (f, pose) in keys {
            let f = *f as usize;
            k[f * c.key_dim as usize..(f + 1) * c.key_dim as usize].copy_from_slice(pose);
            mask[f] = 1.0;
        }
        let frames: Vec<i64> = keys.iter().map(|(f, _)| *f).collect();
        WindowInput {
            music: music.unsqueeze(0),
            seed: seed.unsqueeze(0),
            keys: Tensor::from_slice(&k).view([1, t, c.key_dim]),
            key_mask: Tensor::from_slice(&mask).view([1, t]),
            local_pos: Tensor::from_slice(&local_position_embedding(t, &frames, c.d))
                .view([1, t, c.d]),
        }
    }

    /// Generates `n` frames from music `[n, music_dim]` in overlapping windows of `T` frames
    /// ([`generation_windows`]), each seeded with `T′` final frames (the first with `seed`
    /// `[T′, pose_dim]`, or the mean pose) and crossfaded into the previous window's output. Key
    /// poses `(frame, [key_dim])` (normalised) go to every window that contains them. With
    /// `keep_seed` the seed's frames are the output's first `T′` (a user's seed motion is
    /// continued, not redrawn); without, the network's own rendering of them is, which joins the
    /// frames after them without a jump (a seed drawn from the pose bank only has to start the
    /// dance). `on_window(done, total)` may stop the loop. Returns `[n, pose_dim]`.
    pub fn generate_long(
        &self,
        music: &Tensor,
        seed: Option<&Tensor>,
        keep_seed: bool,
        keys: &[(i64, Vec<f32>)],
        mut on_window: impl FnMut(usize, usize) -> bool,
    ) -> Option<Tensor> {
        let c = &self.config;
        let (w, ts) = (c.window, c.seed_len);
        let n = music.size()[0];
        let dev = music.device();
        // Pad short songs with the mean (zero) music to one whole window.
        let total = n.max(w);
        let music = if total > n {
            Tensor::cat(
                &[
                    music.shallow_clone(),
                    Tensor::zeros([total - n, c.music_dim], (Kind::Float, dev)),
                ],
                0,
            )
        } else {
            music.shallow_clone()
        };
        let starts = generation_windows(total, w, ts);
        let out = Tensor::zeros([total, c.pose_dim], (Kind::Float, dev));
        let mut written = 0i64; // frames [0, written) have output
        let seeded = seed.is_some() && keep_seed;
        for (i, &s) in starts.iter().enumerate() {
            let seed_rows = if i == 0 {
                match seed {
                    Some(sd) => sd.shallow_clone(),
                    None => Tensor::zeros([ts, c.pose_dim], (Kind::Float, dev)),
                }
            } else {
                out.narrow(0, s, ts)
            };
            let local: Vec<(i64, Vec<f32>)> = keys
                .iter()
                .filter(|(f, _)| *f >= s && *f < s + w)
                .map(|(f, p)| (f - s, p.clone()))
                .collect();
            let y = self
                .forward(
                    &self.window_input(&music.narrow(0, s, w), &seed_rows, &local),
                    false,
                )
                .squeeze_dim(0);
            if i == 0 {
                // The given seed stays as it is; the network writes the rest of the window.
                let keep = if seeded {
                    out.narrow(0, 0, ts).copy_(&seed_rows);
                    ts
                } else {
                    0
                };
                out.narrow(0, keep, w - keep)
                    .copy_(&y.narrow(0, keep, w - keep));
            } else {
                // [s, s + T′) is this window's seed. Over [s + T′, written) the previous window
                // has output too: crossfade from it to this one, so the join has no jump; write
                // the rest as it is.
                let (b0, l) = (s + ts, written - s - ts);
                if l > 0 {
                    let ramp: Vec<f32> = (1..=l)
                        .map(|k| smoothstep(0.0, 1.0, k as f64 / (l + 1) as f64) as f32)
                        .collect();
                    let ramp = Tensor::from_slice(&ramp).view([l, 1]).to_device(dev);
                    let blended = out.narrow(0, b0, l) * (1.0 - &ramp) + y.narrow(0, ts, l) * &ramp;
                    out.narrow(0, b0, l).copy_(&blended);
                }
                let new = s + w - written.max(b0);
                if new > 0 {
                    out.narrow(0, s + w - new, new)
                        .copy_(&y.narrow(0, w - new, new));
                }
            }
            written = s + w;
            if !on_window(i + 1, starts.len()) {
                return None;
            }
        }
        Some(out.narrow(0, 0, n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::nn::OptimizerConfig;
    use tch::Device;

    fn model(seed: i64) -> (nn::VarStore, KeyposeTransformer) {
        tch::manual_seed(seed);
        let vs = nn::VarStore::new(Device::Cpu);
        let m = KeyposeTransformer::new(&vs.root(), Config::tiny(4, 7, 6));
        (vs, m)
    }

    #[test]
    fn window_shapes() {
        let (_vs, m) = model(0);
        let x = m.window_input(
            &Tensor::randn([20, 4], (Kind::Float, Device::Cpu)),
            &Tensor::randn([5, 7], (Kind::Float, Device::Cpu)),
            &[(7, vec![0.5; 6])],
        );
        assert_eq!(m.forward(&x, false).size(), vec![1, 20, 7]);
    }

    #[test]
    fn windows_seed_from_final_frames_and_overlap_for_the_crossfade() {
        for (total, w, ts) in [
            (100, 100, 25),
            (101, 100, 25),
            (1234, 100, 25),
            (53, 20, 5),
            (20, 20, 5),
        ] {
            let starts = generation_windows(total, w, ts);
            assert_eq!(starts[0], 0);
            assert_eq!(*starts.last().unwrap() + w, total, "{total} {w} {ts}");
            for p in starts.windows(2) {
                assert!(p[1] > p[0], "{starts:?}");
                // The seed lies inside what the previous window wrote, and some frames are new.
                assert!(p[1] + ts <= p[0] + w && p[1] + w > p[0] + w, "{starts:?}");
            }
        }
        assert_eq!(crossfade_len(100, 25), 25);
        let c = Config {
            window: 100,
            seed_len: 25,
            ..Config::tiny(4, 7, 6)
        };
        assert_eq!(join_frames(300, &c), vec![87, 137, 187, 237]);
    }

    #[test]
    fn long_generation_is_deterministic_and_covers_the_song() {
        let (_vs, m) = model(1);
        let music = Tensor::randn([53, 4], (Kind::Float, Device::Cpu));
        let keys = vec![(30i64, vec![1.0f32; 6])];
        let mut windows = 0;
        let a = m
            .generate_long(&music, None, true, &keys, |_, _| {
                windows += 1;
                true
            })
            .unwrap();
        let b = m
            .generate_long(&music, None, true, &keys, |_, _| true)
            .unwrap();
        assert_eq!(a.size(), vec![53, 7]);
        assert_eq!(
            windows, 5,
            "windows of 20 advancing by 10 (5 seed + 5 crossfade frames) over 53 frames"
        );
        assert_eq!((&a - &b).abs().max().double_value(&[]), 0.0);
        // The key pose is an input: removing it changes the dance near it.
        let c = m
            .generate_long(&music, None, true, &[], |_, _| true)
            .unwrap();
        assert!((&a - &c).abs().max().double_value(&[]) > 1e-5);
        // A given seed is kept verbatim at the start.
        let seed = Tensor::randn([5, 7], (Kind::Float, Device::Cpu));
        let d = m
            .generate_long(&music, Some(&seed), true, &keys, |_, _| true)
            .unwrap();
        assert!((d.narrow(0, 0, 5) - &seed).abs().max().double_value(&[]) < 1e-6);
        // Cancelling stops it.
        assert!(m
            .generate_long(&music, None, true, &keys, |i, _| i < 2)
            .is_none());
        // A drawn seed is not kept: the network's rendering of it starts the dance.
        let e = m
            .generate_long(&music, Some(&seed), false, &keys, |_, _| true)
            .unwrap();
        assert!((e.narrow(0, 0, 5) - &seed).abs().max().double_value(&[]) > 1e-4);
        assert_eq!(e.size(), vec![53, 7]);
    }

    #[test]
    fn local_position_embedding_tracks_nearest_keys() {
        let e = local_position_embedding(10, &[2, 7], 8);
        let pe = |d: f64| sinusoid_of(&[d], 4);
        // Frame 4: left key 2 (distance 2), right key 7 (distance 3).
        assert_eq!(&e[4 * 8..4 * 8 + 4], pe(2.0).as_slice());
        assert_eq!(&e[4 * 8 + 4..5 * 8], pe(3.0).as_slice());
        // Frame 9: no key to the right.
        assert_eq!(&e[9 * 8 + 4..10 * 8], pe(NO_KEY_DISTANCE).as_slice());
    }

    #[test]
    fn loss_weights_peak_at_keys() {
        let w = loss_weights(10, &[3], 2.0, 1.0);
        assert!((w[3] - 3.0).abs() < 1e-6);
        assert!((w[0] - 1.0).abs() < 0.03);
        assert_eq!(loss_weights(4, &[], 5.0, 1.0), vec![1.0; 4]);
    }

    #[test]
    fn loss_falls_on_a_few_batches() {
        let (vs, m) = model(4);
        let mut opt = nn::Adam::default().build(&vs, 3e-3).unwrap();
        let music = Tensor::randn([4, 20, 4], (Kind::Float, Device::Cpu));
        let poses =
            Tensor::randn([4, 20, 7], (Kind::Float, Device::Cpu)).cumsum(1, Kind::Float) * 0.2;
        let x = WindowInput {
            music,
            seed: poses.narrow(1, 0, 5),
            keys: poses.narrow(2, 0, 6) * Tensor::zeros([4, 20, 1], (Kind::Float, Device::Cpu)),
            key_mask: Tensor::zeros([4, 20], (Kind::Float, Device::Cpu)),
            local_pos: Tensor::zeros([4, 20, 16], (Kind::Float, Device::Cpu)),
        };
        let w = Tensor::from_slice(&loss_weights(20, &[10], 3.0, 2.0)).view([1, 20, 1]);
        let loss =
            |m: &KeyposeTransformer| ((m.forward(&x, true) - &poses).abs() * &w).mean(Kind::Float);
        let first = loss(&m).double_value(&[]);
        for _ in 0..40 {
            opt.backward_step(&loss(&m));
        }
        let last = loss(&m).double_value(&[]);
        assert!(last < 0.7 * first, "loss {first} -> {last}");
    }
}
