//! §3.4 inference: the mixture sampled one frame at a time from a context, each step running
//! the gated layers on one frame against queues of their past inputs, and how a frame is drawn
//! from its mixture ([`Sampling`], [`Draws`]).
use ndarray::Array2;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use tch::nn;
use tch::{Kind, Tensor};

use super::{DanceNet, LOG_SIGMA};

impl DanceNet {
    /// Samples frames after the context `prefix` `[m ≥ 1, D + contacts]` (normalised). `code`
    /// `[m − 1 + n, d_code]` is the music code of every frame after the first of the prefix: the
    /// prefix's own frames 1..m, then the `n` frames to make. Each step runs the gated layers on
    /// one frame against queues of their past inputs (the dilated convolution needs only the
    /// input `d` frames back), so a frame costs the same however long the song.
    /// `on_step(done)` is called before the first frame and every 250 frames, and may stop it.
    ///
    /// `average` (`[1, d_code]`, or `code`'s shape for one per row) is what music guidance's
    /// second branch hears: the serving passes the average of the whole dance's rows when it
    /// draws only the dance's first frames (the opening check), so they are guided as the whole
    /// dance's are. `None`: the mean of `code`.
    #[allow(clippy::too_many_arguments)]
    pub fn sample(
        &self,
        prefix: &Array2<f32>,
        code: &Tensor,
        average: Option<&Tensor>,
        style: usize,
        sampling: Sampling,
        rng: &mut StdRng,
        mut on_step: impl FnMut(usize) -> bool,
    ) -> Option<Array2<f32>> {
        let c = &self.config;
        let (d, width) = (c.pose_dim as usize, (c.pose_dim + c.contacts) as usize);
        let m = prefix.nrows();
        if m == 0 || prefix.ncols() != width {
            return None;
        }
        let n = (code.size()[0] as usize).checked_sub(m - 1)?;
        let dev = code.device();
        let style = self.style_one_hot(&[style], dev); // [1, styles, 1]
        let code_t = code.transpose(0, 1).unsqueeze(0); // [1, d_code, m − 1 + n]

        // Branch 0 hears the song; with music guidance (`Sampling::music_guidance` ≠ 1) branch 1
        // hears the song's average code on every frame, and the mixture's weights and means are
        // pushed from branch 1's along the difference, so what a frame's music adds to the song's
        // average is amplified.
        let guidance = sampling.music_guidance as f32;
        let mut codes = vec![code_t.shallow_clone()];
        if sampling.branches() == 2 {
            codes.push(match average {
                Some(a) => a
                    .to_device(dev)
                    .transpose(0, 1)
                    .unsqueeze(0)
                    .expand_as(&code_t),
                None => code_t.mean_dim(2, true, Kind::Float).expand_as(&code_t),
            });
        }
        let branches: Vec<Vec<Tensor>> = codes
            .iter()
            .map(|code_t| {
                self.decoder
                    .layers
                    .iter()
                    .map(|l| l.conditioning(code_t, &style))
                    .collect() // [1, 2C, m − 1 + n]
            })
            .collect();
        // The context but its last frame, as one teacher-forced pass per branch; each layer keeps
        // the inputs of its last `dilation` positions.
        let mut queues: Vec<Vec<std::collections::VecDeque<Tensor>>> = branches
            .iter()
            .map(|_| {
                self.decoder
                    .layers
                    .iter()
                    .map(|_| std::collections::VecDeque::new())
                    .collect()
            })
            .collect();
        if m > 1 {
            let x = crate::models::to_tensor(&prefix.slice(ndarray::s![..m - 1, ..]).to_owned())
                .to_device(dev)
                .transpose(0, 1)
                .unsqueeze(0);
            for (conds, queues) in branches.iter().zip(queues.iter_mut()) {
                let mut h = x.apply(&self.decoder.input); // [1, C, m − 1]
                for ((l, cond), q) in self.decoder.layers.iter().zip(conds).zip(queues.iter_mut()) {
                    let keep = (m - 1).min(l.dilation as usize);
                    for t in m - 1 - keep..m - 1 {
                        q.push_back(h.get(0).select(1, t as i64));
                    }
                    h = l.forward(&h, &cond.narrow(2, 0, (m - 1) as i64)).0;
                }
            }
        }
        // The branches are decoded side by side as the rows of one batch: one call per product
        // for both, where a call per branch had twice the calls (the loop is bound by calls, not
        // arithmetic: `choreo bench generate`). Per layer: taps at t − d and t, and the 1×1
        // convolutions, as matrices transposed once for `x · Wᵀ` `[C, 2C]`, `[C, C]`, `[C, S]`.
        let tr = |w: &Tensor| w.tr().contiguous();
        let mat = |conv: &nn::Conv1D| {
            let b = conv
                .bs
                .as_ref()
                .map(|b| b.shallow_clone())
                .unwrap_or_else(|| Tensor::zeros([conv.ws.size()[0]], (Kind::Float, dev)));
            (conv.ws.squeeze_dim(-1), b)
        };
        let mat_t = |conv: &nn::Conv1D| {
            let (w, b) = mat(conv);
            (tr(&w), b)
        };
        let taps: Vec<_> = self
            .decoder
            .layers
            .iter()
            .map(|l| {
                (
                    tr(&l.conv.ws.select(2, 0)),
                    tr(&l.conv.ws.select(2, 1)),
                    mat_t(&l.res),
                    mat_t(&l.skip),
                    l.dilation as usize,
                )
            })
            .collect();
        let rows: Vec<Vec<Tensor>> = branches
            .iter()
            .map(|conds| {
                conds
                    .iter()
                    .map(|cond| cond.squeeze_dim(0).transpose(0, 1).contiguous())
                    .collect()
            })
            .collect();
        let (w_in, b_in) = mat(&self.decoder.input);
        let (w_head, b_head) = mat_t(&self.decoder.head);
        let (w_out, b_out) = mat_t(&self.decoder.out);
        let b = rows.len() as i64;
        // Per layer: the branches' conditioning rows `[B, m − 1 + n, 2C]`, and their kept inputs
        // `[B, C]`, oldest first.
        let conds: Vec<Tensor> = (0..taps.len())
            .map(|l| Tensor::stack(&rows.iter().map(|r| &r[l]).collect::<Vec<_>>(), 0))
            .collect();
        let mut queues: Vec<std::collections::VecDeque<Tensor>> = (0..taps.len())
            .map(|l| {
                (0..queues[0][l].len())
                    .map(|i| Tensor::stack(&queues.iter().map(|q| &q[l][i]).collect::<Vec<_>>(), 0))
                    .collect()
            })
            .collect();
        let zeros = Tensor::zeros([b, c.residual], (Kind::Float, dev));
        let mut out = Array2::<f32>::zeros((n, width));
        let mut frame: Vec<f32> = prefix.row(m - 1).to_vec();
        if !on_step(0) {
            return None;
        }
        let k = c.mixtures as usize;
        let mut probs = vec![0f32; k];
        let mut draws = Draws::new(d, rng);
        for t in 0..n {
            let row = (m - 1 + t) as i64;
            let input = w_in.mv(&Tensor::from_slice(&frame).to_device(dev)) + &b_in;
            let mut h = input.unsqueeze(0).expand([b, c.residual], false);
            let mut skip: Option<Tensor> = None;
            for (((w_past, w_now, (w_res, b_res), (w_skip, b_skip), dilation), cond), q) in
                taps.iter().zip(&conds).zip(queues.iter_mut())
            {
                let past = if q.len() >= *dilation {
                    q[q.len() - dilation].shallow_clone()
                } else {
                    zeros.shallow_clone()
                };
                let z = past.matmul(w_past) + h.matmul(w_now) + cond.select(1, row);
                let zs = z.chunk(2, 1);
                let g = zs[0].tanh() * zs[1].sigmoid();
                let sk = b_skip.addmm(&g, w_skip);
                skip = Some(match skip {
                    Some(a) => a + sk,
                    None => sk,
                });
                q.push_back(h.shallow_clone());
                while q.len() > *dilation {
                    q.pop_front();
                }
                // A new tensor, not `+=`: `h` is also the queue's entry for this frame (and at
                // the first layer a broadcast view of the input), so it must not change in place.
                let next = &h + b_res.addmm(&g, w_res);
                h = next;
            }
            let hidden = b_head.addmm(&skip?.relu(), &w_head).relu();
            let all = Vec::<f32>::try_from(b_out.addmm(&hidden, &w_out).flatten(0, -1)).ok()?;
            let width_out = all.len() / b as usize;
            let mut raws: Vec<Vec<f32>> = all.chunks(width_out).map(<[f32]>::to_vec).collect();
            let mut raw = raws.swap_remove(0);
            if let Some(average) = raws.first() {
                // The mixture's weights and means (its first k + k·d outputs) guided; the
                // spreads after them stay the song's branch's.
                for i in 0..k + k * d {
                    raw[i] = average[i] + guidance * (raw[i] - average[i]);
                }
            }
            let mut base = frame[..d].to_vec();
            base[..c.absolute_dims as usize].fill(0.0);
            let next = sampling.draw(
                &raw,
                &base,
                k,
                d,
                c.contacts as usize,
                &mut probs,
                &mut draws,
                rng,
            );
            out.row_mut(t).assign(&ndarray::ArrayView1::from(&next));
            frame = next;
            if (t + 1) % 250 == 0 && !on_step(t + 1) {
                return None;
            }
        }
        Some(out)
    }
}

