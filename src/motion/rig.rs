//! The rigid skeleton every export describes, inverse kinematics from joint positions, and
//! forward kinematics back.
//!
//! # The rig
//! 26 joints ([`RIG_JOINTS`]): joint 0 is the body centre (the root, carrying the root
//! translation), joint `k + 1` is dataset joint `k` ([`super::skeleton::JOINT_NAMES`]) with the
//! hierarchy of [`super::skeleton::PARENTS`], and two branch joints follow:
//! - 24 `pelvis`, child of the body centre at the spine's position, parent of both hips;
//! - 25 `neck`, child of the spine at the spine's position, parent of the head.
//!
//! They exist because one rotation cannot carry both the chest and the pelvis (ballroom
//! contra-body motion twists one against the other) nor the head as well: over all 43 dances the
//! branch joints lower the per-dance mean rigid-fit error from 2.15 to 1.77 cm (median) and the
//! hips' error from 4.2 to 2.7 cm (`tests/motion.rs`, `rigid_fit_error_over_every_dance`). Each
//! joint has a fixed offset from its parent (metres, in the parent's frame): its length is the
//! **median over frames** of that bone's length in the motion being exported, its direction the
//! mean direction of the bone in the body's facing frame, so the rest pose is the motion's
//! average pose facing +z.
//!
//! # Inverse kinematics (positions → local rotations)
//! Joints are solved parent first, frame after frame ([`solve`], `rig/chain.rs`). The root sits
//! exactly on the root track, turned by the facing yaw tilted onto the spine (`rig/root.rs`). For
//! each joint, with its own fitted position `P` (from its parent's solution, not the raw data, so
//! errors do not accumulate down a chain) and its children's target positions:
//! - **one child**: the rotation turns the rest bone exactly onto the direction from `P` to the
//!   child's target (shortest arc), then adds a **twist** about that bone;
//! - **several children** (spine, pelvis, left elbow, ankles): the rotation that best maps the
//!   rest offsets of all children onto their targets in least squares (Wahba's problem, by SVD);
//! - **leaves**: no rotation of their own (identity local rotation).
//!
//! Since every bone points exactly at its child's target and bone lengths are fixed at their
//! medians, the only error left against the data is the rigid fit of marker-based bone lengths,
//! which vary by 1–3 cm; and no position depends on a twist. That is [`Aim::FittedEnds`], for
//! captured dances. A served dance is aimed along its own bones instead ([`Aim::DanceBones`]:
//! `P` is the joint's target, the left elbow aims at its forearm alone), which keeps every angle
//! between bones that a network drew with bones of changing length (`rig/chain.rs` says why). The twist is what a skinned mesh
//! follows, so it is chosen to be continuous over time (`rig/continuity.rs`): the one that brings
//! the grandchildren and great-grandchildren closest to their targets (each weighted by its
//! distance from the bone axis: the bend of the elbow for the upper arm, the hand-direction point
//! for the forearm), with the previous frame's twist as one more reference 3 cm off the axis, at
//! most 25° from it a frame; a joint with nothing below to take twist from (the wrist) keeps the
//! previous frame's, pulled gently towards the shortest arc. Chosen from each frame alone, as it
//! was, the twist flipped wherever its references passed near the axis (a straight arm, a hand in
//! line with the forearm): over all 43 dances some joint turned more than 60° between two frames
//! on 1.66 % of steps (DANCE_C_8 7.17 %, DANCE_R_9 1.74 %; right elbow and forearm two thirds of
//! them), and on 0.32 % with the twist carried. The rest were the data's own: a bone whose
//! direction jumps 80–145° in one frame and back (the 4.7 cm wrist → hand-direction bone most of
//! all). So no joint turns faster than 1375°/s (55° a frame at 25 fps), the joints below it placed
//! from where it points: 0.000 % of steps past 60° on all 43 dances, the limit holding on 0.63 %
//! of steps, the per-joint error medians unchanged (within 0.01 cm) and the largest single error
//! 47.3 cm where the data jumps (36.6 before). `metrics::rotation_flips` measures it; every
//! report.json carries it. Frames with no frame rate (`fps` NaN) are unrelated poses, each solved
//! on its own.
//!
//! # Least squares, for motions with key poses
//! The chain IK places each joint from its parent's fitted end, so a bone the rig has shorter than
//! the data puts every joint below it off by the difference, and it holds the spine at a fixed
//! distance from the root. For generated motion the root is the joints' weighted centroid
//! ([`super::skeleton::body_centre_track`]), no rigid point of the body: its distance to the spine
//! varies by 10–20 cm as the body bends. Where captured key poses must come back as posed,
//! [`fit_and_solve`] with anchors fits the bone lengths to the key frames in least squares
//! ([`Rig::fit_lengths`]) and refines every frame's chain solution in least squares over all 23
//! joints with the root free ([`fit_frame`], [`solve_least_squares`]), the root's rotation being
//! the facing yaw tilted onto the spine, the twists the chain's and the turns limited as the
//! chain limits them. Five captured poses of DANCE_W_3 whose thigh measures 43–54 cm came back
//! 4.25 / 0.84 / 1.63 / 1.24 / 5.37 cm off through the chain IK (per joint at the worst: hips 10,
//! spine 8, ankles 7–8 cm) and 2.04 / 1.53 / 1.72 / 1.54 / 2.12 cm through this.
//!
//! # Forward kinematics
//! `world_rot[j] = world_rot[parent] · local[j]`, `pos[j] = pos[parent] + world_rot[parent] ·
//! offset[j]`, root `pos[0] = root_translation`: the BVH and glTF conventions.
use nalgebra::{Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};
use ndarray::{Array2, Array3, ArrayView2, ArrayView3};

