//! Figures the arms move through over a song (not in the paper).
//!
//! The decoder holds one arm shape from a song's first second to its last: a draw of `h_0` sets
//! it, and neither kicks to the LSTM state nor fresh draws at cuts through the song left it for
//! anything but a stand or a flail (the model card). Real
//! dancers move through figures: their arms' 4-s mean posture lies 0.06–0.22 m (median 0.13) from
//! itself 8 s later (`metrics::posture`). So the arm head ([`super::ArmHead`], never fed back) is
//! also told a *figure* at each frame: the elbows' and wrists' place relative to the spine in the
//! facing frame, one real dancer's 4-s mean from the train split ([`Figures::bank`]). Served, a
//! figure is drawn from the seed every [`Figures::every_frames`] and blended into the next over
//! [`Figures::blend_frames`]; the head, trained to put the arms' mean there and keep them moving
//! (`train::arm_head`), carries the arms from one to the next. The legs and their timing are the
//! LSTM's, untouched.
use ndarray::{Array2, ArrayView2};
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use tch::{Kind, Tensor};

use crate::metrics::musicality::ARM_JOINTS;
use crate::motion::skeleton::{ELBOWS, SPINE, WRISTS};

/// Numbers in one figure: the four arm joints' `x, y, z` relative to the spine (m, facing frame).
pub const FIGURE_DIM: i64 = 3 * ARM_JOINTS.len() as i64;

/// One figure ([`FIGURE_DIM`] numbers).
pub type Figure = [f32; 3 * ARM_JOINTS.len()];

/// Frames of a train dance averaged into one figure of the bank: [`crate::metrics::posture`]'s
/// 4-s window, so a figure is what that measure compares.
pub const BANK_WINDOW_FRAMES: usize = 100;

/// `model.json`'s figures: how often the served figure changes, and the real figures it is drawn
/// from.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Figures {
    /// Network frames a figure is held for before the next begins to blend in.
    pub every_frames: usize,
    /// Network frames over which one figure becomes the next (smoothstep).
    pub blend_frames: usize,
    /// The next figure lies at least this far from the last (mean over the four joints, m): the
    /// slowest-changing real dance's posture variety is 0.059 m.
    pub min_change_m: f32,
    /// The train split's figures: every dance's 4-s means, back to back.
    pub bank: Vec<Figure>,
}

/// What `choreo train dance-revolution --arm-figures true` writes beside the bank: a figure every
/// 16 s of the network's clock, blended over 1 s, at least 0.10 m from the last.
pub const SERVED_EVERY_FRAMES: usize = 400;
pub const SERVED_BLEND_FRAMES: usize = 25;
pub const SERVED_MIN_CHANGE_M: f32 = 0.10;

/// Mean distance (m) of the four joints between two figures.
pub fn distance_m(a: &Figure, b: &Figure) -> f32 {
    a.chunks(3)
        .zip(b.chunks(3))
        .map(|(p, q)| {
            p.iter()
                .zip(q)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f32>()
                .sqrt()
        })
        .sum::<f32>()
        / ARM_JOINTS.len() as f32
}

/// `[n, FIGURE_DIM]`: each frame's figure of pose rows `poses` `[n, ≥ 69]` (metres, the
/// representation's root-relative joints in the facing frame).
pub fn postures(poses: ArrayView2<'_, f32>) -> Array2<f32> {
    Array2::from_shape_fn((poses.nrows(), FIGURE_DIM as usize), |(t, c)| {
        let (j, axis) = (ARM_JOINTS[c / 3], c % 3);
        poses[[t, 3 * j + axis]] - poses[[t, 3 * SPINE + axis]]
    })
}

/// The figures of `dances` (each `[n, ≥ 69]`, metres): every dance's [`BANK_WINDOW_FRAMES`] means,
/// back to back.
pub fn bank_of<'a>(dances: impl IntoIterator<Item = ArrayView2<'a, f32>>) -> Vec<Figure> {
    let mut bank = Vec::new();
    for dance in dances {
        let p = postures(dance);
        for w in 0..p.nrows() / BANK_WINDOW_FRAMES {
            let rows = p.slice(ndarray::s![
                w * BANK_WINDOW_FRAMES..(w + 1) * BANK_WINDOW_FRAMES,
                ..
            ]);
            let mut f: Figure = [0.0; FIGURE_DIM as usize];
            for (k, v) in f.iter_mut().enumerate() {
                *v = rows.column(k).mean().unwrap_or(0.0);
            }
            bank.push(f);
        }
    }
    bank
}

