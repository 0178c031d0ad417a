//! A window of music features or of poses played at another tempo.
//!
//! The feature frames are resampled in time, which is what a tempo change does to onset, chroma
//! and MFCC frames; the columns whose meaning a tempo change alters are corrected: one-hot marks
//! (beats) stay one-hot and move with their frame, per-frame rates (ΔMFCC, root and yaw velocity)
//! scale by `f`, the tempogram's lag axis shrinks by `f`, and the beat clock's tempo gains
//! `log2 f`. `f > 1` plays the window faster.
//!
//! Serving and training read it alike, so it sits beside the models, not under the trainers:
//! beat time ([`super::beat_time`]) hears a song at the network's tempo, the served seed clips
//! are played at the song's pace, and the trainers draw windows at other tempi
//! ([`super::train::augment`]).
use std::ops::Range;

use ndarray::{s, Array2, ArrayView2};

use crate::audio::clock;
use crate::motion::repr::{ROOT_VX, YAW_VEL};

/// What each music column means to a tempo change.
#[derive(Clone, Debug, Default)]
pub struct MusicLayout {
    /// Columns of 0/1 marks (beat, downbeat one-hots).
    pub one_hot: Vec<usize>,
    /// Columns holding a per-frame rate of change (scale with the tempo).
    pub rates: Vec<Range<usize>>,
    /// A tempogram block: column `k` is the onset autocorrelation at lag `k` frames.
    pub lags: Option<Range<usize>>,
    /// First column of a [`clock::beat_clock`] block.
    pub clock: Option<usize>,
}

impl MusicLayout {
    /// The DanceRevolution set, with or without its beat clock.
    pub fn dance_revolution(beat_clock: bool) -> Self {
        use crate::audio::features::dance_revolution_cols as c;
        Self {
            one_hot: vec![c::BEAT],
            rates: vec![c::DMFCC],
            lags: Some(c::TEMPOGRAM),
            clock: beat_clock.then_some(c::CLOCK.start),
        }
    }

    /// The DanceNet set ([`crate::audio::features::dancenet`]): onset | beat, downbeat | chroma.
    pub fn dancenet() -> Self {
        Self {
            one_hot: vec![
                crate::audio::features::DANCENET_BEAT,
                crate::audio::features::DANCENET_BEAT + 1,
            ],
            ..Default::default()
        }
    }

    /// The TSMT set ([`crate::audio::features::tsmt`]): MFCC | ΔMFCC | beat.
    pub fn tsmt() -> Self {
        Self {
            one_hot: vec![crate::audio::features::TSMT_BEAT],
            rates: vec![crate::audio::features::TSMT_DMFCC],
            ..Default::default()
        }
    }
}

/// Linear interpolation of `src`'s rows at fractional frame `t`.
fn lerp_row(src: ArrayView2<'_, f32>, t: f64, out: &mut [f32]) {
    let last = src.nrows() - 1;
    let i = (t.floor().max(0.0) as usize).min(last);
    let j = (i + 1).min(last);
    let w = (t - i as f64).clamp(0.0, 1.0) as f32;
    for (k, o) in out.iter_mut().enumerate() {
        *o = src[[i, k]] * (1.0 - w) + src[[j, k]] * w;
    }
}

/// `len` rows of `src` from frame `start` at tempo `f`: output row j is source time `start + j·f`.
fn resample(src: ArrayView2<'_, f32>, start: usize, len: usize, f: f64) -> Array2<f32> {
    let mut out = Array2::<f32>::zeros((len, src.ncols()));
    for (j, mut row) in out.outer_iter_mut().enumerate() {
        lerp_row(
            src,
            start as f64 + j as f64 * f,
            row.as_slice_mut().expect("standard layout"),
        );
    }
    out
}