use super::repr::facing_yaw;
use super::skeleton::{JOINT_NAMES, PARENTS};
use super::{MotionError, NUM_JOINTS};

mod chain;
mod continuity;
mod keyed;
mod least_squares;
mod root;

/// The retarget solver splits its torso and head turns the same way, and turns a target's joints
/// no faster than choreo's.
pub(crate) use continuity::{limit_turn, max_turn, twist_angle};

/// Joints in the rig: the body centre, the 23 dataset joints, and the branch joints.
pub const RIG_JOINTS: usize = NUM_JOINTS + 1 + VIRTUAL.len();
/// Name of the rig's root joint.
pub const ROOT_NAME: &str = "body_centre";

/// Rig index of dataset joint `j`.
pub const fn rig_index(j: usize) -> usize {
    j + 1
}

/// A rigid skeleton: names, parents and rest offsets.
#[derive(Clone, Debug, PartialEq)]
pub struct Rig {
    /// `ROOT_NAME` then the 23 joint names.
    pub names: Vec<String>,
    /// Parent rig index of each joint; `None` for the root.
    pub parents: Vec<Option<usize>>,
    /// Offset from the parent at rest, metres, in the parent's frame (zero for the root).
    pub offsets: Vec<Vector3<f64>>,
}

/// A motion on a rigid skeleton: root translation and local rotations per frame.
#[derive(Clone, Debug)]
pub struct RigMotion {
    pub rig: Rig,
    pub fps: f64,
    /// `[T]` root positions, metres.
    pub root_translation: Vec<Vector3<f64>>,
    /// `[T][RIG_JOINTS]` local rotations (relative to the parent's frame).
    pub rotations: Vec<Vec<UnitQuaternion<f64>>>,
}

impl RigMotion {
    /// Number of frames.
    pub fn num_frames(&self) -> usize {
        self.root_translation.len()
    }

    /// World positions of every rig joint, `[T, RIG_JOINTS, 3]` (forward kinematics).
    pub fn world_positions(&self) -> Array3<f64> {
        let t_len = self.num_frames();
        let n = self.rig.names.len();
        let mut out = Array3::zeros((t_len, n, 3));
        for t in 0..t_len {
            let (pos, _) = fk_frame(&self.rig, &self.root_translation[t], &self.rotations[t]);
            for (j, p) in pos.iter().enumerate() {
                for c in 0..3 {
                    out[[t, j, c]] = p[c];
                }
            }
        }
        out
    }

    /// World positions of the 23 dataset joints (root dropped), `[T, 23, 3]` as f32.
    pub fn joint_positions(&self) -> Array3<f32> {
        let w = self.world_positions();
        let t_len = w.shape()[0];
        let mut out = Array3::zeros((t_len, NUM_JOINTS, 3));
        for t in 0..t_len {
            for j in 0..NUM_JOINTS {
                for c in 0..3 {
                    out[[t, j, c]] = w[[t, rig_index(j), c]] as f32;
                }
            }
        }
        out
    }
}

