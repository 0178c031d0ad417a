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
//! hips' error from 4.2 to 2.7 cm (`tests/motion.rs`, `rigid_fit_error_over_every_dance`). Each joint has a fixed offset from its parent (metres, in the
//! parent's frame): its length is the **median over frames** of that bone's length in the motion
//! being exported, its direction the mean direction of the bone in the body's facing frame, so the
//! rest pose is the motion's average pose facing +z.
//!
//! # Inverse kinematics (positions → local rotations)
//! Joints are solved parent first. The root sits exactly on the root track. For each joint, with
//! its own fitted position `P` (from its parent's solution, not the raw data, so errors do not
//! accumulate down a chain) and its children's target positions:
//! - **one child**: the rotation turns the rest bone exactly onto the direction from `P` to the
//!   child's target (shortest arc); the **twist** about that bone is then chosen so the
//!   grandchildren and great-grandchildren (e.g. the bend of the elbow for the upper arm, the
//!   hand-direction point for the forearm) come as close as possible to their targets, each
//!   weighted by its distance from the bone axis. With none to take twist from (the wrist, whose
//!   only child is the hand-direction point) the twist is inherited from the parent.
//! - **several children** (spine, left elbow, ankles): the rotation that best maps the rest offsets
//!   of all children onto their targets in least squares (Wahba's problem, solved by SVD).
//! - **leaves**: no rotation of their own (identity local rotation).
//!
//! Since bone lengths are fixed at their medians, the only error left against the data is the
//! rigid fit of marker-based bone lengths, which vary by 1–3 cm.
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
//! the facing yaw tilted onto the spine. Five captured poses of DANCE_W_3 whose thigh measures 43–54 cm came back
//! 4.25 / 0.84 / 1.63 / 1.24 / 5.37 cm off through the chain IK (per joint at the worst: hips 10,
//! spine 8, ankles 7–8 cm) and 2.04 / 1.53 / 1.72 / 1.54 / 2.12 cm through this.
//!
//! # Forward kinematics
//! `world_rot[j] = world_rot[parent] · local[j]`, `pos[j] = pos[parent] + world_rot[parent] ·
//! offset[j]`, root `pos[0] = root_translation`: the BVH and glTF conventions.
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};
use ndarray::{Array2, Array3, ArrayView2, ArrayView3, Axis};

use super::repr::facing_yaw;
use super::skeleton::{JOINT_NAMES, PARENTS};
use super::{MotionError, NUM_JOINTS};

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
    pub fn fit(positions: ArrayView3<'_, f32>, root: ArrayView2<'_, f32>) -> Result<Rig, MotionError> {
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
                    let target: Vec<Vector3<f64>> = kids.iter().map(|&c| frame[c] - frame[j]).collect();
                    let Some(r) = wahba(&rest, &target) else { continue };
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
            return Err(MotionError::Shape(format!("{} rig offsets, expected {} finite ones", offsets.len(), names.len())));
        }
        Ok(Rig { names, parents, offsets: offsets.iter().map(|o| Vector3::new(o[0], o[1], o[2])).collect() })
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
        let perp = if perp.norm() < 1e-6 { a.cross(&Vector3::y()) } else { perp };
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

