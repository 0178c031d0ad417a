//! Free runs of `choreo train tsmt` (`--free-runs`): a few windows of each
//! batch are danced on by the network from [`FREE_CONTEXT`] real frames, as served
//! ([`Tsmt::free_run`], straight-through draws), and the run is scored against the real
//! continuation of the same frames:
//! - the **lock** term ([`super::lock::Lock`]): the toes' speed projected on the window's step
//!   clock, held to the real dancer's score (`--free-weight`);
//! - the **body** term ([`Body`], `--free-body`): the run keeps the pace and the floor of the
//!   dance it continues. The lock term alone (docs/experiments.md) taught runs that step on the
//!   clock by holding still between bursts: a served dance at 0.49 m/s, one held off the floor
//!   for 1.2 s, where the weights before it passed all 24. So every second of the run moves at
//!   least [`SLOWEST`] of the real continuation's mean joint speed, the whole run at most
//!   `--free-pace-max` of it ([`FASTEST`] by default), and its lowest foot rises no more than
//!   [`LIFT_M`] above the highest the real lowest foot reached. The ceiling is a sum over all
//!   joints: a run met it by stilling the arms (docs/experiments.md), so 0 leaves it out.
use ndarray::{s, Array2, ArrayView2};
use rand::rngs::StdRng;
use rand::Rng;
use tch::{Kind, Tensor};

use super::lock::{self, Lock};
use super::{token_tensor, Options, TrainError, MAX_POSITION};
use crate::models::train::Data;
use crate::models::tsmt::{Bins, Tsmt};
use crate::motion::repr;
use crate::motion::skeleton::{ANKLES, HEELS, TOES};

/// Real frames a free run starts from (1.6 s: the served seed clip is 2 s).
pub(super) const FREE_CONTEXT: usize = 40;

/// Frames of one block of the body term's pace floor (1 s at 25 fps).
const BLOCK: i64 = 25;
/// Each block's mean joint speed is held to at least this share of the real continuation's.
pub(super) const SLOWEST: f64 = 0.7;
/// The run's mean joint speed is held by default to at most this multiple of the real
/// continuation's (`Options::free_pace_max`).
pub(super) const FASTEST: f64 = 1.3;
/// The run's lowest foot may rise this much (m) above the real continuation's highest lowest
/// foot before the term pulls it down (real dances lift it at most 0.14 m, `motion::hang`).
pub(super) const LIFT_M: f64 = 0.02;

/// One free run's window: the real context's tokens `[FREE_CONTEXT, coords]`, the real
/// continuation's `[frames, coords]`, the normalised music and the clock of all of them.
pub(super) struct FreeWindow {
    prefix: Tensor,
    real: Tensor,
    music: Tensor,
    clock: Tensor,
}

/// The free run of the last `FREE_CONTEXT + frames` rows of a drawn window (`poses`, `music` and
/// the window's `clock` as drawn, before any warp).
pub(super) fn window(
    poses: &Array2<f32>,
    music: &Array2<f32>,
    clock: ArrayView2<f32>,
    frames: usize,
    bins: &Bins,
    data: &Data,
) -> Result<FreeWindow, TrainError> {
    let n = FREE_CONTEXT + frames;
    let from = poses.nrows() - n;
    let tokens = token_tensor(bins.tokens(&poses.slice(s![from.., ..]).to_owned()).view());
    Ok(FreeWindow {
        prefix: tokens.narrow(0, 0, FREE_CONTEXT as i64),
        real: tokens.narrow(0, FREE_CONTEXT as i64, frames as i64),
        music: crate::models::to_tensor(
            &data
                .music_norm
                .normalize(&music.slice(s![from.., ..]).to_owned())?,
        ),
        clock: crate::models::to_tensor(&clock.slice(s![from.., ..]).to_owned()),
    })
}

/// What one batch's free runs give: the lock term and the body term.
pub(super) struct Scored {
    pub lock: Lock,
    pub body: Body,
}

