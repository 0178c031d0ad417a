//! DanceNet: Zhuang, Wang, Chai, Wang, Shao, Xia, "Music2Dance: DanceNet for Music-driven Dance
//! Generation" (arXiv 2002.03761, 2020). Served as `dancenet`.
//!
//! - §3.1 **motion**: root translation and rotation as changes from the previous frame, every
//!   other joint's rotation relative to its parent (6-D), end-effector positions
//!   (`motion::rotations`), and foot-contact labels. The root's height is the lowest foot's
//!   clearance above the floor, so the height follows the legs (the paper integrates it).
//! - §3.2 **music**: the control signals at 25 fps (`audio::features::dancenet`: onset strength,
//!   beat and downbeat one-hots, chroma); a **musical style classifier** ([`style`]) over 30-s
//!   windows; a **musical context-aware encoder** ([`ContextEncoder`]: temporal convolutions and a
//!   Bi-LSTM over 8-s windows, overlapping by half at inference and cross-faded).
//! - §3.3 **motion decoder** ([`Decoder`]): dilated causal convolutions (kernel 2, dilations
//!   1, 2, 4, 8, 16 repeating), gated activation `tanh(W_f * x + V_f c) ⊙ σ(W_g * x + V_g c)`,
//!   residual and skip connections, the control signals (style one-hot and music code) added
//!   through 1×1 convolutions (`V c`). Receptive field: `1 + Σ dilations` frames
//!   ([`Config::receptive_field`]).
//! - §3.4 **output**: a Gaussian mixture (diagonal, `mixtures` components; the paper and the
//!   served weights use one) over the next frame's features, with means absolute or relative to
//!   the current frame ([`Config::absolute_dims`]), and foot contact by binary cross-entropy:
//!   `L = L_gmm + λ · L_foot`, with Gaussian noise on the decoder's input frames during training
//!   (`σ_in`, and drift: `train::dancenet`). At inference the mixture is sampled, seeded, one frame
//!   at a time; `temperature` scales σ and [`Sampling::coherence`] correlates the draws of
//!   neighbouring frames.
//!
//! Sizes differ from the paper to train in an hour on two CPU cores, and so does what keeps the
//! sampled dance bounded and smooth; the model card says where, why, and what each change measured.
use serde::{Deserialize, Serialize};
use tch::nn::{self, RNN};
use tch::{Device, Kind, Tensor};

mod sampling;
pub mod served;
pub mod style;

use super::step_clock;

pub use sampling::{Draws, Sampling};

pub use served::Served;

/// The API id.
pub const ID: &str = "dancenet";
/// Smallest and largest log σ of a mixture component (normalised units), so a component can
/// neither collapse onto a training point nor spread over everything.
pub const LOG_SIGMA: (f64, f64) = (-7.0, 2.0);

/// Hyper-parameters, with the paper's names where it has them.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Config {
    /// Width of a motion frame (`motion::rotations::Layout::dim`).
    pub pose_dim: i64,
    /// Foot-contact labels per frame (4: heels and toes).
    pub contacts: i64,
    /// Control-signal width (15).
    pub music_dim: i64,
    /// Styles (4).
    pub styles: i64,
    /// Context encoder: temporal convolution channels.
    pub enc_channels: i64,
    /// Context encoder: temporal convolutions (kernel `enc_kernel`, centred).
    pub enc_convs: i64,
    pub enc_kernel: i64,
    /// Context encoder: Bi-LSTM hidden width per direction.
    pub enc_hidden: i64,
    /// Width of the music code `c` the decoder is conditioned on.
    pub d_code: i64,
    /// Context encoder window (frames; the paper's 8 s) and hop between windows at inference.
    pub enc_window: i64,
    pub enc_hop: i64,
    /// Decoder residual channels.
    pub residual: i64,
    /// Decoder skip channels.
    pub skip: i64,
    /// Dilation of each gated layer (kernel 2).
    pub dilations: Vec<i64>,
    /// Mixture components `N` (the paper: 1).
    pub mixtures: i64,
    /// Leading frame columns whose mixture means are absolute; the rest are relative to the current
    /// frame. Served: all absolute. Means relative to the current frame (a residual) made every
    /// sampled error part of the next frame's starting point, and the dance drifted off without
    /// bound (from 9 training epochs on, every song); with the root's rates alone absolute it still
    /// drifted, with all absolute it stays within the train split's range for whole songs.
    #[serde(default)]
    pub absolute_dims: i64,
    /// The control signals themselves (onset, beat, downbeat, chroma) join the music code in
    /// every gated layer's conditioning, so a beat reaches the decoder on its frame rather than
    /// only through the 8-s encoder (without it the network heard the music seconds late). Absent
    /// in older `model.json` files: no.
    #[serde(default)]
    pub music_direct: bool,
    /// The step clock ([`step_clock`]) joins every gated layer's conditioning, after the rest:
    /// a phase that turns once per step of the song's beats. Absent in older `model.json`
    /// files: no.
    #[serde(default)]
    pub step_clock: bool,
}

