//! Training windows at other tempi and mirrored.
//!
//! The data's tempi cluster by style (every waltz near 87 BPM, every cha-cha 115–127), so a network
//! never sees one figure danced at two tempi and learns a step rate per style, not per song. Each
//! window is therefore drawn at a tempo factor `f` in `[min, max]` (log-uniform) and played at it
//! ([`crate::models::stretch`]: music and dance faster together). Mirroring (left ↔ right)
//! doubles the dances; the music is unchanged by it.
use ndarray::{s, Array2};
use rand::Rng;

use crate::motion::repr::{POSE_DIM, ROOT_VX, YAW_VEL};
use crate::motion::skeleton::JOINT_NAMES;

/// How training windows are varied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Augment {
    /// Slowest tempo factor (e.g. 0.8).
    pub min_tempo: f64,
    /// Fastest tempo factor (e.g. 1.25).
    pub max_tempo: f64,
    /// Mirror half the windows left ↔ right.
    pub mirror: bool,
}

impl Augment {
    /// No augmentation: windows as danced.
    pub const NONE: Self = Self {
        min_tempo: 1.0,
        max_tempo: 1.0,
        mirror: false,
    };

    /// The tempo range asked for, refused unless `0 < min_tempo ≤ max_tempo` (a factor is drawn
    /// log-uniform between them).
    pub fn checked(
        min_tempo: f64,
        max_tempo: f64,
        mirror: bool,
    ) -> Result<Self, super::TrainError> {
        if !(min_tempo > 0.0 && min_tempo <= max_tempo) {
            return Err(super::TrainError::InvalidOption(format!(
                "--min-tempo {min_tempo} and --max-tempo {max_tempo}: want 0 < min ≤ max"
            )));
        }
        Ok(Self {
            min_tempo,
            max_tempo,
            mirror,
        })
    }

    /// Source frames a window of `len` output frames may span at the fastest tempo.
    pub fn source_len(&self, len: usize) -> usize {
        ((len.saturating_sub(1)) as f64 * self.max_tempo.max(1.0)).ceil() as usize + 1
    }

    /// A tempo factor and a mirror flag for one window.
    pub fn draw(&self, rng: &mut impl Rng) -> (f64, bool) {
        let (lo, hi) = (self.min_tempo.ln(), self.max_tempo.ln());
        let f = if hi > lo {
            rng.gen_range(lo..hi).exp()
        } else {
            1.0
        };
        (f, self.mirror && rng.gen_bool(0.5))
    }
}

/// The joint each joint becomes in the mirror image (`right_*` ↔ `left_*`, `head_right` ↔ `head_left`).
pub fn mirror_joints() -> Vec<usize> {
    let swap = |n: &str| -> String {
        if let Some(r) = n.strip_prefix("right_") {
            format!("left_{r}")
        } else if let Some(r) = n.strip_prefix("left_") {
            format!("right_{r}")
        } else if let Some(r) = n.strip_suffix("_right") {
            format!("{r}_left")
        } else if let Some(r) = n.strip_suffix("_left") {
            format!("{r}_right")
        } else {
            n.to_string()
        }
    };
    JOINT_NAMES
        .iter()
        .map(|n| {
            JOINT_NAMES
                .iter()
                .position(|m| *m == swap(n))
                .unwrap_or_else(|| panic!("joint {n} has no mirror"))
        })
        .collect()
}

/// Mirrors pose rows in place, left ↔ right: in the facing frame x is the lateral axis, so each
/// joint takes its partner's coordinates with x negated, the root's lateral velocity and the
/// yaw velocity change sign.
pub fn mirror_poses(rows: &mut Array2<f32>, partner: &[usize]) {
    for mut row in rows.outer_iter_mut() {
        let old: Vec<f32> = row.slice(s![..POSE_DIM]).to_vec();
        for (j, &p) in partner.iter().enumerate() {
            row[3 * j] = -old[3 * p];
            row[3 * j + 1] = old[3 * p + 1];
            row[3 * j + 2] = old[3 * p + 2];
        }
        row[ROOT_VX] = -row[ROOT_VX];
        row[YAW_VEL] = -row[YAW_VEL];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::repr::FEATURE_DIM;

    #[test]
    fn mirroring_twice_is_the_identity_and_swaps_the_wrists() {
        let partner = mirror_joints();
        let rw = JOINT_NAMES
            .iter()
            .position(|n| *n == "right_wrist")
            .unwrap();
        let lw = JOINT_NAMES.iter().position(|n| *n == "left_wrist").unwrap();
        assert_eq!(partner[rw], lw);
        let orig = Array2::from_shape_fn((3, FEATURE_DIM), |(i, k)| (i * 100 + k) as f32 * 0.01);
        let mut m = orig.clone();
        mirror_poses(&mut m, &partner);
        assert_eq!(m[[1, 3 * lw]], -orig[[1, 3 * rw]]);
        assert_eq!(m[[1, 3 * lw + 1]], orig[[1, 3 * rw + 1]]);
        mirror_poses(&mut m, &partner);
        assert_eq!(m, orig);
    }
}
