//! The 23-joint skeleton of the dance-with-melody data, identified from the data itself.
//!
//! # How the joints were identified
//! The dataset ships joint positions without names. Measured over all 43 dances
//! (`tools/motion_skeleton_stats.py` prints these figures):
//! - **Chains.** Distances between joints that stay nearly constant over frames form five
//!   chains: head (0, 1), spine (2), two arms (3–6, 12–15) and two legs (7–11, 16–20). The
//!   dataset's own drawing order (3-4-5-6, 12-13-14-15, 7-8-9, 16-17-18) agrees.
//! - **Up and down.** Mean heights relative to the body centre: head ≈ +0.56 m, shoulders
//!   ≈ +0.42 m, spine ≈ +0.13 m, hips ≈ −0.02 m, knees ≈ −0.47 m, ankles ≈ −0.75 m, heel
//!   ≈ −0.82 m, toe ≈ −0.87 m.
//! - **Heel and toe.** Of the two foot points, the one 12 cm from the ankle (10, 19) sits behind
//!   the ankle and the one 17–18 cm away (11, 20) in front of it (in 92–96 % of all frames, the
//!   rest being pointed feet): heel and toe.
//! - **Left and right.** With the toes giving "forward" and y up, joints 3–11 lie on the side
//!   `up × forward` points away from (the body's right, right-handed axes), 12–20 on its left.
//!   Indices i and i + 9 mirror each other for i in 3..=11. The closed ballroom hold agrees:
//!   the raised arm held out to the side (12–15) is the leader's left.
//! - **Head.** Joints 0 and 1 are 10.6 cm apart at the same height; 0 is nearer the right
//!   shoulder and hip, 1 the left: two head markers, right and left.
//!
//! # Hand-direction points (21, 22)
//! Joints 21 and 22 are not anatomical joints. 22 sits 4.7 ± 0.8 cm beyond the right wrist (6);
//! 21 sits on the left forearm, 12.0 ± 0.7 cm from the left elbow (13), the steadiest distance
//! in the whole skeleton. They mirror each other by index, not by placement. We keep them as
//! leaf joints (22 under the right wrist, 21 under the left elbow, their steadiest neighbours):
//! they give the hand and forearm their twist in the rotation fit and are exported like any
//! joint, but [`ANATOMICAL`] leaves them out for metrics that compare anatomy.
//!
//! # Hierarchy
//! The root is the body centre (`center.npy`), which is not one of the 23 joints: exports add
//! it as joint 0 of the rigid skeleton, plus two branch joints (pelvis, neck) that give the hips
//! and the head their own rotations (see [`crate::motion::rig`]). In the 23-joint
//! index space, [`PARENTS`] gives `None` for the joints hanging from the body centre.
//! ```text
//! body_centre ─ spine(2) ┬ head_left(1) ─ head_right(0)
//!                        ├ right_shoulder(3) ─ right_elbow(4) ─ right_forearm(5) ─ right_wrist(6) ─ right_hand_dir(22)
//!                        ├ left_shoulder(12) ─ left_elbow(13) ┬ left_forearm(14) ─ left_wrist(15)
//!                        │                                    └ left_hand_dir(21)
//!                        ├ right_hip(7) ─ right_knee(8) ─ right_ankle(9) ┬ right_heel(10)
//!                        │                                               └ right_toe(11)
//!                        └ left_hip(16) ─ left_knee(17) ─ left_ankle(18) ┬ left_heel(19)
//!                                                                        └ left_toe(20)
//! ```
//! Bone lengths are nearly, not exactly, constant: marker-based capture varies 1–3 cm
//! (standard deviation over frames) even for the steadiest neighbour of each joint.
use super::NUM_JOINTS;

/// Name of each joint, in the dataset's order.
pub const JOINT_NAMES: [&str; NUM_JOINTS] = [
    "head_right",
    "head_left",
    "spine",
    "right_shoulder",
    "right_elbow",
    "right_forearm",
    "right_wrist",
    "right_hip",
    "right_knee",
    "right_ankle",
    "right_heel",
    "right_toe",
    "left_shoulder",
    "left_elbow",
    "left_forearm",
    "left_wrist",
    "left_hip",
    "left_knee",
    "left_ankle",
    "left_heel",
    "left_toe",
    "left_hand_dir",
    "right_hand_dir",
];

/// Parent of each joint; `None` means the body centre (the root, not one of the 23).
pub const PARENTS: [Option<usize>; NUM_JOINTS] = [
    Some(1),  // head_right ← head_left
    Some(2),  // head_left ← spine
    None,     // spine ← body centre
    Some(2),  // right_shoulder ← spine
    Some(3),  // right_elbow
    Some(4),  // right_forearm
    Some(5),  // right_wrist
    Some(2),  // right_hip ← spine (18.6 ± 2.0 cm; steadier than from the body centre)
    Some(7),  // right_knee
    Some(8),  // right_ankle
    Some(9),  // right_heel
    Some(9),  // right_toe
    Some(2),  // left_shoulder ← spine
    Some(12), // left_elbow
    Some(13), // left_forearm
    Some(14), // left_wrist
    Some(2),  // left_hip ← spine
    Some(16), // left_knee
    Some(17), // left_ankle
    Some(18), // left_heel
    Some(18), // left_toe
    Some(13), // left_hand_dir ← left_elbow
    Some(6),  // right_hand_dir ← right_wrist
];

