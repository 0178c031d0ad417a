//! The step clock of tsmt's training windows and its lock term (`choreo train tsmt --step-clock
//! --lock-weight W`).
//!
//! TSMT's pose stream, taught by teacher forcing, continues the step rate of its history; its
//! own dances drift off the beat (the card: the network's own tempo lock at chance). The clock
//! (`models::step_clock`) names where in the step each frame lies. In a window it is set to the
//! real dancer's own rate and zero (`train::step_lock::dancer_phase`) over the 10 s up to the
//! window's end, longer than the 3.2-s window, so a waltz's step every 2 s is heard.
//!
//! The clock alone is ignored in teacher forcing (dancenet's card), since the real
//! history already says when the next step comes. The lock term asks what the history cannot:
//! after the model's own draws (self-conditioning's runs) and the noised dance, the toes' speed
//! the network means to draw next (the expected value of its read-out, differentiable) is
//! scored by the signed projection on the clock's phase, and held to the real continuation's
//! score over the same frames. A network that drifted in its own runs is pulled back to the
//! clock by one step each frame, which is what a free run needs. Unlike dancenet's term it needs
//! no free run through the sampler: TSMT's draws are discrete, and each scored frame here is one
//! step from a history the network itself drew.
use ndarray::{s, Array2, ArrayView2};
use tch::{Kind, Tensor};

use crate::audio::features::TSMT_BEAT;
use crate::models::step_clock::{self, beat_count};
use crate::models::train::step_lock::{signed_projection, step_phase};
use crate::models::tsmt::{Bins, Tsmt};
use crate::motion::repr;
use crate::motion::skeleton::TOES;

/// Frames of the real dance a training window's clock is fitted over (10 s at 25 fps), ending
/// where the window ends.
pub(super) const CLOCK_CONTEXT: usize = 250;

/// The pose coordinates the toes' speed is read from: each toe's root-relative x, y, z in the
/// facing frame, then the root's displacement x and z.
pub(super) fn toe_coords() -> [usize; 8] {
    let (r, l) = (3 * TOES[0], 3 * TOES[1]);
    [
        r,
        r + 1,
        r + 2,
        l,
        l + 1,
        l + 2,
        repr::ROOT_VX,
        repr::ROOT_VZ,
    ]
}

/// Toes' summed speed (m/frame) from frame `prev` to frame `next`, rows `[.., 8]` in
/// [`toe_coords`] order: each toe's move relative to the root plus the root's own (the facing
/// frame's turn left out).
pub(super) fn toe_speed(prev: &Tensor, next: &Tensor) -> Tensor {
    let root = Tensor::stack(
        &[
            next.select(-1, 6),
            next.select(-1, 6).zeros_like(),
            next.select(-1, 7),
        ],
        -1,
    );
    [0i64, 3]
        .iter()
        .map(|&k| {
            let v = next.narrow(-1, k, 3) - prev.narrow(-1, k, 3) + &root;
            (v.square().sum_dim_intlist(-1, false, Kind::Float) + 1e-10).sqrt()
        })
        .reduce(|a, b| a + b)
        .expect("two toes")
}

/// The clock `[n, WIDTH]` of the last `n` rows of a real window: `poses` `[m ≥ n, FEATURE_DIM]`
/// and `music` `[m, TSMT_DIM]` as the split holds them (not normalised). The dancer's phase is
/// fitted over all `m` rows. Zeros under two beats.
pub(super) fn window_clock(
    poses: ArrayView2<f32>,
    music: ArrayView2<f32>,
    n: usize,
) -> Array2<f32> {
    let m = poses.nrows();
    let is_beat: Vec<bool> = music.column(TSMT_BEAT).iter().map(|&v| v > 0.5).collect();
    let Some(count) = beat_count(&is_beat) else {
        return Array2::zeros((n, step_clock::WIDTH as usize));
    };
    let rows = poses.select(ndarray::Axis(1), &toe_coords());
    let t = crate::models::to_tensor(&rows);
    let speed = toe_speed(&t.narrow(0, 0, m as i64 - 1), &t.narrow(0, 1, m as i64 - 1));
    let speed: Vec<f32> = Vec::try_from(speed.contiguous()).expect("f32 speed");
    let phase = step_phase(&speed, &count);
    step_clock::columns(&phase)
        .slice(s![m - n.min(m).., ..])
        .to_owned()
}

