//! The lock term (`choreo train dancenet --lock-weight W`): how much of the
//! toes' speed, while the decoder dances on its own, turns with the song's beats at the style's
//! step fraction.
//!
//! Real dancers step at a fixed fraction of the beat (1/2 of it in rumba and cha-cha, 1/3 in
//! waltz: the tempo lock, docs/evaluation.md), and the network's own dances do not. The rhythm
//! term (`train::spectral`) holds the danced velocities' magnitude spectra to the real
//! continuation's; that never names the beat, and a 5-s rollout cannot tell a step rate 10 % off.
//! This term names it: the
//! phase 2π·f·B(t), with B the beat count at each frame (from the window's beat column, so a
//! window drawn at another tempo brings its own grid) and f the style's fraction, and it scores
//! the normalised projection of the toes' speed on it,
//! `|Σ w s'(t) e^{−iθ(t)}| / Σ w |s'(t)|` (w a Hann window, s' the speed less its mean): 1 for
//! a speed that swings once per f-th of a beat, whatever its phase, and near 0 for stepping at
//! any other rate or for jitter. The loss is how far the danced window falls short of the real
//! dancer's projection over the same frames.
use tch::{Kind, Tensor};

use crate::audio::features::DANCENET_BEAT;
use crate::models::step_clock::{beat_count, step_fraction};
use crate::models::train::step_lock::{projection, signed_projection};
use crate::models::DanceStyle;
use crate::motion::dataset::NormStats;
use crate::motion::rotations::{self, Layout};

/// Toes' summed speed (m/frame) of feature rows `[b, n, D]` (denormalised): each toe's motion
/// relative to the anchor plus the anchor's own (yaw's turn left out). `[b, n − 1]`.
pub(super) fn toe_speed(rows: &Tensor, layout: &Layout) -> Tensor {
    let ee = layout.end_effectors().start as i64;
    let n = rows.size()[1];
    let anchor = Tensor::stack(
        &[
            rows.select(2, rotations::ROOT_VX as i64),
            rows.zeros_like().select(2, 0),
            rows.select(2, rotations::ROOT_VZ as i64),
        ],
        2,
    )
    .narrow(1, 1, n - 1);
    // End effectors: head, right wrist, left wrist, right toe, left toe.
    [3i64, 4]
        .iter()
        .map(|&e| {
            let p = rows.narrow(2, ee + 3 * e, 3);
            let v = p.narrow(1, 1, n - 1) - p.narrow(1, 0, n - 1) + &anchor;
            (v.square().sum_dim_intlist(-1, false, Kind::Float) + 1e-10).sqrt()
        })
        .reduce(|a, b| a + b)
        .expect("two toes")
}

/// Each window's beat frames from normalised music `[b, n, ·]`: the beat column over its
/// midpoint between "no beat" and "beat".
pub(super) fn window_beats(music: &Tensor, music_norm: &NormStats) -> Vec<Vec<bool>> {
    let col = DANCENET_BEAT;
    let cut = (0.5 - music_norm.mean[col]) / music_norm.std[col].max(NormStats::MIN_STD);
    let n = music.size()[1].max(1) as usize;
    let values: Vec<f32> =
        Vec::try_from(music.select(2, col as i64).contiguous().view([-1])).expect("f32 music");
    values
        .chunks(n)
        .map(|w| w.iter().map(|&v| v > cut).collect())
        .collect()
}

/// What one batch's lock term gives: the loss (the shortfall), and the mean projection of the danced and of
/// the real continuation (the same frames as the real dancer made them), for the log.
pub(super) struct Lock {
    pub loss: Tensor,
    pub danced: f64,
    pub real: f64,
}

/// The term for `danced` `[r, n − context, D]` (normalised features the decoder made after
/// `context` real frames of `real` `[r, n, D + contacts]`), with `music` `[r, n, ·]` (normalised;
/// its column 1 the beat one-hot) and each window's style. Windows without two beats are left
/// out; `None` when none is left. With the windows' step clock `clock` `[r, n, WIDTH]`
/// (`phase::window_clock`: the real dancer's rate and zero) the score is [`signed_projection`]
/// on the clock's phase: the danced toes are held to peak where the real dancer's do.
#[allow(clippy::too_many_arguments)]
pub(super) fn term(
    danced: &Tensor,
    real: &Tensor,
    music: &Tensor,
    clock: Option<&Tensor>,
    styles: &[DanceStyle],
    context: i64,
    pose_norm: &NormStats,
    music_norm: &NormStats,
    layout: &Layout,
) -> Option<Lock> {
    let (r, n, _) = real.size3().ok()?;
    let d = danced.size()[2];
    let std = Tensor::from_slice(&pose_norm.std).view([1, 1, -1]);
    let mean = Tensor::from_slice(&pose_norm.mean).view([1, 1, -1]);
    let denorm = |x: &Tensor| x * &std + &mean;
    // The last real frame before the free run, so its first frame has a speed too.
    let last = real.narrow(1, context - 1, 1).narrow(2, 0, d);
    let own = toe_speed(
        &denorm(&Tensor::cat(&[last, danced.shallow_clone()], 1)),
        layout,
    );
    let truth = toe_speed(
        &denorm(&real.narrow(1, context - 1, n - context + 1).narrow(2, 0, d)),
        layout,
    );
    // Held to at least the real dancer's score over the same frames, not past it: a decoder
    // pushed further swings its feet harder than anyone danced.
    let shortfall = |own: Tensor, truth: Tensor| Lock {
        loss: (&truth - &own).relu().mean(Kind::Float),
        danced: own.mean(Kind::Float).double_value(&[]),
        real: truth.mean(Kind::Float).double_value(&[]),
    };
    if let Some(clock) = clock {
        let k = clock.narrow(1, context, n - context);
        let phase = k.select(2, 0).atan2(&k.select(2, 1));
        // Windows without two beats have a zero clock: left out.
        let keep = k
            .abs()
            .sum_dim_intlist([1, 2].as_slice(), false, Kind::Float)
            .gt(0.0);
        let idx = keep.nonzero().squeeze_dim(1);
        if idx.size()[0] == 0 {
            return None;
        }
        let pick = |t: &Tensor| t.index_select(0, &idx);
        return Some(shortfall(
            signed_projection(&pick(&own), &pick(&phase)),
            signed_projection(&pick(&truth), &pick(&phase)),
        ));
    }
    let beats = window_beats(music, music_norm);
    let (mut keep, mut theta) = (Vec::new(), Vec::new());
    for (i, (style, beats)) in styles.iter().zip(&beats).enumerate().take(r as usize) {
        if let Some(count) = beat_count(beats) {
            let f = step_fraction(*style);
            keep.push(i as i64);
            theta.extend(
                count[context as usize..]
                    .iter()
                    .map(|&b| (std::f64::consts::TAU * f * b) as f32),
            );
        }
    }
    if keep.is_empty() {
        return None;
    }
    let idx = Tensor::from_slice(&keep);
    let theta = Tensor::from_slice(&theta).view([keep.len() as i64, n - context]);
    Some(shortfall(
        projection(&own.index_select(0, &idx), &theta),
        projection(&truth.index_select(0, &idx), &theta),
    ))
}
