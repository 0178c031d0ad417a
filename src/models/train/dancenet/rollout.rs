//! The rhythm term's free-running decoder (`choreo train dancenet --spectral-weight W`): a few
//! windows of each batch danced on by DanceNet's decoder alone, as served, so the term scores
//! the network's own stepping rather than a teacher-forced pass.
use tch::{Kind, Tensor};

use crate::models::dancenet::DanceNet;

/// The decoder dancing on its own: after the first `context` frames of `real` `[b, n, D + contacts]`
/// (normalised) it makes frames `context..n` one at a time, each read back as the next input, drawn
/// as the served sampler draws (σ × `temperature`, AR(1) draws of `coherence`, contacts where
/// their probability is over one half) but as mean + σ·z, so gradients reach every frame's mean
/// and σ (not the history it was read from). `code` `[b, n, d_code]`; returns `[b, n − context,
/// D]`. One mixture component (the served network's); each step reruns the decoder over its
/// receptive field, which training can afford for a few windows a batch.
pub(super) fn rollout(
    model: &DanceNet,
    real: &Tensor,
    code: &Tensor,
    style: &Tensor,
    context: i64,
    temperature: f64,
    coherence: f64,
) -> Tensor {
    let c = &model.config;
    let (b, n, width) = real.size3().expect("windows are [b, n, D + contacts]");
    let (d, rf) = (c.pose_dim, c.receptive_field());
    let dev = real.device();
    let mut history: Vec<Tensor> = (0..context).map(|t| real.select(1, t)).collect();
    let rho = coherence.clamp(0.0, 0.999);
    let mut z = Tensor::randn([b, d], (Kind::Float, dev));
    let blank = Tensor::zeros([b, 1, width], (Kind::Float, dev));
    let mut made = Vec::with_capacity((n - context).max(0) as usize);
    for t in context..n {
        let from = (t - rf).max(0);
        // Frames from..t and a blank for t: the last output predicts frame t.
        let frames = Tensor::cat(
            &[
                Tensor::stack(&history[from as usize..t as usize], 1),
                blank.shallow_clone(),
            ],
            1,
        );
        let m = model.forward(&frames, &code.narrow(1, from, t - from + 1), style);
        let last = t - from - 1;
        let mean = m.mean.select(1, last).select(1, 0);
        let sigma = m.log_sigma.select(1, last).select(1, 0).exp();
        z = &z * rho + Tensor::randn([b, d], (Kind::Float, dev)) * (1.0 - rho * rho).sqrt();
        let frame = mean + sigma * &z * temperature;
        let contacts = m
            .contacts
            .select(1, last)
            .sigmoid()
            .gt(0.5)
            .to_kind(Kind::Float);
        // What it reads back is detached: each frame is scored given the history it made, but
        // the gradient does not run back through 137 steps of its own output (it exploded so:
        // the mixture loss went 0.7 → 17 within 25 steps at lr 1e-3).
        history.push(Tensor::cat(&[frame.detach(), contacts], 1));
        made.push(frame);
    }
    Tensor::stack(&made, 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::dancenet::Config;
    use tch::nn::{self, OptimizerConfig};
    use tch::Device;

    #[test]
    fn the_rhythm_term_moves_the_decoder_from_its_own_dancing() {
        let config = Config {
            mixtures: 1,
            music_dim: 3,
            ..Config::tiny(6)
        };
        let vs = nn::VarStore::new(Device::Cpu);
        let model = DanceNet::new(&vs.root(), config.clone());
        let (b, n, width) = (2, 40, 6 + config.contacts);
        let real = Tensor::randn([b, n, width], (Kind::Float, Device::Cpu));
        let music = Tensor::randn([b, n, 3], (Kind::Float, Device::Cpu));
        let style = model.style_one_hot(&[0, 1], Device::Cpu);
        let context = config.receptive_field();
        let code = model.encoder.forward(&music);
        let danced = rollout(&model, &real, &code, &style, context, 0.8, 0.95);
        assert_eq!(danced.size(), [b, n - context, 6]);
        let continuation = real.narrow(1, context, n - context).narrow(2, 0, 6);
        let loss = crate::models::train::spectral::spectral_loss(
            &danced,
            &continuation,
            &Tensor::ones([6], (Kind::Float, Device::Cpu)),
            25.0,
        );
        let mut opt = nn::Adam::default().build(&vs, 1e-3).unwrap();
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
}
