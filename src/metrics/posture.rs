//! Posture variety: does a dance move through figures over the song, or hold one?
//!
//! The musicality measures ([`super::musicality`]) are speeds and rates, and a dance whose arms
//! swing fast around one fixed shape for three minutes passes them all: dance-revolution's
//! previews hold one arm out and one raised from the first second to the last. This measures the
//! posture's own change over the song, and [`super::musicality::Musicality`] carries it.
use ndarray::ArrayView3;

use super::musicality::ARM_JOINTS;
use crate::motion::skeleton::{HIPS, SPINE};

/// Seconds over which [`posture_variety_m`] averages the posture.
pub const POSTURE_WINDOW_S: f64 = 4.0;
/// The fewest windows apart two averages are compared at ([`posture_variety_m`]): 8 s, longer
/// than a basic figure (a waltz box is 6 beats, 4.1 s at 87 BPM; a rumba basic 8 beats, about
/// 5.3 s), so a figure danced over and over reads as one posture.
const POSTURE_GAP_WINDOWS: usize = 2;

/// How far the arms' posture moves over the dance (m): the elbows and wrists relative to the
/// spine, turned into the hips' facing frame, averaged over each [`POSTURE_WINDOW_S`] window; the
/// median, over every pair of windows at least 8 s apart, of the two averages' mean joint distance.
/// Speed measures cannot see a dance whose arms swing fast around one fixed shape for the whole
/// song (dance-revolution's: 0.005–0.064 m on the shared and test songs, where the 43 real dances
/// read 0.059–0.216; `tools/posture_variety.py` computes the same in numpy). `None` when the dance
/// has fewer than three windows (12 s).
pub fn posture_variety_m(positions: ArrayView3<'_, f32>, fps: f64) -> Option<f64> {
    // The hips alone set the frame, not `repr::facing_yaw`'s hips and shoulders: the shoulders
    // turn with the arms, and a frame that followed them would take part of the arms' posture out.
    let [right_hip, left_hip] = HIPS;
    let w = (POSTURE_WINDOW_S * fps).round() as usize;
    let n = positions.shape()[0].checked_div(w).unwrap_or(0);
    if n <= POSTURE_GAP_WINDOWS || positions.shape()[1] <= left_hip {
        return None;
    }
    let mut means = vec![[[0.0f64; 3]; ARM_JOINTS.len()]; n];
    for (t, frame) in positions.outer_iter().take(n * w).enumerate() {
        let hx = (frame[[left_hip, 0]] - frame[[right_hip, 0]]) as f64;
        let hz = (frame[[left_hip, 2]] - frame[[right_hip, 2]]) as f64;
        let (sin, cos) = (-hz.atan2(hx)).sin_cos();
        for (k, &j) in ARM_JOINTS.iter().enumerate() {
            let d = |c: usize| (frame[[j, c]] - frame[[SPINE, c]]) as f64;
            let m = &mut means[t / w][k];
            m[0] += (d(0) * cos - d(2) * sin) / w as f64;
            m[1] += d(1) / w as f64;
            m[2] += (d(0) * sin + d(2) * cos) / w as f64;
        }
    }
    let mut d: Vec<f64> = Vec::new();
    for i in 0..n {
        for j in i + POSTURE_GAP_WINDOWS..n {
            let sum: f64 = (0..ARM_JOINTS.len())
                .map(|k| {
                    (0..3)
                        .map(|c| (means[i][k][c] - means[j][k][c]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .sum();
            d.push(sum / ARM_JOINTS.len() as f64);
        }
    }
    d.sort_by(f64::total_cmp);
    let mid = d.len() / 2;
    Some(if d.len() % 2 == 1 {
        d[mid]
    } else {
        (d[mid - 1] + d[mid]) / 2.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{s, Array3};

    #[test]
    fn one_figure_all_song_has_no_posture_variety_and_changing_figures_do() {
        // Hips along x (facing +z after the turn is removed), the spine at the origin; the right
        // wrist swings fast (0.1 m at 1 Hz) around one fixed shape, the body turning all the while.
        let fps = 25.0;
        let frames = 25 * 40;
        let dance = |shape: &dyn Fn(usize) -> f32| {
            let mut p = Array3::<f32>::zeros((frames, 23, 3));
            for f in 0..frames {
                let yaw = f as f64 * 0.01;
                let (s, c) = yaw.sin_cos();
                let mut put = |j: usize, x: f64, y: f64, z: f64| {
                    p[[f, j, 0]] = (x * c + z * s) as f32;
                    p[[f, j, 1]] = y as f32;
                    p[[f, j, 2]] = (-x * s + z * c) as f32;
                };
                put(HIPS[0], -0.1, -0.5, 0.0);
                put(HIPS[1], 0.1, -0.5, 0.0);
                let swing = 0.1 * (std::f64::consts::TAU * f as f64 / fps).sin();
                put(6, -0.5 + swing, shape(f) as f64, 0.0);
            }
            p
        };
        let held = posture_variety_m(dance(&|_| 0.0).view(), fps).expect("40 s");
        assert!(held < 0.005, "one figure: {held}");
        // The wrist raised 0.8 m for 10 s out of every 20: the averages 8 s or more apart differ
        // by 0.8 m on one of four joints (0.2 m) in about half the pairs.
        let changing = posture_variety_m(
            dance(&|f| if (f / 250) % 2 == 0 { 0.0 } else { 0.8 }).view(),
            fps,
        )
        .expect("40 s");
        assert!(changing > 0.05, "changing figures: {changing}");
        assert_eq!(
            posture_variety_m(dance(&|_| 0.0).slice(s![..250, .., ..]), fps),
            None
        );
    }
}