/// Inverse kinematics: local rotations of `rig` that follow `positions` around `root`.
pub fn solve(
    rig: &Rig,
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
) -> Result<RigMotion, MotionError> {
    let tg = targets(positions, root)?;
    let n = rig.names.len();
    let children: Vec<Vec<usize>> = (0..n).map(|j| rig.children(j)).collect();
    let order = rig.order();
    // Twist references of single-child joints: descendants two and three levels down.
    let twist_refs: Vec<Vec<usize>> = (0..n)
        .map(|j| {
            let mut refs = Vec::new();
            for &c in &children[j] {
                for &g in &children[c] {
                    refs.push(g);
                    refs.extend(children[g].iter().copied());
                }
            }
            refs
        })
        .collect();
    // Rest position of every joint relative to its ancestors (identity rotations).
    let rest_rel = |from: usize, to: usize| -> Vector3<f64> {
        let mut v = Vector3::zeros();
        let mut k = to;
        while k != from {
            v += rig.offsets[k];
            match rig.parents[k] {
                Some(p) => k = p,
                None => break,
            }
        }
        v
    };
    let mut rotations = Vec::with_capacity(tg.len());
    let mut root_translation = Vec::with_capacity(tg.len());
    for frame in &tg {
        let mut pos = vec![Vector3::zeros(); n];
        let mut world = vec![UnitQuaternion::identity(); n];
        let mut local = vec![UnitQuaternion::identity(); n];
        for &j in &order {
            let parent_world = rig.parents[j].map_or(UnitQuaternion::identity(), |p| world[p]);
            pos[j] = match rig.parents[j] {
                None => frame[j],
                Some(p) => pos[p] + world[p] * rig.offsets[j],
            };
            let kids = &children[j];
            let w = match kids.len() {
                0 => parent_world,
                1 => {
                    let c = kids[0];
                    let rest_dir = parent_world * rig.offsets[c];
                    let target_dir = frame[c] - pos[j];
                    if target_dir.norm() < 1e-9 || rest_dir.norm() < 1e-9 {
                        parent_world
                    } else {
                        let swing = arc(&rest_dir, &target_dir) * parent_world;
                        twist(swing, &target_dir, &pos[j], frame, &twist_refs[j], |g| {
                            rest_rel(j, g)
                        })
                    }
                }
                _ => {
                    let rest: Vec<Vector3<f64>> = kids.iter().map(|&c| rig.offsets[c]).collect();
                    let target: Vec<Vector3<f64>> = kids.iter().map(|&c| frame[c] - pos[j]).collect();
                    wahba(&rest, &target).unwrap_or(parent_world)
                }
            };
            world[j] = w;
            local[j] = parent_world.inverse() * w;
        }
        root_translation.push(frame[0]);
        // The root's children (spine and pelvis) share one rest direction, so the best fit above
        // leaves the root free to turn about it, and it did: 90° (median) from one frame to the
        // next, the children turning back. Positions do not show it; a tool that interpolates
        // between frames would spin the torso. The facing yaw tilted onto the spine fixes the
        // turn; every world position and every other local rotation stays.
        let t = rotations.len();
        rotations.push(rerooted(rig, root_rotation(rig, positions.index_axis(Axis(0), t), frame), &local));
    }
    Ok(RigMotion {
        rig: rig.clone(),
        fps,
        root_translation,
        rotations,
    })
}

/// Adds the twist about `axis` to `swing` that brings the references closest to their targets.
fn twist(
    swing: UnitQuaternion<f64>,
    axis: &Vector3<f64>,
    origin: &Vector3<f64>,
    frame: &[Vector3<f64>],
    refs: &[usize],
    rest_rel: impl Fn(usize) -> Vector3<f64>,
) -> UnitQuaternion<f64> {
    let a = axis.normalize();
    let (mut sin_sum, mut cos_sum) = (0.0, 0.0);
    for &g in refs {
        let have = swing * rest_rel(g);
        let want = frame[g] - origin;
        let have_p = have - a * have.dot(&a);
        let want_p = want - a * want.dot(&a);
        // Unnormalised: a reference far off the axis has a well-defined angle and counts more.
        sin_sum += have_p.cross(&want_p).dot(&a);
        cos_sum += have_p.dot(&want_p);
    }
    if sin_sum == 0.0 && cos_sum == 0.0 {
        return swing;
    }
    let angle = sin_sum.atan2(cos_sum);
    UnitQuaternion::from_axis_angle(&Unit::new_unchecked(a), angle) * swing
}

/// Fits a rig to a motion and solves its rotations in one go.
///
/// Without `anchors` the skeleton is fitted to every frame (median bone lengths) and each frame
/// solved by the chain IK of [`solve`]. With `anchors` (frame indices, the user's key poses) the
/// skeleton is fitted to those frames, so the body the user posed is the body that dances and
/// those frames come back as posed as far as one rigid skeleton can take them: its bone lengths
/// are the least-squares best for the anchor frames ([`Rig::fit_lengths`], starting from the
/// anchors' medians), and every frame is solved in least squares ([`solve_least_squares`]).
pub fn fit_and_solve(
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
    anchors: &[usize],
) -> Result<RigMotion, MotionError> {
    let mut keep: Vec<usize> = anchors.iter().copied().filter(|&f| f < positions.dim().0).collect();
    keep.sort_unstable();
    keep.dedup();
    if keep.is_empty() {
        let rig = Rig::fit(positions, root)?;
        return solve(&rig, positions, root, fps);
    }
    let (key_positions, key_root) = (positions.select(Axis(0), &keep), root.select(Axis(0), &keep));
    let mut rig = Rig::fit(key_positions.view(), key_root.view())?;
    rig.fit_lengths(key_positions.view(), key_root.view())?;
    solve_least_squares(&rig, positions, root, fps)
}