/// Forward kinematics of one frame: world positions and world rotations of every joint.
pub fn fk_frame(
    rig: &Rig,
    root: &Vector3<f64>,
    local: &[UnitQuaternion<f64>],
) -> (Vec<Vector3<f64>>, Vec<UnitQuaternion<f64>>) {
    let n = rig.names.len();
    let mut pos = vec![Vector3::zeros(); n];
    let mut rot = vec![UnitQuaternion::identity(); n];
    for j in rig.order() {
        match rig.parents[j] {
            None => {
                pos[j] = *root + rig.offsets[j];
                rot[j] = local[j];
            }
            Some(p) => {
                pos[j] = pos[p] + rot[p] * rig.offsets[j];
                rot[j] = rot[p] * local[j];
            }
        }
    }
    (pos, rot)
}

/// Names of the rig's joints in rig order: motion.json's `joint_names`.
pub fn joint_names() -> Vec<String> {
    hierarchy().0
}

/// The rig's hierarchy (names, parents) with zero offsets; see [`Rig::fit`] for the offsets.
fn hierarchy() -> (Vec<String>, Vec<Option<usize>>) {
    let mut names = vec![ROOT_NAME.to_string()];
    names.extend(JOINT_NAMES.iter().map(|s| s.to_string()));
    let mut parents = vec![None];
    parents.extend(PARENTS.iter().map(|p| Some(p.map_or(0, rig_index))));
    for (k, v) in VIRTUAL.iter().enumerate() {
        let idx = NUM_JOINTS + 1 + k;
        names.push(v.name.to_string());
        parents.push(Some(v.parent));
        for &c in v.children {
            parents[rig_index(c)] = Some(idx);
        }
    }
    (names, parents)
}

/// A branch joint the rig adds so a group of children gets its own rotation.
struct Virtual {
    name: &'static str,
    /// Rig parent.
    parent: usize,
    /// Dataset joint whose position it shares.
    at: usize,
    /// Dataset joints re-parented under it.
    children: &'static [usize],
}

/// Branch joints of the rig, after the 23 joints.
const VIRTUAL: [Virtual; 2] = [
    Virtual {
        name: "pelvis",
        parent: 0,
        at: super::skeleton::SPINE,
        children: &super::skeleton::HIPS,
    },
    Virtual {
        name: "neck",
        parent: rig_index(super::skeleton::SPINE),
        at: super::skeleton::SPINE,
        children: &[1],
    },
];

/// Targets of every rig joint per frame: root track then joints, `[T][RIG_JOINTS]`.
fn targets(
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
) -> Result<Vec<Vec<Vector3<f64>>>, MotionError> {
    let sh = positions.shape();
    if sh[1] != NUM_JOINTS || sh[2] != 3 || root.shape() != [sh[0], 3] {
        return Err(MotionError::Shape(format!(
            "positions {sh:?} and root {:?}, expected [T, {NUM_JOINTS}, 3] and [T, 3]",
            root.shape()
        )));
    }
    if positions.iter().chain(root.iter()).any(|v| !v.is_finite()) {
        return Err(MotionError::Invalid("non-finite joint position".into()));
    }
    Ok((0..sh[0])
        .map(|t| {
            let mut v = Vec::with_capacity(RIG_JOINTS);
            v.push(Vector3::new(
                f64::from(root[[t, 0]]),
                f64::from(root[[t, 1]]),
                f64::from(root[[t, 2]]),
            ));
            for j in 0..NUM_JOINTS {
                v.push(Vector3::new(
                    f64::from(positions[[t, j, 0]]),
                    f64::from(positions[[t, j, 1]]),
                    f64::from(positions[[t, j, 2]]),
                ));
            }
            for b in &VIRTUAL {
                v.push(v[rig_index(b.at)]);
            }
            v
        })
        .collect())
}