/// What one batch's lock term gives: the loss (the shortfall), and the mean score of what the
/// network means to draw and of the real continuation, for the log.
pub(super) struct Lock {
    pub loss: Tensor,
    pub danced: f64,
    pub real: f64,
}

impl Lock {
    /// The term from the toes' speed `[b, n]` the network danced (`own`) and the real
    /// continuation's (`real`), both scored by their signed projection on `phase` `[b, n]`.
    /// `capped`: the loss is the shortfall against the real score, else the score's negative.
    pub(super) fn of(own: &Tensor, real: &Tensor, phase: &Tensor, capped: bool) -> Self {
        let danced = signed_projection(own, phase);
        let real = signed_projection(real, phase);
        // Held to at least the real dancer's score over the same frames, not past it: pushed
        // further, the feet would swing harder than anyone danced. Uncapped, the score itself is
        // raised (it is at most 1): a capped term the history already meets pulls on nothing.
        let loss = if capped {
            (&real - &danced).relu().mean(Kind::Float)
        } else {
            -danced.mean(Kind::Float)
        };
        Self {
            loss,
            danced: danced.mean(Kind::Float).double_value(&[]),
            real: real.mean(Kind::Float).double_value(&[]),
        }
    }
}

/// The indices `[k]` of the windows of `clock` `[b, n, WIDTH]` that have a clock (those without
/// two beats have zeros); `None` when none has.
pub(super) fn clocked(clock: &Tensor) -> Option<Tensor> {
    let keep = clock
        .abs()
        .sum_dim_intlist([1, 2].as_slice(), false, Kind::Float)
        .gt(0.0)
        .nonzero()
        .squeeze_dim(1);
    (keep.size()[0] > 0).then_some(keep)
}

/// One training batch as the pass read it.
pub(super) struct Batch<'a> {
    /// The tokens the pass read `[b, n + 1, coords]`.
    pub input: &'a Tensor,
    /// `[b, n + 1]`: the frames of `input` that are the network's own draws (the rest are the
    /// dance, noised).
    pub own: Option<&'a Tensor>,
    /// The dance's tokens `[b, n + 1, coords]`.
    pub target: &'a Tensor,
    /// The windows' clocks `[b, n + 1, WIDTH]`.
    pub clock: &'a Tensor,
}

/// The term of one batch: `fused` the training pass's fused vectors (`Tsmt::fused`) of frames
/// 1..=n of `batch`. Each frame's speed is from the frame before it as the network would have
/// it without the noise (its own draw, or the dance) to the expected next frame. Only frames
/// `skip + 1..=n` are scored (after a warped history, `train::tsmt::warp`). `capped`: the loss
/// is the shortfall against the real continuation's score, else the score's negative
/// (`--lock-uncapped`). Windows without two beats are left out; `None` when none is left.
pub(super) fn term(
    model: &Tsmt,
    fused: &Tensor,
    batch: &Batch<'_>,
    bins: &Bins,
    skip: i64,
    capped: bool,
) -> Option<Lock> {
    let Batch {
        input,
        own,
        target,
        clock,
    } = *batch;
    let n = target.size()[1] - 1;
    let (idx, centres) = toe_centres(bins);
    let values = |tokens: &Tensor| values_of(tokens, &idx, &centres);
    let dance = values(target);
    let prev = match own {
        Some(own) => values(input).where_self(&own.unsqueeze(-1), &dance),
        None => dance.shallow_clone(),
    }
    .narrow(1, 0, n);
    let meant = model.expected(fused, &idx, &centres);
    let scored = |t: Tensor| t.narrow(1, skip, n - skip);
    let own_speed = scored(toe_speed(&prev, &meant));
    let real_speed = scored(toe_speed(&dance.narrow(1, 0, n), &dance.narrow(1, 1, n)));
    let k = scored(clock.narrow(1, 1, n));
    let phase = k.select(2, 0).atan2(&k.select(2, 1));
    let keep = clocked(&k)?;
    let pick = |t: &Tensor| t.index_select(0, &keep);
    Some(Lock::of(
        &pick(&own_speed),
        &pick(&real_speed),
        &pick(&phase),
        capped,
    ))
}