/// Rounds of [`Rig::fit_lengths`]' alternation between the frames' poses and the bone lengths.
/// Over the 258 sets of 4–5 captured poses of `tests/motion.rs` `captured_key_sets_of_every_dance`,
/// the worst key of a set comes back (median over sets) 2.08 cm off with no round, 1.87 after 1,
/// 1.77 after 4, 1.72 after 8, 1.67 after 16 and 1.68 after 32 (measured 2026-11-25).
const LENGTH_ROUNDS: usize = 16;

impl Rig {
    /// Refits the bone lengths (rest directions kept) to the frames `positions` `[K, 23, 3]`
    /// around `root` `[K, 3]` in least squares: each frame is posed by [`fit_frame`] (root
    /// free), then the lengths that bring the 23 joints of all frames closest to their targets
    /// are solved at once (positions are linear in the lengths once the rotations are fixed, and
    /// each frame's root translation is free), `LENGTH_ROUNDS` times. The spine's offset from
    /// the body centre is kept: with every frame's root free, it and the pelvis's could slide
    /// together without changing any joint.
    pub fn fit_lengths(&mut self, positions: ArrayView3<'_, f32>, root: ArrayView2<'_, f32>) -> Result<(), MotionError> {
        let tg = targets(positions, root)?;
        let chain = solve(self, positions, root, 1.0)?; // (the frame rate is not used)
        let mut poses: Vec<(Vector3<f64>, Vec<UnitQuaternion<f64>>)> = chain
            .root_translation
            .iter()
            .zip(&chain.rotations)
            .zip(positions.outer_iter().zip(&tg))
            .map(|((r, l), (p, t))| (*r, rerooted(self, root_rotation(self, p, t), l)))
            .collect();
        for _ in 0..LENGTH_ROUNDS {
            poses = poses.iter().zip(&tg).map(|((r, l), t)| fit_frame(self, r, l, t)).collect();
            self.solve_lengths(&poses, &tg);
        }
        Ok(())
    }

    /// One least-squares solve of the bone lengths for posed frames; see [`Rig::fit_lengths`].
    fn solve_lengths(&mut self, poses: &[(Vector3<f64>, Vec<UnitQuaternion<f64>>)], tg: &[Vec<Vector3<f64>>]) {
        let spine = rig_index(super::skeleton::SPINE);
        let bones: Vec<usize> = (0..self.parents.len())
            .filter(|&j| self.parents[j].is_some() && j != spine && self.offsets[j].norm() > 1e-6)
            .collect();
        let dirs: Vec<Vector3<f64>> = bones.iter().map(|&b| self.offsets[b].normalize()).collect();
        // Normal equations in the lengths. Each frame's root translation is free, and its best
        // value centres the frame's residuals, so every frame's rows are taken about their mean
        // over the joints.
        let mut ata = DMatrix::<f64>::zeros(bones.len(), bones.len());
        let mut atb = DVector::<f64>::zeros(bones.len());
        for ((_, local), frame) in poses.iter().zip(tg) {
            let (_, world) = fk_frame(self, &Vector3::zeros(), local);
            // rows[c][i]: joint i's coordinate c as lengths · coefficients, rhs[c][i] the rest.
            let mut rows = vec![DMatrix::<f64>::zeros(NUM_JOINTS, bones.len()); 3];
            let mut rhs = vec![DVector::<f64>::zeros(NUM_JOINTS); 3];
            for (i, j) in (0..NUM_JOINTS).map(rig_index).enumerate() {
                // p_j = root + Σ over the bones above j of world[parent] · offset: the unknown
                // lengths times their world directions, plus the bones kept as they are.
                let mut known = Vector3::<f64>::zeros();
                let mut k = j;
                while let Some(p) = self.parents[k] {
                    match bones.iter().position(|&b| b == k) {
                        Some(u) => {
                            let v = world[p] * dirs[u];
                            for c in 0..3 {
                                rows[c][(i, u)] = v[c];
                            }
                        }
                        None => known += world[p] * self.offsets[k],
                    }
                    k = p;
                }
                for c in 0..3 {
                    rhs[c][i] = frame[j][c] - known[c];
                }
            }
            for c in 0..3 {
                let mean_row = rows[c].row_mean();
                let mut a = rows[c].clone();
                for mut r in a.row_iter_mut() {
                    r -= &mean_row;
                }
                let b = rhs[c].add_scalar(-rhs[c].mean());
                ata += a.transpose() * &a;
                atb += a.transpose() * b;
            }
        }
        // A light pull towards the current lengths keeps a bone that no frame pins down.
        for (i, &b) in bones.iter().enumerate() {
            ata[(i, i)] += 1e-4;
            atb[i] += 1e-4 * self.offsets[b].norm();
        }
        let Some(x) = ata.cholesky().map(|ch| ch.solve(&atb)) else { return };
        for (i, &b) in bones.iter().enumerate() {
            // A bone is never shorter than 1 cm (none of the data's is).
            if x[i].is_finite() && x[i] > 0.01 {
                self.offsets[b] = dirs[i] * x[i];
            }
        }
    }
}