/// Music window at tempo `f` (see the module doc for each column kind).
pub fn stretch_music(
    src: ArrayView2<'_, f32>,
    start: usize,
    len: usize,
    f: f64,
    layout: &MusicLayout,
) -> Array2<f32> {
    let mut out = resample(src, start, len, f);
    if (f - 1.0).abs() < 1e-12 {
        return out;
    }
    for &c in &layout.one_hot {
        out.column_mut(c).fill(0.0);
        let span = ((len - 1) as f64 * f).ceil() as usize + 1;
        for k in start..(start + span).min(src.nrows()) {
            if src[[k, c]] > 0.5 {
                let j = ((k - start) as f64 / f).round() as usize;
                if j < len {
                    out[[j, c]] = 1.0;
                }
            }
        }
    }
    for r in &layout.rates {
        out.slice_mut(s![.., r.clone()])
            .mapv_inplace(|v| v * f as f32);
    }
    if let Some(lags) = &layout.lags {
        // A figure that repeated every L frames now repeats every L/f: lag k reads old lag k·f.
        let n = lags.len();
        let block = out.slice(s![.., lags.clone()]).to_owned();
        for (j, row) in block.outer_iter().enumerate() {
            for k in 0..n {
                let t = k as f64 * f;
                let i = t.floor() as usize;
                let v = if i + 1 < n {
                    let w = (t - i as f64) as f32;
                    row[i] * (1.0 - w) + row[i + 1] * w
                } else {
                    0.0
                };
                out[[j, lags.start + k]] = v;
            }
        }
    }
    if let Some(c0) = layout.clock {
        use clock::cols;
        for mut row in out.outer_iter_mut() {
            for (a, b) in [
                (cols::BEAT_SIN, cols::BEAT_COS),
                (cols::BAR_SIN, cols::BAR_COS),
            ] {
                // Interpolating across a wrap shortens the vector; the phase is its angle.
                let (x, y) = (row[c0 + a], row[c0 + b]);
                let r = (x * x + y * y).sqrt();
                if r > 1e-6 {
                    row[c0 + a] = x / r;
                    row[c0 + b] = y / r;
                }
            }
            row[c0 + cols::TEMPO] += f.log2() as f32;
        }
    }
    out
}

/// `len` rows of `src` from `start` at tempo `f`, the per-frame rate columns `rates` scaled by
/// `f` (a velocity per frame covers `f` times the ground when the frames come `f` times faster).
fn stretch_rows(
    src: ArrayView2<'_, f32>,
    start: usize,
    len: usize,
    f: f64,
    rates: &[usize],
) -> Array2<f32> {
    let mut out = resample(src, start, len, f);
    if (f - 1.0).abs() > 1e-12 {
        for &c in rates {
            out.column_mut(c).mapv_inplace(|v| v * f as f32);
        }
    }
    out
}

/// Pose window (the `motion::repr` 73-column rows) at tempo `f`: local joints and root height
/// interpolated, per-frame root and yaw velocities scaled by `f`.
pub fn stretch_poses(src: ArrayView2<'_, f32>, start: usize, len: usize, f: f64) -> Array2<f32> {
    stretch_rows(src, start, len, f, &[ROOT_VX, ROOT_VX + 1, YAW_VEL])
}