/// The bin centres `[8, n_bins]` of [`toe_coords`] and their indices.
fn toe_centres(bins: &Bins) -> (Tensor, Tensor) {
    centres_of(bins, &toe_coords())
}

/// The bin centres `[k, n_bins]` of the pose coordinates `coords` and their indices `[k]`.
pub(super) fn centres_of(bins: &Bins, coords: &[usize]) -> (Tensor, Tensor) {
    let nb = bins.n as i64;
    let centres: Vec<f32> = coords
        .iter()
        .flat_map(|&c| (0..nb).map(move |i| bins.centre(c, i)))
        .collect();
    let idx: Vec<i64> = coords.iter().map(|&c| c as i64).collect();
    (
        Tensor::from_slice(&idx),
        Tensor::from_slice(&centres).view([coords.len() as i64, nb]),
    )
}

/// The values `[b, len, k]` of the coordinates `idx` `[k]` (bin centres `centres` `[k, n_bins]`,
/// [`centres_of`]) of `tokens` `[b, len, coords]`.
pub(super) fn values_of(tokens: &Tensor, idx: &Tensor, centres: &Tensor) -> Tensor {
    let (k, nb) = centres.size2().expect("centres are [k, n_bins]");
    let offset = Tensor::arange(k, (Kind::Int64, tokens.device())) * nb;
    centres
        .view([-1])
        .take(&(tokens.index_select(2, idx) + offset))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dancer whose right toe swings forward and back once every 3 beats, fastest 1.1 rad
    /// after every third beat: the clock of the window's last frames turns at 1/3 of the beat
    /// and is zero where the toe is fastest.
    #[test]
    fn the_window_clock_is_the_dancers_own_step() {
        let (m, n, beat) = (250usize, 81usize, 17.0f64);
        let mut music = Array2::<f32>::zeros((m, crate::audio::features::TSMT_DIM));
        let mut poses = Array2::<f32>::zeros((m, repr::FEATURE_DIM));
        let mut b: f64 = 2.0;
        while (b as usize) < m {
            music[[b.round() as usize, TSMT_BEAT]] = 1.0;
            b += beat;
        }
        // Speed ∝ 1 + cos(2π B / 3 − 1.1): the position is its integral.
        let mut x = 0.0f64;
        for t in 0..m {
            let count = (t as f64 - 2.0) / beat;
            x += 0.02 * (1.0 + (std::f64::consts::TAU * count / 3.0 - 1.1).cos());
            poses[[t, 3 * TOES[0] + 2]] = x as f32;
        }
        let clock = window_clock(poses.view(), music.view(), n);
        assert_eq!(clock.dim(), (n, step_clock::WIDTH as usize));
        let phase: Vec<f64> = (0..n)
            .map(|t| f64::from(clock[[t, 0]]).atan2(f64::from(clock[[t, 1]])))
            .collect();
        for (t, &got) in phase.iter().enumerate() {
            let count = ((m - n + t) as f64 - 2.0) / beat;
            let want =
                (std::f64::consts::TAU * count / 3.0 - 1.1).rem_euclid(std::f64::consts::TAU);
            let d = (got.rem_euclid(std::f64::consts::TAU) - want).abs();
            let d = d.min(std::f64::consts::TAU - d);
            assert!(d < 0.1, "frame {t}: phase {got} against {want}");
        }
        let silent = Array2::<f32>::zeros((m, crate::audio::features::TSMT_DIM));
        assert!(window_clock(poses.view(), silent.view(), n)
            .iter()
            .all(|&v| v == 0.0));
    }
}