impl Config {
    /// The decoder's arithmetic per motion frame (a multiply-add counts 2) with each dilated
    /// layer's past inputs kept (the paper's fast generation), for `branches` decoded side by
    /// side (2 with music guidance): the input projection once, then per branch each gated layer's
    /// two taps, skip and residual, and the head over the mixture. The conditioning, computed for
    /// every frame before the loop, is not in it.
    pub fn frame_flops(&self, branches: f64) -> f64 {
        let (d, c, r, s, k) = (
            self.pose_dim as f64,
            self.contacts as f64,
            self.residual as f64,
            self.skip as f64,
            self.mixtures as f64,
        );
        let layers = self.dilations.len() as f64;
        let per_branch = layers * (10.0 * r * r + 2.0 * r * s)
            + 2.0 * s * s
            + 2.0 * s * (k * (1.0 + 2.0 * d) + c);
        2.0 * r * (d + c) + branches * per_branch
    }

    /// The configuration the committed weights were trained with (two CPU cores, an hour).
    pub fn cpu(pose_dim: i64) -> Self {
        Self {
            pose_dim,
            contacts: 4,
            music_dim: crate::audio::features::DANCENET_DIM as i64,
            styles: crate::models::DanceStyle::ALL.len() as i64,
            enc_channels: 32,
            enc_convs: 2,
            enc_kernel: 3,
            enc_hidden: 32,
            d_code: 32,
            enc_window: 200,
            enc_hop: 100,
            residual: 64,
            skip: 128,
            dilations: [1, 2, 4, 8, 16].repeat(2),
            mixtures: 1,
            absolute_dims: pose_dim,
            music_direct: false,
            step_clock: false,
        }
    }

    /// A tiny configuration for tests and smoke runs.
    pub fn tiny(pose_dim: i64) -> Self {
        Self {
            enc_channels: 4,
            enc_convs: 1,
            enc_hidden: 4,
            d_code: 4,
            enc_window: 16,
            enc_hop: 8,
            residual: 8,
            skip: 8,
            dilations: vec![1, 2, 4],
            mixtures: 2,
            ..Self::cpu(pose_dim)
        }
    }

    /// Width of the conditioning each gated layer reads: the music code, with
    /// [`Self::music_direct`] the control signals after it, and with [`Self::step_clock`] the
    /// clock last.
    pub fn code_width(&self) -> i64 {
        self.d_code
            + if self.music_direct { self.music_dim } else { 0 }
            + if self.step_clock {
                step_clock::WIDTH
            } else {
                0
            }
    }

    /// Frames of history each prediction sees: `1 + Σ dilations` (kernel 2).
    pub fn receptive_field(&self) -> i64 {
        1 + self.dilations.iter().sum::<i64>()
    }

    /// Width of the decoder's output: mixture logits, means and log σ, contact logits.
    fn out_dim(&self) -> i64 {
        self.mixtures * (1 + 2 * self.pose_dim) + self.contacts
    }
}

/// §3.2 musical context-aware encoder: control signals `[b, n, music_dim]` → music code
/// `[b, n, code_width]` (the code, then with [`Config::music_direct`] the signals themselves).
#[derive(Debug)]
pub struct ContextEncoder {
    /// [`Config::music_direct`].
    direct: bool,
    convs: Vec<nn::Conv1D>,
    lstm: nn::LSTM,
    out: nn::Linear,
    window: i64,
    hop: i64,
}

