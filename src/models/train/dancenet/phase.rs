//! The step clock of a training window (`choreo train dancenet --step-clock`; served:
//! [`crate::models::step_clock`]).
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
use crate::models::step_clock::{self, beat_count};
use crate::models::train::step_lock::step_phase;
use crate::motion::dataset::NormStats;
use crate::motion::rotations::Layout;

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
        let phase = step_phase(&speed[i * (n - 1)..(i + 1) * (n - 1)], &count);
        out.slice_mut(ndarray::s![i * n..(i + 1) * n, ..])
            .assign(&step_clock::columns(&phase));
    }
    crate::models::to_tensor(&out).view([b as i64, n as i64, step_clock::WIDTH])
}