/// The free runs of one batch's free windows, from a song position of their own: each window's
/// network draws `free_frames` frames after its real context as served, scored by the lock and
/// the body terms against the real continuation. Windows without two beats are left out; `None`
/// when none is left.
pub(super) fn runs(
    model: &Tsmt,
    windows: &[FreeWindow],
    rng: &mut StdRng,
    opts: &Options,
    bins: &Bins,
) -> Option<Scored> {
    let stack = |f: fn(&FreeWindow) -> &Tensor| {
        Tensor::stack(&windows.iter().map(f).collect::<Vec<_>>(), 0)
    };
    let clock = stack(|w| &w.clock);
    let keep = lock::clocked(&clock)?;
    let pick = |t: &Tensor| t.index_select(0, &keep);
    let (prefix, real, music, clock) = (
        pick(&stack(|w| &w.prefix)),
        pick(&stack(|w| &w.real)),
        pick(&stack(|w| &w.music)),
        pick(&clock),
    );
    let (m, frames) = (prefix.size()[1], real.size()[1]);
    let start = rng.gen_range(0..MAX_POSITION - m - frames);
    // Every coordinate is drawn anyway; the run's values of all of them feed both terms.
    let all: Vec<usize> = (0..repr::FEATURE_DIM).collect();
    let (idx, centres) = lock::centres_of(bins, &all);
    let drawn = model.free_run(
        &prefix,
        &music,
        Some(&clock),
        start,
        frames,
        opts.sampling(),
        &idx,
        &centres,
    );
    let values = |t: &Tensor| lock::values_of(t, &idx, &centres);
    // Both runs start from the context's last frame, so the first frame's speed is scored too.
    let last = values(&prefix.narrow(1, m - 1, 1));
    let real = Tensor::cat(&[last.shallow_clone(), values(&real)], 1);
    let own = Tensor::cat(&[last, drawn], 1);
    let toes = Tensor::from_slice(&lock::toe_coords().map(|c| c as i64));
    let toe_speed = |v: &Tensor| {
        let v = v.index_select(2, &toes);
        lock::toe_speed(&v.narrow(1, 0, frames), &v.narrow(1, 1, frames))
    };
    let k = clock.narrow(1, m, frames);
    let phase = k.select(2, 0).atan2(&k.select(2, 1));
    Some(Scored {
        lock: Lock::of(
            &toe_speed(&own),
            &toe_speed(&real),
            &phase,
            !opts.lock_uncapped,
        ),
        body: Body::of(&own, &real, opts.free_pace_max),
    })
}

/// The body term of free runs: `loss` (unitless: the pace's shortfall and excess as shares of
/// the real pace, the lift in tenths of a metre), and for the log the run's mean joint speed
/// over the real continuation's and the mean lift past the allowance (m).
pub(super) struct Body {
    pub loss: Tensor,
    pub pace: f64,
    pub lift: f64,
}

impl Body {
    /// From the run's and the real continuation's values `[b, n + 1, FEATURE_DIM]` (both
    /// starting at the context's last frame), the pace held to at most `fastest` of the real
    /// one's (0: no ceiling).
    pub(super) fn of(own: &Tensor, real: &Tensor, fastest: f64) -> Self {
        let (s_own, s_real) = (joint_speed(own), joint_speed(real));
        let (b, n) = s_own.size2().expect("speed is [b, n]");
        let r = s_real.mean_dim(1, false, Kind::Float) + 1e-6; // [b]
        let block = BLOCK.min(n);
        let blocks = s_own
            .narrow(1, 0, n / block * block)
            .view([b, n / block, block])
            .mean_dim(-1, false, Kind::Float);
        let slow = ((r.unsqueeze(1) * SLOWEST - &blocks).relu() / r.unsqueeze(1)).mean(Kind::Float);
        let pace = s_own.mean_dim(1, false, Kind::Float) / &r;
        let fast = if fastest > 0.0 {
            (&pace - fastest).relu().mean(Kind::Float)
        } else {
            pace.zeros_like().mean(Kind::Float)
        };
        let ceiling = lowest_foot(real).amax(1, true) + LIFT_M;
        let lifted = (lowest_foot(own) - ceiling).relu();
        let loss = slow + fast + lifted.mean(Kind::Float) / 0.1;
        Self {
            loss,
            pace: pace.mean(Kind::Float).double_value(&[]),
            lift: lifted.mean(Kind::Float).double_value(&[]),
        }
    }
}

