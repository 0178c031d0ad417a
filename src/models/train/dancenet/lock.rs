//! The lock term (`choreo train dancenet --lock-weight W`, issue 25 item 4): how much of the
//! toes' speed, while the decoder dances on its own, turns with the song's beats at the style's
//! step fraction.
//!
//! Real dancers step at a fixed fraction of the beat (1/2 of it in rumba and cha-cha, 1/3 in
//! waltz: the README's tempo lock), and the network's own dances do not. The rhythm term tried
//! before held the danced velocities' magnitude spectra to the real continuation's; that never
//! names the beat, and a 5-s rollout cannot tell a step rate 10 % off. This term names it: the
//! phase 2π·f·B(t), with B the beat count at each frame (from the window's beat column, so a
//! window drawn at another tempo brings its own grid) and f the style's fraction, and it scores
//! the normalised projection of the toes' speed on it,
//! `|Σ w s'(t) e^{−iθ(t)}| / Σ w |s'(t)|` (w a Hann window, s' the speed less its mean): 1 for
//! a speed that swings once per f-th of a beat, whatever its phase, and near 0 for stepping at
//! any other rate or for jitter. The loss is how far the danced window falls short of the real
//! dancer's projection over the same frames.
use ndarray::Array2;
use tch::{Kind, Tensor};

use crate::models::DanceStyle;
use crate::motion::dataset::NormStats;
use crate::motion::rotations::{self, Layout};

/// Steps per beat of a style's dancers (the README's tempo lock on the real dances).
pub(super) fn step_fraction(style: DanceStyle) -> f64 {
    match style {
        DanceStyle::Waltz => 1.0 / 3.0,
        DanceStyle::ChaCha | DanceStyle::Rumba | DanceStyle::Tango => 0.5,
    }
}

/// Beat count at each of `n` frames from a beat column (one where a beat falls): linear between
/// beats, the nearest interval carried on beyond the first and last. `None` under two beats.
pub(super) fn beat_count(is_beat: &[bool]) -> Option<Vec<f64>> {
    let beats: Vec<f64> = is_beat
        .iter()
        .enumerate()
        .filter(|(_, &b)| b)
        .map(|(t, _)| t as f64)
        .collect();
    if beats.len() < 2 {
        return None;
    }
    Some(
        (0..is_beat.len())
            .map(|t| {
                let t = t as f64;
                let k = beats.partition_point(|&b| b <= t).clamp(1, beats.len() - 1);
                let (a, b) = (beats[k - 1], beats[k]);
                (k - 1) as f64 + (t - a) / (b - a)
            })
            .collect(),
    )
}

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

/// The normalised projection of `speed` `[b, n]` on phases `theta` `[b, n]` (radians), per window
/// `[b]`: 1 for a speed that swings with the phase, near 0 otherwise.
pub(super) fn projection(speed: &Tensor, theta: &Tensor) -> Tensor {
    let n = speed.size()[1];
    let w = Tensor::hann_window_periodic(n, false, (Kind::Float, speed.device())).unsqueeze(0);
    let mean = (speed * &w).sum_dim_intlist(1, true, Kind::Float) / w.sum(Kind::Float);
    let s = (speed - mean) * &w;
    let re = (&s * theta.cos()).sum_dim_intlist(1, false, Kind::Float);
    let im = (&s * theta.sin()).sum_dim_intlist(1, false, Kind::Float);
    let norm = s.abs().sum_dim_intlist(1, false, Kind::Float) + 1e-8;
    (re.square() + im.square() + 1e-12).sqrt() / norm
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
/// out; `None` when none is left.
#[allow(clippy::too_many_arguments)]
pub(super) fn term(
    danced: &Tensor,
    real: &Tensor,
    music: &Tensor,
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
        &denorm(&Tensor::cat(
            &[last.shallow_clone(), danced.shallow_clone()],
            1,
        )),
        layout,
    );
    let truth = toe_speed(
        &denorm(&real.narrow(1, context - 1, n - context + 1).narrow(2, 0, d)),
        layout,
    );
    // Beat frames: the beat column over its midpoint between "no beat" and "beat".
    let cut = (0.5 - music_norm.mean[1]) / music_norm.std[1].max(NormStats::MIN_STD);
    let col: Array2<f32> = Array2::from_shape_vec(
        (r as usize, n as usize),
        Vec::<f32>::try_from(music.select(2, 1).contiguous().view([-1])).ok()?,
    )
    .ok()?;
    let (mut keep, mut theta) = (Vec::new(), Vec::new());
    for (i, style) in styles.iter().enumerate().take(r as usize) {
        let beats: Vec<bool> = col.row(i).iter().map(|&v| v > cut).collect();
        if let Some(count) = beat_count(&beats) {
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
    let own = projection(&own.index_select(0, &idx), &theta);
    let truth = projection(&truth.index_select(0, &idx), &theta);
    Some(Lock {
        // Held to at least the real dancer's lock over the same frames, not past it: a decoder
        // pushed further swings its feet harder than anyone danced.
        loss: (&truth - &own).relu().mean(Kind::Float),
        danced: own.mean(Kind::Float).double_value(&[]),
        real: truth.mean(Kind::Float).double_value(&[]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_beat_count_runs_on_between_and_beyond_the_beats() {
        let mut beats = vec![false; 30];
        beats[5] = true;
        beats[15] = true;
        beats[23] = true;
        let b = beat_count(&beats).unwrap();
        assert!((b[5] - 0.0).abs() < 1e-9 && (b[10] - 0.5).abs() < 1e-9);
        assert!((b[19] - 1.5).abs() < 1e-9 && (b[27] - 2.5).abs() < 1e-9);
        assert!((b[0] + 0.5).abs() < 1e-9, "before the first beat: {}", b[0]);
        assert!(beat_count(&beats[..10]).is_none());
    }

    /// A speed swinging once every 2 beats scores near 1 on the half-beat phase and near 0 on
    /// the third-beat one, whatever its own phase.
    #[test]
    fn the_projection_hears_the_step_rate_not_the_phase() {
        let n = 250;
        let beat_frames = 17.0; // 88 BPM at 25 fps
        let b: Vec<f64> = (0..n).map(|t| t as f64 / beat_frames).collect();
        let speed: Vec<f32> = b
            .iter()
            .map(|&x| (1.0 + (std::f64::consts::TAU * 0.5 * x + 1.3).cos()) as f32)
            .collect();
        let s = Tensor::from_slice(&speed).view([1, -1]);
        let on = |f: f64| {
            let th: Vec<f32> = b
                .iter()
                .map(|&x| (std::f64::consts::TAU * f * x) as f32)
                .collect();
            projection(&s, &Tensor::from_slice(&th).view([1, -1])).double_value(&[0])
        };
        assert!(on(0.5) > 0.6, "{}", on(0.5));
        assert!(on(1.0 / 3.0) < 0.2, "{}", on(1.0 / 3.0));
    }
}
