//! Training dance-revolution's arm head on the network's own whole-song dances (issue 25,
//! `choreo train dance-revolution --arm-head N --arm-head-only true`).
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
use rand::seq::SliceRandom;
use rand::SeedableRng;
use tch::{Kind, Tensor};

use super::{Sequence, TrainError};
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
    /// the real dance × `arm_weight`, plus the mean offset's cost.
    fn loss(
        &self,
        model: &DanceRevolution,
        windows: &[(usize, usize)],
        pose_std: &Tensor,
        arm_weight: f64,
    ) -> Tensor {
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
        let offsets = model
            .decoder
            .arm_offsets(&hz)
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
        let columns = crate::models::dance_revolution::arm_columns().len() as f64;
        // Offsets are zero outside the arm columns: the sum over columns / 12 is their mean.
        let offset = offsets
            .mean_dim(1, false, Kind::Float)
            .abs()
            .sum_dim_intlist(-1, false, Kind::Float)
            .mean(Kind::Float)
            / columns;
        let shortfall = (window_arm_speed(&truth, pose_std).clamp_max(SPEED_FLOOR_M_S)
            - window_arm_speed(&pred, pose_std))
        .relu()
        .mean(Kind::Float);
        // The offsets' size (mean over the arm columns, normalised units).
        let size = offsets
            .abs()
            .sum_dim_intlist(-1, false, Kind::Float)
            .mean(Kind::Float)
            / columns;
        (spectral + shortfall * SPEED_WEIGHT + offset * OFFSET_WEIGHT + size * SIZE_WEIGHT)
            * arm_weight
    }
}

impl Rollouts {
    /// Each dance's mean speed (m/s) of the elbows and wrists relative to the spine, with the
    /// head's offsets (what `metrics::musicality::arm_speed_m_s` reads) and without.
    /// Without a head, both are the network's own.
    fn arm_speeds(&self, model: &DanceRevolution, pose_std: &Tensor) -> Vec<(f64, f64)> {
        let speed = |x: &Tensor| window_arm_speed(&x.unsqueeze(0), pose_std).double_value(&[0]);
        tch::no_grad(|| {
            self.dances
                .iter()
                .map(|r| {
                    let own = speed(&r.fed);
                    match model.decoder.arm_offsets(&r.hz) {
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
}

impl HeadData {
    /// Dances each train song from `seeds` seeds, each test song from one.
    pub fn collect(
        model: &DanceRevolution,
        train: &[Sequence],
        test: &[Sequence],
        pose_norm: &NormStats,
        seeds: u64,
    ) -> Result<Self, TrainError> {
        let started = std::time::Instant::now();
        let seeds: Vec<u64> = (FIRST_SEED..FIRST_SEED + seeds.max(1)).collect();
        let data = Self {
            train: Rollouts::collect(model, train, &seeds, pose_norm)?,
            test: Rollouts::collect(model, test, &[TEST_SEED], pose_norm)?,
        };
        let std = Tensor::from_slice(&pose_norm.std[..crate::motion::repr::POSE_DIM]);
        let speeds = data.train.arm_speeds(model, &std);
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
        order.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed));
        let (mut total, mut batches) = (0.0, 0);
        for chunk in order.chunks(batch.max(1)) {
            let loss = self.train.loss(model, chunk, pose_std, arm_weight);
            super::dance_revolution::masked_step(opt, &loss, masks);
            total += loss.double_value(&[]);
            batches += 1;
        }
        let test = tch::no_grad(|| {
            let losses: Vec<f64> = self
                .test
                .windows
                .chunks(batch.max(1))
                .map(|c| {
                    self.test
                        .loss(model, c, pose_std, arm_weight)
                        .double_value(&[])
                })
                .collect();
            (!losses.is_empty()).then(|| losses.iter().sum::<f64>() / losses.len() as f64)
        });
        let speeds = self.test.arm_speeds(model, pose_std);
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
        let note = format!(
            "test arms (m/s, with the head / without): slowest {:.3} / {:.3}, each {:?}",
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
        let norm = NormStats {
            mean: vec![0.0; 73],
            std: vec![1.0; 73],
        };
        let train = [swinging("a", 300, 1), swinging("b", 300, 2)];
        let test = [swinging("c", 300, 3)];
        let data = HeadData::collect(&model, &train, &test, &norm, 2).unwrap();
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
        let again = HeadData::collect(&model, &train, &test, &norm, 2).unwrap();
        let moved = (&again.train.dances[0].fed - &own_before)
            .abs()
            .max()
            .double_value(&[]);
        assert_eq!(moved, 0.0, "the network's own dance moved by {moved}");
    }
}
