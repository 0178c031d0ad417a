//! §3.4 inference: each coordinate sampled (seeded RNG, `temperature`, `top_k`), one frame at a
//! time against the pose stream's key/value caches, and the served stall guard (not in the paper).
use ndarray::Array2;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use tch::{Device, Kind, Tensor};

use super::Tsmt;

impl Tsmt {
    /// Generates `n` frames of tokens after the context `prefix` `[m ≥ 1, coords]`, frame t
    /// from the last frames and row t of `audio_vectors` ([`Self::audio_logit_vectors`]).
    /// `clock` `[m + n, WIDTH]`, where the network has a step clock: the clock of every frame
    /// the pose stream reads, the context's then the drawn ones'.
    /// `on_step(done)` is called before the first frame and every 250 frames, and may stop it.
    pub fn sample(
        &self,
        prefix: &Array2<i64>,
        audio_vectors: &Tensor,
        clock: Option<&Tensor>,
        sampling: Sampling,
        seed: u64,
        on_step: impl FnMut(usize) -> bool,
    ) -> Option<Array2<i64>> {
        self.sample_guarded(prefix, audio_vectors, clock, sampling, None, seed, on_step)
    }

    /// [`Self::sample`] with an optional [`StallGuard`] and the metres per bin of each joint
    /// coordinate (the first `POSE_DIM` coordinates) it measures motion with.
    #[allow(clippy::too_many_arguments)]
    pub fn sample_guarded(
        &self,
        prefix: &Array2<i64>,
        audio_vectors: &Tensor,
        clock: Option<&Tensor>,
        sampling: Sampling,
        guard: Option<(&StallGuard, &[f32])>,
        seed: u64,
        on_step: impl FnMut(usize) -> bool,
    ) -> Option<Array2<i64>> {
        let clock = clock.map(Tensor::shallow_clone);
        let audio = audio_vectors.shallow_clone();
        let mut draw = Draw::new(self, prefix, audio, clock, sampling, guard, seed);
        let n = draw.frames();
        draw.run_to(n, on_step)?;
        Some(draw.into_tokens())
    }
}

/// One draw of [`Tsmt::sample_guarded`] that can stop after any frame and go on later, drawing
/// exactly what one run would. The served opening check draws a candidate clip's first seconds,
/// stops at a hold, and goes on from where it stopped for the candidate it keeps: a sampler that
/// could not go on drew the kept opening twice, and every passed-over one to its end (the card:
/// a quarter of a 3-minute song's time).
pub struct Draw<'a> {
    model: &'a Tsmt,
    audio_vectors: Tensor,
    clock: Option<Tensor>,
    sampling: Sampling,
    guard: Option<(&'a StallGuard, &'a [f32])>,
    /// Context frames (the prefix), whose clock rows come before the drawn frames'.
    m: usize,
    caches: Vec<crate::models::layers::KvCache>,
    rng: StdRng,
    wx: Tensor,
    pos: i64,
    probs: Vec<f32>,
    /// The last frames drawn, for the guard.
    recent: std::collections::VecDeque<Vec<i64>>,
    /// The frames drawn, row after row (a candidate's opening holds only its own seconds).
    out: Vec<i64>,
    done: usize,
}

impl<'a> Draw<'a> {
    /// A draw of `audio_vectors.size(0)` frames after the context `prefix` (the arguments of
    /// [`Tsmt::sample_guarded`]), its caches filled with the context; nothing drawn yet.
    pub fn new(
        model: &'a Tsmt,
        prefix: &Array2<i64>,
        audio_vectors: Tensor,
        clock: Option<Tensor>,
        sampling: Sampling,
        guard: Option<(&'a StallGuard, &'a [f32])>,
        seed: u64,
    ) -> Self {
        let mut caches = model.pose.stack.new_caches();
        // The context, all but its last frame, fills the caches (at most the window's worth).
        let m = prefix.nrows();
        let keep = (m as i64).min(model.config.window) as usize;
        let mut wx = Tensor::zeros([1], (Kind::Float, Device::Cpu));
        for (k, t) in (m - keep..m).enumerate() {
            wx = model.step(
                &Tensor::from_slice(&prefix.row(t).to_vec()),
                clock.as_ref().map(|c| c.get(t as i64)).as_ref(),
                k as i64,
                &mut caches,
            );
        }
        Self {
            model,
            audio_vectors,
            clock,
            sampling,
            guard,
            m,
            caches,
            rng: StdRng::seed_from_u64(seed ^ 0x7357_0000_D0CE),
            wx,
            pos: keep as i64,
            probs: vec![0f32; model.config.n_bins as usize],
            recent: std::collections::VecDeque::new(),
            out: Vec::new(),
            done: 0,
        }
    }

    /// Frames the whole draw has.
    pub fn frames(&self) -> usize {
        self.audio_vectors.size()[0] as usize
    }

    /// Coordinates a frame has.
    fn coords(&self) -> usize {
        self.model.config.coords as usize
    }

    /// Frames drawn so far.
    pub fn done(&self) -> usize {
        self.done
    }

