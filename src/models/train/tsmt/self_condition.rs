//! Self-conditioning (`choreo train tsmt --self-condition S`, against the freeze): runs of
//! each window's input frames replaced by the model's own draws (`train::tsmt::Options`).
use rand::rngs::StdRng;
use rand::Rng;
use tch::Tensor;

use super::Options;
use crate::models::tsmt::Tsmt;

/// `[b, len]` booleans: the input frames to replace by the model's own draws. Runs of
/// `self_run` own frames alternate with runs of the dance whose length gives the share
/// `self_condition` on average; each window starts at a random phase. Frame 0 is always the dance.
pub(super) fn runs_mask(b: usize, len: usize, opts: &Options, rng: &mut StdRng) -> Tensor {
    let own = opts.self_run.max(1);
    let share = opts.self_condition.clamp(0.01, 0.99);
    let truth = ((own as f64 * (1.0 - share) / share).round() as usize).max(1);
    let period = own + truth;
    let mut mask = vec![false; b * len];
    for w in 0..b {
        let phase = rng.gen_range(0..period);
        for t in 1..len {
            mask[w * len + t] = (t + phase) % period < own;
        }
    }
    Tensor::from_slice(&mask).reshape([b as i64, len as i64])
}

/// `input` with the frames of `own` replaced by the model's draws (temperature and top-k of the
/// served sampling), each pass drawing from the last pass's mixed input; no gradient flows
/// through the draws.
pub(super) fn self_conditioned(
    model: &Tsmt,
    input: &Tensor,
    music: &Tensor,
    clock: Option<&Tensor>,
    start: i64,
    own: &Tensor,
    opts: &Options,
) -> Tensor {
    let sampling = opts.sampling();
    tch::no_grad(|| {
        let own = own.unsqueeze(-1); // [b, len, 1]
        let mut mixed = input.shallow_clone();
        for _ in 0..opts.self_passes.max(1) {
            // Logits for frames 1..=n from frames 0..n−1; the draw for frame 0 is the dance.
            let logits = model.forward(&mixed, music, clock, start, false);
            let (b, n, c, bins) = logits.size4().expect("[b, n, coords, bins]");
            let drawn = sampling
                .masked_logits(&logits.reshape([-1, bins]))
                .softmax(-1, tch::Kind::Float)
                .multinomial(1, true)
                .reshape([b, n, c]);
            let drawn = Tensor::cat(&[input.narrow(1, 0, 1), drawn], 1);
            mixed = drawn.where_self(&own, input);
        }
        mixed
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::tsmt::Config;
    use rand::SeedableRng;
    use tch::Device;
    use tch::{nn, Kind};

    #[test]
    fn self_conditioning_replaces_only_the_own_runs_with_draws_of_the_model() {
        tch::manual_seed(3);
        let vs = nn::VarStore::new(Device::Cpu);
        let config = Config {
            coords: 5,
            n_bins: 12,
            music_dim: 3,
            ..Config::tiny()
        };
        let model = Tsmt::new(&vs.root(), config);
        let opts = Options {
            self_condition: 0.5,
            self_run: 4,
            self_passes: 2,
            top_k: 3,
            ..Options::default()
        };
        let mut rng = StdRng::seed_from_u64(7);
        let (b, len) = (6usize, 17usize);
        let own = runs_mask(b, len, &opts, &mut rng);
        let own_v: Vec<bool> = Vec::try_from(own.reshape([-1])).expect("bools");
        // Runs of 4 own frames between runs of 4 of the dance; frame 0 always the dance.
        let share = own_v.iter().filter(|&&o| o).count() as f64 / (b * (len - 1)) as f64;
        assert!((0.35..0.65).contains(&share), "share {share}");
        for w in 0..b {
            let row = &own_v[w * len..(w + 1) * len];
            assert!(!row[0]);
            let starts = (1..len).filter(|&t| row[t] && !row[t - 1]).count();
            let frames = row.iter().filter(|&&o| o).count();
            assert!(frames <= 4 * starts, "runs longer than 4: {row:?}");
        }
        // Tokens far from anything the model would draw at random: the dance's are 11, so a
        // drawn token shows as another value wherever the model did not happen to draw 11.
        let input = Tensor::full([b as i64, len as i64, 5], 11, (Kind::Int64, Device::Cpu));
        let music = Tensor::randn([b as i64, len as i64, 3], (Kind::Float, Device::Cpu));
        let mixed = self_conditioned(&model, &input, &music, None, 0, &own, &opts);
        assert_eq!(mixed.size(), input.size());
        let changed = mixed.ne_tensor(&input).any_dim(-1, false);
        // Nothing outside the own runs changes, and the own runs were drawn (some differ).
        assert_eq!(
            changed
                .logical_and(&own.logical_not())
                .sum(Kind::Int64)
                .int64_value(&[]),
            0
        );
        assert!(changed.sum(Kind::Int64).int64_value(&[]) > 0);
        let (lo, hi) = (mixed.min().int64_value(&[]), mixed.max().int64_value(&[]));
        assert!(lo >= 0 && hi < 12, "tokens {lo}..{hi}");
    }
}
