//! Warped histories (`choreo train tsmt --step-clock --history-warp R`): the
//! pose stream reads a history danced at another pace than the clock's, and is scored on the
//! frames after it, danced at the clock's.
//!
//! Taught by teacher forcing, TSMT continues the step rate of its history, which in every real
//! window is the music's: nothing in the data makes it read the beat or the clock, and its own
//! dances drift off the beat where its history does. Here the first `from` frames of a window are
//! the same dance replayed at `r` times its pace (0.75–1.33), ending on the very pose the window
//! continues from, so the history steps at the wrong rate and the continuation at the right one;
//! only the clock and the beats say which. The loss scores only the continuation.
use ndarray::{Array2, ArrayView2};

use crate::motion::repr;

/// Rows `[len, D]`: the last `len` rows of `poses` (a drawn window, `m ≥ len` rows at the clock's
/// pace), with its first `from` rows replaced by the dance at `r` times its pace ending at row
/// `from`: row k < from is `poses` at `J − (from − k)·r` (J the junction, `m − len + from`),
/// interpolated, with the per-frame root and yaw velocities scaled by `r`. Where the history
/// would reach before the drawn rows, it starts at their first.
pub(super) fn warped(poses: ArrayView2<f32>, len: usize, from: usize, r: f64) -> Array2<f32> {
    let m = poses.nrows();
    let first = m - len;
    let mut out = poses.slice(ndarray::s![first.., ..]).to_owned();
    let junction = (first + from) as f64;
    for k in 0..from.min(len) {
        let t = (junction - (from - k) as f64 * r).max(0.0);
        let (i, a) = (t.floor() as usize, (t - t.floor()) as f32);
        let j = (i + 1).min(m - 1);
        let mut row = out.row_mut(k);
        for c in 0..row.len() {
            row[c] = (1.0 - a) * poses[[i, c]] + a * poses[[j, c]];
        }
        for c in [repr::ROOT_VX, repr::ROOT_VZ, repr::YAW_VEL] {
            row[c] *= r as f32;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A joint coordinate moving 1 cm a frame and a root moving 2 cm a frame: replayed at 1.25
    /// times the pace, the history moves 1.25 cm a frame and ends on the junction's pose; the
    /// continuation is as drawn.
    #[test]
    fn the_history_is_the_dance_at_another_pace_up_to_the_junction() {
        let (m, len, from) = (60usize, 20usize, 8usize);
        let poses = Array2::from_shape_fn((m, repr::FEATURE_DIM), |(t, c)| match c {
            0 => 0.01 * t as f32,
            c if c == repr::ROOT_VX => 0.02,
            _ => 0.0,
        });
        let w = warped(poses.view(), len, from, 1.25);
        assert_eq!(w.dim(), (len, repr::FEATURE_DIM));
        for k in 1..from {
            assert!(((w[[k, 0]] - w[[k - 1, 0]]) - 0.0125).abs() < 1e-5);
            assert!((w[[k, repr::ROOT_VX]] - 0.025).abs() < 1e-6);
        }
        // The history's next step is the junction's pose: continuous.
        assert!(((w[[from, 0]] - w[[from - 1, 0]]) - 0.0125).abs() < 1e-5);
        for k in from..len {
            assert_eq!(w.row(k), poses.row(m - len + k));
        }
    }
}