impl Rig {
    /// Fits the rigid skeleton of a motion: median bone lengths, mean bone directions in the
    /// facing frame.
    pub fn fit(
        positions: ArrayView3<'_, f32>,
        root: ArrayView2<'_, f32>,
    ) -> Result<Rig, MotionError> {
        let tg = targets(positions, root)?;
        if tg.is_empty() {
            return Err(MotionError::Shape("motion has no frames".into()));
        }
        let (names, parents) = hierarchy();
        let yaws: Vec<f64> = positions
            .outer_iter()
            .map(|f| f64::from(facing_yaw(f)))
            .collect();
        let mut offsets = vec![Vector3::zeros(); RIG_JOINTS];
        for j in 1..RIG_JOINTS {
            let Some(p) = parents[j] else { continue };
            let mut lengths = Vec::with_capacity(tg.len());
            let mut dir_sum = Vector3::zeros();
            for (t, frame) in tg.iter().enumerate() {
                let d = frame[j] - frame[p];
                let len = d.norm();
                lengths.push(len);
                if len > 1e-9 {
                    let unyawed = Rotation3::from_axis_angle(&Vector3::y_axis(), -yaws[t]) * d;
                    dir_sum += unyawed / len;
                }
            }
            lengths.sort_by(f64::total_cmp);
            let median = lengths[lengths.len() / 2];
            let dir = if dir_sum.norm() > 1e-9 {
                dir_sum.normalize()
            } else {
                Vector3::y()
            };
            offsets[j] = dir * median;
        }
        let mut rig = Rig {
            names,
            parents,
            offsets,
        };
        rig.refine_branches(&tg);
        Ok(rig)
    }

    /// Refines the rest directions of the children of branching joints (spine, left elbow,
    /// ankles) by generalised Procrustes: the mean, over frames, of each child's offset seen from
    /// the branch joint's best-fit frame. Lengths stay the medians.
    fn refine_branches(&mut self, tg: &[Vec<Vector3<f64>>]) {
        const ITERATIONS: usize = 3;
        for j in 0..self.parents.len() {
            let kids = self.children(j);
            if kids.len() < 2 {
                continue;
            }
            for _ in 0..ITERATIONS {
                let rest: Vec<Vector3<f64>> = kids.iter().map(|&c| self.offsets[c]).collect();
                let mut sums = vec![Vector3::zeros(); kids.len()];
                for frame in tg {
                    let target: Vec<Vector3<f64>> =
                        kids.iter().map(|&c| frame[c] - frame[j]).collect();
                    let Some(r) = wahba(&rest, &target) else {
                        continue;
                    };
                    let r_inv = r.inverse();
                    for (s, d) in sums.iter_mut().zip(&target) {
                        *s += r_inv * d;
                    }
                }
                for (k, &c) in kids.iter().enumerate() {
                    if let Some(dir) = sums[k].try_normalize(1e-12) {
                        self.offsets[c] = dir * self.offsets[c].norm();
                    }
                }
            }
        }
    }

    /// The rig's hierarchy with the given rest offsets (`RIG_JOINTS` of them, metres, each in its
    /// parent's frame), e.g. a skeleton stored with a model.
    pub fn from_offsets(offsets: &[[f64; 3]]) -> Result<Rig, MotionError> {
        let (names, parents) = hierarchy();
        if offsets.len() != names.len() || offsets.iter().flatten().any(|v| !v.is_finite()) {
            return Err(MotionError::Shape(format!(
                "{} rig offsets, expected {} finite ones",
                offsets.len(),
                names.len()
            )));
        }
        Ok(Rig {
            names,
            parents,
            offsets: offsets
                .iter()
                .map(|o| Vector3::new(o[0], o[1], o[2]))
                .collect(),
        })
    }

    /// The rest offsets as plain arrays (the form [`Rig::from_offsets`] takes).
    pub fn offset_arrays(&self) -> Vec<[f64; 3]> {
        self.offsets.iter().map(|o| [o.x, o.y, o.z]).collect()
    }

    /// Children of rig joint `j`.
    pub fn children(&self, j: usize) -> Vec<usize> {
        (0..self.parents.len())
            .filter(|&c| self.parents[c] == Some(j))
            .collect()
    }

    /// Joints with every parent before its children (depth first from the root).
    pub fn order(&self) -> Vec<usize> {
        let mut out = Vec::with_capacity(self.parents.len());
        let mut stack: Vec<usize> = (0..self.parents.len())
            .filter(|&j| self.parents[j].is_none())
            .rev()
            .collect();
        while let Some(j) = stack.pop() {
            out.push(j);
            stack.extend(self.children(j).into_iter().rev());
        }
        out
    }

