//! Training dance-revolution's arm head on the network's own whole-song dances
//! (`choreo train dance-revolution --arm-head N --arm-head-only true`).
//!
//! The arm head (`dance_revolution::ArmHead`) is never fed back, so the frozen network dances
//! exactly the same whatever the head does: its dances can be made once, before training, and the
//! head trained on them as a plain regression. Why not on the curriculum's windows: those hold
//! ground-truth frames every `q` and never reach the held ballroom frame that a served dance falls
//! into over a whole song (seeds 101–103 hold their arms under 0.43 m/s in 72 of 111 train-song
//! dances); a head trained on them moved the served arms by nothing (0.40 → 0.40 m/s, the card).
//!
//! Here each train song is danced whole from seeds [`FIRST_SEED`]… (`--rollout-seeds`), as served
//! (stall guard, warm-up), and each ten-second window of it costs:
//! - the arms' spectral term against the real dance of that song (elbows and wrists against the
//!   spine, blind to phase: `spectral::relative_spectral_loss`);
//! - the arms' speed shortfall against the real dance's, capped at [`SPEED_FLOOR_M_S`];
//! - the head's mean offset over the window and the offsets' size, so it adds movement near the
//!   network's own arms rather than moving them somewhere else.
//!
//! The test split is danced from one seed, for the test loss and the arms' speeds in the epoch log.
//!
//! A head with figures (`--arm-figures`, `dance_revolution::figures`) is told, over each window,
//! one real figure of the train split and then another one at least 0.10 m away, blended over a
//! second at a random frame, and the third and fourth terms give way to the *figure term*: each
//! 2-s mean of the arms held to the figure's. The spectral term and the speed shortfall still
//! keep the arms moving around it.
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use tch::{Kind, Tensor};

use super::{Sequence, TrainError};
use crate::models::dance_revolution::figures::{self, Figures, FIGURE_DIM};
use crate::models::dance_revolution::{DanceRevolution, StallGuard, WARM_UP_FRAMES};
use crate::motion::dataset::NormStats;

/// The first seed each train song is danced from (then the next ones): none of them the seeds
/// `choreo eval` reports.
pub const FIRST_SEED: u64 = 101;
/// The test split's one seed.
const TEST_SEED: u64 = 101;
/// Window length and stride (frames): the curriculum's window, ten seconds.
const WINDOW: usize = 250;
const STRIDE: usize = 125;
/// Weight of the arms' speed shortfall (m/s) over each window against the real dance's speed,
/// capped at [`SPEED_FLOOR_M_S`], beside the spectral term. The spectral term alone left the held
/// arms as they were: its gradient at a held pose amplifies jitter in every band, which costs at
/// the high bands what it earns at the low ones, where a shortfall in speed earns any movement.
/// Uncapped, the shortfall lifted every dance to 0.9–3.0 m/s (real: 0.51–1.37) with arms thrown
/// above the head; matched both ways (an L1), it slowed lively dances to 0.31.
const SPEED_WEIGHT: f64 = 1.0;
/// The speed (m/s) the shortfall lifts a window to at most: a little over the slowest real dance's
/// 0.43, so the head lifts held arms and leaves moving ones to the network.
const SPEED_FLOOR_M_S: f64 = 0.55;
/// Weight of the offsets' mean size: keeps the arms near where the network put them.
const SIZE_WEIGHT: f64 = 0.5;
/// Weight of the offsets' mean over each window (normalised units, mean over the arm columns).
const OFFSET_WEIGHT: f64 = 1.0;

/// Weight of the figure term (m, the four joints' mean distance between the arms' 2-s mean and
/// the figure's): a window 0.1 m off its figure costs 1, about what the spectral term costs a
/// held arm.
const FIGURE_WEIGHT: f64 = 10.0;
/// Weight of the forearms' length term (m, how far each frame's elbow-to-wrist distance falls
/// short of [`FOREARM_FLOOR_M`]). The figures are means, shorter from elbow to wrist than any one
/// frame of a moving arm: held to them alone, the head brought the wrist within 0.15 m of the
/// elbow in 13–32 % of a song's frames, which the skeleton's fit shows as a forearm folded at its
/// marker (the network's own left arm does so in 12–15 %; the real dances in 0–1.5 %).
const LENGTH_WEIGHT: f64 = 10.0;
/// The elbow-to-wrist distance (m) a frame should keep: the real dances' 5th percentile is
/// 0.21–0.25 m.
const FOREARM_FLOOR_M: f64 = 0.20;
/// Frames of each mean the figure term compares: 2 s, so the arms may swing around the figure.
const FIGURE_BLOCK: i64 = 50;