/// How the mixture becomes a frame (§3.4): a component drawn by its weight, then each
/// dimension from its Gaussian with σ × `temperature`; contacts where their probability is over
/// one half. With `coherence` ρ > 0 the standard-normal draws behind each frame are an AR(1)
/// process, `z_t = ρ z_{t−1} + √(1 − ρ²) n_t` (the component's uniform through `z`'s CDF): every
/// frame is still a draw from its own mixture, but neighbouring frames' draws move together, so
/// the dance does not shiver at 25 fps with independent noise (not in the paper; the model card
/// shows both).
///
/// `music_guidance` g (not in the paper): each frame's mixture weights and means are those of
/// the song's average music plus g times what this frame's music changes in them (guidance as
/// in classifier-free guidance, with the song's mean code in place of no music). 1: the
/// network as trained.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Sampling {
    pub temperature: f64,
    #[serde(default)]
    pub coherence: f64,
    #[serde(default = "no_guidance", skip_serializing_if = "is_no_guidance")]
    pub music_guidance: f64,
}

fn no_guidance() -> f64 {
    1.0
}

fn is_no_guidance(g: &f64) -> bool {
    *g == 1.0
}

impl Sampling {
    /// Branches the decoder runs a frame: the song's, and with music guidance (≠ 1) a second
    /// hearing the song's average code.
    pub fn branches(&self) -> usize {
        if self.music_guidance == 1.0 {
            1
        } else {
            2
        }
    }
}