/// Mean speed of the 23 joints (m/frame) `[b, n]` from values `[b, n + 1, FEATURE_DIM]`: each
/// joint's move relative to the root plus the root's own (the facing frame's turn left out, as
/// for the toes).
fn joint_speed(v: &Tensor) -> Tensor {
    let (b, len, _) = v.size3().expect("values are [b, n + 1, FEATURE_DIM]");
    let n = len - 1;
    let j = (repr::POSE_DIM / 3) as i64;
    let (prev, next) = (v.narrow(1, 0, n), v.narrow(1, 1, n));
    let moved = (next.narrow(2, 0, 3 * j) - prev.narrow(2, 0, 3 * j)).view([b, n, j, 3]);
    let vx = next.select(2, repr::ROOT_VX as i64);
    let root = Tensor::stack(
        &[
            vx.shallow_clone(),
            vx.zeros_like(),
            next.select(2, repr::ROOT_VZ as i64),
        ],
        -1,
    );
    ((moved + root.unsqueeze(2))
        .square()
        .sum_dim_intlist(-1, false, Kind::Float)
        + 1e-10)
        .sqrt()
        .mean_dim(-1, false, Kind::Float)
}

/// Height (m) of the lowest of the ankles, heels and toes `[b, len]` from values
/// `[b, len, FEATURE_DIM]`: the root's height plus each foot point's root-relative y.
fn lowest_foot(v: &Tensor) -> Tensor {
    let ys: Vec<i64> = [ANKLES, HEELS, TOES]
        .iter()
        .flatten()
        .map(|&j| 3 * j as i64 + 1)
        .collect();
    let feet = v.index_select(2, &Tensor::from_slice(&ys));
    (feet + v.select(2, repr::ROOT_Y as i64).unsqueeze(-1)).amin(-1, false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::Device;

    /// Values `[1, n + 1, FEATURE_DIM]` of a dancer whose joints all move `step(t)` m along x
    /// in frame t (root-relative), standing with the feet at `foot(t)` m.
    fn dancer(n: usize, step: impl Fn(usize) -> f32, foot: impl Fn(usize) -> f32) -> Tensor {
        let mut v = Array2::<f32>::zeros((n + 1, repr::FEATURE_DIM));
        let mut x = 0.0;
        for t in 0..=n {
            if t > 0 {
                x += step(t);
            }
            for j in 0..repr::POSE_DIM / 3 {
                v[[t, 3 * j]] = x;
                v[[t, 3 * j + 1]] = foot(t) - 1.0;
            }
            v[[t, repr::ROOT_Y]] = 1.0;
        }
        crate::models::to_tensor(&v)
            .unsqueeze(0)
            .to_device(Device::Cpu)
    }

    /// A run at the real pace on the real floor costs nothing; one that holds still for a
    /// second, one that moves twice as fast and one held 0.1 m up each cost, and by how much.
    #[test]
    fn the_body_term_holds_the_runs_pace_and_floor_to_the_real_ones() {
        let n = 100;
        let real = dancer(n, |_| 0.02, |_| 0.0);
        let same = Body::of(&real, &real, FASTEST);
        assert!(same.loss.double_value(&[]).abs() < 1e-6);
        assert!((same.pace - 1.0).abs() < 1e-4);

        // Still for the second block (frames 26..=50): that block's shortfall is all of 0.7.
        let held = dancer(
            n,
            |t| if (26..=50).contains(&t) { 0.0 } else { 0.02 },
            |_| 0.0,
        );
        let b = Body::of(&held, &real, FASTEST);
        assert!(
            (b.loss.double_value(&[]) - 0.7 / 4.0).abs() < 1e-3,
            "{}",
            b.loss.double_value(&[])
        );

        // Twice the pace: 0.7 over the 1.3 allowed.
        let busy = Body::of(&dancer(n, |_| 0.04, |_| 0.0), &real, FASTEST);
        assert!((busy.loss.double_value(&[]) - 0.7).abs() < 1e-3);
        assert!((busy.pace - 2.0).abs() < 1e-3);
        // Without the ceiling the same run costs nothing.
        let free = Body::of(&dancer(n, |_| 0.04, |_| 0.0), &real, 0.0);
        assert!(free.loss.double_value(&[]).abs() < 1e-6);

        // Feet 0.1 m up throughout: 0.08 past the allowance, 0.8 in tenths of a metre.
        let up = Body::of(&dancer(n, |_| 0.02, |_| 0.1), &real, FASTEST);
        assert!((up.lift - 0.08).abs() < 1e-4);
        assert!((up.loss.double_value(&[]) - 0.8).abs() < 1e-3);
    }
}