/// The root's rotation for the least-squares IK: the facing yaw of the 23-joint `frame`, tilted
/// by the shortest arc that turns the spine's rest offset towards the spine's target as seen from
/// the root's (`target`, rig-indexed). The tilt keeps the root where the body centre track puts
/// it as the body leans; the yaw settles the turn about the spine's offset, which the spine's and
/// the pelvis's offsets (the root's two children, in one direction) leave free.
fn root_rotation(rig: &Rig, frame: ArrayView2<'_, f32>, target: &[Vector3<f64>]) -> UnitQuaternion<f64> {
    let yaw = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), f64::from(facing_yaw(frame)));
    let spine = rig_index(super::skeleton::SPINE);
    let (rest, data) = (yaw * rig.offsets[spine], target[spine] - target[0]);
    if rest.norm() < 1e-9 || data.norm() < 1e-9 {
        return yaw;
    }
    arc(&rest, &data) * yaw
}

/// The same pose with the root's rotation replaced by `root_rot`: the root's children take the
/// difference, so every world position and every other local rotation stays.
fn rerooted(rig: &Rig, root_rot: UnitQuaternion<f64>, local: &[UnitQuaternion<f64>]) -> Vec<UnitQuaternion<f64>> {
    let (_, world) = fk_frame(rig, &Vector3::zeros(), local);
    let mut out = local.to_vec();
    for (j, p) in rig.parents.iter().enumerate() {
        match p {
            None => out[j] = root_rot,
            Some(p) if rig.parents[*p].is_none() => out[j] = root_rot.inverse() * world[j],
            Some(_) => {}
        }
    }
    out
}

/// Inverse kinematics in least squares: each frame of `positions` around the body-centre track
/// `root` is [`solve`]'s chain solution refined by [`fit_frame`], so where the data's bone lengths
/// differ from the rig's the mismatch is spread over the body rather than piled on the ends of its
/// chains, and the root sits where the body fits best.
///
/// The root's own rotation is `root_rotation`'s (the facing yaw tilted onto the spine), as
/// [`solve`] leaves it, kept through the fit.
///
/// Each frame starts from its own chain solution, not from the previous frame's fit: started from
/// the previous frame, the fits of a captured dance drift into a wrong pose within 20 s (mean joint
/// error 2 → 45 cm on DANCE_W_3) and stay there, while the chain solutions move as smoothly as the
/// data (acceleration p99.9 25.3 m/s² against the data's 26.3).
pub fn solve_least_squares(
    rig: &Rig,
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
) -> Result<RigMotion, MotionError> {
    let tg = targets(positions, root)?;
    let chain = solve(rig, positions, root, fps)?;
    let (root_translation, rotations) = tg
        .iter()
        .enumerate()
        .map(|(t, frame)| fit_frame(rig, &chain.root_translation[t], &chain.rotations[t], frame))
        .unzip();
    Ok(RigMotion { rig: rig.clone(), fps, root_translation, rotations })
}

/// Most Levenberg–Marquardt steps of [`fit_frame`]; 200 change no key error on the test dances.
const FIT_ITERATIONS: usize = 50;

/// [`fit_frame`] stops when a step lowers its cost by less than this fraction. 1e-12 takes 2.3×
/// as long and moves no key error and no acceleration percentile of DANCE_W_3 by 0.01.
const FIT_TOLERANCE: f64 = 1e-6;

/// [`fit_frame`]'s pull towards the rotations it starts from: a joint turned θ radians away
/// costs as much as a joint `ROTATION_PRIOR_M · θ` metres off its target. It settles what the
/// targets leave free and is too weak to hold anything else (1 cm per radian).
const ROTATION_PRIOR_M: f64 = 0.01;