impl ContextEncoder {
    fn new(p: nn::Path, c: &Config) -> Self {
        let conv = |i: i64| {
            let inp = if i == 0 { c.music_dim } else { c.enc_channels };
            nn::conv1d(
                &p / format!("conv{i}"),
                inp,
                c.enc_channels,
                c.enc_kernel,
                nn::ConvConfig {
                    padding: c.enc_kernel / 2,
                    ..Default::default()
                },
            )
        };
        Self {
            direct: c.music_direct,
            convs: (0..c.enc_convs).map(conv).collect(),
            lstm: nn::lstm(
                &p / "lstm",
                c.enc_channels,
                c.enc_hidden,
                nn::RNNConfig {
                    bidirectional: true,
                    ..Default::default()
                },
            ),
            out: nn::linear(&p / "out", 2 * c.enc_hidden, c.d_code, Default::default()),
            window: c.enc_window,
            hop: c.enc_hop,
        }
    }

    /// One window (any length): `[b, n, music_dim]` → `[b, n, code_width]`.
    pub fn forward(&self, music: &Tensor) -> Tensor {
        let mut x = music.transpose(1, 2); // [b, music_dim, n]
        for conv in &self.convs {
            x = x.apply(conv).relu();
        }
        let (h, _) = self.lstm.seq(&x.transpose(1, 2).contiguous()); // [b, n, 2 · enc_hidden]
        let code = h.apply(&self.out);
        if self.direct {
            Tensor::cat(&[code, music.shallow_clone()], -1)
        } else {
            code
        }
    }

    /// A whole song `[1, n, music_dim]` → `[n, d_code]`: windows of `enc_window` frames every
    /// `enc_hop`, each frame's code the mean of the windows over it weighted by a triangle that
    /// peaks mid-window (a cross-fade: a window's edges see the least context). `on_window` gets
    /// the fraction done and may stop it.
    pub fn encode_song(
        &self,
        music: &Tensor,
        mut on_window: impl FnMut(f32) -> bool,
    ) -> Option<Tensor> {
        let n = music.size()[1];
        let d = self.out.ws.size()[0] + if self.direct { music.size()[2] } else { 0 };
        let w = self.window.min(n).max(1);
        let mut starts: Vec<i64> = (0..)
            .map(|k| k * self.hop)
            .take_while(|&s| s + w < n)
            .collect();
        starts.push((n - w).max(0));
        starts.dedup();
        let sum = Tensor::zeros([n, d], (Kind::Float, music.device()));
        let weight = Tensor::zeros([n, 1], (Kind::Float, music.device()));
        let tri: Vec<f32> = (0..w)
            .map(|i| 1.0 - ((i as f32 + 0.5) / w as f32 - 0.5).abs())
            .collect();
        let tri = Tensor::from_slice(&tri)
            .view([w, 1])
            .to_device(music.device());
        for (i, &s) in starts.iter().enumerate() {
            let code = self.forward(&music.narrow(1, s, w)).squeeze_dim(0); // [w, d]
            let _ = sum.narrow(0, s, w).g_add_(&(code * &tri));
            let _ = weight.narrow(0, s, w).g_add_(&tri);
            if !on_window((i + 1) as f32 / starts.len() as f32) {
                return None;
            }
        }
        Some(sum / weight)
    }
}

/// One gated layer of the decoder (§3.3). What a frame-by-frame pass needs is open to
/// `crate::models`: the trainer's free run (`train::dancenet::free_run`) steps it.
#[derive(Debug)]
pub(in crate::models) struct GatedLayer {
    pub(in crate::models) dilation: i64,
    /// `W_f`, `W_g` stacked: `[2C, C, 2]`.
    pub(in crate::models) conv: nn::Conv1D,
    /// `V_f`, `V_g` of the music code (1×1).
    cond: nn::Conv1D,
    /// `V_f`, `V_g` of the style one-hot (1×1, no bias).
    style: nn::Conv1D,
    pub(in crate::models) res: nn::Conv1D,
    pub(in crate::models) skip: nn::Conv1D,
}

impl GatedLayer {
    fn new(p: nn::Path, c: &Config, dilation: i64) -> Self {
        let one = |name: &str, i: i64, o: i64, bias: bool| {
            nn::conv1d(
                &p / name,
                i,
                o,
                1,
                nn::ConvConfig {
                    bias,
                    ..Default::default()
                },
            )
        };
        Self {
            dilation,
            conv: nn::conv1d(
                &p / "conv",
                c.residual,
                2 * c.residual,
                2,
                nn::ConvConfig {
                    dilation,
                    ..Default::default()
                },
            ),
            cond: one("cond", c.code_width(), 2 * c.residual, true),
            style: one("style", c.styles, 2 * c.residual, false),
            res: one("res", c.residual, c.residual, true),
            skip: one("skip", c.residual, c.skip, true),
        }
    }

