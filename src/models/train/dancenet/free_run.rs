//! The decoder dancing on its own for training (the lock term): a batch of windows
//! continued frame by frame from a real context, as §3.4's sampler does, but batched and with
//! the autograd tape kept, so a loss on the danced frames reaches the network.
//!
//! It serves both of the trainer's free-running terms (`--spectral-weight`, `--lock-weight`).
//! The first free run re-ran the whole dilated stack over its receptive field for every frame
//! (6.5 s a batch for 137 frames); here each gated layer runs on one frame
//! against queues of its past inputs, as served (`dancenet::sampling`), so a frame costs one
//! pass of ten 1×1 layers and windows of ten seconds are affordable.
use tch::{Kind, Tensor};

use crate::models::dancenet::DanceNet;

impl DanceNet {
    /// Continues `real` `[b, n, D + contacts]` (normalised) after its first `context` frames:
    /// frames `context..n` made one at a time, each read back (detached, with its contacts over
    /// one half) as the next input. A frame is the mixture's first component drawn as mean +
    /// σ·z·`temperature`, the z an AR(1) stream of `coherence` (as served), so the gradient
    /// reaches each frame's mean and σ but does not run back through the history it was read
    /// from (through a long rollout it explodes). `code` `[b, n, code_width]`, `style`
    /// `[b, styles, 1]`. Returns `[b, n − context, D]`.
    pub fn free_run(
        &self,
        real: &Tensor,
        code: &Tensor,
        style: &Tensor,
        context: i64,
        temperature: f64,
        coherence: f64,
    ) -> Tensor {
        let c = &self.config;
        let (b, n, _) = real.size3().expect("windows are [b, n, D + contacts]");
        let d = c.pose_dim;
        let dev = real.device();
        let context = context.clamp(1, n);
        // Conditioning of frames 1..n (index k is frame k + 1), per layer, as rows [b, n − 1, 2C].
        let code_t = code.narrow(1, 1, n - 1).transpose(1, 2);
        let rows: Vec<Tensor> = self
            .decoder
            .layers
            .iter()
            .map(|l| l.conditioning(&code_t, style).transpose(1, 2))
            .collect();
        // The context but its last frame, teacher-forced; each layer keeps its inputs of the
        // last `dilation` positions.
        let mut queues: Vec<std::collections::VecDeque<Tensor>> = self
            .decoder
            .layers
            .iter()
            .map(|_| Default::default())
            .collect();
        if context > 1 {
            let x = real.narrow(1, 0, context - 1).transpose(1, 2);
            let mut h = x.apply(&self.decoder.input); // [b, C, context − 1]
            for ((l, row), q) in self.decoder.layers.iter().zip(&rows).zip(queues.iter_mut()) {
                let keep = (context - 1).min(l.dilation);
                for t in context - 1 - keep..context - 1 {
                    q.push_back(h.select(2, t));
                }
                let cond = row.narrow(1, 0, context - 1).transpose(1, 2);
                h = l.forward(&h, &cond).0;
            }
        }
        let lin = |x: &Tensor, conv: &tch::nn::Conv1D| -> Tensor {
            let y = x.matmul(&conv.ws.squeeze_dim(-1).transpose(0, 1));
            match &conv.bs {
                Some(bias) => y + bias,
                None => y,
            }
        };
        let zeros = Tensor::zeros([b, c.residual], (Kind::Float, dev));
        let rho = coherence.clamp(0.0, 0.999);
        let mut z = Tensor::randn([b, d], (Kind::Float, dev));
        let mut frame = real.select(1, context - 1);
        let mut made = Vec::with_capacity((n - context).max(0) as usize);
        for t in context..n {
            // Frame t from frame t − 1 and frame t's conditioning (row t − 1).
            let mut h = lin(&frame, &self.decoder.input);
            let mut skip: Option<Tensor> = None;
            for ((l, row), q) in self.decoder.layers.iter().zip(&rows).zip(queues.iter_mut()) {
                let dil = l.dilation as usize;
                let past = if q.len() >= dil {
                    q[q.len() - dil].shallow_clone()
                } else {
                    zeros.shallow_clone()
                };
                let zz = past.matmul(&l.conv.ws.select(2, 0).transpose(0, 1))
                    + h.matmul(&l.conv.ws.select(2, 1).transpose(0, 1))
                    + row.select(1, t - 1);
                let zs = zz.chunk(2, 1);
                let g = zs[0].tanh() * zs[1].sigmoid();
                let sk = lin(&g, &l.skip);
                skip = Some(match skip {
                    Some(a) => a + sk,
                    None => sk,
                });
                q.push_back(h.shallow_clone());
                while q.len() > dil {
                    q.pop_front();
                }
                h = &h + lin(&g, &l.res);
            }
            let raw = lin(
                &lin(
                    &skip.expect("a decoder has layers").relu(),
                    &self.decoder.head,
                )
                .relu(),
                &self.decoder.out,
            );
            let m = self.mixture(&raw, &frame.narrow(1, 0, d));
            let mean = m.mean.select(1, 0);
            let sigma = m.log_sigma.select(1, 0).exp();
            z = &z * rho + Tensor::randn([b, d], (Kind::Float, dev)) * (1.0 - rho * rho).sqrt();
            let next = mean + sigma * &z * temperature;
            let contacts = m.contacts.sigmoid().gt(0.5).to_kind(Kind::Float);
            frame = Tensor::cat(&[next.detach(), contacts], 1);
            made.push(next);
        }
        Tensor::stack(&made, 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::dancenet::Config;
    use tch::nn::{self, OptimizerConfig};
    use tch::Device;

    /// A tiny one-component model (6 features, music 3 wide) and `b` random real windows of
    /// `n` frames (features and contacts).
    fn tiny(b: i64, n: i64) -> (nn::VarStore, DanceNet, Tensor) {
        let config = Config {
            mixtures: 1,
            music_dim: 3,
            ..Config::tiny(6)
        };
        let vs = nn::VarStore::new(Device::Cpu);
        let model = DanceNet::new(&vs.root(), config.clone());
        let real = Tensor::randn([b, n, 6 + config.contacts], (Kind::Float, Device::Cpu));
        (vs, model, real)
    }

    /// With σ → 0 the free run is the teacher-forced pass fed its own means: each frame it makes
    /// equals the mean `forward` predicts from the frames made before it.
    #[test]
    fn a_free_run_makes_what_the_teacher_forced_pass_predicts_from_its_own_frames() {
        let (b, n) = (2, 20);
        let (_vs, model, real) = tiny(b, n);
        let config = model.config.clone();
        let code = Tensor::randn([b, n, config.code_width()], (Kind::Float, Device::Cpu));
        let style = model.style_one_hot(&[0, 3], Device::Cpu);
        let context = config.receptive_field();
        let made = model.free_run(&real, &code, &style, context, 0.0, 0.0);
        assert_eq!(made.size(), [b, n - context, 6]);
        // Rebuild the frames the run read: real context, then its own frames with the contacts
        // it read back (recomputed from the teacher-forced pass).
        let mut frames = real.narrow(1, 0, context).copy();
        for t in context..n {
            let m = model.forward(&frames.pad_end(), &code.narrow(1, 0, t + 1), &style);
            let mean = m.mean.select(1, t - 1).select(1, 0);
            let made_t = made.select(1, t - context);
            let diff = (&mean - &made_t).abs().max().double_value(&[]);
            assert!(diff < 1e-4, "frame {t}: {diff}");
            let contacts = m
                .contacts
                .select(1, t - 1)
                .sigmoid()
                .gt(0.5)
                .to_kind(Kind::Float);
            frames = Tensor::cat(
                &[frames, Tensor::cat(&[made_t, contacts], 1).unsqueeze(1)],
                1,
            );
        }
    }

    /// The rhythm term (`train::spectral`) on a free run reaches the decoder's weights.
    #[test]
    fn the_rhythm_term_moves_the_decoder_from_its_own_dancing() {
        let (b, n) = (2, 40);
        let (vs, model, real) = tiny(b, n);
        let config = model.config.clone();
        let music = Tensor::randn([b, n, 3], (Kind::Float, Device::Cpu));
        let style = model.style_one_hot(&[0, 1], Device::Cpu);
        let context = config.receptive_field();
        let code = model.encoder.forward(&music);
        let danced = model.free_run(&real, &code, &style, context, 0.8, 0.95);
        assert_eq!(danced.size(), [b, n - context, 6]);
        let continuation = real.narrow(1, context, n - context).narrow(2, 0, 6);
        let loss = crate::models::train::spectral::spectral_loss(
            &danced,
            &continuation,
            &Tensor::ones([6], (Kind::Float, Device::Cpu)),
            25.0,
        );
        let mut opt = tch::nn::Adam::default().build(&vs, 1e-3).unwrap();
        opt.zero_grad();
        loss.backward();
        let moved = vs
            .trainable_variables()
            .iter()
            .filter(|v| {
                v.grad().defined() && v.grad().abs().sum(Kind::Float).double_value(&[]) > 0.0
            })
            .count();
        // The decoder's layers and output head all see the loss; only the contact read-out
        // (thresholded, fed back detached) may not.
        assert!(
            moved * 2 > vs.trainable_variables().len(),
            "{moved} of {} variables have a gradient",
            vs.trainable_variables().len()
        );
    }

    trait PadEnd {
        fn pad_end(&self) -> Tensor;
    }
    impl PadEnd for Tensor {
        /// One blank frame after the last: the teacher-forced pass predicts frame t from t − 1.
        fn pad_end(&self) -> Tensor {
            let (b, _, w) = self.size3().unwrap();
            Tensor::cat(
                &[
                    self.shallow_clone(),
                    Tensor::zeros([b, 1, w], (Kind::Float, Device::Cpu)),
                ],
                1,
            )
        }
    }
}
