//! `choreo train dance-revolution`: L1 loss, Adam, and the dynamic auto-condition curriculum
//! (paper §3.3) on the train split of dance-with-melody.
use tch::{Device, Kind, Tensor};

use rand::SeedableRng;

use super::augment::Augment;
use super::{
    batch_tensor, window_starts, CommonOptions, Data, EpochLog, EpochResult, Tempo, TrainError,
    Trainer, Windows,
};
use crate::models::dance_revolution::{
    curriculum_q, figures, Config, Curriculum, DanceRevolution, ModelFile, Serving, ID,
};
use crate::models::stretch::MusicLayout;

/// Options of one training run; the defaults reproduce the committed weights' schedule (the
/// card gives the runs).
#[derive(Clone, Debug)]
pub struct Options {
    pub common: CommonOptions,
    pub epochs: usize,
    pub batch: usize,
    /// Training window in frames (10 s at 25 fps; see the model card for why).
    pub window: usize,
    /// Stride between window starts, in frames.
    pub stride: usize,
    pub lr: f64,
    /// `p`: ground-truth frames per curriculum segment (paper: 10).
    pub p: i64,
    /// `λ`: the curriculum grows q = ⌊λ·epoch⌋.
    pub lambda: f64,
    /// Upper bound on q, so late epochs stay within the window.
    pub q_max: i64,
    pub seed: u64,
    /// The curriculum epoch the first epoch of this run counts as (continuing a run).
    pub first_epoch: usize,
    /// Train the encoder at position offsets drawn over a whole 15-minute song (default), or at 0 only.
    pub random_positions: bool,
    /// Append the beat clock to the music features (`audio::clock`).
    pub beat_clock: bool,
    /// Windows at tempo factors in `[min_tempo, max_tempo]` and mirrored (`train::augment`).
    pub min_tempo: f64,
    pub max_tempo: f64,
    pub mirror: bool,
    /// Weight of an L1 loss on frame-to-frame pose change beside the pose loss: a pose loss alone
    /// is met best by the mean pose where a motion is uncertain, which froze the arms.
    pub velocity_weight: f64,
    /// Re-time every train dance to the split's median tempo (`models::beat_time`), and serve so.
    pub beat_time: bool,
    /// Weight of the spectral loss (`train::spectral`) beside the pose loss: the L1 between the
    /// magnitude spectra of the predicted and real root-relative joint velocities over each
    /// window, curriculum frames included.
    pub spectral_weight: f64,
    /// Weight of the spectral loss of the elbows and wrists relative to the spine
    /// (`spectral::relative_spectral_loss`): the whole-body term let seed 1 keep its ballroom hold.
    pub arm_weight: f64,
    /// Train only the read-out's rows of the elbows and wrists (every other weight frozen): the
    /// arms learn to move from the state the LSTM already has, whose timing the tempo test checks
    /// (a whole-network arm fine-tune moved the steps onto other harmonics of the beat).
    pub arm_readout_only: bool,
    /// Hidden width of the decoder's arm head (`dance_revolution::ArmHead`: elbows and wrists read
    /// out beside the paper's read-out, never fed back); 0: none.
    pub arm_head: i64,
    /// Train only the arm head, every other weight frozen: the network's own motion, timing and
    /// legs stay exactly those of `--init`.
    pub arm_head_only: bool,
    /// With `--arm-head-only`: how many seeds each train song is danced from.
    pub rollout_seeds: u64,
    /// With `arm_head_only`: the head also reads a figure (`dance_revolution::figures`).
    pub arm_figures: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            common: CommonOptions::default(),
            epochs: 60,
            batch: 32,
            window: 250,
            stride: 125,
            lr: 1e-3,
            p: 10,
            lambda: 0.75,
            q_max: 40,
            seed: 2021,
            first_epoch: 0,
            random_positions: true,
            // The served weights' schedule; the runs in the model card set these by flag.
            beat_clock: false,
            min_tempo: 1.0,
            max_tempo: 1.0,
            mirror: false,
            velocity_weight: 0.0,
            beat_time: false,
            spectral_weight: 0.0,
            arm_weight: 0.0,
            arm_readout_only: false,
            arm_head: 0,
            arm_head_only: false,
            rollout_seeds: 3,
            arm_figures: false,
        }
    }
}