    /// The conditioning of every frame: `V c + V_s s + b` `[b, 2C, n]` (the dilated
    /// convolution's bias folded in).
    pub(in crate::models) fn conditioning(&self, code: &Tensor, style: &Tensor) -> Tensor {
        let bias = self.conv.bs.as_ref().map(|b| b.view([1, -1, 1]));
        let c = code.apply(&self.cond) + style.apply(&self.style);
        match bias {
            Some(b) => c + b,
            None => c,
        }
    }

    /// Causal pass over `[b, C, n]` with conditioning `[b, 2C, n]`: `(residual out, skip)`.
    pub(in crate::models) fn forward(&self, h: &Tensor, cond: &Tensor) -> (Tensor, Tensor) {
        let padded = h.constant_pad_nd([self.dilation, 0]);
        let z = padded.conv1d(&self.conv.ws, None::<&Tensor>, [1], [0], [self.dilation], 1) + cond;
        let zs = z.chunk(2, 1);
        let g = zs[0].tanh() * zs[1].sigmoid();
        (h + g.apply(&self.res), g.apply(&self.skip))
    }
}

/// §3.3 motion decoder: frames `[b, n, pose_dim + contacts]` (the current frame) with the next
/// frame's conditioning → mixture and contact parameters of the next frame.
#[derive(Debug)]
pub struct Decoder {
    pub(in crate::models) input: nn::Conv1D,
    pub(in crate::models) layers: Vec<GatedLayer>,
    pub(in crate::models) head: nn::Conv1D,
    pub(in crate::models) out: nn::Conv1D,
}

impl Decoder {
    fn new(p: nn::Path, c: &Config) -> Self {
        let one = |name: &str, i: i64, o: i64| nn::conv1d(&p / name, i, o, 1, Default::default());
        Self {
            input: one("input", c.pose_dim + c.contacts, c.residual),
            layers: c
                .dilations
                .iter()
                .enumerate()
                .map(|(i, &d)| GatedLayer::new(&p / "layers" / i, c, d))
                .collect(),
            head: one("head", c.skip, c.skip),
            out: one("out", c.skip, c.out_dim()),
        }
    }
}

/// The whole model: context encoder and decoder.
#[derive(Debug)]
pub struct DanceNet {
    pub config: Config,
    pub encoder: ContextEncoder,
    pub decoder: Decoder,
}

/// The decoder's output for a batch of frames, split: `[.., K]` mixture logits, `[.., K, D]`
/// means (absolute, normalised units) and log σ, `[.., 4]` contact logits.
pub struct Mixture {
    pub logits: Tensor,
    pub mean: Tensor,
    pub log_sigma: Tensor,
    pub contacts: Tensor,
}

/// The parts of a training loss, per frame and dimension.
pub struct Losses {
    /// Mixture negative log-likelihood per feature dimension (nats).
    pub gmm: Tensor,
    /// Foot-contact binary cross-entropy.
    pub foot: Tensor,
}

impl DanceNet {
    /// Builds the variables under `p` (checkpoint keys `encoder.*`, `decoder.*`).
    pub fn new(p: &nn::Path, config: Config) -> Self {
        Self {
            encoder: ContextEncoder::new(p / "encoder", &config),
            decoder: Decoder::new(p / "decoder", &config),
            config,
        }
    }

    /// Style one-hots `[b, styles, 1]` of style indices.
    pub fn style_one_hot(&self, styles: &[usize], device: Device) -> Tensor {
        let idx: Vec<i64> = styles.iter().map(|&s| s as i64).collect();
        Tensor::from_slice(&idx)
            .to_device(device)
            .one_hot(self.config.styles)
            .to_kind(Kind::Float)
            .unsqueeze(-1)
    }

    /// Splits the decoder's raw output `[.., out_dim]` relative to the current frames `[.., D]`.
    pub(in crate::models) fn mixture(&self, raw: &Tensor, current: &Tensor) -> Mixture {
        let (k, d) = (self.config.mixtures, self.config.pose_dim);
        let mut lead = raw.size();
        lead.pop();
        let shape = |tail: &[i64]| -> Vec<i64> {
            lead.iter().copied().chain(tail.iter().copied()).collect()
        };
        let logits = raw.narrow(-1, 0, k);
        let delta = raw.narrow(-1, k, k * d).reshape(shape(&[k, d]).as_slice());
        let log_sigma = raw
            .narrow(-1, k + k * d, k * d)
            .reshape(shape(&[k, d]).as_slice())
            .clamp(LOG_SIGMA.0, LOG_SIGMA.1);
        let contacts = raw.narrow(-1, k * (1 + 2 * d), self.config.contacts);
        let relative = current.narrow(-1, self.config.absolute_dims, d - self.config.absolute_dims);
        let base = Tensor::cat(
            &[
                current
                    .narrow(-1, 0, self.config.absolute_dims)
                    .zeros_like(),
                relative,
            ],
            -1,
        );
        Mixture {
            logits,
            mean: base.unsqueeze(-2) + delta,
            log_sigma,
            contacts,
        }
    }

