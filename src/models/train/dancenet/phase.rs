//! The step clock of a training window (`choreo train dancenet --step-clock`; served:
//! [`crate::models::dancenet::step_clock`]).
//!
//! Served, the clock is `2π · f · B(t)`: the song's beat count B at the style's fraction f. In a
//! training window the same grid is used (the window's own beat column, so a window drawn at
//! another tempo brings its own), but f and the phase's zero are the real dancer's in that
//! window: of the fractions real dancers step at (1/6 to 2/3 of the beat), the one the toes'
//! speed swings with most, shifted so φ = 0 where the speed peaks. The real dances lock their
//! step *rate* to the beat but not their phase (FACT's beat-align: real 0.175, mismatched 0.177),
//! so a clock with the served zero would contradict the frames it conditions and the decoder
//! would learn to ignore it; with the dancer's own zero it says when the next step comes, which
//! the history alone does not.
use ndarray::Array2;
use tch::Tensor;

use super::lock::{toe_speed, window_beats};
use crate::models::dancenet::step_clock::{self, beat_count};
use crate::motion::dataset::NormStats;
use crate::motion::rotations::Layout;

/// Fractions of the beat a training window's clock may turn at: those of the real dances
/// (1/2, 1/3, and 1/6 where the tracker counts a waltz in double time), and their neighbours.
const FRACTIONS: [f64; 5] = [1.0 / 6.0, 1.0 / 4.0, 1.0 / 3.0, 1.0 / 2.0, 2.0 / 3.0];

/// The clock `[b, n, WIDTH]` of real windows `real` `[b, n, D + contacts]` (normalised rows)
/// with their music `[b, n, ·]` (normalised; column 1 the beat one-hot). Windows with under two
/// beats get zeros.
pub(super) fn window_clock(
    real: &Tensor,
    music: &Tensor,
    pose_norm: &NormStats,
    music_norm: &NormStats,
    layout: &Layout,
) -> Tensor {
    let (b, n, _) = real.size3().expect("[b, n, D + contacts]");
    let d = pose_norm.dim() as i64;
    let std = Tensor::from_slice(&pose_norm.std).view([1, 1, -1]);
    let mean = Tensor::from_slice(&pose_norm.mean).view([1, 1, -1]);
    let speed = toe_speed(&(real.narrow(2, 0, d) * std + mean), layout); // [b, n − 1]
    let speed: Vec<f32> = Vec::try_from(speed.contiguous().view([-1])).expect("f32 speed");
    let (b, n) = (b as usize, n as usize);
    let mut out = Array2::<f32>::zeros((b * n, step_clock::WIDTH as usize));
    for (i, beats) in window_beats(music, music_norm).iter().enumerate() {
        let Some(count) = beat_count(beats) else {
            continue;
        };
        // Frame t's speed is the step from t − 1 to t; the first frame borrows the second's.
        let s: Vec<f64> = std::iter::once(speed[i * (n - 1)])
            .chain(speed[i * (n - 1)..(i + 1) * (n - 1)].iter().copied())
            .map(f64::from)
            .collect();
        let phase = dancer_phase(&s, &count);
        out.slice_mut(ndarray::s![i * n..(i + 1) * n, ..])
            .assign(&step_clock::columns(&phase));
    }
    crate::models::to_tensor(&out).view([b as i64, n as i64, step_clock::WIDTH])
}

/// A clock `[.., WIDTH]` a quarter of a turn later (φ + π/2): the decoder's loss on it, against
/// the loss on the true clock, says how much the decoder listens to the clock.
pub(super) fn quarter_turn(clock: &Tensor) -> Tensor {
    let c = |i: i64| clock.narrow(-1, i, 1);
    Tensor::cat(&[c(1), -c(0), -c(2), -c(3)], -1)
}

/// The phase of a window's steps: `2π f B(t) − θ` for the fraction f whose Hann-windowed
/// projection of `speed` (its mean removed) on `2π f B` is largest, θ that projection's angle.
fn dancer_phase(speed: &[f64], count: &[f64]) -> Vec<f64> {
    let n = speed.len();
    let w: Vec<f64> = (0..n)
        .map(|t| 0.5 - 0.5 * (std::f64::consts::TAU * t as f64 / n as f64).cos())
        .collect();
    let wsum: f64 = w.iter().sum();
    let mean = speed.iter().zip(&w).map(|(s, w)| s * w).sum::<f64>() / wsum.max(1e-12);
    let mut best = (f64::MIN, 0.5, 0.0);
    for f in FRACTIONS {
        let (mut re, mut im) = (0.0, 0.0);
        for t in 0..n {
            let a = std::f64::consts::TAU * f * count[t];
            let s = (speed[t] - mean) * w[t];
            re += s * a.cos();
            im += s * a.sin();
        }
        let mag = re.hypot(im);
        if mag > best.0 {
            best = (mag, f, im.atan2(re));
        }
    }
    let (_, f, theta) = best;
    count
        .iter()
        .map(|&b| std::f64::consts::TAU * f * b - theta)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A speed that peaks once every 3 beats, 1.1 rad after each third beat: the phase turns at
    /// 1/3 of the beat and is zero where the speed peaks.
    #[test]
    fn the_phase_is_the_dancers_own_rate_and_zero() {
        let n = 300;
        let beat_frames = 17.2;
        let count: Vec<f64> = (0..n).map(|t| t as f64 / beat_frames - 0.3).collect();
        let speed: Vec<f64> = count
            .iter()
            .map(|&b| 1.0 + (std::f64::consts::TAU * b / 3.0 - 1.1).cos())
            .collect();
        let phase = dancer_phase(&speed, &count);
        let turn = (phase[n - 1] - phase[0]) / (count[n - 1] - count[0]);
        assert!((turn - std::f64::consts::TAU / 3.0).abs() < 1e-9, "{turn}");
        let peak = (0..n)
            .max_by(|&a, &b| speed[a].total_cmp(&speed[b]))
            .unwrap();
        let at_peak = phase[peak].rem_euclid(std::f64::consts::TAU);
        let off = at_peak.min(std::f64::consts::TAU - at_peak);
        assert!(off < 0.05, "the phase at the speed's peak: {at_peak}");
        let k = crate::models::to_tensor(&step_clock::columns(&phase[..3]));
        let late: Vec<f64> = phase[..3]
            .iter()
            .map(|p| p + std::f64::consts::FRAC_PI_2)
            .collect();
        let want = crate::models::to_tensor(&step_clock::columns(&late));
        assert!((quarter_turn(&k) - want).abs().max().double_value(&[]) < 1e-5);
    }
}