/// What a head with figures is told and measured against.
pub struct FigureTerm {
    /// The train split's figures, with the served change and blend.
    figures: Figures,
    /// The pose normalisation's means and stds (`[pose]`), to read the arms in metres.
    mean: Tensor,
    std: Tensor,
}

impl FigureTerm {
    pub fn new(figures: Figures, norm: &NormStats) -> Self {
        Self {
            figures,
            mean: Tensor::from_slice(&norm.mean),
            std: Tensor::from_slice(&norm.std),
        }
    }

    /// `[WINDOW, FIGURE_DIM]`: one figure, then another at least the served change away, blended
    /// in over the served blend ending at a frame drawn in the window's middle half.
    fn window_plan(&self, rng: &mut impl Rng) -> Tensor {
        let f = &self.figures;
        let a = figures::next_figure(&f.bank, None, 0.0, rng);
        let b = figures::next_figure(&f.bank, Some(&a), f.min_change_m, rng);
        let end = rng.gen_range(WINDOW / 4..3 * WINDOW / 4);
        crate::models::to_tensor(&figures::held_and_blended(
            &[a, b],
            WINDOW,
            end,
            f.blend_frames,
        ))
    }

    /// `[b, t, FIGURE_DIM]`: the arms of `x` (`[b, t, pose]`, normalised) as figures, in metres.
    fn arms(&self, x: &Tensor) -> Tensor {
        figures::postures_of(x, &self.mean, &self.std)
    }

    /// The mean shortfall (m) of the elbow-to-wrist distances of `arms` ([`Self::arms`]) under
    /// [`FOREARM_FLOOR_M`].
    fn forearm_shortfall(&self, arms: &Tensor) -> Tensor {
        let (b, t, _) = arms.size3().expect("[b, t, figure]");
        let joints = arms.view([b, t, FIGURE_DIM / 3, 3]);
        let forearm = |(elbow, wrist): (usize, usize)| {
            joints.select(2, wrist as i64) - joints.select(2, elbow as i64)
        };
        let lengths = (Tensor::stack(&figures::forearms().map(forearm), 2)
            .square()
            .sum_dim_intlist(-1, false, Kind::Float)
            + 1e-10)
            .sqrt();
        (-lengths + FOREARM_FLOOR_M).relu().mean(Kind::Float)
    }

    /// The figure term: the mean over windows, 2-s blocks and joints of the distance (m) between
    /// the mean of `arms` `[b, WINDOW, FIGURE_DIM]` ([`Self::arms`]) and the figures' `plan`
    /// `[b, WINDOW, FIGURE_DIM]` over the block.
    fn miss(&self, arms: &Tensor, plan: &Tensor) -> Tensor {
        let (b, t, _) = arms.size3().expect("[b, t, figure]");
        let blocks = t / FIGURE_BLOCK;
        let means = |y: &Tensor| {
            y.narrow(1, 0, blocks * FIGURE_BLOCK)
                .view([b, blocks, FIGURE_BLOCK, FIGURE_DIM / 3, 3])
                .mean_dim(2, false, Kind::Float)
        };
        ((means(arms) - means(plan))
            .square()
            .sum_dim_intlist(-1, false, Kind::Float)
            + 1e-10)
            .sqrt()
            .mean(Kind::Float)
    }
}

/// One whole-song dance of the frozen network with what its read-outs read, and the real dance.
struct Rollout {
    /// `[n, pose]`: the paper's read-out, as fed back.
    fed: Tensor,
    /// `[n, hidden + d_z]`.
    hz: Tensor,
    /// `[n, pose]`: the song's real dance.
    truth: Tensor,
}

/// The network's dances of one split and their windows.
pub struct Rollouts {
    dances: Vec<Rollout>,
    windows: Vec<(usize, usize)>,
}

