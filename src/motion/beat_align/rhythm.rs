//! The motion's rhythm: the ankles' summed speed, its step rate (the spectral peak the metric
//! reads) and its kinematic beats (step 1 of the stage, [`super`]).
use ndarray::{ArrayView3, Axis};
use realfft::RealFftPlanner;

use super::{BAND_WIDTH_LN, STEP_BAND_HZ};
use crate::motion::skeleton::ANKLES;

/// The ankles' summed speed (m/s) between consecutive frames: sample `i` lies at `(i + ½)/fps`.
pub(super) fn ankle_speed(p: ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    let frames = p.len_of(Axis(0));
    (1..frames)
        .map(|f| {
            ANKLES
                .iter()
                .map(|&j| {
                    (0..3)
                        .map(|c| (f64::from(p[[f, j, c]]) - f64::from(p[[f - 1, j, c]])).powi(2))
                        .sum::<f64>()
                        .sqrt()
                        * fps
                })
                .sum()
        })
        .collect()
}

/// The zero-padding of the spectrum whose peak the warp is planned on: 8× its length.
pub(super) const PLAN_ZERO_PAD: usize = 8;
/// The zero-padding of the spectrum whose peak says whether a dance steps on the beat: the
/// metric's ([`crate::metrics::musicality::ZERO_PAD`], a unit test checks), so the stage reads
/// the peak where the report will. At 8× a 4.4-s dance's peak fell on bins 2.3 % apart, and the
/// stage called a dance on the beat that the metric read 4.1 % off (dancenet on the trumpet loop
/// at 1.2×, seed 2; eval 2026-11-28).
pub(super) const CHECK_ZERO_PAD: usize = 16;

/// The step rate (Hz: the peak within [`STEP_BAND_HZ`] of the Hann-windowed spectrum
/// zero-padded to `zero_pad` × its length, as the metric finds it), with the speed centred on
/// its mean; `None` where the speed does not change.
pub(super) fn step_rate(speed: &[f64], fps: f64, zero_pad: usize) -> Option<(f64, Vec<f64>)> {
    let n = speed.len();
    let mean = speed.iter().sum::<f64>() / n.max(1) as f64;
    let centred: Vec<f64> = speed.iter().map(|v| v - mean).collect();
    if n < 2 || centred.iter().all(|v| v.abs() < 1e-9) {
        return None;
    }
    // Hann window (symmetric, numpy's), zero-padded to interpolate between bins.
    let padded = zero_pad * n;
    let mut input = vec![0.0; padded];
    for (i, v) in centred.iter().enumerate() {
        input[i] = v * (0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / (n - 1) as f64).cos());
    }
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(padded);
    let mut spectrum = fft.make_output_vec();
    fft.process(&mut input, &mut spectrum).ok()?;
    let bin_hz = fps / padded as f64;
    let step_hz = spectrum
        .iter()
        .enumerate()
        .map(|(k, c)| (k as f64 * bin_hz, c.norm()))
        .filter(|(f, _)| (STEP_BAND_HZ.0..=STEP_BAND_HZ.1).contains(f))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(f, _)| f)?;
    Some((step_hz, centred))
}

/// The step rate ([`step_rate`] at [`PLAN_ZERO_PAD`]) and the speed band-passed around it.
pub(super) fn rhythm(speed: &[f64], fps: f64) -> Option<(f64, Vec<f64>)> {
    let (step_hz, centred) = step_rate(speed, fps, PLAN_ZERO_PAD)?;
    let n = centred.len();
    let mut planner = RealFftPlanner::<f64>::new();
    // The band-pass: no window (the whole series keeps its weight), padded 2× so the circular
    // convolution's wrap falls in the padding.
    let padded = 2 * n;
    let mut input = vec![0.0; padded];
    input[..n].copy_from_slice(&centred);
    let fft = planner.plan_fft_forward(padded);
    let mut spectrum = fft.make_output_vec();
    fft.process(&mut input, &mut spectrum).ok()?;
    let bin_hz = fps / padded as f64;
    for (k, c) in spectrum.iter_mut().enumerate() {
        let f = k as f64 * bin_hz;
        let gain = if k == 0 {
            0.0
        } else {
            (-0.5 * ((f / step_hz).ln() / BAND_WIDTH_LN).powi(2)).exp()
        };
        *c *= gain / padded as f64;
    }
    let ifft = planner.plan_fft_inverse(padded);
    let mut out = ifft.make_output_vec();
    ifft.process(&mut spectrum, &mut out).ok()?;
    out.truncate(n);
    Some((step_hz, out))
}

/// Minima below zero of the band-passed speed (sub-frame, by a parabola through three samples),
/// at least half a cycle apart (of two closer, the deeper), as times in seconds.
pub(super) fn kinematic_beats(x: &[f64], fps: f64, step_hz: f64) -> Vec<f64> {
    let min_gap_s = 0.5 / step_hz;
    let mut out: Vec<(f64, f64)> = Vec::new();
    for i in 1..x.len().saturating_sub(1) {
        if !(x[i] < x[i - 1] && x[i] <= x[i + 1] && x[i] < 0.0) {
            continue;
        }
        let curvature = x[i - 1] - 2.0 * x[i] + x[i + 1];
        let offset = if curvature > 0.0 {
            (0.5 * (x[i - 1] - x[i + 1]) / curvature).clamp(-0.5, 0.5)
        } else {
            0.0
        };
        let t = (i as f64 + offset + 0.5) / fps;
        match out.last_mut() {
            Some(last) if t - last.0 < min_gap_s => {
                if x[i] < last.1 {
                    *last = (t, x[i]);
                }
            }
            _ => out.push((t, x[i])),
        }
    }
    out.into_iter().map(|(t, _)| t).collect()
}