/// Mirror image of each joint (left ↔ right); the spine mirrors itself.
pub const MIRROR: [usize; NUM_JOINTS] = [
    1, 0, 2, 12, 13, 14, 15, 16, 17, 18, 19, 20, 3, 4, 5, 6, 7, 8, 9, 10, 11, 22, 21,
];

/// The spine (nearest joint to the body centre).
pub const SPINE: usize = 2;
/// Head markers (right, left); the head point is their midpoint.
pub const HEAD: [usize; 2] = [0, 1];
/// Shoulders (right, left).
pub const SHOULDERS: [usize; 2] = [3, 12];
/// Hips (right, left).
pub const HIPS: [usize; 2] = [7, 16];
/// Ankles (right, left).
pub const ANKLES: [usize; 2] = [9, 18];
/// Heels (right, left).
pub const HEELS: [usize; 2] = [10, 19];
/// Toes (right, left).
pub const TOES: [usize; 2] = [11, 20];
/// Elbows (right, left).
pub const ELBOWS: [usize; 2] = [4, 13];
/// Forearm markers (right, left), between elbow and wrist: not anatomical joints' centres.
pub const FOREARMS: [usize; 2] = [5, 14];
/// Wrists, the hand end of each arm (right, left).
pub const WRISTS: [usize; 2] = [6, 15];
/// Hand-direction points (right, left): not anatomical joints.
pub const HAND_DIRS: [usize; 2] = [22, 21];
/// Foot points used for contact labels: right heel, right toe, left heel, left toe.
pub const FOOT_POINTS: [usize; 4] = [10, 11, 19, 20];
/// End effectors for metrics: right wrist, left wrist, right toe, left toe, head markers.
pub const END_EFFECTORS: [usize; 6] = [6, 15, 11, 20, 0, 1];
/// The 21 anatomical joints (everything but the hand-direction points).
pub const ANATOMICAL: [usize; 21] = [
    0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20,
];

/// Weights whose weighted mean of the 23 joints reproduces the body centre.
///
/// The dataset's body centre (`center.npy`) is not rigidly attached to any joint (its distance
/// to the spine varies by 3 cm), but it is almost exactly a fixed weighted centroid of the
/// markers: least squares over all 69,262 frames (`tools/motion_skeleton_stats.py`) leaves a
/// residual of 2.3 mm median, 5.0 mm p95, 11 mm max. Motions without a known centre (generated
/// ones) take their root from these weights via [`body_centre`].
pub const CENTRE_WEIGHTS: [f32; NUM_JOINTS] = [
    0.0619, 0.0490, 0.0862, 0.0416, 0.0493, 0.0239, 0.0250, 0.0587, 0.0488, 0.0568, 0.0375, 0.0192,
    0.0518, 0.0241, 0.0172, 0.0384, 0.0576, 0.0429, 0.0834, 0.0206, 0.0139, 0.0552, 0.0370,
];

/// The body centre (root) of one frame of `[J, 3]` positions, from [`CENTRE_WEIGHTS`].
pub fn body_centre(frame: ndarray::ArrayView2<'_, f32>) -> [f32; 3] {
    let total: f32 = CENTRE_WEIGHTS.iter().sum();
    let mut c = [0.0f32; 3];
    for (j, w) in CENTRE_WEIGHTS.iter().enumerate() {
        for (k, ck) in c.iter_mut().enumerate() {
            *ck += w * frame[[j, k]];
        }
    }
    c.map(|v| v / total)
}

/// Per-frame mean joint speed in m/s over frame steps: `d[t] = fps · mean_j |p[t+1, j] − p[t, j]|`.
pub fn mean_speed(positions: ndarray::ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    let (t, j, _) = positions.dim();
    (1..t)
        .map(|f| {
            let s: f64 = (0..j)
                .map(|k| {
                    (0..3)
                        .map(|c| {
                            (f64::from(positions[[f, k, c]]) - f64::from(positions[[f - 1, k, c]]))
                                .powi(2)
                        })
                        .sum::<f64>()
                        .sqrt()
                })
                .sum();
            fps * s / j.max(1) as f64
        })
        .collect()
}

/// The mean over frames of [`mean_speed`] (m/s; 0 under two frames): how fast a dance moves,
/// as the served checks read it.
pub fn average_speed(positions: ndarray::ArrayView3<'_, f32>, fps: f64) -> f64 {
    let speeds = mean_speed(positions, fps);
    speeds.iter().sum::<f64>() / speeds.len().max(1) as f64
}

