//! A free run of TSMT that a loss can reach (`choreo train tsmt --free-runs`):
//! the network draws its own frames one at a time, as served (§3.4: the caches, the temperature,
//! top-k), and every draw is straight-through: the forward pass carries the drawn bin exactly,
//! the backward pass the gradient of its probabilities (Bengio, Léonard, Courville 2013; the
//! one-hot of the draw plus `p − stop_gradient(p)`). A term on the whole run then reaches every
//! draw and, through the embeddings of the drawn frames, the steps that read them later.
//!
//! Teacher-forced windows cannot teach what the served sampler gets wrong: each scored frame is
//! one step from a history that already steps at the dance's rate, so a term on the step clock
//! is met before the network reads the clock (the tsmt card). In a free run the
//! network's own history drifts, as served, and only the clock can bring it back.
use tch::{Kind, Tensor};

use crate::models::layers::KvCache;
use crate::models::tsmt::{Sampling, Tsmt};

impl Tsmt {
    /// Draws `frames` frames after the context `prefix` `[b, m, coords]` (int64, `m` ≤ the
    /// window), with `music` `[b, m + frames, music_dim]` (normalised; its first frame at song
    /// position `start`) and, where the network has a step clock, `clock`
    /// `[b, m + frames, WIDTH]`. Returns the drawn frames' values of the coordinates `coords`
    /// (`k` of them, `centres` `[k, n_bins]` their bin centres) `[b, frames, k]`: the bin
    /// centres of the draws, with the gradient of their expected values.
    #[allow(clippy::too_many_arguments)]
    pub fn free_run(
        &self,
        prefix: &Tensor,
        music: &Tensor,
        clock: Option<&Tensor>,
        start: i64,
        frames: i64,
        sampling: Sampling,
        coords: &Tensor,
        centres: &Tensor,
    ) -> Tensor {
        let (b, m, c) = prefix.size3().expect("prefix is [b, m, coords]");
        let nb = self.config.n_bins;
        // The audio side of every frame's fusion, once (served: `audio_logit_vectors`).
        let wa = self.audio.forward(music, start, false).apply(&self.w_a);
        let step = self.clock.as_ref().zip(clock);
        let wa = match step {
            Some((k, t)) => wa + t.apply(&k.fusion),
            None => wa,
        };
        let mut caches = self.pose.stack.new_caches();
        // Embedded frames `[b, n, coords, e_bin]` at positions from `pos` → `W^X z^X` of the last.
        let read = |emb: &Tensor, pos: i64, caches: &mut [KvCache]| {
            let n = emb.size()[1];
            let x = self.pose.merge(emb, pos);
            let x = match step {
                Some((k, t)) => x + t.narrow(1, pos - start, n).apply(&k.pose),
                None => x,
            };
            let z = self.pose.stack.forward_cached(&x, caches);
            for cache in caches.iter_mut() {
                cache.keep_last(self.config.window - 1);
            }
            z.select(1, n - 1).apply(&self.w_x)
        };
        let mut wx = read(&prefix.apply(&self.bin_embed), start, &mut caches);
        let table = self.bin_embed.ws.shallow_clone(); // [n_bins, e_bin]
        let mut out = Vec::with_capacity(frames as usize);
        for t in 0..frames {
            let logits = self.logits(&(&wx + wa.select(1, m + t))); // [b, c, nb]
            let p = sampling.masked_logits(&logits).softmax(-1, Kind::Float);
            let drawn = p
                .detach()
                .reshape([-1, nb])
                .multinomial(1, true)
                .reshape([b, c]);
            let hard = drawn.one_hot(nb).to_kind(Kind::Float);
            let y = hard + &p - p.detach(); // [b, c, nb]
            out.push((y.index_select(1, coords) * centres).sum_dim_intlist(-1, false, Kind::Float));
            if t + 1 < frames {
                let emb = y.matmul(&table).unsqueeze(1); // [b, 1, c, e_bin]
                wx = read(&emb, start + m + t, &mut caches);
            }
        }
        Tensor::stack(&out, 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::tsmt::Config;
    use tch::{nn, Device};

    /// Every drawn value is a bin centre (the forward pass carries the draw), and a loss on the
    /// values reaches the pose stream and the bin embedding (the backward pass goes through the
    /// draws into the frames read after them).
    #[test]
    fn a_free_run_draws_bins_and_its_loss_reaches_the_pose_stream() {
        tch::manual_seed(5);
        let vs = nn::VarStore::new(Device::Cpu);
        let config = Config {
            coords: 5,
            n_bins: 12,
            music_dim: 3,
            ..Config::tiny()
        };
        let model = Tsmt::new(&vs.root(), config);
        let (b, m, frames) = (2i64, 4i64, 6i64);
        let prefix = Tensor::randint(12, [b, m, 5], (Kind::Int64, Device::Cpu));
        let music = Tensor::randn([b, m + frames, 3], (Kind::Float, Device::Cpu));
        let coords = Tensor::from_slice(&[1i64, 3]);
        let centres = Tensor::arange(12, (Kind::Float, Device::Cpu))
            .unsqueeze(0)
            .repeat([2, 1]);
        let sampling = Sampling {
            temperature: 1.0,
            top_k: 3,
        };
        let v = model.free_run(
            &prefix, &music, None, 7, frames, sampling, &coords, &centres,
        );
        assert_eq!(v.size(), [b, frames, 2]);
        let values: Vec<f32> = Vec::try_from(v.reshape([-1])).expect("f32");
        assert!(values
            .iter()
            .all(|x| (x - x.round()).abs() < 1e-5 && (0.0..12.0).contains(x)));
        v.square().sum(Kind::Float).backward();
        let grad = |name: &str| {
            let vars = vs.variables();
            vars[name].grad().abs().sum(Kind::Float).double_value(&[])
        };
        assert!(grad("bin_embed.weight") > 0.0);
        assert!(grad("pose.merge.weight") > 0.0);
        assert!(grad("w_a.weight") > 0.0);
    }
}