/// Rotation-feature rows (`motion::rotations`, DanceNet's, de-normalised) at tempo `f`: every
/// column interpolated (6-D rotations between neighbouring frames stay near-orthonormal, and the
/// decoder orthonormalises them), the anchor's velocity and the yaw velocity (per frame) scaled
/// by `f`. Columns past the features (contacts) are interpolated too: a contact that starts
/// between two frames becomes a soft target there.
pub fn stretch_rotation_rows(
    src: ArrayView2<'_, f32>,
    start: usize,
    len: usize,
    f: f64,
) -> Array2<f32> {
    use crate::motion::rotations::{ROOT_VX, ROOT_VZ, YAW_VEL};
    stretch_rows(src, start, len, f, &[ROOT_VX, ROOT_VZ, YAW_VEL])
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array1;

    #[test]
    fn beats_stay_one_hot_and_move_with_their_frames() {
        let mut m = Array2::<f32>::zeros((100, 3));
        for k in (0..100).step_by(10) {
            m[[k, 0]] = 1.0;
        }
        m.column_mut(1).assign(&Array1::linspace(0.0, 99.0, 100));
        const RATE_COLUMNS: Range<usize> = 2..3;
        let layout = MusicLayout {
            one_hot: vec![0],
            rates: vec![RATE_COLUMNS],
            ..Default::default()
        };
        m.column_mut(2).fill(1.0);
        let out = stretch_music(m.view(), 0, 40, 2.0, &layout);
        let marks: Vec<usize> = (0..40).filter(|&j| out[[j, 0]] == 1.0).collect();
        assert_eq!(marks, vec![0, 5, 10, 15, 20, 25, 30, 35]);
        assert!(out.column(0).iter().all(|&v| v == 0.0 || v == 1.0));
        assert!((out[[7, 1]] - 14.0).abs() < 1e-5);
        assert!((out[[7, 2]] - 2.0).abs() < 1e-6);
    }

    /// A dance turning and travelling steadily, its joint angles ramping: played 1.25× faster,
    /// it covers 1.25× the ground and turns 1.25× as far per frame, and each frame shows the pose
    /// of source time 1.25 j; the contacts follow their frames.
    #[test]
    fn rotation_rows_play_faster_with_their_velocities_scaled() {
        use crate::motion::rotations::{CLEARANCE, ROOT_VX, ROOT_VZ, YAW_VEL};
        let n = 60;
        let mut rows = Array2::<f32>::zeros((n, 8));
        for t in 0..n {
            rows[[t, ROOT_VX]] = 0.02;
            rows[[t, ROOT_VZ]] = -0.01;
            rows[[t, CLEARANCE]] = 0.05;
            rows[[t, YAW_VEL]] = 0.03;
            rows[[t, 4]] = 0.01 * t as f32;
            rows[[t, 7]] = if (t / 10) % 2 == 0 { 1.0 } else { 0.0 };
        }
        let out = stretch_rotation_rows(rows.view(), 4, 40, 1.25);
        assert_eq!(out.dim(), (40, 8));
        for j in 0..40 {
            assert!((out[[j, ROOT_VX]] - 0.025).abs() < 1e-6);
            assert!((out[[j, ROOT_VZ]] + 0.0125).abs() < 1e-6);
            assert!((out[[j, YAW_VEL]] - 0.0375).abs() < 1e-6);
            assert!(
                (out[[j, CLEARANCE]] - 0.05).abs() < 1e-6,
                "heights do not scale"
            );
            let src = 4.0 + 1.25 * j as f32;
            assert!((out[[j, 4]] - 0.01 * src).abs() < 1e-5, "row {j}");
        }
        // Frame 8 is source time 14 (in a contact), frame 12 source 19 (none): contacts move
        // with their frames.
        assert_eq!((out[[8, 7]], out[[12, 7]]), (0.0, 0.0));
        assert_eq!(out[[13, 7]], 1.0);
        // At tempo 1 the rows are the source's.
        let same = stretch_rotation_rows(rows.view(), 4, 40, 1.0);
        assert_eq!(same, rows.slice(ndarray::s![4..44, ..]));
    }

    #[test]
    fn the_clock_keeps_unit_phases_and_gains_the_tempo() {
        let beats: Vec<usize> = (0..20).map(|i| 10 * i).collect();
        let c = clock::beat_clock(&beats, &[], 200, 25.0);
        let layout = MusicLayout {
            clock: Some(0),
            ..Default::default()
        };
        let out = stretch_music(c.view(), 0, 80, 1.25, &layout);
        for row in out.outer_iter() {
            assert!(((row[0] * row[0] + row[1] * row[1]) - 1.0).abs() < 1e-4);
            assert!((row[clock::cols::TEMPO] - (2.5f32.log2() + 1.25f32.log2())).abs() < 1e-5);
        }
    }

    #[test]
    fn a_tempogram_peak_moves_to_the_shorter_lag() {
        let mut m = Array2::<f32>::zeros((50, 40));
        m.column_mut(20).fill(1.0);
        let layout = MusicLayout {
            lags: Some(0..40),
            ..Default::default()
        };
        let out = stretch_music(m.view(), 0, 20, 1.25, &layout);
        assert!(
            (out[[3, 16]] - 1.0).abs() < 1e-5,
            "lag 20 at ×1.25 is lag 16"
        );
    }
}