    /// The frames drawn so far.
    pub fn tokens(&self) -> ndarray::ArrayView2<'_, i64> {
        ndarray::ArrayView2::from_shape((self.done, self.coords()), &self.out)
            .expect("done rows of coords tokens")
    }

    /// The whole draw (rows not drawn yet are zero).
    pub fn into_tokens(mut self) -> Array2<i64> {
        let shape = (self.frames(), self.coords());
        self.out.resize(shape.0 * shape.1, 0);
        Array2::from_shape_vec(shape, self.out).expect("frames rows of coords")
    }

    /// Draws on up to frame `end` (at most [`Self::frames`]). `on_step(done)` is called before the
    /// first frame drawn here and after every 250th frame of the draw, and may stop it: `None`.
    pub fn run_to(&mut self, end: usize, mut on_step: impl FnMut(usize) -> bool) -> Option<()> {
        let end = end.min(self.frames());
        // Says the loop has begun (a stage clock starts timing it here, however short the song).
        if !on_step(self.done) {
            return None;
        }
        let model = self.model;
        let n_bins = model.config.n_bins as usize;
        for t in self.done..end {
            let fused = self.wx.shallow_clone() + self.audio_vectors.get(t as i64);
            let logits = model.logits(&fused); // [coords, n_bins]
            let flat: Vec<f32> = Vec::<f32>::try_from(logits.contiguous().view([-1])).ok()?;
            let now = match self.guard {
                Some((g, widths))
                    if self.recent.len() >= g.window_frames
                        && reach_m(&self.recent, widths) < g.min_reach_m =>
                {
                    g.boosted(self.sampling)
                }
                _ => self.sampling,
            };
            let row: Vec<i64> = flat
                .chunks(n_bins)
                .map(|logits| now.draw(logits, &mut self.probs, &mut self.rng) as i64)
                .collect();
            self.out.extend_from_slice(&row);
            if let Some((g, _)) = self.guard {
                self.recent.push_back(row.clone());
                while self.recent.len() > g.window_frames {
                    self.recent.pop_front();
                }
            }
            self.wx = model.step(
                &Tensor::from_slice(&row),
                self.clock
                    .as_ref()
                    .map(|c| c.get((self.m + t) as i64))
                    .as_ref(),
                self.pos,
                &mut self.caches,
            );
            self.pos += 1;
            self.done = t + 1;
            if (t + 1) % 250 == 0 && !on_step(t + 1) {
                return None;
            }
        }
        Some(())
    }
}

/// How far the pose has come within `frames` (tokens, oldest first): the largest, over the
/// earlier frames, of the mean distance (m) of the root-relative joints from where they are in
/// the last frame, from the metres per bin of each joint coordinate (`widths`, `POSE_DIM` long).
/// A bin or two of sampling jitter adds a centimetre or so; a dancer who moves reaches tens.
pub(super) fn reach_m(frames: &std::collections::VecDeque<Vec<i64>>, widths: &[f32]) -> f32 {
    let joints = widths.len() / 3;
    let Some(last) = frames.back() else {
        return 0.0;
    };
    if joints == 0 || last.len() < 3 * joints {
        return 0.0;
    }
    frames
        .iter()
        .map(|f| {
            let sum: f32 = (0..joints)
                .map(|j| {
                    (0..3)
                        .map(|c| {
                            ((last[3 * j + c] - f[3 * j + c]) as f32 * widths[3 * j + c]).powi(2)
                        })
                        .sum::<f32>()
                        .sqrt()
                })
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
    /// An opening whose `window_frames` windows all reach less than this (m) for 10 s in a row
    /// within the song's first 20 s is a freeze, and the dance opens again from the next
    /// candidate clip (`tsmt::served`; 0, or absent in older `model.json` files: never). A boost
    /// does not free a true freeze (its reach stays at 0.04–0.06 m: the likeliest next pose is
    /// the last), nor does drawing the same opening again from the same clip; another clip does.
    #[serde(default)]
    pub reopen_reach_m: f32,
}

impl StallGuard {
    fn boosted(&self, s: Sampling) -> Sampling {
        Sampling {
            temperature: s.temperature * self.boost,
            top_k: if s.top_k == 0 { 0 } else { s.top_k * 2 },
        }
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
        Self {
            temperature: 1.0,
            top_k: 0,
        }
    }
}

impl Sampling {
    /// `logits` `[.., n_bins]` over the temperature, with every bin below the `top_k`-th largest
    /// of its row at −∞ (ties at the cut are kept): the distribution [`Self::draw`] draws from, as
    /// tensors (training's own draws: self-conditioning, free runs).
    pub fn masked_logits(&self, logits: &Tensor) -> Tensor {
        let logits = logits / self.temperature.max(1e-3);
        let bins = logits.size().last().copied().unwrap_or(0);
        if self.top_k == 0 || self.top_k as i64 >= bins {
            return logits;
        }
        let (top, _) = logits.topk(self.top_k as i64, -1, true, true);
        let floor = top.narrow(-1, self.top_k as i64 - 1, 1);
        logits.masked_fill(&logits.lt_tensor(&floor), f64::NEG_INFINITY)
    }

    /// Draws a bin from one coordinate's `logits`; `probs` is scratch of the same length.
    pub fn draw(&self, logits: &[f32], probs: &mut [f32], rng: &mut StdRng) -> usize {
        let t = self.temperature.max(1e-3) as f32;
        let k = if self.top_k == 0 {
            logits.len()
        } else {
            self.top_k.min(logits.len())
        };
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