/// Trains and writes the model folder; returns the per-epoch log.
pub fn train(opts: &Options) -> Result<Vec<EpochLog>, TrainError> {
    let features = if opts.beat_clock {
        crate::audio::features::dance_revolution_clock_at
    } else {
        crate::audio::features::dance_revolution_at
    };
    let tempo = if opts.beat_time {
        Tempo::Analysed
    } else {
        Tempo::Skipped
    };
    let data = Data::load(&opts.common.data, features, tempo, |_| Ok(()))?;
    let base = if opts.common.tiny {
        Config::tiny(0, 0)
    } else {
        Config::cpu()
    };
    let config = Config {
        music_dim: data.music_norm.dim() as i64,
        pose_dim: data.pose_norm.dim() as i64,
        beat_clock: opts.beat_clock,
        arm_head: opts.arm_head,
        arm_figures: opts.arm_figures,
        ..base
    };
    if opts.arm_head_only && (opts.arm_head == 0 || opts.arm_readout_only) {
        return Err(TrainError::InvalidOption(
            "--arm-head-only needs --arm-head N (N > 0) and not --arm-readout-only".into(),
        ));
    }
    if opts.arm_figures && !opts.arm_head_only {
        return Err(TrainError::InvalidOption(
            "--arm-figures trains the arm head alone: give --arm-head-only true".into(),
        ));
    }
    // The real figures the head is told (and serving draws from): the train split's only.
    let figures = opts.arm_figures.then(|| {
        let joints = crate::motion::repr::POSE_DIM;
        let dances: Vec<ndarray::Array2<f32>> = data
            .train
            .iter()
            .map(|s| data.pose_norm.denormalize(&s.poses))
            .collect::<Result<_, _>>()?;
        Ok::<_, TrainError>(figures::Figures::served(figures::bank_of(
            dances.iter().map(|d| d.slice(ndarray::s![.., ..joints])),
        )))
    });
    let figures = figures.transpose()?;
    let augment = Augment {
        min_tempo: opts.min_tempo,
        max_tempo: opts.max_tempo,
        mirror: opts.mirror,
    };
    let beat_time = if opts.beat_time {
        Some(data.reference_tempo()?)
    } else {
        None
    };
    let mut windows = Windows::new(
        &data,
        MusicLayout::dance_revolution(opts.beat_clock),
        augment,
    );
    if let Some(cfg) = beat_time {
        windows = windows.in_beat_time(cfg);
    }
    let (mut trainer, model) = Trainer::new(&opts.common, ID, opts.lr, opts.seed, |p| {
        DanceRevolution::new(p, config.clone())
    })?;
    // Gradient masks (1 where a weight trains), applied after each backward pass; Adam's moments
    // of a masked weight stay 0, so it never moves.
    let masks = if opts.arm_readout_only {
        arm_readout_masks(&trainer.vs, config.pose_dim)?
    } else if opts.arm_head_only {
        arm_head_masks(&trainer.vs)?
    } else {
        Vec::new()
    };
    // The arm head trains on the frozen network's own whole-song dances (`train::arm_head`).
    let head_data = if opts.arm_head_only {
        Some(super::arm_head::HeadData::collect(
            &model,
            &data.train,
            &data.test,
            &data.pose_norm,
            opts.rollout_seeds,
            figures.clone(),
        )?)
    } else {
        None
    };
    let test = &data.test;
    // Windows hold window + 1 frames: frame 0 is only the decoder's first input.
    let len = opts.window + 1;
    let curriculum = Curriculum {
        window: opts.window,
        p: opts.p,
        lambda: opts.lambda,
        q_max: opts.q_max,
        spectral_weight: opts.spectral_weight,
        arm_weight: opts.arm_weight,
        arm_readout_only: opts.arm_readout_only,
        arm_head_only: opts.arm_head_only,
    };
    let epochs = opts.first_epoch..opts.first_epoch + opts.epochs;
    let weights = LossWeights {
        velocity: opts.velocity_weight,
        spectral: opts.spectral_weight,
        arms: opts.arm_weight,
        pose_std: Tensor::from_slice(&data.pose_norm.std[..crate::motion::repr::POSE_DIM]),
    };
    let pose_only = LossWeights {
        velocity: 0.0,
        spectral: 0.0,
        arms: 0.0,
        pose_std: weights.pose_std.shallow_clone(),
    };
    trainer.run(
        epochs,
        5,
        |epoch, opt, _| {
            if let Some(h) = &head_data {
                let (train_loss, test_loss, arms) = h.epoch(&model, opt, &masks, opts.batch, opts.seed ^ epoch as u64, &weights.pose_std, opts.arm_weight);
                return Ok(EpochResult {
                    train_loss,
                    test_loss,
                    note: format!("arm head on the network's own dances: arm_weight={} arm_head={}; {arms}", opts.arm_weight, opts.arm_head),
                });
            }
            let q = curriculum_q(opts.lambda, epoch).min(opts.q_max);
            let starts = window_starts(&data.train_raw, windows.source_len(len), opts.stride, opts.seed + epoch as u64);
            if starts.is_empty() {
                return Err(TrainError::NoWindows(len));
            }
            let mut rng = rand::rngs::StdRng::seed_from_u64(opts.seed ^ (epoch as u64).wrapping_mul(0x2545_F491_4F6C_DD1D));
            let (mut total, mut batches) = (0.0, 0);
            for (bi, chunk) in starts.chunks(opts.batch).enumerate() {
                let (music, poses) = windows.train_batch(chunk, len, &mut rng)?;
                let loss = window_loss(&model, &music, &poses, opts.p, q, opts.seed ^ ((epoch * 100_003 + bi) as u64), true, opts.random_positions, &weights);
                masked_step(opt, &loss, &masks);
                total += loss.double_value(&[]);
                batches += 1;
            }
            let test_loss = tch::no_grad(|| {
                let starts = window_starts(test, len, opts.window, 0);
                let losses: Vec<f64> = starts
                    .chunks(opts.batch)
                    .map(|c| {
                        let music = batch_tensor(test, c, len, |s| &s.music, Device::Cpu);
                        let poses = batch_tensor(test, c, len, |s| &s.poses, Device::Cpu);
                        // The test loss stays the pose L1 alone, comparable with earlier runs.
                        window_loss(&model, &music, &poses, opts.p, q, 7, false, opts.random_positions, &pose_only).double_value(&[])
                    })
                    .collect();
                (!losses.is_empty()).then(|| losses.iter().sum::<f64>() / losses.len() as f64)
            });
            Ok(EpochResult {
                train_loss: total / batches as f64,
                test_loss,
                note: format!(
                    "p={} q={q} random_positions={} beat_clock={} tempo={}..{} mirror={} velocity_weight={} spectral_weight={} arm_weight={} arm_readout_only={} arm_head={} arm_head_only={} beat_time={:?}",
                    opts.p, opts.random_positions, opts.beat_clock, opts.min_tempo, opts.max_tempo, opts.mirror, opts.velocity_weight, opts.spectral_weight, opts.arm_weight, opts.arm_readout_only, opts.arm_head, opts.arm_head_only, beat_time.map(|c| c.bpm)
                ),
            })
        },
        |t| ModelFile {
            config: config.clone(),
            music_norm: data.music_norm.clone(),
            pose_norm: data.pose_norm.clone(),
            fps: crate::motion::MOTION_FPS,
            training: t.record(opts.lr, opts.batch, opts.seed, curriculum.clone()),
            extra: Serving {
                beat_time,
                figures: figures.clone(),
                ..Serving::served()
            },
        },
    )?;
    Ok(trainer.logs)
}