impl Rollouts {
    /// Dances every sequence of `seqs` (normalised) whole from each of `seeds`.
    fn collect(
        model: &DanceRevolution,
        seqs: &[Sequence],
        seeds: &[u64],
        pose_norm: &NormStats,
    ) -> Result<Self, TrainError> {
        let guard = StallGuard::SERVED;
        let mut dances = Vec::new();
        let mut windows = Vec::new();
        tch::no_grad(|| -> Result<(), TrainError> {
            for s in seqs {
                let n = s.music.nrows().min(s.poses.nrows());
                if n < WINDOW {
                    continue;
                }
                let music =
                    crate::models::to_tensor(&s.music.slice(ndarray::s![..n, ..]).to_owned())
                        .unsqueeze(0);
                let truth =
                    crate::models::to_tensor(&s.poses.slice(ndarray::s![..n, ..]).to_owned());
                let z = model
                    .encoder
                    .forward_chunked(&music, 1000, |_| true)
                    .ok_or_else(|| TrainError::InvalidOption("encoding stopped".into()))?;
                for &seed in seeds {
                    let (fed, hz) =
                        model.rollout(&z, seed, Some((&guard, pose_norm)), WARM_UP_FRAMES);
                    for start in (0..=n - WINDOW).step_by(STRIDE) {
                        windows.push((dances.len(), start));
                    }
                    dances.push(Rollout {
                        fed: fed.squeeze_dim(0),
                        hz: hz.squeeze_dim(0),
                        truth: truth.shallow_clone(),
                    });
                }
                tracing::info!(dance = %s.id, frames = n, "danced for the arm head");
            }
            Ok(())
        })?;
        if windows.is_empty() {
            return Err(TrainError::NoWindows(WINDOW));
        }
        Ok(Self { dances, windows })
    }

    /// The loss of `windows` (indices into [`Self::windows`]): the arms' spectral term against
    /// the real dance × `arm_weight`, plus the mean offset's cost; with `figures`, the figure
    /// term instead of the offsets' (their plans drawn from the generator), and its miss (m).
    fn loss(
        &self,
        model: &DanceRevolution,
        windows: &[(usize, usize)],
        pose_std: &Tensor,
        arm_weight: f64,
        figures: Option<(&FigureTerm, &mut rand::rngs::StdRng)>,
    ) -> (Tensor, Option<f64>) {
        let pick = |f: fn(&Rollout) -> &Tensor| {
            Tensor::stack(
                &windows
                    .iter()
                    .map(|&(d, s)| f(&self.dances[d]).narrow(0, s as i64, WINDOW as i64))
                    .collect::<Vec<_>>(),
                0,
            )
        };
        let (fed, hz, truth) = (pick(|r| &r.fed), pick(|r| &r.hz), pick(|r| &r.truth));
        let told = figures.map(|(term, rng)| {
            let plans: Vec<Tensor> = windows.iter().map(|_| term.window_plan(rng)).collect();
            (term, Tensor::stack(&plans, 0))
        });
        let offsets = model
            .decoder
            .arm_offsets(&hz, told.as_ref().map(|(_, plan)| plan))
            .expect("the arm head is checked before training");
        let pred = &fed + &offsets;
        let spectral = super::spectral::relative_spectral_loss(
            &pred,
            &truth,
            pose_std,
            &crate::metrics::musicality::ARM_JOINTS,
            crate::motion::skeleton::SPINE,
            crate::motion::MOTION_FPS,
        );
        let shortfall = (window_arm_speed(&truth, pose_std).clamp_max(SPEED_FLOOR_M_S)
            - window_arm_speed(&pred, pose_std))
        .relu()
        .mean(Kind::Float);
        if let Some((term, plan)) = told {
            let arms = term.arms(&pred);
            let miss = term.miss(&arms, &plan);
            let figure_miss = miss.double_value(&[]);
            let length = term.forearm_shortfall(&arms);
            return (
                (spectral
                    + shortfall * SPEED_WEIGHT
                    + miss * FIGURE_WEIGHT
                    + length * LENGTH_WEIGHT)
                    * arm_weight,
                Some(figure_miss),
            );
        }
        let columns = crate::models::dance_revolution::arm_columns().len() as f64;
        // Offsets are zero outside the arm columns: the sum over columns / 12 is their mean.
        let offset = offsets
            .mean_dim(1, false, Kind::Float)
            .abs()
            .sum_dim_intlist(-1, false, Kind::Float)
            .mean(Kind::Float)
            / columns;
        // The offsets' size (mean over the arm columns, normalised units).
        let size = offsets
            .abs()
            .sum_dim_intlist(-1, false, Kind::Float)
            .mean(Kind::Float)
            / columns;
        (
            (spectral + shortfall * SPEED_WEIGHT + offset * OFFSET_WEIGHT + size * SIZE_WEIGHT)
                * arm_weight,
            None,
        )
    }
}

