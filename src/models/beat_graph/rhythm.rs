//! The music match: what a beat of music sounds like, what a unit's body does, and a map from
//! the one to the other fitted on the train split's (beat, unit) pairs.
//!
//! ChoreoMaster learns a rhythm signature and a style embedding with networks on 30 hours of
//! paired data; on 46 minutes a network of that kind learns the songs. Here both sides are a
//! handful of named measures and the map is ridge regression, so it is fitted in a second and
//! its held-out ranking says plainly how much the music tells about the motion.
use ndarray::{s, Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use crate::audio::features::KEYPOSE_DIM;
use crate::motion::repr::{POSE_DIM, ROOT_VX, ROOT_VZ, YAW_VEL};
use crate::motion::NUM_JOINTS;

/// Width of [`music_descriptors`]: onset intensity, accent, phrase intensity, harmonic change,
/// tempo.
pub const MUSIC_DIM: usize = 5;
/// Width of [`motion_descriptors`]: body speed, wrist speed, travel, turning.
pub const MOTION_DIM: usize = 4;
/// The onset-strength column of the key-pose feature set the music is read from.
const ONSET: usize = KEYPOSE_DIM - 1;
const EPS: f64 = 1e-3;
/// The wrists, in [`crate::motion::skeleton::JOINT_NAMES`] order (right, left).
const WRISTS: [usize; 2] = [6, 15];

/// One row per beat interval `(t0, t1)` (seconds on the song's clock) of music features
/// `feats` (`audio::features::keypose`, row i = song time i / fps): how strong its onsets are
/// against the song's median, how much the beat itself stands out, how strong the music is over
/// the two beats either side, how far its harmony moved from the beat before, and its tempo.
pub fn music_descriptors(
    feats: ArrayView2<'_, f32>,
    fps: f64,
    slots: &[(f64, f64)],
) -> Array2<f32> {
    let n = feats.nrows();
    let onset: Vec<f64> = feats.column(ONSET).iter().map(|&v| f64::from(v)).collect();
    let mut sorted = onset.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted
        .get(sorted.len() / 2)
        .copied()
        .unwrap_or(0.0)
        .max(EPS);
    let frame = |t: f64| ((t * fps).round().max(0.0) as usize).min(n.saturating_sub(1));
    let mean_over = |a: usize, b: usize| -> f64 {
        let b = b.max(a + 1).min(n);
        let a = a.min(b.saturating_sub(1));
        onset[a..b].iter().sum::<f64>() / (b - a).max(1) as f64
    };
    let chroma_mean = |a: usize, b: usize| -> [f64; 12] {
        let b = b.max(a + 1).min(n);
        let a = a.min(b.saturating_sub(1));
        let mut c = [0.0; 12];
        for t in a..b {
            for (k, v) in c.iter_mut().enumerate() {
                *v += f64::from(feats[[t, k]]);
            }
        }
        c
    };
    let mut out = Array2::zeros((slots.len(), MUSIC_DIM));
    let mut previous: Option<[f64; 12]> = None;
    for (i, &(t0, t1)) in slots.iter().enumerate() {
        let (a, b) = (frame(t0), frame(t1));
        let here = mean_over(a, b);
        let accent = onset[a.saturating_sub(2)..(a + 3).min(n).max(a.saturating_sub(2) + 1)]
            .iter()
            .copied()
            .fold(0.0, f64::max);
        let p = t1 - t0;
        let phrase = mean_over(frame(t0 - 2.0 * p), frame(t1 + 2.0 * p));
        let chroma = chroma_mean(a, b);
        let change = previous.map_or(0.0, |q| 1.0 - cosine(&q, &chroma));
        previous = Some(chroma);
        let row = [
            ((here + EPS) / median).ln(),
            ((accent + EPS) / (here + EPS)).ln(),
            ((phrase + EPS) / median).ln(),
            change,
            (p.max(0.05) / 0.6).ln(),
        ];
        for (k, v) in row.into_iter().enumerate() {
            out[[i, k]] = v as f32;
        }
    }
    out
}

fn cosine(a: &[f64; 12], b: &[f64; 12]) -> f64 {
    let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    if na < 1e-9 || nb < 1e-9 {
        1.0
    } else {
        dot / (na * nb)
    }
}

/// What a stretch of motion features `rows` (`[T, FEATURE_DIM]`, [`crate::motion::repr`]) does:
/// the log of its joints' mean speed about the root, its wrists' (arms are what a ballroom
/// dancer's music moves most), its root's travel speed and its turning rate.
pub fn motion_descriptor(rows: ArrayView2<'_, f32>, fps: f64) -> [f32; MOTION_DIM] {
    let t = rows.nrows();
    if t < 2 {
        return [0.0; MOTION_DIM];
    }
    let (mut body, mut wrist, mut travel, mut turn) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for f in 1..t {
        let (r, q) = (rows.row(f), rows.row(f - 1));
        let speed = |j: usize| -> f64 {
            (0..3)
                .map(|c| f64::from(r[3 * j + c] - q[3 * j + c]).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        body += (0..NUM_JOINTS).map(speed).sum::<f64>() / NUM_JOINTS as f64;
        wrist += WRISTS.iter().map(|&j| speed(j)).sum::<f64>() / WRISTS.len() as f64;
        travel += f64::from(r[ROOT_VX]).hypot(f64::from(r[ROOT_VZ]));
        turn += f64::from(r[YAW_VEL]).abs();
    }
    let per_s = fps / (t - 1) as f64;
    const { assert!(POSE_DIM == 3 * NUM_JOINTS) };
    [
        (body * per_s + 0.05).ln() as f32,
        (wrist * per_s + 0.05).ln() as f32,
        (travel * per_s + 0.05).ln() as f32,
        (turn * per_s + 0.1).ln() as f32,
    ]
}

/// Ridge regression from standardised music descriptors to motion descriptors, and the
/// residual spread it leaves on the train pairs.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Match {
    pub music_mean: Vec<f64>,
    pub music_std: Vec<f64>,
    /// `[MUSIC_DIM + 1][MOTION_DIM]`, the last row the intercept.
    pub weights: Vec<Vec<f64>>,
    /// Per motion measure, the residual's standard deviation on the train pairs.
    pub residual_std: Vec<f64>,
}

impl Match {
    /// Fits the map on pairs `(music[i], motion[i])` with ridge penalty `lambda`.
    pub fn fit(music: &Array2<f32>, motion: &Array2<f32>, lambda: f64) -> Self {
        let n = music.nrows().max(1) as f64;
        let (dm, dy) = (MUSIC_DIM, MOTION_DIM);
        let mean: Vec<f64> = (0..dm)
            .map(|k| music.column(k).iter().map(|&v| f64::from(v)).sum::<f64>() / n)
            .collect();
        let std: Vec<f64> = (0..dm)
            .map(|k| {
                let var = music
                    .column(k)
                    .iter()
                    .map(|&v| (f64::from(v) - mean[k]).powi(2))
                    .sum::<f64>()
                    / n;
                var.sqrt().max(1e-6)
            })
            .collect();
        let x = |i: usize, k: usize| -> f64 {
            if k == dm {
                1.0
            } else {
                (f64::from(music[[i, k]]) - mean[k]) / std[k]
            }
        };
        let p = dm + 1;
        let mut a = vec![vec![0.0; p]; p];
        let mut b = vec![vec![0.0; dy]; p];
        for i in 0..music.nrows() {
            for (r, (a_row, b_row)) in a.iter_mut().zip(b.iter_mut()).enumerate() {
                let x_r = x(i, r);
                for (c, v) in a_row.iter_mut().enumerate() {
                    *v += x_r * x(i, c);
                }
                for (c, v) in b_row.iter_mut().enumerate() {
                    *v += x_r * f64::from(motion[[i, c]]);
                }
            }
        }
        for (r, row) in a.iter_mut().enumerate().take(dm) {
            row[r] += lambda * n;
        }
        let weights = solve(a, b);
        let mut fitted = Self {
            music_mean: mean,
            music_std: std,
            weights,
            residual_std: vec![1.0; dy],
        };
        let pred = fitted.predict(music);
        fitted.residual_std = (0..dy)
            .map(|c| {
                let ss: f64 = (0..music.nrows())
                    .map(|i| f64::from(pred[[i, c]] - motion[[i, c]]).powi(2))
                    .sum();
                (ss / n).sqrt().max(1e-3)
            })
            .collect();
        fitted
    }

    /// The motion descriptors the music predicts, one row per row of `music`.
    pub fn predict(&self, music: &Array2<f32>) -> Array2<f32> {
        let mut out = Array2::zeros((music.nrows(), MOTION_DIM));
        for i in 0..music.nrows() {
            for c in 0..MOTION_DIM {
                let mut v = self.weights[MUSIC_DIM][c];
                for k in 0..MUSIC_DIM {
                    let z = (f64::from(music[[i, k]]) - self.music_mean[k]) / self.music_std[k];
                    v += z * self.weights[k][c];
                }
                out[[i, c]] = v as f32;
            }
        }
        out
    }

    /// Mean squared distance, in residual standard deviations, between a predicted descriptor
    /// and a unit's: about 1 for the true unit of a train beat.
    pub fn cost(
        &self,
        predicted: ndarray::ArrayView1<'_, f32>,
        unit: ndarray::ArrayView1<'_, f32>,
    ) -> f64 {
        (0..MOTION_DIM)
            .map(|c| (f64::from(predicted[c] - unit[c]) / self.residual_std[c]).powi(2))
            .sum::<f64>()
            / MOTION_DIM as f64
    }

    /// Checks the shapes read from `model.json`.
    pub fn is_well_formed(&self) -> bool {
        self.music_mean.len() == MUSIC_DIM
            && self.music_std.len() == MUSIC_DIM
            && self.weights.len() == MUSIC_DIM + 1
            && self.weights.iter().all(|r| r.len() == MOTION_DIM)
            && self.residual_std.len() == MOTION_DIM
            && self.residual_std.iter().all(|s| *s > 0.0)
    }
}

/// Solves `a x = b` for a small symmetric positive-definite `a` (Gauss–Jordan with partial
/// pivoting; six unknowns do not warrant a linear-algebra crate).
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    let p = a.len();
    for col in 0..p {
        let pivot = (col..p)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap_or(col);
        a.swap(col, pivot);
        b.swap(col, pivot);
        let d = if a[col][col].abs() < 1e-12 {
            1e-12
        } else {
            a[col][col]
        };
        for v in a[col].iter_mut().chain(b[col].iter_mut()) {
            *v /= d;
        }
        // The pivot row is copied so that every other row can be borrowed mutably against it.
        let (a_col, b_col) = (a[col].clone(), b[col].clone());
        for (r, (a_row, b_row)) in a.iter_mut().zip(b.iter_mut()).enumerate() {
            let f = a_row[col];
            if r != col && f != 0.0 {
                for (v, w) in a_row.iter_mut().zip(&a_col) {
                    *v -= f * w;
                }
                for (v, w) in b_row.iter_mut().zip(&b_col) {
                    *v -= f * w;
                }
            }
        }
    }
    b
}

/// The motion descriptors of every unit `(dance rows, start, end)`.
pub fn motion_descriptors<'a>(
    units: impl Iterator<Item = (ArrayView2<'a, f32>, f64, f64)>,
    fps: f64,
) -> Array2<f32> {
    let rows: Vec<[f32; MOTION_DIM]> = units
        .map(|(x, a, b)| {
            let lo = (a.floor().max(0.0) as usize).min(x.nrows().saturating_sub(1));
            let hi = (b.ceil() as usize + 1).min(x.nrows()).max(lo + 1);
            motion_descriptor(x.slice(s![lo..hi, ..]), fps)
        })
        .collect();
    let mut out = Array2::zeros((rows.len(), MOTION_DIM));
    for (i, r) in rows.iter().enumerate() {
        for (k, v) in r.iter().enumerate() {
            out[[i, k]] = *v;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ridge_recovers_a_linear_map() {
        let n = 200;
        let music = Array2::from_shape_fn((n, MUSIC_DIM), |(i, k)| {
            ((i * 7 + k * 13) % 17) as f32 / 17.0 + k as f32
        });
        let motion = Array2::from_shape_fn((n, MOTION_DIM), |(i, c)| {
            music[[i, c]] * 2.0 - music[[i, 4]] + c as f32
        });
        let m = Match::fit(&music, &motion, 1e-6);
        let pred = m.predict(&music);
        let err = (&pred - &motion)
            .mapv(f32::abs)
            .fold(0.0f32, |a, &b| a.max(b));
        assert!(err < 1e-3, "max error {err}");
        assert!(m.is_well_formed());
    }

    #[test]
    fn a_louder_beat_reads_louder() {
        let fps = 25.0;
        let mut feats = Array2::<f32>::from_elem((250, KEYPOSE_DIM), 0.1);
        for t in 125..150 {
            feats[[t, ONSET]] = 1.0;
        }
        let d = music_descriptors(feats.view(), fps, &[(1.0, 1.5), (5.0, 6.0)]);
        assert!(d[[1, 0]] > d[[0, 0]] + 1.0);
        assert!(d[[1, 4]] > d[[0, 4]]);
    }
}