    /// Median bone lengths (metres) per rig joint (0 for the root).
    pub fn bone_lengths(&self) -> Vec<f64> {
        self.offsets.iter().map(|o| o.norm()).collect()
    }
}

/// Shortest-arc rotation taking direction `a` onto direction `b`.
fn arc(a: &Vector3<f64>, b: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(a, b).unwrap_or_else(|| {
        // Opposite vectors: half a turn about any axis perpendicular to `a`.
        let perp = a.cross(&Vector3::x());
        let perp = if perp.norm() < 1e-6 {
            a.cross(&Vector3::y())
        } else {
            perp
        };
        UnitQuaternion::from_axis_angle(&Unit::new_normalize(perp), std::f64::consts::PI)
    })
}

/// Rotation `R` minimising `Σ |R·rest_k − target_k|²` (Wahba's problem, SVD solution).
fn wahba(rest: &[Vector3<f64>], target: &[Vector3<f64>]) -> Option<UnitQuaternion<f64>> {
    let mut b = Matrix3::zeros();
    for (r, d) in rest.iter().zip(target) {
        b += d * r.transpose();
    }
    let svd = b.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let det = (u * v_t).determinant();
    let m = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, det.signum()));
    let r = u * m * v_t;
    let rot = Rotation3::from_matrix_unchecked(r);
    let q = UnitQuaternion::from_rotation_matrix(&rot);
    q.coords.iter().all(|c| c.is_finite()).then_some(q)
}

pub use chain::{solve, solve_aimed, Aim};
pub use least_squares::{fit_and_solve, fit_and_solve_seeded, fit_frame, solve_least_squares};

/// Local rotations in the continuous 6-D representation (Zhou et al. 2019): the first two
/// columns of each rotation matrix, `[T, RIG_JOINTS, 6]`.
pub fn rotations_6d(motion: &RigMotion) -> Array3<f32> {
    let t_len = motion.num_frames();
    let n = motion.rig.names.len();
    let mut out = Array3::zeros((t_len, n, 6));
    for (t, frame) in motion.rotations.iter().enumerate() {
        for (j, q) in frame.iter().enumerate() {
            let m = q.to_rotation_matrix();
            let m = m.matrix();
            for r in 0..3 {
                out[[t, j, r]] = m[(r, 0)] as f32;
                out[[t, j, 3 + r]] = m[(r, 1)] as f32;
            }
        }
    }
    out
}

/// Rotation from a 6-D vector: Gram–Schmidt on the two columns (inverse of [`rotations_6d`]).
pub fn rotation_from_6d(v: &[f32; 6]) -> Option<UnitQuaternion<f64>> {
    let a = Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
    let b = Vector3::new(f64::from(v[3]), f64::from(v[4]), f64::from(v[5]));
    let x = a.try_normalize(1e-12)?;
    let y = (b - x * x.dot(&b)).try_normalize(1e-12)?;
    let z = x.cross(&y);
    let m = Matrix3::from_columns(&[x, y, z]);
    Some(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(m),
    ))
}

/// Local rotations as quaternions `[T, RIG_JOINTS, 4]` in `x, y, z, w` order.
pub fn rotations_quat(motion: &RigMotion) -> Array3<f32> {
    let t_len = motion.num_frames();
    let n = motion.rig.names.len();
    let mut out = Array3::zeros((t_len, n, 4));
    for (t, frame) in motion.rotations.iter().enumerate() {
        for (j, q) in frame.iter().enumerate() {
            let c = q.coords; // nalgebra stores (i, j, k, w)
            for k in 0..4 {
                out[[t, j, k]] = c[k] as f32;
            }
        }
    }
    out
}

/// Per-joint distance (metres) between two `[T, J, 3]` position arrays, `[T, J]`.
pub fn joint_errors(a: ArrayView3<'_, f32>, b: ArrayView3<'_, f32>) -> Array2<f32> {
    let (t_len, j_len) = (
        a.shape()[0].min(b.shape()[0]),
        a.shape()[1].min(b.shape()[1]),
    );
    let mut out = Array2::zeros((t_len, j_len));
    for t in 0..t_len {
        for j in 0..j_len {
            let mut d2 = 0.0f32;
            for c in 0..3 {
                let d = a[[t, j, c]] - b[[t, j, c]];
                d2 += d * d;
            }
            out[[t, j]] = d2.sqrt();
        }
    }
    out
}

#[cfg(test)]
mod tests;