impl Rollouts {
    /// Each dance's mean speed (m/s) of the elbows and wrists relative to the spine, with the
    /// head's offsets (what `metrics::musicality::arm_speed_m_s` reads) and without.
    /// Without a head, both are the network's own.
    /// A head with figures is told a served plan of `figures` (seed: the dance's index).
    fn arm_speeds(
        &self,
        model: &DanceRevolution,
        pose_std: &Tensor,
        figures: Option<&FigureTerm>,
    ) -> Vec<(f64, f64)> {
        let speed = |x: &Tensor| window_arm_speed(&x.unsqueeze(0), pose_std).double_value(&[0]);
        tch::no_grad(|| {
            self.dances
                .iter()
                .enumerate()
                .map(|(i, r)| {
                    let own = speed(&r.fed);
                    let plan = figures.map(|term| {
                        let n = r.hz.size()[0] as usize;
                        crate::models::to_tensor(&term.figures.plan(n, i as u64))
                    });
                    match model.decoder.arm_offsets(&r.hz, plan.as_ref()) {
                        Some(offsets) => (speed(&(&r.fed + offsets)), own),
                        None => (own, own),
                    }
                })
                .collect()
        })
    }
}

/// `[b]`: each window's mean speed (m/s) of the elbows and wrists relative to the spine (`x`:
/// `[b, t, pose]` normalised; `pose_std`: the joint columns' std).
fn window_arm_speed(x: &Tensor, pose_std: &Tensor) -> Tensor {
    let joints = crate::metrics::musicality::ARM_JOINTS;
    let rel =
        super::spectral::relative_joints(x, pose_std, &joints, crate::motion::skeleton::SPINE);
    let (b, t, _) = rel.size3().expect("[b, t, 3·joints]");
    let rel = rel.view([b, t, joints.len() as i64, 3]);
    // + ε: the norm's gradient at a joint that did not move at all.
    ((rel.narrow(1, 1, t - 1) - rel.narrow(1, 0, t - 1))
        .square()
        .sum_dim_intlist(3, false, Kind::Float)
        + 1e-10)
        .sqrt()
        .mean_dim([1i64, 2].as_slice(), false, Kind::Float)
        * crate::motion::MOTION_FPS
}

/// The train and test splits danced by the frozen network.
pub struct HeadData {
    train: Rollouts,
    test: Rollouts,
    /// For a head with figures.
    figures: Option<FigureTerm>,
}

impl HeadData {
    /// Dances each train song from `seeds` seeds, each test song from one.
    pub fn collect(
        model: &DanceRevolution,
        train: &[Sequence],
        test: &[Sequence],
        pose_norm: &NormStats,
        seeds: u64,
        figures: Option<Figures>,
    ) -> Result<Self, TrainError> {
        let started = std::time::Instant::now();
        let seeds: Vec<u64> = (FIRST_SEED..FIRST_SEED + seeds.max(1)).collect();
        if model.config.arm_figures != figures.is_some() {
            return Err(TrainError::InvalidOption(
                "a head with figures is trained with the train split's figures, and only it".into(),
            ));
        }
        let data = Self {
            train: Rollouts::collect(model, train, &seeds, pose_norm)?,
            test: Rollouts::collect(model, test, &[TEST_SEED], pose_norm)?,
            figures: figures.map(|f| FigureTerm::new(f, pose_norm)),
        };
        let std = Tensor::from_slice(&pose_norm.std[..crate::motion::repr::POSE_DIM]);
        let speeds = data.train.arm_speeds(model, &std, data.figures.as_ref());
        let held = |pick: fn(&(f64, f64)) -> f64| {
            (
                speeds.iter().filter(|s| pick(s) < 0.43).count(),
                speeds.iter().map(pick).fold(f64::INFINITY, f64::min),
            )
        };
        tracing::info!(
            held_with_head = ?held(|s| s.0),
            held_without = ?held(|s| s.1),
            of = speeds.len(),
            "train dances whose arms move under 0.43 m/s (the slowest real dance), and the slowest"
        );
        tracing::info!(
            seconds = started.elapsed().as_secs_f64(),
            train_windows = data.train.windows.len(),
            test_windows = data.test.windows.len(),
            "the network's own dances, for the arm head"
        );
        Ok(data)
    }