/// The next figure after `last`: drawn from `bank` until one lies `min_change_m` or more away (up
/// to 64 tries; else the farthest tried).
pub fn next_figure(
    bank: &[Figure],
    last: Option<&Figure>,
    min_change_m: f32,
    rng: &mut impl Rng,
) -> Figure {
    let mut best: Option<(f32, Figure)> = None;
    for _ in 0..64 {
        let f = bank[rng.gen_range(0..bank.len())];
        let d = last.map_or(f32::INFINITY, |l| distance_m(l, &f));
        if d >= min_change_m {
            return f;
        }
        if best.is_none_or(|(b, _)| d > b) {
            best = Some((d, f));
        }
    }
    best.map(|(_, f)| f).unwrap_or([0.0; FIGURE_DIM as usize])
}

/// Smoothstep from `a` to `b` at `s` in 0..=1.
fn blend(a: &Figure, b: &Figure, s: f32) -> Figure {
    if s >= 1.0 {
        return *b;
    }
    let w = s * s * (3.0 - 2.0 * s);
    std::array::from_fn(|k| a[k] + (b[k] - a[k]) * w)
}

impl Figures {
    /// What is served, with the train split's `bank`.
    pub fn served(bank: Vec<Figure>) -> Self {
        Self {
            every_frames: SERVED_EVERY_FRAMES,
            blend_frames: SERVED_BLEND_FRAMES,
            min_change_m: SERVED_MIN_CHANGE_M,
            bank,
        }
    }

    /// `[n, FIGURE_DIM]`: the figure at each of `n` network frames for the draw `seed`
    /// ([`held_and_blended`] of figures drawn from the bank, each the least change from the
    /// last). The same seed gives the same figures.
    pub fn plan(&self, n: usize, seed: u64) -> Array2<f32> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed ^ 0x4649_4755_5245_5300);
        let every = self.every_frames.max(1);
        let mut figures: Vec<Figure> = Vec::with_capacity(n / every + 2);
        for _ in 0..n / every + 2 {
            let f = next_figure(&self.bank, figures.last(), self.min_change_m, &mut rng);
            figures.push(f);
        }
        held_and_blended(&figures, n, every, self.blend_frames)
    }
}

/// `[n, FIGURE_DIM]`: `figures[k]` held over frames `k·every ..`, and over the last
/// `blend_frames` frames before `(k+1)·every` becoming `figures[k+1]` (smoothstep; the last blend frame is the
/// next figure itself). The last figure is held on to the end. What is served and what the head
/// is trained on (`train::arm_head`) blend alike.
pub fn held_and_blended(
    figures: &[Figure],
    n: usize,
    every: usize,
    blend_frames: usize,
) -> Array2<f32> {
    let every = every.max(1);
    let blend_frames = blend_frames.min(every);
    let last = figures.len().saturating_sub(1);
    let mut out = Array2::zeros((n, FIGURE_DIM as usize));
    for t in 0..n {
        let k = (t / every).min(last);
        let into = (t % every + blend_frames) as isize - every as isize;
        let f = if blend_frames > 0 && into >= 0 && k < last {
            blend(
                &figures[k],
                &figures[k + 1],
                (into as f32 + 1.0) / blend_frames as f32,
            )
        } else {
            figures[k]
        };
        for (c, v) in f.iter().enumerate() {
            out[[t, c]] = *v;
        }
    }
    out
}

/// Rows of the right and the left elbow and wrist in a figure (or in [`postures_of`]'s joints):
/// `[(elbow, wrist); 2]`, indices into [`ARM_JOINTS`].
pub fn forearms() -> [(usize, usize); 2] {
    let row = |joint: usize| {
        ARM_JOINTS
            .iter()
            .position(|&j| j == joint)
            .expect("an arm joint")
    };
    [0, 1].map(|side| (row(ELBOWS[side]), row(WRISTS[side])))
}