/// Per-frame mean joint acceleration `mean_j |p[t+1] − 2p[t] + p[t−1]|·fps²` for `t = 1..T−1`
/// (m/s²); index `i` is frame `i + 1`: the pops the verdict grades
/// ([`crate::metrics::physical`]) and the bursts a served stage calms ([`super::bursts`]).
pub fn joint_acceleration(positions: ndarray::ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    let (t, j, _) = positions.dim();
    if t < 3 || j == 0 {
        return Vec::new();
    }
    (1..t - 1)
        .map(|f| {
            let s: f64 = (0..j)
                .map(|k| {
                    (0..3)
                        .map(|c| {
                            let a = f64::from(positions[[f + 1, k, c]])
                                - 2.0 * f64::from(positions[[f, k, c]])
                                + f64::from(positions[[f - 1, k, c]]);
                            a * a
                        })
                        .sum::<f64>()
                        .sqrt()
                })
                .sum();
            s / j as f64 * fps * fps
        })
        .collect()
}

/// The body centre of every frame of `[T, J, 3]` positions, `[T, 3]`.
pub fn body_centre_track(positions: ndarray::ArrayView3<'_, f32>) -> ndarray::Array2<f32> {
    let mut out = ndarray::Array2::zeros((positions.shape()[0], 3));
    for (t, frame) in positions.outer_iter().enumerate() {
        let c = body_centre(frame);
        for k in 0..3 {
            out[[t, k]] = c[k];
        }
    }
    out
}

/// Index of a joint by name.
pub fn joint_index(name: &str) -> Option<usize> {
    JOINT_NAMES.iter().position(|n| *n == name)
}

/// Children of joint `j` (or of the body centre for `None`), in index order.
pub fn children(j: Option<usize>) -> Vec<usize> {
    (0..NUM_JOINTS).filter(|&c| PARENTS[c] == j).collect()
}

/// Joints in an order where every parent comes before its children (depth first from the root).
pub fn topological_order() -> Vec<usize> {
    fn visit(j: Option<usize>, out: &mut Vec<usize>) {
        for c in children(j) {
            out.push(c);
            visit(Some(c), out);
        }
    }
    let mut out = Vec::with_capacity(NUM_JOINTS);
    visit(None, &mut out);
    out
}

/// Bones as `(parent, child)` pairs between two of the 23 joints (the body-centre bone excluded).
pub fn bones() -> Vec<(usize, usize)> {
    (0..NUM_JOINTS)
        .filter_map(|c| PARENTS[c].map(|p| (p, c)))
        .collect()
}

/// A person standing upright facing +z with the feet on y = 0, for tests: (x, y, z) of the right
/// side and centre, the left side mirrored in x; heights from this module's measured means.
#[cfg(test)]
pub(crate) fn standing_pose() -> [[f32; 3]; NUM_JOINTS] {
    let right: [(usize, [f32; 3]); 10] = [
        (0, [-0.05, 1.65, 0.0]),
        (3, [-0.2, 1.45, 0.0]),
        (4, [-0.25, 1.15, 0.0]),
        (5, [-0.27, 1.0, 0.0]),
        (6, [-0.28, 0.85, 0.0]),
        (7, [-0.1, 0.95, 0.0]),
        (8, [-0.1, 0.5, 0.0]),
        (9, [-0.1, 0.1, 0.0]),
        (10, [-0.1, 0.03, -0.05]),
        (11, [-0.1, 0.02, 0.15]),
    ];
    let mut pose = [[0.0f32; 3]; NUM_JOINTS];
    for (j, p) in right {
        pose[j] = p;
        let m = MIRROR[j];
        pose[m] = [-p[0], p[1], p[2]];
    }
    pose[2] = [0.0, 1.2, 0.0];
    pose[21] = [0.26, 1.05, 0.0];
    pose[22] = [-0.29, 0.8, 0.0];
    pose
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirror_is_an_involution_and_pairs_right_with_left() {
        for j in 0..NUM_JOINTS {
            assert_eq!(MIRROR[MIRROR[j]], j);
            let (a, b) = (JOINT_NAMES[j], JOINT_NAMES[MIRROR[j]]);
            if j == SPINE {
                assert_eq!(a, b);
            } else if a.starts_with("right_") {
                assert_eq!(a.replacen("right_", "left_", 1), b);
            } else if a.starts_with("left_") {
                assert_eq!(a.replacen("left_", "right_", 1), b);
            } else {
                assert_eq!(a.replace("_right", "_left"), b.replace("_right", "_left"));
            }
        }
    }

    #[test]
    fn hierarchy_is_a_tree_covering_every_joint() {
        let order = topological_order();
        assert_eq!(order.len(), NUM_JOINTS);
        for (i, &j) in order.iter().enumerate() {
            if let Some(p) = PARENTS[j] {
                assert!(order[..i].contains(&p), "parent of {j} comes after it");
            }
        }
        // Mirrored joints have mirrored parents.
        for j in 0..NUM_JOINTS {
            if j == 0 || j == 1 || j == 21 || j == 22 {
                continue; // head markers and hand points are chained, not mirrored
            }
            assert_eq!(
                PARENTS[MIRROR[j]],
                PARENTS[j].map(|p| MIRROR[p]),
                "joint {j}"
            );
        }
    }
}