/// Refits one frame of `rig` in least squares, starting from `root` and `local`: the root
/// translation and the rotation of every joint with children but the root (whose rotation is
/// kept) that bring the 23 dataset joints closest to `target` (rig-indexed, as `targets` builds
/// it) in the sum of squared distances, plus `ROTATION_PRIOR_M`'s pull towards `local`, by
/// Levenberg–Marquardt.
///
/// [`solve`] points each bone at its child's target from the parent's already-fitted end: where
/// the data's bone lengths differ from the rig's the whole mismatch lands on the chain's far end
/// (a thigh 5 cm longer than the rig's puts the knee, ankle, heel and toe 5 cm off), and the root
/// is the body centre (for generated motion the joints' weighted centroid, no rigid point of the
/// body), from which the spine is put at a fixed distance that the data's varies by 10–20 cm
/// when the body bends. This fit spreads the mismatch over every joint and moves the root where
/// the body fits best.
pub fn fit_frame(
    rig: &Rig,
    root: &Vector3<f64>,
    local: &[UnitQuaternion<f64>],
    target: &[Vector3<f64>],
) -> (Vector3<f64>, Vec<UnitQuaternion<f64>>) {
    let measured: Vec<usize> = (0..NUM_JOINTS).map(rig_index).collect();
    let movers: Vec<usize> = (0..rig.names.len()).filter(|&j| rig.parents[j].is_some() && !rig.children(j).is_empty()).collect();
    let is_below = |j: usize, k: usize| {
        let mut a = rig.parents[j];
        while let Some(p) = a {
            if p == k {
                return true;
            }
            a = rig.parents[p];
        }
        false
    };
    // below[m][i]: measured joint i moves with mover m's rotation.
    let below: Vec<Vec<bool>> = movers.iter().map(|&k| measured.iter().map(|&j| is_below(j, k)).collect()).collect();
    let start = local.to_vec();
    // A mover's turn away from its start, as a rotation vector in world axes.
    let turn = |k: usize, local: &[UnitQuaternion<f64>], world: &[UnitQuaternion<f64>]| -> Vector3<f64> {
        let d = start[k].inverse() * local[k];
        let d = if d.w < 0.0 { UnitQuaternion::new_unchecked(-d.into_inner()) } else { d };
        world[k] * d.scaled_axis()
    };
    let cost_of = |root: &Vector3<f64>, local: &[UnitQuaternion<f64>]| {
        let (pos, world) = fk_frame(rig, root, local);
        let c = measured.iter().map(|&j| (pos[j] - target[j]).norm_squared()).sum::<f64>()
            + movers.iter().map(|&k| (turn(k, local, &world) * ROTATION_PRIOR_M).norm_squared()).sum::<f64>();
        (c, pos, world)
    };
    let mut root = *root;
    let mut local = local.to_vec();
    let (mut cost, mut pos, mut world) = cost_of(&root, &local);
    let params = 3 + 3 * movers.len();
    let rows = 3 * measured.len() + 3 * movers.len();
    let mut lambda = 1e-3;
    for _ in 0..FIT_ITERATIONS {
        // Residuals and Jacobian: the root translation moves every joint; a world-frame turn ω
        // of mover k moves a joint j below it by ω × (p_j − p_k) and adds ω to k's own turn.
        let mut jac = DMatrix::<f64>::zeros(rows, params);
        let mut res = DVector::<f64>::zeros(rows);
        for (i, &j) in measured.iter().enumerate() {
            let r = pos[j] - target[j];
            for c in 0..3 {
                res[3 * i + c] = r[c];
                jac[(3 * i + c, c)] = 1.0;
            }
            for (m, &k) in movers.iter().enumerate() {
                if below[m][i] {
                    // ω × d = −[d]× ω
                    jac.view_mut((3 * i, 3 + 3 * m), (3, 3)).copy_from(&(-(pos[j] - pos[k]).cross_matrix()));
                }
            }
        }
        for (m, &k) in movers.iter().enumerate() {
            let row = 3 * measured.len() + 3 * m;
            let r = turn(k, &local, &world) * ROTATION_PRIOR_M;
            for c in 0..3 {
                res[row + c] = r[c];
                jac[(row + c, 3 + 3 * m + c)] = ROTATION_PRIOR_M;
            }
        }
        let jtj = jac.transpose() * &jac;
        let jtr = jac.transpose() * &res;
        let mut improved = false;
        for _ in 0..10 {
            let mut a = jtj.clone();
            for d in 0..params {
                a[(d, d)] += lambda * (jtj[(d, d)] + 1e-9);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&(-&jtr))) else {
                lambda *= 10.0;
                continue;
            };
            let new_root = root + Vector3::new(step[0], step[1], step[2]);
            let mut new_local = local.clone();
            for (m, &k) in movers.iter().enumerate() {
                let w = Vector3::new(step[3 + 3 * m], step[4 + 3 * m], step[5 + 3 * m]);
                let parent_world = rig.parents[k].map_or(UnitQuaternion::identity(), |p| world[p]);
                new_local[k] = parent_world.inverse() * UnitQuaternion::from_scaled_axis(w) * world[k];
            }
            let (c, p, w) = cost_of(&new_root, &new_local);
            if c < cost {
                improved = cost - c > FIT_TOLERANCE * cost;
                (root, local, cost, pos, world) = (new_root, new_local, c, p, w);
                lambda = (lambda / 3.0).max(1e-9);
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    (root, local)
}

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
    Some(UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m)))
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
    let (t_len, j_len) = (a.shape()[0].min(b.shape()[0]), a.shape()[1].min(b.shape()[1]));
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
mod tests {
    use super::*;
    use ndarray::Array2;