/// The extra terms of [`window_loss`] beside the pose L1.
struct LossWeights {
    /// × the L1 of frame-to-frame changes.
    velocity: f64,
    /// × `spectral::spectral_loss` over the root-relative joints.
    spectral: f64,
    /// × `spectral::relative_spectral_loss` over the elbows and wrists against the spine.
    arms: f64,
    /// The pose normalisation's std of the root-relative joint block, to read the spectra in m/s.
    pose_std: Tensor,
}

/// Mean L1 between the curriculum forward pass and the ground truth over a batch of windows
/// (`music`, `poses`: `[b, len, ·]`, normalised), plus the weighted extra terms.
#[allow(clippy::too_many_arguments)]
fn window_loss(
    model: &DanceRevolution,
    music: &Tensor,
    poses: &Tensor,
    p: i64,
    q: i64,
    seed: u64,
    train: bool,
    random_positions: bool,
    weights: &LossWeights,
) -> Tensor {
    let len = poses.size()[1];
    let music = music.narrow(1, 1, len - 1);
    // A position offset drawn per batch over the whole range a served song uses.
    let start = if random_positions {
        (seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11) as i64
            % (crate::models::dance_revolution::MAX_POSITION - len).max(1)
    } else {
        0
    };
    let pred = model.forward_curriculum(&music, poses, start, p, q, seed, train);
    let truth = poses.narrow(1, 1, len - 1);
    let mut loss = (&pred - &truth).abs().mean(Kind::Float);
    if weights.velocity > 0.0 {
        let step = |x: &Tensor| x.narrow(1, 1, len - 2) - x.narrow(1, 0, len - 2);
        loss += (step(&pred) - step(&truth)).abs().mean(Kind::Float) * weights.velocity;
    }
    if weights.spectral > 0.0 {
        loss += super::spectral::spectral_loss(
            &pred,
            &truth,
            &weights.pose_std,
            crate::motion::MOTION_FPS,
        ) * weights.spectral;
    }
    if weights.arms > 0.0 {
        loss += super::spectral::relative_spectral_loss(
            &pred,
            &truth,
            &weights.pose_std,
            &crate::metrics::musicality::ARM_JOINTS,
            crate::motion::skeleton::SPINE,
            crate::motion::MOTION_FPS,
        ) * weights.arms;
    }
    loss
}

