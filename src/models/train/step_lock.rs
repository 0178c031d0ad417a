//! What the step clock's trainers share (`choreo train dancenet --step-clock`,
//! `choreo train tsmt --step-clock`): the projections of a speed on a phase that score how a
//! danced window steps with the clock, and the real dancer's own phase in a training window that
//! the clock is set to. Each model measures its toes' speed in its own features (dancenet:
//! `train::dancenet::lock`; tsmt: `train::tsmt::lock`).
use tch::{Kind, Tensor};

use crate::models::step_clock::FRACTIONS;

/// `speed` `[b, n]` less its Hann-weighted mean, times the Hann window, and the sum of its
/// magnitude per window `[b]`: what both projections divide by.
fn windowed(speed: &Tensor) -> (Tensor, Tensor) {
    let n = speed.size()[1];
    let w = Tensor::hann_window_periodic(n, false, (Kind::Float, speed.device())).unsqueeze(0);
    let mean = (speed * &w).sum_dim_intlist(1, true, Kind::Float) / w.sum(Kind::Float);
    let s = (speed - mean) * &w;
    let norm = s.abs().sum_dim_intlist(1, false, Kind::Float) + 1e-8;
    (s, norm)
}

/// The normalised projection of `speed` `[b, n]` on phases `theta` `[b, n]` (radians), per window
/// `[b]`: 1 for a speed that swings with the phase, near 0 otherwise.
pub fn projection(speed: &Tensor, theta: &Tensor) -> Tensor {
    let (s, norm) = windowed(speed);
    let re = (&s * theta.cos()).sum_dim_intlist(1, false, Kind::Float);
    let im = (&s * theta.sin()).sum_dim_intlist(1, false, Kind::Float);
    (re.square() + im.square() + 1e-12).sqrt() / norm
}

/// The signed projection of `speed` `[b, n]` on phases `phase` `[b, n]`: how much of it peaks
/// where the phase is zero (1 for a speed that swings with the phase and peaks at its zero, −1
/// for one that peaks half a turn off). The step clock's term ([`term`] with a clock): a score
/// blind to the phase rewards stepping at the clock's rate at whatever phase the free run
/// happens to dance, so its pull on the clock's weights points every way and cancels over a
/// batch; this one points them all one way.
pub fn signed_projection(speed: &Tensor, phase: &Tensor) -> Tensor {
    let (s, norm) = windowed(speed);
    (&s * phase.cos()).sum_dim_intlist(1, false, Kind::Float) / norm
}

/// A clock `[.., WIDTH]` a quarter of a turn later (φ + π/2): the decoder's loss on it, against
/// the loss on the true clock, says how much the decoder listens to the clock.
pub fn quarter_turn(clock: &Tensor) -> Tensor {
    let c = |i: i64| clock.narrow(-1, i, 1);
    Tensor::cat(&[c(1), -c(0), -c(2), -c(3)], -1)
}

/// The dancer's phase ([`dancer_phase`]) of a window's frames from its toes' `steps` (one fewer
/// than the frames: step t − 1 → t). Frame t's speed is the step from t − 1 to t; the first frame
/// borrows the second's.
pub fn step_phase(steps: &[f32], count: &[f64]) -> Vec<f64> {
    let speed: Vec<f64> = steps
        .first()
        .into_iter()
        .chain(steps)
        .map(|&v| f64::from(v))
        .collect();
    dancer_phase(&speed, count)
}

/// The phase of a window's steps: `2π f B(t) − θ` for the fraction f whose Hann-windowed
/// projection of `speed` (its mean removed) on `2π f B` is largest, θ that projection's angle.
pub fn dancer_phase(speed: &[f64], count: &[f64]) -> Vec<f64> {
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
    use crate::models::step_clock;

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

    /// The clock's score is signed: a speed peaking where the phase is zero scores near π/4
    /// (the most a mean-free cosine can), the same speed half a step late as much below zero.
    #[test]
    fn the_signed_projection_hears_the_phase_too() {
        let n = 300;
        let phase: Vec<f32> = (0..n).map(|t| t as f32 * 0.12).collect();
        let at = |shift: f32| {
            let s: Vec<f32> = phase.iter().map(|p| 1.0 + (p + shift).cos()).collect();
            signed_projection(
                &Tensor::from_slice(&s).view([1, -1]),
                &Tensor::from_slice(&phase).view([1, -1]),
            )
            .double_value(&[0])
        };
        assert!(
            (at(0.0) - std::f64::consts::FRAC_PI_4).abs() < 0.05,
            "{}",
            at(0.0)
        );
        assert!((at(std::f32::consts::PI) + std::f64::consts::FRAC_PI_4).abs() < 0.05);
        assert!(at(std::f32::consts::FRAC_PI_2).abs() < 0.1);
    }
}