impl Default for Sampling {
    fn default() -> Self {
        Self {
            temperature: 1.0,
            coherence: 0.0,
            music_guidance: 1.0,
        }
    }
}

/// The random state [`Sampling::draw`] carries from frame to frame: one normal per dimension and
/// one for the component.
pub struct Draws {
    z: Vec<f32>,
    pick: f32,
}

impl Draws {
    /// Fresh standard normals for `d` dimensions.
    pub fn new(d: usize, rng: &mut StdRng) -> Self {
        Self {
            z: (0..d).map(|_| StandardNormal.sample(rng)).collect(),
            pick: StandardNormal.sample(rng),
        }
    }
}

/// Standard normal CDF, logistic approximation (within 0.01; it only turns a normal into a
/// uniform for the component draw).
fn phi(z: f32) -> f32 {
    1.0 / (1.0 + (-1.702 * z).exp())
}

impl Sampling {
    /// The next frame `[D + contacts]` from the decoder's raw output for one frame, whose means are
    /// relative to `base` `[D]` (the current frame, zero where means are absolute); `probs` is
    /// scratch of `k` entries.
    #[allow(clippy::too_many_arguments)]
    pub fn draw(
        &self,
        raw: &[f32],
        base: &[f32],
        k: usize,
        d: usize,
        contacts: usize,
        probs: &mut [f32],
        draws: &mut Draws,
        rng: &mut StdRng,
    ) -> Vec<f32> {
        let rho = self.coherence.clamp(0.0, 0.999) as f32;
        let fresh = (1.0 - rho * rho).sqrt();
        let mut step = |z: &mut f32| {
            let n: f32 = StandardNormal.sample(rng);
            *z = rho * *z + fresh * n;
        };
        step(&mut draws.pick);
        for z in draws.z.iter_mut() {
            step(z);
        }
        let logits = &raw[..k];
        let max = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let mut total = 0f32;
        for (p, &l) in probs.iter_mut().zip(logits) {
            *p = (l - max).exp();
            total += *p;
        }
        let mut u = phi(draws.pick) * total;
        let mut pick = k - 1;
        for (i, &p) in probs.iter().enumerate() {
            if u < p {
                pick = i;
                break;
            }
            u -= p;
        }
        let mean = &raw[k + pick * d..k + (pick + 1) * d];
        let log_sigma = &raw[k + k * d + pick * d..k + k * d + (pick + 1) * d];
        let t = self.temperature.max(0.0) as f32;
        let mut next: Vec<f32> = (0..d)
            .map(|i| {
                let ls = log_sigma[i].clamp(LOG_SIGMA.0 as f32, LOG_SIGMA.1 as f32);
                base[i] + mean[i] + t * ls.exp() * draws.z[i]
            })
            .collect();
        let c0 = k * (1 + 2 * d);
        next.extend(
            raw[c0..c0 + contacts]
                .iter()
                .map(|&l| if l > 0.0 { 1.0 } else { 0.0 }),
        );
        next
    }
}