    /// A rig with random offsets, the branch joints on the spine as [`Rig::fit`] puts them.
    fn random_rig(rng: &mut impl rand::Rng) -> Rig {
        let (names, parents) = hierarchy();
        let mut offsets: Vec<Vector3<f64>> = (0..RIG_JOINTS)
            .map(|j| {
                if j == 0 {
                    Vector3::zeros()
                } else {
                    Vector3::new(rng.gen_range(-0.2..0.2), rng.gen_range(-0.3..0.3), rng.gen_range(-0.2..0.2))
                }
            })
            .collect();
        offsets[NUM_JOINTS + 1] = offsets[rig_index(super::super::skeleton::SPINE)];
        offsets[NUM_JOINTS + 2] = Vector3::zeros();
        Rig { names, parents, offsets }
    }

    /// The 23 dataset joints of posed frames, `[T, 23, 3]`, and the root track `[T, 3]`.
    fn arrays(rig: &Rig, roots: &[Vector3<f64>], locals: &[Vec<UnitQuaternion<f64>>]) -> (Array3<f32>, Array2<f32>) {
        let t_len = roots.len();
        let mut pos = Array3::zeros((t_len, NUM_JOINTS, 3));
        let mut root = Array2::zeros((t_len, 3));
        for t in 0..t_len {
            let p = fk_frame(rig, &roots[t], &locals[t]).0;
            for c in 0..3 {
                root[[t, c]] = roots[t][c] as f32;
                for j in 0..NUM_JOINTS {
                    pos[[t, j, c]] = p[rig_index(j)][c] as f32;
                }
            }
        }
        (pos, root)
    }

    fn random_rotation(rng: &mut impl rand::Rng, size: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(rng.gen_range(-size..size), rng.gen_range(-size..size), rng.gen_range(-size..size))
    }

    /// Mean distance (cm) over the 23 joints between two frames, each centred on its joints'
    /// centroid: the key-pose error of `metrics::kinematics::key_pose_errors_cm`.
    fn centred_error_cm(a: ArrayView2<'_, f32>, b: ArrayView2<'_, f32>) -> f64 {
        let mean = |x: ArrayView2<'_, f32>| x.mean_axis(Axis(0)).expect("joints");
        let (ca, cb) = (mean(a), mean(b));
        let sum: f64 = (0..NUM_JOINTS)
            .map(|j| (0..3).map(|c| f64::from(a[[j, c]] - ca[c] - b[[j, c]] + cb[c]).powi(2)).sum::<f64>().sqrt())
            .sum();
        100.0 * sum / NUM_JOINTS as f64
    }

