//! The beat clock: where each frame lies in its beat and its bar, and how fast the
//! beats come, as feature columns a network can read directly.
//!
//! A beat one-hot column tells a network *that* a beat falls on this frame; to step on the next
//! one it must count frames since the last, which an LSTM or local attention learns poorly (the
//! served models stepped at their own fixed rate on every song). A phase that turns once per
//! beat, and once per bar, is the same information in the form a periodic motion needs: the pose
//! can be a smooth function of it. sin/cos keep the wrap from 1 to 0 continuous.
use ndarray::Array2;

/// Columns of [`beat_clock`].
pub mod cols {
    /// sin(2π · beat phase).
    pub const BEAT_SIN: usize = 0;
    /// cos(2π · beat phase).
    pub const BEAT_COS: usize = 1;
    /// sin(2π · bar phase).
    pub const BAR_SIN: usize = 2;
    /// cos(2π · bar phase).
    pub const BAR_COS: usize = 3;
    /// log2 of the local beat rate in beats per second (a tempo change of ×f adds log2 f).
    pub const TEMPO: usize = 4;
    /// Width of the clock.
    pub const DIM: usize = 5;
}

/// Beats per bar assumed where the downbeats are too few to say (the data's rumba and cha-cha are
/// in 4; a waltz's 3 shows in its downbeats).
const DEFAULT_BEATS_PER_BAR: usize = 4;

/// Phase in [0, 1) of frame `t` between sorted marks, extrapolating the first and last interval
/// beyond the ends; with the interval's length in frames. `None` with fewer than two marks.
fn phase(marks: &[usize], t: usize) -> Option<(f64, f64)> {
    if marks.len() < 2 {
        return None;
    }
    let k = marks.partition_point(|&m| m <= t);
    // The interval [a, b) holding t, or the nearest end interval outside the marks.
    let i = k.clamp(1, marks.len() - 1);
    let (a, b) = (marks[i - 1] as f64, marks[i] as f64);
    let len = (b - a).max(1.0);
    Some((((t as f64 - a) / len).rem_euclid(1.0), len))
}

/// `[len, 5]` clock on a frame grid at `frame_rate` from beat and downbeat frames (ascending):
/// [`cols`]. Without two beats the clock is all zeros (no phase to give). Without two downbeats
/// the bar is every [`DEFAULT_BEATS_PER_BAR`] beats from the first downbeat (or the first beat).
pub fn beat_clock(
    beats: &[usize],
    downbeats: &[usize],
    len: usize,
    frame_rate: f64,
) -> Array2<f32> {
    let mut out = Array2::<f32>::zeros((len, cols::DIM));
    if beats.len() < 2 {
        return out;
    }
    let bars: Vec<usize> = if downbeats.len() >= 2 {
        downbeats.to_vec()
    } else {
        let first = downbeats.first().copied().unwrap_or(beats[0]);
        let from = beats.partition_point(|&b| b < first);
        beats[from..]
            .iter()
            .step_by(DEFAULT_BEATS_PER_BAR)
            .copied()
            .collect()
    };
    let tau = std::f64::consts::TAU;
    for t in 0..len {
        let (p, beat_len) = phase(beats, t).expect("two beats");
        let mut row = out.row_mut(t);
        row[cols::BEAT_SIN] = (tau * p).sin() as f32;
        row[cols::BEAT_COS] = (tau * p).cos() as f32;
        if let Some((q, _)) = phase(&bars, t) {
            row[cols::BAR_SIN] = (tau * q).sin() as f32;
            row[cols::BAR_COS] = (tau * q).cos() as f32;
        }
        row[cols::TEMPO] = (frame_rate / beat_len).log2() as f32;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Beats every 10 frames at 25 fps (150 BPM), bars of 4 from frame 5: phase 0 on each beat,
    /// 1/2 halfway, the bar's phase a quarter per beat, tempo log2(2.5).
    #[test]
    fn phases_turn_once_per_beat_and_bar() {
        let beats: Vec<usize> = (0..10).map(|i| 5 + 10 * i).collect();
        let c = beat_clock(&beats, &[5, 45, 85], 100, 25.0);
        let close = |a: f32, b: f64| assert!((f64::from(a) - b).abs() < 1e-5, "{a} vs {b}");
        close(c[[15, cols::BEAT_SIN]], 0.0);
        close(c[[15, cols::BEAT_COS]], 1.0);
        close(c[[20, cols::BEAT_COS]], -1.0);
        close(c[[25, cols::BAR_SIN]], 0.0); // half a bar after 5
        close(c[[25, cols::BAR_COS]], -1.0);
        close(c[[15, cols::BAR_SIN]], 1.0); // a quarter
        close(c[[0, cols::BEAT_COS]], -1.0); // 5 frames before the first beat: extrapolated, phase 1/2
        close(c[[60, cols::TEMPO]], 2.5f64.log2());
        // Past the last beat the last interval continues.
        close(c[[99, cols::BEAT_SIN]], (std::f64::consts::TAU * 0.4).sin());
    }

    #[test]
    fn too_few_beats_give_zeros_and_missing_downbeats_count_four() {
        assert!(beat_clock(&[3], &[], 10, 25.0).iter().all(|&v| v == 0.0));
        let beats: Vec<usize> = (0..9).map(|i| 10 * i).collect();
        let c = beat_clock(&beats, &[], 80, 25.0);
        // Bars of 4 beats from beat 0: frame 20 is half a bar.
        assert!((c[[20, cols::BAR_COS]] + 1.0).abs() < 1e-5);
    }
}