/// One optimiser step on `loss`, its gradients multiplied by `masks` first (none: every weight
/// trains), clipped to norm 1 after masking.
pub(super) fn masked_step(opt: &mut tch::nn::Optimizer, loss: &Tensor, masks: &[(Tensor, Tensor)]) {
    if masks.is_empty() {
        opt.backward_step_clip(loss, 1.0);
        return;
    }
    opt.zero_grad();
    loss.backward();
    tch::no_grad(|| {
        for (var, mask) in masks {
            // A weight the loss never reached has no gradient (the arm head's loss reads only
            // the head).
            let mut grad = var.grad();
            if grad.defined() {
                let _ = grad.g_mul_(mask);
            }
        }
    });
    opt.clip_grad_norm(1.0);
    opt.step();
}

/// Every variable with its gradient mask for `--arm-readout-only`: ones on the read-out's rows (and
/// bias entries) of the columns of `metrics::musicality::ARM_JOINTS`, zeros everywhere else.
fn arm_readout_masks(
    vs: &tch::nn::VarStore,
    pose_dim: i64,
) -> Result<Vec<(Tensor, Tensor)>, TrainError> {
    let mut rows = vec![0f32; pose_dim as usize];
    for k in crate::models::dance_revolution::arm_columns() {
        rows[k as usize] = 1.0;
    }
    let rows = Tensor::from_slice(&rows);
    let mut found = 0;
    let masks = vs
        .variables()
        .into_iter()
        .map(|(name, var)| {
            let mask = match name.as_str() {
                "decoder.readout.weight" => {
                    found += 1;
                    rows.view([pose_dim, 1])
                        .expand(var.size(), false)
                        .contiguous()
                }
                "decoder.readout.bias" => {
                    found += 1;
                    rows.shallow_clone()
                }
                _ => var.zeros_like(),
            };
            (var, mask)
        })
        .collect();
    if found != 2 {
        return Err(TrainError::InvalidOption(
            "--arm-readout-only: the decoder's read-out was not found".into(),
        ));
    }
    Ok(masks)
}