    /// The test loss and, with figures, the figure term's miss (m): the same figures every call.
    fn test_loss(
        &self,
        model: &DanceRevolution,
        batch: usize,
        pose_std: &Tensor,
        arm_weight: f64,
    ) -> (Option<f64>, Option<f64>) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(TEST_SEED);
        let mut misses = Vec::new();
        let losses: Vec<f64> = tch::no_grad(|| {
            self.test
                .windows
                .chunks(batch.max(1))
                .map(|c| {
                    let told = self.figures.as_ref().map(|f| (f, &mut rng));
                    let (loss, miss) = self.test.loss(model, c, pose_std, arm_weight, told);
                    misses.extend(miss);
                    loss.double_value(&[])
                })
                .collect()
        });
        let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        (mean(&losses), mean(&misses))
    }

    /// One epoch over the train windows in a seeded order; returns the mean train loss, the test
    /// loss, and the test dances' arm speeds as a log note.
    #[allow(clippy::too_many_arguments)]
    pub fn epoch(
        &self,
        model: &DanceRevolution,
        opt: &mut tch::nn::Optimizer,
        masks: &[(Tensor, Tensor)],
        batch: usize,
        seed: u64,
        pose_std: &Tensor,
        arm_weight: f64,
    ) -> (f64, Option<f64>, String) {
        let mut order = self.train.windows.clone();
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        order.shuffle(&mut rng);
        let (mut total, mut batches) = (0.0, 0);
        for chunk in order.chunks(batch.max(1)) {
            let told = self.figures.as_ref().map(|f| (f, &mut rng));
            let (loss, _) = self.train.loss(model, chunk, pose_std, arm_weight, told);
            super::dance_revolution::masked_step(opt, &loss, masks);
            total += loss.double_value(&[]);
            batches += 1;
        }
        let (test, miss) = self.test_loss(model, batch, pose_std, arm_weight);
        let speeds = self.test.arm_speeds(model, pose_std, self.figures.as_ref());
        let slowest = speeds
            .iter()
            .cloned()
            .fold((f64::INFINITY, f64::INFINITY), |a, b| {
                if b.0 < a.0 {
                    b
                } else {
                    a
                }
            });
        let figure_miss = miss
            .map(|m| format!("test figure miss {m:.3} m; "))
            .unwrap_or_default();
        let note = format!(
            "{figure_miss}test arms (m/s, with the head / without): slowest {:.3} / {:.3}, each {:?}",
            slowest.0,
            slowest.1,
            speeds
                .iter()
                .map(|s| format!("{:.2}/{:.2}", s.0, s.1))
                .collect::<Vec<_>>()
        );
        (total / batches.max(1) as f64, test, note)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::dance_revolution::Config;
    use ndarray::Array2;
    use tch::nn::OptimizerConfig;

    /// A real dance whose arms swing at 1 Hz against a still trunk, with random music.
    fn swinging(id: &str, frames: usize, seed: u64) -> Sequence {
        use rand::Rng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let music = Array2::from_shape_fn((frames, 6), |_| rng.gen_range(-1.0f32..1.0));
        let mut poses = Array2::<f32>::zeros((frames, 73));
        for f in 0..frames {
            let swing = (2.0 * std::f32::consts::PI * f as f32 / 25.0).sin();
            for &j in &crate::metrics::musicality::ARM_JOINTS {
                poses[[f, 3 * j]] = swing;
            }
        }
        Sequence {
            id: id.into(),
            music,
            poses,
            beat_hz: None,
        }
    }

    /// A pose normalisation that leaves the poses as they are.
    fn unit_norm() -> NormStats {
        NormStats {
            mean: vec![0.0; 73],
            std: vec![1.0; 73],
        }
    }

    /// Two train dances and a test dance, each swinging its arms.
    fn swinging_split() -> ([Sequence; 2], [Sequence; 1]) {
        (
            [swinging("a", 300, 1), swinging("b", 300, 2)],
            [swinging("c", 300, 3)],
        )
    }

    /// A head with figures learns to put the arms' mean where it is told, on dances it never
    /// trained on.
    #[test]
    fn a_head_with_figures_learns_to_hold_the_arms_where_it_is_told() {
        tch::manual_seed(5);
        let vs = tch::nn::VarStore::new(tch::Device::Cpu);
        let model = DanceRevolution::new(
            &vs.root(),
            Config {
                arm_head: 32,
                arm_figures: true,
                ..Config::tiny(6, 73)
            },
        );
        let norm = unit_norm();
        let (train, test) = swinging_split();
        let bank: Vec<figures::Figure> = [0.4f32, -0.4, 0.0, 0.8]
            .iter()
            .map(|&v| std::array::from_fn(|k| if k % 3 == 1 { v } else { -v / 2.0 }))
            .collect();
        assert!(HeadData::collect(&model, &train, &test, &norm, 1, None).is_err());
        let figures = Some(Figures::served(bank));
        let data = HeadData::collect(&model, &train, &test, &norm, 2, figures).unwrap();
        let std = Tensor::ones([69], (Kind::Float, tch::Device::Cpu));
        let (_, first) = data.test_loss(&model, 4, &std, 1.0);
        let masks = super::super::dance_revolution::arm_head_masks(&vs).unwrap();
        let mut opt = tch::nn::Adam::default().build(&vs, 1e-2).unwrap();
        for epoch in 0..40 {
            data.epoch(&model, &mut opt, &masks, 4, epoch, &std, 1.0);
        }
        let (_, last) = data.test_loss(&model, 4, &std, 1.0);
        let (first, last) = (first.unwrap(), last.unwrap());
        assert!(last < 0.5 * first, "figure miss {first} → {last} m");
    }

    /// The head learns to swing the arms the network holds still: the loss on a dance it never
    /// trained on falls, and the frozen network's own read-out (what it feeds itself) is the
    /// same after training as before.
    #[test]
    fn the_head_learns_arms_on_the_networks_own_dances_and_leaves_them_as_they_were() {
        tch::manual_seed(4);
        let vs = tch::nn::VarStore::new(tch::Device::Cpu);
        let model = DanceRevolution::new(
            &vs.root(),
            Config {
                arm_head: 16,
                ..Config::tiny(6, 73)
            },
        );
        let norm = unit_norm();
        let (train, test) = swinging_split();
        let data = HeadData::collect(&model, &train, &test, &norm, 2, None).unwrap();
        let own_before = data.train.dances[0].fed.copy();
        let masks = super::super::dance_revolution::arm_head_masks(&vs).unwrap();
        let mut opt = tch::nn::Adam::default().build(&vs, 1e-2).unwrap();
        let std = Tensor::ones([69], (Kind::Float, tch::Device::Cpu));
        let (_, first, _) = data.epoch(&model, &mut opt, &masks, 4, 0, &std, 1.0);
        let mut last = first;
        for epoch in 1..30 {
            last = data.epoch(&model, &mut opt, &masks, 4, epoch, &std, 1.0).1;
        }
        let (first, last) = (first.unwrap(), last.unwrap());
        assert!(last < 0.7 * first, "test loss {first} → {last}");
        let again = HeadData::collect(&model, &train, &test, &norm, 2, None).unwrap();
        let moved = (&again.train.dances[0].fed - &own_before)
            .abs()
            .max()
            .double_value(&[]);
        assert_eq!(moved, 0.0, "the network's own dance moved by {moved}");
    }
}
