//! How the AIST++ (SMPL) joints the features name map onto our 23-joint skeleton
//! ([`crate::motion::skeleton`]).
//!
//! Our skeleton has no pelvis, neck, belly or chest joint (the body centre is not among the 23),
//! so three virtual points are appended after the 23 joints before features are computed:
//! - `pelvis` (index 23): the midpoint of the hips (7, 16);
//! - `neck` (index 24): the midpoint of the shoulders (3, 12);
//! - `head` (index 25): the midpoint of the two head markers (0, 1).
//!
//! | SMPL (`manual.py`) | ours                                  |
//! |--------------------|---------------------------------------|
//! | root, belly        | pelvis (virtual 23)                   |
//! | chest              | spine (2), 15 cm above the hips       |
//! | neck               | neck (virtual 24)                     |
//! | r/l shoulder       | right_shoulder (3) / left_shoulder (12) |
//! | r/l elbow          | right_elbow (4) / left_elbow (13)     |
//! | r/l wrist          | right_wrist (6) / left_wrist (15)     |
//! | r/l hip            | right_hip (7) / left_hip (16)         |
//! | r/l knee           | right_knee (8) / left_knee (17)       |
//! | r/l ankle          | right_ankle (9) / left_ankle (18)     |
//! | r/l toes           | right_toe (11) / left_toe (20)        |
//!
//! Belly and root share the pelvis, so `belly → chest` (pelvis → spine) and `chest → neck`
//! (spine → neck) both point up the torso, as in SMPL.
//!
//! Kinetic features use [`KINETIC_JOINTS`]: the 21 anatomical joints and the pelvis (the body's
//! trajectory, as SMPL's root carries it), 22 joints × 3 = 66 features. The hand-direction points
//! (21, 22) are left out: they are markers, not joints.
use crate::motion::skeleton as sk;
use ndarray::{s, Array3, ArrayView3};

use super::features::GeometricJoints;

/// Index of the virtual pelvis point in the augmented array.
pub const PELVIS: usize = crate::motion::NUM_JOINTS;
/// Index of the virtual neck point.
pub const NECK: usize = crate::motion::NUM_JOINTS + 1;
/// Index of the virtual head point.
pub const HEAD: usize = crate::motion::NUM_JOINTS + 2;
/// Joints in the augmented array.
pub const AUGMENTED_JOINTS: usize = crate::motion::NUM_JOINTS + 3;

/// Joints (augmented indices) whose kinetic features make up FID_k: 21 anatomical + pelvis.
pub const KINETIC_JOINTS: [usize; 22] = [
    0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, PELVIS,
];

/// The SMPL joints of the geometric features, as augmented indices.
pub const GEOMETRIC_JOINTS: GeometricJoints = GeometricJoints {
    root: PELVIS,
    belly: PELVIS,
    chest: sk::SPINE,
    neck: NECK,
    lhip: sk::HIPS[1],
    rhip: sk::HIPS[0],
    lknee: 17,
    rknee: 8,
    lankle: sk::ANKLES[1],
    rankle: sk::ANKLES[0],
    ltoes: sk::TOES[1],
    rtoes: sk::TOES[0],
    lshoulder: sk::SHOULDERS[1],
    rshoulder: sk::SHOULDERS[0],
    lelbow: 13,
    relbow: 4,
    lwrist: sk::WRISTS[1],
    rwrist: sk::WRISTS[0],
};

/// Appends the virtual pelvis, neck and head points to `[T, 23, 3]` positions.
pub fn augment(positions: ArrayView3<'_, f32>) -> Array3<f32> {
    let (t, j, _) = positions.dim();
    let mut out = Array3::<f32>::zeros((t, j + 3, 3));
    out.slice_mut(s![.., ..j, ..]).assign(&positions);
    let mid = |a: usize, b: usize, f: usize, c: usize| {
        0.5 * (positions[[f, a, c]] + positions[[f, b, c]])
    };
    for f in 0..t {
        for c in 0..3 {
            out[[f, PELVIS, c]] = mid(sk::HIPS[0], sk::HIPS[1], f, c);
            out[[f, NECK, c]] = mid(sk::SHOULDERS[0], sk::SHOULDERS[1], f, c);
            out[[f, HEAD, c]] = mid(sk::HEAD[0], sk::HEAD[1], f, c);
        }
    }
    out
}

/// The kinetic joints of an augmented array, `[T, 22, 3]`.
pub fn kinetic_view(augmented: &Array3<f32>) -> Array3<f32> {
    augmented.select(ndarray::Axis(1), &KINETIC_JOINTS)
}

/// Joint-angle triples `(parent, joint, child)` for physical plausibility: every anatomical joint
/// with an anatomical parent and child; the angle is between bones `parent → joint` and
/// `joint → child`.
pub fn angle_triples() -> Vec<(usize, usize, usize)> {
    let anatomical = |j: usize| sk::ANATOMICAL.contains(&j);
    let mut out = Vec::new();
    for j in 0..crate::motion::NUM_JOINTS {
        let Some(p) = sk::PARENTS[j] else { continue };
        if !anatomical(j) || !anatomical(p) {
            continue;
        }
        for c in sk::children(Some(j)) {
            if anatomical(c) {
                out.push((p, j, c));
            }
        }
    }
    out
}