    /// A rigid skeleton posed with random rotations: IK must recover its positions exactly.
    #[test]
    fn ik_of_a_rigid_motion_is_exact() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let rig = random_rig(&mut rng);
        let t_len = 20;
        let roots: Vec<Vector3<f64>> = (0..t_len).map(|t| Vector3::new(0.1 * t as f64, 1.0, 0.0)).collect();
        let locals: Vec<Vec<UnitQuaternion<f64>>> =
            (0..t_len).map(|_| (0..RIG_JOINTS).map(|_| random_rotation(&mut rng, 1.0)).collect()).collect();
        let (pos, root) = arrays(&rig, &roots, &locals);
        for m in [solve(&rig, pos.view(), root.view(), 25.0).expect("solve"), solve_least_squares(&rig, pos.view(), root.view(), 25.0).expect("solve")] {
            let back = m.joint_positions();
            let err = joint_errors(back.view(), pos.view()).fold(0.0f32, |a, &b| a.max(b));
            assert!(err < 1e-4, "max error {err} m");
        }
    }

    /// Two key frames whose data disagree on the right thigh by 8 cm (as captured poses do:
    /// DANCE_W_3's thigh measures 43–54 cm): the chain IK on the anchors' median skeleton puts the
    /// whole difference on the knee and everything below it, the least-squares fit spreads it.
    #[test]
    fn a_thigh_the_key_frames_disagree_on_is_spread_over_the_body() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let rig = random_rig(&mut rng);
        let roots = vec![Vector3::new(0.0, 1.0, 0.0); 2];
        let locals: Vec<Vec<UnitQuaternion<f64>>> =
            (0..2).map(|_| (0..RIG_JOINTS).map(|_| random_rotation(&mut rng, 0.6)).collect()).collect();
        let (mut pos, root) = arrays(&rig, &roots, &locals);
        // Frame 1's thigh 8 cm longer: the knee and everything below it moves along the thigh.
        use crate::motion::skeleton::{HIPS, PARENTS};
        let knee = (0..NUM_JOINTS).find(|&j| PARENTS[j] == Some(HIPS[0])).expect("right knee");
        let thigh: Vec<f32> = (0..3).map(|c| pos[[1, knee, c]] - pos[[1, HIPS[0], c]]).collect();
        let len = thigh.iter().map(|v| v * v).sum::<f32>().sqrt();
        let below = |mut j: usize| loop {
            if j == knee {
                return true;
            }
            match PARENTS[j] {
                Some(p) => j = p,
                None => return false,
            }
        };
        for j in (0..NUM_JOINTS).filter(|&j| below(j)) {
            for c in 0..3 {
                pos[[1, j, c]] += 0.08 * thigh[c] / len;
            }
        }
        let worst = |m: &RigMotion| {
            let back = m.joint_positions();
            (0..2).map(|t| centred_error_cm(back.index_axis(Axis(0), t), pos.index_axis(Axis(0), t))).fold(0.0, f64::max)
        };
        let chain = worst(&solve(&Rig::fit(pos.view(), root.view()).expect("fit"), pos.view(), root.view(), 25.0).expect("solve"));
        let fitted = worst(&fit_and_solve(pos.view(), root.view(), 25.0, &[0, 1]).expect("solve"));
        eprintln!("worst key frame error: chain on median lengths {chain:.2} cm, least squares {fitted:.2} cm");
        assert!(chain > 1.0, "the test's mismatch does not show in the chain IK: {chain:.2} cm");
        assert!(fitted < 0.5 * chain, "least squares {fitted:.2} cm against the chain's {chain:.2} cm");
    }

    /// A smoothly turning rigid motion: the least-squares IK keeps its positions and its root
    /// track, and the root's, spine's and pelvis's rotations move as smoothly as the motion. ([`solve`]'s root rotation is free about the spine's offset, which the
    /// pelvis's repeats, and jumps by up to 180°, spine and pelvis turning back.)
    #[test]
    fn least_squares_keeps_the_root_track_and_turns_smoothly() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let rig = random_rig(&mut rng);
        let t_len = 50;
        let (a, b): (Vec<UnitQuaternion<f64>>, Vec<UnitQuaternion<f64>>) =
            (0..RIG_JOINTS).map(|_| (random_rotation(&mut rng, 0.5), random_rotation(&mut rng, 0.5))).unzip();
        let roots: Vec<Vector3<f64>> = (0..t_len).map(|t| Vector3::new(0.02 * t as f64, 1.0, 0.0)).collect();
        let locals: Vec<Vec<UnitQuaternion<f64>>> = (0..t_len)
            .map(|t| {
                let u = t as f64 / (t_len - 1) as f64;
                (0..RIG_JOINTS)
                    .map(|j| {
                        let q = a[j].slerp(&b[j], u);
                        // The root also turns a quarter of a turn about +y over the motion.
                        if j == 0 { UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 1.5 * u) * q } else { q }
                    })
                    .collect()
            })
            .collect();
        let (pos, root) = arrays(&rig, &roots, &locals);
        let m = solve_least_squares(&rig, pos.view(), root.view(), 25.0).expect("solve");
        let err = joint_errors(m.joint_positions().view(), pos.view()).fold(0.0f32, |a, &b| a.max(b));
        assert!(err < 1e-3, "max error {err} m");
        for t in 0..t_len {
            let off = (m.root_translation[t] - roots[t]).norm();
            assert!(off < 1e-3, "frame {t}: the root is {off} m off its track");
        }
        // The root and its children (spine, pelvis); further down, the twist of a limb its
        // joints leave free is the chain's (the left knee of this rig turns 16° in one frame in
        // both).
        let turn = |m: &RigMotion| {
            (1..t_len)
                .flat_map(|t| [0, rig_index(super::super::skeleton::SPINE), NUM_JOINTS + 1].map(|j| (t, j)))
                .map(|(t, j)| m.rotations[t - 1][j].angle_to(&m.rotations[t][j]).to_degrees())
                .fold(0.0, f64::max)
        };
        let chain = solve(&rig, pos.view(), root.view(), 25.0).expect("solve");
        eprintln!("largest turn of the root, spine or pelvis between frames: chain {:.1}°, least squares {:.1}°", turn(&chain), turn(&m));
        assert!(turn(&m) < 5.0, "the root, spine or pelvis turns {:.1}° between two frames", turn(&m));
    }

    /// Without anchors (a dance with no key pose) the export is the chain IK on the median
    /// skeleton, as it always was.
    #[test]
    fn without_anchors_the_chain_solution_is_kept() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let rig = random_rig(&mut rng);
        let roots: Vec<Vector3<f64>> = (0..10).map(|t| Vector3::new(0.0, 1.0, 0.05 * t as f64)).collect();
        let locals: Vec<Vec<UnitQuaternion<f64>>> =
            (0..10).map(|_| (0..RIG_JOINTS).map(|_| random_rotation(&mut rng, 0.8)).collect()).collect();
        let (pos, root) = arrays(&rig, &roots, &locals);
        let a = fit_and_solve(pos.view(), root.view(), 25.0, &[]).expect("solve");
        let b = solve(&Rig::fit(pos.view(), root.view()).expect("fit"), pos.view(), root.view(), 25.0).expect("solve");
        assert_eq!(a.rig, b.rig);
        assert_eq!(a.root_translation, b.root_translation);
        assert_eq!(a.rotations, b.rotations);
    }

    /// A pose turning slowly about y: the root's rotation turns with it, never by the free
    /// quarter turns a best fit of the coinciding spine and pelvis offsets allows.
    #[test]
    fn the_root_turns_with_the_body() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let (names, parents) = hierarchy();
        let mut offsets: Vec<Vector3<f64>> = (0..RIG_JOINTS).map(|_| Vector3::new(rng.gen_range(-0.2..0.2), rng.gen_range(-0.3..0.3), rng.gen_range(-0.2..0.2))).collect();
        offsets[0] = Vector3::zeros();
        offsets[NUM_JOINTS + 1] = offsets[rig_index(super::super::skeleton::SPINE)];
        offsets[NUM_JOINTS + 2] = Vector3::zeros();
        let rig = Rig { names, parents, offsets };
        let pose: Vec<UnitQuaternion<f64>> = (0..RIG_JOINTS).map(|_| UnitQuaternion::from_euler_angles(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5))).collect();
        let t_len = 30;
        let step = 0.02; // rad per frame
        let mut pos = Array3::zeros((t_len, NUM_JOINTS, 3));
        let mut root = Array2::zeros((t_len, 3));
        for t in 0..t_len {
            let mut local = pose.clone();
            local[0] = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), step * t as f64) * pose[0];
            let r = Vector3::new(0.0, 1.0, 0.0);
            let (p, _) = fk_frame(&rig, &r, &local);
            for j in 0..NUM_JOINTS {
                for c in 0..3 {
                    pos[[t, j, c]] = p[rig_index(j)][c] as f32;
                }
            }
            for c in 0..3 {
                root[[t, c]] = r[c] as f32;
            }
        }
        let m = solve(&rig, pos.view(), root.view(), 25.0).expect("solve");
        let worst = (1..t_len).map(|t| m.rotations[t][0].angle_to(&m.rotations[t - 1][0])).fold(0.0, f64::max);
        assert!(worst < 3.0 * step, "the root turned {worst:.3} rad in one frame (the body {step})");
        let err = joint_errors(m.joint_positions().view(), pos.view()).fold(0.0f32, |a, &b| a.max(b));
        assert!(err < 1e-4, "positions moved by {err} m");
    }

    #[test]
    fn six_d_round_trips() {
        let q = UnitQuaternion::from_euler_angles(0.3, -1.2, 2.0);
        let m = q.to_rotation_matrix();
        let m = m.matrix();
        let v = [
            m[(0, 0)] as f32, m[(1, 0)] as f32, m[(2, 0)] as f32,
            m[(0, 1)] as f32, m[(1, 1)] as f32, m[(2, 1)] as f32,
        ];
        let back = rotation_from_6d(&v).expect("valid");
        assert!(back.angle_to(&q) < 1e-5);
    }
}