    /// Teacher-forced pass: `frames` `[b, n, D + contacts]` (frame t's features and contacts,
    /// normalised; possibly noised), `code` `[b, n, d_code]` and `style` `[b, styles, 1]`.
    /// Position t predicts frame t + 1 from frames ≤ t and frame t + 1's music code, so outputs
    /// `[b, n − 1, ..]` cover frames 1..n.
    pub fn forward(&self, frames: &Tensor, code: &Tensor, style: &Tensor) -> Mixture {
        let n = frames.size()[1];
        let x = frames.narrow(1, 0, n - 1).transpose(1, 2); // [b, D + 4, n − 1]
        let c = code.narrow(1, 1, n - 1).transpose(1, 2); // [b, d_code, n − 1]
        let mut h = x.apply(&self.decoder.input); // [b, C, n − 1]
        let mut skip: Option<Tensor> = None;
        for l in &self.decoder.layers {
            let (next, s) = l.forward(&h, &l.conditioning(&c, style));
            h = next;
            skip = Some(match skip {
                Some(acc) => acc + s,
                None => s,
            });
        }
        let skip = skip.unwrap_or_else(|| Tensor::zeros([1], (Kind::Float, frames.device())));
        let raw = skip
            .relu()
            .apply(&self.decoder.head)
            .relu()
            .apply(&self.decoder.out)
            .transpose(1, 2); // [b, n − 1, out]
        let current = frames
            .narrow(1, 0, n - 1)
            .narrow(2, 0, self.config.pose_dim);
        self.mixture(&raw, &current)
    }

    /// The conditioning of a window: the encoder's code of `music` `[b, n, music_dim]` and its
    /// clock ([`Self::with_clock`]).
    pub fn code(&self, music: &Tensor, clock: Option<&Tensor>) -> Tensor {
        self.with_clock(self.encoder.forward(music), clock)
    }

    /// `code` `[.., code columns]` as every gated layer reads it: with [`Config::step_clock`]
    /// the clock `[.., step_clock::WIDTH]` after it (zeros when `None`), else as it is.
    pub fn with_clock(&self, code: Tensor, clock: Option<&Tensor>) -> Tensor {
        if !self.config.step_clock {
            return code;
        }
        let clock = match clock {
            Some(c) => c.to_device(code.device()),
            None => {
                let mut shape = code.size();
                if let Some(last) = shape.last_mut() {
                    *last = step_clock::WIDTH;
                }
                Tensor::zeros(shape, (Kind::Float, code.device()))
            }
        };
        Tensor::cat(&[code, clock], -1)
    }

    /// Training losses on a window: `input` the frames the decoder reads (noised), `target` the
    /// clean frames `[b, n, D + contacts]`, `music` `[b, n, music_dim]` and its step clock
    /// ([`Self::code`]); frames before `warmup` are context only (they would see zero padding
    /// instead of history).
    pub fn losses(
        &self,
        input: &Tensor,
        target: &Tensor,
        music: &Tensor,
        clock: Option<&Tensor>,
        style: &Tensor,
        warmup: i64,
    ) -> Losses {
        let code = self.code(music, clock);
        let m = self.forward(input, &code, style);
        let n = target.size()[1] - 1;
        let from = warmup.clamp(0, n - 1);
        let keep = |t: &Tensor| t.narrow(1, from, n - from);
        let d = self.config.pose_dim;
        let y = keep(&target.narrow(1, 1, n).narrow(2, 0, d)).unsqueeze(-2); // [b, m, 1, D]
        let (mean, log_sigma) = (keep(&m.mean), keep(&m.log_sigma));
        let z = (&y - mean) * (-&log_sigma).exp();
        let log_n = (z.square() * -0.5 - &log_sigma).sum_dim_intlist(-1, false, Kind::Float)
            - 0.5 * (d as f64) * (2.0 * std::f64::consts::PI).ln();
        let log_p = (keep(&m.logits).log_softmax(-1, Kind::Float) + log_n).logsumexp(-1, false); // [b, m]
        let gmm = -log_p.mean(Kind::Float) / d as f64;
        let contacts = keep(&target.narrow(1, 1, n).narrow(2, d, self.config.contacts));
        let foot = keep(&m.contacts).binary_cross_entropy_with_logits::<Tensor>(
            &contacts,
            None,
            None,
            tch::Reduction::Mean,
        );
        Losses { gmm, foot }
    }
}