/// `[b, t, FIGURE_DIM]`: the figure of every frame of `x` `[b, t, pose]` (normalised by `mean`,
/// `std`, each `[pose]` or longer), in metres: [`postures`] on tensors, for training.
pub fn postures_of(x: &Tensor, mean: &Tensor, std: &Tensor) -> Tensor {
    let metres = |j: usize| {
        let c = 3 * j as i64;
        x.narrow(2, c, 3) * std.narrow(0, c, 3).view([1, 1, 3])
            + mean.narrow(0, c, 3).view([1, 1, 3])
    };
    let spine = metres(SPINE);
    Tensor::cat(
        &ARM_JOINTS
            .iter()
            .map(|&j| metres(j) - &spine)
            .collect::<Vec<_>>(),
        2,
    )
    .to_kind(Kind::Float)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figure(v: f32) -> Figure {
        [v; FIGURE_DIM as usize]
    }

    /// A plan holds each figure, blends into the next over the blend's frames without a jump, each
    /// next figure lies the least change away, and a seed always plans the same.
    #[test]
    fn a_plan_holds_a_figure_then_blends_into_one_far_enough_away() {
        let figures = Figures {
            every_frames: 100,
            blend_frames: 20,
            min_change_m: 0.5,
            bank: vec![figure(0.0), figure(0.1), figure(1.0)],
        };
        let plan = figures.plan(350, 7);
        assert_eq!(plan.dim(), (350, FIGURE_DIM as usize));
        assert_eq!(plan, figures.plan(350, 7));
        for k in 0..3 {
            let held = plan.row(k * 100);
            assert!(
                held.iter().all(|&v| v == held[0]),
                "one figure at frame {}",
                k * 100
            );
            assert_eq!(plan.row(k * 100 + 79), held, "held up to the blend");
        }
        for k in 0..3 {
            let (a, b) = (plan[[k * 100, 0]], plan[[(k + 1) * 100, 0]]);
            // Every figure of this bank lies 0.1·√3 (0.17) or 0.9·√3 from another; only the
            // 0 ↔ 1 and 0.1 ↔ 1 changes reach 0.5.
            assert!((a - b).abs() * 3f32.sqrt() >= 0.5, "{a} → {b}");
        }
        for t in 1..350 {
            let step = (plan[[t, 0]] - plan[[t - 1, 0]]).abs();
            assert!(step < 0.2, "a jump of {step} at frame {t}");
        }
        assert_eq!(
            plan.row(99),
            plan.row(100),
            "the blend ends on the next figure"
        );
    }

    /// Past its last figure a blend holds it; the forearms are the arm joints' elbow and wrist.
    #[test]
    fn the_last_figure_is_held_to_the_end() {
        let p = held_and_blended(&[figure(0.0), figure(1.0)], 60, 20, 5);
        assert_eq!(p[[14, 0]], 0.0);
        assert!(p[[15, 0]] > 0.0 && p[[18, 0]] < 1.0);
        assert!((19..60).all(|t| p[[t, 0]] == 1.0));
        assert_eq!(forearms(), [(0, 1), (2, 3)]);
    }

    /// The bank's figures are the arms' 4-s means relative to the spine.
    #[test]
    fn the_bank_holds_each_windows_mean_arms_against_the_spine() {
        let mut dance = Array2::<f32>::zeros((250, 69));
        for t in 0..250 {
            dance[[t, 3 * SPINE + 1]] = 0.5;
            for &j in &ARM_JOINTS {
                dance[[t, 3 * j + 1]] = if t < 100 {
                    1.0
                } else {
                    0.5 + t as f32 / 1000.0
                };
            }
        }
        let bank = bank_of([dance.view()]);
        assert_eq!(bank.len(), 2, "two whole windows of 100 frames");
        assert!((bank[0][1] - 0.5).abs() < 1e-6 && bank[0][0] == 0.0);
        assert!((bank[1][1] - 0.1495).abs() < 1e-4, "{}", bank[1][1]);
        let x = crate::models::to_tensor(&dance).unsqueeze(0);
        let zeros = Tensor::zeros([69], (Kind::Float, tch::Device::Cpu));
        let ones = Tensor::ones([69], (Kind::Float, tch::Device::Cpu));
        let p = postures_of(&x, &zeros, &ones);
        assert_eq!(p.size(), vec![1, 250, FIGURE_DIM]);
        assert!((p.double_value(&[0, 0, 1]) - 0.5).abs() < 1e-6);
        assert!((distance_m(&figure(0.0), &figure(1.0)) - 3f32.sqrt()).abs() < 1e-6);
    }
}
