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
use super::layers::{Lstm, LstmState};
use crate::motion::dataset::NormStats;

mod arm_head;
mod decoding;
mod encoder;
pub mod figures;
mod served;
pub use arm_head::{arm_columns, ArmHead};
pub use decoding::Decoding;
pub use encoder::MusicEncoder;
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
    /// The music features end with the beat clock ([`crate::audio::clock`]): weights
    /// trained before it read the paper's 438 columns only.
    #[serde(default)]
    pub beat_clock: bool,
    /// Hidden width of the arm head ([`ArmHead`]; not in the paper); 0: none, the paper's
    /// read-out alone.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub arm_head: i64,
    /// The arm head also reads the figure the arms are to hold ([`figures`]; not in the
    /// paper).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub arm_figures: bool,
}

fn is_zero(v: &i64) -> bool {
    *v == 0
}

impl Config {
    /// The decoder's arithmetic per motion frame (a multiply-add counts 2): the LSTM step
    /// (`lstm_layers` cells, the first reading the last pose), the readout from hidden state and
    /// latent, and the arm head where there is one. The encoder runs once per song and is not in
    /// it. `choreo bench generate` sets it against one core's peak.
    pub fn frame_flops(&self) -> f64 {
        let (p, h, l, z) = (
            self.pose_dim as f64,
            self.hidden as f64,
            self.lstm_layers as f64,
            self.d_z as f64,
        );
        let lstm = 8.0 * h * (p + (2.0 * l - 1.0) * h);
        let readout = 2.0 * (h + z) * p;
        let arm = if self.arm_head > 0 {
            let a = self.arm_head as f64;
            let figures = if self.arm_figures {
                figures::FIGURE_DIM as f64
            } else {
                0.0
            };
            let n = arm_head::arm_columns().len() as f64;
            2.0 * (h + z + figures) * a + 2.0 * a * n + 2.0 * n * p
        } else {
            0.0
        };
        lstm + readout + arm
    }

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
            arm_figures: false,
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
            arm_figures: false,
        }
    }
}

/// The last song frame a served song can reach: 15 minutes at 25 fps (the upload limit's length).
pub const MAX_POSITION: i64 = 15 * 60 * 25;

/// The dance decoder (§3.2): an LSTM over the previous pose, read out with `[h_i; z_i]·W + b`.
#[derive(Debug)]
pub struct DanceDecoder {
    lstm: Lstm,
    readout: nn::Linear,
    arm_head: Option<ArmHead>,
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
        let (fed, emitted, _) = self.run_with_input(inputs, z, None, state);
        (fed, emitted)
    }

    /// [`Self::run`], also returning `[h; z]`, what the read-outs read; `figure` `[b, t,
    /// FIGURE_DIM]` is what a head with figures reads ([`figures`]).
    fn run_with_input(
        &self,
        inputs: &Tensor,
        z: &Tensor,
        figure: Option<&Tensor>,
        state: &mut LstmState,
    ) -> (Tensor, Tensor, Tensor) {
        let t = inputs.size()[1];
        let hs: Vec<Tensor> = (0..t)
            .map(|i| self.lstm.step(&inputs.select(1, i), state))
            .collect();
        let hz = Tensor::cat(&[Tensor::stack(&hs, 1), z.shallow_clone()], 2);
        let fed = hz.apply(&self.readout);
        let emitted = match self.arm_offsets(&hz, figure) {
            Some(offsets) => &fed + offsets,
            None => fed.shallow_clone(),
        };
        (fed, emitted, hz)
    }

    /// The [`ArmHead`]'s offsets `[b, t, pose]` for read-out inputs `hz` `[b, t, hidden + d_z]`
    /// and, for a head with figures, the figures `[b, t, FIGURE_DIM]`; `None` without a head.
    pub fn arm_offsets(&self, hz: &Tensor, figure: Option<&Tensor>) -> Option<Tensor> {
        self.arm_head.as_ref().map(|head| head.forward(hz, figure))
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
            figures: None,
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

    /// A tiny network from `seed` (6 music columns, 5 pose columns).
    pub(super) fn model(seed: i64) -> (nn::VarStore, DanceRevolution) {
        tch::manual_seed(seed);
        let vs = nn::VarStore::new(Device::Cpu);
        let m = DanceRevolution::new(&vs.root(), Config::tiny(6, 5));
        (vs, m)
    }

    /// The decoder uses each of its weight matrices once a frame, so its arithmetic is twice
    /// their entries (biases aside): the formula follows the network it describes.
    #[test]
    fn frame_flops_are_twice_the_decoder_weights() {
        let (vs, _m) = model(1);
        let weights: usize = vs
            .variables()
            .iter()
            .filter(|(name, t)| name.starts_with("decoder.") && t.dim() >= 2)
            .map(|(_, t)| t.numel())
            .sum();
        let flops = Config::tiny(6, 5).frame_flops();
        assert!(weights > 0);
        assert_eq!(
            flops,
            2.0 * weights as f64,
            "{flops} against {weights} weights"
        );
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