/// The run behind the committed weights, beside the common record.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Schedule {
    pub window: usize,
    pub stride: usize,
    /// σ_in: noise on the decoder's input frames (normalised units), and its AR(1) correlation
    /// from frame to frame.
    pub input_noise: f64,
    #[serde(default)]
    pub input_coherence: f64,
    /// Per-window offset and per-frame random walk on the input frames (normalised units).
    #[serde(default)]
    pub input_offset: f64,
    #[serde(default)]
    pub input_walk: f64,
    /// λ of the foot-contact loss.
    pub lambda_foot: f64,
    /// Context-only frames at the start of each window.
    pub warmup: usize,
    /// Exponent of the rarer styles' window repeats.
    pub style_balance: f64,
    pub steps: usize,
    /// Mean per-joint distance (cm, root-relative) between the train split and its rigid
    /// rotation features decoded back.
    pub rigid_fit_error_cm: f64,
    /// Tempo factors the windows were drawn at (`train::augment`; 1 and 1: as danced).
    #[serde(default = "unit_tempo")]
    pub min_tempo: f64,
    #[serde(default = "unit_tempo")]
    pub max_tempo: f64,
    /// Share of windows trained without their style input.
    #[serde(default)]
    pub style_dropout: f64,
    /// Weight of the lock term (`train::dancenet::lock`; 0: without it).
    #[serde(default)]
    pub lock_weight: f64,
}

fn unit_tempo() -> f64 {
    1.0
}

/// How the committed weights are served.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Serving {
    /// Rest offsets of the rig every dance is expressed on (`motion::rig`, metres), fitted on the
    /// train split.
    pub rig: Vec<[f64; 3]>,
    /// Default sampling.
    pub sampling: Sampling,
    /// σ (frames) of the temporal smoothing of the sampled features before they become joint
    /// positions (`models::smooth_columns`); 0: none.
    #[serde(default)]
    pub smooth_frames: f64,
    /// The network runs on a clock of beats at this tempo (`models::beat_time`); absent: in
    /// seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beat_time: Option<crate::models::beat_time::BeatTimeConfig>,
    /// Frames danced over the song's music before the dance starts and dropped, when the job
    /// brings no seed motion (`dancenet::served`); 0: none.
    #[serde(default)]
    pub warm_up_frames: usize,
    /// The check of a draw's opening, if any ([`crate::models::opening_check::OpeningCheck`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub opening_check: Option<crate::models::opening_check::OpeningCheck>,
}

/// The served warm-up: 10 s. The music moves the decoder only after a few seconds (pink noise
/// and a song, one seed and style: 0.03 m apart over the first 5 s, 0.27 m over the next 15),
/// so without it one seed opened every song of a style alike (model card).
pub const WARM_UP_FRAMES: usize = 250;

/// The served music guidance ([`Sampling::music_guidance`]): 3. The network hears the song
/// weakly (the same seed on two songs of one style opened 0.11 m apart, where two real dances are
/// 0.34 apart); with each frame's music amplified three times against the song's average, 0.16 at
/// the closest over seeds 0–2 on eight songs (model card).
pub const MUSIC_GUIDANCE: f64 = 3.0;

/// The served check of a draw's opening ([`crate::models::opening_check::OpeningCheck`]): the
/// first 20 s after the warm-up, 6 draws (the seed's stream and clip, then others derived from
/// it), inside the real dances' ranges with a margin.
pub const OPENING_CHECK: crate::models::opening_check::OpeningCheck =
    crate::models::opening_check::OpeningCheck {
        frames: 500,
        draws: 6,
        speed_m_s: [0.6, 1.6],
        arms_m_s: [0.5, 1.3],
    };

/// `model.json`.
pub type ModelFile = super::folder::ModelFile<Config, Schedule, Serving>;

#[cfg(test)]
mod tests;