/// Every variable with its gradient mask for `--arm-head-only`: ones on the arm head's weights,
/// zeros everywhere else.
pub(super) fn arm_head_masks(vs: &tch::nn::VarStore) -> Result<Vec<(Tensor, Tensor)>, TrainError> {
    let mut found = 0;
    let masks: Vec<(Tensor, Tensor)> = vs
        .variables()
        .into_iter()
        .map(|(name, var)| {
            let mask = if name.starts_with("decoder.arm_head.") {
                found += 1;
                var.ones_like()
            } else {
                var.zeros_like()
            };
            (var, mask)
        })
        .collect();
    if found == 0 {
        return Err(TrainError::InvalidOption(
            "--arm-head-only: the network has no arm head".into(),
        ));
    }
    Ok(masks)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::nn::OptimizerConfig;

    /// One Adam step on a loss with a gradient on every weight, through `masks`; returns every
    /// weight as it was before.
    fn one_masked_step(
        vs: &tch::nn::VarStore,
        masks: &[(Tensor, Tensor)],
    ) -> std::collections::HashMap<String, Tensor> {
        let before = vs
            .variables()
            .into_iter()
            .map(|(k, v)| (k, v.copy()))
            .collect();
        let mut opt = tch::nn::Adam::default().build(vs, 1e-2).unwrap();
        let loss = vs
            .variables()
            .values()
            .map(|v| (v - 0.5).square().sum(Kind::Float))
            .fold(Tensor::zeros([], (Kind::Float, Device::Cpu)), |a, b| a + b);
        masked_step(&mut opt, &loss, masks);
        before
    }

    #[test]
    fn arm_head_only_moves_the_arm_head_and_nothing_else() {
        let vs = tch::nn::VarStore::new(Device::Cpu);
        let _model = DanceRevolution::new(
            &vs.root(),
            Config {
                arm_head: 8,
                ..Config::tiny(8, 73)
            },
        );
        let before = one_masked_step(&vs, &arm_head_masks(&vs).unwrap());
        for (name, v) in vs.variables() {
            let moved = (&v - &before[&name]).abs().max().double_value(&[]) > 0.0;
            assert_eq!(moved, name.starts_with("decoder.arm_head."), "{name}");
        }
        // A network without a head has nothing to train.
        let plain = tch::nn::VarStore::new(Device::Cpu);
        let _ = DanceRevolution::new(&plain.root(), Config::tiny(8, 73));
        assert!(arm_head_masks(&plain).is_err());
    }

    #[test]
    fn arm_readout_only_moves_the_arms_rows_of_the_readout_and_nothing_else() {
        let vs = tch::nn::VarStore::new(Device::Cpu);
        let _model = DanceRevolution::new(&vs.root(), Config::tiny(8, 73));
        let before = one_masked_step(&vs, &arm_readout_masks(&vs, 73).unwrap());
        let arm_rows = crate::models::dance_revolution::arm_columns();
        for (name, v) in vs.variables() {
            let moved = (&v - &before[&name]).abs().gt(0.0);
            let moved_rows: Vec<i64> = if v.dim() == 2 {
                Vec::<bool>::try_from(moved.any_dim(1, false)).unwrap()
            } else {
                Vec::<bool>::try_from(moved.flatten(0, -1)).unwrap()
            }
            .iter()
            .enumerate()
            .filter(|(_, &m)| m)
            .map(|(i, _)| i as i64)
            .collect();
            if name.starts_with("decoder.readout.") {
                assert_eq!(moved_rows, arm_rows, "{name}");
            } else {
                assert!(moved_rows.is_empty(), "{name} moved");
            }
        }
    }
}
